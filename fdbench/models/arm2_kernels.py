"""Forward dynamics of the two-segment arm by the penalty formulation (eq. 12), as compiled kernels.

The leading matrix M + alpha Phi_q^T Phi_q is 6x6, but its angle rows hold no mass: they say that
the multipliers of the angle constraints are lambda_3 = -(tau_s - tau_e) / (L01 cos s) and
lambda_4 = -tau_e / (L12 cos(s + e)). With them known, the point accelerations solve a 4x4
symmetric positive definite system (an L D L^T factorisation below), and the angle accelerations follow from the
angle constraints' rows. This is the forearm kernel's elimination (``fdbench.dynamics``) once per
segment, and gives the same numbers as a dense solve of eq. 12.

State: [x1, y1, x2, y2, s, e, x1', y1', x2', y2', s', e'], shape (12,). Strict IEEE arithmetic.
"""

from __future__ import annotations

import math

import numpy as np

from ..dynamics import CONSTRAINT, COS_TOL, NONFINITE, OK, SINGULAR, VIOLATION_TOL
from ..jit import njit
from ..population import DEGREES_PER_RADIAN

N_STATE = 12


def kernel_constants(model, penalty, cos_tol=COS_TOL, violation_tol=VIOLATION_TOL) -> np.ndarray:
    """Pack the constants the kernels need, shape (12,)."""
    m11, m12, m22 = model.point_masses
    elbow_y, hand_y = model.loads_y
    return np.array([m11, m12, m22, model.L01, model.L12, elbow_y, hand_y, penalty.alpha,
                     2 * penalty.xi * penalty.omega, penalty.omega**2, cos_tol, violation_tol])


@njit(error_model="numpy")
def accelerations(y, tau_s, tau_e, consts, out):
    """q'' of eq. 12 for the state y (12,) and joint torques (N m) into out[6:12] (out[:6] gets
    q'). Returns (cos s, cos(s + e)); the accelerations are zero where either is below the
    tolerance consts[10] in magnitude (a singular leading matrix). A division by an exact zero
    (a pivot lost to cancellation in a state far off the manifold) gives inf or NaN, which the
    integrator reports as a non-finite state, rather than raising."""
    m11, m12, m22, L01, L12 = consts[0], consts[1], consts[2], consts[3], consts[4]
    alpha, txo, om2 = consts[7], consts[8], consts[9]
    x1, y1, x2, y2, s, e = y[0], y[1], y[2], y[3], y[4], y[5]
    vx1, vy1, vx2, vy2, ws, we = y[6], y[7], y[8], y[9], y[10], y[11]
    for k in range(6):
        out[k] = y[6 + k]
    cs, ss = math.cos(s), math.sin(s)
    ca, sa = math.cos(s + e), math.sin(s + e)
    if abs(cs) < consts[10] or abs(ca) < consts[10]:
        for k in range(6, 12):
            out[k] = 0.0
        return cs, ca
    dx, dy, dvx, dvy, wa = x2 - x1, y2 - y1, vx2 - vx1, vy2 - vy1, ws + we
    # c = Phi_q' q' + 2 xi omega Phi' + omega^2 Phi, one entry per constraint
    c1 = 2 * (vx1 * vx1 + vy1 * vy1) + txo * 2 * (x1 * vx1 + y1 * vy1) + om2 * (x1 * x1 + y1 * y1 - L01 * L01)
    c2 = 2 * (dvx * dvx + dvy * dvy) + txo * 2 * (dx * dvx + dy * dvy) + om2 * (dx * dx + dy * dy - L12 * L12)
    c3 = L01 * ss * ws * ws + txo * (vy1 - L01 * cs * ws) + om2 * (y1 - L01 * ss)
    c4 = L12 * sa * wa * wa + txo * (dvy - L12 * ca * wa) + om2 * (dy - L12 * sa)
    ics, ica = 1.0 / (L01 * cs), 1.0 / (L12 * ca)
    lam3 = -(tau_s - tau_e) * ics
    lam4 = -tau_e * ica
    # the 4x4 system of the points, A = M_p + alpha (J1^T J1 + J2^T J2), J1 = 2 [x1, y1, 0, 0],
    # J2 = 2 [-dx, -dy, dx, dy]; lower triangle only
    p, r = 4 * alpha, 2 * alpha
    a00 = m11 + p * (x1 * x1 + dx * dx)
    a10 = p * (x1 * y1 + dx * dy)
    a11 = m11 + p * (y1 * y1 + dy * dy)
    a20 = m12 - p * dx * dx
    a21 = -p * dx * dy
    a22 = m22 + p * dx * dx
    a30 = -p * dx * dy
    a31 = m12 - p * dy * dy
    a32 = p * dx * dy
    a33 = m22 + p * dy * dy
    b0 = -r * (x1 * c1 - dx * c2)
    b1 = consts[5] - r * (y1 * c1 - dy * c2) - lam3 + lam4
    b2 = -r * dx * c2
    b3 = consts[6] - r * dy * c2 - lam4
    # A = L D L^T (L unit lower triangular), with the reciprocals of D: four divisions in all
    d0 = a00
    i0 = 1.0 / d0
    l10, l20, l30 = a10 * i0, a20 * i0, a30 * i0
    d1 = a11 - l10 * l10 * d0
    i1 = 1.0 / d1
    l21 = (a21 - l20 * l10 * d0) * i1
    l31 = (a31 - l30 * l10 * d0) * i1
    d2 = a22 - l20 * l20 * d0 - l21 * l21 * d1
    i2 = 1.0 / d2
    l32 = (a32 - l30 * l20 * d0 - l31 * l21 * d1) * i2
    d3 = a33 - l30 * l30 * d0 - l31 * l31 * d1 - l32 * l32 * d2
    z0 = b0
    z1 = b1 - l10 * z0
    z2 = b2 - l20 * z0 - l21 * z1
    z3 = b3 - l30 * z0 - l31 * z1 - l32 * z2
    u3 = z3 / d3
    u2 = z2 * i2 - l32 * u3
    u1 = z1 * i1 - l21 * u2 - l31 * u3
    u0 = z0 * i0 - l10 * u1 - l20 * u2 - l30 * u3
    dws = (u1 - lam3 / alpha + c3) * ics
    dwa = (u3 - u1 - lam4 / alpha + c4) * ica
    out[6], out[7], out[8], out[9], out[10], out[11] = u0, u1, u2, u3, dws, dwa - dws
    return cs, ca


