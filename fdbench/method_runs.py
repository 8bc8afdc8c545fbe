"""The runs of a ``RunSpec`` on the multibody engine, one per command: inverse dynamics
(``inverse_run``), open-loop simulation (``run_simulation``, ``replay``), control (the paper's PD
per joint with computed feedforward, computed torque, LQR or a registered controller), shooting
optimisation and direct collocation (``run``), each giving a flat record and a trajectory table.
What a spec stands for on the engine is ``fdbench.run_inputs``.
"""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import replace

import numpy as np

from . import __version__
from .casadi_loader import casadi
from .collocation import collocate, collocate_muscles, own_fields, record_fields
from .multibody.model_changes import rigid_tendons
from .controllers.base import failing_on_options, muscle_columns
from .excitation_problem import DEFAULT_EFFORT_WEIGHT, ExcitationProblem
from .excitation_problem import warm_up as warm_up_excitations
from .files import BadFile, read_history_csv, read_input_text
from .method_options import options_text
from .models import named_motions
from .multibody import simulation as sim
from .multibody.sensitivity import warm_up as warm_up_sensitivities
from .multibody.static_optimization import static_optimization, unmet_notes
from .optimizers import make_optimizer
from .optimizers.base import NO_ITERATION
from .outcomes import in_file_units, outcome, residual_fields
from .params_file import make_saved_torque, read_params
from .problem import TrackingProblem, tracking_setup
from .problem import residual_weight as problem_residual_weight
from .peers import run as run_peer
from .peers.common import muscle_replay, rigid_plant, simulate_muscles
from .records import RunOutcome, base_record, explained
from .registry import unknown_name_message
from .run_inputs import (controller, describe, engine, integration, joints, loads, motions, nominal, plan,
                         reference, warm_up)
