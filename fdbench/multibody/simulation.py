"""Inverse and forward dynamics of any model on a desired joint motion through the engine: compiled
RK4 or scipy's adaptive methods on the same compiled feedback laws (PD, computed torque, gains).

A motion has ``samples`` (s, (n,)), ``duration``, ``name``, ``joints`` and ``motion(t) -> (z, zd,
zdd)`` (rad, rad/s, rad/s^2; t.shape + (J,)); a torque function maps times (k,) to N m (k, J).
A simulation never raises on a physical failure: it stops and says why in ``status``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..integrate import (AdaptiveSystem, Status, StopIntegration, check_integrator, check_tolerances,
                         solve_adaptive, steps)
from .engine import Engine
from .layout import COMPUTED, GAINS, PD, VIOLATION
from .muscle import (ALPHA_OPT, F0, L_OPT, L_SLACK, MIN_ACTIVATION, PASSIVE_STRAIN, TENDON_STRAIN, WIDTH,
                     active_force_length, compliant_tendon, fiber_length, passive_force_length,
                     rigid_tendon_force, tendon_force_length_inverse)
from .muscle_paths import muscle_geometry

STATUS_OF_CODE = (Status.SUCCESS, Status.NONFINITE, Status.SINGULAR, Status.CONSTRAINT)  # the kernels' codes


@dataclass(frozen=True)
class JointInverse:
    """Histories on the time grid ``t`` (s): angles (rad), velocities (rad/s), accelerations
    (rad/s^2) and joint torques (N m), each of shape (n, J), the joints in ``joints``' order."""

    t: np.ndarray
    angles: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    torque: np.ndarray
    motion: str
    joints: tuple


def inverse_dynamics(t, engine: Engine, motion) -> JointInverse:
    """The joint torques of ``motion`` at times t (s) (None: the motion's samples), eq. 3."""
    t = motion.samples if t is None else np.asarray(t, dtype=float)
    z, zd, zdd = motion(t)
    return JointInverse(t, z, zd, zdd, engine.inverse_dynamics(z, zd, zdd, t), motion.name, engine.joints)


@dataclass
class Simulation:
    """A forward simulation on the motion's samples ``t`` (s): joint angles z (rad), rates zd
    (rad/s) and total applied joint torques (N m), shape (n, J); mixed-coordinate states
    (n, n_state); samples after ``t_end`` (s) are NaN."""

    t: np.ndarray
    z: np.ndarray
    zd: np.ndarray
    states: np.ndarray
    torque: np.ndarray
    t_end: float
    status: Status
    max_violation: float  # max |Phi_i| reached (at the RK4 steps, or at the samples), m^2 or m
    runtime_s: float = 0.0
    integrator: str = "rk4"
    detail: str = ""  # what made an adaptive integrator fail
    rhs_evaluations: int = 0  # adaptive integrators
    # with excitations (``simulate``'s): per muscle on the samples, shape (n, M), the activation,
    # the excitation (in [0, 1]) and the force along the path (N); None otherwise
    activation: np.ndarray | None = None
    excitation: np.ndarray | None = None
    muscle_force: np.ndarray | None = None

    @property
    def angles(self) -> np.ndarray:
        """Joint angles (rad), shape (n, J)."""
        return self.z

    @property
    def reached(self) -> np.ndarray:
        return np.isfinite(self.z[:, 0])

    @property
    def success(self) -> bool:
        return self.status is Status.SUCCESS


@dataclass(frozen=True)
class FeedbackLaw:
    """A feedback law as the engine's kernels apply it: per-joint gains kp, kd (J,), the mode (PD,
    COMPUTED, GAINS), the gain matrices ``gains`` (a function of times (s), shape (k,) ->
    (k, J, 2J), or None) and the believed model ``nominal`` (an Engine, or None: the plant)."""

    kp: np.ndarray
    kd: np.ndarray
    mode: int
    gains: object
    nominal: Engine | None

    def gain_matrices(self, t: np.ndarray, n_joints: int) -> np.ndarray | None:
        """K at times t (s), shape (k, J, 2J), or None without a gain matrix."""
        return None if self.gains is None else np.asarray(self.gains(t), dtype=float).reshape(len(t), n_joints,
                                                                                               2 * n_joints)


