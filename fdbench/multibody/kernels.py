"""The multibody engine's compiled kernels (see ``fdbench.multibody.engine`` for the formulation).

Every kernel takes arrays only: the engine's data layout (indices and constants built once per
``Engine``), so numba compiles and caches each kernel once for every model. Three layouts travel
with the calls, each a tuple of arrays in a fixed order:

* the penalty layout (``Engine._kernel_layout``): pt_index, pt_fixed, body_pts, body_geom,
  joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params;
* the inverse-dynamics layout (``Engine.inverse_torques_layout``): joint_parent, joint_offset,
  joint_at_parent, joint_at_child, pt_owner, pt_local, pt_index, mass, q_ext;
* the simulation layout (``Engine.simulation_layout``): the plant's joint offsets, its penalty
  layout, then the inverse-dynamics layout of the model computed-torque control believes.

One RK4 driver (``_drive``, called as ``rk4``) serves every feedback law (``mode``): PD (per-joint
PD plus feedforward), COMPUTED (computed torque through the believed model's inverse dynamics) and
GAINS (a full gain matrix on the half-step grid). Its stage code is the only one: ``derivatives``
(the adaptive integrators' right-hand side for k states), ``constraint_violation``,
``rk4_candidates`` (the population's open-loop simulations with eq. 18) and the sensitivities
(``fdbench.multibody.sensitivity``: the driver runs the tangents after each stage) all run it.
Strict IEEE arithmetic.

Speed (``python benchmarks/bench_engine.py``): numba increments and decrements the reference count
of every array that an inlined function takes at each of its calls whenever the callee branches
or loops (the LLVM pass that removes the pairs does not see through them), which cost more than
the arithmetic. So the stage code is closures over the driver's own arrays (inlined without
such counts), the stages run in one loop, per-body indices and geometry are hoisted out of it, a
step's start reuses the sin and cos of its violation check, and the solve is unrolled for one free
point. The operations on every number are those of the plain formulas: the results do not move by
a bit.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..population import DEGREES_PER_RADIAN

# a simulation's status codes (``simulation.STATUS_OF_CODE`` names them)
OK, NONFINITE, SINGULAR, CONSTRAINT = 0, 1, 2, 3
VIOLATION_TOL = 1e-3  # m (or m^2): a constraint violation beyond this stops a simulation

# named indices into the kernels' arrays
ALPHA, TWO_XI_OMEGA, OMEGA2, SWITCH_COS, VIOLATION, N_PARAMS = 0, 1, 2, 3, 4, 5  # params
LENGTH, BETA = 0, 1  # body_geom columns: d (m), beta (rad)
LAMBDA, PIVOT, VELOCITY_TERM, FORM, N_AUX = 0, 1, 2, 3, 4  # aux columns per body
FIXED = -1  # pt_index of a point fixed to ground (and lin_idx padding)
PD, COMPUTED, GAINS = 0, 1, 2  # feedback laws (``rk4``'s mode)
# columns of the inverse dynamics' per-body scratch: angle (rad), its cos and sin, rate (rad/s),
# angular acceleration (rad/s^2), the joint point (m), the frame origin (m) and its acceleration (m/s^2)
PHI, COS, SIN, RATE, ACC, JOINT_X, JOINT_Y, ORIGIN_X, ORIGIN_Y, ORIGIN_AX, ORIGIN_AY, N_KIN = range(12)


# ---------------------------------------------------------------------- inverse dynamics (eq. 3)
@njit(inline="always")
def _body_point(kin, b, lx, ly):
    """Position (m) and acceleration (m/s^2) of the point (lx, ly) (m, body frame) of body b, from
    the bodies' kinematics ``kin``: x, y, ax, ay."""
    c, s = kin[b, COS], kin[b, SIN]
    arm_x, arm_y = lx * c - ly * s, lx * s + ly * c
    al, w2 = kin[b, ACC], kin[b, RATE] * kin[b, RATE]
    return (kin[b, ORIGIN_X] + arm_x, kin[b, ORIGIN_Y] + arm_y, kin[b, ORIGIN_AX] - al * arm_y - w2 * arm_x,
            kin[b, ORIGIN_AY] + al * arm_x - w2 * arm_y)


