"""Peers: the tools fdbench's methods are compared with, run on the same model, motion and
indicators and giving the same flat record as fdbench's runs (plus their own fields).

* ``opensim``: OpenSim's forward simulation under fdbench's PD law with computed feedforward, the
  law inside OpenSim, one integrate (``fdbench.peers.opensim_pd``), beside ``fdbench control``.
* ``opensim-cmc``: OpenSim's CMCTool on the torque-driven model (``fdbench.peers.cmc``), beside
  ``fdbench control``.
* ``moco``: OpenSim Moco's MocoTrack, its torque replayed by fdbench's forward simulation
  (``fdbench.peers.moco``), beside ``fdbench collocate``.

A peer run is a ``RunSpec`` of command "peer" whose ``method_options`` hold the peer's name and
its options, so it is stored, resumed and reported like every run. OpenSim runs in a child
process (``fdbench.peers.child``); without the opensim package a peer is refused in one line
naming ``pip install 'fdbench[opensim]'``."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..collocation import check_options
from ..controllers.pd import PD
from ..registry import unknown_name_message
from .child import opensim_version
from .cmc import SUMMARY as CMC
from .moco import DEFAULT_TOLERANCE
from .moco import SUMMARY as MOCO
from .opensim_pd import SUMMARY as OPENSIM


@dataclass(frozen=True)
class Peer:
    """A peer: its name, its row's label, one sentence on what it does, its options' defaults
    (besides the PD gains, which are the spec's ``kp``/``kd`` as for ``control``) and the module
    that carries it out (its ``run(spec)``)."""

    name: str
    label: str
    summary: str
    defaults: dict = field(default_factory=dict)
    module: str = ""

    def run(self, spec):
        import importlib

        return importlib.import_module(self.module).run(spec)


def _peers() -> dict:
    return {
        "opensim": Peer("opensim", "OpenSim forward simulation, PD + feedforward", OPENSIM, {},
                        "fdbench.peers.opensim_pd"),
        "opensim-cmc": Peer("opensim-cmc", "OpenSim CMCTool (Computed Muscle Control), torque-driven", CMC, {},
                            "fdbench.peers.cmc"),
        "moco": Peer("moco", "MocoTrack (Hermite-Simpson) + forward replay", MOCO,
                     {"nodes": 100, "regularization": 1e-6, "tolerance": DEFAULT_TOLERANCE, "max_iter": 1000},
                     "fdbench.peers.moco"),
    }


NAMES = ("opensim", "opensim-cmc", "moco")


def peer(name: str) -> Peer:
    """The peer ``name``; ValueError (one line listing the valid names) for another."""
    if name not in NAMES:
        raise ValueError(unknown_name_message("peer", name, list(NAMES)))
    return _peers()[name]


def parse_names(text: str, option: str = "--peers") -> list[str]:
    """The peers of a comma-separated list ('opensim,opensim-cmc,moco'), each once, in the order given;
    ValueError naming the option for an unknown or empty one."""
    names = [part.strip() for part in str(text).split(",")]
    for name in names:
        if name not in NAMES:
            raise ValueError(f"{option}: " + unknown_name_message("peer", name or "''", list(NAMES)))
    return list(dict.fromkeys(names))


def check_spec(spec) -> None:
    """ValueError (one line) for a peer spec's unknown peer or out-of-range option; no work done."""
    options = dict(spec.method_options)
    found = peer(str(options.get("peer")))
    if set(options) - {"peer"} != set(found.defaults):
        raise ValueError(f"peer {found.name}: options {sorted(set(options) - {'peer'})}, expected "
                         f"{sorted(found.defaults)}")
    if found.name == "opensim-cmc":
        return
    if found.name == "opensim":
        PD(spec.kp, spec.kd)  # a ValueError names a bad gain
        return
    check_options(options["nodes"], "hermite-simpson", options["regularization"], options["max_iter"])
    tolerance = options["tolerance"]
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not (
            math.isfinite(tolerance) and 0 < tolerance < 1):
        raise ValueError(f"--tolerance must be a number in (0, 1), got {tolerance}")


def run(spec):
    """Carry out a peer run (``RunOutcome``)."""
    return peer(dict(spec.method_options)["peer"]).run(spec)


def check_available() -> str:
    """OpenSim's version where the peers run; ``child.PeerUnavailable`` (a ValueError, one line
    naming ``pip install 'fdbench[opensim]'``) without the opensim package."""
    return opensim_version()
