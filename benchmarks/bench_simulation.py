"""Runtime of one 1-second PD simulation (kp 80, kd 0.3, paper kinematics): the compiled RK4 of
``fdbench.integrate.simulate`` against scipy ``solve_ivp`` RK45 with a pure-Python right-hand
side (the un-compiled source of the numba kernel), plus ``fdbench.control.pd_control`` end to end.

Run: python benchmarks/bench_simulation.py
"""

from __future__ import annotations

import math
import platform
import time
import timeit

import numpy as np
import scipy
from scipy.integrate import solve_ivp

import fdbench
from fdbench import dynamics
from fdbench.control import feedforward, pd_control
from fdbench.indicators import rmse_rot_deg
from fdbench.integrate import Settings, SimulationResult, Status, initial_state, simulate, warm_up
from fdbench.inverse import inverse_dynamics
from fdbench.motion import desired_motion, sample_times

KP, KD = 80.0, 0.3
SETTINGS = Settings(kinematics="paper")  # compiled RK4, dt = 1 ms
RTOL, ATOL = 1e-6, 1e-9


def python_rhs(ff, consts, kinematics):
    """Right-hand side of eq. 12 in pure Python: the numba kernel's Python source
    (``accelerations.py_func``), the same feedforward torque and the same PD law."""
    accel = dynamics.accelerations.py_func

    def rhs(t, y):
        ref_th, ref_w, _ = desired_motion(t, kinematics)
        tau = float(ff(np.array([t]))[0]) + KP * (float(ref_th) - y[2]) + KD * (float(ref_w) - y[5])
        ax, ay, ath, _ = accel(y[0], y[1], y[2], y[3], y[4], y[5], tau, consts)
        return np.array([y[3], y[4], y[5], ax, ay, ath])

    return rhs


def simulate_python(ff, consts):
    ts = sample_times()
    return solve_ivp(python_rhs(ff, consts, SETTINGS.kinematics), (0.0, 1.0),
                     initial_state(SETTINGS.kinematics, SETTINGS.model), method="RK45",
                     t_eval=ts, rtol=RTOL, atol=ATOL)


def as_result(sol) -> SimulationResult:
    ts = sample_times()
    q = np.full((len(ts), 3), np.nan)
    qd = np.full((len(ts), 3), np.nan)
    q[: sol.y.shape[1]], qd[: sol.y.shape[1]] = sol.y[:3].T, sol.y[3:].T
    status = Status.SUCCESS if sol.status == 0 else Status.SOLVER
    return SimulationResult(ts, q, qd, np.full(len(ts), np.nan), float(sol.t[-1]), status, math.nan,
                            "python-rk45", rhs_evaluations=int(sol.nfev))


def best(stmt, number, repeat):
    """Minimum time (s) of one call over ``repeat`` batches of ``number`` calls."""
    return min(timeit.repeat(stmt, number=number, repeat=repeat)) / number


def main() -> None:
    start = time.perf_counter()
    ff = feedforward(SETTINGS)  # one feedforward object, reused (its memo holds the torque grid)
    consts = dynamics.kernel_constants(SETTINGS.model, SETTINGS.penalty)
    theta_desired = inverse_dynamics(kinematics=SETTINGS.kinematics).theta

    # warm up: load or compile the kernels for every signature used below
    warm_up()
    compiled = simulate(ff, SETTINGS, KP, KD)
    pd_control(KP, KD, SETTINGS)

    t_rk4 = best(lambda: simulate(ff, SETTINGS, KP, KD), number=20, repeat=7)
    t_pd = best(lambda: pd_control(KP, KD, SETTINGS), number=20, repeat=7)
    sol = simulate_python(ff, consts)
    t_py = best(lambda: simulate_python(ff, consts), number=1, repeat=3)

    python = as_result(sol)
    rot_rk4 = rmse_rot_deg(compiled, theta_desired)
    rot_py = rmse_rot_deg(python, theta_desired)

    print(f"fdbench {fdbench.__version__}, numpy {np.__version__}, scipy {scipy.__version__}, "
          f"python {platform.python_version()}, {platform.machine()}")
    print("PD control, kp 80 N m/rad, kd 0.3 N m s/rad, paper kinematics, t in [0, 1] s "
          "(min over repeats)")
    rows = [
        ("compiled RK4 (dt 1 ms), fdbench simulate()", t_rk4,
         f"rmse_rot_deg = {rot_rk4:.6f}  ({compiled.rhs_evaluations} rhs evaluations, {compiled.status.name})"),
        (f"scipy RK45 (rtol {RTOL:g}, atol {ATOL:g}), Python rhs", t_py,
         f"rmse_rot_deg = {rot_py:.6f}  ({python.rhs_evaluations} rhs evaluations, {python.status.name})"),
        ("fdbench pd_control() incl. feedforward", t_pd, "(the paper reports 75 ms for its PD simulation)"),
    ]
    width = max(len(label) for label, _, _ in rows)
    for label, seconds, note in rows:
        print(f"  {label:<{width}}  {seconds * 1e3:9.3f} ms   {note}")
    print(f"  {'speed-up (Python RK45 / compiled RK4)':<{width}}  {t_py / t_rk4:9.1f} x")
    print(f"total benchmark time: {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