from .torques import TORQUES
from .torques.ann import select_hidden


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
    start_end = in_file_units(inv.angles[[0, -1]], kinds)

    def force(metric: str, j: int) -> str:  # a translation's in N, never pooled with N m
        return metric.replace("torque", "force").replace("_nm", "_n") if kinds[j] == "translation" else metric

    unit = ["m" if kind == "translation" else "deg" for kind in kinds]
    record = {"command": "inverse", "kinematics": spec.motion, **describe(spec),
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
    rows = np.column_stack([inv.t, *(in_file_units(v, kinds) for v in (inv.angles, inv.velocities, inv.accelerations)),
                            inv.torque])
    return record, header, rows


RESERVE_NEEDED = 0.05  # a reserve is needed where its peak exceeds this share of its joint's peak torque


def muscles_run(spec, exponent: float = 2.0, reserve_optimal_force: float | None = None,
                passive: bool = False, along_tendon: bool = True) -> tuple[dict, list[str], np.ndarray]:
    """Static optimisation of the nominal model's muscles on the desired motion's inverse dynamics
    (``fdbench.multibody.static_optimization``): (record, CSV header, rows), the columns t (s),
    <muscle>_activation, <muscle>_force (N) and per coordinate <joint>_reserve (N m; N for a
    translation), or <joint>_unmet on a coordinate without a reserve (the model has actuators, none
    on it): the torque the muscles leave unmet. The reserves: the model's actuators (each its optimal
    force, or ``reserve_optimal_force`` for all), else one per coordinate of ``reserve_optimal_force``
    (default 1). ValueError for a model without muscles or a bad exponent or optimal force."""
    model = nominal(spec)
    if not model.muscles:
        raise ValueError(f"--muscles: model {spec.model_name} has no muscles (no [[muscles]] tables)")
    desired, _ = motions(spec)
    body = engine(spec, model)
    inv = sim.inverse_dynamics(None, body, desired)
    given = options_text((name, value) for name, value in (("activation_exponent", exponent),
                                                           ("reserve_optimal_force", reserve_optimal_force))
                         if value is not None)
    with failing_on_options("--muscles (static optimisation)", given):
        so = static_optimization(model, body.muscle_params, inv.t, inv.angles, inv.velocities, inv.torque, exponent,
                                 reserve_optimal_force, passive, along_tendon=along_tendon)
    reserved = so.optimal_force > 0
    peak_torque = np.abs(so.torque).max(axis=0)
    peak_reserve = np.abs(so.reserve).max(axis=0)
    needed = [j for j, r, q, has in zip(so.joints, peak_reserve, peak_torque, reserved) if has and r > RESERVE_NEEDED * q]
    forces = sorted(set(so.optimal_force[reserved].tolist()))
    record = {"command": "inverse --muscles", "kinematics": spec.motion, **describe(spec),
              "activation_exponent": exponent,
              "reserve_optimal_force": forces[0] if len(forces) == 1 else "per actuator (see reserves)",
              "passive_forces": passive, "force_along_tendon": along_tendon,
              **{f"{m}_activation_{k}": float(v) for i, m in enumerate(so.muscles)
                 for k, v in (("rms", np.sqrt(np.mean(so.activation[:, i] ** 2))),
                              ("peak", so.activation[:, i].max()))},
              **{f"{j}_{'reserve' if reserved[i] else 'unmet'}_{k}_nm": float(v) for i, j in enumerate(so.joints)
                 for v, k in zip(_rms_and_peak(so.reserve[:, i] if reserved[i] else so.unmet[:, i]), ("rms", "peak"))},
              "reserves_needed": ", ".join(needed) if needed else "none"}
    if model.actuators:
        record["reserves"] = ", ".join(f"{j} ({f:g})" for j, f, has in zip(so.joints, so.optimal_force, reserved)
                                       if has) or "none"
    if not reserved.all():
        kinds = model.coordinate_kinds
        unmet = unmet_notes(so, tuple("N" if kind == "translation" else "N m" for kind in kinds))
        record["unmet"] = "; ".join(unmet) if unmet else "none"
    record.update(runtime_s=so.runtime_s, runtime_per_sample_ms=1e3 * so.runtime_s / len(so.t),
                  fdbench_version=__version__)
    header = ["t", *(f"{m}_{k}" for m in so.muscles for k in ("activation", "force")),
              *(f"{j}_{'reserve' if has else 'unmet'}" for j, has in zip(so.joints, reserved))]
    rows = np.column_stack([so.t, *(c for i in range(len(so.muscles))
                                    for c in (so.activation[:, i], so.force[:, i])),
                            np.where(reserved, so.reserve, so.unmet)])
    return record, header, rows


def _rms_and_peak(values: np.ndarray) -> tuple[float, float]:
    return float(np.sqrt(np.mean(values**2))), float(np.abs(values).max())


def _method_run(spec, on_evaluation=None, on_start=None):
    """Carry out a control, optimisation or collocation run (``RunOutcome``)."""
    if spec.command == "optimize":
        return _optimize(spec, on_evaluation, on_start)
    if spec.command == "collocate":
        return _collocate(spec)
    if spec.command != "control":
        raise ValueError(f"{spec.command}: not available with --model {spec.model_name}")
    warm_up(spec)
    law, known = controller(spec), plan(spec)
    law.warm_up(known)
    body, desired, inverse, grid = _set_up(spec)
    if hasattr(law, "run"):  # a controller that simulates the plant itself (cmc, window by window)
        return _self_simulated(spec, law, known, body, desired, inverse, grid)
    if grid is not None:  # the plan's feedforward (eq. 3) on the half-step grid, kept by it
        known.feedforward()(grid.t)
    start = sim.start_state(body, desired)
    began = time.perf_counter()
    with failing_on_options(f"--controller {spec.controller or 'pd'}", options_text(spec.method_options)):
        design = law.design(known)
    result = sim.simulate(design.feedforward, body, desired, kp=design.kp, kd=design.kd, gains=design.gains,
                          computed=design.computed, nominal=known.engine if design.computed else None, grid=grid,
                          start=start, **integration(spec))
    runtime = time.perf_counter() - began
    record = base_record(spec)
    name = spec.controller or "pd"  # the name it is registered under
    record.update(torque=design.label, evaluations=1, runtime_s=runtime, controller=name, **design.fields)
    if name != "pd":
        record["controller_options"] = options_text(spec.method_options)
    done = outcome(spec, record, result, inverse)
    if body.n_muscles:
        done.record["message"] += (f"; torque-driven: the model's {body.n_muscles} muscles left out "
                                   "(--controller cmc drives them)")
    return done


def _self_simulated(spec, law, known, body, desired, inverse, grid):
    """A control run by a controller that simulates the plant itself (``law.run``: computed muscle
    control), its fields and trajectory columns (each muscle's activation, excitation, force) added."""
    if spec.integrator != "rk4":
        raise ValueError(f"--controller {spec.controller}: muscles run on the compiled RK4 only, not "
                         f"--integrator {spec.integrator}")
    began = time.perf_counter()
    with failing_on_options(f"--controller {spec.controller}", options_text(spec.method_options)):
        result, fields, (columns, values) = law.run(known, body, desired, grid, spec.dt)
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque="reserves+muscles", evaluations=1, runtime_s=runtime, controller=spec.controller,
                  controller_options=options_text(spec.method_options), **fields)
    done = outcome(spec, record, result, inverse)
    header, rows = done.table
    done.table = (header + columns, np.column_stack([rows, values]))
    return done


