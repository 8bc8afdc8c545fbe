"""The interface of a torque parameterisation and its registry.

A parameterisation maps a parameter vector p, shape (n_params,), to an elbow torque history
evaluated over an array of times t (s), shape (n,) -> (n,) N m. ``prepare`` is called once per
problem with the target (inverse-dynamics) torque and returns the initial guess.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from typing import Callable

import numpy as np

from ..registry import Registry


class TorqueParameterisation(ABC):
    """Base class. Subclasses take their options (``hidden``, ``knots``, ...) as keyword
    arguments, validate them in ``__init__`` (ValueError with a one-line message) and set
    ``n_params``."""

    name: str = ""
    summary: str = ""
    n_params: int
    # the options offered as flags of their own (--knots): {option: fdbench.method_options.MethodOption}
    command_line: dict = {}
    # default options of optimisers on this parameterisation, {optimizer: {option: value}}
    # (in the scaled parameters of ``scale``); an option given by the user wins
    optimizer_defaults: dict = {}

    @abstractmethod
    def prepare(self, t: np.ndarray, target: np.ndarray, feedforward: bool) -> np.ndarray:
        """Fit to the target torque (N m) on times t (s) and return the initial guess, shape
        (n_params,). With feedforward the parameterisation describes an additional torque whose
        initial guess is zero torque."""

    @abstractmethod
    def evaluate(self, p: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Torque (N m) at times t (s), shape (n,), for parameters p."""

    def scale(self) -> np.ndarray:
        """A typical magnitude of each parameter, shape (n_params,): optimisers work on p / scale."""
        return np.ones(self.n_params)

    def on_grid(self, t: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """A fast evaluator p -> torque (N m) on the fixed times t (s), shape (n_params,) -> (n,).

        Where the parameterisation has its own ``on_grid_batch``, a population of one through it,
        so that one candidate and a population give the same numbers to the last bit; else
        ``evaluate`` (override to precompute)."""
        if type(self).on_grid_batch is not TorqueParameterisation.on_grid_batch:
            batch = self.on_grid_batch(t)
            return lambda p: batch(np.asarray(p, dtype=float).reshape(1, -1))[0]
        return lambda p: self.evaluate(p, t)

    def on_grid_batch(self, t: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """A fast evaluator P -> torques (N m) on the fixed times t (s) for a whole population,
        shape (lam, n_params) -> (lam, n). Row c depends on P[c] alone, to the last bit, whatever
        lam. Override with array operations or a compiled kernel; this default runs ``on_grid``
        row by row."""
        single = self.on_grid(t)
        count = len(t)

        def evaluate(P):
            P = np.asarray(P, dtype=float)
            out = np.empty((len(P), count))
            for c, p in enumerate(P):
                out[c] = single(p)
            return out

        return evaluate

    @classmethod
    def warm_up(cls) -> None:
        """Import what the parameterisation needs, so that a run's timing excludes start-up costs."""

    def on_grid_jacobian(self, t: np.ndarray) -> Callable[[np.ndarray], np.ndarray] | None:
        """An evaluator p -> d torque / d p on the fixed times t, shape (n, n_params) (N m per
        parameter unit), for exact gradients; None where the parameterisation gives none."""
        return None


TORQUES: Registry[type[TorqueParameterisation]] = Registry("torque")


def make_torque(name: str, **options) -> TorqueParameterisation:
    """An instance of the registered torque ``name``, given the options its class accepts
    (others are ignored, so one set of command-line options serves every torque)."""
    cls = TORQUES[name]
    accepted = inspect.signature(cls).parameters
    return cls(**{k: v for k, v in options.items() if k in accepted and v is not None})


def check_count(option: str, value: int, minimum: int, maximum: int = 10**6) -> int:
    if not isinstance(value, (int, np.integer)) or not minimum <= value <= maximum:
        raise ValueError(f"{option} must be an integer in [{minimum}, {maximum}], got {value}")
    return int(value)
