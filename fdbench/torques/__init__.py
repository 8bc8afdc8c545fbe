"""Registry of torque parameterisations: ``TORQUES[name]`` -> class; ``make_torque(name, **options)``."""

from . import ann, cs, pf  # noqa: F401  (registration)
from .base import TORQUES, TorqueParameterisation, make_torque
from ..registry import load_plugins

__all__ = ["TORQUES", "TorqueParameterisation", "make_torque"]

load_plugins()  # methods registered by plugin modules ($FDBENCH_PLUGINS, entry points)
