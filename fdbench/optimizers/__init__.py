"""Registry of optimisers: ``OPTIMIZERS[name]`` -> class; ``make_optimizer(name, **options)``."""

from . import cmaes, scipy_methods  # noqa: F401  (registration; cma itself is imported lazily)
from .base import OPTIMIZERS, Budgeted, BudgetExhausted, OptimizationResult, Optimizer, make_optimizer

__all__ = ["OPTIMIZERS", "Budgeted", "BudgetExhausted", "OptimizationResult", "Optimizer", "make_optimizer"]
