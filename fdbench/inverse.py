"""Inverse dynamics of eq. 3: Q_m = R^T (M q'' - Q_ext), with q, q', q'' from eqs. 7-8."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import Forearm
from .motion import Motion, as_motion


@dataclass(frozen=True)
class InverseResult:
    """Histories on the time grid ``t`` (s), each of shape (n,)."""

    t: np.ndarray
    theta: np.ndarray  # rad
    theta_dot: np.ndarray  # rad/s
    theta_ddot: np.ndarray  # rad/s^2
    torque: np.ndarray  # elbow drive torque M_elbow, N m
    kinematics: str  # the motion's name


def elbow_torque(t, model: Forearm = Forearm(), kinematics: str | Motion = "paper") -> np.ndarray:
    """The inverse-dynamics elbow torque (N m) at times t (s), shaped like t."""
    return inverse_dynamics(t, model, kinematics).torque


def inverse_dynamics(t=None, model: Forearm = Forearm(), kinematics: str | Motion = "paper") -> InverseResult:
    """Solve eq. 3 at times t (s) (default: the motion's samples; eq. 5: 1001 of [0, 1] s) on a
    Motion or the named variant of eq. 5."""
    motion = as_motion(kinematics)
    t = motion.samples if t is None else np.asarray(t, dtype=float)
    theta, w, dw = motion(t)
    _, _, qdd = model.coordinates(theta, w, dw)
    R = model.velocity_transform(theta)
    generalized = qdd @ model.mass_matrix().T - model.external_forces()
    torque = np.sum(R * generalized, axis=-1)
    return InverseResult(t, theta, w, dw, torque, motion.name)


class Feedforward:
    """The inverse-dynamics torque as a torque function t (s) -> N m, remembering the grids it
    was evaluated on (a simulation asks for the same grid many times)."""

    def __init__(self, model: Forearm = Forearm(), kinematics: str | Motion = "paper"):
        self.model, self.kinematics = model, kinematics
        self._memo: dict[bytes, np.ndarray] = {}
        self._last: tuple = (None, None)

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if t.ndim != 1 or t.size < 16:
            return elbow_torque(t, self.model, self.kinematics)
        if t is self._last[0]:  # the same (read-only, cached) grid as last time
            return self._last[1]
        key = t.tobytes()
        if key not in self._memo:
            if len(self._memo) > 8:
                self._memo.clear()
            torque = elbow_torque(t, self.model, self.kinematics)
            torque.flags.writeable = False
            self._memo[key] = torque
        if not t.flags.writeable:
            self._last = (t, self._memo[key])
        return self._memo[key]
