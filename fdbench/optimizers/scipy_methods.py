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

    def warm_up(self):
        import scipy.optimize  # noqa: F401  (its import is not part of the runtime)

    def smallest_budget(self, n_params: int, exact_gradient: bool = False) -> int:
        """A gradient optimiser's first iteration needs the value and the gradient at its start
        and at the first point of its line search: 2 (n + 1) evaluations with forward differences
        (a value and one per parameter, twice), 2 with exact gradients; 1 for the others."""
        if not self.uses_gradient:
            return 1
        return 2 if exact_gradient else 2 * (n_params + 1)

    def run(self, f: Budgeted, x0, seed):
        from scipy.optimize import minimize

        if self.uses_gradient and f.gradient is not None:  # exact gradients: one pass per evaluation
            fun, jac = f.value_and_gradient, True
        else:
            fun, jac = f, None
        result = minimize(fun, np.asarray(x0, dtype=float), method=self.method, jac=jac,
                          options={"maxiter": 100 * f.budget, **self.options})
        return str(result.message)


@OPTIMIZERS.register("bfgs")
class BFGS(ScipyMinimize):
    name = "bfgs"
    summary = "BFGS quasi-Newton (scipy), gradients by forward differences or exact (--gradient exact)"
    method = "BFGS"
    uses_gradient = True


@OPTIMIZERS.register("lbfgsb")
class LBFGSB(ScipyMinimize):
    name = "lbfgsb"
    summary = "L-BFGS-B limited-memory quasi-Newton (scipy), gradients by forward differences or exact (--gradient exact)"
    method = "L-BFGS-B"
    uses_gradient = True
    options = {"maxfun": 10**9}


@OPTIMIZERS.register("nelder-mead")
class NelderMead(ScipyMinimize):
    name = "nelder-mead"
    summary = "Nelder-Mead simplex (scipy), derivative-free"
    method = "Nelder-Mead"
    options = {"adaptive": True}
