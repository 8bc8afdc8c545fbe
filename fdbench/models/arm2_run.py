"""The arm's runs from a ``RunSpec`` whose ``model_name`` is 'arm2' (``fdbench.experiment`` hands
them over here): inverse dynamics, open-loop simulation, control (PD per joint with computed
feedforward, computed-torque, LQR), optimisation and direct collocation (its torque replayed by the
arm's forward simulation), each giving a flat record (the forearm's keys plus per-joint
indicators) and a trajectory.

Indicators for n joints: ``rmse_rot_deg`` is the root mean square over all joints and samples of
the angle error (deg), ``rmse_torque_nm`` likewise of the torque (N m) against the inverse-dynamics
torques; ``rmse_rot_deg_<joint>`` and ``rmse_torque_nm_<joint>`` give each joint's.

Files (CSV with a header, names case-insensitive, any order):
* a motion: ``t`` (s) and one angle column per joint, ``shoulder``, ``elbow`` (deg, or rad), with
  optional ``<joint>_vel`` and ``<joint>_acc`` (deg/s, deg/s^2); derivatives otherwise estimated
  as for a recorded forearm motion (``fdbench.motion.SampledMotion``); the columns ``inverse
  --format csv`` writes, and the angles of ``--save-trajectory``;
* a torque history: ``t`` (s) and ``shoulder``, ``elbow`` (N m), covering the motion's span,
  linearly interpolated; ``shoulder_torque``, ``elbow_torque`` where the file has them (the
  history of ``inverse --format csv`` or ``--save-trajectory``, whose ``shoulder`` is an angle).
"""

from __future__ import annotations

import hashlib
import math
import time
from functools import lru_cache
from pathlib import Path

import numpy as np

from .. import __version__
from ..files import BadFile, read_columns, read_history_csv
from ..model import Penalty
from .arm2 import JOINTS, Arm2, arm2_with
from .arm2_motion import (MOTIONS, JointMotion, PerJoint, Resampled, as_joint_motion, check_arm_angles,
                          noisy_joints)
from . import arm2_sim as sim


def read_arm_motion_csv(path, option: str = "--motion", radians: bool = False, **estimate) -> JointMotion:
    """A recorded arm motion from a CSV file (see the module's docstring). Raises BadFile."""
    from ..motion import SampledMotion, given_rates, rate_column_names

    path = Path(path)
    optional = tuple(name for joint in JOINTS for name in rate_column_names(joint))
    columns = read_columns(path, option, required=("t",) + JOINTS, optional=optional)
    unit = 1.0 if radians else math.pi / 180
    parts = []
    for joint in JOINTS:
        vel, acc = given_rates(columns, joint, path, option, radians)
        try:
            parts.append(SampledMotion(columns["t"], columns[joint] * unit, None if vel is None else vel * unit,
                                       None if acc is None else acc * unit, name=joint, absolute=False, **estimate))
        except ValueError as exc:
            raise BadFile(f"{option}: {path}: {joint}: {exc}") from None
    try:
        check_arm_angles(np.column_stack([columns[joint] * unit for joint in JOINTS]))
    except ValueError as exc:
        raise BadFile(f"{option}: {path}: {exc}") from None
    motion = PerJoint(parts, JOINTS)
    motion.name = f"file:{path.name}"
    return motion


def arm_motion(name: str, radians: bool = False, **estimate) -> JointMotion:
    """'reach' or a motion file; BadFile for a file that cannot be used."""
    from ..motion import KINEMATICS

    if name in KINEMATICS:
        from ..registry import unknown_name_message

        raise ValueError("--motion: " + unknown_name_message("arm2 motion", name, list(MOTIONS)) + " or a CSV file")
    return as_joint_motion(name) if name in MOTIONS else read_arm_motion_csv(name, "--motion", radians, **estimate)


@lru_cache(maxsize=32)
def _motions(source, radians, cutoff_hz, smoothing, spline_lambda, sample_dt, noise_deg, seed, capture_hz, digest):
    from ..experiment import motion_digest

    estimate = dict(cutoff_hz=cutoff_hz, smoothing=smoothing, spline_lambda=spline_lambda)
    truth = arm_motion(source, radians, **estimate)
    if sample_dt is not None:
        truth = Resampled(truth, sample_dt)
    if digest is not None and digest != motion_digest(source):
        raise BadFile(f"--motion: {source} has changed since this run was specified (or differs on this machine)")
    if not noise_deg:
        return truth, truth
    return noisy_joints(truth, noise_deg, seed, capture_hz, **estimate), truth


