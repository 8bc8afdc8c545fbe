"""The registry of simulated bodies: a name -> the frozen dataclass of its constants.

* ``forearm``: Table 1's 1-DOF forearm (``fdbench.model.Forearm``), the paper's model.
* ``arm2``: the planar two-segment arm, shoulder + elbow (``fdbench.models.arm2.Arm2``).

A new model is a new module here that registers its class (``@MODELS.register("leg")``) and gives
it the class attributes ``motions`` (its named motions, the default first), ``keys`` (the
constants ``--model KEY=VALUE`` may change), ``with_changes`` (a function of (key, value) pairs
returning the checked model) and ``runs``: the name of the module carrying out its runs
(``check``, ``motions``, ``reference``, ``describe``, ``run``, ``run_simulation``,
``inverse_run`` and ``replay`` of a ``RunSpec``; see ``arm2_run``), None for the forearm, whose
runs are ``fdbench.experiment``'s own.
"""

from __future__ import annotations

import importlib

from ..model import MODEL_KEYS, Forearm, forearm_with
from ..motion import KINEMATICS
from ..registry import Registry

MODELS: Registry = Registry("model")
MODELS.register("forearm")(Forearm)
Forearm.motions = KINEMATICS  # eq. 5 as printed (the default) or differentiated exactly
Forearm.keys = MODEL_KEYS
Forearm.with_changes = staticmethod(forearm_with)
Forearm.runs = None  # its runs are fdbench.experiment's own

from . import arm2  # noqa: E402,F401 - registers "arm2"

SUMMARIES = {
    "forearm": "the paper's 1-DOF forearm (Table 1): the elbow fixed at the origin",
    "arm2": "planar two-segment arm, shoulder + elbow: Table 1's forearm on a 0.30 m, 2 kg upper arm",
}


def summary(name: str) -> str:
    """One line saying what the model ``name`` is (empty for a model registered without one)."""
    return SUMMARIES.get(name, getattr(MODELS[name], "summary", ""))


def model_class(name: str):
    """The class of the model registered as ``name``; UnknownName (a ValueError) lists the valid ones."""
    return MODELS[name]


def named_motions(name: str) -> tuple:
    """The motions model ``name`` knows by name, its default first (any other is a CSV file)."""
    return tuple(model_class(name).motions)


def default_motion(name: str) -> str:
    """The motion a command of model ``name`` follows when none is given."""
    return model_class(name).motions[0]


def model_keys(name: str) -> tuple:
    """The constants of model ``name`` that --model and --plant KEY=VALUE may change."""
    return tuple(model_class(name).keys)


def with_changes(name: str, pairs=()):
    """Model ``name`` with some constants changed ((key, value) pairs); ValueError if out of range."""
    return model_class(name).with_changes(pairs)


def runs(name: str):
    """The module carrying out the runs of model ``name``, or None for the forearm (whose runs are
    ``fdbench.experiment``'s own)."""
    module = model_class(name).runs
    return None if module is None else importlib.import_module(module)