@dataclass(frozen=True)
class HalfSteps:
    """RK4's grid over ``motion``'s span, asked for with steps of about ``dt`` s: ``n`` steps of
    ``step`` s, the half-step times ``t`` = k step / 2, k = 0 .. 2 n (s, shape (2 n + 1,)), the motion
    on them (ref rad, refd rad/s, refdd rad/s^2, each (2 n + 1, J); all read-only), the steps' times
    ``t_steps`` (s, shape (n + 1,)) and ``every``, the steps between the motion's samples where they
    lie on the steps (else 0, see ``samples_on_grid``).
    Made once (``half_steps``) before a timed run, as the C loop prepares its references."""

    motion: object
    dt: float
    n: int
    step: float
    t: np.ndarray
    ref: np.ndarray
    refd: np.ndarray
    refdd: np.ndarray
    t_steps: np.ndarray
    every: int


def half_steps(motion, dt: float = 1e-3) -> HalfSteps:
    """The ``HalfSteps`` of ``motion`` with steps of about dt (s)."""
    n = steps(dt, motion.duration)
    t = np.linspace(0.0, motion.duration, 2 * n + 1)
    ref, refd, refdd = (np.array(r, dtype=float) for r in motion(t))  # copies of the motion's: made read-only
    t_steps = np.linspace(0.0, motion.duration, n + 1)
    for array in (t, ref, refd, refdd, t_steps):
        array.flags.writeable = False
    return HalfSteps(motion, float(dt), n, motion.duration / n, t, ref, refd, refdd, t_steps,
                     samples_on_grid(t_steps, motion.samples))


def on_half_steps(torque, grid: HalfSteps, n_joints: int):
    """The torque function ``torque`` (None: zero) with its values at the grid's half steps
    computed now, (2 n + 1, J) N m: called at ``grid.t`` it returns them, at other times it calls
    ``torque``. For a timed simulation whose drive, like the C loop's, is sampled beforehand."""
    values = _torques(torque, grid.t, n_joints)
    values.flags.writeable = False

    def sampled(t):
        return values if t is grid.t else _torques(torque, np.asarray(t, dtype=float), n_joints)

    sampled.__name__ = getattr(torque, "__name__", "function")
    return sampled


def simulate(torque, engine: Engine, motion, kp=0.0, kd=0.0, *, dt: float = 1e-3, start=None,
             computed: bool = False, nominal: Engine | None = None, gains=None, integrator: str = "rk4",
             rtol: float = 1e-6, atol: float = 1e-9, grid: HalfSteps | None = None, excitation=None) -> Simulation:
    """Forward dynamics of ``engine`` (the plant) over the motion's span on its samples, driven by
    ``torque`` (a torque function, or None) plus feedback: PD (kp N m/rad, kd N m s/rad, scalars or
    (J,)), with ``computed`` computed torque through ``nominal`` (None: the plant; kp 1/s^2, kd 1/s),
    or ``gains`` K(t): (k,) -> (k, J, 2J) on [z_d - z, z'_d - z']. ``start``: the state (n_state,)
    (default: on the motion at t = 0); with ``excitation`` it may hold the muscle states after it
    (n_state + n_muscle_states,), which then replace the start below. ``integrator``: 'rk4' (a fixed step of about ``dt`` s) or a
    scipy method (``integrate.SCIPY_METHODS``, tolerances ``rtol``, ``atol``). ``grid``: the motion's ``HalfSteps`` for this dt,
    made beforehand (default: made here; rk4 only). ``excitation``: the muscles' excitations, a function
    of times (s), shape (k,) -> (k, M) in [0, 1] (RK4 only, sampled on its half-step grid): the muscles'
    generalised forces add to the torques, each activation starts at its excitation at t = 0 and a
    compliant tendon's force at the fibre's static equilibrium; None: the muscles left out."""
    check_integrator(integrator)
    if excitation is not None and integrator != "rk4":
        raise ValueError(f"muscle excitations run on the compiled RK4 only, not --integrator {integrator}")
    if integrator != "rk4":
        check_tolerances(rtol, atol)
    if tuple(motion.joints) != engine.joints:
        raise ValueError(f"the motion's joints {tuple(motion.joints)} are not the model's {engine.joints}")
    began = time.perf_counter()
    y0 = start_state(engine, motion) if start is None else np.array(start, dtype=float)
    muscled = excitation is not None and y0.shape == (engine.n_state + engine.n_muscle_states,)
    if (y0.shape != (engine.n_state,) and not muscled) or not np.all(np.isfinite(y0)):
        raise ValueError(f"the initial state must be {engine.n_state} finite numbers [q, q'], got shape {y0.shape}")
    law = _law(engine, kp, kd, computed, nominal, gains)
    if grid is not None and (grid.motion is not motion or grid.dt != dt):
        raise ValueError(f"the half-step grid is of another motion or step (dt {grid.dt} s, not {dt} s)")
    if integrator == "rk4":
        result = _simulate_rk4(torque, engine, motion, law, y0, grid or half_steps(motion, dt), excitation)
    else:
        result = _simulate_adaptive(torque, engine, motion, law, y0, integrator, rtol, atol)
    result.runtime_s = time.perf_counter() - began
    return result