def _set_up(spec):
    """What a run prepares before its clock starts, as the C loop precomputes its references and
    feedforward: the plant's engine, the desired motion, the indicators' reference (eq. 3 on the
    true motion's samples, ``run_inputs.reference``; measured after the run, not part of it) and,
    with RK4, the desired motion on the half-step grid (``simulation.HalfSteps``; else None). The
    start state (``simulation.start_state``) is prepared beside it by the caller."""
    desired = motions(spec)[0]
    grid = sim.half_steps(desired, spec.dt) if spec.integrator == "rk4" else None
    return engine(spec), desired, reference(spec), grid


# ---------------------------------------------------------------------- open loop
def run_simulation(spec, torque_file=None, params_file=None, torque=None, excitation_file=None,
                   warn=None) -> RunOutcome:
    """Open-loop forward dynamics driven by the inverse-dynamics torques, a CSV torque history (``t``
    and a column per joint or ``<joint>_torque``, N m), saved optimisation parameters or ``torque``
    (t (s), (k,) -> N m, (k, J)); with ``excitation_file`` (``t,<muscle>...``, in [0, 1]) the muscles
    excited and the torques those given or zero. Bad files raise ``files.BadFile``. ``warn`` (a
    function of a text) hears, before the run, of a step too long for a compliant tendon."""
    names = joints(spec)
    desired, _ = motions(spec)
    label, drive = "id", sim.feedforward(engine(spec, nominal(spec)), desired)
    excitation = None
    if excitation_file is not None:
        excitation, digest = _excitation_history(spec, excitation_file, desired.duration)
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--excitation-file", digest),))))
        label, drive = "zero", None
    if params_file is not None:
        drive, label, digest, spec = _saved_torque(spec, params_file)
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--params", digest),))))
    elif torque is not None:
        drive, label = torque, getattr(torque, "__name__", "function")
    elif torque_file is not None and excitation is not None and engine(spec).model.actuators:
        drive, digest = _actuator_torques(spec, torque_file, desired.duration)
        label = f"file:{torque_file}"
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--torque-file", digest),))))
    elif torque_file is not None:
        preferred = (tuple(f"{joint}_torque" for joint in names),) + ((("torque",),) if len(names) == 1 else ())
        t, values = read_history_csv(torque_file, "--torque-file", desired.duration, names, preferred)
        drive = lambda s: np.stack([np.interp(s, t, values[:, j]) for j in range(len(names))], axis=-1)  # noqa: E731
        label = f"file:{torque_file}"
        digest = hashlib.sha256(t.tobytes() + values.tobytes()).hexdigest()
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--torque-file", digest),))))
    warm_up(spec)
    body, desired, inverse, grid = _set_up(spec)
    if excitation is not None and warn is not None:
        _check_tendon_step(body, desired, excitation, spec.dt, warn)
    if grid is not None:
        drive = sim.on_half_steps(drive, grid, body.n_joints)
    start = sim.start_state(body, desired)
    began = time.perf_counter()
    result = sim.simulate(drive, body, desired, grid=grid, start=start, **integration(spec),
                          **({} if excitation is None else {"excitation": excitation}))
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque=label, evaluations=1, runtime_s=runtime)
    done = outcome(spec, record, result, inverse)
    compliant = [m.name for m in body.model.muscles if m.tendon == "compliant"]
    if excitation is not None and compliant and done.record.get("status") == "nonfinite":
        done.record["message"] = (f"{done.record.get('message', '')}; compliant tendons near slack are stiff "
                                  f"({', '.join(compliant[:3])}{', ...' if len(compliant) > 3 else ''}): try a "
                                  f"smaller --dt than {spec.dt:g} s")
    if excitation is not None:  # each muscle's activation, excitation and force (N) beside the joints
        _with_muscle_columns(done, spec)
    done.extra["spec"] = spec  # the spec run: its inputs name the torque file or parameters by content
    return explained(done, spec)


