"""The desired elbow motion of eq. 5 in two kinematics variants.

``paper``: the velocity and acceleration exactly as eq. 5 prints them, derivatives with respect
to the warped time t* (this is what reproduces the paper's figures). ``exact``: derivatives with
respect to t by the chain rule through t*(t) = a1 t + (1 - a1) t^2 (kinematically consistent).
"""

from __future__ import annotations

import numpy as np

A1 = 0.05
AMPLITUDE = np.pi / 4  # L of eq. 5, rad
T_FINAL = 1.0  # s
SAMPLE_DT = 1e-3  # s, the sampling of every reported history
KINEMATICS = ("paper", "exact")


def sample_times() -> np.ndarray:
    """The 1001 sample instants 0, 1 ms, ..., 1 s (a read-only array)."""
    return _SAMPLES


_SAMPLES = np.linspace(0.0, T_FINAL, int(round(T_FINAL / SAMPLE_DT)) + 1)
_SAMPLES.flags.writeable = False


def check_kinematics(kinematics: str) -> str:
    if kinematics not in KINEMATICS:
        from .registry import unknown_name_message

        raise ValueError(unknown_name_message("kinematics", kinematics, list(KINEMATICS)))
    return kinematics


def warped_time(t):
    """t*(t) and dt*/dt, dimensionless."""
    t = np.asarray(t, dtype=float)
    return A1 * t + (1 - A1) * t**2, A1 + 2 * (1 - A1) * t


def desired_motion(t, kinematics: str = "paper"):
    """theta (rad), theta' (rad/s), theta'' (rad/s^2) at times t (s), each shaped like t."""
    check_kinematics(kinematics)
    ts, dts = warped_time(t)
    phase = 2 * np.pi * ts
    theta = AMPLITUDE * (ts - np.sin(phase) / (2 * np.pi) - 1)
    dtheta = AMPLITUDE * (1 - np.cos(phase))  # d theta / d t*
    ddtheta = 2 * np.pi * AMPLITUDE * np.sin(phase)  # d^2 theta / d t*^2
    if kinematics == "paper":
        return theta, dtheta, ddtheta
    return theta, dtheta * dts, ddtheta * dts**2 + dtheta * 2 * (1 - A1)
