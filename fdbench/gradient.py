"""Exact gradients of the tracking objective (eq. 18) by forward sensitivity of the RK4 map.

f*(p) = RMSE_rot_deg(p) + w (1 - t_end / T). Over the m samples reached, with e_k the rotation
error in degrees, d RMSE / d p = sum_k e_k (180 / pi) d theta_k / d p / (m RMSE), where
d theta_k / d p comes from ``sensitivity.rk4_sensitivity`` (exact for the discrete simulation
that is run). The penalty term is piecewise constant in p: t_end only changes where a failure
moves by a whole step, so its gradient is zero almost everywhere. When a simulation fails the
gradient is therefore the gradient of the RMSE over the samples reached; at RMSE = 0 (or where
nothing beyond t = 0 was reached) it is zero.
"""

from __future__ import annotations

import math

import numpy as np

EXACT_GRADIENT_TORQUES_HINT = "the torque parameterisation gives d tau / d p (ann, cs, pf)"


def check_problem(problem) -> None:
    """ValueError with a one-line message when exact gradients are not available for problem."""
    if problem.settings.integrator != "rk4":
        raise ValueError(f"--gradient exact needs --integrator rk4, got {problem.settings.integrator}")
    if not problem._fast:
        raise ValueError("--gradient exact needs motion samples on the RK4 grid (uniform, every k steps)")
    if problem.torque_jacobian() is None:
        raise ValueError(f"--gradient exact: torque {problem.torque.name!r} gives no d tau / d p")


def value_and_gradient(problem, p: np.ndarray) -> tuple[float, np.ndarray]:
    """(f*(p), d f* / d p, shape (n_params,)) for a ``problem.TrackingProblem`` on RK4.
    The value equals ``problem.objective(p)`` to the last bit (the same states are computed)."""
    from .integrate import constants, half_step_reference, initial_state
    from .population import tracking_objective
    from .sensitivity import rk4_sensitivity

    check_problem(problem)
    settings, n = problem.settings, problem._n
    _, ref_th, ref_w = half_step_reference(n, settings.kinematics)
    tau = problem.torques_on_grid(p[None])[0]  # the very torque of ``objective``
    with np.errstate(all="ignore"):
        jac = np.ascontiguousarray(problem.torque_jacobian()(p), dtype=float)
    states, _, _ = problem._buffers
    dtheta = problem._dtheta
    if dtheta is None or dtheta.shape[1] != len(p):
        dtheta = problem._dtheta = np.empty((n + 1, len(p)))
    _, done = rk4_sensitivity(initial_state(settings.kinematics, settings.model), problem.duration / n, n,
                              tau, jac, ref_th, ref_w, constants(settings), states, dtheta)
    every = problem._every
    # the value by the very kernel of ``objective``, on the same states
    value = tracking_objective(states, done, every, problem._theta_ref, n, problem.penalty_weight)
    theta = states[: done + 1 : every, 2]
    error = np.degrees(theta - problem.inverse.theta[: len(theta)])
    rmse = float(np.sqrt(np.mean(error**2)))
    gradient = np.zeros(len(p))
    if math.isfinite(rmse) and rmse > 0:
        with np.errstate(all="ignore"):
            gradient = np.degrees(error @ dtheta[: done + 1 : every]) / (len(theta) * rmse)
        if not np.all(np.isfinite(gradient)):
            gradient = np.zeros(len(p))
    return float(value), gradient


def warm_up() -> None:
    """Load (or compile) the sensitivity and objective kernels, so that later timings exclude them."""
    from .integrate import Settings, constants, initial_state
    from .population import tracking_objective
    from .sensitivity import rk4_sensitivity

    settings = Settings(dt=0.1)
    n = 10
    ref = np.zeros(2 * n + 1)
    rk4_sensitivity(initial_state(settings.kinematics, settings.model), 0.1, n, ref, np.zeros((2 * n + 1, 1)), ref,
                    ref, constants(settings), np.empty((n + 1, 6)), np.empty((n + 1, 1)))
    tracking_objective(np.zeros((n + 1, 6)), n, 1, np.zeros(n + 1), n, 1.0)
