"""Forward sensitivities of the engine's RK4 map (compiled), for exact gradients on any model.

Every RK4 stage k_s = f(y_s, tau_s) is differentiated with the chain rule,
K_s = f_y(y_s) dy_s/dp + f_tau(y_s) dtau_s/dp, and the step y+ = y + dt/6 (k1 + 2 k2 + 2 k3 + k4)
gives S+ = S + dt/6 (K1 + 2 K2 + 2 K3 + K4), S = dy/dp of shape (n_state, P).
f_y S and f_tau are exact: ``_tangent`` is the forward-mode (tangent) derivative of the engine's
stage code (``kernels._drive``) written by hand, one parameter direction at a time. It differentiates the
assembly of the points' matrix K and right-hand side r, and for the linear solve K x = r uses
dx = K^-1 (dr - dK x) with the L D L^T factor the stage has already computed (no refactoring per
direction); the angle rows follow as in the stage code. The form of each angle constraint is that
in force at the stage (the derivative of the branch taken).

The states are those of the open-loop ``kernels.rk4`` to the last bit (the same stage code,
``kernels._drive`` in PD mode with zero gains, is run for each stage, and it leaves the stage's
factor, solution and multipliers in its work arrays), so the value and the gradient belong to one
simulation. The kernels take the engine's layout arrays only, so numba compiles and caches them
once for every model.
"""

from __future__ import annotations

import math

import numpy as np

from ..dynamics import CONSTRAINT, NONFINITE, OK
from ..jit import njit
from .kernels import (ALPHA, BETA, FORM, LAMBDA, LENGTH, N_AUX, OMEGA2, PD, PIVOT, TWO_XI_OMEGA, VIOLATION,
                      _drive)

# columns of a stage's per-body coefficients (``_stage_values``), with e = r_j - r_i the body's
# end minus its joint point (m) and de, de' a direction's change of e and e':
#   the distance rows' change g = de GAIN + e (TX dex + TY dey + TVX dex' + TVY dey'), -g on j, +g on i;
#   the angle row's pivot change PSI_PIVOT dpsi and velocity term change
#   PSI_TERM dpsi + RATE_TERM dw + 2 xi omega de'_axis + omega^2 de_axis;
# the multiplier, 1 / pivot, the angle acceleration (rad/s^2) and the form (the axis) at the stage
(EX, EY, GAIN, TX, TY, TVX, TVY, PSI_PIVOT, PSI_TERM, RATE_TERM, STAGE_LAMBDA, INV_PIVOT, ACC, AXIS,
 N_STAGE) = range(15)


@njit(error_model="numpy", inline="always")
def _stage_values(y, k, pt_index, pt_fixed, body_pts, body_geom, first, base, params, K, x, aux, values, inv_diag):
    """The coefficients every direction's tangent at the stage state y needs: per body into values
    (n_b, N_STAGE), and 1 / D of the factor K = L D L^T into inv_diag (n_p,). x: the stage's
    solution of K x = r (the point accelerations, m/s^2), k its state derivative, aux its
    multipliers, pivots and forms (``kernels._drive``'s work arrays).

    The distance rows r -= 2 alpha e cd (cd = 2 |e'|^2 + 2 xi omega 2 e.e' + omega^2 (|e|^2 - d^2))
    and K's block 4 alpha e e^T, whose change acts on x through -dK x = -4 alpha (de (e.rel) +
    e (de.rel)), rel = x_j - x_i, give g of the columns' comment."""
    n_p, n_b = base.shape[0], body_pts.shape[0]
    n_q = n_p + n_b
    alpha, txo, om2 = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2]
    for r in range(n_p):
        inv_diag[r] = 1.0 / K[r, r]
    for b in range(n_b):
        ki, kj = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        if ki >= 0:
            xi, yi, vxi, vyi = y[ki], y[ki + 1], y[n_q + ki], y[n_q + ki + 1]
        else:
            xi, yi, vxi, vyi = pt_fixed[body_pts[b, 0], 0], pt_fixed[body_pts[b, 0], 1], 0.0, 0.0
        ex, ey, evx, evy = y[kj] - xi, y[kj + 1] - yi, y[n_q + kj] - vxi, y[n_q + kj + 1] - vyi
        rx, ry = x[kj] - (x[ki] if ki >= 0 else 0.0), x[kj + 1] - (x[ki + 1] if ki >= 0 else 0.0)
        d = body_geom[b, LENGTH]
        cd = 2 * (evx * evx + evy * evy) + txo * 2 * (ex * evx + ey * evy) + om2 * (ex * ex + ey * ey - d * d)
        values[b, EX], values[b, EY] = ex, ey
        values[b, GAIN] = 2 * alpha * cd + 4 * alpha * (ex * rx + ey * ry)
        values[b, TX] = 4 * alpha * (txo * evx + om2 * ex + rx)
        values[b, TY] = 4 * alpha * (txo * evy + om2 * ey + ry)
        values[b, TVX] = 4 * alpha * (2 * evx + txo * ex)
        values[b, TVY] = 4 * alpha * (2 * evy + txo * ey)
        psi = y[n_p + b] + body_geom[b, BETA]
        s, c, w = math.sin(psi), math.cos(psi), y[n_q + n_p + b]
        if aux[b, FORM] == 1:  # (y_j - y_i) - d sin(psi): pivot -d c, velocity term d s w^2 + txo (ey' - d c w) + ...
            values[b, PSI_PIVOT] = d * s
            values[b, PSI_TERM] = d * c * w * w + txo * d * s * w - om2 * d * c
            values[b, RATE_TERM] = 2 * d * s * w - txo * d * c
        else:  # (x_j - x_i) - d cos(psi): pivot d s, velocity term d c w^2 + txo (ex' + d s w) + ...
            values[b, PSI_PIVOT] = d * c
            values[b, PSI_TERM] = -d * s * w * w + txo * d * c * w + om2 * d * s
            values[b, RATE_TERM] = 2 * d * c * w + txo * d * s
        values[b, STAGE_LAMBDA], values[b, INV_PIVOT] = aux[b, LAMBDA], 1.0 / aux[b, PIVOT]
        values[b, ACC], values[b, AXIS] = k[n_q + n_p + b], aux[b, FORM]


