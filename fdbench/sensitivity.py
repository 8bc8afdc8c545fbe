"""Forward sensitivities of the discrete RK4 map (compiled): the derivative of the simulated
rotation with respect to the torque parameters, exact for the simulation actually run.

Every RK4 stage k_s = f(y_s, tau_s) is differentiated with the chain rule:
K_s = f_y(y_s) dy_s/dp + f_tau(y_s) dtau_s/dp, and the step y+ = y + dt/6 (k1 + 2 k2 + 2 k3 + k4)
gives S+ = S + dt/6 (K1 + 2 K2 + 2 K3 + K4) with S = dy/dp, shape (6, P). The states are those of
``dynamics.rk4`` to the last bit (the same stage code is run), so the value and the gradient
belong to one and the same simulation.
"""

from __future__ import annotations

import math

import numpy as np

from .dynamics import NONFINITE, OK, SINGULAR, CONSTRAINT, _derivative, constraint_violation
from .jit import njit


@njit
def acceleration_jacobian(x, y, th, vx, vy, w, tau, consts, jac):
    """Partial derivatives of (x2'', y2'', theta'') of ``dynamics.accelerations`` with respect to
    (x2, y2, theta, x2', y2', theta', tau), written into jac, shape (3, 7) (SI units).
    Zero where the leading matrix is singular (the accelerations are set to zero there)."""
    a, L, load_y, alpha, A, B = consts[0], consts[1], consts[2], consts[3], consts[4], consts[5]
    s, c = math.sin(th), math.cos(th)
    lc = L * c
    for r in range(3):
        for m in range(7):
            jac[r, m] = 0.0
    if abs(c) < consts[6]:
        return
    c1 = 2 * vx * vx + 2 * vy * vy + A * (2 * x * vx + 2 * y * vy) + B * (x * x + y * y - L * L)
    c2 = L * s * w * w + A * (vy - lc * w) + B * (y - L * s)
    b1 = -2 * alpha * x * c1
    b2 = load_y + tau / lc - 2 * alpha * y * c1
    det = a * a + 4 * alpha * a * (x * x + y * y)
    ax = ((a + 4 * alpha * y * y) * b1 - 4 * alpha * x * y * b2) / det
    ay = ((a + 4 * alpha * x * x) * b2 - 4 * alpha * x * y * b1) / det
    # partials of c1 (index: 0 x, 1 y, 3 vx, 4 vy) and of c2 (1 y, 2 th, 4 vy, 5 w)
    dc1 = (2 * A * vx + 2 * B * x, 2 * A * vy + 2 * B * y, 0.0, 4 * vx + 2 * A * x, 4 * vy + 2 * A * y, 0.0, 0.0)
    dc2 = (0.0, B, L * c * w * w + A * L * s * w - B * L * c, 0.0, A, 2 * L * s * w - A * lc, 0.0)
    for m in range(7):
        db1 = -2 * alpha * x * dc1[m]
        db2 = -2 * alpha * y * dc1[m]
        ddet = 0.0
        dnx = 0.0
        dny = 0.0
        if m == 0:
            db1 += -2 * alpha * c1
            ddet = 8 * alpha * a * x
            dnx = -4 * alpha * y * b2
            dny = 8 * alpha * x * b2 - 4 * alpha * y * b1
        elif m == 1:
            db2 += -2 * alpha * c1
            ddet = 8 * alpha * a * y
            dnx = 8 * alpha * y * b1 - 4 * alpha * x * b2
            dny = -4 * alpha * x * b1
        elif m == 2:
            db2 += tau * L * s / (lc * lc)
        elif m == 6:
            db2 += 1.0 / lc
        dnx += (a + 4 * alpha * y * y) * db1 - 4 * alpha * x * y * db2
        dny += (a + 4 * alpha * x * x) * db2 - 4 * alpha * x * y * db1
        dax = (dnx - ax * ddet) / det
        day = (dny - ay * ddet) / det
        dath = (dc2[m] + day) / lc
        if m == 2:
            dath += 2 * tau * L * s / (alpha * lc * lc * lc) + (c2 + ay) * L * s / (lc * lc)
        elif m == 6:
            dath += 1.0 / (alpha * lc * lc)
        jac[0, m], jac[1, m], jac[2, m] = dax, day, dath


