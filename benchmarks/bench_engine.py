"""Cost of one RK4 step of the multibody engine for chains of 1, 2, 3, 5, 8 and 12 bodies against
the engine's forearm (the library's one-body model), measured in the same run.

Both: the compiled RK4 kernel alone (``multibody.kernels.rk4``, the same inputs every call), dt =
1 ms, 1 s of motion, PD feedback (kp 80, kd 0.3 per joint) plus the inverse-dynamics feedforward;
the forearm on the paper motion (eq. 5). The chain's bodies are 0.3 m bars of 1 kg; its joints
follow slow sines clear of the angle constraint's switch. Printed: the cost per step (us), its
ratio to the forearm's, and the growth law fitted to the ratios (least squares of ratio = a + b N;
the goal is at most 2N, a banded solve makes it linear). With a C compiler, the forearm's step
against that of the same algorithm in C (../shared/bench/pd_forearm.c, cc -O2, as
bench_speed_limit.py builds and runs it).

Then the cost per step of leg3 (three bodies) under each feedback law of the one RK4 driver: PD,
computed torque (the inverse dynamics at every stage) and a gain matrix; and the library's models
(forearm, arm2, leg3) under PD by the kernel alone, with their ratio to the forearm's step on the
paper motion.

Last, OpenSim's gait model (examples/opensim/subject01.osim: 10 coordinates, a free pelvis, the
knees on paths; imported through OpenSim, so only where it is installed) on its recorded walk
(subject01_walk_IK.mot, 2.5 s, dt 1 ms) under PD (kp 300, kd 30) plus the feedforward and under
computed torque (kp 400 1/s^2, kd 40 1/s), by ``Engine.simulate`` (the dense kernels of
``multibody.kernels``, the dense solve), per step and against the forearm's step.

Run: python benchmarks/bench_engine.py
"""

from __future__ import annotations

import math
import platform

import numpy as np

import fdbench
from fdbench.multibody import engine as mb
from fdbench.multibody import kernels
from fdbench.multibody.layout import COMPUTED, GAINS, OK, PD, Law
from fdbench.multibody.model import GROUND, Body, Joint, Model
from bench_speed_limit import c_loop_ms
from kernel_call import gait_walk, half_step_grid, model_and_motion, rk4_call
from timing import best_of

REPEAT, NUMBER = 5, 10
SIZES = (1, 2, 3, 5, 8, 12)


def best_per_call(fn) -> float:
    """Seconds of one call of fn: the best of REPEAT rounds of NUMBER calls."""
    return best_of(fn, REPEAT, NUMBER)


def chain(n_bodies: int) -> Model:
    """n 0.3 m bars of 1 kg, pinned end to end from the origin."""
    bodies = tuple(Body(f"b{k}", 1.0, (0.15, 0.0), 0.0075, end=(0.3, 0.0)) for k in range(n_bodies))
    joints = tuple(Joint(f"q{k}", "pin", GROUND if k == 0 else f"b{k - 1}", f"b{k}",
                         (0.0, 0.0) if k == 0 else (0.3, 0.0), (0.0, 0.0)) for k in range(n_bodies))
    return Model(f"chain{n_bodies}", (0.0, -9.81), bodies, joints)


def forearm_kernel():
    """The engine's forearm on the paper motion under PD plus feedforward: (steps, call)."""
    engine, motion = model_and_motion("forearm")
    grid = half_step_grid(engine, motion)
    return grid.n, rk4_call(engine, grid, 80.0, 0.3)


def _rk4(engine, y0, n, law, states, rates, applied):
    """A function of no argument: the compiled RK4 of n steps of 1 / n s under the law, the model's
    own as the believed one, no loads."""
    args = (*engine.kernel_args(), None, engine.layout, engine.paths, None, states, rates, applied)
    return lambda: kernels.rk4(y0, 1.0 / n, n, 0, law, *args)


