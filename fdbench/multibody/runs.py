"""The runs of every model, from a ``RunSpec`` (``fdbench.runners`` hands them over): inverse
dynamics, open-loop simulation, control (PD per joint with computed feedforward, computed torque,
LQR, or a registered controller), optimisation and direct collocation, on the multibody engine
(``fdbench.multibody``) built from the model's description (a library name or a model file), each
giving a flat record (``records.RECORD_FIELDS`` plus per-joint indicators) and a trajectory table.

Indicators for J joints: ``rmse_rot_deg`` is the root mean square over all angle coordinates and
samples of the angle error (deg), ``rmse_torque_nm`` likewise of their torques (N m) against the
inverse-dynamics torques; ``rmse_rot_deg_<joint>`` and ``rmse_torque_nm_<joint>`` give each joint's.
Units are never pooled: a model with translations (a free joint's x, y) has ``rmse_trans_cm`` (cm)
and ``rmse_force_n`` (N) over them, and ``rmse_trans_cm_<x>``, ``rmse_force_n_<x>`` per translation.

Files (CSV with a header, names case-insensitive, any order): a motion has ``t`` (s) and one angle
column per joint (deg, or rad), with optional ``<joint>_vel`` and ``<joint>_acc``; a torque history
has ``t`` (s) and one column per joint (N m), or ``<joint>_torque`` where the file has them (the
history of ``inverse --format csv`` or ``--save-trajectory``, whose ``<joint>`` is an angle), and a
one-joint model's may name its column ``torque``.
"""

from __future__ import annotations

import hashlib
import math
import time
from functools import lru_cache

import numpy as np

from .. import __version__
from ..controllers.base import per_joint
from ..files import BadFile, read_history_csv
from . import simulation as sim

# ---------------------------------------------------------------------- the model and its motion
def nominal(spec):
    """The model the methods believe: the spec's model with its ``--model`` changes."""
    from ..models import with_changes

    return with_changes(spec.model_name, spec.model)


def plant(spec):
    """The simulated body: the nominal model with the ``--plant`` changes too."""
    from ..models import with_changes

    return with_changes(spec.model_name, tuple(spec.model) + tuple(spec.plant))


@lru_cache(maxsize=32)
def _engine(model, alpha: float, xi: float, omega: float, loads=None):
    from .engine import Engine

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
    from .loads import loads_digest, read_external_loads

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
    from ..experiment import motion_digest
    from ..models import description
    from .motions import Resampled, joint_motion, noisy_joints

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
    return _motions(spec.model_name, spec.kinematics, spec.radians, spec.cutoff_hz, spec.smoothing, spec.spline_lambda,
                    spec.sample_dt, spec.noise_deg, spec.seed or 0, spec.capture_hz, dict(spec.inputs).get("--motion"))


def reference(spec) -> sim.JointInverse:
    """The nominal model's inverse dynamics on the true motion, on its samples (the indicators' reference)."""
    return sim.inverse_dynamics(None, engine(spec, nominal(spec)), motions(spec)[1])


def describe(spec) -> dict:
    """The record's fields that say which motion, noise, filter, model and plant a run used."""
    from ..method_options import options_text

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
    from ..integrate import check_settings

    check_settings(spec.integrator, spec.dt, spec.rtol, spec.atol, spec.alpha, spec.xi, spec.omega)
    engine(spec, nominal(spec)), engine(spec)
    if spec.residual_weight is not None and engine(spec).model.floating_base is None:
        raise ValueError(f"--residual-weight needs a model with a floating base (a free joint on ground); "
                         f"{engine(spec).model.name!r} has none")
    desired, _ = motions(spec)
    if spec.command == "optimize" and spec.gradient == "exact" and spec.integrator == "rk4":
        _check_samples_on_grid(spec, desired)


