"""Time integration of the penalty formulation: compiled fixed-step RK4 (default) or scipy's
adaptive ``solve_ivp`` methods. Both return a ``SimulationResult`` on the 1 ms sample grid.

A simulation never raises on a physical failure: it stops where it cannot go on and says why in
``status`` and ``message``; ``t_end`` is the time reached.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from enum import Enum
from functools import lru_cache
from typing import Callable

import numpy as np

from .model import Forearm, Penalty
from .motion import Motion, as_motion

TorqueFunction = Callable[[np.ndarray], np.ndarray]
"""An open-loop elbow torque history: times (s), shape (n,) -> torque (N m), shape (n,)."""

SCIPY_METHODS = {"rk45": "RK45", "dop853": "DOP853", "lsoda": "LSODA", "radau": "Radau", "bdf": "BDF"}
INTEGRATORS = ("rk4",) + tuple(SCIPY_METHODS)
MAX_DT = 0.1  # s
MIN_DT = 1e-6  # s: a million steps per simulation
PENALTY_RANGES = {"alpha": (1.0, 1e15), "xi": (0.0, 1e6), "omega": (1e-6, 1e6)}  # sensible, and no overflow
MIN_RTOL = 100 * np.finfo(float).eps  # scipy's own floor for rtol
MIN_ATOL, MAX_ATOL = 1e-30, 1.0  # beyond these the step size underflows (LSODA) or nothing is checked
MAX_RHS_EVALUATIONS = 100_000  # an adaptive integrator that needs more has met a stiff or broken problem


class Status(str, Enum):
    """How a simulation ended; the value is the message for the user."""

    SUCCESS = "reached the end of the motion"
    NONFINITE = "the state or the applied torque became non-finite: the model was driven unstable"
    SINGULAR = "theta reached +-pi/2, where the mixed coordinate theta is undefined (singular leading matrix)"
    CONSTRAINT = "the constraint violation exceeded its tolerance; try a larger --alpha (or a smaller --dt with rk4)"
    SOLVER = "the integrator failed"

    @property
    def code(self) -> str:
        return self.name.lower()



@dataclass
class SimulationResult:
    """A forward simulation on the desired motion's samples (eq. 5: every 1 ms, 1001 of them).
    Histories have shape (n,) or (n, 3); samples after ``t_end`` are NaN."""

    t: np.ndarray  # s
    q: np.ndarray  # [x2 (m), y2 (m), theta (rad)]
    qd: np.ndarray  # [x2', y2' (m/s), theta' (rad/s)]
    torque: np.ndarray  # total applied elbow torque, N m
    t_end: float  # s
    status: Status
    max_violation: float  # max |Phi_i| reached, m^2 or m
    integrator: str
    runtime_s: float = 0.0
    detail: str = ""
    rhs_evaluations: int = 0
    qdd: np.ndarray | None = None  # [x2'', y2'' (m/s^2), theta'' (rad/s^2)] (None: not recorded)

    @property
    def theta(self) -> np.ndarray:
        return self.q[:, 2]

    @property
    def reached(self) -> np.ndarray:
        """Boolean mask of the samples reached, shape (n,)."""
        return np.isfinite(self.q[:, 2])

    @property
    def message(self) -> str:
        text = self.status.value
        if self.status is not Status.SUCCESS:
            text += f" (stopped at t = {self.t_end:.4g} s)"
        return text + (f": {self.detail}" if self.detail else "")

    @property
    def success(self) -> bool:
        return self.status is Status.SUCCESS


@dataclass(frozen=True)
class Settings:
    """How to simulate: the simulated body (``model``, the plant), penalty parameters, the desired
    motion (``kinematics``: a Motion, or 'paper' / 'exact' for eq. 5), the integrator, and the
    ``nominal`` model that inverse dynamics and model-based controllers believe (default: the
    plant itself)."""

    model: Forearm = Forearm()
    penalty: Penalty = Penalty()
    kinematics: str | Motion = "paper"
    integrator: str = "rk4"
    dt: float = 1e-3  # s, RK4 step
    rtol: float = 1e-6  # solve_ivp only
    atol: float = 1e-9  # solve_ivp only
    nominal: Forearm | None = None

    @property
    def motion(self) -> Motion:
        return as_motion(self.kinematics)

    @property
    def nominal_model(self) -> Forearm:
        return self.model if self.nominal is None else self.nominal

    def __post_init__(self):
        as_motion(self.kinematics)
        check_integrator(self.integrator)
        if not (MIN_DT <= self.dt <= MAX_DT):
            raise ValueError(f"dt must be in [{MIN_DT:g}, {MAX_DT:g}] s, got {self.dt}")
        check_tolerances(self.rtol, self.atol)
        for name, (low, high) in PENALTY_RANGES.items():
            value = getattr(self.penalty, name)
            if not (math.isfinite(value) and low <= value <= high):
                raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {value}")


@dataclass(frozen=True)
class FeedbackLaw:
    """The feedback every controller is made of, added to the feedforward torque tau_ff(t):

        applied torque = tau_ff(t) + kp(t) (theta_d - theta) + kd(t) (theta'_d - theta') + gravity cos(theta)

    kp (N m/rad) and kd (N m s/rad) are constants or functions of time (s), shape (n,) -> (n,);
    gravity (N m) is a constant. Zero gains and gravity: open loop."""

    kp: float | TorqueFunction = 0.0
    kd: float | TorqueFunction = 0.0
    gravity: float = 0.0

    def gains(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """kp, kd at times t (s), each shape (n,), or shape (1,) where the gain is a constant."""
        return _gain_on(self.kp, t), _gain_on(self.kd, t)

    @property
    def closed_loop(self) -> bool:
        return callable(self.kp) or callable(self.kd) or self.kp != 0 or self.kd != 0 or self.gravity != 0


def _gain_on(gain, t) -> np.ndarray:
    if callable(gain):
        return np.array(gain(t), dtype=float).reshape(np.shape(t))
    return np.full(1, float(gain))


def check_tolerances(rtol: float, atol: float) -> None:
    """ValueError (one line) for a relative or absolute tolerance of the adaptive integrators out of range."""
    if not (math.isfinite(rtol) and MIN_RTOL <= rtol < 1):
        raise ValueError(f"rtol must be in [{MIN_RTOL:.2g}, 1), got {rtol}")
    if not (math.isfinite(atol) and MIN_ATOL <= atol <= MAX_ATOL):
        raise ValueError(f"atol must be in [{MIN_ATOL:g}, {MAX_ATOL:g}], got {atol}")


def check_integrator(name: str) -> str:
    if name not in INTEGRATORS:
        from .registry import unknown_name_message

        raise ValueError(unknown_name_message("integrator", name, list(INTEGRATORS)))
    return name


@lru_cache(maxsize=16)
def constants(settings: Settings) -> np.ndarray:
    """The kernels' constants for these settings (cached), shape (8,)."""
    from . import dynamics

    return dynamics.kernel_constants(settings.model, settings.penalty)


