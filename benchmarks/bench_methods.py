"""The methods beyond the paper beside PD control: computed-torque, LQR and direct collocation,
on both kinematics variants, with runtimes as ratios to PD's measured in the same run; then the
collocation's forward-replay error as the number of intervals grows.

Run: python benchmarks/bench_methods.py
"""

from __future__ import annotations

import platform
import time

import numpy as np

import fdbench
from fdbench.api import run, run_simulation
from fdbench.spec import RunSpec, collocate_spec, control_spec

REPEATS = 5


def best_of(spec, runner=run):
    """The record of the run with the smallest runtime over REPEATS (the numbers are identical)."""
    records = [runner(spec).record for _ in range(REPEATS)]
    return min(records, key=lambda r: r["runtime_s"])


def main() -> None:
    start = time.perf_counter()
    print(f"fdbench {fdbench.__version__}, python {platform.python_version()}, {platform.machine()}")
    print("RK4, dt 1 ms, alpha 1e7; runtime = min over 5 runs (controller design and IPOPT solve included)\n")
    header = f"{'kinematics':<10} {'method':<34} {'RMSE_rot deg':>12} {'RMSE_tq N m':>11} {'runtime ms':>10} {'x PD':>7}"
    print(header)
    print("-" * len(header))
    for kinematics in ("paper", "exact"):
        common = dict(kinematics=kinematics)
        rows = [
            ("PD kp 80 kd 0.3 (paper)", best_of(control_spec(80.0, 0.3, **common))),
            ("open loop (inverse-dynamics torque)", best_of(RunSpec(command="simulate", **common), run_simulation)),
            ("computed-torque w_n 20 zeta 1", best_of(control_spec(controller="computed-torque",
                                                                   controller_options=dict(bandwidth=20.0, damping=1.0), **common))),
            ("computed-torque w_n 100 zeta 1", best_of(control_spec(controller="computed-torque",
                                                                    controller_options=dict(bandwidth=100.0, damping=1.0), **common))),
            ("LQR (q 1e4, 1; r 1)", best_of(control_spec(controller="lqr", **common))),
            ("collocation H-S N 100", best_of(collocate_spec(**common))),
        ]
        pd = rows[0][1]["runtime_s"]
        for label, r in rows:
            print(f"{kinematics:<10} {label:<34} {r['rmse_rot_deg']:>12.3g} {r['rmse_torque_nm']:>11.4f} "
                  f"{r['runtime_s'] * 1e3:>10.2f} {r['runtime_s'] / pd:>7.1f}")
    print("\ncollocation on the paper motion: the forward replay (fdbench RK4) against the number of intervals")
    header = (f"{'scheme':<16} {'nodes':>5} {'replay RMSE_rot deg':>19} {'own RMSE_rot deg':>16} "
              f"{'RMSE_tq N m':>11} {'IPOPT it':>8} {'solve s':>8} {'runtime s':>9}")
    print(header)
    print("-" * len(header))
    for scheme in ("hermite-simpson", "trapezoidal"):
        for nodes in (50, 100, 200, 400):
            r = best_of(collocate_spec(nodes, scheme))
            print(f"{scheme:<16} {nodes:>5} {r['rmse_rot_deg']:>19.3g} {r['collocation_rmse_rot_deg']:>16.3g} "
                  f"{r['rmse_torque_nm']:>11.4f} {r['ipopt_iterations']:>8} {r['solve_time_s']:>8.4f} "
                  f"{r['runtime_s']:>9.4f}  {r['ipopt_status']}")
    print(f"\ntotal benchmark time: {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    np.seterr(all="ignore")
    main()