def _check_samples_on_grid(spec, motion) -> None:
    """ValueError (one line) unless the motion's samples lie on the RK4 grid of ``--dt``, one
    every so many steps: exact gradients differentiate eq. 18 on the RK4 states themselves."""
    from ..integrate import steps

    n = steps(spec.dt, motion.duration)
    if not sim.samples_on_grid(np.linspace(0.0, motion.duration, n + 1), motion.samples):
        fitted = sim.dt_on_samples(spec.dt, motion.samples)
        hint = f"; --dt {fitted!r} puts them on it" if fitted != spec.dt else ""
        raise ValueError(f"--gradient exact needs the motion's samples on the RK4 grid (uniform, every k steps of "
                         f"--dt {spec.dt!r}){hint}")


def integration(spec) -> dict:
    """The keyword arguments of ``simulation.simulate`` that say how a spec integrates."""
    return dict(dt=spec.dt, integrator=spec.integrator, rtol=spec.rtol, atol=spec.atol)


def _simulate(spec, drive, **law):
    """The plant's forward simulation of the desired motion under ``drive`` and a feedback law."""
    return sim.simulate(drive, engine(spec), motions(spec)[0], **law, **integration(spec))


# ---------------------------------------------------------------------- records
def inverse_run(spec) -> tuple[dict, list[str], np.ndarray]:
    """Inverse dynamics of the desired motion with the nominal model: (record, CSV header, rows), the
    columns of a motion file (t, <joint>, <joint>_vel, <joint>_acc in s, deg, deg/s, deg/s^2; a
    translation's in m, m/s, m/s^2) and <joint>_torque (N m; N for a translation)."""
    desired, _ = motions(spec)
    names = joints(spec)
    body = engine(spec, nominal(spec))
    began = time.perf_counter()
    inv = sim.inverse_dynamics(None, body, desired)
    runtime = time.perf_counter() - began
    kinds = nominal(spec).coordinate_kinds
    angle = np.array([kind != "translation" for kind in kinds])
    start_end = _in_file_units(inv.angles[[0, -1]], kinds)

    def force(metric: str, j: int) -> str:  # a translation's in N, never pooled with N m
        return metric.replace("torque", "force").replace("_nm", "_n") if kinds[j] == "translation" else metric

    unit = ["m" if kind == "translation" else "deg" for kind in kinds]
    record = {"command": "inverse", "kinematics": spec.kinematics, **describe(spec),
              **{f"{force(k, i)}_{j}": float(v)
                 for k, vals in (("torque_rms_nm", np.sqrt(np.mean(inv.torque**2, axis=0))),
                                 ("torque_max_nm", inv.torque.max(axis=0)), ("torque_min_nm", inv.torque.min(axis=0)))
                 for i, (j, v) in enumerate(zip(names, vals))},
              **{f"{j}_{end}_{unit[i]}": float(start_end[k, i]) for i, j in enumerate(names)
                 for end, k in (("start", 0), ("end", 1))}}
    record["torque_rms_nm"] = float(np.sqrt(np.mean(inv.torque[:, angle] ** 2))) if angle.any() else math.nan
    if not angle.all():
        record["force_rms_n"] = float(np.sqrt(np.mean(inv.torque[:, ~angle] ** 2)))
    record.update(residual_fields(nominal(spec), inv.torque))
    record.update(runtime_s=runtime, fdbench_version=__version__)
    header = ["t"] + [f"{j}{s}" for s in ("", "_vel", "_acc", "_torque") for j in names]
    rows = np.column_stack([inv.t, *(_in_file_units(v, kinds) for v in (inv.angles, inv.velocities, inv.accelerations)),
                            inv.torque])
    return record, header, rows


RESIDUAL_FIELDS = ("residual_force_rms_n", "residual_moment_rms_nm", "residual_fx_rms_n", "residual_fy_rms_n",
                   "residual_fx_mean_n", "residual_fy_mean_n", "residual_mz_mean_nm")


