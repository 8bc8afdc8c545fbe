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
