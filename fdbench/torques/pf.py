"""Parametric function of eq. 20 as its source intends: a sum of Gaussian bumps,
PF(t) = sum_i A_i exp(-C_i (t - T_i)^2). The form printed in the paper, A e^{-C (t - T)},
makes A and T redundant (A e^{CT} is one constant), so it cannot be what was meant.
"""

from __future__ import annotations

import numpy as np

from ..method_options import MethodOption
from .base import TORQUES, TorqueParameterisation, check_count


@TORQUES.register("pf")
class GaussianSumTorque(TorqueParameterisation):
    """Parameters [A_1, C_1, T_1, A_2, ...]: amplitude (N m), sharpness C (1/s^2), centre (s)."""

    name = "pf"
    # CMA-ES: small steps, as sharpness and centres react strongly (Table 3: 0.54 deg against 1.73 with 0.1)
    optimizer_defaults = {"cmaes": {"sigma0": 0.03}}
    summary = "sum of --terms Gaussian bumps A exp(-C (t - T)^2), 3 parameters each (default 4)"

    command_line = {"terms": MethodOption("terms (Gaussian bumps) in [1, 100], 3 parameters each.", int, 4)}

    def __init__(self, terms: int = 4):
        self.terms = check_count("--terms", terms, 1, 100)
        self.n_params = 3 * self.terms
        self._amplitude = 1.0
        self.duration = 1.0  # s, set by prepare from the motion's samples

    def default_shape(self) -> np.ndarray:
        """Bumps of zero amplitude, centred in equal slices of [0, T] s, about as wide as one."""
        n, span = self.terms, self.duration
        centres = (np.arange(n) + 0.5) / n * span
        sharpness = np.full(n, 2.0 * n**2 / span**2)  # standard deviation T / (2 n) s
        return np.column_stack([np.zeros(n), sharpness, centres]).ravel()

    @classmethod
    def warm_up(cls):
        import scipy.optimize  # noqa: F401  (its import is not part of a run's runtime)

        from .kernels import warm_up  # lazy: numba off the CLI's start-up

        warm_up()

    def prepare(self, t, target, feedforward):
        self._amplitude = max(float(np.max(np.abs(target))), 1e-9)
        self.duration = float(t[-1]) if t[-1] > 0 else 1.0
        p = self.default_shape()
        if feedforward:
            return p
        from scipy.optimize import least_squares

        # the torque is smooth: ~200 points fit it as well as 1001, but never fewer than the parameters
        every = max(1, len(t) // max(200, self.n_params))
        ts, targets = t[::every], target[::every]
        # Levenberg-Marquardt needs at least as many residuals as parameters; a trust region does not
        method = "lm" if len(ts) >= self.n_params else "trf"
        with np.errstate(all="ignore"):
            fit = least_squares(lambda p: self.evaluate(p, ts) - targets, p, jac=lambda p: self.jacobian(p, ts),
                                method=method, max_nfev=300)
        return fit.x

    def jacobian(self, p, t) -> np.ndarray:
        """d PF(t) / d p, shape (n, n_params): columns dA, dC, dT of each term in turn."""
        a, c, centre = np.asarray(p, dtype=float).reshape(-1, 3).T
        d = np.asarray(t, dtype=float)[:, None] - centre
        with np.errstate(over="ignore", invalid="ignore"):
            bump = np.exp(-c * d**2)
        return np.stack([bump, -a * d**2 * bump, 2 * a * c * d * bump], axis=-1).reshape(len(d), -1)

    def evaluate(self, p, t):
        p = np.asarray(p, dtype=float).reshape(-1, 3)
        t = np.asarray(t, dtype=float)
        with np.errstate(over="ignore", invalid="ignore"):
            return np.exp(-p[:, 1] * (t[..., None] - p[:, 2]) ** 2) @ p[:, 0]

    def on_grid_batch(self, t):
        from .kernels import gaussian_exponents, own_weighted_sums  # lazy: numba off the CLI's start-up

        t = np.ascontiguousarray(t, dtype=float)
        terms = self.terms

        def evaluate(P):
            """The exponents in a kernel, their exp by numpy, the bumps' weighted sum in a kernel."""
            P = np.ascontiguousarray(P, dtype=float).reshape(len(P), terms, 3)
            bumps = np.empty((len(P), terms, len(t)))
            gaussian_exponents(t, P, bumps)
            with np.errstate(over="ignore", invalid="ignore"):
                np.exp(bumps, out=bumps)
            out = np.empty((len(P), len(t)))
            own_weighted_sums(np.ascontiguousarray(P[:, :, 0]), bumps, np.zeros(len(P)), 1.0, 0.0, out)
            return out

        return evaluate

    def on_grid_jacobian(self, t):
        t = np.asarray(t, dtype=float)

        def jacobian(p):
            with np.errstate(over="ignore", invalid="ignore"):
                return np.ascontiguousarray(self.jacobian(p, t))

        return jacobian

    def scale(self):
        n, span = self.terms, self.duration
        return np.tile([self._amplitude, 2.0 * n**2 / span**2, span / n], n)
