"""Optimisers from scipy.optimize.minimize; gradients by finite differences where needed.

Each is a few lines: the method name and its options. Adding another scipy method means adding
one class here.
"""

from __future__ import annotations

import numpy as np

from .base import OPTIMIZERS, Budgeted, Optimizer


class ScipyMinimize(Optimizer):
    method = ""
    options: dict = {}

    def run(self, f: Budgeted, x0, seed):
        from scipy.optimize import minimize

        result = minimize(f, np.asarray(x0, dtype=float), method=self.method,
                          options={"maxiter": 100 * f.budget, **self.options})
        return str(result.message)


@OPTIMIZERS.register("bfgs")
class BFGS(ScipyMinimize):
    name = "bfgs"
    summary = "BFGS quasi-Newton (scipy), gradients by forward differences"
    method = "BFGS"


@OPTIMIZERS.register("lbfgsb")
class LBFGSB(ScipyMinimize):
    name = "lbfgsb"
    summary = "L-BFGS-B limited-memory quasi-Newton (scipy), gradients by forward differences"
    method = "L-BFGS-B"
    options = {"maxfun": 10**9}


@OPTIMIZERS.register("nelder-mead")
class NelderMead(ScipyMinimize):
    name = "nelder-mead"
    summary = "Nelder-Mead simplex (scipy), derivative-free"
    method = "Nelder-Mead"
    options = {"adaptive": True}
