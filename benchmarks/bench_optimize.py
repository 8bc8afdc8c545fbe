"""Overhead of an optimisation run over the forward simulations it is made of.

For each torque parameterisation (ann, cs without feedforward; pf with feedforward, as in the
paper's tables) and each of bfgs and cmaes, one optimisation of 200 evaluations with the default
integrator (the engine's compiled RK4, dt = 1 ms, the forearm on the paper motion) is timed after
a warm-up run (so kernel compilation or loading, the ``cma`` import and the ANN pre-training, which
is cached, are excluded). The time spent integrating in such a run is measured as the time of the
same number of calls of the engine's RK4 alone (``multibody.kernels.rk4``, open loop, buffers
allocated once) on a fixed torque array (the inverse-dynamics torque on the half-step grid), so

    overhead = (total - integrating) / integrating

is the cost of everything else: torque evaluation, the objective (eq. 18), the optimiser itself.
The integrating time counts evaluations + 1 simulations (the run simulates its best parameters
once more for the record). The optimisation and its integrating time are measured alternately,
REPEATS times each, so both see the same machine load; each figure is the minimum over the
repeats (the least disturbed by other load). A BFGS evaluation simulates one candidate, a CMA-ES
generation its whole population in one compiled call; both reuse their buffers as the baseline
does, so the overhead could come out slightly negative.

Run: python benchmarks/bench_optimize.py
"""

from __future__ import annotations

import platform
import time

import numpy as np
import scipy

import fdbench
from fdbench.api import run
from fdbench.spec import optimize_spec
from fdbench.multibody.simulation import warm_up
from fdbench.optimizers import make_optimizer
from kernel_call import half_step_grid, model_and_motion, rk4_call

BUDGET = 200
REPEATS = 7
CELLS = [  # (torque, optimizer, feedforward)
    ("ann", "bfgs", False), ("ann", "cmaes", False),
    ("cs", "bfgs", False), ("cs", "cmaes", False),
    ("pf", "bfgs", True), ("pf", "cmaes", True),
]


def integrating_time(calls: int, simulate) -> float:
    """Seconds for ``calls`` calls of simulate (one RK4 simulation each)."""
    start = time.perf_counter()
    for _ in range(calls):
        simulate()
    return time.perf_counter() - start


def main() -> None:
    wall = time.perf_counter()
    engine, motion = model_and_motion("forearm")  # what optimize_spec's runs use: rk4, dt = 1 ms, paper motion
    grid = half_step_grid(engine, motion)
    simulate = rk4_call(engine, grid)  # open loop on the inverse-dynamics torques

    # warm-up: kernels, optimiser imports (cma), ANN pre-training cache, one short run per cell
    warm_up()
    for name in {opt for _, opt, _ in CELLS}:
        make_optimizer(name).warm_up()
    for torque, optimizer, feedforward in CELLS:
        run(optimize_spec(torque, optimizer, feedforward, seed=0, budget=5))
    integrating_time(5, simulate)

    rows = []
    for torque, optimizer, feedforward in CELLS:
        totals, integrating, evaluations, rmse = [], [], set(), set()
        for _ in range(REPEATS):
            record = run(optimize_spec(torque, optimizer, feedforward, seed=0, budget=BUDGET)).record
            totals.append(record["runtime_s"])  # excludes warm-up; includes the final simulation
            evaluations.add(record["evaluations"])
            rmse.add(record["rmse_rot_deg"])
            # the run simulated `evaluations` times for the objective, and once more for the record
            integrating.append(integrating_time(record["evaluations"] + 1, simulate))
        assert len(evaluations) == 1 and len(rmse) == 1, "repeated runs with one seed must agree"
        total, integ = min(totals), min(integrating)
        rows.append((torque, optimizer, "yes" if feedforward else "no", evaluations.pop(), total, integ,
                     100.0 * (total - integ) / integ, rmse.pop()))

    print(f"fdbench {fdbench.__version__}, numpy {np.__version__}, scipy {scipy.__version__}, "
          f"python {platform.python_version()}, {platform.machine()}")
    print(f"optimisation of {BUDGET} evaluations, rk4 dt {grid.dt * 1e3:g} ms, forearm, {motion.name} motion, "
          f"seed 0; minimum over {REPEATS} runs")
    header = ("torque", "optimizer", "ff", "evals", "total s", "integrating s", "overhead %", "rmse_rot_deg")
    print("  ".join(f"{h:>13}" if i >= 3 else f"{h:<9}" for i, h in enumerate(header)))
    for torque, optimizer, ff, evals, total, integ, overhead, rot in rows:
        print(f"{torque:<9}  {optimizer:<9}  {ff:<9}  {evals:>13d}  {total:>13.4f}  {integ:>13.4f}  "
              f"{overhead:>13.1f}  {rot:>13.4f}")
    print(f"total benchmark time: {time.perf_counter() - wall:.1f} s")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
