"""Time-varying LQR about the desired trajectory, from the nominal model's minimal equations
(``fdbench.multibody.lqr``)."""

from __future__ import annotations

from ..method_options import MethodOption
from .base import CONTROLLERS, Controller, Design, Plan, check_non_negative, check_positive
from ..multibody.lqr import lqr_gains, warm_up

# The Riccati equation of J coordinates has 4 J^2 states and its CasADi expressions grow as J^3.
# `fdbench control --controller lqr` on a chain of J forearms (tests/test_big_models.py's) took
# 4.3 s and 0.39 GB (J = 20), 14 s and 0.73 GB (30), 36 s and 1.25 GB (40), 137 s and 3.7 GB (60);
# on a star 3.3 s (30), 6 s (40), 80 s and 2.9 GB (100), on an idle core (5 to 40 times longer with
# both cores busy). Beyond 40 coordinates it takes minutes and gigabytes.
MAX_COORDINATES = 40


@CONTROLLERS.register("lqr")
class LQR(Controller):
    """Weights (Bryson's rule: each weight is 1 / the square of the deviation that is as costly as
    1 N m of torque): q_angle = 1e4 rad^-2 (an error of 0.01 rad, 0.57 deg), q_rate = 1 s^2/rad^2
    (1 rad/s), r_torque = 1 (N m)^-2, the same on every joint. On the forearm about theta = 0 these
    give kp = 100 N m/rad and kd = 3 N m s/rad: a closed-loop natural frequency of 50 rad/s with
    damping 0.75, close to the paper's PD gains (80 N m/rad) in stiffness and better damped. They are
    not scaled per joint: the gains already follow each joint's inertia through the linearisation."""

    name = "lqr"
    summary = ("time-varying linear-quadratic regulator about the desired trajectory, gains from the "
               "Riccati equation integrated backwards along it (as Drake's FiniteHorizonLinearQuadraticRegulator "
               "and python-control's lqr)")

    command_line = {
        "q_angle": MethodOption("weight of the squared angle error, rad^-2 (1e4: 0.01 rad costs as much as 1 N m).",
                                default=1e4),
        "q_rate": MethodOption("weight of the squared rate error, s^2 rad^-2.", default=1.0),
        "r_torque": MethodOption("weight of the squared torque correction, (N m)^-2; positive.", default=1.0),
    }

    def __init__(self, q_angle: float = 1e4, q_rate: float = 1.0, r_torque: float = 1.0):
        self.q_angle = check_positive("--q-angle", q_angle)  # rad^-2
        self.q_rate = check_non_negative("--q-rate", q_rate)  # s^2 rad^-2
        self.r_torque = check_positive("--r-torque", r_torque)  # (N m)^-2

    def check_model(self, model) -> None:
        J = model.n_joints
        if J > MAX_COORDINATES:
            raise ValueError(f"--controller lqr: model {model.name!r} has {J} coordinates; lqr takes at most "
                             f"{MAX_COORDINATES} (its Riccati equation has 4 J^2 = {4 * J * J} states and takes "
                             "minutes to build beyond that: 2.3 min and 3.7 GB for a chain of 60); use pd or "
                             "computed-torque")

    def warm_up(self, plan: Plan) -> None:
        warm_up(plan.model)

    def design(self, plan: Plan) -> Design:
        gains = lqr_gains(plan.model, plan.motion, self.q_angle, self.q_rate, self.r_torque)
        return Design(plan.feedforward(), gains=gains)
