"""Forward dynamics by the penalty formulation (eq. 12), as compiled kernels.

The leading matrix M + alpha Phi_q^T Phi_q is solved in closed form: with point 1 at the origin,
elimination of the theta row leaves a 2x2 system in (x2'', y2'') whose determinant
a^2 + 4 alpha a (x2^2 + y2^2) never vanishes, so the only singularity is cos(theta) = 0.

The kernels keep strict IEEE arithmetic (no fastmath): a run gives the same numbers on every
x86-64 machine, which stored results and seeds rely on. Constants travel as one float64 array ``consts`` (see ``kernel_constants``) so that a kernel
compiles once for every model and penalty setting.

Speed: the RK4 driver inlines its right-hand side (``inline="always"``; a call of a compiled
function that takes arrays costs reference counting at every call) and computes sin and cos of
theta once per state, together (one ``sincos``), carrying them from the end of a step to the
start of the next. The operations on every number are those of the plain formulas, so the
results do not move by a bit.
"""

from __future__ import annotations

import math

import numpy as np
from .jit import njit
from .model import Forearm, Penalty

# status codes shared by the kernels and integrate.py
OK, NONFINITE, SINGULAR, CONSTRAINT = 0, 1, 2, 3

# defaults for failure detection
COS_TOL = 1e-3  # |cos(theta)| below this: the leading matrix is numerically singular
VIOLATION_TOL = 1e-3  # m (or m^2): constraint violation beyond this stops a simulation


def kernel_constants(model: Forearm, penalty: Penalty, cos_tol=COS_TOL, violation_tol=VIOLATION_TOL):
    """Pack the constants the kernels need, shape (8,)."""
    return np.array(
        [
            model.point_mass,
            model.L12,
            model.load_y,
            penalty.alpha,
            2 * penalty.xi * penalty.omega,
            penalty.omega**2,
            cos_tol,
            violation_tol,
        ]
    )


@njit
def accelerations(x, y, th, vx, vy, w, tau, consts):
    """q'' of eq. 12 for the state (q, q') and elbow torque tau (N m).

    Returns (x2'', y2'', theta'', cos(theta)); the accelerations are zero where |cos(theta)| is
    below the tolerance consts[6] (the singular leading matrix).
    """
    return _accelerations(x, y, math.sin(th), math.cos(th), vx, vy, w, tau, consts)


@njit(inline="always")
def _accelerations(x, y, s, c, vx, vy, w, tau, consts):
    """``accelerations`` given s = sin(theta) and c = cos(theta)."""
    a, L, load_y, alpha, two_xi_omega, omega2 = consts[0], consts[1], consts[2], consts[3], consts[4], consts[5]
    lc = L * c
    if abs(c) < consts[6]:
        return 0.0, 0.0, 0.0, c
    # c = Phi_q' q' + 2 xi omega Phi' + omega^2 Phi, one entry per constraint
    c1 = 2 * vx * vx + 2 * vy * vy + two_xi_omega * (2 * x * vx + 2 * y * vy) + omega2 * (x * x + y * y - L * L)
    c2 = L * s * w * w + two_xi_omega * (vy - lc * w) + omega2 * (y - L * s)
    # right-hand side after eliminating theta'' (the alpha c2 terms cancel exactly)
    b1 = -2 * alpha * x * c1
    b2 = load_y + tau / lc - 2 * alpha * y * c1
    det = a * a + 4 * alpha * a * (x * x + y * y)
    ax = ((a + 4 * alpha * y * y) * b1 - 4 * alpha * x * y * b2) / det
    ay = ((a + 4 * alpha * x * x) * b2 - 4 * alpha * x * y * b1) / det
    ath = tau / (alpha * lc * lc) + (c2 + ay) / lc
    return ax, ay, ath, c


@njit
def constraint_violation(x, y, th, L):
    """max |Phi_i| of eq. 9 (m^2 and m)."""
    return _violation(x, y, math.sin(th), L)


@njit(inline="always")
def _violation(x, y, s, L):
    """``constraint_violation`` given s = sin(theta)."""
    return max(abs(x * x + y * y - L * L), abs(y - L * s))


@njit(inline="always")
def _derivative(state, tau, ref_th, ref_w, kp, kd, g_c, consts, c0, out):
    """``_derivative_at`` of a state whose sin and cos of theta are still to compute."""
    th = state[2]
    return _derivative_at(state, math.sin(th), math.cos(th), tau, ref_th, ref_w, kp, kd, g_c, consts, c0, out)


@njit(inline="always")
def _derivative_at(state, s, c, tau, ref_th, ref_w, kp, kd, g_c, consts, c0, out):
    """State derivative for state = [q, q'] (s, c: sin and cos of its theta) with the feedback law
    added to tau (see ``rk4_feedback``). Returns a status: NONFINITE for a non-finite theta,
    SINGULAR where |cos(theta)| is below tolerance or of another sign than c0 (a step that jumped
    over cos(theta) = 0), else OK."""
    total = tau + kp * (ref_th - state[2]) + kd * (ref_w - state[5])
    if g_c != 0.0:
        total += g_c * c
    ax, ay, ath, c = _accelerations(state[0], state[1], s, c, state[3], state[4], state[5], total, consts)
    out[0], out[1], out[2] = state[3], state[4], state[5]
    out[3], out[4], out[5] = ax, ay, ath
    if not math.isfinite(c):
        return NONFINITE
    if abs(c) < consts[6] or c * c0 <= 0.0:
        return SINGULAR
    return OK


