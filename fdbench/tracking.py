"""Eq. 18 of the shooting problem (``fdbench.problem``), compiled: the tracking objective of a
simulation's states and the population of open-loop candidates that ``fdbench.population.Population``
spreads over threads. The simulations are the engine's (``fdbench.multibody.kernels.rk4_muscles``,
which is ``rk4`` without muscles)."""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.extending import overload

from .jit import njit
from .multibody.kernels import rk4_muscles
from .multibody.layout import AT_PARENT_X, COLUMN, FREE, KI, OFFSET, OK, PARENT, PD, Law, Muscles
from .population import DEGREES_PER_RADIAN, Population

from .multibody.simulation import CM_PER_M


@njit(nogil=True)
def tracking_objective(states, done, every, angles_ref, n_steps, penalty_weight, model):
    """Eq. 18 from a simulation's states (n_steps + 1, n_state), filled up to step ``done``: at the
    motion's samples (every ``every``-th step; desired coordinates angles_ref (rad, m for a free
    joint's x and y; shape (samples, J))) over the samples reached, the RMSE of the angles (deg)
    (the body angles' differences minus the offsets), plus, for a model with free joints, that of
    their translations (cm), units never pooled; plus penalty_weight times the fraction of the
    steps not reached. The squared errors are summed sample by sample, coordinate by coordinate in
    order; a non-finite RMSE counts as 0."""
    body_int, body_float = model.body_int, model.body_float
    n_b, n_p = body_int.shape[0], model.mass.shape[0]
    count = done // every + 1
    angles, translations, n_translations = 0.0, 0.0, 0
    for k in range(count):
        y = states[k * every]
        for b in range(n_b):
            p, col = body_int[b, PARENT], body_int[b, COLUMN]
            z = y[n_p + b] - (y[n_p + p] if p >= 0 else 0.0) - body_float[b, OFFSET]
            error = (z - angles_ref[k, col]) * DEGREES_PER_RADIAN
            angles += error * error
            if body_int[b, FREE] == 1:
                n_translations += 2
                ki = body_int[b, KI]
                for axis in range(2):
                    x = y[ki + axis] - body_float[b, AT_PARENT_X + axis]
                    error = (x - angles_ref[k, col + 1 + axis]) * CM_PER_M
                    translations += error * error
    rmse = math.sqrt(angles / (n_b * count))
    if n_translations > 0:
        rmse += math.sqrt(translations / n_translations)
    if not math.isfinite(rmse):
        rmse = 0.0
    return rmse + penalty_weight * (1.0 - done / n_steps)


def _candidate_muscles(muscles, candidate):
    """The muscles of one candidate: None without muscles, else a ``layout.Muscles`` with the
    candidate's excitations (rows, M)."""


@overload(_candidate_muscles)
def _candidate_muscles_typed(muscles, candidate):
    # chosen by type when compiling: a branch on ``muscles is None`` would compile both calls, and
    # RK4 without muscles once more for a model with muscles (about a minute on the gait model)
    if isinstance(muscles, types.NoneType):
        return lambda muscles, candidate: None
    return lambda muscles, candidate: Muscles(muscles.paths, muscles.params, muscles.tendon_row,
                                              muscles.excitation[candidate])


@njit(nogil=True)
def rk4_candidates(y0, dt, n_steps, tau, ref, refd, every, angles_ref, penalty_weight, model, paths, free, loads,
                   muscles, states, rates, applied, objective, candidate, stride, step, budget):
    """Open-loop RK4 (``rk4`` in PD mode with zero gains) and eq. 18 (``tracking_objective``) for
    candidates candidate, candidate + stride, ... of tau (N m, shape (lam, 2 n_steps + 1, J)), at
    most ``budget`` steps in all: the first candidate resumes at step ``step`` (its states up to
    there in the work buffers, from the call before), each chunk from the last state of the one
    before at the same grid row, so the numbers are those of one call. ref, refd: the half-step
    references (unused by an open loop but for the layout of its call); model, paths, free, loads:
    the engine's (``Engine.population_args``); muscles: None, or a ``layout.Muscles`` whose
    excitations are the candidates' (lam, 2 n_steps + 1, M), each candidate then run by
    ``rk4_muscles`` on its own (y0 and the states with the muscle states after [q, q']); states
    (n+1, n_state), rates (n+1, n_state), applied (n+1, J): this thread's work buffers, reused
    candidate after candidate; objective (lam,):
    filled for the candidates finished. Returns the (candidate, step) to resume at (a candidate past
    the last: all done). Runs without the GIL."""
    J = tau.shape[2]
    zero, no_gains = np.zeros(J), np.zeros((1, J, 2 * J))
    while candidate < tau.shape[0] and budget > 0:
        n = min(budget, n_steps - step)
        y = y0 if step == 0 else states[step].copy()
        law = Law(tau[candidate], ref, refd, ref, zero, zero, PD, no_gains)
        code, done, _ = rk4_muscles(y, dt, n, 2 * step, law, model, paths, free, loads, model, paths, loads,
                                    _candidate_muscles(muscles, candidate), states[step:step + n + 1],
                                    rates[step:step + n + 1], applied[step:step + n + 1])
        step, budget = step + done, budget - max(done, 1)  # steps run: a failing candidate costs few
        if code != OK or step == n_steps:
            objective[candidate] = tracking_objective(states, step, every, angles_ref, n_steps, penalty_weight,
                                                      model)
            candidate, step = candidate + stride, 0
    return candidate, step


def warm_up(engines) -> None:
    """Load (or compile) the population kernel (``rk4_candidates`` over threads) on each engine
    (one per kind of model: ``fdbench.multibody.simulation.warm_up`` returns them), so that later
    timings exclude it."""
    from .compile_guard import compiling

    with compiling():  # Ctrl-C while a kernel compiles ends the command at once
        for engine in engines:
            J = engine.n_joints
            y0, rows = engine.state_from_joints(np.zeros(J), np.zeros(J)), np.zeros((5, J))
            Population(rk4_candidates, 2, engine.population_widths)(
                2, engine.population_args(y0, 0.05, 2, np.zeros((2, 5, J)), rows, rows, 1, np.zeros((3, J)), 1.0))
