"""Cost of an exact gradient on the engine's models: one value-and-gradient pass (the RK4
simulation with its forward sensitivities, ``JointTrackingProblem.value_and_gradient``) against one
plain evaluation of the objective (the same RK4 simulation without sensitivities,
``JointTrackingProblem.objective``), and against the finite-difference gradient it replaces
(n_params + 1 plain evaluations), on arm2 and leg3 with their default motions, for each torque
parameterisation at its default size. Both are measured in the same run, interleaved, REPEATS
rounds of CALLS calls each after a warm-up; each figure is the minimum over the rounds.

Run: python benchmarks/bench_multibody_gradient.py
"""

from __future__ import annotations

import platform

import numpy as np

from fdbench.multibody.description import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.multibody.problem import JointTrackingProblem
from timing import best_of

CALLS = 10
REPEATS = 5
MODELS = ("arm2", "leg3")
CASES = [("cs", False), ("cs", True), ("pf", True), ("ann", False)]



def main() -> None:
    print(f"{platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"{'model':<7}{'torque':<8}{'ff':<6}{'P':>4}{'objective ms':>14}{'value+grad ms':>15}{'ratio':>8}"
          f"{'fd/exact':>10}")
    for name in MODELS:
        model = find_model(name)
        engine, motion = Engine(model), joint_motion(model.motions[0].name, model)
        for torque, ff in CASES:
            problem = JointTrackingProblem(torque, engine, motion, ff)
            x = problem.x0 + 0.01 * np.random.default_rng(0).standard_normal(problem.n_params)
            problem.objective_scaled(x), problem.value_and_gradient_scaled(x)  # warm-up
            plain, exact = [], []
            for _ in range(REPEATS):
                plain.append(best_of(lambda: problem.objective_scaled(x), 1, CALLS))
                exact.append(best_of(lambda: problem.value_and_gradient_scaled(x), 1, CALLS))
            p, e = min(plain), min(exact)
            fd = (problem.n_params + 1) * p
            print(f"{name:<7}{torque:<8}{str(ff):<6}{problem.n_params:>4}{1e3 * p:>14.3f}{1e3 * e:>15.3f}"
                  f"{e / p:>8.1f}{fd / e:>10.1f}")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
