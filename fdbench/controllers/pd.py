"""PD control with computed feedforward (eqs. 13-14): the paper's controller."""

from __future__ import annotations

from ..integrate import FeedbackLaw, Settings
from ..inverse import Feedforward
from .base import CONTROLLERS, Controller, check_non_negative


@CONTROLLERS.register("pd")
class PD(Controller):
    """tau = tau_ID(t) + kp (theta_d - theta) + kd (theta'_d - theta') with constant gains."""

    name = "pd"
    summary = ("the inverse-dynamics torque plus constant PD feedback on the elbow rotation "
               "(the paper's eqs. 13-14; Drake's PidController with an inverse-dynamics feedforward)")

    def __init__(self, kp: float = 80.0, kd: float = 0.3):
        self.kp = check_non_negative("--kp", kp)  # N m/rad
        self.kd = check_non_negative("--kd", kd)  # N m s/rad

    def design(self, settings: Settings):
        return Feedforward(settings.nominal_model, settings.kinematics), FeedbackLaw(self.kp, self.kd)
