"""Computed-torque control (feedback linearisation) on the nominal minimal-coordinate model."""

from __future__ import annotations

import numpy as np

from ..integrate import FeedbackLaw, Settings
from ..minimal import gravity_moment
from ..motion import desired_motion
from .base import CONTROLLERS, Controller, check_non_negative


@CONTROLLERS.register("computed-torque")
class ComputedTorque(Controller):
    """tau = I1 (theta''_d + kp e + kd e') + G cos(theta), kp = omega_n^2, kd = 2 zeta omega_n,
    e = theta_d - theta: on the nominal model the error obeys e'' + 2 zeta omega_n e' + omega_n^2 e = 0.

    As the shared feedback law: tau_ff = I1 theta''_d, gains I1 omega_n^2 (N m/rad) and
    2 I1 zeta omega_n (N m s/rad), gravity coefficient G = F_ext L12 + m g L1G (N m)."""

    name = "computed-torque"
    feedforward_label = "I1*theta_ddot_d"
    summary = ("cancels the model's dynamics and imposes second-order error dynamics of bandwidth omega_n "
               "(feedback linearisation, as in OpenSim's computed muscle control and Drake's InverseDynamicsController)")

    def __init__(self, bandwidth: float = 20.0, damping: float = 1.0):
        self.bandwidth = check_non_negative("--bandwidth", bandwidth)  # omega_n, rad/s
        self.damping = check_non_negative("--damping", damping)  # zeta, dimensionless

    def design(self, settings: Settings):
        model, kinematics = settings.nominal_model, settings.kinematics
        inertia = model.I1

        def feedforward(t):
            return inertia * np.asarray(desired_motion(t, kinematics)[2], dtype=float)

        law = FeedbackLaw(inertia * self.bandwidth**2, 2 * inertia * self.damping * self.bandwidth,
                          gravity_moment(model))
        return feedforward, law
