"""Time-varying LQR of the two-segment arm about its desired motion (the forearm's
``controllers.lqr`` with the full, coupled 4-state linearisation).

For x = [z - z_d, z' - z'_d] and u = tau - tau_ID(t), the arm's minimal-coordinate dynamics
z'' = M(z)^-1 (tau - h(z, z')) linearise along the desired motion to x' = A(t) x + B(t) u with

    A = [[0, I], [d z''/d z, d z''/d z']],   B = [[0], [M(z_d)^-1]],

M and h taken from the model's own inverse dynamics (``Arm2.joint_torques``: h = ID(z, z', 0),
M e_i = ID(z, z', e_i) - h), the derivatives by central differences. The Riccati equation

    -P' = A^T P + P A - P B R^-1 B^T P + Q,   Q = diag(q_angle, q_angle, q_rate, q_rate),
    R = r_torque I,

is integrated backwards from P(T) = the algebraic Riccati solution of the final linearisation, and
tau = tau_ID(t) + K(t) [z_d - z, z'_d - z'] with K = R^-1 B^T P, shape (2, 4).
"""

from __future__ import annotations

import numpy as np

from .arm2 import Arm2
from .arm2_motion import JointMotion

STEP = 1e-6  # rad, rad/s: central-difference step of the linearisation


def accelerations(model: Arm2, z, w, tau):
    """z'' (rad/s^2) and M (kg m^2) of the minimal dynamics for angles z (rad), velocities w
    (rad/s), torques tau (N m), each of shape (..., 2); returns shapes (..., 2) and (..., 2, 2)."""
    zero = np.zeros_like(z)
    h = model.joint_torques(z, w, zero)
    M = np.stack([model.joint_torques(z, w, zero + e) - h for e in np.eye(2)], axis=-1)
    return np.linalg.solve(M, (tau - h)[..., None])[..., 0], M


def linearisation(model: Arm2, z, w, tau):
    """A (4, 4) and B (4, 2) of the arm's minimal dynamics at angles z (rad), velocities w (rad/s)
    and torques tau (N m), each of shape (2,)."""
    e = STEP * np.eye(2)
    zs = np.concatenate([z + e, z - e, np.tile(z, (5, 1))])  # the 9 points of the central differences
    ws = np.concatenate([np.tile(w, (4, 1)), w + e, w - e, w[None]])
    acc, M = accelerations(model, zs, ws, tau)
    A = np.zeros((4, 4))
    A[:2, 2:] = np.eye(2)
    A[2:, :2] = ((acc[0:2] - acc[2:4]) / (2 * STEP)).T
    A[2:, 2:] = ((acc[4:6] - acc[6:8]) / (2 * STEP)).T
    B = np.zeros((4, 2))
    B[2:] = np.linalg.inv(M[8])
    return A, B


def lqr_gains(model: Arm2, motion: JointMotion, q_angle: float = 1e4, q_rate: float = 1.0, r_torque: float = 1.0,
              rtol: float = 1e-8, atol: float = 1e-8):
    """K(t) of the time-varying LQR as a function of times t (s), shape (k,) -> (k, 2, 4)
    (N m/rad for the angle columns, N m s/rad for the rate columns)."""
    from scipy.integrate import solve_ivp
    from scipy.linalg import solve_continuous_are

    Q = np.diag([q_angle, q_angle, q_rate, q_rate])
    r_inv = 1.0 / r_torque

    def system(t):
        z, w, dw = (v.reshape(2) for v in motion(np.array(t)))
        return linearisation(model, z, w, model.joint_torques(z, w, dw))

    def rhs(t, p):
        P = p.reshape(4, 4)
        A, B = system(t)
        dP = -(A.T @ P + P @ A - r_inv * P @ B @ B.T @ P + Q)
        return (0.5 * (dP + dP.T)).ravel()

    T = motion.duration
    A, B = system(T)
    p_final = solve_continuous_are(A, B, Q, r_torque * np.eye(2))
    solution = solve_ivp(rhs, (T, 0.0), p_final.ravel(), method="RK45", dense_output=True, rtol=rtol, atol=atol)
    if not solution.success:
        raise ArithmeticError(f"the Riccati equation could not be integrated: {solution.message}")

    def gains(t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        P = solution.sol(np.clip(t, 0.0, T)).T.reshape(-1, 4, 4)
        z, w, _ = motion(t)
        _, M = accelerations(model, z, w, np.zeros_like(z))
        return r_inv * np.einsum("kji,kjl->kil", np.linalg.inv(M), P[:, 2:, :])  # R^-1 B^T P

    return gains
