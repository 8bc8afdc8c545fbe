"""Direct collocation of the two-segment arm: its equation of motion in minimal coordinates
z = [shoulder, elbow] (rad) as CasADi expressions, and the forearm's two transcriptions
(``fdbench.collocation.transcribe``) with 4 states (z, z') and 2 torques.

Lagrange's equations of the arm (``fdbench.models.arm2``: the upper arm a bar about the shoulder,
inertia I0; the forearm Table 1's, inertia I1 about the elbow, mass m, centre of mass L1G from the
elbow; F_ext downwards at the hand; y up) give

    M(z) z'' + h(z, z') = tau,   tau = [tau_shoulder, tau_elbow] (N m)

    M11 = I0 + I1 + m L01^2 + 2 b cos(e),  M12 = M21 = I1 + b cos(e),  M22 = I1,  b = m L01 L1G
    h1 = -b sin(e) (2 s' e' + e'^2) + (m0 g L0G + (m g + F_ext) L01) cos(s) + G cos(s + e)
    h2 =  b sin(e) s'^2 + G cos(s + e),   G = m g L1G + F_ext L12 (Table 1's gravity moment)

with s = shoulder, e = elbow (the kinetic energy 1/2 I0 s'^2 + 1/2 m |v_G|^2 + 1/2 (I1 - m L1G^2)
(s' + e')^2, the potential energy of both segments' weights and of F_ext at the hand's height).
With s = 0 held still, the elbow's row is the forearm's I1 e'' + G cos(e) = tau.

The objective is the integral of the squared joint-angle errors in deg^2, summed over both joints,
plus ``regularization`` times the integral of |tau|^2 (N^2 m^2 s); the initial state is the
desired motion's at t = 0. ``casadi`` is imported only when a function here is called.
"""

from __future__ import annotations

import time

import numpy as np

from ..collocation import (DEFAULT_MAX_ITER, DEFAULT_MAX_TIME, DEFAULT_NODES, DEFAULT_REGULARIZATION,
                           CollocationResult, check_options, transcribe)
from .arm2 import Arm2
from .arm2_motion import JointMotion, as_joint_motion


def mass_matrix(arm: Arm2, z):
    """The entries (M11, M12, M22) (kg m^2) of the symmetric mass matrix M(z) in minimal
    coordinates; z: CasADi SX of shape (k, 2) [shoulder, elbow] (rad); M11 and M12 of shape (k, 1),
    M22 = I1 a constant."""
    import casadi as ca

    b = arm.m * arm.L01 * arm.L1G
    coupling = b * ca.cos(z[:, 1])
    return arm.I0 + arm.I1 + arm.m * arm.L01**2 + 2 * coupling, arm.I1 + coupling, arm.I1


def bias(arm: Arm2, z, w):
    """h(z, z') (N m) = the Coriolis and centrifugal terms plus the moments of gravity and F_ext,
    shape (k, 2), from z (rad) and w = z' (rad/s), CasADi SX of shape (k, 2)."""
    import casadi as ca

    s, e, ws, we = z[:, 0], z[:, 1], w[:, 0], w[:, 1]
    b_sin = arm.m * arm.L01 * arm.L1G * ca.sin(e)
    G = arm.m * arm.g * arm.L1G + arm.F_ext * arm.L12  # the forearm's gravity moment, N m
    upper = arm.m0 * arm.g * arm.L0G + (arm.m * arm.g + arm.F_ext) * arm.L01  # N m
    forearm = G * ca.cos(s + e)
    return ca.horzcat(-b_sin * (2 * ws * we + we**2) + upper * ca.cos(s) + forearm, b_sin * ws**2 + forearm)


def joint_torques(arm: Arm2, z, w, a):
    """Inverse dynamics M(z) z'' + h(z, z') (N m), shape (k, 2), from CasADi SX z (rad),
    w (rad/s) and a = z'' (rad/s^2), each of shape (k, 2)."""
    import casadi as ca

    m11, m12, m22 = mass_matrix(arm, z)
    return ca.horzcat(m11 * a[:, 0] + m12 * a[:, 1], m12 * a[:, 0] + m22 * a[:, 1]) + bias(arm, z, w)


def accelerations(arm: Arm2, z, w, tau):
    """Forward dynamics z'' = M(z)^-1 (tau - h(z, z')) (rad/s^2), shape (k, 2), from CasADi SX z
    (rad), w (rad/s) and tau (N m), each of shape (k, 2); M's 2x2 inverse written out (det M > 0)."""
    import casadi as ca

    m11, m12, m22 = mass_matrix(arm, z)
    rest = tau - bias(arm, z, w)
    det = m11 * m22 - m12**2
    return ca.horzcat((m22 * rest[:, 0] - m12 * rest[:, 1]) / det, (m11 * rest[:, 1] - m12 * rest[:, 0]) / det)


def collocate(arm: Arm2 = Arm2(), motion: str | JointMotion = "reach", nodes: int = DEFAULT_NODES,
              scheme: str = "hermite-simpson", regularization: float = DEFAULT_REGULARIZATION,
              max_iter: int = DEFAULT_MAX_ITER, max_time: float = DEFAULT_MAX_TIME) -> CollocationResult:
    """Transcribe and solve the arm's tracking problem of ``motion`` with the model ``arm`` on
    ``nodes`` intervals over the motion's span: node arrays of shape (N + 1, 2) [shoulder, elbow]
    (``torque_function`` maps times (s), shape (k,), to torques (N m), shape (k, 2)). The initial
    guess is the desired motion and the arm's inverse-dynamics torques. ValueError (one line) for
    options out of range; never raises on a solver failure: IPOPT's status says what happened."""
    check_options(nodes, scheme, regularization, max_iter, max_time)
    began = time.perf_counter()
    motion = as_joint_motion(motion)
    n = int(nodes)
    t = np.linspace(0.0, motion.duration, n + 1)
    z_d, w_d, a_d = motion(t)
    z_md = um_guess = None
    if scheme == "hermite-simpson":
        z_md, w_md, a_md = motion(t[:-1] + motion.duration / n / 2)
        um_guess = arm.joint_torques(z_md, w_md, a_md)
    return transcribe(lambda z, w, tau: accelerations(arm, z, w, tau), t, z_d, w_d, z_md,
                      arm.joint_torques(z_d, w_d, a_d), um_guess, scheme, regularization, max_iter, max_time, began)
