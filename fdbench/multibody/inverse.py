"""Eq. 3 compiled, tau = R^T (M_p p'' - Q_ext), over the kernels' layout (``fdbench.multibody.layout``):
the engine's inverse dynamics (``Engine.inverse_dynamics``) and computed-torque control's (run by
the RK4 driver, ``fdbench.multibody.kernels``). Its symbolic twin is ``fdbench.multibody.symbolic``
(CasADi, for the collocation and the LQR); ``tests/test_multibody_eq3.py`` checks one against the
other."""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from .layout import (AT_CHILD_X, AT_CHILD_Y, AT_PARENT_X, AT_PARENT_Y, COLUMN, FORCE_FRAME, FREE, FX, FY, LOAD_BODY,
                     MOMENT, N_LOAD, N_LOAD_INT, OFFSET, PARENT, PATH, POINT_FRAME, PX, PY)

# columns of the inverse dynamics' per-body scratch: angle (rad), its cos and sin, rate (rad/s),
# angular acceleration (rad/s^2), the joint point (m), the frame origin (m) and its acceleration
# (m/s^2), the path's world direction per radian (m/rad; 0 without a path), the force (N) on the
# body's subtree and its moment about the world origin (N m), the loads' generalised forces on the
# body's joint (N m on its angle, N on a free joint's x and y)
(PHI, COS, SIN, RATE, ACC, JOINT_X, JOINT_Y, ORIGIN_X, ORIGIN_Y, ORIGIN_AX, ORIGIN_AY, DIR_X, DIR_Y,
 FORCE_X, FORCE_Y, MOMENT_0, LOAD_ANGLE, LOAD_X, LOAD_Y, N_KIN) = range(20)


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
def _inverse(z, zd, zdd, model, paths, frames, values, kin, points, out):
    """Eq. 3, tau = R^T (M_p p'' - Q_ext), into out (J,) (N m; N for a free joint's x and y) for the
    coordinates z, rates zd and accelerations zdd (J,): the bodies' kinematics from ground out
    (parents before children), the free points' positions and accelerations, the points' forces
    f = M_p p'' - Q_ext, then R^T f without R: per body the sum of its points' f and their moment about
    the world origin, summed over its subtree; a joint's angle takes that moment about its point
    (plus the sum along a path's direction), a free joint's x and y the sum; less the external
    loads' generalised forces (frames (L, N_LOAD_INT), values (L, N_LOAD); L may be 0). The
    operations are numpy's former ``Engine.inverse_dynamics``', in its order. kin (B, N_KIN),
    points (3, n_p): scratch."""
    body_int, body_float = model.body_int, model.body_float
    pt_index, pt_owner, pt_local, mass, q_ext = model.pt_index, model.pt_owner, model.pt_local, model.mass, model.q_ext
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
        if paths is not None:
            kin[k, DIR_X], kin[k, DIR_Y] = 0.0, 0.0
            m = body_int[k, PATH]
            if m >= 0:  # the point moves along the path in the parent's frame
                knots, start = paths.knots, paths.start
                theta, rate, acc = z[col], zd[col], zdd[col]
                sx0, sx1, sx2, _ = _spline_at(knots, start[2 * m], start[2 * m + 1], theta)
                sy0, sy1, sy2, _ = _spline_at(knots, start[2 * m + 1], start[2 * m + 2], theta)
                arm_x, arm_y = sx0 * pc - sy0 * ps, sx0 * ps + sy0 * pc
                d1x, d1y = sx1 * pc - sy1 * ps, sx1 * ps + sy1 * pc
                d2x, d2y = sx2 * pc - sy2 * ps, sx2 * ps + sy2 * pc
                rx, ry = rx + arm_x, ry + arm_y
                ax = ax - pal * arm_y - pw * pw * arm_x - 2 * pw * d1y * rate + d2x * (rate * rate) + d1x * acc
                ay = ay + pal * arm_x - pw * pw * arm_y + 2 * pw * d1x * rate + d2y * (rate * rate) + d1y * acc
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
    for k in range(n_b):
        kin[k, FORCE_X], kin[k, FORCE_Y], kin[k, MOMENT_0] = 0.0, 0.0, 0.0
        kin[k, LOAD_ANGLE], kin[k, LOAD_X], kin[k, LOAD_Y] = 0.0, 0.0, 0.0
    for pt in range(pt_index.shape[0]):  # per body: the force on its points and its moment about the origin
        i = pt_index[pt]
        if i >= 0:
            fx, fy, b = points[2, i], points[2, i + 1], pt_owner[pt]
            kin[b, FORCE_X] += fx
            kin[b, FORCE_Y] += fy
            kin[b, MOMENT_0] += points[0, i] * fy - points[0, i + 1] * fx
    for k in range(n_b - 1, -1, -1):  # summed over each subtree (children come after their parent)
        p = body_int[k, PARENT]
        if p >= 0:
            kin[p, FORCE_X] += kin[k, FORCE_X]
            kin[p, FORCE_Y] += kin[k, FORCE_Y]
            kin[p, MOMENT_0] += kin[k, MOMENT_0]
    for k in range(frames.shape[0]):  # the loads' generalised forces, per joint
        fx, fy, px, py = values[k, FX], values[k, FY], values[k, PX], values[k, PY]
        frame = frames[k, FORCE_FRAME]
        if frame >= 0:
            fx, fy = fx * kin[frame, COS] - fy * kin[frame, SIN], fx * kin[frame, SIN] + fy * kin[frame, COS]
        frame = frames[k, POINT_FRAME]
        if frame >= 0:
            px, py = (kin[frame, ORIGIN_X] + (px * kin[frame, COS] - py * kin[frame, SIN]),
                      kin[frame, ORIGIN_Y] + (px * kin[frame, SIN] + py * kin[frame, COS]))
        b = frames[k, LOAD_BODY]
        while b >= 0:
            lever = (px - kin[b, JOINT_X]) * fy - (py - kin[b, JOINT_Y]) * fx
            if paths is not None:
                lever += kin[b, DIR_X] * fx + kin[b, DIR_Y] * fy
            kin[b, LOAD_ANGLE] += lever + values[k, MOMENT]
            kin[b, LOAD_X] += fx
            kin[b, LOAD_Y] += fy
            b = body_int[b, PARENT]
    for k in range(n_b):  # a joint takes its subtree's moment about its point (plus the force along a path)
        col, fx, fy = body_int[k, COLUMN], kin[k, FORCE_X], kin[k, FORCE_Y]
        torque = kin[k, MOMENT_0] - (kin[k, JOINT_X] * fy - kin[k, JOINT_Y] * fx)
        if paths is not None:
            torque += kin[k, DIR_X] * fx + kin[k, DIR_Y] * fy
        out[col] = torque - kin[k, LOAD_ANGLE]
        if body_int[k, FREE] == 1:
            out[col + 1], out[col + 2] = fx - kin[k, LOAD_X], fy - kin[k, LOAD_Y]


@njit(error_model="numpy")
def _no_loads(loads):
    """(frames, values on the grid) of ``loads``, or empty ones for None."""
    if loads is None:
        return np.zeros((0, N_LOAD_INT), dtype=np.int64), np.zeros((1, 0, N_LOAD))
    return loads.frames, loads.values


@njit(error_model="numpy")
def inverse_torques(z, zd, zdd, model, paths, loads, out):
    """Eq. 3 over the model's layout: the generalised forces (N m; N for a free joint's x and y) of
    the minimal motions (z, zd, zdd) (rad, rad/s, rad/s^2; m for a free joint's x and y; shape
    (n, J)) into out (n, J), row i under the external loads' values at row i of ``loads`` (None:
    none)."""
    frames, values = _no_loads(loads)
    kin, points = np.empty((model.body_int.shape[0], N_KIN)), np.empty((3, model.mass.shape[0]))
    for i in range(z.shape[0]):
        _inverse(z[i], zd[i], zdd[i], model, paths, frames, values[i if values.shape[1] > 0 else 0], kin, points,
                 out[i])
