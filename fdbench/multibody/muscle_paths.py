"""Muscle-tendon lengths and moment arms of a model's muscles (``fdbench.multibody.muscles``) at its
coordinates q, exact: a path of points by the planar kinematics of the bodies' frames and their
derivatives by the coordinates (pin angles, a free joint's angle and translations, a joint's path
spline), a polynomial path by its closed-form derivative. A moment arm is -dl/dq (m; for a
translation, dimensionless), OpenSim's ``computeMomentArm`` sign.

The frames follow ``fdbench.multibody.model``: a body's angle is the sum of (coordinate + offset)
along its path from ground; its joint point sits at the parent's ``at_parent`` (plus the path's
(x, y)(angle) in the parent's frame, plus (x, y) for a free joint) and at its own ``at_child``.
"""

from __future__ import annotations

import numpy as np

from .model import GROUND, Model
from .muscles import PointPath, PolynomialPath


def muscle_geometry(model: Model, q) -> tuple[np.ndarray, np.ndarray]:
    """(lengths, moment_arms) of ``model.muscles`` at the coordinates q (rad, m in the model's order):
    for q of shape (J,) lengths (M,) (m) and moment arms (M, J) (-dl/dq: m per rad, m/m for a
    translation); for q of shape (n, J) shapes (n, M) and (n, M, J). ValueError for another shape.
    Where two consecutive points of a path meet, its moment arms are NaN (the length has no slope)."""
    q = np.asarray(q, dtype=float)
    n_coordinates = model.n_joints
    if q.ndim not in (1, 2) or q.shape[-1] != n_coordinates:
        raise ValueError(f"coordinates must have shape ({n_coordinates},) or (n, {n_coordinates}), got {q.shape}")
    single, q = q.ndim == 1, np.atleast_2d(q)
    lengths = np.zeros((q.shape[0], len(model.muscles)))
    arms = np.zeros((q.shape[0], len(model.muscles), n_coordinates))
    frames = body_frames(model, q) if any(isinstance(m.path, PointPath) for m in model.muscles) else {}
    for m, muscle in enumerate(model.muscles):
        if isinstance(muscle.path, PointPath):
            lengths[:, m], slope = _points_length(model, muscle.path, frames, q.shape)
        else:
            lengths[:, m], slope = _polynomial_length(model, muscle.path, q)
        arms[:, m] = -slope
    return (lengths[0], arms[0]) if single else (lengths, arms)


def body_frames(model: Model, q: np.ndarray) -> dict:
    """{body: (phi (n,) rad, dphi (J,), origin (n, 2) m, dorigin (n, 2, J))}: each body frame's angle
    and origin in world axes at the coordinates q (n, J), and their derivatives by the coordinates."""
    n, n_coordinates = q.shape
    ground = (np.zeros(n), np.zeros(n_coordinates), np.zeros((n, 2)), np.zeros((n, 2, n_coordinates)))
    frames, column = {GROUND: ground}, 0
    for joint in model.joints:  # parents first (the model's topological order)
        parent = frames[joint.parent]
        unit = np.zeros(n_coordinates)
        unit[column] = 1.0
        r, dr = _point(parent, joint.at_parent)
        if joint.type == "free":
            r = r + q[:, column + 1:column + 3]
            dr[:, 0, column + 1] += 1.0
            dr[:, 1, column + 2] += 1.0
        if joint.path is not None:  # the joint point moves along (x, y)(angle) in the parent's frame
            angle = q[:, column]
            along, slope = (np.stack([s.evaluate(angle, order) for s in joint.path.splines()], axis=-1)
                            for order in (0, 1))
            arm = _rotate(parent[0], along)
            r = r + arm
            dr = dr + _perp(arm)[..., None] * parent[1] + _rotate(parent[0], slope)[..., None] * unit
        phi, dphi = parent[0] + q[:, column] + joint.offset, parent[1] + unit
        arm = _rotate(phi, np.broadcast_to(np.asarray(joint.at_child, dtype=float), (n, 2)))
        frames[joint.child] = (phi, dphi, r - arm, dr - _perp(arm)[..., None] * dphi)
        column += len(joint.coordinate_names)
    return frames


def _points_length(model: Model, path: PointPath, frames: dict, shape) -> tuple[np.ndarray, np.ndarray]:
    """The path's length (n,) (m) and its derivative by the coordinates (n, J)."""
    n, n_coordinates = shape
    length, slope = np.zeros(n), np.zeros((n, n_coordinates))
    previous = None
    for point in path.points:
        if point.body == GROUND:
            body, local = GROUND, np.asarray(point.at, dtype=float)
        else:  # a body or a frame fixed to one
            body, origin, angle = model.frame(point.body)
            local = np.asarray(origin) + _rotate(np.asarray(angle), np.asarray(point.at, dtype=float))
        current = _point(frames[body], local)
        if previous is not None:
            span = current[0] - previous[0]
            segment = np.hypot(span[:, 0], span[:, 1])
            length += segment
            with np.errstate(invalid="ignore", divide="ignore"):  # two points that meet: no slope (NaN)
                direction = span / segment[:, None]
            slope += np.einsum("nk,nkj->nj", direction, current[1] - previous[1])
        previous = current
    return length, slope


def _polynomial_length(model: Model, path: PolynomialPath, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sum_t c_t prod_k x_k^p_tk (n,) (m) and its derivative by the coordinates (n, J)."""
    columns = [model.coordinates.index(name) for name in path.coordinates]
    x = q[:, columns]
    length, slope = np.zeros(q.shape[0]), np.zeros(q.shape)
    for term in path.terms:
        powers = np.asarray(term.powers)
        length += term.coefficient * np.prod(x**powers, axis=1)
        for k, power in enumerate(term.powers):
            if power:
                lowered = powers.copy()
                lowered[k] -= 1
                slope[:, columns[k]] += term.coefficient * power * np.prod(x**lowered, axis=1)
    return length, slope


def _point(frame: tuple, local) -> tuple[np.ndarray, np.ndarray]:
    """World position (n, 2) of the point ``local`` (m, (2,) or (n, 2)) of a frame and its
    derivative by the coordinates (n, 2, J)."""
    phi, dphi, origin, dorigin = frame
    arm = _rotate(phi, np.broadcast_to(np.asarray(local, dtype=float), origin.shape))
    return origin + arm, dorigin + _perp(arm)[..., None] * dphi


def _rotate(angle, vectors):
    """R(angle) v for angles (n,) and vectors (n, 2) (or one angle and one vector)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([vectors[..., 0] * c - vectors[..., 1] * s, vectors[..., 0] * s + vectors[..., 1] * c], axis=-1)


def _perp(v):
    """R90 v for v of shape (..., 2)."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)