def start_state(engine: Engine, motion) -> np.ndarray:
    """The state (n_state,) [q, q'] on the constraint manifold at the motion's start (t = 0)."""
    z0, zd0, _ = motion(np.zeros(1))
    return engine.state_from_joints(z0[0], zd0[0])


def _law(engine: Engine, kp, kd, computed: bool, nominal: Engine | None, gains) -> FeedbackLaw:
    """The feedback law of ``simulate``'s arguments."""
    kp, kd = (_per_joint(g, engine.n_joints) for g in (kp, kd))
    engine.check_nominal(nominal)  # ValueError for other joints
    return FeedbackLaw(kp, kd, GAINS if gains is not None else COMPUTED if computed else PD, gains, nominal)


def _per_joint(gain, n_joints: int) -> np.ndarray:
    """A gain (one number, or one per joint) as a new array of shape (J,)."""
    gain = np.asarray(gain, dtype=float)
    if gain.ndim == 0:
        return np.full(n_joints, float(gain))
    return np.array(gain if gain.shape == (n_joints,) else np.broadcast_to(gain, (n_joints,)))


def _torques(torque, t: np.ndarray, n_joints: int) -> np.ndarray:
    """The feedforward torques (N m) at times t (s), shape (k, J)."""
    if torque is None:
        return np.zeros((len(t), n_joints))
    return np.array(torque(t), dtype=float).reshape(len(t), n_joints)


def _simulate_rk4(torque, engine: Engine, motion, law: FeedbackLaw, y0: np.ndarray, grid: HalfSteps,
                  excitation=None) -> Simulation:
    """The compiled RK4 (``Engine.simulate``) on the half-step grid ``grid``, with the muscles'
    ``excitation`` (a function of times) or without muscles."""
    n, half = grid.n, grid.t
    excited = None if excitation is None else _excitations(excitation, half, engine)
    if excited is not None and y0.shape[0] == engine.n_state:
        y0 = np.concatenate([y0, muscle_start(engine, y0, excited[0])])
    result = engine.simulate(y0, grid.step, n, _torques(torque, half, engine.n_joints), grid.ref, grid.refd,
                             grid.refdd, law.kp, law.kd, law.mode, law.gain_matrices(half, engine.n_joints),
                             law.nominal, excitation_half=excited)
    y, applied = _on_samples(grid.t_steps, grid.every, result.states, result.rates, result.applied, result.steps_done,
                             motion.samples)
    z, zd = engine.joints_from_state(y[:, :engine.n_state])
    done = Simulation(motion.samples, z, zd, y[:, :engine.n_state], applied, result.steps_done * motion.duration / n,
                      STATUS_OF_CODE[result.status], result.max_violation)
    if excited is not None:
        done.activation = y[:, engine.n_state:engine.n_state + engine.n_muscles]
        done.excitation = _excitations(excitation, motion.samples, engine)
        done.muscle_force = muscle_forces(engine, z, zd, y[:, engine.n_state:])
    return done


def _excitations(excitation, t: np.ndarray, engine: Engine) -> np.ndarray:
    """The muscles' excitations at times t (s), shape (k, M); ValueError outside [0, 1]."""
    values = np.array(excitation(t), dtype=float).reshape(len(t), engine.n_muscles)
    if not np.all((values >= 0.0) & (values <= 1.0)):
        raise ValueError("muscle excitations must lie in [0, 1]")
    return values


