"""The interface of a controller and its registry.

Every controller is one instance of the feedback law compiled in ``dynamics.rk4_feedback``:

    tau(t) = tau_ff(t) + kp(t) (theta_d - theta) + kd(t) (theta'_d - theta') + g_c cos(theta)

A controller designs tau_ff (a torque function) and the ``FeedbackLaw`` (kp, kd, g_c) once per
run, from the settings' model and kinematics; the simulation then runs without a Python call
per integration step.
"""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod

from ..integrate import FeedbackLaw, Settings, TorqueFunction
from ..registry import Registry


class Controller(ABC):
    """Base class. Subclasses take their options (``kp``, ``bandwidth``, ...) as keyword
    arguments, validate them in ``__init__`` (ValueError with a one-line message naming the
    option) and set ``name``, ``summary`` (one sentence: what it does, which tool uses it)."""

    name: str = ""
    summary: str = ""
    feedforward_label: str = "id"  # what tau_ff is, for records: "id" is the inverse-dynamics torque

    @abstractmethod
    def design(self, settings: Settings) -> tuple[TorqueFunction, FeedbackLaw]:
        """The feedforward torque tau_ff (t (s), shape (n,) -> N m, shape (n,)) and the feedback
        law towards the desired motion of ``settings.kinematics``."""

    def warm_up(self) -> None:
        """Import what ``design`` needs, so that a run's timing excludes imports."""

    def options(self) -> dict:
        """The options this controller was made with (for records and run hashes)."""
        return {name: getattr(self, name) for name in inspect.signature(type(self)).parameters}


CONTROLLERS: Registry[type[Controller]] = Registry("controller")


def make_controller(name: str, **options) -> Controller:
    """An instance of the registered controller ``name``, given the options its class accepts
    (others are ignored, so one set of command-line options serves every controller)."""
    return CONTROLLERS[name](**accepted_options(name, options))


def accepted_options(name: str, options: dict) -> dict:
    """The options (not None) that controller ``name``'s class accepts."""
    accepted = inspect.signature(CONTROLLERS[name]).parameters
    return {k: v for k, v in options.items() if k in accepted and v is not None}


def check_non_negative(option: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ValueError(f"{option} must be a non-negative finite number, got {value}")
    return float(value)


def check_positive(option: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{option} must be a positive finite number, got {value}")
    return float(value)