@lru_cache(maxsize=16)
def initial_state(kinematics: str | Motion, model: Forearm) -> np.ndarray:
    """[q, q'] on the desired motion at t = 0, shape (6,)."""
    theta, w, dw = as_motion(kinematics)(0.0)
    q, qd, _ = model.coordinates(theta, w, dw)
    state = np.concatenate([q, qd])
    state.flags.writeable = False
    return state


def simulate(torque: TorqueFunction, settings: Settings = Settings(), kp: float = 0.0, kd: float = 0.0, *,
             law: FeedbackLaw | None = None, start: np.ndarray | None = None) -> SimulationResult:
    """Forward dynamics over the desired motion's span driven by ``torque`` plus PD feedback on theta with gains
    kp (N m/rad) and kd (N m s/rad) towards the desired motion (zero gains: open loop), or plus
    the feedback ``law`` of a controller (which then replaces kp and kd).

    ``start``: the initial state [x2, y2, theta, x2', y2', theta'], shape (6,) (default: on the
    desired motion at t = 0); it should satisfy the constraints (``Forearm.coordinates``)."""
    law = FeedbackLaw(kp, kd) if law is None else law
    began = time.perf_counter()
    if settings.integrator == "rk4":
        result = _simulate_rk4(torque, settings, law, start)
    else:
        result = _simulate_scipy(torque, settings, law, start)
    result.runtime_s = time.perf_counter() - began
    return result


def steps(dt: float, duration: float = 1.0) -> int:
    """Number of RK4 steps over [0, duration] s for a requested step dt (s)."""
    return max(1, int(round(duration / dt)))


