"""What every forward simulation shares: the integrators (the engine's compiled fixed-step RK4, the
default, or scipy's adaptive ``solve_ivp`` methods, stepped by ``solve_adaptive``), their settings'
checks, and the ``Status`` a simulation ends with.

A simulation never raises on a physical failure: it stops where it cannot go on and says why in
its status; ``t_end`` is the time reached.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from enum import Enum
from typing import Callable

import numpy as np

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
    SINGULAR = "the leading matrix became singular: an angle coordinate is undefined there"
    CONSTRAINT = "the constraint violation exceeded its tolerance; try a larger --alpha (or a smaller --dt with rk4)"
    SOLVER = "the integrator failed"

    @property
    def code(self) -> str:
        return self.name.lower()



def check_tolerances(rtol: float, atol: float) -> None:
    """ValueError (one line) for a relative or absolute tolerance of the adaptive integrators out of range."""
    if not (math.isfinite(rtol) and MIN_RTOL <= rtol < 1):
        raise ValueError(f"rtol must be in [100 eps, 1) = [{float(MIN_RTOL)!r}, 1), got {rtol}")
    if not (math.isfinite(atol) and MIN_ATOL <= atol <= MAX_ATOL):
        raise ValueError(f"atol must be in [{MIN_ATOL:g}, {MAX_ATOL:g}], got {atol}")


def check_integrator(name: str) -> str:
    if name not in INTEGRATORS:
        from .registry import unknown_name_message

        raise ValueError(unknown_name_message("integrator", name, list(INTEGRATORS)))
    return name


def check_settings(integrator: str, dt: float, rtol: float, atol: float, alpha: float, xi: float, omega: float) -> None:
    """ValueError (one line) for an integrator, RK4 step (s), tolerances or penalty parameters out of range."""
    check_integrator(integrator)
    if not (MIN_DT <= dt <= MAX_DT):
        raise ValueError(f"dt must be in [{MIN_DT:g}, {MAX_DT:g}] s, got {dt}")
    check_tolerances(rtol, atol)
    for name, value in (("alpha", alpha), ("xi", xi), ("omega", omega)):
        low, high = PENALTY_RANGES[name]
        if not (math.isfinite(value) and low <= value <= high):
            raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {value}")


def steps(dt: float, duration: float = 1.0) -> int:
    """Number of RK4 steps over [0, duration] s for a requested step dt (s)."""
    return max(1, int(round(duration / dt)))


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
