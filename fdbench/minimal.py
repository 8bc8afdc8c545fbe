"""The forearm's minimal-coordinate equation of motion, the limit of the penalty formulation
(eq. 12) as alpha grows: with point 2 on the circle of radius L12, the load F_ext at point 2 and
gravity m g at the centre of mass give the elbow the moment -G cos(theta), so

    I1 theta'' = tau - G cos(theta),    G = F_ext L12 + m g L1G  (N m).

Model-based controllers and direct collocation use it as their nominal model."""

from __future__ import annotations

import numpy as np

from .model import Forearm


def gravity_moment(model: Forearm) -> float:
    """G = F_ext L12 + m g L1G (N m): the moment of the load and of gravity about the elbow at
    theta = 0."""
    return model.F_ext * model.L12 + model.m * model.g * model.L1G


def angular_acceleration(theta, tau, model: Forearm):
    """theta'' (rad/s^2) = (tau - G cos(theta)) / I1 for theta (rad) and tau (N m), broadcast."""
    return (np.asarray(tau) - gravity_moment(model) * np.cos(theta)) / model.I1


def linearisation(theta, model: Forearm):
    """A = [[0, 1], [a21, 0]] and B = [0, 1/I1] of the linearisation about theta (rad) for the
    state [theta, theta']: a21 = G sin(theta) / I1 (1/s^2), shaped like theta; B shape (2,)."""
    a21 = gravity_moment(model) * np.sin(theta) / model.I1
    return a21, np.array([0.0, 1.0 / model.I1])
