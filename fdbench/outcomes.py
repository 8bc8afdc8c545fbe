"""The outcome of a simulated run (``records.RunOutcome``), as fdbench's runs and the peers' replays
measure it: ``rmse_rot_deg`` (deg) and ``rmse_torque_nm`` (N m, against the inverse dynamics) over
the angle coordinates and per joint (``_<joint>``); translations apart (``rmse_trans_cm``,
``rmse_force_n``); a floating base's residuals; the status's message and the trajectory table.
"""

from __future__ import annotations

import math

import numpy as np

from .controllers.base import per_joint
from .multibody import simulation as sim
from .records import ALPHA_HINT, RunOutcome
from .run_inputs import engine, joints, nominal

# an activation at least this is full activation: the muscle gives all it can (its excitation at 1)
FULL_ACTIVATION = 0.99
MAX_SPANS = 3  # the spans of full activation named per muscle in ``saturation``
ACTIVATION_MEAN = "_activation_mean"  # a muscle-driven run's record: <muscle>_activation_mean

RESIDUAL_FIELDS = ("residual_force_rms_n", "residual_moment_rms_nm", "residual_fx_rms_n", "residual_fy_rms_n",
                   "residual_fx_mean_n", "residual_fy_mean_n", "residual_mz_mean_nm")


def residual_fields(model, forces: np.ndarray) -> dict:
    """A floating base's residuals from the forces (n, J) on the samples reached: its coordinates'
    generalised forces FX, FY (N, ground axes) and MZ (N m), as OpenSim's RRA names them, their RMS
    (force magnitude and moment apart) and means; {} without a floating base."""
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


def muscle_fields(muscles, t: np.ndarray, activation: np.ndarray) -> dict:
    """A muscle-driven run's indicators over the samples t (s, (n,)) reached, activations (n, M):
    ``effort``, the mean of sum_m a_m^2; ``<muscle>_activation_mean``; ``saturation``, each muscle
    at full activation (a >= ``FULL_ACTIVATION``) and when, e.g. "BIClong from 0.62 to 1 s" ("at 0 s" for a
    single sample), or None."""
    if not len(t):
        return {"effort": math.nan, **{m + ACTIVATION_MEAN: math.nan for m in muscles}, "saturation": None}
    said = []
    for m, name in enumerate(muscles):
        full = np.concatenate([[False], activation[:, m] >= FULL_ACTIVATION, [False]])
        starts, ends = np.flatnonzero(full[1:] & ~full[:-1]), np.flatnonzero(~full[1:] & full[:-1]) - 1
        if len(starts):
            spans = [f"from {t[a]:.3g} to {t[b]:.3g} s" if f"{t[a]:.3g}" != f"{t[b]:.3g}" else f"at {t[a]:.3g} s"
                     for a, b in zip(starts[:MAX_SPANS], ends[:MAX_SPANS])]
            more = f" and {len(starts) - MAX_SPANS} more times" if len(starts) > MAX_SPANS else ""
            said.append(f"{name} {', '.join(spans)}{more}")
    return {"effort": float(np.mean(np.sum(activation**2, axis=1))),
            **{m + ACTIVATION_MEAN: float(np.mean(activation[:, i])) for i, m in enumerate(muscles)},
            "saturation": "; ".join(said) or None}


def _message(result) -> str:
    text = result.status.value
    if not result.success:
        text += f" (stopped at t = {result.t_end:.4g} s)"
    return text + (f": {result.detail}" if result.detail else "")


DRIFT_DEG = 10.0  # an angle this far from its motion: the torques, not --alpha or --dt, made the run fail


def drift_hint(message: str, result, desired, kinds) -> str:
    """A constraint failure's message, its hint on --alpha and --dt replaced when an angle had drifted
    more than DRIFT_DEG from ``desired`` (rad, (n, J)) by then: the torques, not the penalty, failed."""
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


def outcome(spec, record: dict, result, inverse, **more) -> RunOutcome:
    """The RunOutcome of a finished simulation: indicators over every joint and per joint (angles
    and translations apart), the trajectory table."""
    names, kinds = joints(spec), nominal(spec).coordinate_kinds
    desired = inverse.angles
    rot, trans, per_coordinate = sim.rmse_coordinates(result, desired, kinds)
    trq, force, per_force = sim.rmse_generalized_forces(result, inverse.torque, kinds)
    record.update(rmse_rot_deg=rot, rmse_torque_nm=trq, t_end=result.t_end, status=result.status.code,
                  message=_message(result), max_violation=result.max_violation,
                  **per_coordinate_fields(("rmse_rot_deg", "rmse_trans_cm"), names, kinds, per_coordinate),
                  **per_coordinate_fields(("rmse_torque_nm", "rmse_force_n"), names, kinds, per_force))
    if "translation" in kinds:
        record.update(rmse_trans_cm=trans, rmse_force_n=force)
    record.update(residual_fields(nominal(spec), result.torque[result.reached]))
    if getattr(result, "activation", None) is not None:  # the muscles drove the model
        record.update(muscle_fields([m.name for m in nominal(spec).muscles], result.t[result.reached],
                                    result.activation[result.reached]))
    if result.status is sim.Status.CONSTRAINT:
        record["message"] = drift_hint(record["message"], result, desired, kinds)
    header = ["t"] + [f"{j}{s}" for s in ("", "_desired", "_vel", "_vel_desired", "_acc", "_acc_desired", "_torque",
                                          "_torque_inverse") for j in names]
    values = (result.angles, desired, result.zd, inverse.velocities, _accelerations(spec, result), inverse.accelerations)
    rows = np.column_stack([result.t, *(in_file_units(v, kinds) for v in values), result.torque, inverse.torque])
    return RunOutcome(record, result, inverse, table=(header, rows), **more)


def per_coordinate_fields(prefixes: tuple[str, str], names, kinds, values) -> dict:
    """Per-coordinate record fields ``<prefix>_<coordinate>``: the first prefix for angles, the
    second for translations; none for a model of one coordinate (the overall value says it)."""
    fields = per_joint(prefixes[0], names, values)
    return {(key.replace(prefixes[0], prefixes[1], 1) if kind == "translation" else key): value
            for (key, value), kind in zip(fields.items(), kinds)}


def in_file_units(values: np.ndarray, kinds) -> np.ndarray:
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
