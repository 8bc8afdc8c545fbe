"""Compiled eq. 12 for models with free joints and joint paths: the engine's mixed coordinates
(``fdbench.multibody.engine``) with two more kinds of joint, assembled and solved densely.

What the two joints add to the engine's formulation:

* A free joint's body has its joint point i among the free points with no constraint to ground;
  its coordinates are the body's angle (minus the offset) and point i's x and y (minus
  ``at_parent``), and the generalised forces of x and y (N) act on point i's coordinates.
* A joint with a path makes the child's point i a free point tied to its parent by two
  constraints, r_i - r_pi - G(theta) e_p = 0 with e_p = r_pj - r_pi (the parent's basic points),
  G = c1 I + c2 R90 and (c1, c2) the parent-frame point at_parent + path(theta) in the parent's
  basic-point frame (``engine._point_map``; linear in the path's offset s: (c1, c2) = base + L s);
  on ground, r_i - at_parent - path(theta) = 0. theta = phi_child - phi_parent - offset, so these
  constraints hold the angles too: their Jacobian has -G' e_p on the child's angle and +G' e_p on
  the parent's, and their velocity term is -2 G' theta' e_p' - G'' theta'^2 e_p. The joint's
  torque acts on the angles as a pin's does. The path's splines (``fdbench.multibody.spline``) are
  evaluated here from a table of their pieces.

Everything else is the engine's: the distance and angle constraints of every body (the angle's
sin or cos form chosen from the state, ``params[SWITCH_COS]``), the extra points' linear
constraints, the points' mass matrix and Q_ext. Eq. 12, (M + alpha J^T J) q'' = Q - alpha J^T (J'
q' + 2 xi omega Phi' + omega^2 Phi), is solved by a Cholesky factorisation of the whole (points
and angles) leading matrix inside its envelope, positive definite for positive masses and
inertias (every angle has its angle constraint); each constraint row is kept as its few nonzero
entries. Computed-torque control takes the believed model's inverse dynamics (eq. 3) through the
joints' velocity transform: a pin's lever, a path's direction, a free joint's world axes. The RK4
driver is ``kernels._drive``'s, step for step: the same half-step grid, feedback laws, violation
check and status codes; ``rk4_candidates`` runs a population of open-loop candidates with eq. 18
(angles in deg plus translations in cm); with dz, the driver also carries the forward
sensitivities of an open-loop run (``_stage_tangents`` after each stage; for
``fdbench.multibody.sensitivity.rk4_sensitivity_dense``).

Speed (``python benchmarks/bench_engine.py``): about 17 us per RK4 step for OpenSim's gait model
(10 coordinates, n_q 32), against about 1.1 ms for the same equations by numpy before.

Layouts (``Engine.dense_layout``, ``Engine.dense_inverse_layout``), arrays only, so that one
compilation serves every model:

* the dense layout: body_int (B, N_BODY_INT), body_float (B, N_BODY_FLOAT), path_body (n_paths,),
  path_float (n_paths, N_PATH_FLOAT), knots (n_knots, 5), spline_start (2 n_paths + 1,), lin_idx,
  lin_coef, lin_const, mass (n_p, n_p), q_ext (n_p,), params, load_int (L, N_LOAD_INT), first
  (n_q,): the first column of each row of the leading matrix's envelope (its lower triangle, the
  entries any state can fill: the mass matrix's and those of every constraint row's columns);
* the inverse layout: body_int, body_float, knots, spline_start, load_int, pt_owner, pt_local,
  pt_index, mass, q_ext.

External loads from data (``fdbench.multibody.loads``): per load its body and the frames of its
force and point (load_int), and per run their values on the half-step grid, loads (rows, L,
N_LOAD): in eq. 12 F on the body's joint point i and (P - r_i) x F + M on its angle; in the inverse
dynamics their generalised forces J_P^T F (and M on every angle on the body's path) subtracted.

Path m's x spline is spline 2 m, its y spline 2 m + 1: rows spline_start[s] to spline_start[s + 1]
of knots, each (x, y, b, c, d) of a piece y + b u + c u^2 + d u^3, u = t - x.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..population import DEGREES_PER_RADIAN
from .simulation import CM_PER_M
from .kernels import (ACC, ALPHA, COMPUTED, CONSTRAINT, COS, GAINS, JOINT_X, JOINT_Y, NONFINITE, OK, OMEGA2,
                      ORIGIN_AX, ORIGIN_AY, ORIGIN_X, ORIGIN_Y, PD, PHI, RATE, SIN, SINGULAR, SWITCH_COS, TWO_XI_OMEGA,
                      VIOLATION, _body_point)
from .kernels import N_KIN as N_KIN_BANDED

# body_int columns: the coordinate indices of the body's points i (-1: fixed) and j, its parent
# body (-1: ground), its joint's first coordinate, 1 for a free joint, its path (-1: none)
KI, KJ, PARENT, COLUMN, FREE, PATH, N_BODY_INT = range(7)
# body_float columns: d (m), beta (rad), point i where fixed (m), the joint's offset (rad),
# at_parent (m), at_child (m)
D, BETA, FIXED_X, FIXED_Y, OFFSET, AT_PARENT_X, AT_PARENT_Y, AT_CHILD_X, AT_CHILD_Y, N_BODY_FLOAT = range(10)
# path_float columns: (c1, c2) = base + L s of the path's point in its parent's basic-point frame
BASE_1, BASE_2, L_11, L_12, L_21, L_22, N_PATH_FLOAT = range(7)
# columns of the inverse dynamics' per-body scratch: the banded kernels' (``kernels.PHI`` ...
# ``ORIGIN_AY``), then the path's world direction per radian (m/rad; 0 without a path)
DIR_X, DIR_Y, N_KIN = N_KIN_BANDED, N_KIN_BANDED + 1, N_KIN_BANDED + 2
LOAD_BODY, FORCE_FRAME, POINT_FRAME, N_LOAD_INT = range(4)  # load_int columns (frames: -1 ground)
FX, FY, PX, PY, MOMENT, N_LOAD = range(6)  # a load's values: force (N), point (m), free moment (N m)
MAX_ENTRIES = 8  # nonzero entries of a constraint row (a path's row has up to 7)
CHECK, ASSEMBLE = 0, 1  # what the driver's ``constraints`` does with each row


@njit
def n_rows(body_int, path_body, lin_const):
    """The number of constraint rows: distance and angle per body, the linear rows, two per path."""
    return 2 * body_int.shape[0] + lin_const.shape[0] + 2 * path_body.shape[0]


@njit(error_model="numpy", inline="always")
def _spline_at(knots, first, last, t):
    """(value, first, second, third derivative) at t of the spline in rows first .. last - 1 of
    knots: ``spline.Spline.at``'s formulas (its end lines outside the knots)."""
    if t < knots[first, 0]:
        return knots[first, 1] + (t - knots[first, 0]) * knots[first, 2], knots[first, 2], 0.0, 0.0
    if t > knots[last - 1, 0]:
        return knots[last - 1, 1] + (t - knots[last - 1, 0]) * knots[last - 1, 2], knots[last - 1, 2], 0.0, 0.0
    low, high = first, last - 1  # the last knot <= t, at most the last piece's start
    while high - low > 1:
        middle = (low + high) // 2
        if knots[middle, 0] <= t:
            low = middle
        else:
            high = middle
    u = t - knots[low, 0]
    y, b, c, d = knots[low, 1], knots[low, 2], knots[low, 3], knots[low, 4]
    return y + u * (b + u * (c + u * d)), b + u * (2.0 * c + 3.0 * u * d), 2.0 * c + 6.0 * u * d, 6.0 * d


