"""Cubic spline through torque values at equally spaced knots (paper section 4.1, Figure 4)."""

from __future__ import annotations

import numpy as np

from ..method_options import MethodOption
from .base import TORQUES, TorqueParameterisation, check_count


DEFAULT_KNOTS = 11
KNOT_SPACING_S = 0.1  # the paper's spline: 11 knots over eq. 5's 1 s


def knots_for(duration: float) -> int:
    """The default knot count for a motion of ``duration`` s: one every KNOT_SPACING_S s, the end
    included (11 for the paper's 1 s, 26 for 2.5 s), within [4, 1000]."""
    return min(1000, max(4, int(round(duration / KNOT_SPACING_S)) + 1))


@TORQUES.register("cs")
class CubicSplineTorque(TorqueParameterisation):
    """Parameters: the torque (N m) at ``knots`` equally spaced instants of the motion's span
    [0, T] s (set by ``prepare``; [0, 1] s in the paper); a
    not-a-knot cubic spline (as MATLAB's ``spline``) in between."""

    name = "cs"
    # CMA-ES: steps of 5% of half the torque range; a population of 8 gives 25 generations in 200
    # evaluations (median of 5 seeds, Table 2: 0.37 deg against 0.64 with cma's 0.1 and 11)
    optimizer_defaults = {"cmaes": {"sigma0": 0.05, "popsize": 8}}
    summary = "cubic spline through the torque at --knots equally spaced instants (default: one every 0.1 s)"

    command_line = {"knots": MethodOption("knots in [4, 1000], equally spaced over the motion's span; default one every "
                                          "0.1 s, as the paper's 11 over eq. 5's 1 s (26 for a 2.5 s recording).", int,
                                          show_default=False)}

    def __init__(self, knots: int = DEFAULT_KNOTS):
        self.knots = check_count("--knots", knots, 4, 1000)
        self.n_params = self.knots
        self.t_knots = np.linspace(0.0, 1.0, self.knots)
        self._scale = 1.0

    @classmethod
    def warm_up(cls):
        import scipy.interpolate  # noqa: F401  (its import is not part of a run's runtime)

        from .kernels import warm_up  # lazy: numba off the CLI's start-up

        warm_up()

    def prepare(self, t, target, feedforward):
        self.t_knots = np.linspace(0.0, float(t[-1]) if t[-1] > 0 else 1.0, self.knots)
        self._scale = max(float(np.ptp(target)) / 2, 1e-9)
        if feedforward:
            return np.zeros(self.n_params)
        return np.interp(self.t_knots, t, target)

    def basis(self, t) -> np.ndarray:
        """The spline is linear in its knot values: torque(t) = basis(t) @ p, shape (n, knots)."""
        from scipy.interpolate import CubicSpline

        return CubicSpline(self.t_knots, np.eye(self.knots))(np.asarray(t, dtype=float))

    def evaluate(self, p, t):
        from scipy.interpolate import CubicSpline

        return CubicSpline(self.t_knots, np.asarray(p, dtype=float))(np.asarray(t, dtype=float))

    def on_grid_batch(self, t):
        # the spline is linear in the knot values: each torque history is the knot values'
        # weighted sum of the basis functions, summed knot by knot in a compiled kernel
        from .kernels import weighted_sums  # lazy: numba off the CLI's start-up

        rows = np.ascontiguousarray(self.basis(t).T)  # (knots, n)

        def evaluate(P):
            P = np.ascontiguousarray(P, dtype=float)
            if P.ndim != 2 or P.shape[1] != rows.shape[0]:
                raise ValueError(f"expected parameters of shape (lam, {rows.shape[0]}), got {P.shape}")
            out = np.empty((P.shape[0], rows.shape[1]))
            weighted_sums(P, rows, out)
            return out

        return evaluate

    def on_grid_jacobian(self, t):
        basis = np.ascontiguousarray(self.basis(t))  # the spline is linear in p: a constant Jacobian
        return lambda p: basis

    def scale(self):
        return np.full(self.n_params, self._scale)