@njit(error_model="numpy", inline="always")
def _inverse_torques(z, zd, zdd, joint_parent, joint_offset, joint_at_parent, joint_at_child, pt_owner, pt_local,
                     pt_index, mass, q_ext, kin, points, out):
    """Eq. 3, tau = R^T (M_p p'' - Q_ext) (N m), into out (J,) for the joint angles z (rad), rates zd
    (rad/s) and accelerations zdd (rad/s^2), shape (J,): the bodies' kinematics from ground out
    (parents before children), the free points' positions and accelerations, then each point's
    force M_p p'' - Q_ext projected on R90 (r_P - r_joint) for every joint on its owner's path.
    kin (J, N_KIN), points (3, n_p): scratch."""
    n_b = joint_parent.shape[0]
    for k in range(n_b):
        p = joint_parent[k]
        if p < 0:
            phi, w, al = z[k] + joint_offset[k], zd[k], zdd[k]
            rx, ry, ax, ay = joint_at_parent[k, 0], joint_at_parent[k, 1], 0.0, 0.0
        else:
            phi, w, al = kin[p, PHI] + z[k] + joint_offset[k], kin[p, RATE] + zd[k], kin[p, ACC] + zdd[k]
            rx, ry, ax, ay = _body_point(kin, p, joint_at_parent[k, 0], joint_at_parent[k, 1])
        c, s = math.cos(phi), math.sin(phi)
        arm_x = joint_at_child[k, 0] * c - joint_at_child[k, 1] * s
        arm_y = joint_at_child[k, 0] * s + joint_at_child[k, 1] * c
        kin[k, PHI], kin[k, COS], kin[k, SIN], kin[k, RATE], kin[k, ACC] = phi, c, s, w, al
        kin[k, JOINT_X], kin[k, JOINT_Y] = rx, ry
        kin[k, ORIGIN_X], kin[k, ORIGIN_Y] = rx - arm_x, ry - arm_y
        kin[k, ORIGIN_AX], kin[k, ORIGIN_AY] = ax + al * arm_y + w * w * arm_x, ay - al * arm_x + w * w * arm_y
    for pt in range(pt_index.shape[0]):  # positions (row 0) and accelerations (row 1) of the free points
        i = pt_index[pt]
        if i >= 0:
            points[0, i], points[0, i + 1], points[1, i], points[1, i + 1] = _body_point(
                kin, pt_owner[pt], pt_local[pt, 0], pt_local[pt, 1])
    n_p = mass.shape[0]
    for r in range(n_p):  # row 2: M_p p'' - Q_ext
        total = 0.0
        for c in range(n_p):
            total += mass[r, c] * points[1, c]
        points[2, r] = total - q_ext[r]
    for k in range(n_b):
        out[k] = 0.0
    for pt in range(pt_index.shape[0]):
        i = pt_index[pt]
        if i < 0:
            continue
        b = pt_owner[pt]
        while b >= 0:
            lever_x, lever_y = points[0, i] - kin[b, JOINT_X], points[0, i + 1] - kin[b, JOINT_Y]
            out[b] += lever_x * points[2, i + 1] - lever_y * points[2, i]
            b = joint_parent[b]


@njit(error_model="numpy")
def inverse_torques(z, zd, zdd, joint_parent, joint_offset, joint_at_parent, joint_at_child, pt_owner, pt_local,
                    pt_index, mass, q_ext, out):
    """The joint torques (N m) of the minimal motion (z, zd, zdd) (rad, rad/s, rad/s^2; shape (J,))
    into out (J,): eq. 3 over the inverse-dynamics layout (``Engine.inverse_torques_layout``)."""
    kin, points = np.empty((joint_parent.shape[0], N_KIN)), np.empty((3, mass.shape[0]))
    _inverse_torques(z, zd, zdd, joint_parent, joint_offset, joint_at_parent, joint_at_child, pt_owner, pt_local,
                     pt_index, mass, q_ext, kin, points, out)