def chain_kernel(n_bodies: int):
    engine, n = mb.Engine(chain(n_bodies)), 1000
    half = np.linspace(0.0, 1.0, 2 * n + 1)[:, None]
    signs = np.where(np.arange(n_bodies) % 2 == 0, 1.0, -1.0)
    centre = np.where(np.arange(n_bodies) == 0, 0.2, 0.1 * signs)  # absolute angles within [-0.1, 0.5] rad
    z = centre + 0.1 * np.sin(2 * math.pi * half)
    zd = 0.2 * math.pi * np.cos(2 * math.pi * half)
    zdd = -0.4 * math.pi**2 * np.sin(2 * math.pi * half)
    zd, zdd = np.broadcast_to(zd, z.shape).copy(), np.broadcast_to(zdd, z.shape).copy()
    tau = engine.inverse_dynamics(z, zd, zdd)
    kp, kd = np.full(n_bodies, 80.0), np.full(n_bodies, 0.3)
    y0 = engine.state_from_joints(z[0], zd[0])
    states, rates = np.empty((n + 1, engine.n_state)), np.empty((n + 1, engine.n_state))
    applied = np.empty((n + 1, n_bodies))
    no_gains = np.zeros((1, n_bodies, 2 * n_bodies))
    return n, _rk4(engine, y0, n, Law(tau, np.ascontiguousarray(z), zd, zdd, kp, kd, PD, no_gains), states, rates,
                   applied)


def leg_kernel(mode: int):
    """The compiled RK4 of leg3 (fdbench/models/library/leg3.toml) under each feedback law: PD
    (kp 300, kd 20 per joint), computed torque (kp 400 1/s^2, kd 40 1/s) and a constant gain matrix
    [diag kp, diag kd], on a slow swing of the thigh through -90 deg with the inverse-dynamics
    feedforward."""
    from fdbench.models import find_model

    engine, n = mb.Engine(find_model("leg3")), 1000
    half = np.linspace(0.0, 1.0, 2 * n + 1)[:, None]
    z = np.array([0.0, -0.4, 0.1]) + 0.3 * np.sin(2 * math.pi * half)
    zd, zdd = 0.6 * math.pi * np.cos(2 * math.pi * half), -1.2 * math.pi**2 * np.sin(2 * math.pi * half)
    zd, zdd = np.broadcast_to(zd, z.shape).copy(), np.broadcast_to(zdd, z.shape).copy()
    tau = engine.inverse_dynamics(z, zd, zdd) if mode != COMPUTED else np.zeros_like(z)
    computed = mode == COMPUTED
    kp, kd = np.full(3, 400.0 if computed else 300.0), np.full(3, 40.0 if computed else 20.0)
    gains = np.broadcast_to(np.hstack([np.diag(kp), np.diag(kd)]), (2 * n + 1, 3, 6)).copy()
    if mode != GAINS:
        gains = gains[:1]
    y0 = engine.state_from_joints(z[0], zd[0])
    states, rates, applied = np.empty((n + 1, engine.n_state)), np.empty((n + 1, engine.n_state)), np.empty((n + 1, 3))
    return n, _rk4(engine, y0, n, Law(tau, np.ascontiguousarray(z), zd, zdd, kp, kd, mode, gains), states, rates,
                   applied)


def library_kernel(name: str):
    """The compiled RK4 of a library model under PD (kp 80, kd 0.3 per joint) plus the
    inverse-dynamics feedforward, on a slow sine of every joint about 0.2 rad."""
    from fdbench.models import find_model

    engine, n = mb.Engine(find_model(name)), 1000
    J = engine.n_joints
    half = np.linspace(0.0, 1.0, 2 * n + 1)[:, None]
    z = 0.2 + 0.3 * np.sin(2 * math.pi * half) + np.zeros(J)
    zd = np.broadcast_to(0.6 * math.pi * np.cos(2 * math.pi * half), z.shape).copy()
    zdd = np.zeros_like(z)
    tau = engine.inverse_dynamics(z, zd, zdd)
    kp, kd, no_gains = np.full(J, 80.0), np.full(J, 0.3), np.zeros((1, J, 2 * J))
    y0 = engine.state_from_joints(z[0], zd[0])
    states, rates, applied = np.empty((n + 1, engine.n_state)), np.empty((n + 1, engine.n_state)), np.empty((n + 1, J))
    return n, _rk4(engine, y0, n, Law(tau, np.ascontiguousarray(z), zd, zdd, kp, kd, PD, no_gains), states, rates,
                   applied)


