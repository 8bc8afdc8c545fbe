"""Planar multibody models: the model description and the engine that simulates it."""
