"""Muscle-tendon lengths and moment arms of a model's muscles (``fdbench.multibody.muscles``) at its
coordinates q, exact: a path of points by the planar kinematics of the bodies' frames and their
derivatives by the coordinates (pin angles, a free joint's angle and translations, a joint's path
spline), a polynomial path by its closed-form derivative. A moment arm is -dl/dq (m; for a
translation, dimensionless), OpenSim's ``computeMomentArm`` sign.

The frames follow ``fdbench.multibody.model``: a body's angle is the sum of (coordinate + offset)
along its path from ground; its joint point sits at the parent's ``at_parent`` (plus the path's
(x, y)(angle) in the parent's frame, plus (x, y) for a free joint) and at its own ``at_child``.

One compiled kernel (``geometry``, numba, cached) over one named layout (``MusclePaths``, built once
per model by ``muscle_layout``) computes both path forms, for later use inside the compiled dynamics;
``hessians`` (``path_hessians`` from Python) their exact Hessians d2l/dq2, which the sensitivities
need: a path of points' through the bodies' origins' second derivatives (``_frame_curves``), in a
plain kernel (``points_hessians``) that the RK4 driver calls rather than inlines.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import njit
from .inverse import _spline_at
from .layout import (AT_CHILD_X, AT_CHILD_Y, AT_PARENT_X, AT_PARENT_Y, COLUMN, FIXED, FREE, N_BODY_FLOAT, N_BODY_INT,
                     OFFSET, PARENT, PATH)
from .model import GROUND, Model
from .muscles import MAX_COORDINATES, MAX_POWER, PointPath

POINTS, POLYNOMIAL = 0, 1  # MusclePaths.kind
PHI, ORIGIN_X, ORIGIN_Y, N_FRAME = range(4)  # the kernel's per-body scratch: angle (rad), origin (m)


class MusclePaths(NamedTuple):
    """A model's bodies and muscle paths as arrays. Bodies (the model's joints' children, in its
    order): body_int (B, N_BODY_INT) with PARENT (FIXED: ground), COLUMN, FREE and PATH (-1: none);
    body_float (B, N_BODY_FLOAT) with OFFSET (rad), AT_PARENT_X/Y and AT_CHILD_X/Y (m); knots
    (n_knots, 5) and start (2 n_paths + 1,) the joint paths' splines (``layout.Paths``'s). Muscles:
    kind (M,) POINTS or POLYNOMIAL, rows (M, 2) muscle m's rows rows[m, 0] to rows[m, 1] (exclusive)
    of point_body (FIXED: ground) and point_local (m, in the body's frame), or of a polynomial's lines:
    line i the monomial of the path's coordinates but the last of powers (lines, MAX_COORDINATES) times
    the polynomial of the last with coefficient[lines[i, 0]:lines[i, 1]] (m; of its powers 0, 1, ...);
    columns (M, MAX_COORDINATES) a polynomial's coordinates (-1: none); top (J,) each coordinate's
    highest power in the polynomials."""
    body_int: np.ndarray
    body_float: np.ndarray
    knots: np.ndarray
    start: np.ndarray
    kind: np.ndarray
    rows: np.ndarray
    point_body: np.ndarray
    point_local: np.ndarray
    lines: np.ndarray
    powers: np.ndarray
    coefficient: np.ndarray
    columns: np.ndarray
    top: np.ndarray


def muscle_geometry(model: Model, q, layout: MusclePaths | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lengths, moment_arms) of ``model.muscles`` at the coordinates q (rad, m in the model's order):
    for q of shape (J,) lengths (M,) (m) and moment arms (M, J) (-dl/dq: m per rad, m/m for a
    translation); for q of shape (n, J) shapes (n, M) and (n, M, J). ValueError for another shape.
    Where two consecutive points of a path meet, its moment arms are NaN (the length has no slope).
    ``layout``: ``muscle_layout(model)``, made here if not given."""
    q = np.asarray(q, dtype=float)
    n_coordinates = model.n_joints
    if q.ndim not in (1, 2) or q.shape[-1] != n_coordinates:
        raise ValueError(f"coordinates must have shape ({n_coordinates},) or (n, {n_coordinates}), got {q.shape}")
    # contiguous and writeable whatever the caller's flags: the kernel compiles once, not once more for read-only q
    single, q = q.ndim == 1, np.require(np.atleast_2d(q), requirements=["C", "W"])
    layout = muscle_layout(model) if layout is None else layout
    n, n_bodies = q.shape[0], layout.body_int.shape[0]
    lengths, arms = np.zeros((n, len(model.muscles))), np.zeros((n, len(model.muscles), n_coordinates))
    geometry(q, layout, lengths, arms, np.zeros((n_bodies + 1, N_FRAME)),
             np.zeros((n_bodies + 1, N_FRAME, n_coordinates)), np.zeros((2, 3, max(2, n_coordinates))),
             np.zeros((n_coordinates, 2, MAX_POWER + 1)))
    return (lengths[0], arms[0]) if single else (lengths, arms)


def muscle_layout(model: Model) -> MusclePaths:
    """The arrays of ``MusclePaths`` for ``model`` (a frame's points carried into its body's frame)."""
    index = {joint.child: b for b, joint in enumerate(model.joints)}
    n_bodies = len(model.joints)
    body_int = np.full((n_bodies, N_BODY_INT), FIXED, dtype=np.int64)
    body_float = np.zeros((n_bodies, N_BODY_FLOAT))
    pieces, start, column = [np.zeros((0, 5))], [0], 0
    for b, joint in enumerate(model.joints):
        body_int[b, PARENT], body_int[b, COLUMN] = index.get(joint.parent, FIXED), column
        body_int[b, FREE] = joint.type == "free"
        body_float[b, OFFSET] = joint.offset
        body_float[b, [AT_PARENT_X, AT_PARENT_Y]] = joint.at_parent
        body_float[b, [AT_CHILD_X, AT_CHILD_Y]] = joint.at_child
        column += len(joint.coordinate_names)
        if joint.path is not None:
            body_int[b, PATH] = (len(start) - 1) // 2
            for spline in joint.path.splines():
                pieces.append(np.column_stack([spline.x, spline.y, spline.b, spline.c, spline.d]))
                start.append(start[-1] + len(spline.x))
    kind, rows, point_body, point_local, lines, powers, coefficient = [], [], [], [], [], [], []
    columns = np.full((len(model.muscles), MAX_COORDINATES), -1, dtype=np.int64)
    top = np.zeros(len(model.coordinates), dtype=np.int64)
    for m, muscle in enumerate(model.muscles):
        if isinstance(muscle.path, PointPath):
            kind.append(POINTS)
            row0 = len(point_body)
            for point in muscle.path.points:
                body, origin, angle = (GROUND, (0.0, 0.0), 0.0) if point.body == GROUND else model.frame(point.body)
                c, s = math.cos(angle), math.sin(angle)
                point_body.append(index.get(body, FIXED))
                point_local.append((origin[0] + c * point.at[0] - s * point.at[1],
                                    origin[1] + s * point.at[0] + c * point.at[1]))
            rows.append((row0, len(point_body)))
        else:
            kind.append(POLYNOMIAL)
            used = [model.coordinates.index(name) for name in muscle.path.coordinates]
            columns[m, :len(used)] = used
            grouped = _lines(muscle.path)
            rows.append((len(lines), len(lines) + len(grouped)))
            for prefix, dense in grouped.items():
                lines.append((len(coefficient), len(coefficient) + len(dense)))
                powers.append(list(prefix) + [0] * (MAX_COORDINATES - len(prefix)))
                coefficient.extend(dense)
                top[used] = np.maximum(top[used], list(prefix) + [len(dense) - 1])
    return MusclePaths(body_int, body_float, np.concatenate(pieces), np.array(start, dtype=np.int64),
                       np.array(kind, dtype=np.int64), np.array(rows, dtype=np.int64).reshape(-1, 2),
                       np.array(point_body, dtype=np.int64), np.array(point_local, dtype=float).reshape(-1, 2),
                       np.array(lines, dtype=np.int64).reshape(-1, 2),
                       np.array(powers, dtype=np.int64).reshape(-1, MAX_COORDINATES), np.array(coefficient, dtype=float),
                       columns, top)


def _lines(path) -> dict[tuple[int, ...], list[float]]:
    """A polynomial path's terms grouped by their powers of its coordinates but the last: per group the
    coefficients (m) of the last coordinate's powers 0, 1, ... to the group's highest (0 where none)."""
    grouped: dict[tuple[int, ...], list[float]] = {}
    for term in path.terms:
        dense = grouped.setdefault(tuple(term.powers[:-1]), [])
        dense.extend([0.0] * (term.powers[-1] + 1 - len(dense)))
        dense[term.powers[-1]] = term.coefficient
    return grouped


@njit(error_model="numpy")
def geometry(q, layout, lengths, arms, frames, slopes, points, table):
    """Into lengths (n, M) (m) and arms (n, M, J) (-dl/dq) at the coordinates q (n, J), for the
    muscles of ``layout`` (a ``MusclePaths``). Scratch: frames (B + 1, N_FRAME) each body's angle
    and origin, slopes (B + 1, N_FRAME, J) their derivatives by the coordinates (row B: ground,
    zero), points (2, 3, max(2, J)) a segment's two points (x, y in row 0, their derivatives in rows 1, 2),
    table (J, 2, MAX_POWER + 1) the coordinates' powers and their slopes (``_powers``)."""
    n_bodies = layout.body_int.shape[0]
    for i in range(q.shape[0]):
        _frames(q[i], layout, frames, slopes)
        _powers(q[i], layout, table)
        for m in range(layout.kind.shape[0]):
            if layout.kind[m] == POINTS:
                lengths[i, m] = _points_length(layout, m, frames, slopes, points, arms[i, m], n_bodies)
            else:
                lengths[i, m] = _polynomial_length(layout, m, arms[i, m], table)


@njit(error_model="numpy", inline="always")
def _frames(q, layout, frames, slopes):
    """Each body's angle and origin (frames) and their derivatives by the coordinates (slopes), from
    ground out; row B (ground) stays zero."""
    body_int, body_float, n_bodies = layout.body_int, layout.body_float, layout.body_int.shape[0]
    for k in range(n_bodies):
        p, col = body_int[k, PARENT], body_int[k, COLUMN]
        if p < 0:
            p = n_bodies  # ground's row
        pphi = frames[p, PHI]
        pc, ps = math.cos(pphi), math.sin(pphi)
        ax = body_float[k, AT_PARENT_X] * pc - body_float[k, AT_PARENT_Y] * ps
        ay = body_float[k, AT_PARENT_X] * ps + body_float[k, AT_PARENT_Y] * pc
        rx, ry = frames[p, ORIGIN_X] + ax, frames[p, ORIGIN_Y] + ay
        for j in range(q.shape[0]):  # the joint point: the parent's origin and arm
            slopes[k, ORIGIN_X, j] = slopes[p, ORIGIN_X, j] - ay * slopes[p, PHI, j]
            slopes[k, ORIGIN_Y, j] = slopes[p, ORIGIN_Y, j] + ax * slopes[p, PHI, j]
            slopes[k, PHI, j] = slopes[p, PHI, j]
        if body_int[k, FREE] == 1:
            rx, ry = rx + q[col + 1], ry + q[col + 2]
            slopes[k, ORIGIN_X, col + 1] += 1.0
            slopes[k, ORIGIN_Y, col + 2] += 1.0
        path = body_int[k, PATH]
        if path >= 0:  # the joint point moves along (x, y)(angle) in the parent's frame
            sx0, sx1, _, _ = _spline_at(layout.knots, layout.start[2 * path], layout.start[2 * path + 1], q[col])
            sy0, sy1, _, _ = _spline_at(layout.knots, layout.start[2 * path + 1], layout.start[2 * path + 2], q[col])
            ax, ay = sx0 * pc - sy0 * ps, sx0 * ps + sy0 * pc
            rx, ry = rx + ax, ry + ay
            for j in range(q.shape[0]):
                slopes[k, ORIGIN_X, j] -= ay * slopes[p, PHI, j]
                slopes[k, ORIGIN_Y, j] += ax * slopes[p, PHI, j]
            slopes[k, ORIGIN_X, col] += sx1 * pc - sy1 * ps
            slopes[k, ORIGIN_Y, col] += sx1 * ps + sy1 * pc
        phi = pphi + q[col] + body_float[k, OFFSET]
        slopes[k, PHI, col] += 1.0
        c, s = math.cos(phi), math.sin(phi)
        ax = body_float[k, AT_CHILD_X] * c - body_float[k, AT_CHILD_Y] * s
        ay = body_float[k, AT_CHILD_X] * s + body_float[k, AT_CHILD_Y] * c
        frames[k, PHI], frames[k, ORIGIN_X], frames[k, ORIGIN_Y] = phi, rx - ax, ry - ay
        for j in range(q.shape[0]):  # the origin: the joint point less the child's arm
            slopes[k, ORIGIN_X, j] += ay * slopes[k, PHI, j]
            slopes[k, ORIGIN_Y, j] -= ax * slopes[k, PHI, j]


@njit(error_model="numpy", inline="always")
def _points_length(layout, m, frames, slopes, points, arm, n_bodies):
    """Muscle m's length through its points (m); -dl/dq into arm (J,)."""
    total = 0.0
    for j in range(arm.shape[0]):
        arm[j] = 0.0
    for row in range(layout.rows[m, 0], layout.rows[m, 1]):
        here = (row - layout.rows[m, 0]) % 2
        b = layout.point_body[row]
        if b < 0:
            b = n_bodies
        c, s = math.cos(frames[b, PHI]), math.sin(frames[b, PHI])
        ax = layout.point_local[row, 0] * c - layout.point_local[row, 1] * s
        ay = layout.point_local[row, 0] * s + layout.point_local[row, 1] * c
        points[here, 0, 0], points[here, 0, 1] = frames[b, ORIGIN_X] + ax, frames[b, ORIGIN_Y] + ay
        for j in range(arm.shape[0]):
            points[here, 1, j] = slopes[b, ORIGIN_X, j] - ay * slopes[b, PHI, j]
            points[here, 2, j] = slopes[b, ORIGIN_Y, j] + ax * slopes[b, PHI, j]
        if row > layout.rows[m, 0]:
            before = 1 - here
            dx, dy = points[here, 0, 0] - points[before, 0, 0], points[here, 0, 1] - points[before, 0, 1]
            segment = math.sqrt(dx * dx + dy * dy)
            total += segment
            ux, uy = dx / segment, dy / segment  # two points that meet: NaN
            for j in range(arm.shape[0]):
                arm[j] -= (ux * (points[here, 1, j] - points[before, 1, j])
                           + uy * (points[here, 2, j] - points[before, 2, j]))
    return total


@njit(error_model="numpy", inline="always")
def _powers(q, layout, table):
    """Into table (J, 2, MAX_POWER + 1) the powers the polynomial paths use of the coordinates q (J,):
    table[j, 0, p] = q_j^p and table[j, 1, p] = p q_j^(p - 1), p = 0 to top[j]."""
    for j in range(q.shape[0]):
        table[j, 0, 0], table[j, 1, 0] = 1.0, 0.0
        for p in range(1, layout.top[j] + 1):
            table[j, 0, p] = table[j, 0, p - 1] * q[j]
            table[j, 1, p] = p * table[j, 0, p - 1]


@njit(error_model="numpy", inline="always")
def _polynomial_length(layout, m, arm, table):
    """Muscle m's length sum_t c_t prod_k x_k^p_tk (m) line by line (``MusclePaths``): a line's
    polynomial of the last coordinate a dot product of its coefficients with that coordinate's powers
    (and their slopes), times its monomial of the others; -dl/dq into arm (J,). table: ``_powers``'."""
    columns, powers, coefficient = layout.columns, layout.powers, layout.coefficient
    for j in range(arm.shape[0]):
        arm[j] = 0.0
    last = 0  # the path's last coordinate
    while last + 1 < MAX_COORDINATES and columns[m, last + 1] >= 0:
        last += 1
    values, slopes = table[columns[m, last], 0], table[columns[m, last], 1]
    total = slope_last = slope_first = 0.0
    for line in range(layout.rows[m, 0], layout.rows[m, 1]):
        dense = coefficient[layout.lines[line, 0]:layout.lines[line, 1]]
        inner = inner_slope = 0.0
        for p in range(dense.shape[0]):
            inner += dense[p] * values[p]
            inner_slope += dense[p] * slopes[p]
        monomial = 1.0
        for k in range(last):
            monomial *= table[columns[m, k], 0, powers[line, k]]
        total += monomial * inner
        slope_last += monomial * inner_slope
        if last == 1:  # two coordinates, the common case: the first's slope summed here, not in arm
            slope_first += inner * table[columns[m, 0], 1, powers[line, 0]]
            continue
        for k in range(last):  # the monomial's slopes
            slope = inner * table[columns[m, k], 1, powers[line, k]]
            for other in range(last):
                if other != k:
                    slope *= table[columns[m, other], 0, powers[line, other]]
            arm[columns[m, k]] -= slope
    if last == 1:
        arm[columns[m, 0]] -= slope_first
    arm[columns[m, last]] -= slope_last
    return total


@njit(error_model="numpy", inline="always")
def _power_factor(table, j, power, order):
    """d^order/dq_j^order of q_j^power (order 0, 1, 2) from ``_powers``' table."""
    if order == 0:
        return table[j, 0, power]
    if order == 1:
        return table[j, 1, power]
    return power * (power - 1) * table[j, 0, power - 2] if power >= 2 else 0.0


@njit(error_model="numpy", inline="always")
def _polynomial_hessian(layout, m, hess, table):
    """The Hessian d2l/dq2 (m per rad^2; hess (J, J), overwritten) of polynomial muscle m's length,
    line by line as ``_polynomial_length`` (table: ``_powers``')."""
    columns, powers, coefficient = layout.columns, layout.powers, layout.coefficient
    hess[:, :] = 0.0
    last = 0
    while last + 1 < MAX_COORDINATES and columns[m, last + 1] >= 0:
        last += 1
    for line in range(layout.rows[m, 0], layout.rows[m, 1]):
        dense = coefficient[layout.lines[line, 0]:layout.lines[line, 1]]
        inner0 = inner1 = inner2 = 0.0  # the last coordinate's polynomial and its two derivatives
        for p in range(dense.shape[0]):
            inner0 += dense[p] * _power_factor(table, columns[m, last], p, 0)
            inner1 += dense[p] * _power_factor(table, columns[m, last], p, 1)
            inner2 += dense[p] * _power_factor(table, columns[m, last], p, 2)
        for a in range(last + 1):
            for b in range(a, last + 1):
                value = 1.0
                for k in range(last + 1):
                    order = (1 if k == a else 0) + (1 if k == b else 0)
                    if k == last:
                        value *= inner0 if order == 0 else (inner1 if order == 1 else inner2)
                    else:
                        value *= _power_factor(table, columns[m, k], powers[line, k], order)
                hess[columns[m, a], columns[m, b]] += value
                if a != b:
                    hess[columns[m, b], columns[m, a]] += value


@njit(error_model="numpy", inline="always")
def _frame_curves(q, layout, frames, slopes, curves):
    """Into curves (B + 1, 2, J, J) the second derivatives d2/dq_i dq_j of each body's origin (x, y;
    m per rad^2) from ``_frames``' frames and slopes at q, from ground out (row B, ground: zero). A body's
    angle is linear in q, so a vector a fixed in a frame of angle phi has d2a = -a dphi_i dphi_j; a
    path's point R(phi_p) s(theta) adds R90 R s' (dphi_p_i d_j + d_i dphi_p_j) + R s'' d_i d_j
    (d: the joint's angle column)."""
    body_int, body_float, n_bodies = layout.body_int, layout.body_float, layout.body_int.shape[0]
    n_q = q.shape[0]
    curves[n_bodies] = 0.0
    for k in range(n_bodies):
        p, col = body_int[k, PARENT], body_int[k, COLUMN]
        if p < 0:
            p = n_bodies
        pc, ps = math.cos(frames[p, PHI]), math.sin(frames[p, PHI])
        ax = body_float[k, AT_PARENT_X] * pc - body_float[k, AT_PARENT_Y] * ps  # fixed in the parent
        ay = body_float[k, AT_PARENT_X] * ps + body_float[k, AT_PARENT_Y] * pc
        c, s = math.cos(frames[k, PHI]), math.sin(frames[k, PHI])
        cx = body_float[k, AT_CHILD_X] * c - body_float[k, AT_CHILD_Y] * s  # fixed in the child
        cy = body_float[k, AT_CHILD_X] * s + body_float[k, AT_CHILD_Y] * c
        path = body_int[k, PATH]
        t1x = t1y = t2x = t2y = 0.0
        if path >= 0:  # the path's point turns with the parent too; R s' and R s''
            sx0, sx1, sx2, _ = _spline_at(layout.knots, layout.start[2 * path], layout.start[2 * path + 1], q[col])
            sy0, sy1, sy2, _ = _spline_at(layout.knots, layout.start[2 * path + 1], layout.start[2 * path + 2],
                                          q[col])
            ax, ay = ax + sx0 * pc - sy0 * ps, ay + sx0 * ps + sy0 * pc
            t1x, t1y = sx1 * pc - sy1 * ps, sx1 * ps + sy1 * pc
            t2x, t2y = sx2 * pc - sy2 * ps, sx2 * ps + sy2 * pc
        for i in range(n_q):
            for j in range(n_q):
                turn_parent = slopes[p, PHI, i] * slopes[p, PHI, j]
                turn_child = slopes[k, PHI, i] * slopes[k, PHI, j]
                curves[k, 0, i, j] = curves[p, 0, i, j] - ax * turn_parent + cx * turn_child
                curves[k, 1, i, j] = curves[p, 1, i, j] - ay * turn_parent + cy * turn_child
        if path >= 0:
            for i in range(n_q):
                w = slopes[p, PHI, i]  # zero for i = col: the parent does not turn with its child's joint
                curves[k, 0, i, col] -= t1y * w
                curves[k, 0, col, i] -= t1y * w
                curves[k, 1, i, col] += t1x * w
                curves[k, 1, col, i] += t1x * w
            curves[k, 0, col, col] += t2x
            curves[k, 1, col, col] += t2y


@njit(error_model="numpy", inline="always")
def _points_hessian(layout, m, frames, slopes, curves, hess, n_bodies):
    """The Hessian d2l/dq2 (m per rad^2; hess (J, J), overwritten) of muscle m's path of points: per
    segment d = P_b - P_a of length s and direction u, (dd_i . dd_j - (u . dd_i)(u . dd_j)) / s
    + u . d2d_ij, a point P = O + a (a fixed in its body) having dP = dO + R90 a dphi and
    d2P = d2O - a dphi_i dphi_j (``_frame_curves``). Two points that meet: NaN."""
    n_q = hess.shape[0]
    hess[:, :] = 0.0
    for row in range(layout.rows[m, 0] + 1, layout.rows[m, 1]):
        a, b = layout.point_body[row - 1], layout.point_body[row]
        if a < 0:
            a = n_bodies
        if b < 0:
            b = n_bodies
        ca, sa = math.cos(frames[a, PHI]), math.sin(frames[a, PHI])
        cb, sb = math.cos(frames[b, PHI]), math.sin(frames[b, PHI])
        aax = layout.point_local[row - 1, 0] * ca - layout.point_local[row - 1, 1] * sa
        aay = layout.point_local[row - 1, 0] * sa + layout.point_local[row - 1, 1] * ca
        abx = layout.point_local[row, 0] * cb - layout.point_local[row, 1] * sb
        aby = layout.point_local[row, 0] * sb + layout.point_local[row, 1] * cb
        dx = frames[b, ORIGIN_X] + abx - frames[a, ORIGIN_X] - aax
        dy = frames[b, ORIGIN_Y] + aby - frames[a, ORIGIN_Y] - aay
        segment = math.sqrt(dx * dx + dy * dy)
        ux, uy = dx / segment, dy / segment
        for i in range(n_q):
            dxi = slopes[b, ORIGIN_X, i] - aby * slopes[b, PHI, i] - slopes[a, ORIGIN_X, i] + aay * slopes[a, PHI, i]
            dyi = slopes[b, ORIGIN_Y, i] + abx * slopes[b, PHI, i] - slopes[a, ORIGIN_Y, i] - aax * slopes[a, PHI, i]
            ui = ux * dxi + uy * dyi
            for j in range(n_q):
                dxj = (slopes[b, ORIGIN_X, j] - aby * slopes[b, PHI, j] - slopes[a, ORIGIN_X, j]
                       + aay * slopes[a, PHI, j])
                dyj = (slopes[b, ORIGIN_Y, j] + abx * slopes[b, PHI, j] - slopes[a, ORIGIN_Y, j]
                       - aax * slopes[a, PHI, j])
                turn_a, turn_b = slopes[a, PHI, i] * slopes[a, PHI, j], slopes[b, PHI, i] * slopes[b, PHI, j]
                ddx = curves[b, 0, i, j] - abx * turn_b - curves[a, 0, i, j] + aax * turn_a
                ddy = curves[b, 1, i, j] - aby * turn_b - curves[a, 1, i, j] + aay * turn_a
                hess[i, j] += ((dxi * dxj + dyi * dyj) - ui * (ux * dxj + uy * dyj)) / segment + ux * ddx + uy * ddy


@njit(error_model="numpy")
def points_hessians(q, layout, frames, slopes, curves, out):
    """The Hessians d2l/dq2 (m per rad^2) of the muscles of ``layout`` whose paths run through points,
    at the coordinates q (J,), into out[m] (J, J) (the other muscles' rows untouched): frames, slopes
    ``_frames``' at q; curves (B + 1, 2, J, J) scratch (``_frame_curves``). A plain kernel, not
    inlined: the RK4 driver calls it once a stage, and it compiles once for every driver variant."""
    _frame_curves(q, layout, frames, slopes, curves)
    n_bodies = layout.body_int.shape[0]
    for m in range(layout.kind.shape[0]):
        if layout.kind[m] == POINTS:
            _points_hessian(layout, m, frames, slopes, curves, out[m], n_bodies)


@njit(error_model="numpy")
def hessians(q, layout, out, table, frames, slopes, curves):
    """The Hessians d2l/dq2 (m per rad^2) of the muscle paths of ``layout`` at the coordinates q (J,)
    into out (M, J, J), both forms exact. Scratch: table (J, 2, MAX_POWER + 1) (``_powers``), frames
    (B + 1, N_FRAME), slopes (B + 1, N_FRAME, J) (``_frames``, zero on entry: row B is ground) and
    curves (B + 1, 2, J, J) (``_frame_curves``)."""
    _powers(q, layout, table)
    _frames(q, layout, frames, slopes)
    points_hessians(q, layout, frames, slopes, curves, out)
    for m in range(layout.kind.shape[0]):
        if layout.kind[m] != POINTS:
            _polynomial_hessian(layout, m, out[m], table)


def path_hessians(model: Model, q, layout: MusclePaths | None = None) -> np.ndarray:
    """The Hessians d2l/dq2 (M, J, J) (m per rad^2; m per m^2 for translations) of ``model.muscles``'
    lengths at the coordinates q (J,) (``hessians``); ``layout``: ``muscle_layout(model)``, made here if
    not given. ValueError for q of another shape."""
    q = np.ascontiguousarray(q, dtype=float)
    n_coordinates = model.n_joints
    if q.shape != (n_coordinates,):
        raise ValueError(f"coordinates must have shape ({n_coordinates},), got {q.shape}")
    layout = muscle_layout(model) if layout is None else layout
    n_bodies = layout.body_int.shape[0]
    out = np.zeros((len(model.muscles), n_coordinates, n_coordinates))
    hessians(q, layout, out, np.zeros((n_coordinates, 2, MAX_POWER + 1)), np.zeros((n_bodies + 1, N_FRAME)),
             np.zeros((n_bodies + 1, N_FRAME, n_coordinates)), np.zeros((n_bodies + 1, 2, n_coordinates, n_coordinates)))
    return out