@njit(error_model="numpy", inline="always")
def _inverse(z, zd, zdd, loads, body_int, body_float, knots, spline_start, load_int, pt_owner, pt_local, pt_index, mass,
             q_ext, kin, points, out):
    """Eq. 3, tau = R^T (M_p p'' - Q_ext), into out (J,) (N m; N for a free joint's x and y) for the
    coordinates z, rates zd and accelerations zdd (J,): the bodies' kinematics from ground out, the
    free points' positions and accelerations, then each point's force projected on every joint on
    its owner's path (a pin's lever R90 (r_P - r_joint) plus a path's direction, a free joint's
    world axes), less the external loads' (values loads (L, N_LOAD)). kin (B, N_KIN), points (3, n_p):
    scratch."""
    n_b = body_int.shape[0]
    for k in range(n_b):
        p, col = body_int[k, PARENT], body_int[k, COLUMN]
        if p < 0:
            phi, w, al = z[col] + body_float[k, OFFSET], zd[col], zdd[col]
            rx, ry, ax, ay = body_float[k, AT_PARENT_X], body_float[k, AT_PARENT_Y], 0.0, 0.0
            if body_int[k, FREE] == 1:
                rx, ry, ax, ay = rx + z[col + 1], ry + z[col + 2], zdd[col + 1], zdd[col + 2]
            pc, ps, pw, pal = 1.0, 0.0, 0.0, 0.0
        else:
            phi, w, al = kin[p, PHI] + z[col] + body_float[k, OFFSET], kin[p, RATE] + zd[col], kin[p, ACC] + zdd[col]
            rx, ry, ax, ay = _body_point(kin, p, body_float[k, AT_PARENT_X], body_float[k, AT_PARENT_Y])
            pc, ps, pw, pal = kin[p, COS], kin[p, SIN], kin[p, RATE], kin[p, ACC]
        kin[k, DIR_X], kin[k, DIR_Y] = 0.0, 0.0
        m = body_int[k, PATH]
        if m >= 0:  # the point moves along the path in the parent's frame
            theta, rate, acc = z[col], zd[col], zdd[col]
            sx0, sx1, sx2, _ = _spline_at(knots, spline_start[2 * m], spline_start[2 * m + 1], theta)
            sy0, sy1, sy2, _ = _spline_at(knots, spline_start[2 * m + 1], spline_start[2 * m + 2], theta)
            arm_x, arm_y = sx0 * pc - sy0 * ps, sx0 * ps + sy0 * pc
            d1x, d1y = sx1 * pc - sy1 * ps, sx1 * ps + sy1 * pc
            d2x, d2y = sx2 * pc - sy2 * ps, sx2 * ps + sy2 * pc
            rx, ry = rx + arm_x, ry + arm_y
            ax = ax - pal * arm_y - pw * pw * arm_x - 2 * pw * d1y * rate + d2x * rate * rate + d1x * acc
            ay = ay + pal * arm_x - pw * pw * arm_y + 2 * pw * d1x * rate + d2y * rate * rate + d1y * acc
            kin[k, DIR_X], kin[k, DIR_Y] = d1x, d1y
        c, s = math.cos(phi), math.sin(phi)
        arm_x = body_float[k, AT_CHILD_X] * c - body_float[k, AT_CHILD_Y] * s
        arm_y = body_float[k, AT_CHILD_X] * s + body_float[k, AT_CHILD_Y] * c
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
    for j in range(out.shape[0]):
        out[j] = 0.0
    for pt in range(pt_index.shape[0]):
        i = pt_index[pt]
        if i < 0:
            continue
        fx, fy = points[2, i], points[2, i + 1]
        b = pt_owner[pt]
        while b >= 0:
            col = body_int[b, COLUMN]
            lever_x, lever_y = points[0, i] - kin[b, JOINT_X], points[0, i + 1] - kin[b, JOINT_Y]
            out[col] += lever_x * fy - lever_y * fx + kin[b, DIR_X] * fx + kin[b, DIR_Y] * fy
            if body_int[b, FREE] == 1:
                out[col + 1] += fx
                out[col + 2] += fy
            b = body_int[b, PARENT]
    for k in range(load_int.shape[0]):  # the loads' generalised forces, subtracted
        fx, fy, px, py = loads[k, FX], loads[k, FY], loads[k, PX], loads[k, PY]
        frame = load_int[k, FORCE_FRAME]
        if frame >= 0:
            fx, fy = fx * kin[frame, COS] - fy * kin[frame, SIN], fx * kin[frame, SIN] + fy * kin[frame, COS]
        frame = load_int[k, POINT_FRAME]
        if frame >= 0:
            px, py = (kin[frame, ORIGIN_X] + px * kin[frame, COS] - py * kin[frame, SIN],
                      kin[frame, ORIGIN_Y] + px * kin[frame, SIN] + py * kin[frame, COS])
        b = load_int[k, LOAD_BODY]
        while b >= 0:
            col = body_int[b, COLUMN]
            out[col] -= ((px - kin[b, JOINT_X]) * fy - (py - kin[b, JOINT_Y]) * fx + kin[b, DIR_X] * fx
                         + kin[b, DIR_Y] * fy + loads[k, MOMENT])
            if body_int[b, FREE] == 1:
                out[col + 1] -= fx
                out[col + 2] -= fy
            b = body_int[b, PARENT]


