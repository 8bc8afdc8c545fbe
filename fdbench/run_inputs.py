"""What a ``RunSpec`` stands for on the engine: the believed model (``nominal``) and the simulated
body (``plant``), their engines, motions, loads, reference (nominal inverse dynamics on the true
motion), record fields, checks, controller and input digests. Imports nothing of the run layer."""

from __future__ import annotations

import hashlib
from functools import lru_cache

import numpy as np

from .controllers import make_controller
from .controllers.base import Plan
from .controllers.pd import PD
from .files import BadFile, read_input_bytes, read_input_text
from .integrate import check_settings, steps
from .method_options import options_text
from .models import description, with_changes
from .multibody.motions import check_source
from .multibody import simulation as sim
from .multibody.engine import Engine
from .multibody.loads import loads_digest, read_external_loads
from .multibody.motions import Resampled, joint_motion, noisy_joints
from . import tracking


# ---------------------------------------------------------------------- input files
def motion_digest(path) -> str:
    """SHA-256 of a recorded motion file's content."""
    check_source(str(path))
    return hashlib.sha256(read_input_text(path, "--motion").encode()).hexdigest()


def model_digest(path) -> str:
    """SHA-256 of a model file's content."""
    return hashlib.sha256(read_input_bytes(path, "--model")).hexdigest()


# ---------------------------------------------------------------------- the model and its motion
def nominal(spec):
    """The model the methods believe: the spec's model with its ``--model`` changes."""
    return with_changes(spec.model_name, spec.model)


def plant(spec):
    """The simulated body: the nominal model with the ``--plant`` changes too."""
    return with_changes(spec.model_name, tuple(spec.model) + tuple(spec.plant))


@lru_cache(maxsize=32)
def _engine(model, alpha: float, xi: float, omega: float, loads=None):
    return Engine(model, alpha, xi, omega, loads)


def engine(spec, model=None):
    """The engine of ``model`` (default: the plant) with the spec's penalty parameters and its
    external loads (``--loads``)."""
    return _engine(plant(spec) if model is None else model, spec.alpha, spec.xi, spec.omega, loads(spec))


def loads(spec):
    """The spec's external loads (``--loads``) on its motion's clock, or None."""
    if spec.loads is None:
        return None
    desired, truth = motions(spec)
    return _loads(spec.loads, dict(spec.inputs).get("--loads"), nominal(spec), getattr(truth, "start_s", 0.0),
                  truth.duration)


@lru_cache(maxsize=8)
def _loads(path: str, digest, model, start_s: float, duration: float):
    if digest is not None and digest != loads_digest(path):
        raise BadFile(f"--loads: {path} (or its data file) has changed since this run was specified")
    found = read_external_loads(path, model).shifted(start_s)
    try:
        found.check_span(0.0, duration)
    except ValueError as exc:
        raise BadFile(str(exc)) from None
    return found


def joints(spec) -> tuple:
    return nominal(spec).coordinates


@lru_cache(maxsize=32)
def _motions(model_name, source, radians, cutoff_hz, smoothing, spline_lambda, sample_dt, noise_deg, seed, capture_hz,
             digest):
    estimate = dict(cutoff_hz=cutoff_hz, smoothing=smoothing, spline_lambda=spline_lambda)
    model = description(model_name)
    truth = joint_motion(source, model, radians, **estimate)
    if sample_dt is not None:
        truth = Resampled(truth, sample_dt)
    if digest is not None and digest != motion_digest(source):
        raise BadFile(f"--motion: {source} has changed since this run was specified (or differs on this machine)")
    if not noise_deg:
        return truth, truth
    return noisy_joints(truth, noise_deg, seed, capture_hz, model.coordinate_kinds, **estimate), truth


def motions(spec):
    """(desired, true) motions of a spec: the one given to every method (a noisy capture when
    ``noise_deg`` > 0) and the one its indicators are measured against."""
    return _motions(spec.model_name, spec.motion, spec.radians, spec.cutoff_hz, spec.smoothing, spec.spline_lambda,
                    spec.sample_dt, spec.noise_deg, spec.seed or 0, spec.capture_hz, dict(spec.inputs).get("--motion"))


