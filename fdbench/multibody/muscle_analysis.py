"""A model's muscles along a motion, as OpenSim's MuscleAnalysis reports them (``muscle_analysis``):
each muscle's path length and moment arms, its fibre length, pennation angle and normalised fibre
velocity, and its active fibre force at full activation and passive fibre force, per sample.

A rigid tendon keeps its slack length: the fibre lies along the path at l_MT - l_s with its height
l_opt sin(alpha_opt) kept (``muscle.fiber_length``), and its velocity is cos(alpha) times the path's
lengthening speed dl_MT/dt = -(moment arms . coordinate rates). A compliant tendon is stretched to
the fibre's static equilibrium at full activation (fibre velocity zero: f_T = cos(alpha) (f_L +
f_PE), as a simulation's start, ``simulation.muscle_start``), and the fibre's velocity is that
equilibrium's rate along the motion (quasi-static: d l_M/dt of the equilibrium fibre length, by
implicit differentiation), at which the active force is then evaluated.

Normalised fibre velocity v = v_M / (v_max l_opt) (-1: the fastest shortening). Forces along the
fibre (N): active F0 f_L f_V (activation 1), passive F0 (f_PE + d v) (elastic and damping, as
OpenSim's getPassiveFiberForce); along the path they are times cos(alpha).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .engine import Engine
from .muscle import (ALPHA_OPT, DAMPING, F0, L_OPT, L_SLACK, PASSIVE_STRAIN, TENDON_STRAIN, V_MAX, WIDTH,
                     active_force_length, active_force_length_derivative, fiber_length, force_velocity,
                     passive_force_length, passive_force_length_derivative,
                     tendon_force_length_derivative, tendon_force_length_inverse)
from .muscle_paths import muscle_geometry
from .simulation import static_tendon_force

QUANTITIES = ("length", "fiber_length", "pennation_angle", "fiber_velocity", "active_fiber_force",
              "passive_fiber_force")  # the (n, M) fields of MuscleAnalysis, in this order


class MuscleAnalysis(NamedTuple):
    """Per sample (n) and muscle (M): path length l_MT (m), fibre length (m), pennation angle (rad),
    normalised fibre velocity (1), active fibre force at full activation (N) and passive fibre force
    (N), each (n, M); moment arms -dl_MT/dq (n, M, J) (m per rad; m/m for a translation)."""

    length: np.ndarray
    fiber_length: np.ndarray
    pennation_angle: np.ndarray
    fiber_velocity: np.ndarray
    active_fiber_force: np.ndarray
    passive_fiber_force: np.ndarray
    moment_arm: np.ndarray


def muscle_analysis(engine: Engine, q, qd) -> MuscleAnalysis:
    """The muscles of the engine's model at the coordinates q and rates qd (rad, m; rad/s, m/s),
    shape (n, J)."""
    q, qd = np.atleast_2d(np.asarray(q, dtype=float)), np.atleast_2d(np.asarray(qd, dtype=float))
    lengths, arms = muscle_geometry(engine.model, q, engine.muscle_paths)
    lengthening = -np.einsum("nmj,nj->nm", arms, qd)  # dl_MT/dt (m/s)
    out = {name: np.full(lengths.shape, np.nan) for name in QUANTITIES[1:]}
    for m, p in enumerate(engine.muscle_params):
        for i in range(len(q)):
            fiber = (_compliant_fiber if engine.tendon_row[m] >= 0 else _rigid_fiber)(lengths[i, m], lengthening[i, m], p)
            for name, value in zip(QUANTITIES[1:], fiber):
                out[name][i, m] = value
    return MuscleAnalysis(lengths, moment_arm=arms, **out)


def _rigid_fiber(length: float, lengthening: float, p: np.ndarray) -> tuple:
    """(fibre length m, pennation rad, normalised velocity, active N, passive N) with a rigid tendon."""
    l_m, cos_alpha = fiber_length(length - p[L_SLACK], p[L_OPT], p[ALPHA_OPT])
    return _forces(l_m, cos_alpha, cos_alpha * lengthening, p)


def _compliant_fiber(length: float, lengthening: float, p: np.ndarray) -> tuple:
    """As ``_rigid_fiber`` with the tendon stretched to the fibre's static equilibrium at full
    activation; the velocity that equilibrium's rate: from T(u) = G(l_MT - l_s u) (u the normalised
    tendon length, G the fibre's normalised force along the path at its along-path length x),
    dx/dt = dl_MT/dt T'(u) / (T'(u) + l_s G'(x))."""
    if not math.isfinite(length):
        return (math.nan,) * 5
    u = tendon_force_length_inverse(static_tendon_force(1.0, length, p), p[TENDON_STRAIN])
    along = length - p[L_SLACK] * u
    l_m, cos_alpha = fiber_length(along, p[L_OPT], p[ALPHA_OPT])
    norm = l_m / p[L_OPT]
    force = active_force_length(norm, p[WIDTH]) + passive_force_length(norm, p[PASSIVE_STRAIN])
    slope = (active_force_length_derivative(norm, p[WIDTH])
             + passive_force_length_derivative(norm, p[PASSIVE_STRAIN])) / p[L_OPT]  # dF/dl_M (1/m)
    height = p[L_OPT] * math.sin(p[ALPHA_OPT])
    g_slope = height * height / l_m ** 3 * force + cos_alpha * cos_alpha * slope  # dG/dx (1/m)
    t_slope = tendon_force_length_derivative(u, p[TENDON_STRAIN])
    along_rate = lengthening * t_slope / (t_slope + p[L_SLACK] * g_slope)
    return _forces(l_m, cos_alpha, cos_alpha * along_rate, p)


def _forces(l_m: float, cos_alpha: float, fiber_rate: float, p: np.ndarray) -> tuple:
    """(fibre length m, pennation rad, normalised velocity, active N, passive N) of a fibre l_m m
    long at cos(alpha), lengthening at fiber_rate m/s."""
    norm, velocity = l_m / p[L_OPT], fiber_rate / (p[V_MAX] * p[L_OPT])
    active = p[F0] * active_force_length(norm, p[WIDTH]) * force_velocity(velocity)
    passive = p[F0] * (passive_force_length(norm, p[PASSIVE_STRAIN]) + p[DAMPING] * velocity)
    return l_m, math.acos(min(cos_alpha, 1.0)), velocity, active, passive  # min: NaN stays NaN
