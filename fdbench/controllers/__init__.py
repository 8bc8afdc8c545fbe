"""Registry of controllers: ``CONTROLLERS[name]`` -> class; ``make_controller(name, **options)``."""

from . import computed_torque, lqr, pd  # noqa: F401  (registration)
from .base import CONTROLLERS, Controller, make_controller
from ..registry import load_plugins

__all__ = ["CONTROLLERS", "Controller", "make_controller"]

load_plugins()  # methods registered by plugin modules ($FDBENCH_PLUGINS, entry points)
