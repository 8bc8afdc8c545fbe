"""Per-evaluation cost of CMA-ES runs on the engine's models (the forearm, arm2, leg3, or those named
by --model) against one plain compiled RK4 simulation, and the speed-up of population evaluation
on 2 threads.

Baseline, measured in the same run for each model: one call of the engine's compiled RK4 alone
(``multibody.kernels.rk4``, open loop) on the inverse-dynamics torques of the model's default
motion, buffers allocated once, steady state (the minimum over REPEATS rounds of CALLS calls). For
cs and pf with feedforward and ann without, a CMA-ES run of BUDGET evaluations (``fdbench.run``
after a warm-up run) on 1 and on 2 threads: runtime_s / evaluations (the minimum over RUNS runs)
against the baseline (the goal on the forearm: at most 1.5x). Beside it, the part that is CMA-ES's
own bookkeeping (cma's ask and tell, the budget's records): the same optimiser with the same
options on a trivial objective, no simulation. Candidates whose simulation fails part-way cost
less than a full run, so a ratio below 1 is possible; the column 'reached' gives the mean fraction
of the motion the candidates of one run reached. Then one population of LAMBDA candidates near the
start (full runs) evaluated by ``TrackingProblem.objectives_scaled`` on 1 and on 2 threads: the
speed-up. On a machine whose other cores are busy the speed-up cannot show; the load average is
printed.

Run: python benchmarks/bench_population.py [--model forearm|arm2|leg3|FILE ...]
"""

from __future__ import annotations

import os

import numpy as np

from fdbench.api import run
from fdbench.spec import optimize_spec
from fdbench.models import default_motion, description
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.population import set_threads
from fdbench.problem import TrackingProblem
from kernel_call import half_step_grid, rk4_call
from timing import best_of

# evaluations per CMA-ES run; baseline calls per round; rounds; runs per cell; the population's size
BUDGET, CALLS, REPEATS, RUNS, LAMBDA = 200, 50, 7, 5, 40
MODELS = ("forearm", "arm2", "leg3")
CELLS = [("cs", True), ("pf", True), ("ann", False)]


def engine_and_motion(model: str):
    """(Engine, default motion) of a library model or a model file."""
    found = description(model)
    return Engine(found), joint_motion(default_motion(model), found)


def problem_of(model: str, torque: str, feedforward: bool) -> TrackingProblem:
    """The tracking problem of a cell, with the torque options ``optimize_spec`` gives it."""
    options = dict(optimize_spec(torque, "cmaes", feedforward, model_name=model).torque_options)
    return TrackingProblem(torque, *engine_and_motion(model), feedforward, **options)


def baseline_s(model: str) -> float:
    """Seconds of one open-loop RK4 simulation of the model's default motion (dt = 1 ms) on its
    inverse-dynamics torques, kernel alone."""
    engine, motion = engine_and_motion(model)
    simulate = rk4_call(engine, half_step_grid(engine, motion))
    simulate()
    return best_of(simulate, REPEATS, CALLS)


def bookkeeping_s(model: str, torque: str, feedforward: bool) -> float:
    """Seconds of a BUDGET-evaluation CMA-ES run on a trivial objective (sum of squares) with the
    cell's options, start and dimension: cma and the budget's records alone."""
    from fdbench.optimizers import make_optimizer

    spec = optimize_spec(torque, "cmaes", feedforward, seed=0, budget=BUDGET, model_name=model)
    x0 = problem_of(model, torque, feedforward).x0
    optimizer = make_optimizer("cmaes", **dict(spec.optimizer_options))
    optimizer.warm_up()
    return best_of(lambda: optimizer.minimize(lambda x: float(x @ x), x0, BUDGET, seed=0,
                                              batch=lambda X: np.einsum("ij,ij->i", X, X)), RUNS)


def mean_reached(model: str, torque: str, feedforward: bool) -> float:
    """The mean fraction of the motion reached by the candidates of one CMA-ES run (seed 0)."""
    from fdbench.optimizers import make_optimizer

    spec = optimize_spec(torque, "cmaes", feedforward, seed=0, budget=BUDGET, model_name=model)
    problem = problem_of(model, torque, feedforward)
    reached = []

    def batch(X):
        reached.extend(problem.simulate(x * problem.scale).t_end / problem.duration for x in X)
        return problem.objectives_scaled(X)

    make_optimizer("cmaes", **dict(spec.optimizer_options)).minimize(problem.objective_scaled, problem.x0, BUDGET,
                                                                     seed=0, batch=batch)
    return float(np.mean(reached))


def cells(model: str, base: float) -> None:
    """The CMA-ES cells of one model against the baseline (s)."""
    print(f"{'cell':<12}{'reached':>9}{'1 thread ms/eval':>18}{'x baseline':>12}{'cma own':>9}"
          f"{'2 threads ms/eval':>19}{'x baseline':>12}")
    for torque, ff in CELLS:
        spec = optimize_spec(torque, "cmaes", ff, seed=0, budget=BUDGET, model_name=model)
        per = {}
        for count in (1, 2):
            set_threads(count)
            run(spec)  # warm-up
            per[count] = min(run(spec).record["runtime_s"] for _ in range(RUNS)) / BUDGET
        set_threads(1)
        own = bookkeeping_s(model, torque, ff) / BUDGET
        print(f"{torque + (' + ff' if ff else ''):<12}{mean_reached(model, torque, ff):>9.2f}{1e3 * per[1]:>18.3f}"
              f"{per[1] / base:>12.2f}{own / base:>8.2f}x{1e3 * per[2]:>19.3f}{per[2] / base:>12.2f}")


def population_speed_up(model: str, base: float) -> None:
    """One population of LAMBDA candidates near the start (cs + ff) on 1 and 2 threads."""
    print(f"population of {LAMBDA} candidates near the start (cs + ff, full runs), objectives_scaled:")
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
    set_threads(1)


def main(models) -> None:
    print(f"load average: {os.getloadavg()}, cores available: {len(os.sched_getaffinity(0))}")
    for model in models:
        set_threads(1)
        base = baseline_s(model)
        print(f"\n{model}: one plain RK4 simulation (kernels.rk4, open loop, steady state): {1e3 * base:.3f} ms")
        cells(model, base)
        population_speed_up(model, base)


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", action="append", help="a library model or a model file, repeatable "
                        f"(default: {', '.join(MODELS)})")
    main(parser.parse_args().model or MODELS)
