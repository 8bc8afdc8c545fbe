"""PD control with computed feedforward (eqs. 13-14): the paper's controller, per joint."""

from __future__ import annotations

import numpy as np

from ..spec import PAPER_KD, PAPER_KP
from .base import CONTROLLERS, Controller, Design, Plan, check_non_negative, per_joint

REFERENCE_INERTIA = 0.04  # kg m^2: the paper's forearm about the elbow, for which Kp 80 and Kd 0.3 were tuned


@CONTROLLERS.register("pd")
class PD(Controller):
    """tau = tau_ID(t) + kp (z_d - z) + kd (z'_d - z') with constant gains per joint: ``kp`` and
    ``kd`` where given (the same on every joint), else the paper's 80 N m/rad and 0.3 N m s/rad
    scaled by the joint's inertia I_j / 0.04 kg m^2, I_j the diagonal entry of the nominal mass
    matrix M(z) at the motion's start. Each joint then has the forearm's closed-loop frequency
    sqrt(Kp / I) and damping (as if the joints were uncoupled); the forearm, and a joint of its
    inertia (the arm's elbow), get 80 and 0.3."""

    name = "pd"
    summary = ("the inverse-dynamics torque plus constant PD feedback per joint (the paper's eqs. 13-14; Drake's "
               "PidController with an inverse-dynamics feedforward)")

    def __init__(self, kp: float | None = None, kd: float | None = None):
        self.kp = None if kp is None else check_non_negative("--kp", kp)  # N m/rad
        self.kd = None if kd is None else check_non_negative("--kd", kd)  # N m s/rad

    def gains(self, plan: Plan) -> tuple[np.ndarray, np.ndarray]:
        """Kp (N m/rad) and Kd (N m s/rad) per joint, shape (J,)."""
        z0 = plan.motion(np.zeros(1))[0][0]
        scale = np.diag(plan.engine.mass_matrix(z0)) / REFERENCE_INERTIA
        return tuple(np.full(len(scale), gain) if gain is not None else paper * scale
                     for gain, paper in ((self.kp, PAPER_KP), (self.kd, PAPER_KD)))

    def design(self, plan: Plan) -> Design:
        kp, kd = self.gains(plan)
        return Design(plan.feedforward(), kp, kd, fields={"kp": self.kp, "kd": self.kd,
                                                          **per_joint("kp", plan.joints, kp),
                                                          **per_joint("kd", plan.joints, kd)})
