"""The compiled per-muscle parts of computed muscle control (``fdbench.multibody.cmc``): each
muscle's force per unit activation at a state, its force after a window under a constant
excitation (the engine's own activation and tendon dynamics, by the same RK4 steps, its path
moving with a constant acceleration), the forces reachable at the window's end, and the
excitation that gives a wanted force there. Units: m, m/s, m/s^2, N, s."""

from __future__ import annotations

import numpy as np

from ..jit import njit
from .muscle import (ALPHA_OPT, DAMPING, F0, L_OPT, L_SLACK, PASSIVE_STRAIN, SMOOTHING, TAU_ACT, TAU_DEACT,
                     TENDON_STRAIN, V_MAX, WIDTH, activation_derivative, active_force_length, compliant_tendon,
                     fiber_length, force_velocity, passive_force_length, rigid_tendon_force,
                     tendon_force_length_inverse)

FORCE_TOLERANCE = 1e-7  # of F0: the excitations' root-finding stops within this of the wanted force


@njit(error_model="numpy")
def muscle_gains(muscle_states, lengths, lengthening, params, tendon_row):
    """Each muscle's force along its path (N) per unit activation (``gain``) and at zero activation
    (``passive``), shape (M,) each, at muscle-tendon ``lengths`` (m) and ``lengthening`` speeds (m/s)
    (M,): F0 cos(alpha) (a f_L f_V + f_PE + d v), the fibre at the length the tendon leaves (a rigid
    tendon's slack length; a compliant tendon's at its current normalised force, ``muscle_states``
    (n_muscle_states,) at ``tendon_row``) and moving with the path (v = lengthening cos(alpha))."""
    M = lengths.shape[0]
    gain, passive = np.empty(M), np.empty(M)
    for m in range(M):
        p = params[m]
        tendon = p[L_SLACK]
        if tendon_row[m] >= 0:
            tendon = p[L_SLACK] * tendon_force_length_inverse(muscle_states[tendon_row[m]], p[TENDON_STRAIN])
        l_m, cos_alpha = fiber_length(lengths[m] - tendon, p[L_OPT], p[ALPHA_OPT])
        norm_length = l_m / p[L_OPT]
        velocity = lengthening[m] * cos_alpha / (p[V_MAX] * p[L_OPT])
        gain[m] = p[F0] * cos_alpha * active_force_length(norm_length, p[WIDTH]) * force_velocity(velocity)
        passive[m] = p[F0] * cos_alpha * (passive_force_length(norm_length, p[PASSIVE_STRAIN]) + p[DAMPING] * velocity)
    return gain, passive


@njit(error_model="numpy")
def force_after(excitation, activation, tendon_force, length, lengthening, speeding, step, n_steps, p, compliant):
    """A muscle's force along its path (N) after ``n_steps`` classical RK4 steps of ``step`` s under a
    constant ``excitation``, from ``activation`` (and a compliant tendon's normalised force
    ``tendon_force``), its muscle-tendon length moving from ``length`` (m) at ``lengthening`` (m/s)
    with the constant acceleration ``speeding`` (m/s^2): De Groote's activation dynamics and the
    compliant tendon's explicit form as the engine's kernels integrate them
    (``muscle.activation_derivative``, ``muscle.compliant_tendon``)."""
    a, f = activation, tendon_force
    ta, td, b = p[TAU_ACT], p[TAU_DEACT], p[SMOOTHING]
    for k in range(n_steps):
        s0, s1 = step * k, step * (k + 0.5)
        l0, v0 = length + (lengthening + 0.5 * speeding * s0) * s0, lengthening + speeding * s0
        l1, v1 = length + (lengthening + 0.5 * speeding * s1) * s1, lengthening + speeding * s1
        l2, v2 = length + (lengthening + 0.5 * speeding * (s0 + step)) * (s0 + step), v0 + speeding * step
        ka1 = activation_derivative(excitation, a, ta, td, b)
        ka2 = activation_derivative(excitation, a + 0.5 * step * ka1, ta, td, b)
        ka3 = activation_derivative(excitation, a + 0.5 * step * ka2, ta, td, b)
        ka4 = activation_derivative(excitation, a + step * ka3, ta, td, b)
        if compliant:
            kf1 = compliant_tendon(a, f, l0, v0, p)[1]
            kf2 = compliant_tendon(a + 0.5 * step * ka1, f + 0.5 * step * kf1, l1, v1, p)[1]
            kf3 = compliant_tendon(a + 0.5 * step * ka2, f + 0.5 * step * kf2, l1, v1, p)[1]
            kf4 = compliant_tendon(a + step * ka3, f + step * kf3, l2, v2, p)[1]
            f = f + step / 6.0 * (kf1 + 2.0 * kf2 + 2.0 * kf3 + kf4)
        a = a + step / 6.0 * (ka1 + 2.0 * ka2 + 2.0 * ka3 + ka4)
    if compliant:
        return p[F0] * f
    end = step * n_steps
    return rigid_tendon_force(a, length + (lengthening + 0.5 * speeding * end) * end, lengthening + speeding * end, p)


