"""PD control with computed feedforward (eqs. 13-14): the paper's controller, per joint."""

from __future__ import annotations

import numpy as np

from ..method_options import MethodOption
from .base import CONTROLLERS, Controller, Design, Plan, check_non_negative, per_joint

PAPER_KP, PAPER_KD = 80.0, 0.3  # N m/rad, N m s/rad: the paper's PD gains for the forearm (its defaults)
REFERENCE_INERTIA = 0.04  # kg m^2: the paper's forearm about the elbow, for which Kp 80 and Kd 0.3 were tuned


@CONTROLLERS.register("pd")
class PD(Controller):
    """tau = tau_ID(t) + kp (z_d - z) + kd (z'_d - z') with constant gains per joint: ``kp`` and
    ``kd`` where given (the same on every joint), else the paper's 80 N m/rad and 0.3 N m s/rad
    scaled by the joint's inertia I_j / 0.04 kg m^2, I_j the diagonal entry of the nominal mass
    matrix M(z) at the motion's start. Each joint then has the forearm's closed-loop frequency
    sqrt(Kp / I) and damping (as if the joints were uncoupled); the forearm, and a joint of its
    inertia (the arm's elbow), get 80 and 0.3.

    A model with a floating base (a free joint on ground: a walk) gets other defaults: each
    coordinate's effective inertia I_j = 1 / [M(z)^-1]_jj (what it feels while the others move
    freely), the paper's frequency sqrt(80 / 0.04) = 44.7 rad/s and critical damping: kp = I_j w^2,
    kd = 2 I_j w. There M_jj of the base's coordinates holds the whole body (their effective
    inertia is 1 to 40 % of it), so the scaling above puts the coupled system's fastest mode near
    580 rad/s, and with ground reactions the paper's light damping (zeta 0.08) lets a recorded walk
    fall within 2 s."""

    name = "pd"
    summary = ("the inverse-dynamics torque plus constant PD feedback per joint (the paper's eqs. 13-14; Drake's "
               "PidController with an inverse-dynamics feedforward)")

    command_line = {
        "kp": MethodOption("proportional gain, N m/rad, on every joint (default: the paper's 80 on the forearm; on another "
                           "model 80 per 0.04 kg m^2 of each joint's inertia); cmc: the tasks' kp, 1/s^2 (default "
                           "100, OpenSim's CMC examples').", show_default=False),
        "kd": MethodOption("derivative gain, N m s/rad, on every joint (default: the paper's 0.3 on the forearm; on another "
                           "model 0.3 per 0.04 kg m^2 of each joint's inertia); cmc: the tasks' kv, 1/s (default 20).",
                           show_default=False),
    }

    def __init__(self, kp: float | None = None, kd: float | None = None):
        self.kp = None if kp is None else check_non_negative("--kp", kp)  # N m/rad
        self.kd = None if kd is None else check_non_negative("--kd", kd)  # N m s/rad

    def gains(self, plan: Plan) -> tuple[np.ndarray, np.ndarray]:
        """Kp (N m/rad) and Kd (N m s/rad) per joint, shape (J,); the mass matrix only for a default."""
        if self.kp is not None and self.kd is not None:
            return np.full(len(plan.joints), self.kp), np.full(len(plan.joints), self.kd)
        z0 = plan.motion(np.zeros(1))[0][0]
        mass = plan.engine.mass_matrix(z0)
        if plan.engine.model.floating_base is not None:
            inertia, omega = 1.0 / np.diag(np.linalg.inv(mass)), np.sqrt(PAPER_KP / REFERENCE_INERTIA)
            defaults = (inertia * omega**2, 2.0 * inertia * omega)
        else:
            defaults = tuple(paper * np.diag(mass) / REFERENCE_INERTIA for paper in (PAPER_KP, PAPER_KD))
        return tuple(np.full(len(z0), gain) if gain is not None else default
                     for gain, default in zip((self.kp, self.kd), defaults))

    def design(self, plan: Plan) -> Design:
        kp, kd = self.gains(plan)
        return Design(plan.feedforward(), kp, kd, fields={"kp": self.kp, "kd": self.kd,
                                                          **per_joint("kp", plan.joints, kp),
                                                          **per_joint("kd", plan.joints, kd)})
