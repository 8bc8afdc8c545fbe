"""What the peers share on fdbench's side: the model as OpenSim file text, the desired motion and
the reference as arrays of shape (n, J) for any model, the replay of a torque history by fdbench's
forward simulation, and the indicators of a trajectory computed elsewhere (OpenSim's)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import run_inputs
from ..multibody.model_changes import rigid_tendons
from ..controllers.base import muscle_columns, per_joint
from ..files import read_input_bytes
from ..integrate import steps
from ..models import description, is_file, joints
from ..multibody import simulation as sim
from ..multibody.model_changes import with_short_keys
from ..multibody.loads import data_file
from ..multibody.osim import MAX_OSIM_BYTES, to_osim
from ..outcomes import in_file_units, outcome, per_coordinate_fields, residual_fields
from ..records import RunOutcome, base_record
from ..run_inputs import loads, motions, warm_up  # noqa: F401 - warm_up: the peers'


def osim_texts(spec) -> tuple[str, str]:
    """(nominal, plant) as OpenSim model files: the user's own .osim where ``--model`` is one and
    no constant is changed, else the descriptions written by ``to_osim`` (one CoordinateActuator
    per joint, each load a PrescribedForce)."""
    if is_file(spec.model_name) and str(spec.model_name).lower().endswith(".osim"):
        own = read_input_bytes(spec.model_name, "--model", MAX_OSIM_BYTES).decode("utf-8", errors="replace")
        if not spec.model and not spec.plant:
            return own, own
    model = description(spec.model_name)  # the forearm's too: the library's, with the paper's short keys
    nominal = to_osim(with_short_keys(model, tuple(spec.model)))
    plant = to_osim(with_short_keys(model, tuple(spec.model) + tuple(spec.plant))) if spec.plant else nominal
    return nominal, plant


LOADS_DATA = "loads_data"  # the name (before its suffix) of the loads' data file in OpenSim's folder


def loads_request(spec) -> dict | None:
    """The spec's external loads as OpenSim is given them (None without): ``xml`` naming ``data_name``,
    the data file's text ``data``, and ``shift_s`` (s), the motion's start on the loads' clock."""
    if spec.loads is None:
        return None
    import xml.etree.ElementTree as ElementTree

    loads(spec)
    root = ElementTree.fromstring(read_input_bytes(spec.loads, "--loads"))  # the bytes fdbench read and checked
    element = root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")
    source = data_file(spec.loads)
    name = LOADS_DATA + (source.suffix.lower() if source.suffix.lower() in (".mot", ".sto") else ".mot")
    element.find("datafile").text = name
    version = root.get("Version", "40000") if root.tag == "OpenSimDocument" else "40000"
    document = ElementTree.Element("OpenSimDocument", Version=version)
    document.append(element)
    data = read_input_bytes(source, f"--loads (the <datafile> of {Path(spec.loads).name})")
    return {"xml": ElementTree.tostring(document, encoding="unicode"), "data_name": name,
            "data": data.decode("utf-8", errors="replace"), "shift_s": float(getattr(motions(spec)[1], "start_s", 0.0))}


def grid(spec) -> np.ndarray:
    """The simulation's step times over the motion's span (s), shape (steps + 1,)."""
    duration = spec.motions()[0].duration
    return np.linspace(0.0, duration, steps(spec.dt, duration) + 1)


