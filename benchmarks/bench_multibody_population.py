"""Per-evaluation cost of CMA-ES runs on a model of the multibody engine (``--model``, default the
two-segment arm) against one plain compiled RK4 simulation of it, and the speed-up of population
evaluation on 2 threads.

Baseline, measured in the same run: one call of the engine's compiled RK4 kernel
(``Engine.simulate``, open loop) on the inverse-dynamics torques of the model's default motion,
steady state (the minimum over REPEATS rounds of CALLS calls). For cs and pf with
feedforward and ann without, a CMA-ES run of BUDGET evaluations (``experiment.run``, after a
warm-up run) on 1 and on 2 threads: runtime_s / evaluations (the minimum over RUNS runs) against
the baseline. Candidates whose simulation fails part-way cost less than a full run, so a ratio
below 1 is possible; the column 'reached' gives the mean fraction of the motion the candidates of
one run reached. Then one population of LAMBDA candidates near the start (full runs) evaluated by
``JointTrackingProblem.objectives_scaled`` on 1 and on 2 threads: the speed-up. On a machine whose
other cores are busy the speed-up cannot show; the load average is printed.

Run: python benchmarks/bench_multibody_population.py [--model arm2|leg3|FILE]
"""

from __future__ import annotations

import os

import numpy as np

from fdbench.experiment import optimize_spec, run
from fdbench.integrate import steps
from fdbench.models import default_motion, description
from fdbench.multibody import simulation
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.multibody.problem import JointTrackingProblem
from fdbench.population import set_threads
from timing import best_of

# evaluations per CMA-ES run; baseline calls per round; rounds; runs per cell; the population's size
BUDGET, CALLS, REPEATS, RUNS, LAMBDA = 200, 50, 7, 5, 40
CELLS = [("cs", True), ("pf", True), ("ann", False)]


def problem_of(model: str, torque: str, feedforward: bool) -> JointTrackingProblem:
    engine = Engine(description(model))
    return JointTrackingProblem(torque, engine, joint_motion(default_motion(model), engine.model), feedforward)


def baseline_s(model: str) -> float:
    """Seconds of one open-loop RK4 simulation of the model's default motion (dt = 1 ms), kernel alone."""
    engine = Engine(description(model))
    motion = joint_motion(default_motion(model), engine.model)
    n = steps(1e-3, motion.duration)
    half = np.linspace(0.0, motion.duration, 2 * n + 1)
    ref, refd, refdd = (np.ascontiguousarray(r) for r in motion(half))
    tau = np.array(simulation.inverse_dynamics(half, engine, motion).torque)
    y0 = engine.state_from_joints(ref[0], refd[0])

    def simulate():
        engine.simulate(y0, motion.duration / n, n, tau, ref, refd, refdd, 0.0, 0.0)

    simulate()
    return best_of(simulate, REPEATS, CALLS)


def mean_reached(model: str, torque: str, feedforward: bool) -> float:
    """The mean fraction of the motion reached by the candidates of one CMA-ES run (seed 0)."""
    from fdbench.optimizers import make_optimizer
    from fdbench.torques import TORQUES

    problem = problem_of(model, torque, feedforward)
    reached = []

    def batch(X):
        reached.extend(problem.simulate(x * problem.scale).t_end / problem.duration for x in X)
        return problem.objectives_scaled(X)

    options = TORQUES[torque].optimizer_defaults.get("cmaes", {})
    make_optimizer("cmaes", **options).minimize(problem.objective_scaled, problem.x0, BUDGET, seed=0, batch=batch)
    return float(np.mean(reached))


def main(model: str) -> None:
    print(f"load average: {os.getloadavg()}, cores available: {len(os.sched_getaffinity(0))}, model: {model}")
    set_threads(1)
    base = baseline_s(model)
    print(f"one plain RK4 simulation (Engine.simulate, open loop, steady state): {1e3 * base:.3f} ms")
    print(f"{'cell':<12}{'reached':>9}{'1 thread ms/eval':>18}{'x baseline':>12}{'2 threads ms/eval':>19}"
          f"{'x baseline':>12}")
    for torque, ff in CELLS:
        spec = optimize_spec(torque, "cmaes", ff, seed=0, budget=BUDGET, model_name=model)
        per = {}
        for count in (1, 2):
            set_threads(count)
            run(spec)  # warm-up
            per[count] = min(run(spec).record["runtime_s"] for _ in range(RUNS)) / BUDGET
        print(f"{torque + (' + ff' if ff else ''):<12}{mean_reached(model, torque, ff):>9.2f}{1e3 * per[1]:>18.3f}"
              f"{per[1] / base:>12.2f}{1e3 * per[2]:>19.3f}{per[2] / base:>12.2f}")
    print(f"\npopulation of {LAMBDA} candidates near the start (cs + ff, full runs), objectives_scaled:")
    problem = problem_of(model, "cs", True)
    X = problem.x0 + 1e-5 * np.random.default_rng(0).standard_normal((LAMBDA, problem.n_params))
    times = {}
    for count in (1, 2):
        set_threads(count)
        problem.objectives_scaled(X)
        times[count] = best_of(lambda: problem.objectives_scaled(X), REPEATS)
        print(f"  {count} thread(s): {1e3 * times[count]:.2f} ms ({1e3 * times[count] / LAMBDA:.3f} ms per candidate, "
              f"{times[count] / LAMBDA / base:.2f}x baseline)")
    print(f"  speed-up on 2 threads: {times[1] / times[2]:.2f}x")


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="arm2", help="a library model or a model file (default: arm2)")
    main(parser.parse_args().model)
