"""What the peers share on fdbench's side: the model as OpenSim file text, the desired motion and
the reference as arrays of shape (n, J) for any model, the replay of a torque history by fdbench's
forward simulation, and the indicators of a trajectory computed elsewhere (OpenSim's)."""

from __future__ import annotations

import numpy as np

from ..models import joints
from ..records import RunOutcome, base_record


def osim_texts(spec) -> tuple[str, str]:
    """(nominal, plant) as OpenSim model files: the user's own .osim where ``--model`` is one and
    no constant is changed, else the descriptions written by ``to_osim`` (one CoordinateActuator
    per joint, each load a PrescribedForce)."""
    from ..models import description, is_file
    from ..multibody.description import with_short_keys
    from ..multibody.osim import MAX_OSIM_BYTES, to_osim

    if is_file(spec.model_name) and str(spec.model_name).lower().endswith(".osim"):
        from ..files import read_input_bytes

        own = read_input_bytes(spec.model_name, "--model", MAX_OSIM_BYTES).decode("utf-8", errors="replace")
        if not spec.model and not spec.plant:
            return own, own
    model = description(spec.model_name)  # the forearm's too: the library's, with the paper's short keys
    nominal = to_osim(with_short_keys(model, tuple(spec.model)))
    plant = to_osim(with_short_keys(model, tuple(spec.model) + tuple(spec.plant))) if spec.plant else nominal
    return nominal, plant


def grid(spec) -> np.ndarray:
    """The simulation's step times over the motion's span (s), shape (steps + 1,)."""
    from ..integrate import steps

    duration = spec.motions()[0].duration
    return np.linspace(0.0, duration, steps(spec.dt, duration) + 1)


def desired(spec, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The desired motion (the one the methods are given) at times t (s): angles (rad), rates
    (rad/s), accelerations (rad/s^2), each of shape (len(t), J)."""
    motion = spec.motions()[0]
    values = motion(np.asarray(t, dtype=float))
    return tuple(np.asarray(v, dtype=float).reshape(len(t), -1) for v in values)


def reference(spec):
    """(inverse, angles (n, J) rad, torque (n, J) N m, t (n,) s): the indicators' reference, the
    nominal model's inverse dynamics on the true motion at its samples."""
    inverse = spec.reference()
    return inverse, inverse.angles, inverse.torque, inverse.t


def warm_up(spec) -> None:
    """Load (or compile) fdbench's simulation kernels, so that a replay's runtime excludes it."""
    from ..multibody import runs

    runs._warm_up(spec)


def replay(spec, torque) -> RunOutcome:
    """fdbench's forward simulation of the plant under ``torque``, a function t (s), shape (k,) ->
    N m, shape (k, J), open loop, as ``collocate`` replays its own solution: the run's outcome with
    the three indicators (the record of ``base_record`` with the replay's fields)."""
    from ..multibody import runs

    return runs._outcome(spec, base_record(spec), runs._simulate(spec, torque), runs.reference(spec))


def indicators(spec, t: np.ndarray, angles: np.ndarray, torque: np.ndarray, t_end: float) -> tuple[dict, tuple]:
    """The record's indicators of a trajectory simulated elsewhere (OpenSim's) on the grid ``t``
    (s, shape (m,)): ``angles`` (rad) and applied ``torque`` (N m), shape (m, J), up to ``t_end``;
    measured on the motion's samples reached, against the reference, as fdbench's runs are:
    (fields, (CSV header, rows) of the trajectory)."""
    inverse, truth, torque_ref, samples = reference(spec)
    names = joints(spec.model_name)
    z, tau = _on_samples(samples, t, angles), _on_samples(samples, t, torque)
    reached = samples <= t_end + 1e-12
    rot = np.degrees(z - truth)[reached]
    trq = (tau - torque_ref)[reached]
    fields = {"rmse_rot_deg": float(np.sqrt(np.mean(rot**2))), "rmse_torque_nm": float(np.sqrt(np.mean(trq**2))),
              "t_end": float(t_end)}
    if len(names) > 1:
        fields.update({f"rmse_rot_deg_{j}": float(v) for j, v in zip(names, np.sqrt(np.mean(rot**2, axis=0)))})
        fields.update({f"rmse_torque_nm_{j}": float(v) for j, v in zip(names, np.sqrt(np.mean(trq**2, axis=0)))})
    header = ["t"] + [f"{j}{s}" for s in ("", "_desired", "_torque", "_torque_inverse") for j in names]
    rows = np.column_stack([samples, np.degrees(z), np.degrees(truth), tau, torque_ref])[reached]
    return fields, (header, rows)


def _on_samples(samples: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` (shape (m, J), at times t) at the times ``samples``, linear between: shape (n, J)."""
    return np.stack([np.interp(samples, t, values[:, j]) for j in range(values.shape[1])], axis=-1)
