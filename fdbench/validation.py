"""Checks of a spec's conditions and gradient option, each a one-line ValueError naming the option
(``RunSpec.validate`` runs them before any work)."""

from __future__ import annotations

import math

from .files import BadFile
from .models import check_name, with_changes
from .multibody.motions import check_estimate
from .optimizers import OPTIMIZERS
from .run_inputs import model_digest
from .torques.base import TorqueParameterisation

GRADIENTS = ("fd", "exact")
MAX_SEED = 2**32 - 2  # cma draws from numpy with seed + 1, which must stay below 2**32
MAX_NOISE_DEG = 45.0
MAX_CAPTURE_HZ = 100_000.0


def check_gradient(gradient, optimizer, torque, integrator) -> None:
    """ValueError with a one-line message unless ``gradient`` suits the optimiser, the torque
    parameterisation and the integrator (exact gradients: bfgs or lbfgsb, rk4, a torque with
    d tau / d p)."""
    if gradient not in GRADIENTS:
        raise ValueError(f"--gradient must be one of {', '.join(GRADIENTS)}, got {gradient!r}")
    if gradient == "fd":
        return
    if not optimizer.uses_gradient:
        users = ", ".join(n for n, c in OPTIMIZERS.items() if getattr(c, "uses_gradient", False))
        raise ValueError(f"--gradient exact needs a gradient-based optimiser ({users}), got {optimizer.name}")
    if integrator != "rk4":
        raise ValueError(f"--gradient exact needs --integrator rk4, got {integrator}")
    if type(torque).on_grid_jacobian is TorqueParameterisation.on_grid_jacobian:
        raise ValueError(f"--gradient exact: torque {torque.name!r} gives no d tau / d p")


def check_conditions(spec) -> None:
    """The motion, noise and model options of a spec; ValueError with a one-line message."""
    check_estimate(spec.cutoff_hz, spec.smoothing, spec.spline_lambda)
    if not (math.isfinite(spec.noise_deg) and 0 <= spec.noise_deg <= MAX_NOISE_DEG):
        raise ValueError(f"--noise-deg must be in [0, {MAX_NOISE_DEG:g}] deg, got {spec.noise_deg}")
    if not (math.isfinite(spec.capture_hz) and 1 <= spec.capture_hz <= MAX_CAPTURE_HZ):
        raise ValueError(f"--capture-hz must be in [1, {MAX_CAPTURE_HZ:g}] Hz, got {spec.capture_hz}")
    if spec.noise_deg and spec.seed is not None and not (isinstance(spec.seed, int) and 0 <= spec.seed < MAX_SEED):
        raise ValueError(f"--seed must be an integer in [0, {MAX_SEED - 1}], got {spec.seed}")
    check_name(spec.model_name)
    digest = dict(spec.inputs).get("--model")
    if digest is not None and digest != model_digest(spec.model_name):
        raise BadFile(f"--model: {spec.model_name} has changed since this run was specified (or differs on this machine)")
    for option, changes in (("--model", spec.model), ("--plant", spec.model + spec.plant)):
        try:
            with_changes(spec.model_name, changes)
        except ValueError as exc:  # a change the model cannot take: name the option that made it
            raise ValueError(f"{option} {exc}") from None
