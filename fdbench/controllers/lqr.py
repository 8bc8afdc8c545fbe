"""Time-varying LQR about the desired trajectory, on the nominal minimal-coordinate model.

Along theta_d(t) the model I1 theta'' = tau - G cos(theta) linearises to x' = A(t) x + B u for
x = [theta - theta_d, theta' - theta'_d] and u = tau - tau_ID, with A(t) = [[0, 1],
[G sin(theta_d) / I1, 0]] and B = [0, 1/I1]. The Riccati equation

    -P' = A^T P + P A - P B B^T P / r + Q,    Q = diag(q_angle, q_rate),

is integrated backwards over the motion from P(T) = the algebraic Riccati solution of the final
linearisation (an infinite-horizon tail, so the gains do not fade at the end of the motion), and
the feedback is u = -K(t) x, K = B^T P / r: tau = tau_ID(t) + kp(t) (theta_d - theta)
+ kd(t) (theta'_d - theta') with kp = P12 / (r I1), kd = P22 / (r I1).
"""

from __future__ import annotations

import numpy as np

from ..integrate import FeedbackLaw, Settings
from ..inverse import Feedforward
from ..minimal import gravity_moment
from ..motion import desired_motion
from .base import CONTROLLERS, Controller, check_non_negative, check_positive


@CONTROLLERS.register("lqr")
class LQR(Controller):
    """Weights (Bryson's rule: each weight is 1 / the square of the deviation that is as costly as
    1 N m of torque): q_angle = 1e4 rad^-2 (an error of 0.01 rad, 0.57 deg), q_rate = 1 s^2/rad^2
    (1 rad/s), r_torque = 1 (N m)^-2. On the forearm about theta = 0 these give kp = 100 N m/rad
    and kd = 3 N m s/rad: a closed-loop natural frequency of 50 rad/s with damping 0.75, close to
    the paper's PD gains (80 N m/rad) in stiffness and better damped."""

    name = "lqr"
    summary = ("time-varying linear-quadratic regulator about the desired trajectory, gains from the "
               "Riccati equation integrated backwards along it (as Drake's FiniteHorizonLinearQuadraticRegulator "
               "and python-control's lqr)")

    def __init__(self, q_angle: float = 1e4, q_rate: float = 1.0, r_torque: float = 1.0):
        self.q_angle = check_positive("--q-angle", q_angle)  # rad^-2
        self.q_rate = check_non_negative("--q-rate", q_rate)  # s^2 rad^-2
        self.r_torque = check_positive("--r-torque", r_torque)  # (N m)^-2

    def warm_up(self) -> None:
        import scipy.integrate  # noqa: F401
        import scipy.linalg  # noqa: F401

    def design(self, settings: Settings):
        model, kinematics = settings.nominal_model, settings.kinematics
        G, inertia = gravity_moment(model), model.I1

        def a21(t):
            return G * np.sin(desired_motion(t, kinematics)[0]) / inertia

        weights = np.diag([self.q_angle, self.q_rate])
        p_final = algebraic_riccati(float(a21(settings.motion.duration)), inertia, weights, self.r_torque)
        kp, kd = riccati_gains(a21, inertia, weights, self.r_torque, p_final, 0.0, settings.motion.duration)
        return Feedforward(model, kinematics), FeedbackLaw(kp, kd)


def algebraic_riccati(a21: float, inertia: float, weights: np.ndarray, r: float) -> np.ndarray:
    """The stabilising solution P (2, 2) of the algebraic Riccati equation for A = [[0, 1],
    [a21, 0]] (1/s^2), B = [0, 1/inertia] (inertia in kg m^2), Q = weights (2, 2), R = r."""
    from scipy.linalg import solve_continuous_are

    A = np.array([[0.0, 1.0], [a21, 0.0]])
    B = np.array([[0.0], [1.0 / inertia]])
    return solve_continuous_are(A, B, weights, np.array([[r]]))


def riccati_gains(a21, inertia: float, weights: np.ndarray, r: float, p_final: np.ndarray,
                  t0: float, t1: float, rtol: float = 1e-9, atol: float = 1e-9):
    """Integrate the Riccati differential equation of A(t) = [[0, 1], [a21(t), 0]], B = [0, 1/inertia]
    backwards from P(t1) = p_final (2, 2) to t0 (s); return the gains kp(t) (N m/rad) and kd(t)
    (N m s/rad) of K = B^T P / r as functions of times t in [t0, t1], shape (n,) -> (n,)."""
    from scipy.integrate import solve_ivp

    b2_r = 1.0 / (inertia**2 * r)
    q11, q22 = float(weights[0, 0]), float(weights[1, 1])
    q12 = float(weights[0, 1])

    def rhs(t, p):
        p11, p12, p22 = p
        a = float(a21(t))
        return [
            -(2 * a * p12 - b2_r * p12 * p12 + q11),
            -(a * p22 + p11 - b2_r * p12 * p22 + q12),
            -(2 * p12 - b2_r * p22 * p22 + q22),
        ]

    p_end = [float(p_final[0, 0]), float(p_final[0, 1]), float(p_final[1, 1])]
    solution = solve_ivp(rhs, (t1, t0), p_end, method="RK45", dense_output=True, rtol=rtol, atol=atol)
    if not solution.success:
        raise ArithmeticError(f"the Riccati equation could not be integrated: {solution.message}")
    scale = 1.0 / (inertia * r)

    def kp(t):
        return scale * solution.sol(np.clip(t, t0, t1))[1]

    def kd(t):
        return scale * solution.sol(np.clip(t, t0, t1))[2]

    return kp, kd
