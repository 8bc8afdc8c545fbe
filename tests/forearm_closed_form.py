"""The paper's forearm written out by hand, independent of fdbench: Table 1's constants, the elbow
torque of its minimal equation

    I1 theta'' + cos(theta) (F_ext L12 + m g L1G) = tau

and that equation's right-hand side for scipy. SI units, angles in radians."""

from __future__ import annotations

import numpy as np

L12 = 0.33  # m, elbow to hand (where F_ext acts)
L1G = 0.11  # m, elbow to the centre of mass
M = 1.0  # kg
I1 = 0.04  # kg m^2, about the elbow
F_EXT = 15.0  # N, downwards at the hand
G = 9.81  # m/s^2

GRAVITY_TORQUE = F_EXT * L12 + M * G * L1G  # N m: the load's and gravity's torque at theta = 0


def elbow_torque(theta, theta_dot, theta_ddot, I1=I1, gravity_torque=GRAVITY_TORQUE):
    """The elbow torque (N m) that moves the forearm along theta(t) (rad, rad/s, rad/s^2; any shape);
    theta_dot is unused (no velocity terms in one degree of freedom)."""
    return I1 * np.asarray(theta_ddot) + np.cos(theta) * gravity_torque


def minimal_rhs(torque, I1=I1, gravity_torque=GRAVITY_TORQUE):
    """The right-hand side (t, [theta, theta']) -> [theta', theta''] of the minimal equation under
    the elbow torque torque(t, theta, theta_dot) (N m), for scipy's solve_ivp."""

    def rhs(t, y):
        return [y[1], (torque(t, y[0], y[1]) - gravity_torque * np.cos(y[0])) / I1]

    return rhs


def mixed_state(theta, theta_dot):
    """Eq. 7's state [x2, y2, theta, x2', y2', theta'] of the hand (m, m/s) and the elbow angle, shape (6,)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([L12 * c, L12 * s, theta, -L12 * s * theta_dot, L12 * c * theta_dot, theta_dot])