@njit(error_model="numpy")
def forces_after(excitation, muscle_states, lengths, lengthening, speeding, step, n_steps, params, tendon_row):
    """Each muscle's force along its path (N, (M,)) after ``n_steps`` RK4 steps of ``step`` s under the
    constant ``excitation`` (the same for all), from the muscle states (n_muscle_states,), its path
    at ``lengths`` (m) moving at ``lengthening`` (m/s) with acceleration ``speeding`` (m/s^2), (M,)
    each (``force_after``): at 0 and 1, the range of forces a window can reach."""
    M = lengths.shape[0]
    out = np.empty(M)
    for m in range(M):
        row = tendon_row[m]
        out[m] = force_after(excitation, muscle_states[m], muscle_states[row] if row >= 0 else 0.0, lengths[m],
                             lengthening[m], speeding[m], step, n_steps, params[m], row >= 0)
    return out


@njit(error_model="numpy")
def excitations_for(target, guess, muscle_states, lengths, lengthening, speeding, step, n_steps, params, tendon_row):
    """The constant excitations u (M,) in [0, 1] under which each muscle's force along its path
    reaches ``target`` (N, (M,)) after ``n_steps`` RK4 steps of ``step`` s (``force_after``, from the
    muscle states (n_muscle_states,) at muscle-tendon ``lengths`` (m) moving at ``lengthening``
    (m/s) with acceleration ``speeding`` (m/s^2), (M,)): the force grows with u, so secant steps
    from ``guess`` (M,), kept inside the bracket the forces found so far leave (else its middle),
    find it within FORCE_TOLERANCE F0; 0 or 1 where the target is out of reach."""
    M = target.shape[0]
    out = np.empty(M)
    for m in range(M):
        p, row = params[m], tendon_row[m]
        compliant = row >= 0
        f0, a0 = (muscle_states[row] if compliant else 0.0), muscle_states[m]
        tolerance = FORCE_TOLERANCE * p[F0]
        low, high = 0.0, 1.0
        u = min(max(guess[m], 0.0), 1.0)
        r = force_after(u, a0, f0, lengths[m], lengthening[m], speeding[m], step, n_steps, p, compliant) - target[m]
        v, s = -1.0, 0.0  # no previous point yet
        for _ in range(60):
            if abs(r) <= tolerance or (r < 0.0 and u >= 1.0) or (r > 0.0 and u <= 0.0):
                break  # found, or out of reach at a bound
            if r < 0.0:
                low = u
            else:
                high = u
            if v < 0.0:
                nxt = u - 0.02 if r > 0.0 else u + 0.02
            else:
                nxt = u - r * (u - v) / (r - s) if r != s else -1.0
            if nxt >= high and high == 1.0 and u != 1.0 and v != 1.0:
                nxt = 1.0  # try the bound itself: the target may be out of reach
            elif nxt <= low and low == 0.0 and u != 0.0 and v != 0.0:
                nxt = 0.0
            elif not (low < nxt < high):
                nxt = 0.5 * (low + high)
            v, s = u, r
            u = nxt
            r = force_after(u, a0, f0, lengths[m], lengthening[m], speeding[m], step, n_steps, p, compliant) - target[m]
        out[m] = u
    return out
