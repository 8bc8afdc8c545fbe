"""The three indicators of the benchmark: RMSE of rotation, RMSE of torque, runtime."""

from __future__ import annotations

import numpy as np

from .integrate import SimulationResult


def rmse_rot_deg(result: SimulationResult, theta_desired: np.ndarray) -> float:
    """RMSE (degrees) of the simulated rotation against theta_desired (rad, shape (n,), the motion's samples),
    over the samples reached."""
    reached = result.reached
    if not reached.any():
        return float("nan")
    error = np.degrees(result.theta[reached] - theta_desired[reached])
    return float(np.sqrt(np.mean(error**2)))


def rmse_torque_nm(result: SimulationResult, torque_inverse: np.ndarray) -> float:
    """RMSE (N m) of the total applied elbow torque against the inverse-dynamics torque
    (shape (n,)), over the samples reached."""
    reached = result.reached
    if not reached.any():
        return float("nan")
    return float(np.sqrt(np.mean((result.torque[reached] - torque_inverse[reached]) ** 2)))