def muscle_start(engine: Engine, y0: np.ndarray, excitation: np.ndarray) -> np.ndarray:
    """The muscle states at the mechanical state y0 (n_state,) as an OpenSim user sets them: each
    activation at its excitation (M,), a compliant tendon's normalised force where the fibre is in
    static equilibrium (fibre velocity zero: f_T = cos(alpha) (a f_L + f_PE), by bisection, a at
    least ``muscle.MIN_ACTIVATION`` as in the tendon's dynamics)."""
    z, _ = engine.joints_from_state(y0)
    lengths, _ = muscle_geometry(engine.model, z)
    start = np.zeros(engine.n_muscle_states)
    start[:engine.n_muscles] = excitation
    for m, row in enumerate(engine.tendon_row):
        if row >= 0:
            start[row] = static_tendon_force(max(excitation[m], MIN_ACTIVATION), lengths[m], engine.muscle_params[m])
    return start


RK4_STABLE = 2.785  # RK4 is stable for dt |lambda| up to this on the negative real axis


def compliant_step_limits(engine: Engine, z0: np.ndarray, zd0: np.ndarray, excitation: np.ndarray) -> list:
    """(muscle, dt limit (s)) of each compliant tendon at the start (coordinates z0, rates zd0 (J,),
    excitations (M,) as ``muscle_start`` sets the muscles): RK4_STABLE / |d(df_T/dt)/df_T|, the
    step above which RK4 is unstable on the tendon's own dynamics there (a central difference)."""
    lengths, arms = muscle_geometry(engine.model, z0[None])
    lengthening = -arms[0] @ zd0
    limits = []
    for m, row in enumerate(engine.tendon_row):
        if row < 0:
            continue
        p = engine.muscle_params[m]
        force = static_tendon_force(max(excitation[m], MIN_ACTIVATION), lengths[0, m], p)
        h = 1e-6 * max(force, 1e-3)
        rate = [compliant_tendon(excitation[m], f, lengths[0, m], lengthening[m], p)[1] for f in (force + h, force - h)]
        slope = abs(rate[0] - rate[1]) / (2 * h)
        if math.isfinite(slope) and slope > 0:
            limits.append((engine.model.muscles[m].name, RK4_STABLE / slope))
    return limits


def static_tendon_force(activation: float, length: float, p: np.ndarray) -> float:
    """The normalised tendon force f_T in [0, 5] where f_T = cos(alpha) (a f_L + f_PE) of the
    fibre that the tendon's stretch leaves of ``length`` (m)."""
    def excess(force):
        l_m, cos_alpha = fiber_length(length - p[L_SLACK] * tendon_force_length_inverse(force, p[TENDON_STRAIN]),
                                      p[L_OPT], p[ALPHA_OPT])
        norm = l_m / p[L_OPT]
        return force - cos_alpha * (activation * active_force_length(norm, p[WIDTH])
                                    + passive_force_length(norm, p[PASSIVE_STRAIN]))
    low, high = 0.0, 5.0
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if excess(middle) < 0.0 else (low, middle)
    return 0.5 * (low + high)


def muscle_forces(engine: Engine, z: np.ndarray, zd: np.ndarray, muscle_states: np.ndarray) -> np.ndarray:
    """The muscles' forces along their paths (N), shape (n, M), at the coordinates z and rates zd
    (n, J) with the muscle states (n, n_muscle_states); NaN where a state is not finite."""
    out = np.full((len(z), engine.n_muscles), np.nan)
    finite = np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(muscle_states), axis=1)
    lengths, arms = muscle_geometry(engine.model, z[finite])
    lengthening = -np.einsum("nmj,nj->nm", arms, zd[finite])
    for i, k in enumerate(np.flatnonzero(finite)):
        for m, row in enumerate(engine.tendon_row):
            p = engine.muscle_params[m]
            out[k, m] = (p[F0] * muscle_states[k, row] if row >= 0 else
                         rigid_tendon_force(muscle_states[k, m], lengths[i, m], lengthening[i, m], p))
    return out


def _rates(torque, engine: Engine, motion, law: FeedbackLaw, t: np.ndarray, states: np.ndarray):
    """State derivatives (k, n_state) and applied joint torques (N m, (k, J)) of the states
    (k, n_state) at times t (s, shape (k,)) under the feedback law."""
    ref, refd, refdd = (np.asarray(r, dtype=float).reshape(len(t), engine.n_joints) for r in motion(t))
    return engine.rates(states, _torques(torque, t, engine.n_joints), ref, refd, refdd, law.kp, law.kd, law.mode,
                        law.gain_matrices(t, engine.n_joints), law.nominal, t)


