"""The benchmarks' one way of calling the engine's compiled RK4 alone (``fdbench.multibody.kernels.rk4``):
the references and the inverse-dynamics feedforward prepared once on the half-step grid, the work
buffers allocated once, so that a call costs the integration and nothing else."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HalfStepGrid:
    """A motion on the RK4 half-step grid t_k = k dt / 2, k = 0 .. 2 n: the references ref (rad),
    refd (rad/s), refdd (rad/s^2) and the inverse-dynamics torques tau (N m), each (2 n + 1, J);
    the start y0 (n_state,) on the motion."""

    n: int
    dt: float
    y0: np.ndarray
    ref: np.ndarray
    refd: np.ndarray
    refdd: np.ndarray
    tau: np.ndarray


def model_and_motion(name: str):
    """(Engine, motion) of a library model on its default motion (the forearm's: eq. 5, 'paper')."""
    from fdbench.models import default_motion, description
    from fdbench.multibody.engine import Engine
    from fdbench.multibody.motions import joint_motion

    model = description(name)
    return Engine(model), joint_motion(default_motion(name), model)


def gait_walk():
    """(model, motion, folder) of OpenSim's gait model (examples/opensim/subject01.osim) on its
    recorded walk, or None (with a line saying why) where OpenSim is not installed."""
    from pathlib import Path

    from fdbench.models import find_model
    from fdbench.multibody.motions import joint_motion

    folder = Path(__file__).resolve().parent.parent / "examples" / "opensim"
    try:
        model = find_model(folder / "subject01.osim")
    except Exception as exc:  # noqa: BLE001 - no OpenSim: the gait model is not measured
        print(f"subject01: not measured ({' '.join(str(exc).split())[:100]})")
        return None
    return model, joint_motion(folder / "subject01_walk_IK.mot", model), folder


def half_step_grid(engine, motion, dt: float = 1e-3) -> HalfStepGrid:
    """The motion and its inverse-dynamics torques on the half-step grid of steps of about dt (s)."""
    from fdbench.integrate import steps
    from fdbench.multibody.simulation import inverse_dynamics

    n = steps(dt, motion.duration)
    half = np.linspace(0.0, motion.duration, 2 * n + 1)
    ref, refd, refdd = (np.ascontiguousarray(r, dtype=float) for r in motion(half))
    tau = np.ascontiguousarray(inverse_dynamics(half, engine, motion).torque)
    return HalfStepGrid(n, motion.duration / n, engine.state_from_joints(ref[0], refd[0]), ref, refd, refdd, tau)


def rk4_call(engine, grid: HalfStepGrid, kp=0.0, kd=0.0, tau=None):
    """A function of no argument that runs the compiled RK4 once over the grid under PD (kp N m/rad,
    kd N m s/rad per joint; 0: open loop) plus the feedforward tau (N m, (2 n + 1, J); default the
    grid's inverse-dynamics torques) and returns (status, steps done, max violation); the states
    (n + 1, n_state) are in its attribute ``states``."""
    from fdbench.multibody import kernels

    J = engine.n_joints
    kp, kd = (np.array(np.broadcast_to(np.asarray(g, dtype=float), (J,))) for g in (kp, kd))
    tau = grid.tau if tau is None else np.ascontiguousarray(tau, dtype=float)
    from fdbench.multibody.layout import PD, Law

    law = Law(tau, grid.ref, grid.refd, grid.refdd, kp, kd, PD, np.zeros((1, J, 2 * J)))
    args = (*engine.kernel_args(), None, engine.layout, engine.paths, None)
    states, rates = np.empty((grid.n + 1, engine.n_state)), np.empty((grid.n + 1, engine.n_state))
    applied = np.empty((grid.n + 1, J))

    def call():
        return kernels.rk4(grid.y0, grid.dt, grid.n, 0, law, *args, states, rates, applied)

    call.states = states
    return call
