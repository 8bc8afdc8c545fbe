"""The interface of a controller and its registry.

Every controller is one instance of the feedback law the engine's kernels apply per joint
(``fdbench.multibody.simulation.simulate``):

    tau(t) = tau_ff(t) + kp (z_d - z) + kd (z'_d - z')        (PD: per-joint gains)
    tau(t) = tau_ff(t) + K(t) [z_d - z, z'_d - z']            (a gain matrix K(t), shape (J, 2J))
    tau(t) = M(z) (z''_d + kp e + kd e') + h(z, z')           (computed torque on the nominal model)

A controller designs it once per run from a ``Plan`` (the nominal model and the desired motion);
the simulation then runs without a Python call per integration step.
"""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..registry import Registry


@dataclass(frozen=True)
class Plan:
    """What a controller designs from: ``engine``, the nominal model's engine
    (``multibody.engine.Engine``: inverse dynamics, M(z), h); ``model``, its description
    (``multibody.model.Model``); ``motion``, the desired motion of its J joints
    (``multibody.motions.JointMotion``)."""

    engine: object
    model: object
    motion: object

    @property
    def joints(self) -> tuple[str, ...]:
        return tuple(self.model.coordinates)

    def feedforward(self):
        """The nominal model's inverse-dynamics torques on the desired motion, a torque function
        t (s), shape (k,) -> (k, J) N m: one per plan, which keeps the last times it was
        evaluated at (a run samples it on the half-step grid before its clock starts)."""
        return self._feedforward

    @cached_property
    def _feedforward(self):
        from ..multibody.simulation import feedforward  # lazy: numba off the CLI's start-up

        return feedforward(self.engine, self.motion)


@dataclass(frozen=True)
class Design:
    """A controller's law as the kernels apply it. ``feedforward``: t (s), shape (k,) -> (k, J) N m,
    or None (none). ``kp``, ``kd``: per-joint gains, shape (J,) (N m/rad, N m s/rad; with
    ``computed`` the error dynamics' 1/s^2 and 1/s). ``gains``: None or K(t), t shape (k,) ->
    (k, J, 2J), used instead of kp, kd. ``computed``: computed torque on the nominal model.
    ``label``: what tau_ff is, for records ("id": the inverse-dynamics torque). ``fields``: the
    record's extra fields (e.g. the gains per joint)."""

    feedforward: object
    kp: np.ndarray | float = 0.0
    kd: np.ndarray | float = 0.0
    gains: object = None
    computed: bool = False
    label: str = "id"
    fields: dict = field(default_factory=dict)


class Controller(ABC):
    """Base class. Subclasses take their options (``kp``, ``bandwidth``, ...) as keyword
    arguments, validate them in ``__init__`` (ValueError with a one-line message naming the
    option) and set ``name``, ``summary`` (one sentence: what it does, which tool uses it)."""

    name: str = ""
    summary: str = ""
    # the options offered as flags of their own (--kp): {option: fdbench.method_options.MethodOption}
    command_line: dict = {}

    @abstractmethod
    def design(self, plan: Plan) -> Design:
        """The feedforward torques and the feedback law towards ``plan.motion``."""

    def check_model(self, model) -> None:
        """ValueError (one line) for a model (``multibody.model.Model``) whose design would
        take more time or memory than a run is allowed; checked before any work."""

    def check_run(self, model, duration: float, dt: float) -> None:
        """ValueError (one line) for settings that do not fit a run of ``model`` over ``duration`` s
        with RK4 steps of about ``dt`` s; checked before any work."""

    def warm_up(self, plan: Plan) -> None:
        """Import or build what ``design`` needs, so that a run's timing excludes it."""

    def options(self) -> dict:
        """The options this controller was made with (for records and run hashes)."""
        return {name: getattr(self, name) for name in inspect.signature(type(self)).parameters}


CONTROLLERS: Registry[type[Controller]] = Registry("controller")


class DesignError(ValueError):
    """A method that cannot be carried out with the options given (no finite Riccati solution for
    extreme weights, a gain that overflows, a static optimisation that does not converge): bad input."""


NUMERICAL_FAILURES = (ArithmeticError, np.linalg.LinAlgError)  # what such options make numpy and scipy raise


@contextmanager
def failing_on_options(method: str, options: str):
    """Within the block, a numerical failure (``NUMERICAL_FAILURES``) is raised as DesignError
    naming ``method`` and its ``options`` (text)."""
    try:
        yield
    except NUMERICAL_FAILURES as exc:
        raise DesignError(f"{method} fails with {options or 'its default options'}: {type(exc).__name__}: "
                          f"{str(exc).rstrip('.')}; choose less extreme values") from None


def make_controller(name: str, **options) -> Controller:
    """An instance of the registered controller ``name``, given the options its class accepts
    (others are ignored, so one set of command-line options serves every controller)."""
    return CONTROLLERS[name](**accepted_options(name, options))


def accepted_options(name: str, options: dict) -> dict:
    """The options (not None) that controller ``name``'s class accepts."""
    accepted = inspect.signature(CONTROLLERS[name]).parameters
    return {k: v for k, v in options.items() if k in accepted and v is not None}


def check_non_negative(option: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0):
        raise ValueError(f"{option} must be a non-negative finite number, got {value}")
    return float(value)


def check_positive(option: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise ValueError(f"{option} must be a positive finite number, got {value}")
    return float(value)


def per_joint(prefix: str, joints, values) -> dict:
    """Record fields ``<prefix>_<joint>`` of per-joint values; none for one joint (the overall value)."""
    return {f"{prefix}_{joint}": float(v) for joint, v in zip(joints, values)} if len(joints) > 1 else {}


def muscle_columns(result, muscles) -> tuple[list[str], np.ndarray]:
    """The trajectory columns of a simulation with muscles: (header, values (n, 3 M)),
    ``<muscle>_activation``, ``_excitation`` and ``_force`` (N) for each of ``muscles`` in turn."""
    header = [f"{m}_{s}" for m in muscles for s in ("activation", "excitation", "force")]
    return header, np.stack([result.activation, result.excitation, result.muscle_force], axis=-1).reshape(
        len(result.t), -1)