def gait_simulation(mode: int):
    """subject01 on its walk under PD plus feedforward or computed torque: (steps, call), or None
    without OpenSim."""
    walk = gait_walk()
    if walk is None:
        return None
    model, motion, _ = walk
    engine = mb.Engine(model)
    grid = half_step_grid(engine, motion)
    computed = mode == COMPUTED
    tau = np.zeros_like(grid.tau) if computed else grid.tau
    kp, kd = (400.0, 40.0) if computed else (300.0, 30.0)
    return grid.n, lambda: engine.simulate(grid.y0, grid.dt, grid.n, tau, grid.ref, grid.refd, grid.refdd, kp, kd,
                                           mode)


def main():
    print(f"fdbench {fdbench.__version__}, {platform.python_implementation()} {platform.python_version()}, "
          f"{platform.machine()}")
    n, fn = forearm_kernel()
    fn()
    forearm = best_per_call(fn) / n
    print(f"forearm (engine, paper motion): {forearm * 1e6:.3f} us per RK4 step")
    c_ms = c_loop_ms()
    if c_ms is None:
        print("C loop: no C compiler (cc) or no ../shared/bench/pd_forearm.c, not measured")
    else:
        wall, cpu = (ms / 1e3 / n for ms in c_ms)
        print(f"C loop (pd_forearm.c, cc -O2): {wall * 1e6:.3f} us per step (wall), {cpu * 1e6:.3f} (CPU time); "
              f"engine forearm = {forearm / wall:.2f} x C (wall), {forearm / cpu:.2f} x C (CPU time)")
    ratios = []
    for size in SIZES:
        n, fn = chain_kernel(size)
        code, done, _ = fn()
        assert (code, done) == (OK, n), f"chain of {size}: status {code} at step {done}"
        per_step = best_per_call(fn) / n
        ratios.append(per_step / forearm)
        print(f"chain of {size:2d}: {per_step * 1e6:7.3f} us per step = {ratios[-1]:6.2f} x forearm "
              f"({ratios[-1] / size:.2f} N)")
    a, b = np.polyfit(np.array(SIZES, dtype=float), ratios, 1)[::-1]
    slope = np.polyfit(np.log(SIZES), np.log(ratios), 1)[0]
    print(f"growth: ratio = {a:.2f} + {b:.2f} N (least squares); log-log slope {slope:.2f}")
    for name, mode in (("PD", PD), ("computed torque", COMPUTED), ("gain matrix", GAINS)):
        n, fn = leg_kernel(mode)
        code, done, _ = fn()
        assert (code, done) == (OK, n), f"leg3 {name}: status {code} at step {done}"
        per_step = best_per_call(fn) / n
        print(f"leg3, {name:15s}: {per_step * 1e6:7.3f} us per step = {per_step / forearm:6.2f} x forearm")
    for name in ("forearm", "arm2", "leg3"):
        n, fn = library_kernel(name)
        code, done, _ = fn()
        assert (code, done) == (OK, n), f"{name}: status {code} at step {done}"
        per_step = best_per_call(fn) / n
        print(f"library {name:8s} (PD): {per_step * 1e6:7.3f} us per step = {per_step / forearm:6.2f} x forearm")
    for name, mode in (("PD", PD), ("computed torque", COMPUTED)):
        gait = gait_simulation(mode)
        if gait is None:
            break
        n, fn = gait
        result = fn()
        assert (result.status, result.steps_done) == (OK, n), f"subject01 {name}: status {result.status}"
        per_step = best_of(fn, 3, 1) / n
        print(f"subject01 walk, {name:15s}: {per_step * 1e6:7.3f} us per step = {per_step / forearm:6.2f} x forearm "
              f"({per_step * n:.3f} s for the walk's {n} steps)")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