def _with_muscle_columns(done: RunOutcome, spec) -> None:
    """The run's trajectory with each muscle's activation, excitation and force (N) after the joints'."""
    header, rows = done.table
    columns, values = muscle_columns(done.result, [m.name for m in engine(spec).model.muscles])
    done.table = (header + columns, np.column_stack([rows, values]))


def _check_tendon_step(body, desired, excitation, dt: float, warn) -> None:
    """``warn`` where ``dt`` (s) exceeds RK4's stable step on a compliant tendon at the start."""
    z, zd, _ = desired(np.zeros(1))
    limits = sim.compliant_step_limits(body, z[0], zd[0], excitation(np.zeros(1))[0])
    if limits:
        name, limit = min(limits, key=lambda pair: pair[1])
        if dt > limit:
            warn(f"compliant tendons near slack are stiff: at the start {name}'s tendon needs --dt below "
                 f"{limit:.2g} s for RK4 to be stable, and --dt is {dt:g} s; the run will likely fail: try "
                 f"--dt {limit / 5:.1g}")


def _excitation_history(spec, path, duration: float):
    """The muscles' excitations of an ``--excitation-file`` (``t`` (s) and one column per muscle of
    the model, names ignoring case, each in [0, 1], covering [0, duration] s) as a function of times
    (linear between samples, OpenSim's PiecewiseLinearFunction) and the file's digest. BadFile for
    a model without muscles, a column that names no muscle, a missing muscle or a value outside [0, 1]."""
    option = "--excitation-file"
    muscles = [m.name for m in engine(spec).model.muscles]
    if not muscles:
        raise BadFile(f"{option}: the model {spec.model_name!r} has no muscles ([[muscles]] in its file) to excite")
    if spec.integrator != "rk4":
        raise BadFile(f"{option}: muscles run on the compiled RK4 only, not --integrator {spec.integrator}")
    header = next((line for line in read_input_text(path, option).splitlines() if line.strip()), "")
    known = {name.lower(): name for name in muscles}
    for column in (cell.strip() for cell in header.split(",")):
        if column.lower() != "t" and column.lower() not in known:
            raise BadFile(f"{option}: {path}: column {column!r}: {unknown_name_message('muscle', column, muscles)}")
    t, values = read_history_csv(path, option, duration, tuple(known))
    outside = np.argwhere((values < 0.0) | (values > 1.0))
    if len(outside):
        row, m = outside[0]
        raise BadFile(f"{option}: {path}: {muscles[m]} at t = {t[row]:g} s is {values[row, m]:g}; an excitation "
                      "lies in [0, 1]")
    digest = hashlib.sha256(t.tobytes() + values.tobytes()).hexdigest()
    return (lambda s: np.stack([np.interp(s, t, values[:, m]) for m in range(len(muscles))], axis=-1)), digest