def _simulate_adaptive(torque, engine: Engine, motion, law: FeedbackLaw, y0: np.ndarray, integrator: str,
                       rtol: float, atol: float) -> Simulation:
    """One of scipy's adaptive methods (``fdbench.integrate.solve_adaptive``): stops where the
    state, its derivative or the applied torques become non-finite, the constraint violation
    exceeds its tolerance, or the solver fails."""
    tolerance = engine.params[VIOLATION]

    def rhs(t, y):
        out, applied = _rates(torque, engine, motion, law, np.array([t]), y[None])
        if not (np.all(np.isfinite(applied)) and np.all(np.isfinite(out)) and np.all(np.isfinite(y))):
            raise StopIntegration(Status.NONFINITE, "")
        return out[0]

    def failure(y_old, y):
        """The status that a step from y_old to y ends the simulation with, or None."""
        if not np.all(np.isfinite(y)):
            return Status.NONFINITE
        if engine.constraint_violation(y) > tolerance:
            return Status.CONSTRAINT
        return None

    def clear_of_violation(y, y_old):
        return tolerance - engine.constraint_violation(y)

    system = AdaptiveSystem(rhs, failure, {Status.CONSTRAINT: clear_of_violation})
    found = solve_adaptive(system, y0, motion.duration, integrator, rtol, atol, motion.samples)
    ts, reached = motion.samples, found.reached
    applied = np.full((len(ts), engine.n_joints), np.nan)
    with np.errstate(all="ignore"):
        applied[reached] = _rates(torque, engine, motion, law, ts[reached], found.states[reached])[1]
    max_viol = max(engine.constraint_violation(y) for y in found.states[reached])
    z, zd = engine.joints_from_state(found.states)
    return Simulation(ts, z, zd, found.states, applied, found.t_end, found.status, float(max_viol),
                      integrator=integrator, detail=found.detail, rhs_evaluations=found.evaluations)


def samples_on_grid(grid, ts) -> int:
    """The number of steps between samples when the samples ts (s) lie on the integrator grid
    (s), one every so many steps from the first step to the last, to 1e-4 of a step (a recording's
    times are rounded: a .mot's 60 Hz samples to 1e-8 s); 0 when they do not."""
    every = (len(grid) - 1) // max(len(ts) - 1, 1)
    tolerance = 1e-4 * (grid[-1] - grid[0]) / max(len(grid) - 1, 1)
    on_grid = every * (len(ts) - 1) == len(grid) - 1 and np.allclose(grid[::every], ts, rtol=0, atol=tolerance)
    return every if on_grid else 0


def dt_on_samples(dt: float, ts) -> float:
    """The largest RK4 step (s) not above dt that puts the uniform samples ts (s) on its grid (their
    interval divided by a whole number of steps), so that eq. 18 and its exact gradient read the
    kernel's own states; dt itself where the samples are not uniform or already on its grid."""
    ts = np.asarray(ts, dtype=float)
    if len(ts) < 2:
        return float(dt)
    interval = (ts[-1] - ts[0]) / (len(ts) - 1)
    if not (interval > 0 and np.allclose(np.diff(ts), interval, rtol=0, atol=1e-4 * interval)):
        return float(dt)
    n = steps(dt, ts[-1] - ts[0])
    if samples_on_grid(np.linspace(ts[0], ts[-1], n + 1), ts):
        return float(dt)
    return float(interval / math.ceil(interval / dt - 1e-9))


def _on_samples(grid, every, states, rates, applied, done, ts):
    """States (n, n_state) and applied torques (n, J) on the motion's samples ts (s): taken from
    the grid (s) every ``every`` steps where the samples lie on it (``samples_on_grid``), else (0)
    interpolated (cubic Hermite for the states, linear for the torques)."""
    if every:
        y, tau = states[::every].copy(), applied[::every].copy()
        beyond = np.arange(len(ts)) * every > done
        y[beyond], tau[beyond] = np.nan, np.nan
        return y, tau
    tau = np.stack([np.interp(ts, grid[: done + 1], applied[: done + 1, j], right=np.nan)
                    for j in range(applied.shape[1])], -1)
    return _hermite(grid, states, rates, done, ts), tau


