"""Peers: the tools fdbench's methods are compared with (``opensim``: OpenSim's forward simulation
under the PD law; ``opensim-cmc``: OpenSim's CMCTool; ``moco``: MocoTrack, replayed by fdbench), run
on the same model, motion and indicators and giving the same flat record. A peer run is a
``RunSpec`` of command "peer" (``method_options``: the peer's name and options); OpenSim runs in a
child process (``fdbench.peers.child``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..collocation import DEFAULT_EXCITATION_WEIGHT, check_options
from ..controllers.pd import PD
from ..registry import unknown_name_message
from ..run_inputs import nominal
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


PEERS = {
    "opensim": Peer("opensim", "OpenSim forward simulation, PD + feedforward", OPENSIM, {}, "fdbench.peers.opensim_pd"),
    "opensim-cmc": Peer("opensim-cmc", "OpenSim CMCTool (Computed Muscle Control)", CMC, {},
                        "fdbench.peers.cmc"),
    "moco": Peer("moco", "MocoTrack (Hermite-Simpson) + forward replay", MOCO,
                 {"nodes": 100, "regularization": 1e-6, "tolerance": DEFAULT_TOLERANCE, "max_iter": 1000},
                 "fdbench.peers.moco"),
}
NAMES = tuple(PEERS)


def peer(name: str) -> Peer:
    """The peer ``name``; ValueError (one line listing the valid names) for another."""
    if name not in NAMES:
        raise ValueError(unknown_name_message("peer", name, list(NAMES)))
    return PEERS[name]


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
    if options["regularization"] != found.defaults["regularization"] and nominal(spec).muscles:
        raise ValueError("--regularization weighs the torques of a torque-driven MocoTrack; on a model with muscles "
                         "Moco weighs the excitations and reserves by collocate's effort weight "
                         f"({DEFAULT_EXCITATION_WEIGHT:g} deg^2 per excitation^2)")
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
