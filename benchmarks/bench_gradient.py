"""Cost of an exact gradient on the engine's models: one value-and-gradient pass (the RK4 simulation
with its forward sensitivities, ``TrackingProblem.value_and_gradient_scaled``) against one plain
evaluation of the objective (the same RK4 simulation without sensitivities,
``TrackingProblem.objective_scaled``), and against the finite-difference gradient it replaces
(n_params + 1 plain evaluations), on the forearm (paper motion), arm2 and leg3 (their default
motions) and a tree (a trunk with two children, one joined between its parent's basic points; a
1 s minimum-jerk motion), for each torque parameterisation at its default size. Both are measured
in the same run, interleaved, REPEATS rounds of CALLS calls each after a warm-up; each figure is
the minimum over the rounds. Then an optimisation on the forearm: cs + bfgs, no feedforward,
budget 200, with the finite-difference and with the exact gradient.

Last, OpenSim's gait model on its recorded walk with its ground reactions (the dense kernels'
sensitivities: a free pelvis, knees on paths, external loads; only where OpenSim is installed),
cs per coordinate with feedforward (260 parameters) at the RK4 step fitted to the recording
(1/1020 s): one plain evaluation against one value-and-gradient pass at the start, where the open
loop falls at 0.44 s, and their cost per step reached.

Run: python benchmarks/bench_gradient.py
"""

from __future__ import annotations

import math
import platform

import numpy as np

from fdbench.api import run
from fdbench.spec import optimize_spec
from fdbench.multibody import model as d
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import MinimumJerk
from fdbench.problem import TrackingProblem
from kernel_call import gait_walk, model_and_motion
from timing import best_of

CALLS = 10
REPEATS = 5
MODELS = ("forearm", "arm2", "leg3", "tree")
CASES = [("cs", False), ("cs", True), ("pf", True), ("ann", False)]


def tree():
    """(Engine, motion) of a three-body tree: a trunk hanging from ground with two children, one
    at its end, one at a point between its basic points, a load on the second; every joint moves
    by about 0.3 rad in 1 s."""
    bodies = (d.Body("trunk", 5.0, (0.2, 0.02), 0.08, end=(0.4, 0.0)), d.Body("left", 2.0, (0.15, 0.0), 0.02),
              d.Body("right", 1.5, (0.12, 0.01), 0.015, end=(0.25, 0.0)))
    joints = (d.Joint("root", "pin", d.GROUND, "trunk", (0.0, 0.0), (0.0, 0.0), offset=-math.pi / 2),
              d.Joint("left_joint", "pin", "trunk", "left", (0.4, 0.0), (0.0, 0.0), offset=1.2),
              d.Joint("right_joint", "pin", "trunk", "right", (0.2, 0.05), (0.0, 0.0), offset=-1.0))
    model = d.Model("tree", (0.0, -9.81), bodies, joints, loads=(d.Load("right", (0.25, 0.0), (0.0, -5.0)),))
    motion = d.MotionSpec("move", "minimum-jerk", 1.0, (("root", 0.0), ("left_joint", 0.3), ("right_joint", -0.2)),
                          (("root", 0.15), ("left_joint", -0.2), ("right_joint", 0.4)))
    return Engine(model), MinimumJerk(motion, model.coordinates)


def per_call(problem) -> tuple[float, float]:
    """Seconds of one plain evaluation and of one value-and-gradient pass near the start."""
    x = problem.x0 + 0.01 * np.random.default_rng(0).standard_normal(problem.n_params)
    problem.objective_scaled(x), problem.value_and_gradient_scaled(x)  # warm-up
    plain, exact = [], []
    for _ in range(REPEATS):
        plain.append(best_of(lambda: problem.objective_scaled(x), 1, CALLS))
        exact.append(best_of(lambda: problem.value_and_gradient_scaled(x), 1, CALLS))
    return min(plain), min(exact)


def walk_problem():
    """(problem, steps reached) of the walk's CS + feedforward shooting problem, or None without OpenSim."""
    from fdbench.multibody.loads import read_external_loads
    from fdbench.multibody.simulation import dt_on_samples

    walk = gait_walk()
    if walk is None:
        return None
    model, motion, folder = walk
    loads = read_external_loads(folder / "subject01_walk_grf.xml", model).shifted(motion.start_s)
    knots = int(round(motion.duration / 0.1)) + 1  # a knot every 0.1 s, as the walk report's
    problem = TrackingProblem("cs", Engine(model, loads=loads), motion, True, dt=dt_on_samples(1e-3, motion.samples),
                              knots=knots)
    result = problem.simulate(problem.p0)
    return problem, int(round(result.t_end / problem.dt))


def main() -> None:
    print(f"{platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"{'model':<9}{'torque':<8}{'ff':<6}{'P':>4}{'objective ms':>14}{'value+grad ms':>15}{'ratio':>8}"
          f"{'fd/exact':>10}")
    for name in MODELS:
        engine, motion = tree() if name == "tree" else model_and_motion(name)
        for torque, ff in CASES:
            problem = TrackingProblem(torque, engine, motion, ff)
            p, e = per_call(problem)
            fd = (problem.n_params + 1) * p
            print(f"{name:<9}{torque:<8}{str(ff):<6}{problem.n_params:>4}{1e3 * p:>14.3f}{1e3 * e:>15.3f}"
                  f"{e / p:>8.2f}{fd / e:>10.1f}")
    print("\nforearm, cs + bfgs, no feedforward, budget 200:")
    for gradient in ("fd", "exact"):
        record = run(optimize_spec("cs", "bfgs", budget=200, gradient=gradient)).record
        print(f"  --gradient {gradient:<6} rmse_rot_deg {record['rmse_rot_deg']:.4f}  evaluations {record['evaluations']:>3}"
              f"  runtime_s {record['runtime_s']:.3f}  ({record['stop_reason']})")
    walk = walk_problem()
    if walk is not None:
        problem, reached = walk
        p, e = per_call(problem)
        print(f"\nsubject01 walk, cs + ff, {problem.n_params} parameters, {reached} steps reached of "
              f"{int(round(problem.duration / problem.dt))}: objective {1e3 * p:.1f} ms, value+grad {1e3 * e:.1f} ms "
              f"(ratio {e / p:.1f}; {1e6 * e / reached:.0f} us per step against {1e6 * p / reached:.1f}); finite "
              f"differences would take {(problem.n_params + 1) * p / e:.0f} times the exact gradient's time")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
