"""Registry of torque parameterisations: ``TORQUES[name]`` -> class; ``make_torque(name, **options)``."""

from . import ann, cs, pf  # noqa: F401  (registration)
from .base import TORQUES, TorqueParameterisation, make_torque

__all__ = ["TORQUES", "TorqueParameterisation", "make_torque"]
