"""The optimiser interface, its registry, and the evaluation budget every optimiser obeys.

An optimiser sees only an objective f(x) -> float (and, for a gradient-based optimiser asked
for exact gradients, a value-and-gradient function x -> (f, df/dx)), a start x0 (shape (n,)), a
budget of objective evaluations, a seed and its own options. ``Budgeted`` counts every call,
gradient evaluations by finite differences included (one value-and-gradient pass counts as one
evaluation: it is one simulation with its sensitivities), stops the optimiser by raising ``BudgetExhausted``
when the budget is spent, and remembers the best point evaluated, which is the result whatever
the optimiser itself reports.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..registry import Registry

Objective = Callable[[np.ndarray], float]


NO_ITERATION = "no iteration completed"  # how a stop reason begins when the budget could not buy one


class BudgetExhausted(Exception):
    """Raised inside the objective when the evaluation budget is spent."""


@dataclass
class OptimizationResult:
    x: np.ndarray  # best point evaluated, shape (n,)
    fun: float  # its objective value
    evaluations: int
    stop_reason: str
    history: list[float] = field(default_factory=list)  # best-so-far objective per evaluation


class Budgeted:
    """Wraps an objective: counts evaluations, enforces the budget, keeps the best point.

    ``on_evaluation(count, best)`` is called after every evaluation (progress display)."""

    def __init__(self, objective: Objective, budget: int, on_evaluation=None, gradient=None, batch=None):
        self.objective, self.budget, self.on_evaluation = objective, budget, on_evaluation
        self.gradient = gradient  # x -> (f, df/dx, shape (n,)), or None
        self.batch = batch  # X, shape (lam, n) -> f of each row, shape (lam,), or None
        self.count = 0
        self.best_x: np.ndarray | None = None
        self.best_f = math.inf
        self.history: list[float] = []

    @property
    def remaining(self) -> int:
        return self.budget - self.count

    def __call__(self, x) -> float:
        if self.count >= self.budget:
            raise BudgetExhausted
        x = np.array(x, dtype=float)
        return self._record(x, float(self.objective(x)))

    def many(self, xs) -> list[float]:
        """f of each of the points xs (a population), in order, counted as len(xs) evaluations;
        the same numbers and the same bookkeeping as calling f on each in turn, in one call of
        ``batch`` when given. Evaluates at most the remaining budget's worth of points."""
        if self.count >= self.budget:
            raise BudgetExhausted
        xs = [np.array(x, dtype=float) for x in xs][: self.remaining]
        if self.batch is None:
            return [self(x) for x in xs]
        values = self.batch(np.array(xs))
        return [self._record(x, float(f)) for x, f in zip(xs, values)]

    def value_and_gradient(self, x) -> tuple[float, np.ndarray]:
        """f(x) and its gradient, shape (n,), counted as one evaluation (needs ``gradient``);
        where f is not finite the gradient is zero."""
        if self.count >= self.budget:
            raise BudgetExhausted
        x = np.array(x, dtype=float)
        f, g = self.gradient(x)
        f = self._record(x, float(f))
        g = np.array(g, dtype=float)
        return f, (g if math.isfinite(f) and np.all(np.isfinite(g)) else np.zeros_like(x))

    def _record(self, x, f) -> float:
        if not math.isfinite(f):
            f = math.inf
        self.count += 1
        if f < self.best_f or self.best_x is None:
            self.best_f, self.best_x = f, x
        self.history.append(self.best_f)
        if self.on_evaluation is not None:
            self.on_evaluation(self.count, self.best_f)
        return f

    def result(self, stop_reason: str) -> OptimizationResult:
        if self.count >= self.budget:
            stop_reason = f"budget of {self.budget} evaluations spent"
        return OptimizationResult(self.best_x, self.best_f, self.count, stop_reason, list(self.history))


class Optimizer(ABC):
    """Base class. Subclasses take their options (``sigma0``, ``popsize``, ...) as keyword
    arguments and implement ``run``."""

    name: str = ""
    summary: str = ""
    uses_gradient: bool = False  # True: run() uses f.value_and_gradient when f.gradient is given
    # the options offered as flags of their own (--sigma0): {option: fdbench.method_options.MethodOption}
    command_line: dict = {}

    @abstractmethod
    def run(self, f: Budgeted, x0: np.ndarray, seed: int) -> str:
        """Minimise f from x0 until it converges or raises BudgetExhausted; return a stop reason
        (used when the budget is not spent)."""

    def minimize(self, objective: Objective, x0, budget: int, seed: int = 0, on_evaluation=None,
                 gradient=None, batch=None) -> OptimizationResult:
        """Minimise objective from x0 within budget evaluations. ``gradient``: x -> (f(x), df/dx),
        the exact gradient, used by gradient-based optimisers instead of finite differences.
        ``batch``: X (lam, n) -> f of each row, the same numbers as ``objective`` row by row,
        used by population-based optimisers to evaluate a generation in one call."""
        if budget < 1:
            raise ValueError(f"budget must be >= 1, got {budget}")
        if gradient is not None and not self.uses_gradient:
            raise ValueError(f"optimizer {self.name!r} uses no gradient; exact gradients serve bfgs and lbfgsb")
        f = Budgeted(objective, budget, on_evaluation, gradient, batch)
        x0 = np.asarray(x0, dtype=float)
        try:
            reason = self.run(f, x0, seed)
        except BudgetExhausted:
            reason = "budget spent"
        if f.count == 0:  # an optimiser that never evaluated still reports its start
            try:
                f(x0)
            except BudgetExhausted:  # pragma: no cover - budget >= 1
                pass
        result = f.result(reason)
        need = self.smallest_budget(len(x0), gradient is not None)
        if budget < need:  # the result is the start or a point of an unfinished line search: say so
            result.stop_reason = (f"{NO_ITERATION}: {self.name} needs {need} evaluations for its first iteration on "
                                  f"{len(x0)} parameters" + ("" if gradient is not None else
                                                             " with finite-difference gradients")
                                  + f", the budget was {budget} (give --budget {need} or more"
                                  + ("" if gradient is not None else ", or --gradient exact, which needs 2") + ")")
        return result

    def warm_up(self) -> None:
        """Import what the optimiser needs, so that its timing excludes start-up costs."""

    def smallest_budget(self, n_params: int, exact_gradient: bool = False) -> int:
        """The fewest evaluations in which the optimiser completes one iteration from its start on
        ``n_params`` parameters (1: any budget does)."""
        return 1


OPTIMIZERS: Registry[type[Optimizer]] = Registry("optimizer")


def make_optimizer(name: str, **options) -> Optimizer:
    """An instance of the registered optimiser ``name``, given the options its class accepts."""
    import inspect

    cls = OPTIMIZERS[name]
    accepted = inspect.signature(cls).parameters
    return cls(**{k: v for k, v in options.items() if k in accepted and v is not None})