def _actuator_torques(spec, path, duration: float):
    """The torques (N m; N for a translation) of a ``--torque-file`` beside muscles on a model with
    ``[[actuators]]``: ``t`` (s) and a column per actuated coordinate (``<coordinate>`` or
    ``<coordinate>_torque``, ignoring case; the actuator's torque, not its control), a missing one
    held at zero, the unactuated coordinates at zero; as a function of times (linear between
    samples) -> (k, J), and the file's digest. BadFile for a column of an unactuated coordinate or
    of no coordinate."""
    option = "--torque-file"
    model = engine(spec).model
    coordinates = list(model.coordinates)
    actuated = [a.coordinate for a in model.actuators]
    columns = {name.lower(): c for c in actuated for name in (c, f"{c}_torque")}
    header = next((line for line in read_input_text(path, option).splitlines() if line.strip()), "")
    present = {}
    for column in (cell.strip() for cell in header.split(",")):
        name = column.lower()
        if name == "t":
            continue
        if name not in columns:
            bare = name.removesuffix("_torque")
            lowered = {c.lower(): c for c in coordinates}
            if bare in lowered:
                raise BadFile(f"{option}: {path}: column {column!r}: coordinate {lowered[bare]!r} has no torque "
                              f"actuator ([[actuators]] of the model); actuated: {', '.join(actuated)}")
            raise BadFile(f"{option}: {path}: column {column!r}: "
                          + unknown_name_message("actuated coordinate", column, actuated))
        if columns[name] in present.values():
            raise BadFile(f"{option}: {path}: two columns give {columns[name]!r}'s torque; keep one")
        present[name] = columns[name]
    if not present:
        raise BadFile(f"{option}: {path} has no column of an actuated coordinate; give t and some of "
                      f"{', '.join(actuated)} (N m)")
    t, values = read_history_csv(path, option, duration, tuple(present))
    where = [coordinates.index(c) for c in present.values()]
    digest = hashlib.sha256(t.tobytes() + values.tobytes() + repr(where).encode()).hexdigest()

    def torque(s):
        s = np.asarray(s, dtype=float)
        out = np.zeros(s.shape + (len(coordinates),))
        for k, j in enumerate(where):
            out[..., j] = np.interp(s, t, values[:, k])
        return out
    return torque, digest


def _problem(spec, torque: str, feedforward: bool, penalty_weight: float = 1.0, **options):
    return TrackingProblem(torque, engine(spec), motions(spec)[0], feedforward, penalty_weight,
                           nominal=engine(spec, nominal(spec)), residual_weight=residual_weight(spec),
                           **integration(spec), **options)


def residual_weight(spec) -> float:
    """The weight of an optimisation's residual term in eq. 18 (``problem.residual_weight``)."""
    return problem_residual_weight(spec.residual_weight, engine(spec).model, loads(spec))


