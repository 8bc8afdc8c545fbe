"""Planar multibody models as data and the engine that simulates them: ``model`` is a checked,
frozen ``Model`` (bodies, joints, loads, named motions), ``model_files`` reads and writes it as
TOML or JSON, ``model_changes`` changes its constants (``fdbench.models`` finds one by name or
file; the library ships as TOML files in ``fdbench/models/library``); ``motions`` are the desired
motions; ``engine`` assembles the paper's mixed-coordinate penalty formulation from a ``Model``."""
