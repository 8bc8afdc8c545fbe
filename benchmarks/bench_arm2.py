"""Cost of one simulation of the two-segment arm (arm2) against the 1-DOF forearm's, per RK4 step.

Both: compiled RK4, dt = 1 ms, 1 s of motion, PD feedback plus computed feedforward (the forearm
on eq. 5 'paper', the arm on its reach). Timed: the compiled kernel alone (the same inputs every
call) and the whole simulation call (feedforward, references, resampling). Kernels are compiled
before timing; the ratio arm / forearm is measured in this run. The target is a ratio <= 2.5.

Run: python benchmarks/bench_arm2.py
"""

from __future__ import annotations

import platform
import timeit

import numpy as np

import fdbench
from fdbench import dynamics
from fdbench.control import pd_control
from fdbench.integrate import Settings, constants, half_step_reference, initial_state, steps, warm_up
from fdbench.inverse import elbow_torque
from fdbench.models import arm2_kernels
from fdbench.models import arm2_sim
from fdbench.models.arm2 import Arm2
from fdbench.model import Penalty

REPEAT, NUMBER = 7, 20
SETTINGS = Settings(kinematics="paper")


def best_per_call(fn) -> float:
    return min(timeit.repeat(fn, repeat=REPEAT, number=NUMBER)) / NUMBER


def forearm_kernel():
    n = steps(SETTINGS.dt)
    half, ref_th, ref_w = half_step_reference(n, SETTINGS.kinematics)
    tau = np.array(elbow_torque(half, SETTINGS.model, SETTINGS.kinematics))
    y0, consts = np.array(initial_state(SETTINGS.kinematics, SETTINGS.model)), constants(SETTINGS)
    states, qdd, applied = np.empty((n + 1, 6)), np.empty((n + 1, 3)), np.empty(n + 1)
    kp, kd = np.full(1, 80.0), np.full(1, 0.3)
    return n, lambda: dynamics.rk4_feedback(y0, 1.0 / n, n, tau, ref_th, ref_w, kp, kd, 0.0, consts, states, qdd,
                                            applied)


def arm_kernel():
    arm, motion = Arm2(), arm2_sim.as_joint_motion("reach")
    n = steps(1e-3, motion.duration)
    half = np.linspace(0.0, motion.duration, 2 * n + 1)
    ref, ref_w, ref_a = motion(half)
    tau = arm2_sim.inverse_dynamics(half, arm, motion).torque
    y0, consts = arm2_sim.initial_state(arm, motion), arm2_kernels.kernel_constants(arm, Penalty())
    states, qdd, applied = np.empty((n + 1, 12)), np.empty((n + 1, 6)), np.empty((n + 1, 2))
    kp, kd = np.full(2, 80.0), np.full(2, 0.3)
    no_gains = np.zeros((1, 2, 4))
    return n, lambda: arm2_kernels.rk4_pd(y0, 1.0 / n, n, tau, ref, ref_w, ref_a, kp, kd, 0, no_gains, consts, consts,
                                          states, qdd, applied)


def main() -> None:
    warm_up()
    arm_ff = arm2_sim.feedforward()
    (n_f, forearm), (n_a, arm) = forearm_kernel(), arm_kernel()
    forearm(), arm()  # compile
    results = {
        "kernel": (best_per_call(forearm) / n_f, best_per_call(arm) / n_a),
        "simulation call": (best_per_call(lambda: pd_control(80.0, 0.3, SETTINGS)) / n_f,
                            best_per_call(lambda: arm2_sim.simulate(arm_ff, kp=80.0, kd=0.3)) / n_a),
    }
    print(f"fdbench {fdbench.__version__}, Python {platform.python_version()}, {platform.machine()}")
    print(f"{'per RK4 step':<18}{'forearm (us)':>14}{'arm2 (us)':>12}{'ratio':>8}")
    for name, (f, a) in results.items():
        print(f"{name:<18}{f * 1e6:>14.3f}{a * 1e6:>12.3f}{a / f:>8.2f}")
    ratio = results["kernel"][1] / results["kernel"][0]
    print(f"target: arm2 kernel <= 2.5x the forearm's per step: {'met' if ratio <= 2.5 else 'NOT met'} ({ratio:.2f}x)")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