@njit(error_model="numpy", inline="always")
def _solve_factored(K, first, inv_diag, rhs):
    """Solve K X = rhs in place for the columns of rhs (n_p, P) with the L D L^T factor of
    the stage's solve (``kernels._drive``) in K and 1 / D in inv_diag."""
    n, P = rhs.shape
    for r in range(n):
        for k in range(first[r], r):
            lrk = K[r, k]
            for q in range(P):
                rhs[r, q] -= lrk * rhs[k, q]
    for r in range(n):
        for q in range(P):
            rhs[r, q] *= inv_diag[r]
    for r in range(n - 1, -1, -1):
        for k in range(first[r], r):
            lrk = K[r, k]
            for q in range(P):
                rhs[k, q] -= lrk * rhs[r, q]


@njit(error_model="numpy", inline="always")
def _tangents(U, dtau, pt_index, body_pts, lin_idx, lin_coef, first, base, params, K, values, inv_diag, dr, dlam,
              dpivot, dca, out):
    """out = f_y U + f_tau dtau for P directions at once: the derivative of the stage code
    at a stage in the directions U (n_state, P) of the state and dtau (n_b, P) of the generalised
    forces of the body angles (N m). K: the stage's factor; values, inv_diag: its
    ``_stage_values``. dr (n_p, P), dlam, dpivot, dca (n_b, P): scratch."""
    n_p, n_b = base.shape[0], body_pts.shape[0]
    n_q = n_p + n_b
    P = U.shape[1]
    alpha, txo, om2 = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2]
    for k in range(n_q):
        for q in range(P):
            out[k, q] = U[n_q + k, q]
    for r in range(n_p):
        for q in range(P):
            dr[r, q] = 0.0
    for r in range(lin_idx.shape[0]):  # linear constraints: their right-hand side is linear in y
        for e in range(lin_idx.shape[1]):
            k = lin_idx[r, e]
            if k < 0:
                continue
            for f in range(lin_idx.shape[1]):
                m = lin_idx[r, f]
                if m < 0:
                    continue
                c_om2, c_txo = alpha * om2 * lin_coef[r, e] * lin_coef[r, f], alpha * txo * lin_coef[r, e] * lin_coef[r, f]
                for q in range(P):
                    dr[k, q] -= c_om2 * U[m, q] + c_txo * U[n_q + m, q]
    for b in range(n_b):
        ki, kj = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        ex, ey, gain = values[b, EX], values[b, EY], values[b, GAIN]
        tx, ty, tvx, tvy = values[b, TX], values[b, TY], values[b, TVX], values[b, TVY]
        psi_pivot, psi_term, rate_term = values[b, PSI_PIVOT], values[b, PSI_TERM], values[b, RATE_TERM]
        lam, inv_pivot = values[b, STAGE_LAMBDA], values[b, INV_PIVOT]
        on_y = values[b, AXIS] == 1.0
        for q in range(P):
            dex, dey, devx, devy = U[kj, q], U[kj + 1, q], U[n_q + kj, q], U[n_q + kj + 1, q]
            if ki >= 0:
                dex, dey = dex - U[ki, q], dey - U[ki + 1, q]
                devx, devy = devx - U[n_q + ki, q], devy - U[n_q + ki + 1, q]
            t = tx * dex + ty * dey + tvx * devx + tvy * devy
            gx, gy = dex * gain + ex * t, dey * gain + ey * t
            dpsi = U[n_p + b, q]
            dp = psi_pivot * dpsi
            dl = (dtau[b, q] - lam * dp) * inv_pivot
            dc = psi_term * dpsi + rate_term * U[n_q + n_p + b, q]
            if on_y:
                dc += txo * devy + om2 * dey
                gy += dl
            else:
                dc += txo * devx + om2 * dex
                gx += dl
            dr[kj, q] -= gx
            dr[kj + 1, q] -= gy
            if ki >= 0:
                dr[ki, q] += gx
                dr[ki + 1, q] += gy
            dlam[b, q], dpivot[b, q], dca[b, q] = dl, dp, dc
    _solve_factored(K, first, inv_diag, dr)
    for r in range(n_p):
        for q in range(P):
            out[n_q + r, q] = dr[r, q]
    for b in range(n_b):
        ki, kj = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        axis = 1 if values[b, AXIS] == 1.0 else 0
        acc, inv_pivot = values[b, ACC], values[b, INV_PIVOT]
        for q in range(P):
            drel = dr[kj + axis, q] - (dr[ki + axis, q] if ki >= 0 else 0.0)
            out[n_q + n_p + b, q] = (dlam[b, q] / alpha - dca[b, q] - drel - acc * dpivot[b, q]) * inv_pivot


