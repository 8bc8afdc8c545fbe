"""fdbench: a benchmark of trajectory-tracking methods for forward dynamic simulation.

A body (the paper's 1-DOF forearm, a library model, your own model file or an OpenSim model) must
follow a prescribed motion of its joints; fdbench compares PD control with computed feedforward,
computed torque, LQR, direct collocation and optimised torque histories (ANN, cubic spline,
parametric function) by RMSE of rotation (deg), RMSE of torque (N m) and runtime (s), all on one
planar multibody engine (``fdbench.multibody``).

The entry points for a script (imported on first use, so ``import fdbench`` stays cheap):

- ``RunSpec``, ``control_spec(kp, kd, ...)``, ``optimize_spec(torque, optimizer, ...)``: a run's
  full specification; ``run(spec)`` carries it out and returns a ``RunOutcome`` (``record``:
  the flat record of the command line; ``result``: the simulation; ``history``; ``params``).
- ``simulate(torque=None, ...)``: open-loop forward dynamics, by default of the
  inverse-dynamics torques; ``inverse_dynamics(...)``: those torques on the motion's samples.
- ``TORQUES``, ``OPTIMIZERS``: the registries of torque parameterisations and optimisers.
- ``load_report(db, ...)``: a stored report's table as a pandas DataFrame; ``load_runs(db)``:
  every stored run.
"""

__version__ = "0.1.0"

_ENTRY_POINTS = {
    "RunSpec": "spec", "RunOutcome": "records", "run": "api", "control_spec": "spec", "optimize_spec": "spec",
    "inverse_dynamics": "api", "simulate": "api", "load_report": "api", "load_runs": "api", "TORQUES": "torques", "OPTIMIZERS": "optimizers",
}

__all__ = ["__version__", *_ENTRY_POINTS]


def __getattr__(name):
    module = _ENTRY_POINTS.get(name)
    if module is None:
        raise AttributeError(f"module 'fdbench' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_ENTRY_POINTS))