@njit
def _stage_sensitivity(S_in, G, j, jac, K):
    """K = f_y S_in + f_tau G[j] with jac = (f_y, f_tau) of the accelerations at the stage's
    state: the sensitivity of one stage derivative, shape (6, P)."""
    P = S_in.shape[1]
    for r in range(3):
        for q in range(P):
            K[r, q] = S_in[r + 3, q]
    for r in range(3):
        for q in range(P):
            acc = jac[r, 6] * G[j, q]
            for m in range(6):
                acc += jac[r, m] * S_in[m, q]
            K[r + 3, q] = acc


@njit
def rk4_sensitivity(y0, dt, n_steps, tau_half, G_half, ref_th_half, ref_w_half, consts, states, dtheta):
    """Open-loop RK4 (as ``dynamics.rk4`` with zero gains) and the sensitivity of theta.

    tau_half: the torque (N m) on the half-step grid, shape (2 n + 1,); G_half: its derivative
    with respect to the P parameters, shape (2 n + 1, P) (N m per parameter unit). The initial
    state does not depend on the parameters. Fills states (n+1, 6) and dtheta (n+1, P), the
    derivative of theta (rad per parameter unit) at every step reached.
    Returns (status, steps_done) as ``dynamics.rk4_feedback``."""
    L, viol_tol = consts[1], consts[7]
    P = G_half.shape[1]
    y = y0.copy()
    k1, k2, k3, k4, tmp = np.empty(6), np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    S = np.zeros((6, P))
    Sn = np.empty((6, P))
    K1, K2, K3, K4 = np.empty((6, P)), np.empty((6, P)), np.empty((6, P)), np.empty((6, P))
    jac = np.empty((3, 7))
    h2 = 0.5 * dt
    for i in range(n_steps + 1):
        j = 2 * i
        c0 = math.cos(y[2])
        code = _derivative(y, tau_half[j], ref_th_half[j], ref_w_half[j], 0.0, 0.0, 0.0, consts, c0, k1)
        for m in range(6):
            states[i, m] = y[m]
        for q in range(P):
            dtheta[i, q] = S[2, q]
        if code != OK:
            return code, i
        if i == n_steps:
            break
        acceleration_jacobian(y[0], y[1], y[2], y[3], y[4], y[5], tau_half[j], consts, jac)
        _stage_sensitivity(S, G_half, j, jac, K1)
        for m in range(6):
            tmp[m] = y[m] + 0.5 * dt * k1[m]
        code = _derivative(tmp, tau_half[j + 1], ref_th_half[j + 1], ref_w_half[j + 1], 0.0, 0.0, 0.0, consts, c0, k2)
        if code == OK:
            acceleration_jacobian(tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5], tau_half[j + 1], consts, jac)
            for m in range(6):
                for q in range(P):
                    Sn[m, q] = S[m, q] + h2 * K1[m, q]
            _stage_sensitivity(Sn, G_half, j + 1, jac, K2)
            for m in range(6):
                tmp[m] = y[m] + 0.5 * dt * k2[m]
            code = _derivative(tmp, tau_half[j + 1], ref_th_half[j + 1], ref_w_half[j + 1], 0.0, 0.0, 0.0, consts, c0,
                               k3)
        if code == OK:
            acceleration_jacobian(tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5], tau_half[j + 1], consts, jac)
            for m in range(6):
                for q in range(P):
                    Sn[m, q] = S[m, q] + h2 * K2[m, q]
            _stage_sensitivity(Sn, G_half, j + 1, jac, K3)
            for m in range(6):
                tmp[m] = y[m] + dt * k3[m]
            code = _derivative(tmp, tau_half[j + 2], ref_th_half[j + 2], ref_w_half[j + 2], 0.0, 0.0, 0.0, consts, c0,
                               k4)
        if code != OK:
            return code, i
        acceleration_jacobian(tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5], tau_half[j + 2], consts, jac)
        for m in range(6):
            for q in range(P):
                Sn[m, q] = S[m, q] + dt * K3[m, q]
        _stage_sensitivity(Sn, G_half, j + 2, jac, K4)
        finite = True
        for m in range(6):
            tmp[m] = y[m] + dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            finite = finite and math.isfinite(tmp[m])
        if not finite:
            return NONFINITE, i
        if math.cos(tmp[2]) * c0 <= 0.0:
            return SINGULAR, i
        if constraint_violation(tmp[0], tmp[1], tmp[2], L) > viol_tol:
            return CONSTRAINT, i
        for m in range(6):
            for q in range(P):
                S[m, q] = S[m, q] + dt / 6.0 * (K1[m, q] + 2.0 * K2[m, q] + 2.0 * K3[m, q] + K4[m, q])
        y[:] = tmp
    return OK, n_steps
