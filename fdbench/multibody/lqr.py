"""Time-varying LQR of any model about its desired motion, from the model's minimal equations
(``fdbench.multibody.symbolic``).

For x = [z - z_d, z' - z'_d] and u = tau - tau_ID(t), the dynamics z'' = M(z)^-1 (tau - h(z, z'))
linearise along the desired motion to x' = A(t) x + B(t) u, A and B exact (CasADi's derivatives,
``MinimalDynamics.linearisation`` at z_d, z'_d and the inverse dynamics' torques). The Riccati equation

    -P' = A^T P + P A - P B R^-1 B^T P + Q,   Q = diag(q_angle, q_rate),   R = diag(r_torque),

(each weight one number for every joint or one per joint, in the model's joint order)

is integrated backwards by scipy's RK45 from P(T) = the algebraic Riccati solution of the final
linearisation (an infinite-horizon tail), and tau = tau_ID(t) + K(t) [z_d - z, z'_d - z'] with
K = R^-1 B^T P = R^-1 M(z_d)^-1 P[J:, :], shape (J, 2J). A and B are taken at the motion's own
accelerations (``linearisation`` at the inverse dynamics' torques gives them back to rounding).
The right-hand side, linearisation included, is one CasADi call on arrays it reads and writes in
place (``Function.buffer``): scipy calls it about a thousand times on a 1 s motion.
"""

from __future__ import annotations

import numpy as np

from .model import Model
from .symbolic import MinimalDynamics, riccati_input_size


def lqr_gains(model: Model, motion, q_angle=1e4, q_rate=1.0, r_torque=1.0, rtol: float = 1e-8, atol: float = 1e-8):
    """K(t) of the time-varying LQR of ``model`` about ``motion`` (``duration`` in s, ``motion(t)``
    -> (z, z', z''), each t.shape + (J,)) as a function of times t (s), shape (k,) -> (k, J, 2J)
    (N m/rad for the angle columns, N m s/rad for the rate columns); q_angle (rad^-2), q_rate
    (s^2 rad^-2), r_torque ((N m)^-2): a number, or one per joint (J,). ArithmeticError if the
    Riccati equation cannot be integrated."""
    from scipy.integrate import solve_ivp
    from scipy.linalg import solve_continuous_are

    dynamics, J = MinimalDynamics(model), model.n_joints
    q = np.concatenate([_per_joint(q_angle, J, "q_angle"), _per_joint(q_rate, J, "q_rate")])
    r = _per_joint(r_torque, J, "r_torque")
    packed = np.zeros(riccati_input_size(J))  # [z, z', z'', P, q, r_inv], read by the Function in place
    packed[3 * J + 4 * J * J:] = np.concatenate([q, 1.0 / r])
    rate = np.zeros(4 * J * J)  # written by the Function in place
    evaluate = _in_place(dynamics.functions["riccati_rate"], packed, rate)

    def desired(t):
        return tuple(np.asarray(v, dtype=float).reshape(J) for v in motion(np.array(t)))

    def rhs(t, p):
        for i, values in enumerate(desired(t)):
            packed[i * J:(i + 1) * J] = values
        packed[3 * J:3 * J + 4 * J * J] = p
        evaluate()
        return rate.copy()

    T = float(motion.duration)
    z, w, dw = desired(T)
    A, B = dynamics.linearisation(z, w, dynamics.inverse(z, w, dw))
    p_final = solve_continuous_are(A, B, np.diag(q), np.diag(r))
    solution = solve_ivp(rhs, (T, 0.0), p_final.ravel(), method="RK45", dense_output=True, rtol=rtol, atol=atol)
    if not solution.success:
        raise ArithmeticError(f"the Riccati equation could not be integrated: {solution.message}")

    def gains(t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        P = solution.sol(np.clip(t, 0.0, T)).T.reshape(-1, 2 * J, 2 * J)
        z = np.asarray(motion(t)[0], dtype=float).reshape(-1, J)
        return np.linalg.solve(dynamics.mass_matrix(z), P[:, J:, :]) / r[:, None]  # R^-1 B^T P, M symmetric

    return gains


def _per_joint(weight, J: int, name: str) -> np.ndarray:
    """A weight given as one number or one per joint, as an array (J,); ValueError naming it otherwise."""
    values = np.asarray(weight, dtype=float)
    if values.shape not in ((), (J,)):
        raise ValueError(f"{name} must be one number or {J} (one per joint), got shape {values.shape}")
    return np.broadcast_to(values, (J,)).copy()


def _in_place(function, argument: np.ndarray, result: np.ndarray):
    """A call of the one-input, one-output CasADi ``function`` reading ``argument`` and writing
    ``result`` in place (numpy float arrays of its sizes): a few microseconds, where a call with
    numpy arguments costs tens (the arrays' conversion)."""
    buffer, evaluate = function.buffer()
    buffer.set_arg(0, memoryview(argument))
    buffer.set_res(0, memoryview(result))

    def call():
        evaluate()

    call.keep = (buffer, argument, result)  # the buffer points into the arrays: keep them alive
    return call


def warm_up(model: Model | None = None) -> None:
    """Import scipy's solvers and CasADi and build ``model``'s Functions (when given), so that a
    design's timing excludes them."""
    from ..casadi_loader import casadi

    casadi()
    import scipy.integrate  # noqa: F401
    import scipy.linalg  # noqa: F401

    if model is not None:
        MinimalDynamics(model).build("riccati_rate", "linearisation", "inverse")
