"""The tangents of one RK4 stage of eq. 12, run by the driver (``fdbench.multibody.kernels._drive``)
after each stage for the forward sensitivities (``fdbench.multibody.sensitivity``): the banded
solve's (pin joints, the angle rows eliminated by hand, one direction at a time) and the dense
solve's (free and path joints, loads: each stage's f_y formed as a matrix from the constraint rows'
Hessians and the loads' derivatives). The two derivations agree on pin joints
(``tests/test_sensitivity_dense.py``)."""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from .layout import (ALPHA, AT_CHILD_X, AT_CHILD_Y, BETA, FIXED_X, FIXED_Y, FORCE_FRAME, FX, FY, KI, LENGTH,
                     LOAD_BODY, OMEGA2, PARENT, POINT_FRAME, PX, PY, TWO_XI_OMEGA)

LAMBDA, PIVOT, VELOCITY_TERM, FORM, N_AUX = 0, 1, 2, 3, 4  # the banded solve's aux columns per body
MAX_ENTRIES = 8  # nonzero entries of a dense constraint row (a path's row has up to 7)


# ---------------------------------------------------------------------- sensitivities of a banded stage
# (the tangents of ``fdbench.multibody.sensitivity`` for pin joints, run by the driver after each stage)
# columns of a stage's per-body coefficients (``_stage_values``), with e = r_j - r_i the body's
# end minus its joint point (m) and de, de' a direction's change of e and e':
#   the distance rows' change g = de GAIN + e (TX dex + TY dey + TVX dex' + TVY dey'), -g on j, +g on i;
#   the angle row's pivot change PSI_PIVOT dpsi and velocity term change
#   PSI_TERM dpsi + RATE_TERM dw + 2 xi omega de'_axis + omega^2 de_axis;
# the multiplier, 1 / pivot, the angle acceleration (rad/s^2) and the form (the axis) at the stage
(EX, EY, GAIN, TX, TY, TVX, TVY, PSI_PIVOT, PSI_TERM, RATE_TERM, STAGE_LAMBDA, INV_PIVOT, STAGE_ACC, AXIS,
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
        values[b, STAGE_ACC], values[b, AXIS] = k[n_q + n_p + b], aux[b, FORM]


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
        acc, inv_pivot = values[b, STAGE_ACC], values[b, INV_PIVOT]
        for q in range(P):
            drel = dr[kj + axis, q] - (dr[ki + axis, q] if ki >= 0 else 0.0)
            out[n_q + n_p + b, q] = (dlam[b, q] / alpha - dca[b, q] - drel - acc * dpivot[b, q]) * inv_pivot


@njit(error_model="numpy", inline="always")
def _stage_sensitivity(y, k, S, U, acc, weight, next_step, half, G, torque_sign, muscle_dtau, work, scratch, layout):
    """The tangents K_s of the stage at the state y (derivative k) for every parameter, from their
    inputs U (n_state, P) (the tangents of the stage's state): acc += weight K_s, then
    U = S + next_step K_s (the next stage's input). ``work`` holds the stage's factor and
    multipliers (``_drive``'s K, rhs, aux); G[half, q] is d tau / d p_q (N m per parameter unit), which
    moves the generalised force of body b's angle by torque_sign[b, q] G[half, q]; muscle_dtau
    (n_b, P): the muscles' change of those forces, added (None without muscles; the muscle states'
    rows of dk, beyond the mechanical ones, are the caller's); layout: the
    penalty layout (``rk4``'s order); scratch: values, inv_diag, dtau, dr, dlam, dpivot,
    dca, dk of ``_stage_values`` and ``_tangents``."""
    K, x, aux = work[0], work[1], work[2]
    values, inv_diag, dtau, dr, dlam, dpivot, dca, dk = scratch
    (pt_index, pt_fixed, body_pts, body_geom, _, lin_idx, lin_coef, _, first, base, _, params) = layout
    _stage_values(y, k, pt_index, pt_fixed, body_pts, body_geom, first, base, params, K, x, aux, values, inv_diag)
    for b in range(torque_sign.shape[0]):
        for q in range(torque_sign.shape[1]):
            dtau[b, q] = torque_sign[b, q] * G[half, q]
    if muscle_dtau is not None:
        for b in range(torque_sign.shape[0]):
            for q in range(torque_sign.shape[1]):
                dtau[b, q] += muscle_dtau[b, q]
    _tangents(U, dtau, pt_index, body_pts, lin_idx, lin_coef, first, base, params, K, values, inv_diag, dr, dlam,
              dpivot, dca, dk)
    for m in range(S.shape[0]):
        for q in range(S.shape[1]):
            acc[m, q] += weight * dk[m, q]
            U[m, q] = S[m, q] + next_step * dk[m, q]



# ---------------------------------------------------------------------- the sensitivities of a dense stage
# (``_drive`` with dz runs ``_stage_tangents`` after each stage; module functions, not the driver's
# closures, so that a kernel without sensitivities compiles none of this)
@njit(error_model="numpy", inline="always")
def _point_i(state, body_int, body_float, n_q, b):
    """x, y (m) of body b's point i in the state (fixed: its position)."""
    k = body_int[b, KI]
    if k < 0:
        return body_float[b, FIXED_X], body_float[b, FIXED_Y]
    return state[k], state[k + 1]


@njit(error_model="numpy", inline="always")
def _load_in_ground(values, k, load_int, body_int, body_float, state, n_p, n_q):
    """Load k's force (N) and point (m) in ground at the state, from its values (L, N_LOAD) in its frames."""
    fx, fy, px, py = values[k, FX], values[k, FY], values[k, PX], values[k, PY]
    frame = load_int[k, FORCE_FRAME]
    if frame >= 0:
        c, s = math.cos(state[n_p + frame]), math.sin(state[n_p + frame])
        fx, fy = c * fx - s * fy, s * fx + c * fy
    frame = load_int[k, POINT_FRAME]
    if frame >= 0:
        c, s = math.cos(state[n_p + frame]), math.sin(state[n_p + frame])
        lx, ly = px - body_float[frame, AT_CHILD_X], py - body_float[frame, AT_CHILD_Y]
        xi, yi = _point_i(state, body_int, body_float, n_q, frame)
        px, py = xi + (c * lx - s * ly), yi + (s * lx + c * ly)
    return fx, fy, px, py


@njit(error_model="numpy")
def _loads_jacobian(jac, values, load_int, body_int, body_float, state, n_p, n_q):
    """The loads' part of D (``_drive``'s docstring) into jac (n_q, 2 n_q): d b / dq of F on the
    body's point i and of (P - r_i) x F + M on its angle, F turning with its frame's angle and P
    moving with its frame."""
    for k in range(load_int.shape[0]):
        fx, fy, px, py = _load_in_ground(values, k, load_int, body_int, body_float, state, n_p, n_q)
        b = load_int[k, LOAD_BODY]
        ki = body_int[b, KI]
        xi, yi = _point_i(state, body_int, body_float, n_q, b)
        frame = load_int[k, FORCE_FRAME]
        if frame >= 0:  # dF = R90 F dphi_frame
            if ki >= 0:
                jac[ki, n_p + frame] -= fy
                jac[ki + 1, n_p + frame] += fx
            jac[n_p + b, n_p + frame] += (px - xi) * fx + (py - yi) * fy
        frame = load_int[k, POINT_FRAME]
        if frame >= 0:  # dP = dr_i(frame) + R90 (P - r_i(frame)) dphi_frame
            xf, yf = _point_i(state, body_int, body_float, n_q, frame)
            jac[n_p + b, n_p + frame] += -(py - yf) * fy - (px - xf) * fx
            kf = body_int[frame, KI]
            if kf >= 0:
                jac[n_p + b, kf] += fy
                jac[n_p + b, kf + 1] -= fx
        if ki >= 0:  # -dr_i x F
            jac[n_p + b, ki] -= fy
            jac[n_p + b, ki + 1] += fx


@njit(error_model="numpy")
def _path_hessian(rows, path_kept, m, axis):
    """The Hessian and third derivative (``rows``: row_count, row_term, row_idx, row_val, row_hess,
    row_third) of path m's row ``axis`` (its parent not ground; entries as the driver's
    ``constraints`` orders them: r_i, r_pj (2), the child's and the parent's angle, r_pi (2)), from
    path_kept[m]: its first row, e_p, e_p', theta', c1, c2, c3 (the derivatives of c(theta)).
    Phi = r_i - r_pi - G(c, e_p) has d2 Phi = -G(c2, e) dtheta^2 - 2 G(c1, de) dtheta, and
    T(q', q', .) is -G(c3, e) theta'^2 - 2 G(c2, e') theta' on theta, -G(c2, .) theta'^2 on e."""
    row_count, row_hess, row_third = rows[0], rows[4], rows[5]
    r = int(path_kept[m, 0]) + axis
    ex, ey, evx, evy, rate = path_kept[m, 1], path_kept[m, 2], path_kept[m, 3], path_kept[m, 4], path_kept[m, 5]
    c1a, c1b, c2a, c2b, c3a, c3b = (path_kept[m, 6], path_kept[m, 7], path_kept[m, 8], path_kept[m, 9],
                                    path_kept[m, 10], path_kept[m, 11])
    if axis == 0:  # row 0 of G(c)'s matrix [[c_a, -c_b], [c_b, c_a]]
        g1x, g1y, g2x, g2y, g3x, g3y = c1a, -c1b, c2a, -c2b, c3a, -c3b
    else:
        g1x, g1y, g2x, g2y, g3x, g3y = c1b, c1a, c2b, c2a, c3b, c3a
    hess, third = row_hess[r], row_third[r]
    bend = -(g2x * ex + g2y * ey)
    hess[3, 3], hess[3, 4], hess[4, 3], hess[4, 4] = bend, -bend, -bend, bend
    twist = -(g3x * ex + g3y * ey) * rate * rate - 2.0 * (g2x * evx + g2y * evy) * rate
    third[3], third[4] = twist, -twist
    third[1], third[2] = -g2x * rate * rate, -g2y * rate * rate
    hess[3, 1], hess[1, 3], hess[4, 1], hess[1, 4] = -g1x, -g1x, g1x, g1x
    hess[3, 2], hess[2, 3], hess[4, 2], hess[2, 4] = -g1y, -g1y, g1y, g1y
    if row_count[r] == 7:
        third[5], third[6] = g2x * rate * rate, g2y * rate * rate
        hess[3, 5], hess[5, 3], hess[4, 5], hess[5, 4] = g1x, g1x, -g1x, -g1x
        hess[3, 6], hess[6, 3], hess[4, 6], hess[6, 4] = g1y, g1y, -g1y, -g1y


@njit(error_model="numpy")
def _rows_jacobian(jac, state, x, rows, n_q, params):
    """Every constraint row's part of D (``_drive``'s docstring) into jac, from what the stage's
    assembly kept (``rows``: per row its count of entries, term J' q' + 2 xi omega J q' + omega^2
    Phi, entries' indices and values, Hessian H and third derivative T(q', q', .) on them): the
    derivative of -alpha J^T (term) - alpha J^T J x, with dJ = H dq and
    d(J' q') = T(q', q', dq) + 2 (H q') . dq'."""
    row_count, row_term, row_idx, row_val, row_hess, row_third = rows
    alpha, txo, om2 = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2]
    h_rate, h_acc = np.empty(MAX_ENTRIES), np.empty(MAX_ENTRIES)
    for r in range(row_count.shape[0]):
        count, cc, jx = row_count[r], row_term[r], 0.0
        for e in range(count):
            jx += row_val[r, e] * x[row_idx[r, e]]
            h_rate[e], h_acc[e] = 0.0, 0.0
            for f in range(count):
                h_rate[e] += row_hess[r, e, f] * state[n_q + row_idx[r, f]]
                h_acc[e] += row_hess[r, e, f] * x[row_idx[r, f]]
        for e in range(count):
            ie, ve = row_idx[r, e], row_val[r, e]
            for f in range(count):
                jf, vf = row_idx[r, f], row_val[r, f]
                jac[ie, jf] -= alpha * (row_hess[r, e, f] * (cc + jx) + ve * (
                    row_third[r, f] + txo * h_rate[f] + om2 * vf + h_acc[f]))
                jac[ie, n_q + jf] -= alpha * ve * (2.0 * h_rate[f] + txo * vf)


