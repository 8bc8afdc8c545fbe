"""Forward sensitivities of the engine's RK4 map (compiled), for exact gradients on any model.

Every RK4 stage k_s = f(y_s, tau_s) is differentiated with the chain rule,
K_s = f_y(y_s) dy_s/dp + f_tau(y_s) dtau_s/dp, and the step y+ = y + dt/6 (k1 + 2 k2 + 2 k3 + k4)
gives S+ = S + dt/6 (K1 + 2 K2 + 2 K3 + K4), S = dy/dp of shape (n_state, P).
f_y S and f_tau are exact: ``kernels._tangents`` is the forward-mode (tangent) derivative of the
engine's stage code (``kernels._drive``) written by hand, one parameter direction at a time. It
differentiates the assembly of the points' matrix K and right-hand side r, and for the linear solve K x = r uses
dx = K^-1 (dr - dK x) with the L D L^T factor the stage has already computed (no refactoring per
direction); the angle rows follow as in the stage code. The form of each angle constraint is that
in force at the stage (the derivative of the branch taken).

The states are those of the open-loop ``kernels.rk4`` to the last bit: the RK4 driver itself
(``kernels._drive`` in PD mode with zero gains) runs the tangents after each stage, with the factor,
solution and multipliers the stage has just computed, so the value and the gradient belong to one
simulation. The kernels take the engine's layout arrays only, so numba compiles and caches them
once for every model.

Models with free or path joints or external loads (the dense kernels, ``kernels_general``):
``rk4_sensitivity_dense``. There eq. 12 is A(q) x = b(y, tau) over points and angles together, and
each stage's f_y is formed as a matrix, [0 I; A^-1 D] with D = d(b - A x)/dy at the stage's x:
every constraint row contributes through its Hessian and third derivative on its few entries
(dJ = H dq, d(J' q') = T(q', q', dq) + 2 (H q') . dq'), the loads through the frames their force
and point turn and move with; D is solved with the stage's own Cholesky factor and applied to all
P directions at once (a matrix product), about 4 n_state^2 P flops per stage. The two derivations
agree on pin joints to 1e-9 (``tests/test_sensitivity_dense.py``).
"""

from __future__ import annotations

import numpy as np

from ..jit import njit
from . import kernels_general
from .kernels import N_AUX, PD, _drive


@njit(error_model="numpy")
def rk4_sensitivity(y0, dt, n_steps, tau, ref, refd, G, param_joint, every, offset, pt_index, pt_fixed, body_pts,
                    body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent,
                    n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states, rates,
                    applied, dz):
    """Open-loop RK4 (``kernels.rk4`` in PD mode with zero gains, as ``kernels.rk4_candidates``
    runs it) and the sensitivities of the joint angles.

    tau, ref, refd: as for ``rk4_candidates``' candidate, shape (2 n_steps + 1, J); G: d tau / d p
    on the half-step grid, shape (2 n_steps + 1, P), each parameter q moving the torque of joint
    param_joint[q] only (N m per parameter unit). The initial state does not depend on p. Fills
    states, rates (n_steps + 1, n_state) and applied (n_steps + 1, J) as ``rk4`` does, and
    dz (n_steps // every + 1, J, P), the derivative of the joint angles (rad per parameter unit) at
    every ``every``-th step reached. Returns (status, steps_done)."""
    n_b, n_p, P = joint_parent.shape[0], base.shape[0], G.shape[1]
    torque_sign = np.zeros((n_b, P))  # joint torque -> generalised forces of the body angles
    for q in range(P):
        torque_sign[param_joint[q], q] = 1.0
        if joint_parent[param_joint[q]] >= 0:
            torque_sign[joint_parent[param_joint[q]], q] = -1.0
    zero = np.zeros(n_b)
    code, done, _ = _drive(y0, dt, n_steps, 0, tau, ref, refd, ref, zero, zero, PD, np.zeros((1, n_b, 2 * n_b)),
                           offset, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef,
                           lin_const, first, base, q_ext, params, n_parent, n_offset, n_at_parent, n_at_child,
                           n_owner, n_local, n_index, n_mass, n_q_ext, states, rates, applied, np.zeros((n_p, n_p)),
                           np.zeros(n_p), np.zeros((n_b, N_AUX)), G, torque_sign, every, dz)
    return code, done


@njit(error_model="numpy")
def rk4_sensitivity_dense(y0, dt, n_steps, tau, ref, refd, G, param_col, every, loads, body_int, body_float, path_body,
                          path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params, load_int,
                          first, n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local,
                          n_index, n_mass, n_q_ext, states, rates, applied, dz):
    """``rk4_sensitivity`` for the dense layout (``kernels_general``: free and path joints, external
    loads): open-loop RK4 (``kernels_general.rk4`` in PD mode with zero gains, as its
    ``rk4_candidates`` runs it) under the loads' values loads (2 n_steps + 1, L, N_LOAD), and the
    sensitivities dz (n_steps // every + 1, J, P) of the coordinates (rad; m for a free joint's x
    and y, per parameter unit), parameter q moving coordinate param_col[q]'s generalised force by
    G[:, q] (N m or N per unit). ref, refd without the joint offsets. Returns (status, steps_done)."""
    J = tau.shape[1]
    zero = np.zeros(J)
    m = kernels_general.n_rows(body_int, path_body, lin_const)
    code, done, _ = kernels_general._drive(
        y0, dt, n_steps, 0, tau, ref, refd, ref, zero, zero, PD, np.zeros((1, J, 2 * J)), loads, loads, body_int,
        body_float, path_body, path_float, knots, spline_start, lin_idx, lin_coef, lin_const, mass, q_ext, params,
        load_int, first, n_body_int, n_body_float, n_knots, n_spline_start, n_load_int, n_owner, n_local, n_index,
        n_mass, n_q_ext, states, rates, applied, np.empty(m), np.empty(m), G, param_col, every, dz)
    return code, done


def warm_up() -> None:
    """Load (or compile) the sensitivity kernel on a small library model, so that later timings
    exclude it."""
    from ..compile_guard import compiling
    from ..models import find_model
    from .engine import Engine

    engine = Engine(find_model("forearm"))
    n, rows = 2, np.zeros((5, 1))
    y0 = engine.state_from_joints(np.zeros(1), np.zeros(1))
    with compiling():  # Ctrl-C while the kernel compiles ends the command at once
        rk4_sensitivity(y0, 0.05, n, rows, rows, rows, np.zeros((5, 1)), np.zeros(1, dtype=np.int64), 1,
                        *engine.simulation_layout(), np.empty((n + 1, engine.n_state)),
                        np.empty((n + 1, engine.n_state)), np.empty((n + 1, 1)), np.empty((n + 1, 1, 1)))