def residual_fields(model, forces: np.ndarray) -> dict:
    """The residuals of a model with a floating base (a free joint on ground): the generalised
    forces on its three coordinates, as OpenSim's RRA and CMC name them FX, FY (N, ground axes, at
    the base's joint point) and MZ (N m), from the forces (n, J) on the samples reached. The fourth
    indicator is their RMS, the force's magnitude and the moment apart (units never pooled); the
    means are set beside RRA's averages. {} for a model without a floating base."""
    base = model.floating_base
    if base is None:
        return {}
    c = model.coordinates.index(base.coordinate_names[0])
    mz, fx, fy = (forces[:, c + i] for i in range(3))
    if not len(mz):
        return dict.fromkeys(RESIDUAL_FIELDS, math.nan)
    rms = lambda v: float(np.sqrt(np.mean(v**2)))  # noqa: E731
    return {"residual_force_rms_n": float(np.sqrt(np.mean(fx**2 + fy**2))), "residual_moment_rms_nm": rms(mz),
            "residual_fx_rms_n": rms(fx), "residual_fy_rms_n": rms(fy), "residual_fx_mean_n": float(np.mean(fx)),
            "residual_fy_mean_n": float(np.mean(fy)), "residual_mz_mean_nm": float(np.mean(mz))}


def _message(result) -> str:
    text = result.status.value
    if not result.success:
        text += f" (stopped at t = {result.t_end:.4g} s)"
    return text + (f": {result.detail}" if result.detail else "")


DRIFT_DEG = 10.0  # an angle this far from its motion: the torques, not --alpha or --dt, made the run fail


def _drift_hint(message: str, result, desired, kinds) -> str:
    """A constraint failure's message, its hint on --alpha and --dt replaced when an angle had
    drifted more than DRIFT_DEG from its desired value (rad, shape (n, J)) by then: the penalty
    then fails because the torques whirl the bodies far off the motion (an unstable open loop, or
    a torque history made for another model or motion), which a larger --alpha does not cure."""
    from ..records import ALPHA_HINT

    angle = np.array([kind == "angle" for kind in kinds])
    reached = result.reached
    if not angle.any() or not reached.any():
        return message
    drift = float(np.degrees(np.max(np.abs(result.angles[reached][:, angle] - desired[reached][:, angle]))))
    if not drift > DRIFT_DEG:
        return message
    return message.replace(ALPHA_HINT, f"; by then an angle was {drift:.3g} deg off the desired motion: the torques "
                                       "drive the model far from it (an unstable open loop, or a torque history made "
                                       "for another model or motion?), which --alpha and --dt do not change")


def _outcome(spec, record: dict, result, inverse, **more):
    """The RunOutcome of a finished simulation: indicators over every joint and per joint (angles
    and translations apart), the trajectory table."""
    from ..experiment import RunOutcome

    names, kinds = joints(spec), nominal(spec).coordinate_kinds
    desired = inverse.angles
    rot, trans, per_coordinate = sim.rmse_coordinates(result, desired, kinds)
    trq, force, per_force = sim.rmse_generalized_forces(result, inverse.torque, kinds)
    record.update(rmse_rot_deg=rot, rmse_torque_nm=trq, t_end=result.t_end, status=result.status.code,
                  message=_message(result), max_violation=result.max_violation,
                  **_per_coordinate(("rmse_rot_deg", "rmse_trans_cm"), names, kinds, per_coordinate),
                  **_per_coordinate(("rmse_torque_nm", "rmse_force_n"), names, kinds, per_force))
    if "translation" in kinds:
        record.update(rmse_trans_cm=trans, rmse_force_n=force)
    record.update(residual_fields(nominal(spec), result.torque[result.reached]))
    if result.status is sim.Status.CONSTRAINT:
        record["message"] = _drift_hint(record["message"], result, desired, kinds)
    header = ["t"] + [f"{j}{s}" for s in ("", "_desired", "_vel", "_vel_desired", "_acc", "_acc_desired", "_torque",
                                          "_torque_inverse") for j in names]
    values = (result.angles, desired, result.zd, inverse.velocities, _accelerations(spec, result), inverse.accelerations)
    rows = np.column_stack([result.t, *(_in_file_units(v, kinds) for v in values), result.torque, inverse.torque])
    return RunOutcome(record, result, inverse, table=(header, rows), **more)