def _saved_torque(spec, path):
    """(torque function, label, digest, spec) of a parameter file saved by ``optimize --save-params``;
    the spec follows the file's named motion. BadFile if it cannot be used."""
    saved = read_params(path, spec.model_name, motions(spec)[1].name, named_motions(spec.model_name))
    if saved["kinematics"] is not None and saved["kinematics"] != spec.motion:
        spec = replace(spec, motion=saved["kinematics"], inputs=tuple(p for p in spec.inputs if p[0] != "--motion"))
    expected = make_saved_torque(saved).n_params * len(joints(spec))
    if saved["params"].shape != (expected,):
        raise BadFile(f"--params: {path}: expected {expected} parameters for {saved['torque']} on "
                      f"{len(joints(spec))} joints")
    problem = _problem(spec, saved["torque"], saved["feedforward"], **saved["options"])
    name = saved["torque"] + (" (feedforward)" if saved["feedforward"] else "")
    return problem.torque_function(saved["params"]), f"{name} from {saved['path'].name}", saved["digest"], spec


def _excitation_problem(spec, **options) -> ExcitationProblem:
    """The shooting problem on the plant's muscles' excitations of an ``--actuation muscles`` spec
    (static optimisation of its start on the plant too)."""
    effort = DEFAULT_EFFORT_WEIGHT if spec.effort_weight is None else spec.effort_weight
    return ExcitationProblem(spec.torque, engine(spec), motions(spec)[0], spec.penalty_weight, effort, spec.dt,
                             spec.feedforward, **options)


def replay(spec, params) -> sim.Simulation:
    """The simulation of a stored optimisation run's best parameters (for figures)."""
    if spec.actuation == "muscles":
        return _excitation_problem(spec, **dict(spec.torque_options)).simulation(np.asarray(params, dtype=float))
    options = dict(spec.torque_options)
    if options.get("hidden") == "auto":  # 3 n + 1 parameters per joint
        options["hidden"] = (len(params) // len(joints(spec)) - 1) // 3
    problem = _problem(spec, spec.torque, spec.feedforward, spec.penalty_weight, **options)
    return problem.simulate(np.asarray(params, dtype=float))


# ---------------------------------------------------------------------- optimisation and collocation
def _optimize(spec, on_evaluation, on_start):
    """Shooting optimisation of per-joint torque parameters (``fdbench.problem.TrackingProblem``) or,
    with ``--actuation muscles``, of per-muscle excitation parameters (``ExcitationProblem``)."""
    muscles = spec.actuation == "muscles"
    optimizer = make_optimizer(spec.optimizer, **dict(spec.optimizer_options))
    warm_up(spec, population=not muscles)  # the population kernel and its threads too
    if muscles:  # the muscles' population and sensitivity kernels on this model
        warm_up_excitations(engine(spec), spec.gradient == "exact")
    elif spec.gradient == "exact":
        warm_up_sensitivities()
    optimizer.warm_up()
    TORQUES[spec.torque].warm_up()
    # eq. 3 and the references on the half-step grid, before the clock as the C loop's
    setup = None if muscles else tracking_setup(engine(spec, nominal(spec)), motions(spec)[0], spec.dt,
                                                spec.feedforward)
    if on_start:
        on_start(spec.budget)
    began = time.perf_counter()
    options, extra = dict(spec.torque_options), {}
    if options.get("hidden") == "auto":  # the count that fits every joint's inverse-dynamics torque
        inv = setup.inverse
        fits = [select_hidden(inv.t, inv.torque[:, j]) for j in range(inv.torque.shape[1])]
        options["hidden"] = max(n for n, _ in fits)
        extra["hidden_fits"] = [(n, max(dict(tried).get(n, math.inf) for _, tried in fits))
                                for n in range(1, options["hidden"] + 1)]
    if muscles:
        problem = _excitation_problem(spec, **options)
    else:
        problem = _problem(spec, spec.torque, spec.feedforward, spec.penalty_weight, setup=setup, **options)
    batch = problem.objectives_scaled if problem.batched else None
    gradient = problem.value_and_gradient_scaled if spec.gradient == "exact" else None
    found = optimizer.minimize(problem.objective_scaled, problem.x0, spec.budget, spec.seed, on_evaluation, gradient,
                               batch)
    params = np.asarray(found.x) * problem.scale
    result = problem.simulation(params) if muscles else problem.simulate(params)
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque=spec.torque, optimizer=spec.optimizer, seed=spec.seed, budget=spec.budget,
                  evaluations=found.evaluations, best_objective=found.fun, stop_reason=found.stop_reason,
                  n_params=problem.n_params, runtime_s=runtime, penalty_weight=spec.penalty_weight,
                  **({"residual_weight": problem.residual_weight}
                     if getattr(problem, "base_column", None) is not None else {}),
                  torque_options=options_text(sorted(options.items())),
                  optimizer_options=options_text(spec.optimizer_options), gradient=spec.gradient,
                  initial_objective=problem.objective(problem.p0))
    if muscles:  # no reserves: the muscles alone drive the joints
        record.update(actuation="muscles", effort_weight=problem.effort_weight, reserve_rms_nm=0.0)
    done = outcome(spec, record, result, reference(spec), history=list(found.history), params=params, extra=extra)
    if muscles:
        _with_muscle_columns(done, spec)
    if found.stop_reason.startswith(NO_ITERATION):  # "success" of a run that hardly moved: say why
        done.record["message"] += f"; {spec.optimizer} completed no iteration within the budget (see stop_reason)"
    return done


