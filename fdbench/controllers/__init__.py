"""Registry of controllers: ``CONTROLLERS[name]`` -> class; ``make_controller(name, **options)``."""

from . import pd, computed_torque, lqr, cmc  # noqa: F401, I001  (registration; pd, the paper's, first)
from .base import CONTROLLERS, Controller, make_controller
from ..registry import load_plugins

__all__ = ["CONTROLLERS", "Controller", "make_controller"]

load_plugins()  # methods registered by plugin modules ($FDBENCH_PLUGINS, entry points)