@lru_cache(maxsize=16)
def half_step_reference(n: int, kinematics: str | Motion):
    """The half-step grid t_k = k dt / 2 (s) of n steps over the motion's span and the desired
    theta (rad) and theta' (rad/s) on it; read-only arrays of shape (2 n + 1,)."""
    motion = as_motion(kinematics)
    half = np.linspace(0.0, motion.duration, 2 * n + 1)
    theta, w, _ = motion(half)
    for array in (half, theta, w):
        array.flags.writeable = False
    return half, theta, w


def _simulate_rk4(torque, settings: Settings, law: FeedbackLaw, start) -> SimulationResult:
    half, _, _ = half_step_reference(steps(settings.dt, settings.motion.duration), settings.kinematics)
    return simulate_rk4_on_grid(torque(half), settings, law=law, start=start)


def simulate_rk4_on_grid(tau: np.ndarray, settings: Settings, kp: float = 0.0, kd: float = 0.0, *,
                         law: FeedbackLaw | None = None, start: np.ndarray | None = None) -> SimulationResult:
    """RK4 with the open-loop torque tau (N m) given on the half-step grid of ``settings.dt``,
    shape (2 n + 1,) (see ``half_step_reference``); feedback and ``start`` as in ``simulate``."""
    from . import dynamics

    motion = settings.motion
    n = steps(settings.dt, motion.duration)
    dt = motion.duration / n
    half, ref_th, ref_w = half_step_reference(n, settings.kinematics)
    tau = np.array(tau, dtype=float)  # a writable copy: one compiled signature for every caller
    if tau.shape != ref_th.shape:
        raise ValueError(f"torque on the half-step grid must have shape {ref_th.shape}, got {tau.shape}")
    states = np.full((n + 1, 6), np.nan)
    qdd = np.full((n + 1, 3), np.nan)
    applied = np.full(n + 1, np.nan)
    consts = constants(settings)
    law = FeedbackLaw(kp, kd) if law is None else law
    kp_half, kd_half = law.gains(half)
    code, done, max_viol = dynamics.rk4_feedback(
        _start_state(settings, start), dt, n, tau, ref_th, ref_w,
        kp_half, kd_half, float(law.gravity), consts, states, qdd, applied,
    )
    status = [Status.SUCCESS, Status.NONFINITE, Status.SINGULAR, Status.CONSTRAINT][code]
    t_end = done * dt
    grid = np.linspace(0.0, motion.duration, n + 1)
    q, qd, qdd_s, applied_s = _resample(grid, states, qdd, applied, done, motion)
    return SimulationResult(motion.samples, q, qd, applied_s, t_end, status, float(max_viol), "rk4",
                            rhs_evaluations=4 * done + 1, qdd=qdd_s)


def _start_state(settings: Settings, start) -> np.ndarray:
    if start is None:
        return initial_state(settings.kinematics, settings.model)
    start = np.array(start, dtype=float)
    if start.shape != (6,) or not np.all(np.isfinite(start)):
        raise ValueError(f"the initial state must be 6 finite numbers [q, q'], got {start}")
    return start


def _resample(grid, states, qdd, applied, done, motion: Motion):
    """States on the integrator grid -> the motion's samples (cubic Hermite between steps; the
    accelerations and torque linear): q, q', q'', applied torque."""
    ts = motion.samples
    n = len(grid) - 1
    if motion.uniform and n % (len(ts) - 1) == 0:
        every = n // (len(ts) - 1)
        return states[::every, :3].copy(), states[::every, 3:].copy(), qdd[::every].copy(), applied[::every].copy()
    q = np.full((len(ts), 3), np.nan)
    qd = np.full((len(ts), 3), np.nan)
    acc = np.full((len(ts), 3), np.nan)
    tau = np.full(len(ts), np.nan)
    inside = ts <= grid[done] + 1e-12
    i = np.minimum(np.searchsorted(grid, ts[inside], side="right") - 1, max(done - 1, 0))
    h = grid[1] - grid[0]
    s = ((ts[inside] - grid[i]) / h)[:, None]
    j = np.minimum(i + 1, done)
    y0, y1 = states[i, :3], states[j, :3]
    v0, v1 = states[i, 3:], states[j, 3:]
    a0, a1 = qdd[i], qdd[j]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    q[inside] = h00 * y0 + h10 * h * v0 + h01 * y1 + h11 * h * v1
    qd[inside] = h00 * v0 + h10 * h * a0 + h01 * v1 + h11 * h * a1
    tau[inside] = (1 - s[:, 0]) * applied[i] + s[:, 0] * applied[j]
    acc[inside] = (1 - s) * a0 + s * a1
    return q, qd, acc, tau