def motions(spec) -> tuple[JointMotion, JointMotion]:
    """(desired, true) motions of a spec: the one given to every method (a noisy capture when
    ``noise_deg`` > 0) and the one its indicators are measured against."""
    return _motions(spec.kinematics, spec.radians, spec.cutoff_hz, spec.smoothing, spec.spline_lambda, spec.sample_dt,
                    spec.noise_deg,
                    spec.seed or 0, spec.capture_hz, dict(spec.inputs).get("--motion"))


def nominal(spec) -> Arm2:
    return arm2_with(spec.model)


def plant(spec) -> Arm2:
    return arm2_with(tuple(spec.model) + tuple(spec.plant))


def reference(spec) -> sim.ArmInverse:
    """The nominal arm's inverse dynamics on the true motion, on its samples (the indicators' reference)."""
    return sim.inverse_dynamics(None, nominal(spec), motions(spec)[1])


def describe(spec) -> dict:
    """The record's fields that say which motion, noise, filter, model and plant a run used."""
    from ..experiment import _options_text

    desired, truth = motions(spec)
    out = {"motion": desired.name, "duration_s": truth.duration, "samples": len(truth.samples)}
    parts = getattr(desired, "parts", [])
    if parts and hasattr(parts[0], "describe"):
        out["derivatives"] = parts[0].describe().get("derivatives")
    out.update(noise_deg=spec.noise_deg, model="arm2", model_options=_options_text(spec.model) or None,
               plant=_options_text(spec.plant) or None)
    return out


CONTROLLERS = ("pd", "computed-torque", "lqr")


def check(spec) -> None:
    """ValueError (one line) for what the arm cannot run, or settings out of range; BadFile for a
    motion file that cannot be used. No simulation is run."""
    from ..integrate import Settings

    unavailable = {"--gradient exact": spec.gradient != "fd",
                   f"--controller {spec.controller}": spec.command == "control" and (spec.controller or "pd")
                   not in CONTROLLERS}
    for what, refused in unavailable.items():
        if refused:
            only = {"--controller": f" ({', '.join(CONTROLLERS)})"}
            raise ValueError(f"{what}: not available with --model arm2 yet{only.get(what.split()[0], '')}")
    nominal(spec), plant(spec)
    # the forearm's checks of the integrator, its dt or tolerances, and the penalty
    Settings(penalty=Penalty(spec.alpha, spec.xi, spec.omega), integrator=spec.integrator, dt=spec.dt, rtol=spec.rtol,
             atol=spec.atol)
    motions(spec)


def integration(spec) -> dict:
    """The keyword arguments of ``arm2_sim.simulate`` that say how a spec integrates: the penalty
    parameters, the integrator, its step (rk4) or its tolerances (the adaptive ones)."""
    return dict(penalty=Penalty(spec.alpha, spec.xi, spec.omega), dt=spec.dt, integrator=spec.integrator,
                rtol=spec.rtol, atol=spec.atol)


def inverse_run(spec) -> tuple[dict, list[str], np.ndarray]:
    """Inverse dynamics of the desired motion with the nominal arm: (record, CSV header, rows), the
    columns of a motion file (t, <joint>, <joint>_vel, <joint>_acc in s, deg, deg/s, deg/s^2) and
    <joint>_torque (N m)."""
    desired, _ = motions(spec)
    began = time.perf_counter()
    inv = sim.inverse_dynamics(None, nominal(spec), desired)
    runtime = time.perf_counter() - began
    record = {"command": "inverse", "kinematics": spec.kinematics, **describe(spec),
              **{f"{k}_{j}": float(v) for k, vals in (("torque_rms_nm", np.sqrt(np.mean(inv.torque**2, axis=0))),
                                                      ("torque_max_nm", inv.torque.max(axis=0)),
                                                      ("torque_min_nm", inv.torque.min(axis=0)))
                 for j, v in zip(JOINTS, vals)},
              "torque_rms_nm": float(np.sqrt(np.mean(inv.torque**2))), "runtime_s": runtime,
              "fdbench_version": __version__}
    header = ["t"] + [f"{j}{s}" for s in ("", "_vel", "_acc", "_torque") for j in JOINTS]
    rows = np.column_stack([inv.t, *np.degrees([inv.angles, inv.velocities, inv.accelerations]), inv.torque])
    return record, header, rows


def _per_joint(prefix: str, values) -> dict:
    return {f"{prefix}_{joint}": float(v) for joint, v in zip(JOINTS, values)}


def _message(result) -> str:
    text = result.status.value
    if not result.success:
        text = text.replace("theta reached +-pi/2", "the shoulder or the forearm reached +-90 deg")
        text += f" (stopped at t = {result.t_end:.4g} s)"
    return text + (f": {result.detail}" if result.detail else "")


