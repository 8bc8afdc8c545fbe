"""Planar multibody models as data and the engine that simulates them: ``description`` reads and
checks a model file (bodies, pin joints, constant loads) into a frozen ``Model`` (the library of
built-in models ships as TOML files in ``fdbench/models/library``); ``engine`` assembles the
paper's mixed-coordinate penalty formulation from a ``Model``."""
