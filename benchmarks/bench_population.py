"""Per-evaluation cost of CMA-ES runs against one plain compiled RK4 simulation, and the speed-up
of population evaluation on more threads.

Baseline, measured in the same run: one call of the compiled RK4 kernel (``dynamics.rk4``) on a
fixed torque array with preallocated buffers, steady state (the minimum over REPEATS rounds of
CALLS calls). For each of cs and ann without feedforward and pf with feedforward, a CMA-ES run of
BUDGET evaluations (``experiment.run``, after a warm-up run) on 1 thread: runtime_s / evaluations
(the minimum over RUNS runs) against the baseline; the goal is at most 1.5x. Beside it, the part
that is CMA-ES's own bookkeeping (cma's ask and tell, the budget's records): the same optimiser
with the same options on a trivial objective, no simulation. Then one population of LAMBDA
candidates evaluated by ``TrackingProblem.objectives_scaled`` on 1 and on 2 threads (minimum over
rounds): the speed-up. On a machine whose other cores are busy the speed-up cannot show;
``uptime``'s load is printed.

Run: python benchmarks/bench_population.py
"""

from __future__ import annotations

import os
import time

import numpy as np

from fdbench import dynamics
from fdbench.experiment import optimize_spec, run
from fdbench.integrate import Settings, constants, half_step_reference, initial_state, steps
from fdbench.inverse import Feedforward
from fdbench.population import set_threads
from fdbench.problem import TrackingProblem
from fdbench.torques import make_torque

BUDGET = 200
CALLS = 50
REPEATS = 7
RUNS = 9
LAMBDA = 40
CELLS = [("cs", False), ("pf", True), ("ann", False)]


def baseline_s() -> float:
    settings = Settings()
    n = steps(settings.dt)
    half, ref_th, ref_w = half_step_reference(n, settings.kinematics)
    tau = np.array(Feedforward(settings.model, settings.kinematics)(half))
    buffers = np.empty((n + 1, 6)), np.empty((n + 1, 3)), np.empty(n + 1)
    y0, consts = initial_state(settings.kinematics, settings.model), constants(settings)
    best = np.inf
    for _ in range(REPEATS):
        start = time.perf_counter()
        for _ in range(CALLS):
            dynamics.rk4(y0, settings.dt, n, tau, ref_th, ref_w, 0.0, 0.0, consts, *buffers)
        best = min(best, (time.perf_counter() - start) / CALLS)
    return best


def bookkeeping_s(torque: str, feedforward: bool) -> float:
    """Seconds of a BUDGET-evaluation CMA-ES run on a trivial objective (sum of squares) with the
    torque's default options, start and dimension: cma and the budget's records alone."""
    from fdbench.optimizers import make_optimizer
    from fdbench.torques import TORQUES

    problem = TrackingProblem(make_torque(torque), feedforward=feedforward)
    optimizer = make_optimizer("cmaes", **TORQUES[torque].optimizer_defaults.get("cmaes", {}))
    optimizer.warm_up()
    best = np.inf
    for _ in range(RUNS):
        start = time.perf_counter()
        optimizer.minimize(lambda x: float(x @ x), problem.x0, BUDGET, seed=0,
                           batch=lambda X: np.einsum("ij,ij->i", X, X))
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    print(f"load average: {os.getloadavg()}, cores available: {len(os.sched_getaffinity(0))}")
    set_threads(1)
    base = baseline_s()
    print(f"one plain RK4 simulation (dynamics.rk4, steady state): {1e3 * base:.3f} ms")
    print(f"{'cell':<12}{'ms / evaluation':>17}{'x baseline':>12}{'of which CMA-ES bookkeeping':>30}")
    for torque, ff in CELLS:
        spec = optimize_spec(torque, "cmaes", ff, seed=0, budget=BUDGET)
        run(spec)  # warm-up
        per = min(run(spec).record["runtime_s"] for _ in range(RUNS)) / BUDGET
        own = bookkeeping_s(torque, ff) / BUDGET
        print(f"{torque + (' + ff' if ff else ''):<12}{1e3 * per:>17.3f}{per / base:>12.2f}{own / base:>29.2f}x")
    print(f"\npopulation of {LAMBDA} candidates (cs), objectives_scaled:")
    problem = TrackingProblem(make_torque("cs"))
    X = problem.x0 + 0.02 * np.random.default_rng(0).standard_normal((LAMBDA, problem.n_params))
    times = {}
    for count in (1, 2):
        set_threads(count)
        problem.objectives_scaled(X)
        best = np.inf
        for _ in range(REPEATS):
            start = time.perf_counter()
            problem.objectives_scaled(X)
            best = min(best, time.perf_counter() - start)
        times[count] = best
        print(f"  {count} thread(s): {1e3 * best:.2f} ms")
    print(f"  speed-up on 2 threads: {times[1] / times[2]:.2f}x")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
