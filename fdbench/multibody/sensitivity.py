"""Forward sensitivities of the engine's RK4 map (compiled), for exact gradients on any model.

Every RK4 stage k_s = f(y_s, tau_s) is differentiated with the chain rule,
K_s = f_y(y_s) dy_s/dp + f_tau(y_s) dtau_s/dp, and the step y+ = y + dt/6 (k1 + 2 k2 + 2 k3 + k4)
gives S+ = S + dt/6 (K1 + 2 K2 + 2 K3 + K4), S = dy/dp of shape (n_state, P).
f_y S and f_tau are exact. On pin joints (the banded solve) ``tangents._tangents`` is the forward-mode (tangent) derivative of the
engine's stage code (``kernels._drive``) written by hand, one parameter direction at a time. It
differentiates the assembly of the points' matrix K and right-hand side r, and for the linear solve K x = r uses
dx = K^-1 (dr - dK x) with the L D L^T factor the stage has already computed (no refactoring per
direction); the angle rows follow as in the stage code. The form of each angle constraint is that
in force at the stage (the derivative of the branch taken).

The states are those of the open-loop ``kernels.rk4`` to the last bit: the RK4 driver itself
(``kernels.rk4_sensitivity``: ``kernels._drive`` in PD mode with zero gains) runs the tangents after each stage, with the factor,
solution and multipliers the stage has just computed, so the value and the gradient belong to one
simulation. The kernels take the engine's layout arrays only, so numba compiles and caches them
once for every model.

Models with free or path joints or external loads (the dense solve, ``tangents._stage_tangents``;
the same ``rk4_sensitivity``, its paths, free or loads not None). There eq. 12 is A(q) x = b(y, tau) over points and angles together, and
each stage's f_y is formed as a matrix, [0 I; A^-1 D] with D = d(b - A x)/dy at the stage's x:
every constraint row contributes through its Hessian and third derivative on its few entries
(dJ = H dq, d(J' q') = T(q', q', dq) + 2 (H q') . dq'), the loads through the frames their force
and point turn and move with; D is solved with the stage's own Cholesky factor and applied to all
P directions at once (a matrix product), about 4 n_state^2 P flops per stage. The two derivations
agree on pin joints to 1e-9 (``tests/test_sensitivity_dense.py``).

Muscles (``rk4_sensitivity``'s ``muscles``): the state and S carry the activations and compliant
tendons' forces. Each stage forms the change of the muscles' generalised forces in every direction,
-H dq F + arm dF (H the path's Hessian, exact for both forms, ``muscle_paths.hessians``: a path of
points' from the bodies' origins' second derivatives; dF from the curves' partials at the stage),
adds it to the generalised forces' change of either derivation above, and the muscle states' own
rows (activation dynamics, the tendon's rate) from their partials; an excitation parameter enters its
muscle's activation row. ``tests/engine/test_muscle_sensitivity.py`` checks it against central
differences.
"""

from __future__ import annotations

import numpy as np

from .kernels import rk4_sensitivity

__all__ = ["rk4_sensitivity", "warm_up"]


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
                        *engine.kernel_args(), None, np.empty((n + 1, engine.n_state)),
                        np.empty((n + 1, engine.n_state)), np.empty((n + 1, 1)), np.empty((n + 1, 1, 1)))