@njit(error_model="numpy", inline="always")
def _stage_sensitivity(y, k, S, U, acc, weight, next_step, half, G, torque_sign, work, scratch, layout):
    """The tangents K_s of the stage at the state y (derivative k) for every parameter, from their
    inputs U (n_state, P) (the tangents of the stage's state): acc += weight K_s, then
    U = S + next_step K_s (the next stage's input). ``work`` holds the stage's factor and
    multipliers (``_stage_rate``); G[half, q] is d tau / d p_q (N m per parameter unit), which
    moves the generalised force of body b's angle by torque_sign[b, q] G[half, q]; layout: the
    penalty layout (``kernels.rk4``'s order); scratch: values, inv_diag, dtau, dr, dlam, dpivot,
    dca, dk of ``_stage_values`` and ``_tangents``."""
    K, x, aux = work[0], work[1], work[2]
    values, inv_diag, dtau, dr, dlam, dpivot, dca, dk = scratch
    (pt_index, pt_fixed, body_pts, body_geom, _, lin_idx, lin_coef, _, first, base, _, params) = layout
    _stage_values(y, k, pt_index, pt_fixed, body_pts, body_geom, first, base, params, K, x, aux, values, inv_diag)
    for b in range(torque_sign.shape[0]):
        for q in range(torque_sign.shape[1]):
            dtau[b, q] = torque_sign[b, q] * G[half, q]
    _tangents(U, dtau, pt_index, body_pts, lin_idx, lin_coef, first, base, params, K, values, inv_diag, dr, dlam,
              dpivot, dca, dk)
    for m in range(S.shape[0]):
        for q in range(S.shape[1]):
            acc[m, q] += weight * dk[m, q]
            U[m, q] = S[m, q] + next_step * dk[m, q]


@njit(error_model="numpy", inline="always")
def _stage_rate(y, half, tau, ref, refd, offset, layout, nominal, work, k, torque):
    """The open-loop state derivative (``kernels.rk4`` in PD mode with zero gains) at the stage
    state y and grid row ``half`` into k, the joint torques into torque (J,); work (the stage's
    factor, solution and multipliers) and its buffers. Returns (status, max |Phi_i| of y)."""
    K, x, aux, state, rate, applied, zero, no_gains = work
    (pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext,
     params) = layout
    n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext = nominal
    code, _, viol = _drive(y, 0.0, 0, half, tau, ref, refd, ref, zero, zero, PD, no_gains, offset, pt_index, pt_fixed,
                           body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params,
                           n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext,
                           state, rate, applied, K, x, aux)
    for m in range(k.shape[0]):
        k[m] = rate[0, m]
    for m in range(torque.shape[0]):
        torque[m] = applied[0, m]
    return code, viol


