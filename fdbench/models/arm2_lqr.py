"""Time-varying LQR of the two-segment arm about its desired motion (the forearm's
``controllers.lqr`` with the full, coupled 4-state linearisation).

For x = [z - z_d, z' - z'_d] and u = tau - tau_ID(t), the arm's minimal-coordinate dynamics
z'' = M(z)^-1 (tau - h(z, z')) linearise along the desired motion to x' = A(t) x + B(t) u with

    A = [[0, I], [d z''/d z, d z''/d z']],   B = [[0], [M(z_d)^-1]],

M and h taken from the model's own inverse dynamics (the compiled ``arm2_kernels.inverse_torques``,
the numbers of ``Arm2.joint_torques``: h = ID(z, z', 0), M e_i = ID(z, z', e_i) - h), the
derivatives by central differences. The Riccati equation

    -P' = A^T P + P A - P B R^-1 B^T P + Q,   Q = diag(q_angle, q_angle, q_rate, q_rate),
    R = r_torque I,

is integrated backwards from P(T) = the algebraic Riccati solution of the final linearisation, and
tau = tau_ID(t) + K(t) [z_d - z, z'_d - z'] with K = R^-1 B^T P, shape (2, 4). The right-hand
side, linearisation included, is one compiled call (``riccati_rate``): scipy's adaptive RK45 calls
it about a thousand times on the reach.
"""

from __future__ import annotations

import numpy as np

from ..jit import njit
from ..model import Penalty
from .arm2 import Arm2
from .arm2_kernels import inverse_torques, kernel_constants
from .arm2_motion import JointMotion

STEP = 1e-6  # rad, rad/s: central-difference step of the linearisation


def accelerations(model: Arm2, z, w, tau):
    """z'' (rad/s^2) and M (kg m^2) of the minimal dynamics for angles z (rad), velocities w
    (rad/s), torques tau (N m), each of shape (..., 2); returns shapes (..., 2) and (..., 2, 2)."""
    zero = np.zeros_like(z)
    h = model.joint_torques(z, w, zero)
    M = np.stack([model.joint_torques(z, w, zero + e) - h for e in np.eye(2)], axis=-1)
    return np.linalg.solve(M, (tau - h)[..., None])[..., 0], M


@njit(error_model="numpy")
def _acceleration(y, tau0, tau1, consts, out):
    """z'' (rad/s^2) of the minimal dynamics into out (2,) at the joint angles y[4:6] (rad) and
    velocities y[10:12] (rad/s) of the state y (12,) under the joint torques tau (N m):
    M^-1 (tau - h) with h = ID(z, z', 0) and M e_i = ID(z, z', e_i) - h (``inverse_torques``).
    Returns M^-1's entries (kg^-1 m^-2) (i00, i01, i10, i11)."""
    inverse_torques(y, 0.0, 0.0, consts, out)
    h0, h1 = out[0], out[1]
    inverse_torques(y, 1.0, 0.0, consts, out)
    m00, m10 = out[0] - h0, out[1] - h1
    inverse_torques(y, 0.0, 1.0, consts, out)
    m01, m11 = out[0] - h0, out[1] - h1
    det = m00 * m11 - m01 * m10
    i00, i01, i10, i11 = m11 / det, -m01 / det, -m10 / det, m00 / det
    r0, r1 = tau0 - h0, tau1 - h1
    out[0], out[1] = i00 * r0 + i01 * r1, i10 * r0 + i11 * r1
    return i00, i01, i10, i11


@njit(error_model="numpy")
def linearisation(z, w, dw, consts, A, B):
    """A (4, 4) and B (4, 2) of the arm's minimal dynamics about the desired angles z (rad),
    velocities w (rad/s) and accelerations dw (rad/s^2), each of shape (2,), into A and B; consts:
    the model's (``arm2_kernels.kernel_constants``). The torques are the inverse dynamics'
    (``inverse_torques``); A's lower rows are central differences of step STEP of z'' at
    z +- STEP e_j and at w +- STEP e_j."""
    y, tau, out = np.zeros(12), np.empty(2), np.empty(2)
    y[4], y[5], y[10], y[11] = z[0], z[1], w[0], w[1]
    inverse_torques(y, dw[0], dw[1], consts, tau)
    A[:, :] = 0.0
    A[0, 2], A[1, 3] = 1.0, 1.0
    B[:, :] = 0.0
    B[2, 0], B[2, 1], B[3, 0], B[3, 1] = _acceleration(y, tau[0], tau[1], consts, out)
    for column, index in ((0, 4), (1, 5), (2, 10), (3, 11)):  # the angles, then the velocities
        centre = y[index]
        y[index] = centre + STEP
        _acceleration(y, tau[0], tau[1], consts, out)
        plus0, plus1 = out[0], out[1]
        y[index] = centre - STEP
        _acceleration(y, tau[0], tau[1], consts, out)
        y[index] = centre
        A[2, column] = (plus0 - out[0]) / (2 * STEP)
        A[3, column] = (plus1 - out[1]) / (2 * STEP)


@njit(error_model="numpy")
def riccati_rate(z, w, dw, p, consts, q, r_inv, out):
    """The right-hand side P' of the Riccati equation, P' = -(A^T P + P A - P B R^-1 B^T P + Q)
    (symmetrised), about the desired angles z (rad), velocities w (rad/s) and accelerations dw
    (rad/s^2), each (2,), for P flattened, p (16,); q: the diagonal of Q, shape (4,); r_inv: R^-1,
    (N m)^2. Into out (16,)."""
    A, B = np.empty((4, 4)), np.empty((4, 2))
    linearisation(z, w, dw, consts, A, B)
    P = np.ascontiguousarray(p).reshape(4, 4)
    PB = P @ B
    dP = A.T @ P + P @ A - r_inv * (PB @ PB.T)
    for i in range(4):
        dP[i, i] += q[i]
    for i in range(4):
        for k in range(4):
            out[4 * i + k] = -0.5 * (dP[i, k] + dP[k, i])


def lqr_gains(model: Arm2, motion: JointMotion, q_angle: float = 1e4, q_rate: float = 1.0, r_torque: float = 1.0,
              rtol: float = 1e-8, atol: float = 1e-8):
    """K(t) of the time-varying LQR as a function of times t (s), shape (k,) -> (k, 2, 4)
    (N m/rad for the angle columns, N m s/rad for the rate columns)."""
    from scipy.integrate import solve_ivp
    from scipy.linalg import solve_continuous_are

    q = np.array([q_angle, q_angle, q_rate, q_rate])
    r_inv = 1.0 / r_torque
    consts = kernel_constants(model, Penalty())  # the body's constants; the penalty is not used

    def desired(t):
        return tuple(np.ascontiguousarray(v, dtype=float).reshape(2) for v in motion(np.array(t)))

    def rhs(t, p):
        out = np.empty(16)
        riccati_rate(*desired(t), p, consts, q, r_inv, out)
        return out

    T = motion.duration
    z, w, dw = desired(T)
    A, B = np.empty((4, 4)), np.empty((4, 2))
    linearisation(z, w, dw, consts, A, B)
    p_final = solve_continuous_are(A, B, np.diag(q), r_torque * np.eye(2))
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


def warm_up() -> None:
    """Load (or compile) the Riccati kernels and import scipy's solvers, so that a design's
    timing excludes them."""
    import scipy.integrate  # noqa: F401
    import scipy.linalg  # noqa: F401

    zero = np.zeros(2)
    riccati_rate(zero, zero, zero, np.zeros(16), kernel_constants(Arm2(), Penalty()), np.ones(4), 1.0, np.empty(16))
