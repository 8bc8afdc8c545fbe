"""fdbench as a library: a new torque parameterisation, registered and optimised.

    python examples/custom_torque.py [BUDGET]      # BUDGET: forward simulations allowed (default 100)

The new parameterisation is a piecewise-linear torque through the values at equally spaced
knots. Registering it with ``@TORQUES.register("pwl")`` is all it takes to make it usable by
``TrackingProblem``, by every optimiser of the registry and by ``fdbench.run``, the
function behind ``fdbench optimize``. The command line runs in a fresh process: to reach it, put
the registration in a module and name it in ``FDBENCH_PLUGINS`` (see ``examples/my_methods.py``).
"""

from __future__ import annotations

import math
import sys

import numpy as np

from fdbench.api import run
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.spec import optimize_spec
from fdbench.optimizers import make_optimizer
from fdbench.problem import TrackingProblem
from fdbench.torques import TORQUES, TorqueParameterisation
from fdbench.torques.base import check_count


@TORQUES.register("pwl")
class PiecewiseLinearTorque(TorqueParameterisation):
    """Parameters: the torque (N m) at ``knots`` equally spaced instants of [0, 1] s, joined by
    straight lines."""

    name = "pwl"
    summary = "piecewise-linear torque through --knots equally spaced values (default 8)"

    def __init__(self, knots: int = 8):
        # options arrive as keyword arguments; a bad one raises ValueError with a one-line message
        self.knots = check_count("--knots", knots, 2)
        self.n_params = self.knots
        self.t_knots = np.linspace(0.0, 1.0, self.knots)
        self._scale = 1.0

    def prepare(self, t, target, feedforward):
        """The initial guess: the target (inverse-dynamics) torque at the knots, or zero when the
        parameterisation only adds to the feedforward torque."""
        self._scale = max(float(np.ptp(target)) / 2, 1e-9)
        if feedforward:
            return np.zeros(self.n_params)
        return np.interp(self.t_knots, t, target)

    def evaluate(self, p, t):
        return np.interp(np.asarray(t, dtype=float), self.t_knots, np.asarray(p, dtype=float))

    def on_grid(self, t):
        """A fast evaluator on fixed times: the interpolation is linear in p, so precompute it."""
        basis = np.column_stack([np.interp(t, self.t_knots, column) for column in np.eye(self.knots)])
        return lambda p: basis @ p

    def scale(self):
        return np.full(self.n_params, self._scale)


def show(title: str, indicators: dict) -> None:
    print(title)
    for key, value in indicators.items():
        print(f"  {key} = {value:.6g}" if isinstance(value, float) else f"  {key} = {value}")


def main(argv: list[str]) -> int:
    budget = int(argv[1]) if len(argv) > 1 else 100
    if budget < 1:
        print("usage: custom_torque.py [BUDGET >= 1]", file=sys.stderr)
        return 2

    # 1. the building blocks: the forearm's engine and motion, a TrackingProblem, an optimiser from the registry
    forearm = find_model("forearm")
    problem = TrackingProblem(PiecewiseLinearTorque(knots=8), Engine(forearm), joint_motion("paper", forearm))
    optimizer = make_optimizer("bfgs")
    start = problem.simulate(problem.p0)
    result = optimizer.minimize(problem.objective_scaled, problem.x0, budget, seed=0)
    best = problem.simulate(result.x * problem.scale)
    show("pwl + bfgs through the library (TrackingProblem, make_optimizer):", {
        "initial_rmse_rot_deg": problem.rmse_deg(start),
        "rmse_rot_deg": problem.rmse_deg(best),
        "rmse_torque_nm": float(np.sqrt(np.mean((best.torque - problem.inverse.torque) ** 2))),
        "best_objective": result.fun,
        "evaluations": result.evaluations,
        "t_end": best.t_end,
        "status": best.status.code,
    })

    # 2. the same torque through fdbench.run, which fills the command line's record
    outcome = run(optimize_spec(torque="pwl", optimizer="bfgs", budget=budget, torque_options={"knots": 8}))
    record = outcome.record
    show("pwl + bfgs through fdbench.run (the record of 'fdbench optimize'):",
         {key: record[key] for key in ("torque", "optimizer", "rmse_rot_deg", "rmse_torque_nm", "runtime_s",
                                       "evaluations", "t_end", "status")})

    ok = all(math.isfinite(v) for v in (record["rmse_rot_deg"], record["rmse_torque_nm"], record["runtime_s"]))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