def reference(spec) -> sim.JointInverse:
    """The nominal model's inverse dynamics on the true motion, on its samples (the indicators' reference)."""
    return sim.inverse_dynamics(None, engine(spec, nominal(spec)), motions(spec)[1])


def describe(spec) -> dict:
    """The record's fields that say which motion, noise, filter, model and plant a run used."""
    desired, truth = motions(spec)
    out = {"motion": desired.name, "duration_s": truth.duration, "samples": len(truth.samples)}
    parts = getattr(desired, "parts", [])
    if parts and hasattr(parts[0], "describe"):
        out["derivatives"] = parts[0].describe().get("derivatives")
    out.update(noise_deg=spec.noise_deg, model=spec.model_name, model_options=options_text(spec.model) or None,
               plant=options_text(spec.plant) or None)
    if spec.loads is not None:
        out["loads"] = spec.loads
    return out


def check(spec) -> None:
    """ValueError (one line) for what the engine cannot run, or settings out of range; BadFile for a
    motion file that cannot be used. No simulation is run."""
    check_settings(spec.integrator, spec.dt, spec.rtol, spec.atol, spec.alpha, spec.xi, spec.omega)
    engine(spec, nominal(spec)), engine(spec)
    given = ["--residual-weight"] if spec.residual_weight is not None else []
    if spec.command == "collocate":
        given += [f"--{key.replace('_', '-')}" for key in ("residual_force_weight", "residual_moment_weight")
                  if dict(spec.method_options).get(key) is not None]
    if given and engine(spec).model.floating_base is None:
        raise ValueError(f"{given[0]} needs a model with a floating base (a free joint on ground); "
                         f"{engine(spec).model.name!r} has none")
    desired, _ = motions(spec)
    if spec.command == "optimize" and spec.gradient == "exact" and spec.integrator == "rk4":
        _check_samples_on_grid(spec, desired)


def _check_samples_on_grid(spec, motion) -> None:
    """ValueError (one line) unless the motion's samples lie on the RK4 grid of ``--dt``, one
    every so many steps: exact gradients differentiate eq. 18 on the RK4 states themselves."""
    n = steps(spec.dt, motion.duration)
    if not sim.samples_on_grid(np.linspace(0.0, motion.duration, n + 1), motion.samples):
        fitted = sim.dt_on_samples(spec.dt, motion.samples)
        hint = f"; --dt {fitted!r} puts them on it" if fitted != spec.dt else ""
        raise ValueError(f"--gradient exact needs the motion's samples on the RK4 grid (uniform, every k steps of "
                         f"--dt {spec.dt!r}){hint}")


def integration(spec) -> dict:
    """The keyword arguments of ``simulation.simulate`` that say how a spec integrates."""
    return dict(dt=spec.dt, integrator=spec.integrator, rtol=spec.rtol, atol=spec.atol)


def simulate(spec, drive, **law):
    """The plant's forward simulation of the desired motion under ``drive`` and a feedback law."""
    return sim.simulate(drive, engine(spec), motions(spec)[0], **law, **integration(spec))


def warm_up(spec, population: bool = False) -> None:
    """Load (or compile) the engine's kernels for the spec's model (and scipy's integrators for an
    adaptive one; with ``population`` the shooting problem's population kernel), so that runtimes
    exclude it."""
    engines = sim.warm_up(spec.integrator != "rk4", (engine(spec),))
    if population:
        tracking.warm_up(engines)


# ---------------------------------------------------------------------- control
def controller(spec):
    """The spec's registered controller (``fdbench.controllers``) with its options; the paper's PD
    takes the spec's gains (None: scaled per joint)."""
    name = spec.controller or "pd"
    options = {"kp": spec.kp, "kd": spec.kd} if name == "pd" else dict(spec.method_options)
    return make_controller(name, **options)


def plan(spec) -> Plan:
    """What a controller designs from: the nominal model's engine and description, the desired motion."""
    return Plan(engine(spec, nominal(spec)), nominal(spec), motions(spec)[0])


def pd_gains(spec) -> tuple[np.ndarray, np.ndarray]:
    """Kp (N m/rad) and Kd (N m s/rad) per joint, shape (J,), of the spec's PD (``controllers.pd.PD``)."""
    return PD(spec.kp, spec.kd).gains(plan(spec))