def _simulate_scipy(torque, settings: Settings, law: FeedbackLaw, start) -> SimulationResult:
    """One of scipy's adaptive methods (``solve_adaptive``) on the forearm: stops where the state
    or the applied torque becomes non-finite, theta reaches +-pi/2, the constraint violation
    exceeds its tolerance, the solver fails, or it needs more than MAX_RHS_EVALUATIONS right-hand
    side evaluations."""
    from . import dynamics

    consts = constants(settings)
    accel, violation = dynamics.accelerations, dynamics.constraint_violation
    motion = settings.motion
    closed_loop = law.closed_loop

    def applied_torque(t, th, w):
        total = float(torque(np.array([t]))[0])
        if closed_loop:
            ref_th, ref_w, _ = motion(t)
            kp, kd = law.gains(np.array([t]))
            total += float(kp[0]) * (float(ref_th) - th) + float(kd[0]) * (float(ref_w) - w)
            if law.gravity != 0:
                total += law.gravity * math.cos(th)
        return total

    def rhs(t, y):
        tau = applied_torque(t, y[2], y[5])
        if not (math.isfinite(tau) and np.all(np.isfinite(y))):
            raise StopIntegration(Status.NONFINITE, "")
        ax, ay, ath, _ = accel(y[0], y[1], y[2], y[3], y[4], y[5], tau, consts)
        return np.array([y[3], y[4], y[5], ax, ay, ath])

    def failure(y_old, y):
        """The status that a step from y_old to y ends the simulation with, or None."""
        if not np.all(np.isfinite(y)):
            return Status.NONFINITE
        if abs(math.cos(y[2])) < consts[6]:
            return Status.SINGULAR
        if violation(y[0], y[1], y[2], consts[1]) > consts[7]:
            return Status.CONSTRAINT
        if math.cos(y[2]) * math.cos(y_old[2]) <= 0:  # jumped over cos(theta) = 0
            return Status.SINGULAR
        return None

    def clear_of_singular(y, y_old):  # positive while theta is on y_old's side, clear of the tolerance
        return math.copysign(1.0, math.cos(y_old[2])) * math.cos(y[2]) - consts[6]

    def clear_of_violation(y, y_old):
        return consts[7] - violation(y[0], y[1], y[2], consts[1])

    y0 = np.array(_start_state(settings, start))
    system = AdaptiveSystem(rhs, failure, {Status.SINGULAR: clear_of_singular, Status.CONSTRAINT: clear_of_violation})
    found = solve_adaptive(system, y0, motion.duration, settings.integrator, settings.rtol, settings.atol,
                           motion.samples)
    ts, reached = motion.samples, found.reached
    q, qd, applied = np.full((len(ts), 3), np.nan), np.full((len(ts), 3), np.nan), np.full(len(ts), np.nan)
    q[reached], qd[reached] = found.states[reached, :3], found.states[reached, 3:]
    qdd = np.full((len(ts), 3), np.nan)
    for i in np.flatnonzero(reached):
        applied[i] = applied_torque(ts[i], q[i, 2], qd[i, 2])
        qdd[i] = accel(*q[i], *qd[i], applied[i], consts)[:3]
    viol = settings.model.constraints(q[reached])
    max_viol = float(np.max(np.abs(viol))) if viol.size else 0.0
    return SimulationResult(ts, q, qd, applied, found.t_end, found.status, max_viol, settings.integrator,
                            detail=found.detail, rhs_evaluations=found.evaluations, qdd=qdd)


@dataclass(frozen=True)
class AdaptiveSystem:
    """A model as ``solve_adaptive`` integrates it; states have shape (m,).

    rhs(t, y): the state derivative at time t (s); it may raise ``StopIntegration`` to end the integration
    with a status (e.g. a non-finite torque). failure(y_old, y): the status that an accepted step
    from y_old to y ends the simulation with, or None. margins[status](y, y_old): positive while
    the state y, on a step begun at y_old, is clear of that failure, zero or negative once it is
    not: where within the failing step the failure began (a root of the step's interpolant)."""

    rhs: Callable[[float, np.ndarray], np.ndarray]
    failure: Callable[[np.ndarray, np.ndarray], "Status | None"]
    margins: dict


