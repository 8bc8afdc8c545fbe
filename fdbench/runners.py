"""The runs of a ``RunSpec``: ``run`` (control, optimize, collocate), ``run_simulation``,
``replay`` and ``inverse_run``, each carried out on the multibody engine by
``fdbench.method_runs`` (one runner per command) and turned into a flat record."""

from __future__ import annotations

from . import method_runs
from .records import RunOutcome, explained
from .spec import RunSpec


def run(spec: RunSpec, on_evaluation=None, on_start=None) -> RunOutcome:
    """Carry out a control, optimisation or collocation run. ``on_evaluation(count, best)``
    reports progress; ``on_start(budget)`` is called once compilation and imports are done."""
    spec.validate()
    if spec.command == "simulate":
        raise ValueError("simulate runs are carried out by run_simulation")
    if spec.command == "peer":  # OpenSim's and Moco's runs (fdbench.peers)
        from .peers import run as run_peer

        return explained(run_peer(spec), spec)
    return explained(method_runs.run(spec, on_evaluation, on_start), spec)


def run_simulation(spec: RunSpec, torque_file=None, params_file=None, torque=None) -> RunOutcome:
    """Open-loop forward dynamics driven by the inverse-dynamics torques, a CSV torque history,
    saved optimisation parameters or ``torque`` (a function of t (s), shape (k,) -> N m, shape (k,)
    or (k, J)). Bad files raise ``files.BadFile``."""
    return explained(method_runs.run_simulation(spec, torque_file, params_file, torque), spec)


def replay(spec: RunSpec, params):
    """The simulation of a stored optimisation run's best parameters (for figures)."""
    return method_runs.replay(spec, params)


def inverse_run(spec: RunSpec) -> tuple:
    """Inverse dynamics of the desired motion with the nominal model: (record, CSV header, rows on
    the motion's samples), the columns of a motion file plus the torques."""
    return method_runs.inverse_run(spec)