@njit(error_model="numpy")
def inverse_torques(z, zd, zdd, loads, body_int, body_float, knots, spline_start, load_int, pt_owner, pt_local,
                    pt_index, mass, q_ext, out):
    """The generalised forces (N m; N for a free joint's x and y) of the minimal motion (z, zd, zdd)
    (shape (J,)) under the external loads' values loads (L, N_LOAD) into out (J,): eq. 3 over the
    inverse layout (``Engine.dense_inverse_layout``)."""
    kin, points = np.empty((body_int.shape[0], N_KIN)), np.empty((3, mass.shape[0]))
    _inverse(z, zd, zdd, loads, body_int, body_float, knots, spline_start, load_int, pt_owner, pt_local, pt_index, mass,
             q_ext, kin, points, out)


# ---------------------------------------------------------------------- the sensitivities of a stage
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
def _solve_factored(L, first, X):
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
    parameter q moving coordinate param_col[q]. jac (n_q, n_state), solved_rows (n_q, J), moved
    (n_q, P): scratch."""
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
    _solve_factored(L, first, jac)
    _solve_factored(L, first, solved_rows)
    np.dot(jac, U, moved)
    for r in range(n_q):
        for q in range(U.shape[1]):
            dk[r, q] = U[n_q + r, q]
            dk[n_q + r, q] = moved[r, q] + solved_rows[r, param_col[q]] * g[q]


# ---------------------------------------------------------------------- the RK4 driver (eq. 12 under a feedback law)
@njit(error_model="numpy")
def _drive(y0, dt, n_steps, start, tau, ref, refd, refdd, kp, kd, mode, gains, loads, n_loads, body_int, body_float,
           path_body, path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params, load_int,
           first, n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local, n_index, n_mass,
           n_q_ext, states, rates, applied, phi_rows, jv_rows, G, param_col, every, dz):
    """``rk4`` whose grid starts at row ``start`` of tau, ref, refd, refdd and gains; with n_steps 0
    it evaluates the state derivative of y0 alone (into rates[0]), with -1 only the constraints of
    y0 (the returned violation). phi_rows, jv_rows (n_rows,):
    after the call, Phi and J q' of every constraint row at the last state checked or stage run.

    With dz not None, also the forward sensitivities of the coordinates (module
    ``fdbench.multibody.sensitivity``; open loop only, the torque not depending on the state): G
    (2 n_steps + 1, P) d tau / d p on the grid, parameter q moving coordinate param_col[q]'s
    generalised force; dz (n_steps // every + 1, J, P) the derivatives of the coordinates at every
    ``every``-th step reached. Each stage's derivative is differentiated as a matrix: eq. 12 is
    A(q) x = b(y, tau), so f_y = [0 I; A^-1 D] with D = d(b - A x)/dy at the stage's x, built row
    by row from each constraint's Hessian (kept by the stage's assembly) and the loads'
    derivatives, then solved with the stage's own Cholesky factor (``_stage_tangents``).

    The stage code is closures over this function's arrays (numba inlines them without reference
    counting), as in ``kernels._drive``."""
    n_b, n_p = body_int.shape[0], mass.shape[0]
    n_q = n_p + n_b
    n = 2 * n_q
    J = tau.shape[1]
    alpha, txo, om2, switch = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2], params[SWITCH_COS]
    y, state, ks = np.empty(n), np.empty(n), np.empty((4, n))
    A, rhs = np.empty((n_q, n_q)), np.empty(n_q)
    torque, z, zd, v = np.empty(J), np.empty(J), np.empty(J), np.empty(J)
    idx, val = np.empty(MAX_ENTRIES, dtype=np.int64), np.empty(MAX_ENTRIES)
    kin, points = np.empty((n_b, N_KIN)), np.empty((3, n_mass.shape[0]))
    for m in range(n):
        y[m] = y0[m]
    # the sensitivities: S = dy/dp, the stage's input U and derivative dk, their RK4 sum acc; D the
    # stage's D = d(b - A x)/dy (jac), then A^-1 D; force_rows (n_q, J): where each coordinate's force enters b
    # (``dz is None`` tests are resolved when numba compiles: a kernel without sensitivities has none of their code)
    P = 0 if G is None else G.shape[1]
    ns = 0 if dz is None else n
    S, U, acc, dk = np.zeros((ns, P)), np.zeros((ns, P)), np.zeros((ns, P)), np.zeros((ns, P))
    jac, moved = np.zeros((ns // 2, n)), np.zeros((ns // 2, P))
    force_rows, solved_rows = np.zeros((ns // 2, J)), np.zeros((ns // 2, J))
    n_kept = 0 if dz is None else phi_rows.shape[0]  # per constraint row: its entries, Hessian, term
    row_count, row_term = np.zeros(n_kept, dtype=np.int64), np.zeros(n_kept)
    row_idx, row_val = np.zeros((n_kept, MAX_ENTRIES), dtype=np.int64), np.zeros((n_kept, MAX_ENTRIES))
    row_third, row_hess = np.zeros((n_kept, MAX_ENTRIES)), np.zeros((n_kept, MAX_ENTRIES, MAX_ENTRIES))
    path_kept = np.zeros((path_body.shape[0] if dz is not None else 0, 12))  # per path: its first row, geometry
    kept_rows = (row_count, row_term, row_idx, row_val, row_hess, row_third)
    if dz is not None:
        for k in range(n_b):
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            force_rows[n_p + k, col] += 1.0
            if p >= 0:
                force_rows[n_p + p, col] -= 1.0
            if body_int[k, FREE] == 1:
                force_rows[body_int[k, KI], col + 1] += 1.0
                force_rows[body_int[k, KI] + 1, col + 2] += 1.0

    def point(b):
        """x, y, x', y' of body b's point i in the stage's state (fixed: its position, zero velocity)."""
        k = body_int[b, KI]
        if k < 0:
            return body_float[b, FIXED_X], body_float[b, FIXED_Y], 0.0, 0.0
        return state[k], state[k + 1], state[n_q + k], state[n_q + k + 1]

    def row(r, phi, jdv, count, task):
        """Constraint row r of value phi and velocity term J' q' jdv, its count nonzero entries in
        idx, val: Phi and J q' into phi_rows, jv_rows; in task ASSEMBLE, its alpha J^T J into A's
        lower triangle and -alpha J^T (J' q' + 2 xi omega J q' + omega^2 Phi) into rhs, and with
        the sensitivities its entries and that term into the row_* arrays (``constraints`` puts its
        Hessian H and third derivative T(q', q', .) on those entries into row_hess, row_third).
        Returns |phi|."""
        jv = 0.0
        for e in range(count):
            jv += val[e] * state[n_q + idx[e]]
        phi_rows[r], jv_rows[r] = phi, jv
        if dz is not None and task == ASSEMBLE:  # kept for ``_stage_tangents`` (the sites keep H and T)
            row_count[r], row_term[r] = count, jdv + txo * jv + om2 * phi
            for e in range(count):
                row_idx[r, e], row_val[r, e] = idx[e], val[e]
        if task == ASSEMBLE:
            cc = alpha * (jdv + txo * jv + om2 * phi)
            for e in range(count):
                rhs[idx[e]] -= val[e] * cc
                for f in range(count):
                    if idx[e] >= idx[f]:
                        A[idx[e], idx[f]] += alpha * val[e] * val[f]
        return abs(phi)

    def constraints(task):
        """Every constraint row at the stage's state (``row`` in task CHECK or ASSEMBLE): the bodies'
        distance and angle rows (the form in force), the linear rows, two rows per path. Returns max
        |Phi| (m^2 and m). Every test of the task compares it with a constant and every test of the
        sensitivities dz with None, so that numba drops the code of the others from each (inlined) call."""
        worst, r = 0.0, 0
        for b in range(n_b):
            ki, kj = body_int[b, KI], body_int[b, KJ]
            xi, yi, vxi, vyi = point(b)
            ex, ey, evx, evy = state[kj] - xi, state[kj + 1] - yi, state[n_q + kj] - vxi, state[n_q + kj + 1] - vyi
            d = body_float[b, D]
            idx[0], val[0], idx[1], val[1] = kj, 2 * ex, kj + 1, 2 * ey
            if ki >= 0:
                idx[2], val[2], idx[3], val[3] = ki, -2 * ex, ki + 1, -2 * ey
            if dz is not None and task == ASSEMBLE:  # |e|^2 - d^2: H = 2 on (j, j), (i, i), -2 on (i, j) per axis
                hess = row_hess[r]
                hess[0, 0], hess[1, 1] = 2.0, 2.0
                if ki >= 0:
                    hess[2, 2], hess[3, 3] = 2.0, 2.0
                    hess[0, 2], hess[2, 0], hess[1, 3], hess[3, 1] = -2.0, -2.0, -2.0, -2.0
            worst = max(worst, row(r, ex * ex + ey * ey - d * d, 2 * (evx * evx + evy * evy), 4 if ki >= 0 else 2,
                                   task))
            psi, w = state[n_p + b] + body_float[b, BETA], state[n_q + n_p + b]
            s, c = math.sin(psi), math.cos(psi)
            if abs(c) >= switch:  # the sin form, (y_j - y_i) - d sin(psi)
                axis, phi, pivot, jdv = 1, ey - d * s, -d * c, d * s * w * w
            else:  # the cos form, (x_j - x_i) - d cos(psi)
                axis, phi, pivot, jdv = 0, ex - d * c, d * s, d * c * w * w
            idx[0], val[0], idx[1], val[1] = kj + axis, 1.0, n_p + b, pivot
            if ki >= 0:
                idx[2], val[2] = ki + axis, -1.0
            if dz is not None and task == ASSEMBLE:  # d2 Phi / d psi2 and d3 Phi / d psi3 w^2 of the form
                row_hess[r + 1, 1, 1] = d * s if axis == 1 else d * c
                row_third[r + 1, 1] = d * c * w * w if axis == 1 else -d * s * w * w
            worst = max(worst, row(r + 1, phi, jdv, 3 if ki >= 0 else 2, task))
            r += 2
        for lr in range(lin_const.shape[0]):
            total, count = 0.0, 0
            for e in range(lin_idx.shape[1]):
                if lin_idx[lr, e] >= 0:
                    total += lin_coef[lr, e] * state[lin_idx[lr, e]]
                    idx[count], val[count] = lin_idx[lr, e], lin_coef[lr, e]
                    count += 1
            worst = max(worst, row(r, total + lin_const[lr], 0.0, count, task))
            r += 1
        for m in range(path_body.shape[0]):
            k = path_body[m]
            p, ki = body_int[k, PARENT], body_int[k, KI]
            theta = state[n_p + k] - (state[n_p + p] if p >= 0 else 0.0) - body_float[k, OFFSET]
            rate = state[n_q + n_p + k] - (state[n_q + n_p + p] if p >= 0 else 0.0)
            sx0, sx1, sx2, sx3 = _spline_at(knots, spline_start[2 * m], spline_start[2 * m + 1], theta)
            sy0, sy1, sy2, sy3 = _spline_at(knots, spline_start[2 * m + 1], spline_start[2 * m + 2], theta)
            if p < 0:  # on ground: r_i - at_parent - s(theta)
                idx[0], val[0], idx[1], val[1] = ki, 1.0, n_p + k, -sx1
                if dz is not None and task == ASSEMBLE:
                    row_hess[r, 1, 1], row_third[r, 1] = -sx2, -sx3 * rate * rate
                worst = max(worst, row(r, state[ki] - body_float[k, AT_PARENT_X] - sx0, -sx2 * rate * rate, 2,
                                       task))
                idx[0], val[0], idx[1], val[1] = ki + 1, 1.0, n_p + k, -sy1
                if dz is not None and task == ASSEMBLE:
                    row_hess[r + 1, 1, 1], row_third[r + 1, 1] = -sy2, -sy3 * rate * rate
                worst = max(worst, row(r + 1, state[ki + 1] - body_float[k, AT_PARENT_Y] - sy0, -sy2 * rate * rate,
                                       2, task))
                r += 2
                continue
            pi, pj = body_int[p, KI], body_int[p, KJ]
            xpi, ypi, vxpi, vypi = point(p)
            ex, ey = state[pj] - xpi, state[pj + 1] - ypi
            evx, evy = state[n_q + pj] - vxpi, state[n_q + pj + 1] - vypi
            f = path_float[m]
            c0a, c0b = f[BASE_1] + (f[L_11] * sx0 + f[L_12] * sy0), f[BASE_2] + (f[L_21] * sx0 + f[L_22] * sy0)
            c1a, c1b = f[L_11] * sx1 + f[L_12] * sy1, f[L_21] * sx1 + f[L_22] * sy1
            c2a, c2b = f[L_11] * sx2 + f[L_12] * sy2, f[L_21] * sx2 + f[L_22] * sy2
            # G(c, x) = c_a x + c_b R90 x; the angle columns -G(c1, e_p) on the child, + on the parent
            tx, ty = -(c1a * ex - c1b * ey), -(c1a * ey + c1b * ex)
            jx = -2 * (c1a * evx - c1b * evy) * rate - (c2a * ex - c2b * ey) * rate * rate
            jy = -2 * (c1a * evy + c1b * evx) * rate - (c2a * ey + c2b * ex) * rate * rate
            for axis in range(2):
                if axis == 0:
                    phi, t, jdv = state[ki] - xpi - (c0a * ex - c0b * ey), tx, jx
                    gj0, gj1 = c0a, -c0b  # row 0 of G's matrix [[c0a, -c0b], [c0b, c0a]]
                else:
                    phi, t, jdv = state[ki + 1] - ypi - (c0a * ey + c0b * ex), ty, jy
                    gj0, gj1 = c0b, c0a
                idx[0], val[0] = ki + axis, 1.0
                idx[1], val[1], idx[2], val[2] = pj, -gj0, pj + 1, -gj1
                idx[3], val[3], idx[4], val[4] = n_p + k, t, n_p + p, -t
                count = 5
                if pi >= 0:
                    idx[5], val[5] = pi, gj0 - (1.0 if axis == 0 else 0.0)
                    idx[6], val[6] = pi + 1, gj1 - (1.0 if axis == 1 else 0.0)
                    count = 7
                worst = max(worst, row(r + axis, phi, jdv, count, task))
            if dz is not None and task == ASSEMBLE:  # for ``_path_hessian``
                path_kept[m, 0], path_kept[m, 1], path_kept[m, 2], path_kept[m, 3] = r, ex, ey, evx
                path_kept[m, 4], path_kept[m, 5], path_kept[m, 6], path_kept[m, 7] = evy, rate, c1a, c1b
                path_kept[m, 8], path_kept[m, 9] = c2a, c2b
                path_kept[m, 10] = f[L_11] * sx3 + f[L_12] * sy3
                path_kept[m, 11] = f[L_21] * sx3 + f[L_22] * sy3
            r += 2
        return worst

    def coordinates():
        """The coordinates z and rates zd (J,) of the stage's state."""
        for k in range(n_b):
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            z[col] = state[n_p + k] - (state[n_p + p] if p >= 0 else 0.0) - body_float[k, OFFSET]
            zd[col] = state[n_q + n_p + k] - (state[n_q + n_p + p] if p >= 0 else 0.0)
            if body_int[k, FREE] == 1:
                ki = body_int[k, KI]
                z[col + 1] = state[ki] - body_float[k, AT_PARENT_X]
                z[col + 2] = state[ki + 1] - body_float[k, AT_PARENT_Y]
                zd[col + 1], zd[col + 2] = state[n_q + ki], state[n_q + ki + 1]

    def law(half):
        """The applied generalised forces at the stage's state and grid row ``half`` into torque."""
        coordinates()
        if mode == GAINS:
            for k in range(J):  # term by term onto tau: K = [diag kp, diag kd] gives PD's numbers to the bit
                total = tau[half, k]
                for j in range(J):
                    total += gains[half, k, j] * (ref[half, j] - z[j])
                for j in range(J):
                    total += gains[half, k, J + j] * (refd[half, j] - zd[j])
                torque[k] = total
        elif mode == COMPUTED:
            for k in range(J):
                v[k] = refdd[half, k] + kp[k] * (ref[half, k] - z[k]) + kd[k] * (refd[half, k] - zd[k])
            _inverse(z, zd, v, n_loads[half], n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner,
                     n_local, n_index, n_mass, n_q_ext, kin, points, torque)
            for k in range(J):
                torque[k] += tau[half, k]
        else:
            for k in range(J):
                torque[k] = tau[half, k] + kp[k] * (ref[half, k] - z[k]) + kd[k] * (refd[half, k] - zd[k])

    def solve():
        """Solve A x = rhs in place (x into rhs) by the Cholesky factor L of A's lower triangle (into
        it), row by row inside the envelope first[r] <= c <= r (which L keeps). Returns OK,
        NONFINITE for a matrix that is not finite, SINGULAR for one that is not positive definite."""
        for r in range(n_q):
            for c in range(first[r], r + 1):
                if not math.isfinite(A[r, c]):
                    return NONFINITE
        for r in range(n_q):
            fr = first[r]
            for c in range(fr, r):
                total = A[r, c]
                for k in range(max(fr, first[c]), c):
                    total -= A[r, k] * A[c, k]
                A[r, c] = total / A[c, c]
            diag = A[r, r]
            for k in range(fr, r):
                diag -= A[r, k] * A[r, k]
            if not diag > 0.0:
                return SINGULAR
            A[r, r] = math.sqrt(diag)
        for r in range(n_q):  # L w = rhs
            total = rhs[r]
            for k in range(first[r], r):
                total -= A[r, k] * rhs[k]
            rhs[r] = total / A[r, r]
        for r in range(n_q - 1, -1, -1):  # L^T x = w, column by column
            x = rhs[r] / A[r, r]
            rhs[r] = x
            for k in range(first[r], r):
                rhs[k] -= A[r, k] * x
        return OK

    def coordinate_sensitivities(sample):
        """dz[sample] = the coordinates' rows of S: a body's angle minus its parent's, a free joint's
        point i."""
        for k in range(n_b):
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            for q in range(P):
                dz[sample, col, q] = S[n_p + k, q] - (S[n_p + p, q] if p >= 0 else 0.0)
                if body_int[k, FREE] == 1:
                    dz[sample, col + 1, q] = S[body_int[k, KI], q]
                    dz[sample, col + 2, q] = S[body_int[k, KI] + 1, q]

    def derivative(stage, half):
        """y' = [q', q''] of eq. 12 at the stage's state under torque and the loads of grid row half
        into ks[stage]. Returns OK, or the solve's status (then the accelerations are left unfinished)."""
        for k in range(n_q):
            ks[stage, k] = state[n_q + k]
        for r in range(n_q):
            for c in range(first[r], r + 1):
                A[r, c] = mass[r, c] if r < n_p else 0.0
            rhs[r] = q_ext[r] if r < n_p else 0.0
        for k in range(n_b):  # generalised forces: a joint's torque on its child's and parent's angles
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            rhs[n_p + k] += torque[col]
            if p >= 0:
                rhs[n_p + p] -= torque[col]
            if body_int[k, FREE] == 1:
                rhs[body_int[k, KI]] += torque[col + 1]
                rhs[body_int[k, KI] + 1] += torque[col + 2]
        for k in range(load_int.shape[0]):  # external loads: F on the body's point i, (P - r_i) x F + M on its angle
            fx, fy, px, py = _load_in_ground(loads[half], k, load_int, body_int, body_float, state, n_p, n_q)
            b = load_int[k, LOAD_BODY]
            xi, yi, _, _ = point(b)
            if body_int[b, KI] >= 0:
                rhs[body_int[b, KI]] += fx
                rhs[body_int[b, KI] + 1] += fy
            rhs[n_p + b] += (px - xi) * fy - (py - yi) * fx + loads[half, k, MOMENT]
        if dz is not None:  # the rows' Hessians, filled where nonzero by the assembly
            row_hess[:], row_third[:] = 0.0, 0.0
        constraints(ASSEMBLE)
        status = solve()
        if status == OK:
            for r in range(n_q):
                ks[stage, n_q + r] = rhs[r]
        return status

    for m in range(n):
        state[m] = y[m]
    max_viol = constraints(CHECK)
    code = OK
    for i in range(n_steps + 1):
        j = start + 2 * i
        for stage in range(4):  # k1 at y, k2 and k3 at the half step, k4 at the full step
            if stage > 0:
                h = dt if stage == 3 else 0.5 * dt
                for m in range(n):
                    state[m] = y[m] + h * ks[stage - 1, m]
            law(j + (stage + 1) // 2)
            code = derivative(stage, j + (stage + 1) // 2)
            if stage == 0:
                for m in range(n):
                    states[i, m] = y[m]
                    rates[i, m] = ks[0, m] if (code == OK or m < n_q) else np.nan
                for m in range(J):
                    applied[i, m] = torque[m]
                if dz is not None:
                    if i % every == 0 and i // every < dz.shape[0]:
                        coordinate_sensitivities(i // every)
            if code != OK or i == n_steps:
                break
            if dz is not None:  # dk of this stage: acc += weight dk, U = S + (the next stage's step) dk
                if stage == 0:
                    for m in range(n):
                        for q in range(P):
                            U[m, q], acc[m, q] = S[m, q], 0.0
                half = j + (stage + 1) // 2
                _stage_tangents(state, rhs, A, first, loads[half], load_int, body_int, body_float, path_body, params,
                                kept_rows, path_kept, force_rows, G[half], param_col, U, jac, solved_rows, moved, dk)
                weight = 1.0 if stage == 0 or stage == 3 else 2.0
                next_step = 0.5 * dt if stage < 2 else (dt if stage == 2 else 0.0)
                for m in range(n):
                    for q in range(P):
                        acc[m, q] += weight * dk[m, q]
                        U[m, q] = S[m, q] + next_step * dk[m, q]
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
        viol = constraints(CHECK)
        if viol > params[VIOLATION]:
            return CONSTRAINT, i, max(max_viol, viol)
        max_viol = max(max_viol, viol)
        if dz is not None:
            for m in range(n):
                for q in range(P):
                    S[m, q] += dt / 6.0 * acc[m, q]
        for m in range(n):
            y[m] = state[m]
    return OK, n_steps, max_viol


@njit(error_model="numpy")
def rk4(y0, dt, n_steps, tau, ref, refd, refdd, kp, kd, mode, gains, loads, n_loads, body_int, body_float, path_body,
        path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params, load_int, first, n_body_int,
        n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local, n_index, n_mass, n_q_ext, states, rates,
        applied):
    """Classical RK4 of eq. 12 over n_steps steps of dt (s) from the state y0 (n_state,) under the
    feedback law ``mode`` of ``kernels.rk4`` (PD, COMPUTED or GAINS), for the coordinates (J
    of them; a free joint's x and y take forces, N): tau, ref, refd, refdd of shape (2 n_steps + 1,
    J) on the half-step grid (N m, rad, rad/s, rad/s^2; ref WITHOUT the joint offsets), kp, kd (J,),
    gains (2 n_steps + 1, J, 2J) for GAINS; loads, n_loads (2 n_steps + 1, L, N_LOAD): the plant's
    and the believed model's external loads on the grid; then the plant's dense layout and the
    believed model's inverse layout. Fills states, rates (n+1, n_state) and applied (n+1, J) up to the last step
    reached. Returns (status, steps_done, max constraint violation)."""
    m = n_rows(body_int, path_body, lin_const)
    return _drive(y0, dt, n_steps, 0, tau, ref, refd, refdd, kp, kd, mode, gains, loads, n_loads, body_int, body_float,
                  path_body, path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params,
                  load_int, first, n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local,
                  n_index, n_mass, n_q_ext, states, rates, applied, np.empty(m), np.empty(m),
                  None, None, 1, None)


@njit(error_model="numpy")
def derivatives(states, tau, ref, refd, refdd, kp, kd, mode, gains, loads, n_loads, body_int, body_float, path_body,
                path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params, load_int, first,
                n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local, n_index, n_mass,
                n_q_ext, out, applied):
    """The state derivatives (into out, (k, n_state)) and applied generalised forces (into applied,
    (k, J)) of k states (k, n_state) under ``rk4``'s feedback law, row i with row i of tau, ref,
    refd, refdd (each (k, J)), of gains and of the loads (k, L, N_LOAD); the accelerations are NaN
    where the solve fails."""
    m, n, J = n_rows(body_int, path_body, lin_const), states.shape[1], tau.shape[1]
    phi_rows, jv_rows = np.empty(m), np.empty(m)
    state, rate, torque = np.empty((1, n)), np.empty((1, n)), np.empty((1, J))
    for i in range(states.shape[0]):
        _drive(states[i], 0.0, 0, i, tau, ref, refd, refdd, kp, kd, mode, gains, loads, n_loads, body_int, body_float,
               path_body, path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params,
               load_int, first, n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local,
               n_index, n_mass, n_q_ext, state, rate, torque, phi_rows, jv_rows, None, None, 1, None)
        out[i] = rate[0]
        applied[i] = torque[0]


@njit(error_model="numpy")
def constraint_residuals(y, body_int, body_float, path_body, path_float, knots, spline_start, lin_idx, lin_coef,
                         lin_const, mass, q_ext, params, load_int, first, phi_rows, jv_rows):
    """Phi and J q' of every constraint row (into phi_rows, jv_rows, (n_rows,): distance and angle
    per body, the linear rows, two per path) at the state y (n_state,), the angle constraints in the
    form in force; returns max |Phi| (m^2 and m), the value ``rk4`` checks."""
    n = y.shape[0]
    rows, J, no_loads = np.zeros((1, 1)), 1, np.zeros((1, 0, N_LOAD))
    no_owner, no_local, no_index = np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    _, _, worst = _drive(y, 0.0, -1, 0, rows, rows, rows, rows, rows[0], rows[0], -1, np.zeros((1, J, 2 * J)),
                         no_loads, no_loads, body_int, body_float, path_body, path_float, knots, spline_start, lin_idx,
                         lin_coef, lin_const, mass, q_ext, params, load_int, first, body_int, body_float, knots,
                         spline_start, load_int, no_owner, no_local, no_index, np.zeros((0, 0)), np.zeros(0),
                         np.empty((1, n)), np.empty((1, n)), np.empty((1, J)), phi_rows, jv_rows,
                         None, None, 1, None)
    return worst


# ---------------------------------------------------------------------- the population (eq. 18)


@njit(nogil=True)
def tracking_objective(states, done, every, angles_ref, n_steps, penalty_weight, body_int, body_float, n_p):
    """Eq. 18 from a simulation's states (n_steps + 1, n_state), filled up to step ``done``: at the
    motion's samples (every ``every``-th step; desired coordinates angles_ref (rad, m for a free
    joint's x and y; shape (samples, J))) over the samples reached, the RMSE of the angles (deg)
    plus, for a model with free joints, that of their translations (cm), units never pooled; plus
    penalty_weight times the fraction of the steps not reached. A non-finite RMSE counts as 0."""
    n_b = body_int.shape[0]
    count = done // every + 1
    angles, translations, n_translations = 0.0, 0.0, 0
    for k in range(count):
        y = states[k * every]
        for b in range(n_b):
            p, col = body_int[b, PARENT], body_int[b, COLUMN]
            z = y[n_p + b] - (y[n_p + p] if p >= 0 else 0.0) - body_float[b, OFFSET]
            error = (z - angles_ref[k, col]) * DEGREES_PER_RADIAN
            angles += error * error
            if body_int[b, FREE] == 1:
                n_translations += 2
                ki = body_int[b, KI]
                for axis in range(2):
                    x = y[ki + axis] - body_float[b, AT_PARENT_X + axis]
                    error = (x - angles_ref[k, col + 1 + axis]) * CM_PER_M
                    translations += error * error
    rmse = math.sqrt(angles / (n_b * count))
    if n_translations > 0:
        rmse += math.sqrt(translations / n_translations)
    if not math.isfinite(rmse):
        rmse = 0.0
    return rmse + penalty_weight * (1.0 - done / n_steps)


@njit(nogil=True)
def rk4_candidates(y0, dt, n_steps, tau, ref, refd, every, angles_ref, penalty_weight, loads, body_int, body_float,
                   path_body, path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params,
                   load_int, first, n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local,
                   n_index, n_mass, n_q_ext, states, rates, applied, objective, candidate, stride, step, budget):
    """Open-loop RK4 (``rk4`` in PD mode with zero gains) and eq. 18 (``tracking_objective``) for
    candidates candidate, candidate + stride, ... of tau (shape (lam, 2 n_steps + 1, J)), at most
    ``budget`` steps in all, resuming at ``step``, for ``fdbench.population.Population``:
    ``kernels.rk4_candidates`` for the dense layout (ref, refd without the joint offsets; loads
    (2 n_steps + 1, L, N_LOAD) the external loads on the grid). Returns the (candidate, step) to
    resume at. Runs without the GIL."""
    J = tau.shape[2]
    zero, no_gains = np.zeros(J), np.zeros((1, J, 2 * J))
    while candidate < tau.shape[0] and budget > 0:
        n = min(budget, n_steps - step)
        low, high = 2 * step, 2 * (step + n) + 1
        y = y0 if step == 0 else states[step].copy()
        rows = loads[low:high]
        code, done, _ = rk4(y, dt, n, tau[candidate, low:high], ref[low:high], refd[low:high], ref[low:high], zero,
                            zero, PD, no_gains, rows, rows, body_int, body_float, path_body, path_float, knots,
                            spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params, load_int, first,
                            n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local, n_index,
                            n_mass, n_q_ext, states[step:step + n + 1], rates[step:step + n + 1],
                            applied[step:step + n + 1])
        step, budget = step + done, budget - max(done, 1)  # steps run: a failing candidate costs few
        if code != OK or step == n_steps:
            objective[candidate] = tracking_objective(states, step, every, angles_ref, n_steps, penalty_weight,
                                                      body_int, body_float, mass.shape[0])
            candidate, step = candidate + stride, 0
    return candidate, step