@dataclass
class AdaptiveSolution:
    """The outcome of ``solve_adaptive``: the states on the samples, shape (n, m), NaN where not
    ``reached`` (a boolean mask, shape (n,)); how and when (s) it ended; right-hand side
    evaluations."""

    states: np.ndarray
    reached: np.ndarray
    status: Status
    detail: str
    t_end: float
    evaluations: int


def solve_adaptive(system: AdaptiveSystem, y0: np.ndarray, duration: float, integrator: str, rtol: float,
                   atol: float, samples: np.ndarray) -> AdaptiveSolution:
    """Integrate ``system`` from y0 (shape (m,)) at t = 0 to ``duration`` (s) with one of scipy's
    adaptive methods, stepped here so that a failure keeps the steps accepted before it: the
    right-hand side stopping it, a state failing (cut at the failure's start within the step), a
    solver failure, or more than MAX_RHS_EVALUATIONS right-hand side evaluations. The dense output
    is read at the ``samples`` (s, shape (n,)) reached."""
    import scipy.integrate

    evaluations = [0]

    def rhs(t, y):
        evaluations[0] += 1
        if evaluations[0] > MAX_RHS_EVALUATIONS:
            raise StopIntegration(Status.SOLVER, f"more than {MAX_RHS_EVALUATIONS} right-hand side evaluations "
                                       "(a stiff problem: try rk4, radau or bdf)")
        return system.rhs(t, y)

    steps_t, pieces = [0.0], []
    status, detail, t_end = Status.SUCCESS, "", duration
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")  # the status reports what went wrong, once
        solver, t_old = None, 0.0
        while solver is None or solver.status == "running":
            try:
                if solver is None:  # the constructor evaluates the right-hand side too
                    solver = getattr(scipy.integrate, SCIPY_METHODS[integrator])(
                        rhs, 0.0, y0, duration, rtol=rtol, atol=atol)
                t_old, y_old = solver.t, solver.y.copy()
                message = solver.step()
            except StopIntegration as stop:
                status, detail, t_end = stop.status, stop.detail, t_old
                break
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:  # a solver breaking down
                status, detail, t_end = Status.SOLVER, str(exc), t_old
                break
            if solver.status == "failed":
                status, detail, t_end = Status.SOLVER, str(message), t_old
                break
            piece = solver.dense_output()
            ended = system.failure(y_old, solver.y)
            if ended is not None:
                status, t_end = ended, _crossing(piece, system.margins.get(ended), t_old, solver.t)
                if t_end > t_old:
                    steps_t.append(t_end)
                    pieces.append(piece)
                break
            steps_t.append(solver.t)
            pieces.append(piece)
    states = np.full((len(samples), len(y0)), np.nan)
    reached = samples <= steps_t[-1] + 1e-12
    reached[0] = True
    if pieces and steps_t[-1] > steps_t[0]:
        keep = np.flatnonzero(np.diff(steps_t) > 0)  # a step of zero length adds nothing
        solution = scipy.integrate.OdeSolution([steps_t[0]] + [steps_t[k + 1] for k in keep], [pieces[k] for k in keep])
        states[reached] = solution(np.minimum(samples[reached], steps_t[-1])).T
    else:
        states[reached] = y0
    return AdaptiveSolution(states, reached, status, detail, t_end, evaluations[0])


def _crossing(piece, margin, t_old, t_new) -> float:
    """Where within the step [t_old, t_new] (s) the failure began: the root of margin(y(t), y(t_old))
    on the step's interpolant y, or t_old without a margin or a sign change."""
    from scipy.optimize import brentq

    if margin is None:
        return t_old
    y_old = piece(t_old)

    def g(t):
        return margin(piece(t), y_old)

    try:
        if g(t_old) > 0 and g(t_new) <= 0:
            return float(brentq(g, t_old, t_new, xtol=1e-12))
    except (ValueError, ArithmeticError):
        pass
    return t_old


class StopIntegration(Exception):
    """Raised in the right-hand side to end an adaptive integration with a status."""

    def __init__(self, status: Status, detail: str):
        super().__init__(detail)
        self.status, self.detail = status, detail


def warm_up() -> None:
    """Load (or compile) the RK4 kernels so that later timings exclude compilation."""
    simulate(lambda t: np.zeros_like(t), Settings(dt=0.1))