def desired(spec, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The desired motion (the one the methods are given) at times t (s): angles (rad), rates
    (rad/s), accelerations (rad/s^2), each of shape (len(t), J)."""
    motion = spec.motions()[0]
    values = motion(np.asarray(t, dtype=float))
    return tuple(np.asarray(v, dtype=float).reshape(len(t), -1) for v in values)


def replay(spec, torque) -> RunOutcome:
    """fdbench's forward simulation of the plant under ``torque``, a function t (s), shape (k,) ->
    N m, shape (k, J), open loop, as ``collocate`` replays its own solution: the run's outcome with
    the three indicators (the record of ``base_record`` with the replay's fields)."""
    return outcome(spec, base_record(spec), run_inputs.simulate(spec, torque), run_inputs.reference(spec))


def rigid_plant(spec):
    """The plant's engine with its tendons rigid (as muscle-driven collocation takes them), its
    kernels loaded or compiled so that a replay's time excludes them."""
    body = run_inputs.engine(spec, rigid_tendons(run_inputs.plant(spec)))
    sim.warm_up(False, (body,))
    return body


def simulate_muscles(spec, body, solution):
    """fdbench's forward simulation of ``body`` (``rigid_plant``) under a muscle-driven solution's
    excitations and reserve torques (``collocation.MuscleCollocationResult``), open loop."""
    desired = motions(spec)[0]
    return sim.simulate(solution.torque_function(), body, desired, grid=sim.half_steps(desired, spec.dt),
                        excitation=solution.excitation_function(), **run_inputs.integration(spec))


def muscle_replay(spec, result, solution) -> RunOutcome:
    """The outcome of a muscle-driven solution's replay ``result`` (``simulate_muscles``): the
    replay's indicators and muscle fields, ``actuation``, ``tendons``, the reserves' RMS torque
    (N m, over the coordinates with one, and per coordinate) on the samples reached, and the
    trajectory with each muscle's activation, excitation and force and each reserve (N m)."""
    names = joints(spec.model_name)
    done = outcome(spec, base_record(spec), result, run_inputs.reference(spec), extra={"collocation": solution})
    reserve = solution.torque_samples(result.t).reshape(len(result.t), -1)
    reached = result.reached
    per_reserve = np.sqrt(np.mean(reserve[reached] ** 2, axis=0)) if reached.any() else np.full(len(names), np.nan)
    reserved = solution.reserve_forces > 0
    taken = solution.rigid_tendons
    done.record.update(actuation="muscles", tendons=f"rigid (compliant taken as rigid: {', '.join(taken)})" if taken
                       else "rigid", reserve_rms_nm=float(np.sqrt(np.mean(per_reserve[reserved] ** 2)))
                       if reserved.any() else 0.0, **per_joint("reserve_rms_nm", names, per_reserve))
    header, rows = done.table
    columns, values = muscle_columns(result, solution.muscles)
    done.table = (header + columns + [f"{j}_reserve" for j in names], np.column_stack([rows, values, reserve]))
    return done


def indicators(spec, t: np.ndarray, angles: np.ndarray, torque: np.ndarray, t_end: float,
               t_start: float = 0.0) -> tuple[dict, tuple]:
    """(fields, (CSV header, rows)) of a trajectory simulated elsewhere on the grid ``t`` (s, (m,)):
    ``angles`` (rad, m) and ``torque`` (N m, N), (m, J), from ``t_start`` up to ``t_end``, measured
    as fdbench's over the samples between."""
    from types import SimpleNamespace

    inverse = spec.reference()  # the nominal model's inverse dynamics on the true motion
    truth, torque_ref, samples = inverse.angles, inverse.torque, inverse.t
    names, kinds = joints(spec.model_name), run_inputs.nominal(spec).coordinate_kinds
    z, tau = _on_samples(samples, t, angles), _on_samples(samples, t, torque)
    reached = (samples >= t_start - 1e-12) & (samples <= t_end + 1e-12)
    result = SimpleNamespace(angles=z, z=z, torque=tau, reached=reached)
    rot, trans, per_coordinate = sim.rmse_coordinates(result, truth, kinds)
    trq, force, per_force = sim.rmse_generalized_forces(result, torque_ref, kinds)
    fields = {"rmse_rot_deg": rot, "rmse_torque_nm": trq, "t_end": float(t_end),
              **per_coordinate_fields(("rmse_rot_deg", "rmse_trans_cm"), names, kinds, per_coordinate),
              **per_coordinate_fields(("rmse_torque_nm", "rmse_force_n"), names, kinds, per_force)}
    if "translation" in kinds:
        fields.update(rmse_trans_cm=trans, rmse_force_n=force)
    fields.update(residual_fields(run_inputs.nominal(spec), tau[reached]))
    header = ["t"] + [f"{j}{s}" for s in ("", "_desired", "_torque", "_torque_inverse") for j in names]
    rows = np.column_stack([samples, in_file_units(z, kinds), in_file_units(truth, kinds), tau,
                            torque_ref])[reached]
    return fields, (header, rows)


def _on_samples(samples: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` (shape (m, J), at times t) at the times ``samples``, linear between: shape (n, J)."""
    return np.stack([np.interp(samples, t, values[:, j]) for j in range(values.shape[1])], axis=-1)