@njit
def constraint_violation(y, L01, L12):
    """max |Phi_i| (m^2 and m) of the state y."""
    x1, y1, dx, dy, s = y[0], y[1], y[2] - y[0], y[3] - y[1], y[4]
    v = max(abs(x1 * x1 + y1 * y1 - L01 * L01), abs(dx * dx + dy * dy - L12 * L12))
    return max(v, max(abs(y1 - L01 * math.sin(s)), abs(dy - L12 * math.sin(s + y[5]))))


@njit
def inverse_torques(y, vs, ve, consts, out):
    """The joint torques (N m) that give the joint accelerations vs, ve (rad/s^2) at the state y on
    the constraint manifold: R^T (M q'' - Q_ext), the points' accelerations from the joint angles
    and velocities of y (the model's inverse dynamics, ``Arm2.joint_torques``), into out (2,)."""
    m11, m12, m22, L01, L12 = consts[0], consts[1], consts[2], consts[3], consts[4]
    s, a, ws, wa, va = y[4], y[4] + y[5], y[10], y[10] + y[11], vs + ve
    cs, ss, ca, sa = math.cos(s), math.sin(s), math.cos(a), math.sin(a)
    ax1, ay1 = -L01 * (cs * ws * ws + ss * vs), L01 * (-ss * ws * ws + cs * vs)
    ax2, ay2 = ax1 - L12 * (ca * wa * wa + sa * va), ay1 + L12 * (-sa * wa * wa + ca * va)
    f1x, f1y = m11 * ax1 + m12 * ax2, m11 * ay1 + m12 * ay2 - consts[5]
    f2x, f2y = m12 * ax1 + m22 * ax2, m12 * ay1 + m22 * ay2 - consts[6]
    out[1] = L12 * (ca * f2y - sa * f2x)
    out[0] = L01 * (cs * (f1y + f2y) - ss * (f1x + f2x)) + out[1]


