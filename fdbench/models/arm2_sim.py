"""Inverse and forward dynamics of the two-segment arm on a desired joint motion: the arm's
counterparts of ``fdbench.inverse`` and ``fdbench.integrate``: compiled fixed-step RK4 (torques
and references on the half-step grid) or scipy's adaptive methods (``integrate.solve_adaptive``)
on the same compiled feedback laws (per-joint PD plus feedforward, computed torque, a gain matrix).

A simulation never raises on a physical failure: it stops where it cannot go on and says why in
``status`` (``fdbench.integrate.Status``); ``t_end`` is the time reached.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..integrate import (AdaptiveSystem, Status, StopIntegration, check_integrator, check_tolerances,
                         solve_adaptive, steps)
from ..model import Penalty
from .arm2 import Arm2
from .arm2_motion import JointMotion, as_joint_motion


@dataclass(frozen=True)
class ArmInverse:
    """Histories on the time grid ``t`` (s): angles (rad), velocities (rad/s), accelerations
    (rad/s^2) and joint torques (N m), each of shape (n, 2) [shoulder, elbow]."""

    t: np.ndarray
    angles: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    torque: np.ndarray
    motion: str
    joints: tuple = ("shoulder", "elbow")


def inverse_dynamics(t=None, model: Arm2 = Arm2(), motion: str | JointMotion = "reach") -> ArmInverse:
    """The joint torques of ``motion`` at times t (s) (default: the motion's samples)."""
    motion = as_joint_motion(motion)
    t = motion.samples if t is None else np.asarray(t, dtype=float)
    z, w, dw = motion(t)
    return ArmInverse(t, z, w, dw, model.joint_torques(z, w, dw), motion.name)


@dataclass
class ArmSimulation:
    """A forward simulation on the motion's samples; histories of shape (n, 6) (q, q') or (n, 2)
    (joint angles, torques); samples after ``t_end`` are NaN."""

    t: np.ndarray  # s
    q: np.ndarray  # [x1, y1, x2, y2 (m), shoulder, elbow (rad)]
    qd: np.ndarray  # their derivatives, m/s and rad/s
    torque: np.ndarray  # total applied joint torques, N m
    t_end: float  # s
    status: Status
    max_violation: float  # max |Phi_i| reached (at the RK4 steps, or at the samples), m^2 or m
    runtime_s: float = 0.0
    integrator: str = "rk4"
    detail: str = ""  # what made an adaptive integrator fail
    rhs_evaluations: int = 0  # adaptive integrators

    @property
    def angles(self) -> np.ndarray:
        """Joint angles [shoulder, elbow] (rad), shape (n, 2)."""
        return self.q[:, 4:6]

    @property
    def reached(self) -> np.ndarray:
        return np.isfinite(self.q[:, 4])

    @property
    def success(self) -> bool:
        return self.status is Status.SUCCESS


def initial_state(model: Arm2, motion: JointMotion) -> np.ndarray:
    """[q, q'] on the desired motion at t = 0, shape (12,)."""
    z, w, dw = motion(np.array(0.0))
    q, qd, _ = model.coordinates(z, w, dw)
    return np.concatenate([q, qd])


def simulate(torque, model: Arm2 = Arm2(), motion: str | JointMotion = "reach", kp=0.0, kd=0.0, *,
             penalty: Penalty = Penalty(), dt: float = 1e-3, start=None, computed: bool = False,
             nominal: Arm2 | None = None, gains=None, integrator: str = "rk4", rtol: float = 1e-6,
             atol: float = 1e-9) -> ArmSimulation:
    """Forward dynamics over the motion's span driven by the feedforward ``torque`` plus PD
    feedback of each joint towards the desired motion, or by computed-torque control.

    torque: a function of times (s), shape (k,) -> joint torques (N m), shape (k, 2), or None for
    zero. kp (N m/rad), kd (N m s/rad): one number for both joints or one per joint (zero: open
    loop). ``computed``: computed-torque control instead of PD, the model's inverse dynamics at the
    current state for the accelerations z''_d + kp e + kd e' (kp in 1/s^2, kd in 1/s; the error
    obeys e'' + kd e' + kp e = 0 but for the penalty formulation's small deviations), plus torque.
    ``start``: the initial state [q, q'], shape (12,) (default: on the motion at t = 0).
    ``model`` is the simulated body (the plant); ``nominal`` the model computed-torque control
    believes (default: the plant). ``gains``: instead of kp and kd, a full gain matrix K(t) (2, 4)
    as a function of times (s), shape (k,) -> (k, 2, 4), applied to [z_d - z, z'_d - z']
    (N m/rad, N m s/rad), e.g. time-varying LQR (``arm2_lqr``).
    ``integrator``: 'rk4' (compiled, fixed step ``dt`` in s, torques and references on its
    half-step grid) or one of scipy's adaptive methods (``fdbench.integrate.SCIPY_METHODS``) with
    the relative and absolute tolerances ``rtol`` and ``atol``, stopped like the forearm's
    (``fdbench.integrate.solve_adaptive``)."""
    check_integrator(integrator)
    if integrator != "rk4":
        check_tolerances(rtol, atol)
    motion = as_joint_motion(motion)
    began = time.perf_counter()
    y0 = initial_state(model, motion) if start is None else np.array(start, dtype=float)
    if y0.shape != (12,) or not np.all(np.isfinite(y0)):
        raise ValueError(f"the initial state must be 12 finite numbers [q, q'], got {y0}")
    law = _law(model, penalty, kp, kd, computed, nominal, gains)
    if integrator == "rk4":
        result = _simulate_rk4(torque, motion, law, y0, dt)
    else:
        result = _simulate_adaptive(torque, motion, law, y0, integrator, rtol, atol)
    result.runtime_s = time.perf_counter() - began
    return result


@dataclass(frozen=True)
class ArmFeedback:
    """The arm's feedback law as ``arm2_kernels.rk4_pd`` applies it: gains kp, kd of shape (2,);
    ``mode`` 0 PD, 1 computed torque, 2 the gain matrix ``gains`` (a function of times (s), shape
    (k,) -> (k, 2, 4)); the kernel constants of the simulated arm (``consts``) and of the model
    computed-torque control believes (``nominal``), each shape (12,)."""

    kp: np.ndarray
    kd: np.ndarray
    mode: int
    gains: object
    consts: np.ndarray
    nominal: np.ndarray

    def gain_matrices(self, t: np.ndarray) -> np.ndarray:
        """K at times t (s), shape (k, 2, 4), or zeros of shape (1, 2, 4) when the law has none."""
        return np.zeros((1, 2, 4)) if self.gains is None else np.ascontiguousarray(self.gains(t), dtype=float)


def _law(model: Arm2, penalty: Penalty, kp=0.0, kd=0.0, computed: bool = False, nominal: Arm2 | None = None,
         gains=None) -> ArmFeedback:
    """The feedback law of ``simulate``'s arguments."""
    from . import arm2_kernels as kernels

    consts = kernels.kernel_constants(model, penalty)
    believed = consts if nominal is None or nominal == model else kernels.kernel_constants(nominal, penalty)
    kp, kd = (np.broadcast_to(np.asarray(g, dtype=float), (2,)).copy() for g in (kp, kd))
    return ArmFeedback(kp, kd, 2 if gains is not None else 1 if computed else 0, gains, consts, believed)


def _simulate_rk4(torque, motion: JointMotion, law: ArmFeedback, y0: np.ndarray, dt: float) -> ArmSimulation:
    """The compiled RK4 (``arm2_kernels.rk4_pd``) with steps of about dt (s)."""
    from . import arm2_kernels as kernels

    n = steps(dt, motion.duration)
    half = np.linspace(0.0, motion.duration, 2 * n + 1)
    ref, ref_w, ref_a = motion(half)
    tau = np.zeros((2 * n + 1, 2)) if torque is None else np.array(torque(half), dtype=float).reshape(2 * n + 1, 2)
    states, qdd, applied = np.full((n + 1, 12), np.nan), np.full((n + 1, 6), np.nan), np.full((n + 1, 2), np.nan)
    ref, ref_w, ref_a = (np.ascontiguousarray(r, dtype=float) for r in (ref, ref_w, ref_a))
    code, done, max_viol = kernels.rk4_pd(y0, motion.duration / n, n, tau, ref, ref_w, ref_a, law.kp, law.kd, law.mode,
                                          law.gain_matrices(half), law.consts, law.nominal, states, qdd, applied)
    grid = np.linspace(0.0, motion.duration, n + 1)
    y, tau_s = _on_samples(grid, states, qdd, applied, done, motion.samples)
    status = [Status.SUCCESS, Status.NONFINITE, Status.SINGULAR, Status.CONSTRAINT][code]
    return ArmSimulation(motion.samples, y[:, :6], y[:, 6:], tau_s, done * motion.duration / n, status, float(max_viol))


def _rates(torque, motion: JointMotion, law: ArmFeedback, t: np.ndarray, states: np.ndarray):
    """State derivatives (shape (k, 12)) and applied joint torques (N m, shape (k, 2)) of the
    states (shape (k, 12)) at times t (s, shape (k,)) under the feedback law."""
    from . import arm2_kernels as kernels

    k = len(t)
    tau = np.zeros((k, 2)) if torque is None else np.array(torque(t), dtype=float).reshape(k, 2)
    ref, ref_w, ref_a = (np.ascontiguousarray(r, dtype=float).reshape(k, 2) for r in motion(t))
    out, applied = np.empty((k, 12)), np.empty((k, 2))
    kernels.derivatives(np.ascontiguousarray(states, dtype=float), tau, ref, ref_w, ref_a, law.kp, law.kd, law.mode,
                        law.gain_matrices(t), law.consts, law.nominal, out, applied)
    return out, applied


def _simulate_adaptive(torque, motion: JointMotion, law: ArmFeedback, y0: np.ndarray, integrator: str, rtol: float,
                       atol: float) -> ArmSimulation:
    """One of scipy's adaptive methods (``fdbench.integrate.solve_adaptive``): stops where the
    state or the applied torques become non-finite, the shoulder or the forearm reaches +-90 deg,
    the constraint violation exceeds its tolerance, or the solver fails."""
    from . import arm2_kernels as kernels

    tol, L01, L12, viol_tol = law.consts[10], law.consts[3], law.consts[4], law.consts[11]

    def rhs(t, y):
        out, applied = _rates(torque, motion, law, np.array([t]), y[None])
        if not (np.all(np.isfinite(applied)) and np.all(np.isfinite(y))):
            raise StopIntegration(Status.NONFINITE, "")
        return out[0]

    def failure(y_old, y):
        """The status that a step from y_old to y ends the simulation with, or None."""
        if not np.all(np.isfinite(y)):
            return Status.NONFINITE
        if clear_of_singular(y, y_old) <= 0:  # near +-90 deg, or jumped over it
            return Status.SINGULAR
        if kernels.constraint_violation(y, L01, L12) > viol_tol:
            return Status.CONSTRAINT
        return None

    def clear_of_singular(y, y_old):  # positive while both angles stay on y_old's side of +-90 deg, clear of it
        return min(math.copysign(1.0, math.cos(a_old)) * math.cos(a) - tol
                   for a, a_old in ((y[4], y_old[4]), (y[4] + y[5], y_old[4] + y_old[5])))

    def clear_of_violation(y, y_old):
        return viol_tol - kernels.constraint_violation(y, L01, L12)

    system = AdaptiveSystem(rhs, failure, {Status.SINGULAR: clear_of_singular, Status.CONSTRAINT: clear_of_violation})
    found = solve_adaptive(system, y0, motion.duration, integrator, rtol, atol, motion.samples)
    ts, reached = motion.samples, found.reached
    applied = np.full((len(ts), 2), np.nan)
    with np.errstate(all="ignore"):
        applied[reached] = _rates(torque, motion, law, ts[reached], found.states[reached])[1]
    max_viol = np.max([kernels.constraint_violation(y, L01, L12) for y in found.states[reached]])
    return ArmSimulation(ts, found.states[:, :6], found.states[:, 6:], applied, found.t_end, found.status,
                         float(max_viol), integrator=integrator, detail=found.detail,
                         rhs_evaluations=found.evaluations)


def samples_on_grid(grid, ts) -> int:
    """The number of steps between samples when the samples ts (s) lie on the integrator grid
    (s), one every so many steps from the first step to the last; 0 when they do not."""
    every = (len(grid) - 1) // max(len(ts) - 1, 1)
    on_grid = every * (len(ts) - 1) == len(grid) - 1 and np.allclose(grid[::every], ts, rtol=0, atol=1e-12)
    return every if on_grid else 0


def _on_samples(grid, states, qdd, applied, done, ts):
    """States (n, 12) and applied torques (n, 2) on the motion's samples ts: taken from the grid
    where the samples lie on it, else interpolated (cubic Hermite for the states)."""
    every = samples_on_grid(grid, ts)
    if every:
        y, tau = states[::every].copy(), applied[::every].copy()
        beyond = np.arange(len(ts)) * every > done
        y[beyond], tau[beyond] = np.nan, np.nan
        return y, tau
    tau = np.stack([np.interp(ts, grid[: done + 1], applied[: done + 1, j], right=np.nan) for j in range(2)], -1)
    return _hermite(grid, states, qdd, done, ts), tau


def _hermite(grid, states, qdd, done, ts) -> np.ndarray:
    """States on the integrator grid -> times ts (cubic Hermite between steps), NaN beyond step
    ``done``; shape (len(ts), 12)."""
    out = np.full((len(ts), states.shape[1]), np.nan)
    inside = ts <= grid[done] + 1e-12
    if done == 0:
        out[inside] = states[0]
        return out
    i = np.clip(np.searchsorted(grid, ts[inside], side="right") - 1, 0, done - 1)
    h = grid[1] - grid[0]
    s = ((ts[inside] - grid[i]) / h)[:, None]
    rate = np.concatenate([states[:, 6:], qdd], axis=1)  # d/dt of the state
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    out[inside] = h00 * states[i] + h10 * h * rate[i] + h01 * states[i + 1] + h11 * h * rate[i + 1]
    return out


class Feedforward:
    """The inverse-dynamics joint torques of ``model`` on ``motion`` as a torque function
    t (s), shape (k,) -> (k, 2) N m, remembering the last grid it was evaluated on."""

    def __init__(self, model: Arm2 = Arm2(), motion: str | JointMotion = "reach"):
        self.model, self.motion = model, as_joint_motion(motion)
        self._last: tuple = (b"", None)

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        key = t.tobytes()
        if key != self._last[0]:
            torque = inverse_dynamics(t, self.model, self.motion).torque
            torque.flags.writeable = False
            self._last = (key, torque)
        return self._last[1]


def feedforward(model: Arm2 = Arm2(), motion: str | JointMotion = "reach") -> Feedforward:
    """The inverse-dynamics joint torques of ``model`` on ``motion`` as a torque function."""
    return Feedforward(model, motion)


def rmse_deg(result: ArmSimulation, desired: np.ndarray) -> tuple[float, np.ndarray]:
    """RMSE (deg) of the joint angles against ``desired`` (rad, shape (n, 2)) over the samples
    reached: over all joints and samples, and per joint (shape (2,))."""
    reached = result.reached
    if not reached.any():
        return float("nan"), np.full(2, np.nan)
    error = np.degrees(result.angles[reached] - desired[reached])
    return float(np.sqrt(np.mean(error**2))), np.sqrt(np.mean(error**2, axis=0))


def rmse_torque_nm(result: ArmSimulation, torque: np.ndarray) -> tuple[float, np.ndarray]:
    """RMSE (N m) of the applied joint torques against ``torque`` (shape (n, 2)), overall and per joint."""
    reached = result.reached & np.all(np.isfinite(result.torque), axis=1)
    if not reached.any():
        return float("nan"), np.full(2, np.nan)
    error = result.torque[reached] - torque[reached]
    return float(np.sqrt(np.mean(error**2))), np.sqrt(np.mean(error**2, axis=0))


def warm_up(adaptive: bool = False) -> None:
    """Load (or compile) the RK4 kernel, and with ``adaptive`` the adaptive integrators' kernel
    and scipy's integrators, so that later timings exclude it."""
    simulate(None, Arm2(), "reach", dt=0.1)
    if adaptive:
        import scipy.integrate  # noqa: F401
        import scipy.optimize  # noqa: F401

        y0 = initial_state(Arm2(), as_joint_motion("reach"))
        _rates(None, as_joint_motion("reach"), _law(Arm2(), Penalty()), np.zeros(1), y0[None])