def _hermite(grid, states, rates, done, ts) -> np.ndarray:
    """States on the integrator grid (s) -> times ts (s) by cubic Hermite between steps (``rates``:
    the states' derivatives), NaN beyond step ``done``; shape (len(ts), n_state)."""
    out = np.full((len(ts), states.shape[1]), np.nan)
    inside = ts <= grid[done] + 1e-12
    if done == 0:
        out[inside] = states[0]
        return out
    i = np.clip(np.searchsorted(grid, ts[inside], side="right") - 1, 0, done - 1)
    h = grid[1] - grid[0]
    s = ((ts[inside] - grid[i]) / h)[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    out[inside] = h00 * states[i] + h10 * h * rates[i] + h01 * states[i + 1] + h11 * h * rates[i + 1]
    return out


class Feedforward:
    """The inverse-dynamics joint torques of ``engine`` on ``motion`` as a torque function
    t (s), shape (k,) -> (k, J) N m, remembering the last grid it was evaluated on."""

    def __init__(self, engine: Engine, motion):
        self.engine, self.motion = engine, motion
        self._last: tuple = (b"", None)

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        key = t.tobytes()
        if key != self._last[0]:
            torque = inverse_dynamics(t, self.engine, self.motion).torque
            torque.flags.writeable = False
            self._last = (key, torque)
        return self._last[1]


feedforward = Feedforward


def rmse_deg(result: Simulation, desired: np.ndarray) -> tuple[float, np.ndarray]:
    """RMSE (deg) of the joint angles against ``desired`` (rad, (n, J)) over the samples reached,
    overall and per joint (J,); every coordinate taken as an angle."""
    overall, _, per_joint = rmse_coordinates(result, desired, ("angle",) * result.z.shape[1])
    return overall, per_joint


def rmse_torque_nm(result: Simulation, torque: np.ndarray) -> tuple[float, np.ndarray]:
    """RMSE (N m) of the applied joint torques against ``torque`` ((n, J)), overall and per joint;
    every coordinate taken as an angle."""
    overall, _, per_joint = rmse_generalized_forces(result, torque, ("angle",) * result.torque.shape[1])
    return overall, per_joint


CM_PER_M = 100.0


def _rmse_over(error: np.ndarray, columns: np.ndarray) -> float:
    """RMSE of ``error`` (shape (m, J)) over its rows and the columns where ``columns`` (bool, (J,))
    is true; NaN where there are none."""
    if not columns.any() or not len(error):
        return float("nan")
    part = error if columns.all() else error[:, columns]
    return float(np.sqrt(np.mean(part**2)))


def _rmse_by_kind(values, reference, reached, translation, scale):
    """(RMSE over the angles, over the translations, per coordinate (J,)) of ``scale`` (a function of
    the error) over the rows ``reached``; NaN for a kind the model lacks or with no row reached."""
    if not reached.any():
        return float("nan"), float("nan"), np.full(values.shape[1], np.nan)
    error = scale(values[reached] - reference[reached])
    return _rmse_over(error, ~translation), _rmse_over(error, translation), np.sqrt(np.mean(error**2, axis=0))


def rmse_coordinates(result: Simulation, desired: np.ndarray, kinds) -> tuple[float, float, np.ndarray]:
    """The coordinates' RMSE against ``desired`` (rad or m, (n, J)) over the samples reached, ``kinds``
    per coordinate 'angle' or 'translation': (angles, deg; translations, cm; per coordinate, (J,))."""
    translation = np.array([kind == "translation" for kind in kinds])
    scale = (lambda e: np.where(translation, e * CM_PER_M, np.degrees(e))) if translation.any() else np.degrees
    return _rmse_by_kind(result.angles, desired, result.reached, translation, scale)


def rmse_generalized_forces(result: Simulation, reference: np.ndarray, kinds) -> tuple[float, float, np.ndarray]:
    """The applied generalized forces' RMSE against ``reference`` ((n, J)) over the samples reached:
    (angles' torques, N m; translations' forces, N; per coordinate, (J,))."""
    translation = np.array([kind == "translation" for kind in kinds])
    reached = result.reached & np.all(np.isfinite(result.torque), axis=1)
    return _rmse_by_kind(result.torque, reference, reached, translation, lambda e: e)


class _Still:
    """The joints held at zero for 0.1 s, sampled every 0.05 s (for ``warm_up``)."""

    name, duration = "still", 0.1

    def __init__(self, joints: tuple):
        self.joints, self.samples = joints, np.linspace(0.0, 0.1, 3)

    def __call__(self, t):
        zero = np.zeros(np.shape(t) + (len(self.joints),))
        return zero, zero, zero


WARM_CALLS = 10  # simulations of the warm-up per kind of model, each about 0.1 ms


def warm_up(adaptive: bool = False, engines=()) -> list:
    """Load (or compile) the engine's kernels on the forearm and each kind of ``engines``, the
    muscles' kernel for those with muscles (and with ``adaptive`` the adaptive right-hand side and
    scipy), so that timings exclude it; the engines warmed, one per kind."""
    from ..compile_guard import compiling

    with compiling():  # Ctrl-C while a kernel compiles ends the command at once
        return _warm_up(adaptive, engines)


def kind(engine: Engine) -> tuple:
    """The variant of the kernels an engine's model takes: which of paths, free joints and loads it has."""
    return engine.paths is None, engine.free is None, engine.loads is None


def _warm_up(adaptive: bool, others) -> list:
    for _, task in compile_tasks(others):  # the banded kernels, then the others
        task()
    warmed = {}
    for engine in (forearm_engine(), *others):
        warmed.setdefault(kind(engine), engine)
    if adaptive:
        import scipy.integrate  # noqa: F401
        import scipy.optimize  # noqa: F401

        for engine in warmed.values():
            J = engine.n_joints
            y0 = engine.state_from_joints(np.zeros(J), np.zeros(J))
            _rates(None, engine, _Still(engine.joints), _law(engine, 0.0, 0.0, False, None, None), np.zeros(1),
                   y0[None])
    return list(warmed.values())


def forearm_engine() -> Engine:
    """The library's forearm's engine (the pin-joint kernels every command warms)."""
    from ..models import find_model

    return Engine(find_model("forearm"))


def warm_simulation(engine: Engine) -> None:
    """Load (or compile) ``rk4`` and eq. 3 for the engine's kind of model: ``WARM_CALLS`` simulations
    of a still model (which also let Python specialise the calls' bytecode, after 8 runs)."""
    motion = _Still(engine.joints)
    J = engine.n_joints
    for _ in range(WARM_CALLS):
        simulate(None, engine, motion, dt=0.05, start=start_state(engine, motion))
    engine.inverse_torques(np.zeros(J), np.zeros(J), np.zeros(J), 0.0)


def warm_muscles(engine: Engine) -> None:
    """Load (or compile) the muscles' RK4 (``rk4_muscles``) for the engine's kind of model."""
    simulate(None, engine, _Still(engine.joints), dt=0.05,
             excitation=lambda t, m=engine.n_muscles: np.full((len(t), m), 0.1))


# seconds a kernel took to compile on one core of a 2-core machine, by (kernel, dense): RK4 without
# or with muscles, for pin joints only (banded) or with any of paths, free joints or loads (dense)
COMPILE_S = {("rk4", False): 27.0, ("rk4", True): 62.0, ("muscles", False): 45.0, ("muscles", True): 66.0}


def compile_tasks(engines) -> list[tuple[float, object]]:
    """What ``warm_up`` on ``engines`` compiles or loads (the forearm's kernels first), one task per
    kernel variant: RK4 (with eq. 3) per kind of model (``kind``), and the muscles' RK4 per kind of
    model with muscles, each as (its compile time in s, a function of no arguments that loads or
    compiles it). The tasks compile different kernels, so they can run in separate processes at
    once (``execution.compile_side_by_side``); numba's cache then holds every kernel for the
    processes that follow."""
    tasks = {}

    def add(job: str, engine: Engine, warm) -> None:
        if (job, kind(engine)) not in tasks:
            tasks[job, kind(engine)] = (COMPILE_S[job, not all(kind(engine))], lambda: warm(engine))

    for engine in (forearm_engine(), *engines):
        add("rk4", engine, warm_simulation)
        if engine.n_muscles:
            add("muscles", engine, warm_muscles)
    return list(tasks.values())