def _per_coordinate(prefixes: tuple[str, str], names, kinds, values) -> dict:
    """Per-coordinate record fields ``<prefix>_<coordinate>``: the first prefix for angles, the
    second for translations; none for a model of one coordinate (the overall value says it)."""
    fields = per_joint(prefixes[0], names, values)
    return {(key.replace(prefixes[0], prefixes[1], 1) if kind == "translation" else key): value
            for (key, value), kind in zip(fields.items(), kinds)}


def _in_file_units(values: np.ndarray, kinds) -> np.ndarray:
    """Coordinates or their rates (rad or m based, shape (n, J)) in a motion file's units: angles
    in deg, translations as they are (m, m/s, m/s^2)."""
    if "translation" not in kinds:
        return np.degrees(values)
    return np.where([kind == "translation" for kind in kinds], values, np.degrees(values))


def _accelerations(spec, result) -> np.ndarray:
    """The joint accelerations (rad/s^2, shape (n, J)) of a simulation's states under its applied
    torques (NaN after t_end), so that its trajectory reads back as a motion with its own rates."""
    plant = engine(spec)
    zero = np.zeros_like(result.torque)
    with np.errstate(invalid="ignore"):
        rates, _ = plant.rates(result.states, result.torque, zero, zero, zero, 0.0, 0.0, t=result.t)
    return plant.joints_from_state(rates)[1]


def _warm_up(spec) -> None:
    """Load (or compile) the engine's kernels (and scipy's integrators for an adaptive one), so that
    runtimes exclude it."""
    sim.warm_up(spec.integrator != "rk4", engine=engine(spec))


# ---------------------------------------------------------------------- control
def controller(spec):
    """The spec's registered controller (``fdbench.controllers``) with its options; the paper's PD
    takes the spec's gains (None: scaled per joint)."""
    from ..controllers import make_controller

    name = spec.controller or "pd"
    options = {"kp": spec.kp, "kd": spec.kd} if name == "pd" else dict(spec.method_options)
    return make_controller(name, **options)


def pd_gains(spec) -> tuple[np.ndarray, np.ndarray]:
    """Kp (N m/rad) and Kd (N m s/rad) per joint, shape (J,), of the spec's PD (``controllers.pd.PD``)."""
    from ..controllers.pd import PD

    return PD(spec.kp, spec.kd).gains(plan(spec))


def plan(spec):
    """What a controller designs from: the nominal model's engine and description, the desired motion."""
    from ..controllers.base import Plan

    return Plan(engine(spec, nominal(spec)), nominal(spec), motions(spec)[0])


def run(spec, on_evaluation=None, on_start=None):
    """Carry out a control, optimisation or collocation run (``RunOutcome``)."""
    from ..experiment import base_record
    from ..method_options import options_text

    if spec.command == "optimize":
        return _optimize(spec, on_evaluation, on_start)
    if spec.command == "collocate":
        return _collocate(spec)
    if spec.command != "control":
        raise ValueError(f"{spec.command}: not available with --model {spec.model_name}")
    _warm_up(spec)
    law, known = controller(spec), plan(spec)
    law.warm_up(known)
    began = time.perf_counter()
    inverse = reference(spec)
    design = law.design(known)
    result = _simulate(spec, design.feedforward, kp=design.kp, kd=design.kd, gains=design.gains,
                       computed=design.computed, nominal=known.engine if design.computed else None)
    runtime = time.perf_counter() - began
    record = base_record(spec)
    name = spec.controller or "pd"  # the name it is registered under
    record.update(torque=design.label, evaluations=1, runtime_s=runtime, controller=name, **design.fields)
    if name != "pd":
        record["controller_options"] = options_text(spec.method_options)
    return _outcome(spec, record, result, inverse)


