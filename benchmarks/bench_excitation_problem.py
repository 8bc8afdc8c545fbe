"""Excitation-driven tracking on the library's arm26 (six muscles, compliant tendons as in the
library, or all rigid with --rigid): ``fdbench.excitation_problem.ExcitationProblem`` (a cubic
spline per muscle through the logistic, prepared on static optimisation's activations) on the
motion mid_range, one CMA-ES run (its generations evaluated in compiled calls) and one BFGS run
with exact gradients (forward sensitivities through the activation and tendon states). Printed per
run: eq. 18 (RMSE deg + penalty) and the effort term at the start and at the best point, the
evaluations and the time.

Run: python benchmarks/bench_excitation_problem.py [--rigid] [--budget N] [--knots K]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fdbench.excitation_problem import ExcitationProblem
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.motions import joint_motion
from fdbench.optimizers import make_optimizer


def terms(problem: ExcitationProblem, p) -> tuple[float, float]:
    """(eq. 18, effort) of parameters p."""
    f = problem.objective(p)
    effort = float(problem.effort(problem.excitations_on_grid(p)[None])[0])
    return f - effort, effort


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rigid", action="store_true", help="every tendon rigid")
    parser.add_argument("--budget", type=int, default=300, help="evaluations per run")
    parser.add_argument("--knots", type=int, default=5, help="spline knots per muscle")
    parser.add_argument("--dt", type=float, default=None,
                        help="RK4 step (s); default 1e-3 rigid, 1e-4 compliant (at 2e-4 the library's "
                             "compliant arm26 fails within 50 steps at the start's excitations)")
    options = parser.parse_args()
    data = to_dict(find_model("arm26"))
    if options.rigid:
        for m in data["muscles"]:
            m["tendon"] = "rigid"
    model = model_from_dict(data, "arm26.toml")
    dt = options.dt or (1e-3 if options.rigid else 1e-4)
    problem = ExcitationProblem("cs", Engine(model), joint_motion("mid_range", model), knots=options.knots, dt=dt)
    problem.objective(problem.p0), problem.value_and_gradient(problem.p0)  # compiled before the clocks
    start = terms(problem, problem.p0)
    print(f"arm26 ({'rigid' if options.rigid else 'compliant'} tendons, dt {dt:g} s), mid_range, cs with "
          f"{options.knots} knots "
          f"per muscle: {problem.n_params} parameters; start: eq. 18 {start[0]:.3f}, effort {start[1]:.4f}")
    for name, kwargs in (("cmaes", {}), ("bfgs", {"gradient": problem.value_and_gradient_scaled})):
        began = time.perf_counter()
        found = make_optimizer(name).minimize(problem.objective_scaled, problem.x0, options.budget, 0,
                                              batch=problem.objectives_scaled if name == "cmaes" else None, **kwargs)
        seconds = time.perf_counter() - began
        end = terms(problem, np.asarray(found.x) * problem.scale)
        print(f"  {name:6s} eq. 18 {start[0]:.3f} -> {end[0]:.3f}, effort {start[1]:.4f} -> {end[1]:.4f} "
              f"({found.evaluations} evaluations, {seconds:.1f} s; {found.stop_reason})")


if __name__ == "__main__":
    main()
