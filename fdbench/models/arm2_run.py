"""The arm's runs as the commands report them: inverse dynamics, open-loop simulation and PD
control with computed feedforward, each giving one flat record (the forearm's keys plus per-joint
indicators) and a history as CSV rows.

Indicators for n joints: ``rmse_rot_deg`` is the root mean square over all joints and samples of
the angle error (deg), ``rmse_torque_nm`` likewise of the torque (N m) against the inverse-dynamics
torques; ``rmse_rot_deg_<joint>`` and ``rmse_torque_nm_<joint>`` give each joint's.

Files (CSV with a header, names case-insensitive, any order):
* a motion: ``t`` (s) and one angle column per joint, ``shoulder``, ``elbow`` (deg, or rad), with
  optional ``<joint>_vel`` and ``<joint>_acc`` (deg/s, deg/s^2); derivatives otherwise estimated
  as for a recorded forearm motion (``fdbench.motion.SampledMotion``);
* a torque history: ``t`` (s) and ``shoulder``, ``elbow`` (N m), covering the motion's span,
  linearly interpolated.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from .. import __version__
from ..files import BadFile, read_columns, read_history_csv
from ..model import Penalty
from .arm2 import JOINTS, arm2_with
from .arm2_motion import MOTIONS, JointMotion, PerJoint, as_joint_motion
from . import arm2_sim as sim


def read_arm_motion_csv(path, option: str = "--motion", radians: bool = False, **estimate) -> JointMotion:
    """A recorded arm motion from a CSV file (see the module's docstring). Raises BadFile."""
    from ..motion import SampledMotion

    path = Path(path)
    optional = tuple(f"{j}_{d}" for j in JOINTS for d in ("vel", "acc"))
    columns = read_columns(path, option, required=("t",) + JOINTS, optional=optional)
    unit = 1.0 if radians else math.pi / 180
    parts = []
    for joint in JOINTS:
        vel, acc = columns.get(f"{joint}_vel"), columns.get(f"{joint}_acc")
        if (vel is None) != (acc is None):
            raise BadFile(f"{option}: {path} gives only one of {joint}_vel and {joint}_acc; give both or neither")
        try:
            parts.append(SampledMotion(columns["t"], columns[joint] * unit, None if vel is None else vel * unit,
                                       None if acc is None else acc * unit, name=joint, **estimate))
        except ValueError as exc:
            raise BadFile(f"{option}: {path}: {joint}: {exc}") from None
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


def read_arm_torque_csv(path, duration: float, option: str = "--torque-file"):
    """A joint-torque history from a CSV file as a function t (s), shape (k,) -> (k, 2) N m."""
    t, values = read_history_csv(path, option, duration, JOINTS)
    return lambda s: np.stack([np.interp(s, t, values[:, j]) for j in range(len(JOINTS))], axis=-1)


CONTROLLER_OPTIONS = {"pd": ("kp", "kd"), "computed-torque": ("bandwidth", "damping"),
                      "lqr": ("q_angle", "q_rate", "r_torque")}


def _controller_options(controller: str, values: dict) -> str:
    return " ".join(f"{k}={float(values[k])}" for k in CONTROLLER_OPTIONS[controller])


def _pairs_text(pairs) -> str:
    return " ".join(f"{k}={float(v):g}" for k, v in pairs)


def _per_joint(prefix: str, values) -> dict:
    return {f"{prefix}_{joint}": float(v) for joint, v in zip(JOINTS, values)}


def inverse_run(model_pairs, motion: JointMotion) -> tuple[dict, list[str], np.ndarray]:
    """Inverse dynamics of the arm: (record, CSV header, rows) on the motion's samples."""
    arm = arm2_with(model_pairs)
    began = time.perf_counter()
    inv = sim.inverse_dynamics(None, arm, motion)
    runtime = time.perf_counter() - began
    record = {"command": "inverse", "model": "arm2", "kinematics": motion.name, "motion": motion.name,
              **{f"{k}_{j}": float(v) for k, vals in (("torque_rms_nm", np.sqrt(np.mean(inv.torque**2, axis=0))),
                                                      ("torque_max_nm", inv.torque.max(axis=0)),
                                                      ("torque_min_nm", inv.torque.min(axis=0)))
                 for j, v in zip(JOINTS, vals)},
              "torque_rms_nm": float(np.sqrt(np.mean(inv.torque**2))), "runtime_s": runtime,
              "fdbench_version": __version__}
    header = ["t"] + [f"{j}{s}" for s in ("", "_dot", "_ddot", "_torque") for j in JOINTS]
    rows = np.column_stack([inv.t, inv.angles, inv.velocities, inv.accelerations, inv.torque])
    return record, header, rows


def tracking_run(command: str, model_pairs, motion: JointMotion, *, kp=0.0, kd=0.0, torque=None, dt=1e-3,
                 alpha=1e7, xi=1.0, omega=10.0, controller: str = "pd", bandwidth: float = 20.0,
                 damping: float = 1.0, plant_pairs=(), q_angle: float = 1e4, q_rate: float = 1.0,
                 r_torque: float = 1.0) -> tuple[dict, list[str], np.ndarray]:
    """A forward simulation of the arm: open loop under ``torque`` (a function, default the
    inverse-dynamics torques) for 'simulate'; for 'control', PD per joint (kp N m/rad, kd N m s/rad)
    plus computed feedforward, or ``controller`` 'computed-torque': the arm's inverse dynamics with
    its full mass matrix at the current state, for error dynamics of natural frequency
    ``bandwidth`` (rad/s) and damping ratio ``damping`` on both joints, or 'lqr': computed
    feedforward plus time-varying LQR (weights q_angle rad^-2, q_rate s^2 rad^-2, r_torque
    (N m)^-2, ``arm2_lqr``). ``model_pairs`` change the
    nominal model and the simulated body, ``plant_pairs`` the simulated body only: inverse dynamics,
    feedforward and computed torque keep the nominal model (model-mismatch studies).
    Returns (record, CSV header, history rows)."""
    from ..integrate import Settings

    arm = arm2_with(model_pairs)
    plant = arm2_with(tuple(model_pairs) + tuple(plant_pairs))
    penalty = Penalty(alpha, xi, omega)
    Settings(penalty=penalty, dt=dt)  # the forearm's checks of the step and the penalty parameters
    inv = sim.inverse_dynamics(None, arm, motion)
    computed = command == "control" and controller == "computed-torque"
    lqr = command == "control" and controller == "lqr"
    gains = None
    if computed:
        drive, kp, kd = None, bandwidth**2, 2 * damping * bandwidth
    else:
        drive = sim.feedforward(arm, motion) if torque is None else torque
    if lqr:
        from .arm2_lqr import lqr_gains

        gains, kp, kd = lqr_gains(arm, motion, q_angle, q_rate, r_torque), 0.0, 0.0
    result = sim.simulate(drive, plant, motion, kp, kd, penalty=penalty, dt=dt, computed=computed, nominal=arm,
                          gains=gains)
    rot, rot_j = sim.rmse_deg(result, inv.angles)
    trq, trq_j = sim.rmse_torque_nm(result, inv.torque)
    closed = command == "control"
    record = {
        "command": command, "model": "arm2", "kinematics": motion.name, "integrator": "rk4", "dt": dt,
        "torque": "M(z)*z_ddot_d+h(z,z_dot)" if computed else "inverse" if torque is None else "file",
        "optimizer": None, "feedforward": closed or torque is None,
        "kp": kp if controller == "pd" and closed else None, "kd": kd if controller == "pd" and closed else None,
        "seed": None, "budget": None,
        "rmse_rot_deg": rot, **_per_joint("rmse_rot_deg", rot_j), "rmse_torque_nm": trq,
        **_per_joint("rmse_torque_nm", trq_j), "runtime_s": result.runtime_s, "evaluations": 1,
        "t_end": result.t_end, "status": result.status.code, "message": _message(result),
        "max_violation": result.max_violation, "alpha": alpha, "xi": xi, "omega": omega, "motion": motion.name,
        "model_options": _pairs_text(model_pairs) or None, "plant": _pairs_text(plant_pairs) or None,
        **({"controller": controller, "controller_options": _controller_options(controller, locals())} if closed
           else {}),
        "fdbench_version": __version__,
    }
    header = ["t"] + [f"{j}{s}" for s in ("", "_desired", "_torque", "_torque_inverse") for j in JOINTS]
    rows = np.column_stack([result.t, result.angles, inv.angles, result.torque, inv.torque])
    return record, header, rows


def _message(result) -> str:
    text = result.status.value
    if not result.success:
        text = text.replace("theta reached +-pi/2", "the shoulder or the forearm reached +-90 deg")
        text += f" (stopped at t = {result.t_end:.4g} s)"
    return text


def optimize_run(model_pairs, motion: JointMotion, *, torque="cs", optimizer="bfgs", feedforward=False, seed=0,
                 budget=200, torque_options=None, optimizer_options=None, penalty_weight=1.0, dt=1e-3, alpha=1e7,
                 xi=1.0, omega=10.0, on_evaluation=None) -> tuple[dict, list[str], np.ndarray, list[float]]:
    """Shooting optimisation on the arm (``arm2_problem``): (record, CSV header, history rows,
    best objective per evaluation); ``on_evaluation(count, best)`` after each evaluation."""
    from ..integrate import Settings
    from ..torques import TORQUES
    from .arm2_problem import ArmTrackingProblem, optimize

    arm = arm2_with(model_pairs)
    penalty = Penalty(alpha, xi, omega)
    Settings(penalty=penalty, dt=dt)
    options = {k: v for k, v in (torque_options or {}).items() if v is not None}
    problem = ArmTrackingProblem(torque, arm, motion, feedforward, penalty_weight, penalty, dt, **options)
    TORQUES[torque].warm_up()  # the parameterisation's kernels load before the clock starts
    began = time.perf_counter()
    initial = problem.objective(problem.p0)
    p, found, result, _ = optimize(problem, optimizer, budget, seed, on_evaluation,
                                   **{k: v for k, v in (optimizer_options or {}).items() if v is not None})
    runtime = time.perf_counter() - began
    inv = problem.inverse
    rot, rot_j = sim.rmse_deg(result, inv.angles)
    trq, trq_j = sim.rmse_torque_nm(result, inv.torque)
    record = {
        "command": "optimize", "model": "arm2", "kinematics": motion.name, "integrator": "rk4", "dt": dt,
        "torque": torque, "optimizer": optimizer, "feedforward": feedforward, "kp": None, "kd": None, "seed": seed,
        "budget": budget, "rmse_rot_deg": rot, **_per_joint("rmse_rot_deg", rot_j), "rmse_torque_nm": trq,
        **_per_joint("rmse_torque_nm", trq_j), "runtime_s": runtime, "evaluations": found.evaluations,
        "best_objective": found.fun, "initial_objective": initial, "t_end": result.t_end,
        "status": result.status.code, "message": _message(result), "stop_reason": found.stop_reason,
        "max_violation": result.max_violation, "n_params": problem.n_params,
        "torque_options": " ".join(f"{k}={v}" for k, v in sorted(options.items())),
        "alpha": alpha, "xi": xi, "omega": omega, "penalty_weight": penalty_weight, "motion": motion.name,
        "fdbench_version": __version__,
    }
    header = ["t"] + [f"{j}{s}" for s in ("", "_desired", "_torque", "_torque_inverse") for j in JOINTS]
    rows = np.column_stack([result.t, result.angles, inv.angles, result.torque, inv.torque])
    return record, header, rows, list(found.history)