# ---------------------------------------------------------------------- open loop
def run_simulation(spec, torque_file=None, params_file=None, torque=None):
    """Open-loop forward dynamics driven by the inverse-dynamics torques, a CSV torque history
    (``t,<joint>...``), saved parameters, or ``torque``, a function t (s), shape (k,) -> joint
    torques (N m), shape (k, J); BadFile for a file that cannot be used."""
    from dataclasses import replace

    from ..experiment import base_record

    names = joints(spec)
    desired, _ = motions(spec)
    label, drive = "id", sim.feedforward(engine(spec, nominal(spec)), desired)
    if params_file is not None:
        drive, label, digest, spec = _saved_torque(spec, params_file)
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--params", digest),))))
    elif torque is not None:
        drive, label = torque, getattr(torque, "__name__", "function")
    elif torque_file is not None:
        preferred = (tuple(f"{joint}_torque" for joint in names),) + ((("torque",),) if len(names) == 1 else ())
        t, values = read_history_csv(torque_file, "--torque-file", desired.duration, names, preferred)
        drive = lambda s: np.stack([np.interp(s, t, values[:, j]) for j in range(len(names))], axis=-1)  # noqa: E731
        label = f"file:{torque_file}"
        digest = hashlib.sha256(t.tobytes() + values.tobytes()).hexdigest()
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--torque-file", digest),))))
    _warm_up(spec)
    began = time.perf_counter()
    inverse = reference(spec)
    result = _simulate(spec, drive)
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque=label, evaluations=1, runtime_s=runtime)
    outcome = _outcome(spec, record, result, inverse)
    outcome.extra["spec"] = spec  # the spec run: its inputs name the torque file or parameters by content
    return outcome


def _problem(spec, torque: str, feedforward: bool, penalty_weight: float = 1.0, **options):
    from ..problem import TrackingProblem

    return TrackingProblem(torque, engine(spec), motions(spec)[0], feedforward, penalty_weight,
                           nominal=engine(spec, nominal(spec)), residual_weight=residual_weight(spec),
                           **integration(spec), **options)


def residual_weight(spec) -> float:
    """The weight of an optimisation's residual term in eq. 18 (``problem.residual_weight``)."""
    from ..problem import residual_weight as weight

    return weight(spec.residual_weight, engine(spec).model, loads(spec))


def _saved_torque(spec, path):
    """(torque function, label, digest, spec) of a parameter file saved by ``optimize --save-params``;
    the spec follows the file's named motion. BadFile if it cannot be used."""
    from dataclasses import replace

    from ..models import named_motions
    from ..params_file import make_saved_torque, read_params

    saved = read_params(path, spec.model_name, motions(spec)[1].name, named_motions(spec.model_name))
    if saved["kinematics"] is not None and saved["kinematics"] != spec.kinematics:
        spec = replace(spec, kinematics=saved["kinematics"], inputs=tuple(p for p in spec.inputs if p[0] != "--motion"))
    expected = make_saved_torque(saved).n_params * len(joints(spec))
    if saved["params"].shape != (expected,):
        raise BadFile(f"--params: {path}: expected {expected} parameters for {saved['torque']} on "
                      f"{len(joints(spec))} joints")
    problem = _problem(spec, saved["torque"], saved["feedforward"], **saved["options"])
    name = saved["torque"] + (" (feedforward)" if saved["feedforward"] else "")
    return problem.torque_function(saved["params"]), f"{name} from {saved['path'].name}", saved["digest"], spec