@njit(error_model="numpy")
def rk4_sensitivity(y0, dt, n_steps, tau, ref, refd, G, param_joint, every, offset, pt_index, pt_fixed, body_pts,
                    body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent,
                    n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states, rates,
                    applied, dz):
    """Open-loop RK4 (``kernels.rk4`` in PD mode with zero gains, as ``kernels.rk4_candidates``
    runs it) and the sensitivities of the joint angles.

    tau, ref, refd: as for ``rk4_candidates``' candidate, shape (2 n_steps + 1, J); G: d tau / d p
    on the half-step grid, shape (2 n_steps + 1, P), each parameter q moving the torque of joint
    param_joint[q] only (N m per parameter unit). The initial state does not depend on p. Fills
    states, rates (n_steps + 1, n_state) and applied (n_steps + 1, J) as ``rk4`` does, and
    dz (n_steps // every + 1, J, P), the derivative of the joint angles (rad per parameter unit) at
    every ``every``-th step reached. Returns (status, steps_done)."""
    layout = (pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext,
              params)
    nominal = (n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext)
    n_b, n_p = joint_parent.shape[0], base.shape[0]
    n, P = y0.shape[0], G.shape[1]
    work = (np.zeros((n_p, n_p)), np.zeros(n_p), np.zeros((n_b, N_AUX)), np.empty((1, n)), np.empty((1, n)),
            np.empty((1, n_b)), np.zeros(n_b), np.zeros((1, n_b, 2 * n_b)))
    torque = np.zeros(n_b)
    y = y0.copy()
    k1, k2, k3, k4, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    S, U, acc = np.zeros((n, P)), np.zeros((n, P)), np.zeros((n, P))
    scratch = (np.empty((n_b, N_STAGE)), np.empty(n_p), np.empty((n_b, P)), np.empty((n_p, P)), np.empty((n_b, P)),
               np.empty((n_b, P)), np.empty((n_b, P)), np.empty((n, P)))
    torque_sign = np.zeros((n_b, P))  # joint torque -> generalised forces of the body angles
    for q in range(P):
        torque_sign[param_joint[q], q] = 1.0
        if joint_parent[param_joint[q]] >= 0:
            torque_sign[joint_parent[param_joint[q]], q] = -1.0
    for i in range(n_steps + 1):
        j = 2 * i
        code, viol = _stage_rate(y, j, tau, ref, refd, offset, layout, nominal, work, k1, torque)
        if i > 0 and viol > params[VIOLATION]:  # the step before left the constraint manifold
            return CONSTRAINT, i - 1
        for m in range(n):
            states[i, m] = y[m]
            rates[i, m] = k1[m]
        for m in range(n_b):
            applied[i, m] = torque[m]
        if i % every == 0:
            for b in range(n_b):
                parent = joint_parent[b]
                for q in range(P):
                    dz[i // every, b, q] = S[n_p + b, q] - (S[n_p + parent, q] if parent >= 0 else 0.0)
        if code != OK:
            return code, i
        if i == n_steps:
            break
        for m in range(n):
            for q in range(P):
                U[m, q], acc[m, q] = S[m, q], 0.0
        _stage_sensitivity(y, k1, S, U, acc, 1.0, 0.5 * dt, j, G, torque_sign, work, scratch, layout)
        for m in range(n):
            tmp[m] = y[m] + 0.5 * dt * k1[m]
        code, _ = _stage_rate(tmp, j + 1, tau, ref, refd, offset, layout, nominal, work, k2, torque)
        if code == OK:
            _stage_sensitivity(tmp, k2, S, U, acc, 2.0, 0.5 * dt, j + 1, G, torque_sign, work, scratch, layout)
            for m in range(n):
                tmp[m] = y[m] + 0.5 * dt * k2[m]
            code, _ = _stage_rate(tmp, j + 1, tau, ref, refd, offset, layout, nominal, work, k3, torque)
        if code == OK:
            _stage_sensitivity(tmp, k3, S, U, acc, 2.0, dt, j + 1, G, torque_sign, work, scratch, layout)
            for m in range(n):
                tmp[m] = y[m] + dt * k3[m]
            code, _ = _stage_rate(tmp, j + 2, tau, ref, refd, offset, layout, nominal, work, k4, torque)
        if code != OK:
            return code, i
        _stage_sensitivity(tmp, k4, S, U, acc, 1.0, 0.0, j + 2, G, torque_sign, work, scratch, layout)
        finite = True
        for m in range(n):
            tmp[m] = y[m] + dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            finite = finite and math.isfinite(tmp[m])
        if not finite:
            return NONFINITE, i
        for m in range(n):
            for q in range(P):
                S[m, q] += dt / 6.0 * acc[m, q]
        y[:] = tmp
    return OK, n_steps


def warm_up() -> None:
    """Load (or compile) the sensitivity kernel on a small library model, so that later timings
    exclude it."""
    from .description import find_model
    from .engine import Engine

    engine = Engine(find_model("forearm"))
    n, rows = 2, np.zeros((5, 1))
    y0 = engine.state_from_joints(np.zeros(1), np.zeros(1))
    rk4_sensitivity(y0, 0.05, n, rows, rows, rows, np.zeros((5, 1)), np.zeros(1, dtype=np.int64), 1,
                    *engine.simulation_layout(), np.empty((n + 1, engine.n_state)), np.empty((n + 1, engine.n_state)),
                    np.empty((n + 1, 1)), np.empty((n + 1, 1, 1)))