@njit(error_model="numpy")
def _solve_cholesky(L, first, X):
    """Solve L L^T Y = X in place for the columns of X (n_q, m), L the Cholesky factor that the
    driver's ``solve`` leaves in its matrix (inside the envelope ``first``)."""
    n_q, m = X.shape
    for r in range(n_q):
        for k in range(first[r], r):
            for c in range(m):
                X[r, c] -= L[r, k] * X[k, c]
        for c in range(m):
            X[r, c] /= L[r, r]
    for r in range(n_q - 1, -1, -1):
        for c in range(m):
            X[r, c] /= L[r, r]
        for k in range(first[r], r):
            for c in range(m):
                X[k, c] -= L[r, k] * X[r, c]


@njit(error_model="numpy")
def _stage_tangents(state, x, L, first, values, load_int, body_int, body_float, path_body, params, rows, path_kept,
                    force_rows, g, param_col, U, jac, solved_rows, moved, dk):
    """dk (n_state, P) = f_y U + f_tau g for the stage just solved at the state (its factor L,
    solution x = the accelerations): the top rows U's rates, the bottom A^-1 (D U + b_tau g) with D
    built from the loads (values (L, N_LOAD) at the stage) and the constraint rows the assembly
    kept (``rows``, path_kept), b_tau = force_rows (n_q, J) and g (P,) = d tau / d p at the stage,
    parameter q moving coordinate param_col[q] (none for param_col[q] >= J: an excitation, whose
    rows are the caller's). jac (n_q, n_state), solved_rows (n_q, J), moved (n_q, P): scratch."""
    n_q = L.shape[0]
    n_p = n_q - body_int.shape[0]
    jac[:] = 0.0
    solved_rows[:] = force_rows
    _loads_jacobian(jac, values, load_int, body_int, body_float, state, n_p, n_q)
    for m in range(path_body.shape[0]):
        if body_int[path_body[m], PARENT] >= 0:
            _path_hessian(rows, path_kept, m, 0)
            _path_hessian(rows, path_kept, m, 1)
    _rows_jacobian(jac, state, x, rows, n_q, params)
    _solve_cholesky(L, first, jac)
    _solve_cholesky(L, first, solved_rows)
    np.dot(jac, U, moved)
    n_forces = force_rows.shape[1]
    for r in range(n_q):
        for q in range(U.shape[1]):
            dk[r, q] = U[n_q + r, q]
            c = param_col[q]
            dk[n_q + r, q] = moved[r, q] + solved_rows[r, c] * g[q] if c < n_forces else moved[r, q]
