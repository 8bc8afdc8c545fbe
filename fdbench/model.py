"""The forearm model of Table 1 in mixed coordinates q = [x2, y2, theta] (eqs. 1, 4, 9-11).

Point 1 (the elbow) is fixed at the origin; point 2 is the far end of the forearm. SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Forearm:
    """Constants of Table 1. Override any of them: ``Forearm(F_ext=0.0)``."""

    L12: float = 0.33  # forearm length, m
    L1G: float = 0.11  # elbow to centre of mass, m
    m: float = 1.0  # mass, kg
    I1: float = 0.04  # moment of inertia about the elbow, kg m^2
    F_ext: float = 15.0  # vertical load at point 2 (downwards), N
    g: float = 9.81  # gravity, m/s^2

    @property
    def point_mass(self) -> float:
        """Diagonal entry I1 / L12^2 of the mass matrix, kg."""
        return self.I1 / self.L12**2

    @property
    def load_y(self) -> float:
        """y component of Q_ext (eq. 4): -F_ext - m g L1G / L12, N."""
        return -self.F_ext - self.m * self.g * self.L1G / self.L12

    def mass_matrix(self) -> np.ndarray:
        """M of eq. 4, shape (3, 3)."""
        return np.diag([self.point_mass, self.point_mass, 0.0])

    def external_forces(self) -> np.ndarray:
        """Q_ext of eq. 4 (external load plus gravity through C_G), shape (3,)."""
        c_g = self.L1G / self.L12 * np.diag([1.0, 1.0, 0.0])
        return np.array([0.0, -self.F_ext, 0.0]) + c_g.T @ np.array([0.0, -self.m * self.g, 0.0])

    def coordinates(self, theta, theta_dot, theta_ddot):
        """q, q', q'' from the independent coordinate (eq. 7); each of shape (..., 3)."""
        theta, w, dw = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (theta, theta_dot, theta_ddot)))
        c, s, L = np.cos(theta), np.sin(theta), self.L12
        q = np.stack([L * c, L * s, theta], axis=-1)
        qd = np.stack([-L * s * w, L * c * w, w], axis=-1)
        qdd = np.stack([-L * (c * w**2 + s * dw), L * (-s * w**2 + c * dw), dw], axis=-1)
        return q, qd, qdd

    def velocity_transform(self, theta) -> np.ndarray:
        """R = dq/dz (eq. 4), shape (..., 3)."""
        theta = np.asarray(theta, dtype=float)
        return np.stack([-self.L12 * np.sin(theta), self.L12 * np.cos(theta), np.ones_like(theta)], axis=-1)

    def constraints(self, q) -> np.ndarray:
        """Phi(q) of eq. 9, shape (..., 2); point 1 at the origin."""
        q = np.asarray(q, dtype=float)
        x, y, th = q[..., 0], q[..., 1], q[..., 2]
        return np.stack([x**2 + y**2 - self.L12**2, y - self.L12 * np.sin(th)], axis=-1)

    def jacobian(self, q) -> np.ndarray:
        """Phi_q(q) of eq. 10, shape (2, 3)."""
        x, y, th = q
        return np.array([[2 * x, 2 * y, 0.0], [0.0, 1.0, -self.L12 * np.cos(th)]])

    def jacobian_dot_qdot(self, q, qd) -> np.ndarray:
        """Phi_q' q' (eq. 11 times q'), shape (2,)."""
        vx, vy, w = qd
        return np.array([2 * vx**2 + 2 * vy**2, self.L12 * np.sin(q[2]) * w**2])


@dataclass(frozen=True)
class Penalty:
    """Penalty-formulation parameters of eq. 12: penalty factor alpha, damping ratio xi,
    natural frequency omega (rad/s)."""

    alpha: float = 1e7
    xi: float = 1.0
    omega: float = 10.0


MODEL_KEYS = ("L12", "L1G", "m", "I1", "F_ext", "g")
POSITIVE_KEYS = ("L12", "L1G", "m", "I1")


def checked_constants(kind: str, keys, positive, changes) -> dict:
    """{key: float} from (key, value) pairs of a model's constants: keys among ``keys``, those in
    ``positive`` positive, all finite and of magnitude at most 1e6. ValueError otherwise."""
    values = {}
    for key, value in changes:
        if key not in keys:
            from .registry import unknown_name_message

            raise ValueError(unknown_name_message(f"{kind} constant", key, list(keys)))
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{key} must be a number, got {value!r}") from None
        if not math.isfinite(value) or (key in positive and value <= 0) or abs(value) > 1e6:
            what = "a positive number" if key in positive else "a finite number"
            raise ValueError(f"{key} must be {what} of at most 1e6, got {value}")
        values[key] = value
    return values


# What a human arm's constants can be (SI units): a value outside is most likely a unit mistyped
# (centimetres for metres, grams for kilograms). Warned about, not refused: a study may want it.
PLAUSIBLE = {
    "L12": (0.05, 1.0, "m", "a forearm's length"), "L1G": (0.01, 1.0, "m", "a centre of mass's distance"),
    "L01": (0.05, 1.0, "m", "an upper arm's length"), "L0G": (0.01, 1.0, "m", "a centre of mass's distance"),
    "m": (0.1, 20.0, "kg", "a forearm's mass"), "m0": (0.1, 20.0, "kg", "an upper arm's mass"),
    "I1": (1e-4, 2.0, "kg m^2", "a forearm's inertia about the elbow"),
    "I0": (1e-4, 2.0, "kg m^2", "an upper arm's inertia about the shoulder"),
    "F_ext": (-1000.0, 1000.0, "N", "a load held in the hand"), "g": (0.0, 30.0, "m/s^2", "gravity"),
}


def implausible(changes) -> list[str]:
    """One text per (key, value) pair of ``changes`` outside what a human arm can be (PLAUSIBLE),
    naming the value and its unit: 'L12 = 30 m is implausible (a forearm's length is 0.05 to 1 m;
    centimetres typed for metres?)'."""
    texts = []
    for key, value in dict(changes).items():
        if key not in PLAUSIBLE or not isinstance(value, (int, float)):
            continue
        low, high, unit, what = PLAUSIBLE[key]
        if not low <= value <= high:
            hint = "; centimetres typed for metres?" if unit == "m" and 100 * low <= value <= 100 * high else ""
            hint = "; grams typed for kilograms?" if unit == "kg" and 1000 * low <= value <= 1000 * high else hint
            texts.append(f"{key} = {value:g} {unit} is implausible ({what} is {low:g} to {high:g} {unit}{hint})")
    return texts


def forearm_with(changes=()) -> Forearm:
    """Table 1's forearm with some constants changed: ``changes`` are (key, value) pairs of the
    keys L12, L1G, m, I1 (positive) and F_ext, g (any finite value). ValueError otherwise."""
    forearm = Forearm(**checked_constants("model", MODEL_KEYS, POSITIVE_KEYS, changes))
    if forearm.L1G > forearm.L12:
        raise ValueError(f"L1G ({forearm.L1G:g} m) must not exceed L12 ({forearm.L12:g} m)")
    return forearm
