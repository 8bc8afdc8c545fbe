"""Registry of optimisers: ``OPTIMIZERS[name]`` -> class; ``make_optimizer(name, **options)``."""

from . import cmaes, scipy_methods  # noqa: F401  (registration; cma itself is imported lazily)
from .base import OPTIMIZERS, Budgeted, BudgetExhausted, OptimizationResult, Optimizer, make_optimizer
from ..registry import load_plugins

__all__ = ["OPTIMIZERS", "Budgeted", "BudgetExhausted", "OptimizationResult", "Optimizer", "make_optimizer"]

load_plugins()  # methods registered by plugin modules ($FDBENCH_PLUGINS, entry points)
