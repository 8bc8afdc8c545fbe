"""The paper's desired motion, eq. 5: the elbow from -45 deg to 0 over [0, 1] s along the warped
time t* = a1 t + (1 - a1) t^2, sampled every 1 ms (the forearm's named motions). 'paper' takes the
rates as eq. 5 prints them (derivatives in t*: the paper's figures); 'exact' by the chain rule in t.
"""

from __future__ import annotations

import numpy as np

from .base import Motion, grid

A1 = 0.05
AMPLITUDE = np.pi / 4  # L of eq. 5, rad
T_FINAL = 1.0  # s, the duration of eq. 5
KINEMATICS = ("paper", "exact")  # eq. 5's two variants
START, GOAL = -AMPLITUDE, 0.0  # rad, the angle at t = 0 and at t = T_FINAL

_SAMPLES = grid(T_FINAL)


def warped_time(t):
    """t*(t) and dt*/dt, dimensionless."""
    t = np.asarray(t, dtype=float)
    return A1 * t + (1 - A1) * t**2, A1 + 2 * (1 - A1) * t


def eq5(t, kinematics: str = "paper"):
    """theta (rad), theta' (rad/s), theta'' (rad/s^2) of eq. 5 at times t (s)."""
    ts, dts = warped_time(t)
    phase = 2 * np.pi * ts
    theta = AMPLITUDE * (ts - np.sin(phase) / (2 * np.pi) - 1)
    dtheta = AMPLITUDE * (1 - np.cos(phase))  # d theta / d t*
    ddtheta = 2 * np.pi * AMPLITUDE * np.sin(phase)  # d^2 theta / d t*^2
    if kinematics == "paper":
        return theta, dtheta, ddtheta
    return theta, dtheta * dts, ddtheta * dts**2 + dtheta * 2 * (1 - A1)


class Eq5(Motion):
    """Eq. 5 over [0, 1] s in one of its variants (``KINEMATICS``), sampled every 1 ms, named
    ``name`` (default: the variant's name)."""

    def __init__(self, variant: str = "paper", name: str | None = None):
        self.variant = check_kinematics(variant)
        self.name = variant if name is None else name

    @property
    def samples(self) -> np.ndarray:
        return _SAMPLES

    def __call__(self, t):
        return eq5(t, self.variant)


def check_kinematics(kinematics: str) -> str:
    if kinematics not in KINEMATICS:
        from ...registry import unknown_name_message

        raise ValueError(unknown_name_message("kinematics", kinematics, list(KINEMATICS)))
    return kinematics


def as_motion(motion) -> Motion:
    """A Motion from a Motion or the name of one of eq. 5's variants ('paper', 'exact')."""
    if isinstance(motion, Motion):
        return motion
    return _VARIANTS[check_kinematics(motion)]


_VARIANTS = {variant: Eq5(variant) for variant in KINEMATICS}


def sample_times() -> np.ndarray:
    """The 1001 sample instants 0, 1 ms, ..., 1 s of eq. 5 (a read-only array)."""
    return _SAMPLES


def desired_motion(t, kinematics="paper"):
    """theta (rad), theta' (rad/s), theta'' (rad/s^2) at times t (s) of a motion or of the named
    variant of eq. 5, each shaped like t."""
    return as_motion(kinematics)(t)