@njit
def rk4(y0, dt, n_steps, tau_half, ref_th_half, ref_w_half, kp, kd, consts, states, qdd, applied):
    """``rk4_feedback`` with constant PD gains kp (N m/rad) and kd (N m s/rad) and no gravity term:
    the applied torque is tau + kp (ref_th - theta) + kd (ref_w - theta')."""
    return rk4_feedback(y0, dt, n_steps, tau_half, ref_th_half, ref_w_half, np.full(1, kp), np.full(1, kd), 0.0,
                        consts, states, qdd, applied)


@njit
def rk4_feedback(y0, dt, n_steps, tau_half, ref_th_half, ref_w_half, kp_half, kd_half, g_c, consts, states, qdd,
                 applied):
    """Classical RK4 over n_steps steps of dt (s) under one feedback law shared by every controller.

    tau_half, ref_th_half, ref_w_half: shape (2 n_steps + 1,), the feedforward torque (N m) and the
    reference rotation (rad) and velocity (rad/s) on the half-step grid t_k = k dt / 2.
    kp_half (N m/rad), kd_half (N m s/rad): the gains on the same grid, shape (2 n_steps + 1,), or
    shape (1,) for constant gains. g_c (N m): the coefficient of a gravity compensation term.
    The applied torque is tau + kp (ref_th - theta) + kd (ref_w - theta') + g_c cos(theta).
    Fills states (n+1, 6), qdd (n+1, 3) and applied (n+1,) up to the last step reached.
    Returns (status, steps_done, max constraint violation).
    """
    L, viol_tol = consts[1], consts[7]
    sp = 1 if kp_half.shape[0] > 1 else 0  # stride: 0 reads the one constant gain
    sd = 1 if kd_half.shape[0] > 1 else 0
    y = y0.copy()
    k1, k2, k3, k4, tmp = np.empty(6), np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    s, c = math.sin(y[2]), math.cos(y[2])  # of the step's start state, carried over from the step before
    max_viol = _violation(y[0], y[1], s, L)
    for i in range(n_steps + 1):
        j = 2 * i
        c0 = c
        kp0, kd0 = kp_half[j * sp], kd_half[j * sd]
        code = _derivative_at(y, s, c, tau_half[j], ref_th_half[j], ref_w_half[j], kp0, kd0, g_c, consts, c0, k1)
        for m in range(6):
            states[i, m] = y[m]
        qdd[i, 0], qdd[i, 1], qdd[i, 2] = k1[3], k1[4], k1[5]
        applied[i] = tau_half[j] + kp0 * (ref_th_half[j] - y[2]) + kd0 * (ref_w_half[j] - y[5])
        if g_c != 0.0:
            applied[i] += g_c * c
        if code != OK:
            return code, i, max_viol
        if i == n_steps:
            break
        kp1, kd1 = kp_half[(j + 1) * sp], kd_half[(j + 1) * sd]
        kp2, kd2 = kp_half[(j + 2) * sp], kd_half[(j + 2) * sd]
        for m in range(6):
            tmp[m] = y[m] + 0.5 * dt * k1[m]
        code = _derivative(tmp, tau_half[j + 1], ref_th_half[j + 1], ref_w_half[j + 1], kp1, kd1, g_c, consts, c0, k2)
        if code == OK:
            for m in range(6):
                tmp[m] = y[m] + 0.5 * dt * k2[m]
            code = _derivative(tmp, tau_half[j + 1], ref_th_half[j + 1], ref_w_half[j + 1], kp1, kd1, g_c, consts, c0,
                               k3)
        if code == OK:
            for m in range(6):
                tmp[m] = y[m] + dt * k3[m]
            code = _derivative(tmp, tau_half[j + 2], ref_th_half[j + 2], ref_w_half[j + 2], kp2, kd2, g_c, consts, c0,
                               k4)
        if code != OK:
            return code, i, max_viol
        finite = True
        for m in range(6):
            tmp[m] = y[m] + dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            finite = finite and math.isfinite(tmp[m])
        if not finite:
            return NONFINITE, i, max_viol
        s, c = math.sin(tmp[2]), math.cos(tmp[2])
        if c * c0 <= 0.0:  # the step itself jumped over cos(theta) = 0
            return SINGULAR, i, max_viol
        viol = _violation(tmp[0], tmp[1], s, L)
        if viol > viol_tol:
            return CONSTRAINT, i, max(max_viol, viol)
        max_viol = max(max_viol, viol)
        y[:] = tmp
    return OK, n_steps, max_viol
