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
    Zero where the leading matrix is singular (the accelerations are set to zero there).
    Straight-line code: with ax = nx / det, ay = ny / det (see ``accelerations``),
    d ax = (d nx - ax d det) / det, and theta'' = tau / (alpha lc^2) + (c2 + ay) / lc."""
    a, L, load_y, alpha, A, B = consts[0], consts[1], consts[2], consts[3], consts[4], consts[5]
    s, c = math.sin(th), math.cos(th)
    lc = L * c
    if abs(c) < consts[6]:
        for r in range(3):
            for m in range(7):
                jac[r, m] = 0.0
        return
    c1 = 2 * vx * vx + 2 * vy * vy + A * (2 * x * vx + 2 * y * vy) + B * (x * x + y * y - L * L)
    c2 = L * s * w * w + A * (vy - lc * w) + B * (y - L * s)
    b1 = -2 * alpha * x * c1
    b2 = load_y + tau / lc - 2 * alpha * y * c1
    det = a * a + 4 * alpha * a * (x * x + y * y)
    inv_det, inv_lc = 1.0 / det, 1.0 / lc
    p1, p2, q = a + 4 * alpha * y * y, a + 4 * alpha * x * x, 4 * alpha * x * y
    ax = (p1 * b1 - q * b2) * inv_det
    ay = (p2 * b2 - q * b1) * inv_det
    k = -2 * alpha
    # c1's partials (x, y, vx, vy); c2's (y, theta, vy, theta')
    c1x, c1y, c1vx, c1vy = 2 * A * vx + 2 * B * x, 2 * A * vy + 2 * B * y, 4 * vx + 2 * A * x, 4 * vy + 2 * A * y
    c2th, c2w = L * c * w * w + A * L * s * w - B * L * c, 2 * L * s * w - A * lc
    # x
    b1m, b2m, ddet = k * c1 + k * x * c1x, k * y * c1x, 8 * alpha * a * x
    dax = (p1 * b1m - q * b2m - 4 * alpha * y * b2 - ax * ddet) * inv_det
    day = (p2 * b2m - q * b1m + 8 * alpha * x * b2 - 4 * alpha * y * b1 - ay * ddet) * inv_det
    jac[0, 0], jac[1, 0], jac[2, 0] = dax, day, day * inv_lc
    # y
    b1m, b2m, ddet = k * x * c1y, k * c1 + k * y * c1y, 8 * alpha * a * y
    dax = (p1 * b1m - q * b2m + 8 * alpha * y * b1 - 4 * alpha * x * b2 - ax * ddet) * inv_det
    day = (p2 * b2m - q * b1m - 4 * alpha * x * b1 - ay * ddet) * inv_det
    jac[0, 1], jac[1, 1], jac[2, 1] = dax, day, (B + day) * inv_lc
    # theta (through tau / lc in b2, and lc, c2 in theta'')
    b2m = tau * L * s * inv_lc * inv_lc
    dax, day = -q * b2m * inv_det, p2 * b2m * inv_det
    jac[0, 2], jac[1, 2] = dax, day
    jac[2, 2] = (c2th + day) * inv_lc + 2 * tau * L * s / (alpha * lc * lc * lc) + (c2 + ay) * L * s * inv_lc * inv_lc
    # x' and y'
    b1m, b2m = k * x * c1vx, k * y * c1vx
    day = (p2 * b2m - q * b1m) * inv_det
    jac[0, 3], jac[1, 3], jac[2, 3] = (p1 * b1m - q * b2m) * inv_det, day, day * inv_lc
    b1m, b2m = k * x * c1vy, k * y * c1vy
    day = (p2 * b2m - q * b1m) * inv_det
    jac[0, 4], jac[1, 4], jac[2, 4] = (p1 * b1m - q * b2m) * inv_det, day, (A + day) * inv_lc
    # theta'
    jac[0, 5], jac[1, 5], jac[2, 5] = 0.0, 0.0, c2w * inv_lc
    # tau
    dax, day = -q * inv_lc * inv_det, p2 * inv_lc * inv_det
    jac[0, 6], jac[1, 6], jac[2, 6] = dax, day, day * inv_lc + 1.0 / (alpha * lc * lc)


@njit
def _step_sensitivity(S, G, j, j1, j2, J1, J2, J3, J4, dt):
    """Advance S (P, 6), the sensitivity of the state, over one RK4 step, column by column in
    registers: K_s = f_y(y_s) (S + c_s dt K_{s-1}) + f_tau(y_s) G[j_s] with the stage Jacobians
    J1..J4, shape (3, 7) (f_y: the first six columns of the accelerations' rows; the first three
    rows of f_y are the identity on the velocities), then S += dt/6 (K1 + 2 K2 + 2 K3 + K4)."""
    h2 = 0.5 * dt
    for q in range(S.shape[0]):
        s0, s1, s2, s3, s4, s5 = S[q, 0], S[q, 1], S[q, 2], S[q, 3], S[q, 4], S[q, 5]
        ga, gb, gc = G[j, q], G[j1, q], G[j2, q]
        # stage 1 at y
        a0, a1, a2 = s3, s4, s5
        a3 = J1[0, 6] * ga + J1[0, 0] * s0 + J1[0, 1] * s1 + J1[0, 2] * s2 + J1[0, 3] * s3 + J1[0, 4] * s4 + J1[0, 5] * s5
        a4 = J1[1, 6] * ga + J1[1, 0] * s0 + J1[1, 1] * s1 + J1[1, 2] * s2 + J1[1, 3] * s3 + J1[1, 4] * s4 + J1[1, 5] * s5
        a5 = J1[2, 6] * ga + J1[2, 0] * s0 + J1[2, 1] * s1 + J1[2, 2] * s2 + J1[2, 3] * s3 + J1[2, 4] * s4 + J1[2, 5] * s5
        # stage 2 at y + dt/2 k1
        u0, u1, u2 = s0 + h2 * a0, s1 + h2 * a1, s2 + h2 * a2
        u3, u4, u5 = s3 + h2 * a3, s4 + h2 * a4, s5 + h2 * a5
        b0, b1, b2 = u3, u4, u5
        b3 = J2[0, 6] * gb + J2[0, 0] * u0 + J2[0, 1] * u1 + J2[0, 2] * u2 + J2[0, 3] * u3 + J2[0, 4] * u4 + J2[0, 5] * u5
        b4 = J2[1, 6] * gb + J2[1, 0] * u0 + J2[1, 1] * u1 + J2[1, 2] * u2 + J2[1, 3] * u3 + J2[1, 4] * u4 + J2[1, 5] * u5
        b5 = J2[2, 6] * gb + J2[2, 0] * u0 + J2[2, 1] * u1 + J2[2, 2] * u2 + J2[2, 3] * u3 + J2[2, 4] * u4 + J2[2, 5] * u5
        # stage 3 at y + dt/2 k2
        u0, u1, u2 = s0 + h2 * b0, s1 + h2 * b1, s2 + h2 * b2
        u3, u4, u5 = s3 + h2 * b3, s4 + h2 * b4, s5 + h2 * b5
        c0, c1, c2 = u3, u4, u5
        c3 = J3[0, 6] * gb + J3[0, 0] * u0 + J3[0, 1] * u1 + J3[0, 2] * u2 + J3[0, 3] * u3 + J3[0, 4] * u4 + J3[0, 5] * u5
        c4 = J3[1, 6] * gb + J3[1, 0] * u0 + J3[1, 1] * u1 + J3[1, 2] * u2 + J3[1, 3] * u3 + J3[1, 4] * u4 + J3[1, 5] * u5
        c5 = J3[2, 6] * gb + J3[2, 0] * u0 + J3[2, 1] * u1 + J3[2, 2] * u2 + J3[2, 3] * u3 + J3[2, 4] * u4 + J3[2, 5] * u5
        # stage 4 at y + dt k3
        u0, u1, u2 = s0 + dt * c0, s1 + dt * c1, s2 + dt * c2
        u3, u4, u5 = s3 + dt * c3, s4 + dt * c4, s5 + dt * c5
        d0, d1, d2 = u3, u4, u5
        d3 = J4[0, 6] * gc + J4[0, 0] * u0 + J4[0, 1] * u1 + J4[0, 2] * u2 + J4[0, 3] * u3 + J4[0, 4] * u4 + J4[0, 5] * u5
        d4 = J4[1, 6] * gc + J4[1, 0] * u0 + J4[1, 1] * u1 + J4[1, 2] * u2 + J4[1, 3] * u3 + J4[1, 4] * u4 + J4[1, 5] * u5
        d5 = J4[2, 6] * gc + J4[2, 0] * u0 + J4[2, 1] * u1 + J4[2, 2] * u2 + J4[2, 3] * u3 + J4[2, 4] * u4 + J4[2, 5] * u5
        w = dt / 6.0
        S[q, 0] = s0 + w * (a0 + 2.0 * b0 + 2.0 * c0 + d0)
        S[q, 1] = s1 + w * (a1 + 2.0 * b1 + 2.0 * c1 + d1)
        S[q, 2] = s2 + w * (a2 + 2.0 * b2 + 2.0 * c2 + d2)
        S[q, 3] = s3 + w * (a3 + 2.0 * b3 + 2.0 * c3 + d3)
        S[q, 4] = s4 + w * (a4 + 2.0 * b4 + 2.0 * c4 + d4)
        S[q, 5] = s5 + w * (a5 + 2.0 * b5 + 2.0 * c5 + d5)


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
    S = np.zeros((P, 6))
    J1, J2, J3, J4 = np.empty((3, 7)), np.empty((3, 7)), np.empty((3, 7)), np.empty((3, 7))
    for i in range(n_steps + 1):
        j = 2 * i
        c0 = math.cos(y[2])
        code = _derivative(y, tau_half[j], ref_th_half[j], ref_w_half[j], 0.0, 0.0, 0.0, consts, c0, k1)
        for m in range(6):
            states[i, m] = y[m]
        for q in range(P):
            dtheta[i, q] = S[q, 2]
        if code != OK:
            return code, i
        if i == n_steps:
            break
        acceleration_jacobian(y[0], y[1], y[2], y[3], y[4], y[5], tau_half[j], consts, J1)
        for m in range(6):
            tmp[m] = y[m] + 0.5 * dt * k1[m]
        code = _derivative(tmp, tau_half[j + 1], ref_th_half[j + 1], ref_w_half[j + 1], 0.0, 0.0, 0.0, consts, c0, k2)
        if code == OK:
            acceleration_jacobian(tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5], tau_half[j + 1], consts, J2)
            for m in range(6):
                tmp[m] = y[m] + 0.5 * dt * k2[m]
            code = _derivative(tmp, tau_half[j + 1], ref_th_half[j + 1], ref_w_half[j + 1], 0.0, 0.0, 0.0, consts, c0,
                               k3)
        if code == OK:
            acceleration_jacobian(tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5], tau_half[j + 1], consts, J3)
            for m in range(6):
                tmp[m] = y[m] + dt * k3[m]
            code = _derivative(tmp, tau_half[j + 2], ref_th_half[j + 2], ref_w_half[j + 2], 0.0, 0.0, 0.0, consts, c0,
                               k4)
        if code != OK:
            return code, i
        acceleration_jacobian(tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5], tau_half[j + 2], consts, J4)
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
        _step_sensitivity(S, G_half, j, j + 1, j + 2, J1, J2, J3, J4, dt)
        y[:] = tmp
    return OK, n_steps