def _collocate(spec):
    """Direct collocation of the nominal model, its torque replayed by the plant: the indicators are
    the replay's, the collocation's own beside them; ``extra['collocation']`` holds the solution."""
    if spec.actuation == "muscles":
        return _collocate_muscles(spec)
    options = dict(spec.method_options)
    warm_up(spec)
    casadi()  # its import is not part of the runtime

    truth = motions(spec)[1]
    body, desired, inverse, grid = _set_up(spec)
    model, external = nominal(spec), loads(spec)
    began = time.perf_counter()
    solution = collocate(model, desired, **options, loads=external)
    result = sim.simulate(solution.torque_function(), body, desired, grid=grid, **integration(spec))
    runtime = time.perf_counter() - began
    record = base_record(spec)
    done = outcome(spec, record, result, inverse, extra={"collocation": solution})
    own = own_fields(model, solution, truth)
    record.update(runtime_s=runtime, **record_fields(solution, options, own, record["message"]))
    return done


def _collocate_muscles(spec):
    """Muscle-driven direct collocation of the nominal model (``collocation.collocate_muscles``; its
    compliant tendons taken as rigid), its excitations and reserves replayed by the plant with rigid
    tendons too (``peers.common.muscle_replay``); the record has the replay's indicators and muscle
    fields (as CMC's), the collocation's own beside them. The spec's checks refuse a model without
    muscles."""
    options = {key: value for key, value in spec.method_options if key != "regularization"}
    model = nominal(spec)
    body, params = rigid_plant(spec), engine(spec, rigid_tendons(model)).muscle_params
    casadi()  # its import is not part of the runtime
    desired, truth = motions(spec)
    began = time.perf_counter()
    solution = collocate_muscles(model, desired, params, **options, loads=loads(spec))
    result = simulate_muscles(spec, body, solution)
    runtime = time.perf_counter() - began
    done = muscle_replay(spec, result, solution)
    record = done.record
    record.update(runtime_s=runtime, **record_fields(solution, options, own_fields(model, solution, truth),
                                                     record["message"]))
    return done


# ---------------------------------------------------------------------- the runs of a spec
def run(spec, on_evaluation=None, on_start=None) -> RunOutcome:
    """Carry out a control, optimisation, collocation or peer run, checked first, as a flat record
    with its explanation. ``on_evaluation(count, best)`` reports progress; ``on_start(budget)`` is
    called once compilation and imports are done."""
    spec.validate()
    if spec.command == "simulate":
        raise ValueError("simulate runs are carried out by run_simulation")
    if spec.command == "peer":  # OpenSim's, its CMC's and Moco's runs
        return explained(run_peer(spec), spec)
    return explained(_method_run(spec, on_evaluation, on_start), spec)
