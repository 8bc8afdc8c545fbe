"""PD control with computed feedforward (eqs. 13-14)."""

from __future__ import annotations

import math

from .integrate import Settings, SimulationResult, simulate
from .inverse import Feedforward


def check_gain(name: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a non-negative finite number, got {value}")
    return value


def feedforward(settings: Settings) -> Feedforward:
    """The inverse-dynamics torque of the settings' nominal model and desired motion, as a torque
    function."""
    return Feedforward(settings.nominal_model, settings.kinematics)


def pd_control(kp: float = 80.0, kd: float = 0.3, settings: Settings = Settings()) -> SimulationResult:
    """Forward dynamics with the inverse-dynamics feedforward plus PD feedback on theta.

    kp in N m/rad, kd in N m s/rad (the paper's gains: 80 and 0.3)."""
    check_gain("kp", kp)
    check_gain("kd", kd)
    return simulate(feedforward(settings), settings, kp, kd)


def track(controller, settings: Settings = Settings(), start=None) -> SimulationResult:
    """Forward dynamics under a controller (a ``controllers.Controller`` or its registered name):
    its feedforward torque plus its feedback law, designed once for these settings. ``start``: an
    initial state [q, q'] of shape (6,) instead of the desired motion's (see ``simulate``)."""
    if isinstance(controller, str):
        from .controllers import make_controller

        controller = make_controller(controller)
    torque, law = controller.design(settings)
    return simulate(torque, settings, law=law, start=start)
