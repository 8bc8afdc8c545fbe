"""Cost of an exact gradient: one value-and-gradient pass (the RK4 simulation with its forward
sensitivities, ``TrackingProblem.value_and_gradient``) against one plain evaluation of the
objective (the same RK4 simulation without sensitivities, ``TrackingProblem.objective``), and
against the finite-difference gradient it replaces (n_params + 1 plain evaluations), for each
torque parameterisation at its default size. Both are measured in the same run, interleaved,
REPEATS rounds of CALLS calls each after a warm-up; each figure is the minimum over the rounds.
Then the optimisation the issue names: cs + bfgs, no feedforward, budget 200, fd and exact.

Run: python benchmarks/bench_gradient.py
"""

from __future__ import annotations

import platform

import numpy as np

from fdbench.experiment import optimize_spec, run
from fdbench.problem import TrackingProblem
from fdbench.torques import make_torque
from timing import best_of

CALLS = 50
REPEATS = 7
CASES = [("cs", False), ("cs", True), ("pf", True), ("ann", False)]



def main() -> None:
    print(f"{platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"{'torque':<8}{'ff':<5}{'P':>4}{'objective ms':>14}{'value+grad ms':>15}{'ratio':>8}{'fd/exact':>10}")
    for name, ff in CASES:
        problem = TrackingProblem(make_torque(name), feedforward=ff)
        x = problem.x0 + 0.01 * np.random.default_rng(0).standard_normal(problem.n_params)
        problem.objective_scaled(x), problem.value_and_gradient_scaled(x)  # warm-up
        plain, exact = [], []
        for _ in range(REPEATS):
            plain.append(best_of(lambda: problem.objective_scaled(x), 1, CALLS))
            exact.append(best_of(lambda: problem.value_and_gradient_scaled(x), 1, CALLS))
        p, e = min(plain), min(exact)
        fd = (problem.n_params + 1) * p
        print(f"{name:<8}{str(ff):<5}{problem.n_params:>4}{1e3 * p:>14.3f}{1e3 * e:>15.3f}{e / p:>8.2f}{fd / e:>10.1f}")
    print("\ncs + bfgs, no feedforward, budget 200:")
    for gradient in ("fd", "exact"):
        record = run(optimize_spec("cs", "bfgs", budget=200, gradient=gradient)).record
        print(f"  --gradient {gradient:<6} rmse_rot_deg {record['rmse_rot_deg']:.4f}  evaluations {record['evaluations']:>3}"
              f"  runtime_s {record['runtime_s']:.3f}  ({record['stop_reason']})")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