# ---------------------------------------------------------------------- sensitivities of a stage
# (the tangents of ``fdbench.multibody.sensitivity``, run by the driver after each stage)
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
def _stage_sensitivity(y, k, S, U, acc, weight, next_step, half, G, torque_sign, work, scratch, layout):
    """The tangents K_s of the stage at the state y (derivative k) for every parameter, from their
    inputs U (n_state, P) (the tangents of the stage's state): acc += weight K_s, then
    U = S + next_step K_s (the next stage's input). ``work`` holds the stage's factor and
    multipliers (``_drive``'s K, rhs, aux); G[half, q] is d tau / d p_q (N m per parameter unit), which
    moves the generalised force of body b's angle by torque_sign[b, q] G[half, q]; layout: the
    penalty layout (``rk4``'s order); scratch: values, inv_diag, dtau, dr, dlam, dpivot,
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


# ---------------------------------------------------------------------- the RK4 driver (eq. 12 under a feedback law)
@njit(error_model="numpy")
def _drive(y0, dt, n_steps, start, tau, ref, refd, refdd, kp, kd, mode, gains, offset, pt_index, pt_fixed, body_pts,
           body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent, n_offset,
           n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states, rates, applied, K, rhs, aux,
           G, torque_sign, every, dz):
    """``rk4`` whose grid starts at row ``start`` of tau, ref, refd, refdd and gains (step i uses rows
    start + 2 i, start + 2 i + 1, start + 2 i + 2); with n_steps 0 it evaluates the state derivative
    of y0 alone (into rates[0]). K (n_p, n_p), rhs (n_p,), aux (J, N_AUX): work arrays that hold,
    after the call, the last stage's L D L^T factor of the points' matrix, its solution (the point
    accelerations, m/s^2) and per body the multiplier, pivot, velocity term and form.

    With dz of more than zero rows, also the forward sensitivities of the joint angles
    (``fdbench.multibody.sensitivity.rk4_sensitivity``): G (2 n_steps + 1, P) d tau / d p on the
    grid, torque_sign (J, P) the signs with which parameter q moves the body angles' generalised
    forces, dz (n_steps // every + 1, J, P) the derivatives at every ``every``-th step reached.

    Speed: the stage code is written once, as closures over this function's arrays (numba inlines
    them without the reference counting that array arguments of inlined functions cost at every
    call), and runs in a loop over the four stages; ``state`` holds the stage's state, ``ks``
    0 to 3 its derivatives k1 to k4. The operations on every number are the plain formulas'."""
    n_p, n_b = base.shape[0], joint_parent.shape[0]
    n_q = n_p + n_b
    n = 2 * n_q
    alpha, txo, om2, switch = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2], params[SWITCH_COS]
    p4 = 4 * alpha
    one_point = n_p == 2 and first[1] == 0  # one free point: the solve's unrolled form
    # the work arrays: views of one buffer (one allocation per call; the sensitivities call this per stage)
    n_nominal = n_mass.shape[0]
    vectors = 6 * n + 5 * n_b  # y, the stage's state, k1 to k4; torque, q_phi, z, zd, v
    tables = n_b * (N_KIN + 6)  # kin; trig (sin, cos); shape (d, beta, fixed point i)
    buffer, ends = np.zeros(vectors + tables + 3 * n_nominal), np.empty((n_b, 2), dtype=np.int64)
    y, state, ks = buffer[:n], buffer[n:2 * n], buffer[2 * n:6 * n].reshape((4, n))
    per_joint = buffer[6 * n:vectors].reshape((5, n_b))
    torque, q_phi, z, zd, v = per_joint[0], per_joint[1], per_joint[2], per_joint[3], per_joint[4]
    kin = buffer[vectors:vectors + n_b * N_KIN].reshape((n_b, N_KIN))
    trig = buffer[vectors + n_b * N_KIN:vectors + n_b * (N_KIN + 2)].reshape((n_b, 2))
    shape = buffer[vectors + n_b * (N_KIN + 2):vectors + tables].reshape((n_b, 4))
    points = buffer[vectors + tables:].reshape((3, n_nominal))
    for m in range(n):
        y[m] = y0[m]
    sensitive, P = dz.shape[0] > 0, G.shape[1]  # the sensitivities: S = dy/dp, stage inputs U, their sum acc
    S, U, acc = np.zeros((n, P)), np.zeros((n, P)), np.zeros((n, P))
    tangent_work = (np.empty((n_b, N_STAGE)), np.empty(n_p), np.empty((n_b, P)), np.empty((n_p, P)),
                    np.empty((n_b, P)), np.empty((n_b, P)), np.empty((n_b, P)), np.empty((n, P)))
    factor = (K, rhs, aux)
    layout = (pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext,
              params)
    # per body, hoisted: the coordinate indices of its points i and j (i: FIXED on ground), and its
    # d (m), beta (rad) and point i's position (m) where it is fixed
    for b in range(n_b):
        ends[b, 0], ends[b, 1] = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        shape[b, 0], shape[b, 1] = body_geom[b, LENGTH], body_geom[b, BETA]
        shape[b, 2], shape[b, 3] = pt_fixed[body_pts[b, 0], 0], pt_fixed[body_pts[b, 0], 1]

    def joint_point(b):
        """x, y, x', y' of body b's point i in the stage's state (fixed: its position, zero velocity)."""
        k = ends[b, 0]
        if k < 0:
            return shape[b, 2], shape[b, 3], 0.0, 0.0
        return state[k], state[k + 1], state[n_q + k], state[n_q + k + 1]

    def violation():
        """max |Phi_i| (m^2 and m) of the stage's state: distances, angles (the form in force), linear;
        sin and cos of the bodies' angles into trig, for the state's first stage."""
        worst = 0.0
        for b in range(n_b):
            xi, yi, _, _ = joint_point(b)
            kj = ends[b, 1]
            dx, dy, d = state[kj] - xi, state[kj + 1] - yi, shape[b, 0]
            psi = state[n_p + b] + shape[b, 1]
            s, c = math.sin(psi), math.cos(psi)
            trig[b, 0], trig[b, 1] = s, c
            angle = dy - d * s if abs(c) >= switch else dx - d * c
            worst = max(worst, max(abs(dx * dx + dy * dy - d * d), abs(angle)))
        for r in range(lin_const.shape[0]):
            value = lin_const[r]
            for e in range(lin_idx.shape[1]):
                if lin_idx[r, e] >= 0:
                    value += lin_coef[r, e] * state[lin_idx[r, e]]
            worst = max(worst, abs(value))
        return worst

    def law(half):
        """The applied joint torques (N m) at the stage's state and grid row ``half`` into torque
        (``rk4``'s modes). ref holds the reference joint angles plus the plant's joint offsets, as
        z here is the difference of the body angles."""
        for k in range(n_b):
            p = joint_parent[k]
            z[k] = state[n_p + k] - (state[n_p + p] if p >= 0 else 0.0)
            zd[k] = state[n_q + n_p + k] - (state[n_q + n_p + p] if p >= 0 else 0.0)
        if mode == GAINS:
            for k in range(n_b):
                total = tau[half, k]
                for j in range(n_b):
                    total += gains[half, k, j] * (ref[half, j] - z[j])
                for j in range(n_b):
                    total += gains[half, k, n_b + j] * (refd[half, j] - zd[j])
                torque[k] = total
        elif mode == COMPUTED:
            for k in range(n_b):
                v[k] = refdd[half, k] + kp[k] * (ref[half, k] - z[k]) + kd[k] * (refd[half, k] - zd[k])
                z[k] -= offset[k]
            _inverse_torques(z, zd, v, n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass,
                             n_q_ext, kin, points, torque)
            for k in range(n_b):
                torque[k] += tau[half, k]
        else:
            for k in range(n_b):
                torque[k] = tau[half, k] + kp[k] * (ref[half, k] - z[k]) + kd[k] * (refd[half, k] - zd[k])

    def assemble(carried):
        """The points' matrix K (its envelope) and right-hand side rhs of eq. 12 at the stage's state
        under the joint torques, and per body the angle row's values into aux. carried: the state's
        sin and cos are those in trig (the state's violation was computed)."""
        for k in range(n_b):  # joint torques -> generalised forces of the absolute angles
            q_phi[k] = torque[k]
        for k in range(n_b):
            if joint_parent[k] >= 0:
                q_phi[joint_parent[k]] -= torque[k]
        for r in range(n_p):
            rhs[r] = q_ext[r]
            for c in range(first[r], r + 1):
                K[r, c] = base[r, c]
        for r in range(lin_const.shape[0]):  # linear constraints: their J^T J is in base
            phi, rate = lin_const[r], 0.0
            for e in range(lin_idx.shape[1]):
                k = lin_idx[r, e]
                if k >= 0:
                    phi += lin_coef[r, e] * state[k]
                    rate += lin_coef[r, e] * state[n_q + k]
            cc = alpha * (txo * rate + om2 * phi)
            for e in range(lin_idx.shape[1]):
                k = lin_idx[r, e]
                if k >= 0:
                    rhs[k] -= lin_coef[r, e] * cc
        for b in range(n_b):
            ki, kj = ends[b, 0], ends[b, 1]
            xi, yi, vxi, vyi = joint_point(b)
            xj, yj, vxj, vyj = state[kj], state[kj + 1], state[n_q + kj], state[n_q + kj + 1]
            dx, dy, dvx, dvy = xj - xi, yj - yi, vxj - vxi, vyj - vyi
            d = shape[b, 0]
            w = state[n_q + n_p + b]
            if carried:
                s, c = trig[b, 0], trig[b, 1]
            else:
                psi = state[n_p + b] + shape[b, 1]
                s, c = math.sin(psi), math.cos(psi)
            # distance: Phi = |dr|^2 - d^2, J = 2 dr on j, -2 dr on i
            cd = 2 * (dvx * dvx + dvy * dvy) + txo * 2 * (dx * dvx + dy * dvy) + om2 * (dx * dx + dy * dy - d * d)
            K[kj, kj] += p4 * dx * dx
            K[kj + 1, kj] += p4 * dx * dy
            K[kj + 1, kj + 1] += p4 * dy * dy
            rhs[kj] -= 2 * alpha * dx * cd
            rhs[kj + 1] -= 2 * alpha * dy * cd
            if ki >= 0:
                K[ki, ki] += p4 * dx * dx
                K[ki + 1, ki] += p4 * dx * dy
                K[ki + 1, ki + 1] += p4 * dy * dy
                K[kj, ki] -= p4 * dx * dx
                K[kj, ki + 1] -= p4 * dx * dy
                K[kj + 1, ki] -= p4 * dx * dy
                K[kj + 1, ki + 1] -= p4 * dy * dy
                rhs[ki] += 2 * alpha * dx * cd
                rhs[ki + 1] += 2 * alpha * dy * cd
            # angle: its row gives the multiplier lambda = Q_phi / (dPhi/dphi)
            if abs(c) >= switch:  # the sin form, (y_j - y_i) - d sin(psi)
                pivot = -d * c
                ca = d * s * w * w + txo * (dvy - d * c * w) + om2 * (dy - d * s)
                axis = 1
            else:  # the cos form, (x_j - x_i) - d cos(psi)
                pivot = d * s
                ca = d * c * w * w + txo * (dvx + d * s * w) + om2 * (dx - d * c)
                axis = 0
            lam = q_phi[b] / pivot
            rhs[kj + axis] -= lam
            if ki >= 0:
                rhs[ki + axis] += lam
            aux[b, LAMBDA], aux[b, PIVOT], aux[b, VELOCITY_TERM], aux[b, FORM] = lam, pivot, ca, axis

    def solve():
        """Solve K x = rhs in place (x into rhs) for K symmetric positive definite, its lower triangle
        given inside the envelope first[r] <= c <= r, by L D L^T (L into K's strict lower triangle, D
        on its diagonal). Returns OK, NONFINITE for a pivot that is NaN, or SINGULAR for one that is
        not positive (rank lost; rhs is then unfinished)."""
        if one_point:  # the same operations, unrolled for one free point (a 2 x 2 matrix)
            if math.isnan(K[0, 0]):
                return NONFINITE
            if not K[0, 0] > 0.0:
                return SINGULAR
            l10 = K[1, 0] / K[0, 0]
            diag = K[1, 1] - l10 * K[1, 0]
            if math.isnan(diag):
                return NONFINITE
            if not diag > 0.0:
                return SINGULAR
            K[1, 0], K[1, 1] = l10, diag
            rhs[1] = (rhs[1] - l10 * rhs[0]) / diag
            rhs[0] = rhs[0] / K[0, 0] - l10 * rhs[1]
            return OK
        status = OK
        for r in range(n_p):
            fr = first[r]
            for c in range(fr, r):
                total = K[r, c]
                for k in range(max(fr, first[c]), c):
                    total -= K[r, k] * K[c, k]  # K[r, k] holds L[r, k] D[k] until row r is done
                K[r, c] = total
            diag = K[r, r]
            for c in range(fr, r):
                lrc = K[r, c] / K[c, c]
                diag -= lrc * K[r, c]
                K[r, c] = lrc
            if math.isnan(diag):
                status = NONFINITE
                break
            if not diag > 0.0:
                status = SINGULAR
                break
            K[r, r] = diag
        if status == OK:
            for r in range(n_p):  # L z = rhs
                total = rhs[r]
                for k in range(first[r], r):
                    total -= K[r, k] * rhs[k]
                rhs[r] = total
            for r in range(n_p):
                rhs[r] /= K[r, r]
            for r in range(n_p - 1, -1, -1):  # L^T x = z, column by column
                x = rhs[r]
                for k in range(first[r], r):
                    rhs[k] -= K[r, k] * x
        return status

    def derivative(row):
        """y' = [q', q''] of eq. 12 at the stage's state under torque into ks[row] (row 0: the
        step's start, whose sin and cos are in trig). Returns OK, or the solve's status (then the
        accelerations are left unfinished)."""
        for k in range(n_q):
            ks[row, k] = state[n_q + k]
        assemble(row == 0)
        status = solve()
        if status == OK:
            for r in range(n_p):
                ks[row, n_q + r] = rhs[r]
            for b in range(n_b):
                ki, kj = ends[b, 0], ends[b, 1]
                axis = int(aux[b, FORM])
                rel = rhs[kj + axis] - (rhs[ki + axis] if ki >= 0 else 0.0)
                ks[row, n_q + n_p + b] = (aux[b, LAMBDA] / alpha - aux[b, VELOCITY_TERM] - rel) / aux[b, PIVOT]
        return status

    for m in range(n):
        state[m] = y[m]
    max_viol = violation()
    code = OK
    for i in range(n_steps + 1):
        j = start + 2 * i
        for stage in range(4):  # k1 at y, k2 and k3 at the half step, k4 at the full step
            if stage > 0:
                h = dt if stage == 3 else 0.5 * dt
                for m in range(n):
                    state[m] = y[m] + h * ks[stage - 1, m]
            law(j + (stage + 1) // 2)
            code = derivative(stage)
            if stage == 0:
                for m in range(n):
                    states[i, m] = y[m]
                    rates[i, m] = ks[0, m]
                for m in range(n_b):
                    applied[i, m] = torque[m]
                if sensitive and i % every == 0:
                    for b in range(n_b):
                        parent = joint_parent[b]
                        for q in range(P):
                            dz[i // every, b, q] = S[n_p + b, q] - (S[n_p + parent, q] if parent >= 0 else 0.0)
            if code != OK or i == n_steps:
                break
            if sensitive:  # K_s of this stage: acc += weight K_s, U = S + (the next stage's step) K_s
                if stage == 0:
                    for m in range(n):
                        for q in range(P):
                            U[m, q], acc[m, q] = S[m, q], 0.0
                weight = 1.0 if stage == 0 or stage == 3 else 2.0
                next_step = 0.5 * dt if stage < 2 else (dt if stage == 2 else 0.0)
                _stage_sensitivity(state, ks[stage], S, U, acc, weight, next_step, j + (stage + 1) // 2, G,
                                   torque_sign, factor, tangent_work, layout)
        if code != OK:
            return code, i, max_viol
        if i == n_steps:
            break
        finite = True
        for m in range(n):
            state[m] = y[m] + dt / 6.0 * (ks[0, m] + 2.0 * ks[1, m] + 2.0 * ks[2, m] + ks[3, m])
            finite = finite and math.isfinite(state[m])
        if not finite:
            return NONFINITE, i, max_viol
        viol = violation()
        if viol > params[VIOLATION]:
            return CONSTRAINT, i, max(max_viol, viol)
        max_viol = max(max_viol, viol)
        if sensitive:
            for m in range(n):
                for q in range(P):
                    S[m, q] += dt / 6.0 * acc[m, q]
        for m in range(n):
            y[m] = state[m]
    return OK, n_steps, max_viol


@njit(inline="always")
def _no_sensitivities(n_b):
    """``_drive``'s sensitivity arguments for a run without them: G, torque_sign, every, dz."""
    return np.zeros((1, 0)), np.zeros((n_b, 0)), 1, np.zeros((0, n_b, 0))


@njit(error_model="numpy")
def rk4(y0, dt, n_steps, tau, ref, refd, refdd, kp, kd, mode, gains, offset, pt_index, pt_fixed, body_pts, body_geom,
        joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent, n_offset, n_at_parent,
        n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states, rates, applied):
    """Classical RK4 of eq. 12 over n_steps steps of dt (s) under the feedback law ``mode`` (PD,
    COMPUTED or GAINS), from the state y0 (n_state,). mode PD: tau + kp (ref - z) + kd (refd - z');
    GAINS: tau + gains[half] [ref - z, refd - z'], accumulated term by term onto tau (so that
    K = [diag kp, diag kd] gives PD's numbers to the last bit); COMPUTED: the believed model's
    (``nominal``) inverse dynamics at (z, z') for the accelerations refdd + kp e + kd e', plus tau.

    tau, ref, refd, refdd: shape (2 n_steps + 1, J), the feedforward torques (N m), the reference
    joint angles plus the joint offsets (rad), velocities (rad/s) and accelerations (rad/s^2) on
    the half-step grid t_k = k dt / 2; kp, kd: shape (J,) (PD: N m/rad, N m s/rad; COMPUTED: 1/s^2,
    1/s); gains: shape (2 n_steps + 1, J, 2J) for GAINS (N m/rad, N m s/rad), any (m, J, 2J)
    otherwise; offset: the plant's joint offsets (rad); then the penalty layout and the believed
    model's inverse-dynamics layout (``Engine.simulation_layout``). Fills states (n+1, n_state),
    rates (n+1, n_state) (the state derivative) and applied (n+1, J) (N m) up to the last step
    reached. Returns (status, steps_done, max constraint violation)."""
    n_p, n_b = base.shape[0], joint_parent.shape[0]
    return _drive(y0, dt, n_steps, 0, tau, ref, refd, refdd, kp, kd, mode, gains, offset, pt_index, pt_fixed, body_pts,
                  body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent,
                  n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states, rates,
                  applied, np.zeros((n_p, n_p)), np.zeros(n_p), np.zeros((n_b, N_AUX)), *_no_sensitivities(n_b))


@njit(error_model="numpy")
def derivatives(states, tau, ref, refd, refdd, kp, kd, mode, gains, offset, pt_index, pt_fixed, body_pts, body_geom,
                joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent, n_offset,
                n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, out, applied):
    """The state derivatives (into out, shape (k, n_state)) and the applied joint torques (N m, into
    applied, shape (k, J)) of k states (shape (k, n_state)) under ``rk4``'s feedback law, row i with
    row i of tau, ref, refd, refdd (each (k, J)) and of gains ((k, J, 2J) for GAINS); the
    accelerations are NaN where the points' matrix is singular."""
    n_p, n_b, n = base.shape[0], joint_parent.shape[0], states.shape[1]
    K, rhs, aux = np.zeros((n_p, n_p)), np.zeros(n_p), np.zeros((n_b, N_AUX))
    state, rate, torque = np.empty((1, n)), np.empty((1, n)), np.empty((1, n_b))
    no_sensitivities = _no_sensitivities(n_b)
    for i in range(states.shape[0]):
        code, _, _ = _drive(states[i], 0.0, 0, i, tau, ref, refd, refdd, kp, kd, mode, gains, offset, pt_index,
                            pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base,
                            q_ext, params, n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index,
                            n_mass, n_q_ext, state, rate, torque, K, rhs, aux, *no_sensitivities)
        out[i] = rate[0]
        applied[i] = torque[0]
        if code != OK:
            out[i, n // 2:] = np.nan


@njit(error_model="numpy")
def constraint_violation(y, offset, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef,
                         lin_const, first, base, q_ext, params, n_parent, n_offset, n_at_parent, n_at_child, n_owner,
                         n_local, n_index, n_mass, n_q_ext):
    """max |Phi_i| (m^2 and m) of the state y (n_state,), the angle constraints in the form in force
    (the value ``rk4`` checks), over the simulation layout (``Engine.simulation_layout``)."""
    n_p, n_b, n = base.shape[0], joint_parent.shape[0], y.shape[0]
    rows, gains = np.zeros((1, n_b)), np.zeros((1, n_b, 2 * n_b))
    _, _, worst = _drive(y, 0.0, 0, 0, rows, rows, rows, rows, rows[0], rows[0], PD, gains, offset, pt_index, pt_fixed,
                         body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params,
                         n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext,
                         np.empty((1, n)), np.empty((1, n)), np.empty((1, n_b)), np.zeros((n_p, n_p)), np.zeros(n_p),
                         np.zeros((n_b, N_AUX)), *_no_sensitivities(n_b))
    return worst


# ---------------------------------------------------------------------- the population (eq. 18)
@njit(nogil=True)
def tracking_objective(states, done, every, angles_ref, n_steps, penalty_weight, offset, joint_parent, n_p):
    """Eq. 18 for J joints from a simulation's states, shape (n_steps + 1, n_state), filled up to
    step ``done``: the RMSE (deg) of the joint angles (the body angles' differences minus the
    offsets) at the motion's samples (every ``every``-th step; desired angles angles_ref (rad),
    shape (samples, J)) over the samples reached and all joints, plus penalty_weight times the
    fraction of the steps not reached. The squared errors are summed sample by sample, joint by
    joint in order; a non-finite RMSE counts as 0."""
    n_b = angles_ref.shape[1]
    count = done // every + 1
    total = 0.0
    for k in range(count):
        y = states[k * every]
        for j in range(n_b):
            p = joint_parent[j]
            z = y[n_p + j] - (y[n_p + p] if p >= 0 else 0.0) - offset[j]
            error = (z - angles_ref[k, j]) * DEGREES_PER_RADIAN
            total += error * error
    rmse = math.sqrt(total / (n_b * count))
    if not math.isfinite(rmse):
        rmse = 0.0
    return rmse + penalty_weight * (1.0 - done / n_steps)


@njit(nogil=True)
def rk4_candidates(y0, dt, n_steps, tau, ref, refd, every, angles_ref, penalty_weight, offset, pt_index, pt_fixed,
                   body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params,
                   n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states,
                   rates, applied, objective, candidate, stride, step, budget):
    """Open-loop RK4 (``rk4`` in PD mode with zero gains) and eq. 18 (``tracking_objective``) for
    candidates candidate, candidate + stride, ... of tau (N m, shape (lam, 2 n_steps + 1, J)), for
    ``fdbench.population.Population``, at most ``budget`` steps in all: the first candidate resumes at
    step ``step`` (its states up to there in the work buffers, from the call before), each chunk from
    the last state of the one before at the same grid row, so the numbers are those of one call.
    ref, refd: the half-step references as for ``rk4`` (unused by an open loop but for the layout of
    its call); states (n+1, n_state), rates (n+1, n_state), applied (n+1, J): this thread's work
    buffers, reused candidate after candidate; objective (lam,): filled for the candidates finished.
    Returns the (candidate, step) to resume at (a candidate past the last: all done). Runs without
    the GIL."""
    n_b = joint_parent.shape[0]
    zero, no_gains = np.zeros(n_b), np.zeros((1, n_b, 2 * n_b))
    n_p = base.shape[0]
    while candidate < tau.shape[0] and budget > 0:
        n = min(budget, n_steps - step)
        low, high = 2 * step, 2 * (step + n) + 1
        y = y0 if step == 0 else states[step].copy()
        code, done, _ = rk4(y, dt, n, tau[candidate, low:high], ref[low:high], refd[low:high], ref[low:high], zero,
                            zero, PD, no_gains, offset, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx,
                            lin_coef, lin_const, first, base, q_ext, params, n_parent, n_offset, n_at_parent,
                            n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states[step:step + n + 1],
                            rates[step:step + n + 1], applied[step:step + n + 1])
        step, budget = step + done, budget - max(done, 1)  # steps run: a failing candidate costs few
        if code != OK or step == n_steps:
            objective[candidate] = tracking_objective(states, step, every, angles_ref, n_steps, penalty_weight,
                                                      offset, joint_parent, n_p)
            candidate, step = candidate + stride, 0
    return candidate, step