def _outcome(spec, record: dict, result, inverse, **more):
    """The RunOutcome of a finished simulation: indicators over both joints and per joint, the
    trajectory table."""
    from ..experiment import RunOutcome

    desired = inverse.angles
    rot, rot_j = sim.rmse_deg(result, desired)
    trq, trq_j = sim.rmse_torque_nm(result, inverse.torque)
    record.update(rmse_rot_deg=rot, rmse_torque_nm=trq, t_end=result.t_end, status=result.status.code,
                  message=_message(result), max_violation=result.max_violation,
                  **_per_joint("rmse_rot_deg", rot_j), **_per_joint("rmse_torque_nm", trq_j))
    header = ["t"] + [f"{j}{s}" for s in ("", "_desired", "_torque", "_torque_inverse") for j in JOINTS]
    rows = np.column_stack([result.t, np.degrees(result.angles), np.degrees(desired), result.torque, inverse.torque])
    return RunOutcome(record, result, inverse, table=(header, rows), **more)


def _warm_up(spec) -> None:
    """Load (or compile) the arm's kernels (and scipy's integrators for an adaptive one), so that
    runtimes exclude it."""
    sim.warm_up(spec.integrator != "rk4")


def run(spec, on_evaluation=None, on_start=None):
    """Carry out a control, optimisation or collocation run of the arm (``RunOutcome``)."""
    from ..experiment import _options_text, base_record

    if spec.command == "optimize":
        return _optimize(spec, on_evaluation, on_start)
    if spec.command == "collocate":
        return _collocate(spec)
    if spec.command != "control":
        raise ValueError(f"{spec.command}: not available with --model arm2 yet")
    _warm_up(spec)
    controller = spec.controller or "pd"
    options = dict(spec.method_options)
    arm, body = nominal(spec), plant(spec)
    desired, _ = motions(spec)
    if controller == "lqr":
        from .arm2_lqr import warm_up

        warm_up()
    began = time.perf_counter()
    inverse = reference(spec)
    gains, drive, kp, kd = None, None, spec.kp or 0.0, spec.kd or 0.0
    if controller == "computed-torque":
        bandwidth, damping = options.get("bandwidth", 20.0), options.get("damping", 1.0)
        kp, kd = bandwidth**2, 2 * damping * bandwidth
    else:
        drive = sim.feedforward(arm, desired)
    if controller == "lqr":
        from .arm2_lqr import lqr_gains

        gains, kp, kd = lqr_gains(arm, desired, **options), 0.0, 0.0
    result = sim.simulate(drive, body, desired, kp, kd, computed=controller == "computed-torque", nominal=arm,
                          gains=gains, **integration(spec))
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque="M(z)*z_ddot_d+h(z,z_dot)" if controller == "computed-torque" else "id",
                  evaluations=1, runtime_s=runtime, controller=controller,
                  **({"kp": spec.kp, "kd": spec.kd} if controller == "pd" else
                     {"controller_options": _options_text(spec.method_options)}))
    return _outcome(spec, record, result, inverse)


def run_simulation(spec, torque_file=None, params_file=None, torque=None):
    """Open-loop forward dynamics of the arm driven by its inverse-dynamics torques, a CSV torque
    history (``t,shoulder,elbow``), saved parameters, or ``torque``, a function t (s), shape (k,)
    -> joint torques (N m), shape (k, 2); BadFile for a file that cannot be used."""
    from dataclasses import replace

    from ..experiment import base_record

    desired, _ = motions(spec)
    label, drive = "id", sim.feedforward(nominal(spec), desired)
    if params_file is not None:
        drive, label, digest, spec = _saved_torque(spec, params_file)
        desired, _ = motions(spec)
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--params", digest),))))
    elif torque is not None:
        drive, label = torque, getattr(torque, "__name__", "function")
    elif torque_file is not None:
        t, values = read_history_csv(torque_file, "--torque-file", desired.duration, JOINTS,
                                     preferred=tuple(f"{joint}_torque" for joint in JOINTS))
        drive = lambda s: np.stack([np.interp(s, t, values[:, j]) for j in range(len(JOINTS))], axis=-1)  # noqa: E731
        label = f"file:{torque_file}"
        digest = hashlib.sha256(t.tobytes() + values.tobytes()).hexdigest()
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--torque-file", digest),))))
    _warm_up(spec)
    began = time.perf_counter()
    inverse = reference(spec)
    result = sim.simulate(drive, plant(spec), desired, **integration(spec))
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque=label, evaluations=1, runtime_s=runtime)
    return _outcome(spec, record, result, inverse)


