"""Computed-torque control (feedback linearisation) on the nominal model."""

from __future__ import annotations

from ..method_options import MethodOption
from .base import CONTROLLERS, Controller, Design, Plan, check_non_negative


@CONTROLLERS.register("computed-torque")
class ComputedTorque(Controller):
    """tau = M(z) (z''_d + kp e + kd e') + h(z, z'), e = z_d - z, kp = omega_n^2, kd = 2 zeta omega_n,
    M and h the nominal model's at the current state: on the nominal model every joint's error obeys
    e'' + 2 zeta omega_n e' + omega_n^2 e = 0."""

    name = "computed-torque"
    summary = ("cancels the model's dynamics and imposes second-order error dynamics of bandwidth omega_n "
               "(feedback linearisation, as in OpenSim's computed muscle control and Drake's InverseDynamicsController)")

    command_line = {
        "bandwidth": MethodOption("error-dynamics natural frequency omega_n, rad/s.", default=20.0),
        "damping": MethodOption("error-dynamics damping ratio zeta.", default=1.0),
    }

    def __init__(self, bandwidth: float = 20.0, damping: float = 1.0):
        self.bandwidth = check_non_negative("--bandwidth", bandwidth)  # omega_n, rad/s
        self.damping = check_non_negative("--damping", damping)  # zeta, dimensionless

    def design(self, plan: Plan) -> Design:
        return Design(None, self.bandwidth**2, 2 * self.damping * self.bandwidth, computed=True,
                      label="M(z)*z_ddot_d+h(z,z_dot)")
