"""The paper's forearm (Table 1) in closed form, written by hand and independent of fdbench: a rod
pinned at the elbow, gravity at its centre of mass and a vertical load at the hand. SI units,
angles in rad (theta from +x, counter-clockwise)."""

from __future__ import annotations

import numpy as np

L12 = 0.33  # m, elbow to hand (the load's point)
L1G = 0.11  # m, elbow to the centre of mass
M = 1.0  # kg
I1 = 0.04  # kg m^2, about the elbow
F_EXT = 15.0  # N, downwards at the hand
G = 9.81  # m/s^2, downwards


def load_moment(L12=L12, L1G=L1G, m=M, F_ext=F_EXT, g=G) -> float:
    """N m: the moment of the load and of gravity about the elbow at theta = 0 (its cos(theta) factor aside)."""
    return F_ext * L12 + m * g * L1G


def elbow_torque(theta, theta_ddot, I1=I1, **constants):
    """N m: the elbow torque of eq. 3, I1 theta'' + cos(theta) (F_ext L12 + m g L1G); any shape."""
    return I1 * np.asarray(theta_ddot) + np.cos(theta) * load_moment(**constants)


def minimal_rhs(tau, I1=I1, **constants):
    """The minimal ODE I1 theta'' = tau(t) - (F_ext L12 + m g L1G) cos(theta) as scipy's
    right-hand side f(t, [theta, theta']) (tau: a function of t (s) -> N m)."""
    moment = load_moment(**constants)

    def rhs(t, y):
        return [y[1], (float(tau(t)) - moment * np.cos(y[0])) / I1]

    return rhs


GRAVITY_TORQUE = load_moment()  # N m: the load's and gravity's torque at theta = 0


def torque_along(theta, theta_dot, theta_ddot):
    """The elbow torque (N m) that moves Table 1's forearm along theta(t) (rad, rad/s, rad/s^2; any
    shape), eq. 5's (theta, theta', theta'') as they come; theta_dot is unused (one degree of freedom
    has no velocity terms)."""
    return elbow_torque(theta, theta_ddot)


def feedback_rhs(torque):
    """The minimal ODE's right-hand side (t, [theta, theta']) -> [theta', theta''] under a feedback
    torque torque(t, theta, theta_dot) (N m), for scipy's solve_ivp."""

    def rhs(t, y):
        return [y[1], (torque(t, y[0], y[1]) - GRAVITY_TORQUE * np.cos(y[0])) / I1]

    return rhs


def mixed_state(theta, theta_dot):
    """Eq. 7's state [x2, y2, theta, x2', y2', theta'] of the hand (m, m/s) and the elbow angle, shape (6,)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([L12 * c, L12 * s, theta, -L12 * s * theta_dot, L12 * c * theta_dot, theta_dot])