def _saved_torque(spec, path):
    """(torque function, label, digest, spec) of a parameter file saved by ``optimize --model arm2
    --save-params``; the spec follows the file's named motion. BadFile if it cannot be used."""
    from dataclasses import replace

    from ..params_file import make_saved_torque, read_params
    from .arm2_problem import ArmTrackingProblem

    saved = read_params(path, "arm2", motions(spec)[1].name, tuple(MOTIONS))
    if saved["kinematics"] is not None and saved["kinematics"] != spec.kinematics:
        spec = replace(spec, kinematics=saved["kinematics"], inputs=tuple(p for p in spec.inputs if p[0] != "--motion"))
    expected = make_saved_torque(saved).n_params * len(JOINTS)
    if saved["params"].shape != (expected,):
        raise BadFile(f"--params: {path}: expected {expected} parameters for {saved['torque']} on {len(JOINTS)} joints")
    problem = ArmTrackingProblem(saved["torque"], plant(spec), motions(spec)[0], saved["feedforward"],
                                 nominal=nominal(spec), **integration(spec), **saved["options"])
    name = saved["torque"] + (" (feedforward)" if saved["feedforward"] else "")
    return problem.torque_function(saved["params"]), f"{name} from {saved['path'].name}", saved["digest"], spec


def replay(spec, params) -> sim.ArmSimulation:
    """The simulation of a stored optimisation run's best parameters (for figures)."""
    from .arm2_problem import ArmTrackingProblem

    options = dict(spec.torque_options)
    if options.get("hidden") == "auto":  # 3 n + 1 parameters per joint
        options["hidden"] = (len(params) // len(JOINTS) - 1) // 3
    problem = ArmTrackingProblem(spec.torque, plant(spec), motions(spec)[0], spec.feedforward, spec.penalty_weight,
                                 nominal=nominal(spec), **integration(spec), **options)
    return problem.simulate(np.asarray(params, dtype=float))


def _optimize(spec, on_evaluation, on_start):
    """Shooting optimisation of per-joint torque parameters (``arm2_problem``)."""
    from ..experiment import _options_text, base_record
    from ..optimizers import make_optimizer
    from ..torques import TORQUES
    from .arm2_problem import ArmTrackingProblem, warm_up

    optimizer = make_optimizer(spec.optimizer, **dict(spec.optimizer_options))
    _warm_up(spec)
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

        inv = sim.inverse_dynamics(None, nominal(spec), desired)
        fits = [select_hidden(inv.t, inv.torque[:, j]) for j in range(len(JOINTS))]
        options["hidden"] = max(n for n, _ in fits)
        extra["hidden_fits"] = [(n, max(dict(tried).get(n, math.inf) for _, tried in fits))
                                for n in range(1, options["hidden"] + 1)]
    problem = ArmTrackingProblem(spec.torque, plant(spec), desired, spec.feedforward, spec.penalty_weight,
                                 nominal=nominal(spec), **integration(spec), **options)
    batch = problem.objectives_scaled if problem.batched else None
    found = optimizer.minimize(problem.objective_scaled, problem.x0, spec.budget, spec.seed, on_evaluation,
                               batch=batch)
    params = np.asarray(found.x) * problem.scale
    result = problem.simulate(params)
    runtime = time.perf_counter() - began
    record = base_record(spec)
    record.update(torque=spec.torque, optimizer=spec.optimizer, seed=spec.seed, budget=spec.budget,
                  evaluations=found.evaluations, best_objective=found.fun, stop_reason=found.stop_reason,
                  n_params=problem.n_params, runtime_s=runtime, penalty_weight=spec.penalty_weight,
                  torque_options=_options_text(sorted(options.items())),
                  optimizer_options=_options_text(spec.optimizer_options), gradient=spec.gradient,
                  initial_objective=problem.objective(problem.p0))
    return _outcome(spec, record, result, reference(spec), history=list(found.history), params=params, extra=extra)


def _collocate(spec):
    """Direct collocation of the nominal arm on the desired motion (``arm2_collocation``), then
    its torque replayed by the arm's forward simulation of the plant: the indicators are the
    replay's; the collocation's own RMSE over both joints at its nodes (against the true motion),
    IPOPT's status, iterations and solve time stand beside them. ``extra['collocation']`` holds
    the solution (node arrays of shape (N + 1, 2))."""
    from ..experiment import base_record
    from ..collocation import record_fields
    from .arm2_collocation import collocate

    options = dict(spec.method_options)
    _warm_up(spec)
    import casadi  # noqa: F401  (its import is not part of the runtime)

    desired, truth = motions(spec)
    began = time.perf_counter()
    inverse = reference(spec)
    solution = collocate(nominal(spec), desired, **options)
    result = sim.simulate(solution.torque_function(), plant(spec), desired, **integration(spec))
    runtime = time.perf_counter() - began
    own = float(np.sqrt(np.mean(np.degrees(solution.angles - truth(solution.t)[0]) ** 2)))
    record = base_record(spec)
    outcome = _outcome(spec, record, result, inverse, extra={"collocation": solution})
    record.update(runtime_s=runtime, **record_fields(solution, options, own, record["message"]))
    return outcome