def replay(spec, params) -> sim.Simulation:
    """The simulation of a stored optimisation run's best parameters (for figures)."""
    options = dict(spec.torque_options)
    if options.get("hidden") == "auto":  # 3 n + 1 parameters per joint
        options["hidden"] = (len(params) // len(joints(spec)) - 1) // 3
    problem = _problem(spec, spec.torque, spec.feedforward, spec.penalty_weight, **options)
    return problem.simulate(np.asarray(params, dtype=float))


# ---------------------------------------------------------------------- optimisation and collocation
def _optimize(spec, on_evaluation, on_start):
    """Shooting optimisation of per-joint torque parameters (``fdbench.problem.TrackingProblem``)."""
    from ..experiment import base_record
    from ..method_options import options_text
    from ..optimizers import make_optimizer
    from ..optimizers.base import NO_ITERATION
    from ..torques import TORQUES

    optimizer = make_optimizer(spec.optimizer, **dict(spec.optimizer_options))
    _warm_up(spec)  # the population kernel and its threads too
    if spec.gradient == "exact":
        from .sensitivity import warm_up

        warm_up()
    optimizer.warm_up()
    TORQUES[spec.torque].warm_up()
    if on_start:
        on_start(spec.budget)
    desired, _ = motions(spec)
    began = time.perf_counter()
    options, extra = dict(spec.torque_options), {}
    if options.get("hidden") == "auto":  # the count that fits every joint's inverse-dynamics torque
        from ..torques.ann import select_hidden

        inv = sim.inverse_dynamics(None, engine(spec, nominal(spec)), desired)
        fits = [select_hidden(inv.t, inv.torque[:, j]) for j in range(inv.torque.shape[1])]
        options["hidden"] = max(n for n, _ in fits)
        extra["hidden_fits"] = [(n, max(dict(tried).get(n, math.inf) for _, tried in fits))
                                for n in range(1, options["hidden"] + 1)]
    problem = _problem(spec, spec.torque, spec.feedforward, spec.penalty_weight, **options)
    batch = problem.objectives_scaled if problem.batched else None
    gradient = problem.value_and_gradient_scaled if spec.gradient == "exact" else None
    found = optimizer.minimize(problem.objective_scaled, problem.x0, spec.budget, spec.seed, on_evaluation, gradient,
                               batch)
    params = np.asarray(found.x) * problem.scale
    result = problem.simulate(params)
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque=spec.torque, optimizer=spec.optimizer, seed=spec.seed, budget=spec.budget,
                  evaluations=found.evaluations, best_objective=found.fun, stop_reason=found.stop_reason,
                  n_params=problem.n_params, runtime_s=runtime, penalty_weight=spec.penalty_weight,
                  **({"residual_weight": problem.residual_weight} if problem.base_column is not None else {}),
                  torque_options=options_text(sorted(options.items())),
                  optimizer_options=options_text(spec.optimizer_options), gradient=spec.gradient,
                  initial_objective=problem.objective(problem.p0))
    outcome = _outcome(spec, record, result, reference(spec), history=list(found.history), params=params, extra=extra)
    if found.stop_reason.startswith(NO_ITERATION):  # "success" of a run that hardly moved: say why
        outcome.record["message"] += f"; {spec.optimizer} completed no iteration within the budget (see stop_reason)"
    return outcome


def _collocate(spec):
    """Direct collocation of the nominal model on the desired motion under the spec's external loads
    (``collocation``), then its torque replayed by the plant's forward simulation: the indicators are
    the replay's; the collocation's own RMSE at its nodes (against the true motion), IPOPT's status,
    iterations and solve time stand beside them. ``extra['collocation']`` holds the solution (node
    arrays of shape (N + 1, J))."""
    from ..collocation import collocate, own_fields, record_fields
    from ..experiment import base_record

    options = dict(spec.method_options)
    _warm_up(spec)
    from ..casadi_loader import casadi

    casadi()  # its import is not part of the runtime

    desired, truth = motions(spec)
    began = time.perf_counter()
    inverse = reference(spec)
    solution = collocate(nominal(spec), desired, **options, loads=loads(spec))
    result = _simulate(spec, solution.torque_function())
    runtime = time.perf_counter() - began
    record = base_record(spec)
    outcome = _outcome(spec, record, result, inverse, extra={"collocation": solution})
    own = own_fields(nominal(spec), solution, truth)
    record.update(runtime_s=runtime, **record_fields(solution, options, own, record["message"]))
    return outcome
