"""The planar two-segment arm (shoulder + elbow) in mixed coordinates
q = [x1, y1, x2, y2, shoulder, elbow]: the natural coordinates of the elbow (point 1) and the hand
(point 2) plus the two joint angles.

y up, gravity along -y, the shoulder (point 0) fixed at the origin. ``shoulder`` is the angle of the
upper arm from the +x axis; ``elbow`` is the angle of the forearm relative to the upper arm, so the
forearm's absolute angle is shoulder + elbow. tau_shoulder acts on the upper arm from the ground,
tau_elbow on the forearm from the upper arm (and opposite on the upper arm): the joint torques are
the generalised forces of the two angle coordinates. SI units, angles in rad.

Constraints (the forearm's eq. 9, once per segment):

    Phi_1 = x1^2 + y1^2 - L01^2                   Phi_3 = y1 - L01 sin(shoulder)
    Phi_2 = (x2-x1)^2 + (y2-y1)^2 - L12^2         Phi_4 = (y2-y1) - L12 sin(shoulder + elbow)

so the mixed coordinates are singular where cos(shoulder) = 0 or cos(shoulder + elbow) = 0, as the
forearm's are at cos(theta) = 0. The mass matrix is that of two planar bars in natural coordinates
(zero in the angle rows); with the upper arm held at shoulder = 0 the forearm's part is Table 1's
model with its elbow at (L01, 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from . import MODELS

JOINTS = ("shoulder", "elbow")


@MODELS.register("arm2")
@dataclass(frozen=True)
class Arm2:
    """Constants of the arm. Upper arm: L01, L0G, m0, I0 (about the shoulder); forearm: Table 1
    (I1 about the elbow, F_ext downwards at the hand). Override any: ``Arm2(m0=2.5)``."""

    L01: float = 0.30  # upper arm length, shoulder to elbow, m
    L0G: float = 0.13  # shoulder to the upper arm's centre of mass, m
    m0: float = 2.0  # upper arm mass, kg
    I0: float = 0.06  # upper arm moment of inertia about the shoulder, kg m^2
    L12: float = 0.33  # forearm length, m
    L1G: float = 0.11  # elbow to the forearm's centre of mass, m
    m: float = 1.0  # forearm mass, kg
    I1: float = 0.04  # forearm moment of inertia about the elbow, kg m^2
    F_ext: float = 15.0  # vertical load at the hand (downwards), N
    g: float = 9.81  # gravity, m/s^2

    joints = JOINTS
    n_joints = 2
    motions = ("reach",)  # the named motions (``arm2_motion``), the default first
    runs = "fdbench.models.arm2_run"  # the module carrying out its runs

    # ------------------------------------------------------------------ constant matrices
    @property
    def point_masses(self) -> tuple[float, float, float]:
        """(m11, m12, m22), kg: the mass matrix of the points is [[m11 I, m12 I], [m12 I, m22 I]]
        (I the 2x2 identity), the upper arm adding I0/L01^2 to m11."""
        a = self.L1G / self.L12
        m22 = self.I1 / self.L12**2
        m12 = self.m * a - m22
        m11 = self.I0 / self.L01**2 + self.m * (1.0 - 2.0 * a) + m22
        return m11, m12, m22

    @property
    def loads_y(self) -> tuple[float, float]:
        """y components of Q_ext at the elbow and at the hand, N: gravity of both segments shared
        by their end points, plus -F_ext at the hand."""
        a = self.L1G / self.L12
        elbow = -self.m0 * self.g * self.L0G / self.L01 - self.m * self.g * (1.0 - a)
        hand = -self.F_ext - self.m * self.g * a
        return elbow, hand

    def mass_matrix(self) -> np.ndarray:
        """M, shape (6, 6) (zero in the angle rows and columns)."""
        m11, m12, m22 = self.point_masses
        M = np.zeros((6, 6))
        M[:4, :4] = np.kron(np.array([[m11, m12], [m12, m22]]), np.eye(2))
        return M

    def external_forces(self) -> np.ndarray:
        """Q_ext (gravity and the load), shape (6,)."""
        elbow, hand = self.loads_y
        return np.array([0.0, elbow, 0.0, hand, 0.0, 0.0])

    # ------------------------------------------------------------------ kinematics
    def coordinates(self, angles, velocities, accelerations):
        """q, q', q'' from the joint angles (rad), velocities (rad/s) and accelerations (rad/s^2),
        each of shape (..., 2) [shoulder, elbow]; returns three arrays of shape (..., 6)."""
        z, w, dw = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (angles, velocities, accelerations)))
        s, e = z[..., 0], z[..., 1]
        ws, we = w[..., 0], w[..., 1]
        dws, dwe = dw[..., 0], dw[..., 1]
        a, wa, dwa = s + e, ws + we, dws + dwe
        p1 = _circle(self.L01, s, ws, dws)
        p2 = _circle(self.L12, a, wa, dwa)
        q = np.stack([p1[0], p1[1], p1[0] + p2[0], p1[1] + p2[1], s, e], axis=-1)
        qd = np.stack([p1[2], p1[3], p1[2] + p2[2], p1[3] + p2[3], ws, we], axis=-1)
        qdd = np.stack([p1[4], p1[5], p1[4] + p2[4], p1[5] + p2[5], dws, dwe], axis=-1)
        return q, qd, qdd

    def velocity_transform(self, angles) -> np.ndarray:
        """R = dq/dz for z = [shoulder, elbow], shape (..., 6, 2)."""
        z = np.asarray(angles, dtype=float)
        s, a = z[..., 0], z[..., 0] + z[..., 1]
        zero, one = np.zeros_like(s), np.ones_like(s)
        col_s = [-self.L01 * np.sin(s), self.L01 * np.cos(s), -self.L01 * np.sin(s) - self.L12 * np.sin(a),
                 self.L01 * np.cos(s) + self.L12 * np.cos(a), one, zero]
        col_e = [zero, zero, -self.L12 * np.sin(a), self.L12 * np.cos(a), zero, one]
        return np.stack([np.stack(col_s, axis=-1), np.stack(col_e, axis=-1)], axis=-1)

    def constraints(self, q) -> np.ndarray:
        """Phi(q), shape (..., 4) (m^2, m^2, m, m)."""
        q = np.asarray(q, dtype=float)
        x1, y1, x2, y2, s, e = (q[..., k] for k in range(6))
        dx, dy = x2 - x1, y2 - y1
        return np.stack([x1**2 + y1**2 - self.L01**2, dx**2 + dy**2 - self.L12**2,
                         y1 - self.L01 * np.sin(s), dy - self.L12 * np.sin(s + e)], axis=-1)

    def jacobian(self, q) -> np.ndarray:
        """Phi_q(q), shape (4, 6)."""
        x1, y1, x2, y2, s, e = q
        dx, dy = x2 - x1, y2 - y1
        ca = self.L12 * math.cos(s + e)
        return np.array([
            [2 * x1, 2 * y1, 0.0, 0.0, 0.0, 0.0],
            [-2 * dx, -2 * dy, 2 * dx, 2 * dy, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0, -self.L01 * math.cos(s), 0.0],
            [0.0, -1.0, 0.0, 1.0, -ca, -ca],
        ])

    def jacobian_dot_qdot(self, q, qd) -> np.ndarray:
        """Phi_q' q', shape (4,)."""
        vx1, vy1, vx2, vy2, ws, we = qd
        s, a = q[4], q[4] + q[5]
        return np.array([2 * (vx1**2 + vy1**2), 2 * ((vx2 - vx1) ** 2 + (vy2 - vy1) ** 2),
                         self.L01 * math.sin(s) * ws**2, self.L12 * math.sin(a) * (ws + we) ** 2])

    # ------------------------------------------------------------------ inverse dynamics
    def joint_torques(self, angles, velocities, accelerations) -> np.ndarray:
        """Inverse dynamics Q_m = R^T (M q'' - Q_ext) (the forearm's eq. 3): the joint torques
        [tau_shoulder, tau_elbow] (N m) of a joint motion given as in ``coordinates``, shape (..., 2)."""
        z = np.asarray(angles, dtype=float)
        _, _, qdd = self.coordinates(z, velocities, accelerations)
        generalized = qdd @ self.mass_matrix().T - self.external_forces()
        return np.einsum("...ij,...i->...j", self.velocity_transform(z), generalized)


def _circle(L, angle, w, dw):
    """A point at distance L (m) and absolute angle (rad) from a pivot: x, y, x', y', x'', y''."""
    c, s = np.cos(angle), np.sin(angle)
    return (L * c, L * s, -L * s * w, L * c * w, -L * (c * w**2 + s * dw), L * (-s * w**2 + c * dw))


MODEL_KEYS = tuple(f.name for f in fields(Arm2))
POSITIVE_KEYS = ("L01", "L0G", "m0", "I0", "L12", "L1G", "m", "I1")


def arm2_with(changes=()) -> Arm2:
    """The default arm with some constants changed: ``changes`` are (key, value) pairs; lengths,
    masses and inertias positive, F_ext and g any finite number, all of magnitude at most 1e6, and
    the centres of mass on their segments. ValueError otherwise."""
    from ..model import checked_constants

    values = checked_constants("arm2", MODEL_KEYS, POSITIVE_KEYS, changes)
    arm = Arm2(**values)
    for com, length in (("L0G", "L01"), ("L1G", "L12")):
        if getattr(arm, com) > getattr(arm, length):
            raise ValueError(f"{com} ({getattr(arm, com):g} m) must not exceed {length} ({getattr(arm, length):g} m)")
    return arm


Arm2.keys = MODEL_KEYS  # the constants --model and --plant KEY=VALUE may change
Arm2.with_changes = staticmethod(arm2_with)