@njit(inline="always")
def _derivative(y, half, tau_half, ref_half, refw_half, acc_half, kp, kd, computed, gains, consts, nominal, cs0, ca0,
                out, applied):
    """State derivative at grid index ``half`` under the feedback law (see ``rk4_pd``); the applied
    torques go to applied (2,). Returns a status code."""
    if computed == 2:
        e0, e1 = ref_half[half, 0] - y[4], ref_half[half, 1] - y[5]
        e2, e3 = refw_half[half, 0] - y[10], refw_half[half, 1] - y[11]
        for j in range(2):
            applied[j] = tau_half[half, j] + (gains[half, j, 0] * e0 + gains[half, j, 1] * e1 + gains[half, j, 2] * e2
                                              + gains[half, j, 3] * e3)
    elif computed == 1:
        vs = acc_half[half, 0] + kp[0] * (ref_half[half, 0] - y[4]) + kd[0] * (refw_half[half, 0] - y[10])
        ve = acc_half[half, 1] + kp[1] * (ref_half[half, 1] - y[5]) + kd[1] * (refw_half[half, 1] - y[11])
        inverse_torques(y, vs, ve, nominal, applied)
        applied[0] += tau_half[half, 0]
        applied[1] += tau_half[half, 1]
    else:
        for j in range(2):
            applied[j] = (tau_half[half, j] + kp[j] * (ref_half[half, j] - y[4 + j])
                          + kd[j] * (refw_half[half, j] - y[10 + j]))
    cs, ca = accelerations(y, applied[0], applied[1], consts, out)
    if not (math.isfinite(cs) and math.isfinite(ca)):
        return NONFINITE
    tol = consts[10]
    if abs(cs) < tol or abs(ca) < tol or cs * cs0 <= 0.0 or ca * ca0 <= 0.0:
        return SINGULAR
    return OK


@njit
def derivatives(states, tau, ref, refw, acc, kp, kd, computed, gains, consts, nominal, out, applied):
    """The state derivatives (into out, shape (k, 12)) and the applied joint torques (N m, into
    applied, shape (k, 2)) of k states (shape (k, 12)) under the feedback law of ``rk4_pd``, row i
    with the feedforward torques tau[i], the references ref[i], refw[i], acc[i] (each of shape
    (k, 2)) and, for computed 2, the gain matrix gains[i] (shape (k, 2, 4)); for the adaptive
    integrators (one state at a time) and their histories. The accelerations are zero where the
    leading matrix is singular; the state's failures are for the caller to check."""
    for i in range(states.shape[0]):
        y = states[i]
        _derivative(y, i, tau, ref, refw, acc, kp, kd, computed, gains, consts, nominal, math.cos(y[4]),
                    math.cos(y[4] + y[5]), out[i], applied[i])


