"""The registry of simulated bodies: a name -> the frozen dataclass of its constants.

* ``forearm``: Table 1's 1-DOF forearm (``fdbench.model.Forearm``), the paper's model.
* ``arm2``: the planar two-segment arm, shoulder + elbow (``fdbench.models.arm2.Arm2``).

A new model is a new module here that registers its class: ``@MODELS.register("leg")``.
"""

from __future__ import annotations

from ..model import Forearm
from ..registry import Registry

MODELS: Registry = Registry("model")
MODELS.register("forearm")(Forearm)

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