@njit
def rk4_pd(y0, dt, n_steps, tau_half, ref_half, refw_half, acc_half, kp, kd, computed, gains, consts, nominal, states,
           qdd, applied):
    """Classical RK4 over n_steps steps of dt (s) under per-joint PD feedback plus feedforward, or
    computed-torque control.

    tau_half, ref_half, refw_half, acc_half: shape (2 n_steps + 1, 2), the feedforward torques
    (N m), the reference angles (rad), velocities (rad/s) and accelerations (rad/s^2) of
    [shoulder, elbow] on the half-step grid t_k = k dt / 2; kp, kd: shape (2,), one gain per joint.
    computed 0 (PD): the applied torque of joint j is tau_j + kp_j (ref_j - z_j) +
    kd_j (ref_j' - z_j') (kp in N m/rad, kd in N m s/rad). computed 1: the torques of the model's
    inverse dynamics at the current state for the joint accelerations ref'' + kp e + kd e'
    (kp in 1/s^2, kd in 1/s), plus tau: feedback linearisation with the full mass matrix.
    computed 2: tau + K e with a full gain matrix K = gains[k], shape (2, 4), on the half-step grid
    (gains of shape (2 n_steps + 1, 2, 4); N m/rad and N m s/rad) for e = [ref - z, ref' - z'].
    consts: the simulated arm's constants (``kernel_constants``); nominal: those of the model the
    computed-torque law believes (the same array when plant and nominal model agree).
    Fills states (n+1, 12), qdd (n+1, 6) and applied (n+1, 2) up to the last step reached.
    Returns (status, steps_done, max constraint violation).
    """
    L01, L12, viol_tol = consts[3], consts[4], consts[11]
    y = y0.copy()
    k1, k2, k3, k4 = np.empty(N_STATE), np.empty(N_STATE), np.empty(N_STATE), np.empty(N_STATE)
    tmp, torque = np.empty(N_STATE), np.empty(2)
    max_viol = constraint_violation(y, L01, L12)
    for i in range(n_steps + 1):
        j = 2 * i
        cs0, ca0 = math.cos(y[4]), math.cos(y[4] + y[5])
        code = _derivative(y, j, tau_half, ref_half, refw_half, acc_half, kp, kd, computed, gains,
                           consts, nominal, cs0, ca0, k1, torque)
        for m in range(N_STATE):
            states[i, m] = y[m]
        for m in range(6):
            qdd[i, m] = k1[6 + m]
        applied[i, 0], applied[i, 1] = torque[0], torque[1]
        if code != OK:
            return code, i, max_viol
        if i == n_steps:
            break
        for m in range(N_STATE):
            tmp[m] = y[m] + 0.5 * dt * k1[m]
        code = _derivative(tmp, j + 1, tau_half, ref_half, refw_half, acc_half, kp, kd, computed, gains,
                           consts, nominal, cs0, ca0, k2, torque)
        if code == OK:
            for m in range(N_STATE):
                tmp[m] = y[m] + 0.5 * dt * k2[m]
            code = _derivative(tmp, j + 1, tau_half, ref_half, refw_half, acc_half, kp, kd, computed, gains,
                               consts, nominal, cs0, ca0, k3, torque)
        if code == OK:
            for m in range(N_STATE):
                tmp[m] = y[m] + dt * k3[m]
            code = _derivative(tmp, j + 2, tau_half, ref_half, refw_half, acc_half, kp, kd, computed, gains,
                               consts, nominal, cs0, ca0, k4, torque)
        if code != OK:
            return code, i, max_viol
        finite = True
        for m in range(N_STATE):
            tmp[m] = y[m] + dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            finite = finite and math.isfinite(tmp[m])
        if not finite:
            return NONFINITE, i, max_viol
        if math.cos(tmp[4]) * cs0 <= 0.0 or math.cos(tmp[4] + tmp[5]) * ca0 <= 0.0:
            return SINGULAR, i, max_viol
        viol = constraint_violation(tmp, L01, L12)
        if viol > viol_tol:
            return CONSTRAINT, i, max(max_viol, viol)
        max_viol = max(max_viol, viol)
        y[:] = tmp
    return OK, n_steps, max_viol


@njit(nogil=True)
def tracking_objective(states, done, every, angles_ref, n_steps, penalty_weight):
    """Eq. 18 for n joints from a simulation's states, shape (n_steps+1, 12), filled up to step
    ``done``: the RMSE (deg) of both joint angles at the motion's samples (every ``every``-th step;
    desired angles angles_ref (rad), shape (samples, 2)) over the samples reached, plus
    penalty_weight times the fraction of the steps not reached. The squared errors are summed
    sample by sample, shoulder before elbow; a non-finite RMSE counts as 0."""
    count = done // every + 1
    total = 0.0
    for k in range(count):
        for j in range(2):
            error = (states[k * every, 4 + j] - angles_ref[k, j]) * DEGREES_PER_RADIAN
            total += error * error
    rmse = math.sqrt(total / (2 * count))
    if not math.isfinite(rmse):
        rmse = 0.0
    return rmse + penalty_weight * (1.0 - done / n_steps)


@njit(nogil=True)
def rk4_candidates(y0, dt, n_steps, tau, ref_half, refw_half, acc_half, consts, every, angles_ref, penalty_weight,
                   states, qdd, applied, objective, first, stride):
    """Open-loop RK4 (``rk4_pd`` with zero gains) and eq. 18 (``tracking_objective``) for
    candidates first, first + stride, ... of tau.

    tau: the joint torques (N m) on the half-step grid, shape (lam, 2 n_steps + 1, 2); states
    (n+1, 12), qdd (n+1, 6), applied (n+1, 2): this call's work buffers, reused candidate after
    candidate; objective (lam,): filled for the candidates run. Runs without the GIL."""
    zero = np.zeros(2)
    no_gains = np.zeros((1, 2, 4))
    for c in range(first, tau.shape[0], stride):
        _, done, _ = rk4_pd(y0, dt, n_steps, tau[c], ref_half, refw_half, acc_half, zero, zero, 0, no_gains, consts,
                            consts, states, qdd, applied)
        objective[c] = tracking_objective(states, done, every, angles_ref, n_steps, penalty_weight)
