"""The ``opensim-cmc`` peer: OpenSim's Computed Muscle Control (``CMCTool``) beside ``fdbench
control``: the desired angles as a .sto in radians, one CMC_Joint task per coordinate (kp
``TASK_KP``, kv ``TASK_KV``: critically damped), window ``TIME_WINDOW``, fast target. A model without
muscles is made torque-driven: a CoordinateActuator per coordinate (``OPTIMAL_FORCE`` N m, controls
within +-``CONTROL_BOUND``). A model with muscles runs muscle-driven, as OpenSim's users run CMC:
its muscles (``to_osim``'s DeGrooteFregly2016Muscles, or the user's .osim's own) and as reserves its
``[[actuators]]`` (CoordinateActuators of their optimal force; unbounded controls bounded by
+-``CONTROL_BOUND``), or, without actuators, one per coordinate of ``RESERVE_OPTIMAL_FORCE`` N m as
OpenSim's arm26 CMC example; its torque is then the reserves' plus the muscles' generalised forces
(OpenSim's moment arms times their forces). CMC ends one window before the motion (and
muscle-driven starts 0.03 s into it, its muscles' states settled before); the indicators are taken
over the samples it reached, on its own states and forces. Runtime: the whole
``CMCTool.run()``."""

from __future__ import annotations

import time

import numpy as np

from .child import (call, coordinate_paths, loads_file, model_from, muscle_reserves, optimal_forces,
                    radians_table, torque_driven)
from .opensim_pd import hermite

OPTIMAL_FORCE = 100.0  # N m per unit control
CONTROL_BOUND = 1e3  # CMC's controls' bounds: 1e5 N m, never reached
TASK_KP, TASK_KV = 100.0, 20.0  # CMC_Joint gains (1/s^2, 1/s), those of OpenSim's examples
TIME_WINDOW = 0.01  # s: CMC's default look-ahead
RESERVE_OPTIMAL_FORCE = 1.0  # N m per unit control: a muscle-driven model's reserves when it has no actuators
SUMMARY = ("OpenSim's CMCTool (Computed Muscle Control, its fast target) on the same model made torque-driven "
           f"(CoordinateActuators, optimal force {OPTIMAL_FORCE:g} N m), or muscle-driven on a model with muscles "
           f"(its [[actuators]] as reserves, else {RESERVE_OPTIMAL_FORCE:g} N m per coordinate), tracking the desired "
           f"angles with CMC_Joint tasks (kp {TASK_KP:g}, kv {TASK_KV:g}), time window {TIME_WINDOW:g} s; time: its "
           "whole run")


def run(spec):
    """The peer's run (``RunOutcome``): CMCTool in a child process, its indicators on the motion's
    samples against the same reference as fdbench's control."""
    from ..models import joints  # lazy: OpenSim's child imports this module, not the engine
    from ..records import RunOutcome, base_record
    from ..run_inputs import nominal
    from .common import desired, grid, indicators, loads_request, osim_texts

    names = joints(spec.model_name)
    _, plant = osim_texts(spec)
    t = grid(spec)
    z, zd, _ = desired(spec, t)
    model = nominal(spec)
    muscles = [muscle.name for muscle in model.muscles]
    answer = call({"peer": "opensim-cmc", "plant": plant, "coordinates": list(names), "t": t.tolist(),
                   "z": z.tolist(), "zd": zd.tolist(), "loads": loads_request(spec), "muscles": muscles})
    angles, torque = np.array(answer["z"], dtype=float), np.array(answer["torque"], dtype=float)
    start = answer.get("t_start", 0.0)  # s: muscle-driven, CMC settles its muscles' states first and starts later
    ran = t[t >= start - 1e-9][: len(angles)]
    fields, table = indicators(spec, ran, angles, torque, answer["t_end"], t_start=start)
    last = t[t <= t[-1] - TIME_WINDOW + 1e-9][-1]  # the last step time before CMC's end, one window before the motion's
    done = answer["t_end"] >= last - 1e-9
    began = f"starts at t = {start:.4g} s (its initial states' settling before) and " if start > 1e-9 else ""
    message = (f"OpenSim {answer['version']} CMCTool, {answer['steps']} integration steps, time window "
               f"{TIME_WINDOW:g} s (CMC {began}looks one window ahead and so ends at t = {answer['t_end']:.4g} s, the "
               "indicators taken over the samples it reached); runtime: its whole run")
    extra = {}
    if muscles:
        extra = _muscle_fields(spec, ran, answer, names)
        message = _muscle_message(answer, bool(model.actuators)) + message
    else:
        extra["cmc_optimal_force_nm"] = OPTIMAL_FORCE
    if not done:
        message = f"stopped at t = {answer['t_end']:.4g} s: {answer.get('failure')}; " + message
    record = base_record(spec)
    record.update(fields, torque="cmc", controller="cmc", evaluations=1, runtime_s=answer["run_s"],
                  status="success" if done else "error", message=message, peer="opensim-cmc",
                  opensim_version=answer["version"], cmc_time_window_s=TIME_WINDOW, cmc_task_kp=TASK_KP,
                  cmc_task_kv=TASK_KV, opensim_steps=answer["steps"], **extra)
    return RunOutcome(record, None, spec.reference(), table=table)


def _muscle_fields(spec, t: np.ndarray, answer: dict, names) -> dict:
    """A muscle-driven run's fields over the motion's samples reached (as fdbench's CMC's): each
    muscle's mean activation, the effort (mean of sum a^2), the reserves' RMS torque (N m: over them
    all, and per coordinate, 0 where none)."""
    samples = spec.reference().t
    samples = samples[(samples >= t[0] - 1e-12) & (samples <= answer["t_end"] + 1e-12)]
    on = lambda values: np.stack([np.interp(samples, t, column) for column in np.asarray(values, dtype=float).T],  # noqa: E731
                                 axis=-1)
    activation, reserve = on(answer["activation"]), on(answer["reserve"])
    per_reserve = np.sqrt(np.mean(reserve ** 2, axis=0))
    reserved = np.array([name in answer["reserve_coordinates"] for name in names])
    fields = {f"{m}_activation_mean": float(np.mean(activation[:, i])) for i, m in enumerate(answer["muscles"])}
    fields.update(effort=float(np.mean(np.sum(activation ** 2, axis=1))),
                  reserve_rms_nm=float(np.sqrt(np.mean(per_reserve[reserved] ** 2))) if reserved.any() else 0.0)
    if len(names) > 1:
        fields.update({f"reserve_rms_nm_{j}": float(v) for j, v in zip(names, per_reserve)})
    return fields


def _muscle_message(answer: dict, actuators: bool) -> str:
    """The start of a muscle-driven run's message: its muscles and reserves (``actuators``: the
    model has [[actuators]], its reserves; else one per coordinate, written so by ``to_osim`` or
    added where the user's .osim has no CoordinateActuator)."""
    reserves = ", ".join(f"{name} ({force:g} N m)" for name, force in zip(answer["reserve_names"],
                                                                          answer["reserve_forces"]))
    origin = ("the model's actuators" if actuators and not answer["reserves_added"] else
              f"the model has no actuators: one per coordinate, of {RESERVE_OPTIMAL_FORCE:g} N m per unit control as "
              "in OpenSim's arm26 CMC example")
    return (f"muscle-driven: {len(answer['muscles'])} muscles ({', '.join(answer['muscle_kinds'])}), reserves "
            f"{reserves} ({origin}), the torque the reserves' plus the muscles' generalised forces; ")


# ---------------------------------------------------------------------------------------- the child


def solve(osim, request: dict) -> dict:
    """In OpenSim's process: CMCTool on the plant, torque-driven or, with ``muscles`` in the request,
    muscle-driven (external loads on their own clock); angles (rad) and torques (N m) at the step
    times reached (m, J), the last time, steps, wall time; muscle-driven also the muscles' names,
    kinds and activations (m, M), the reserves' torques per coordinate (N m, (m, J)), names,
    coordinates and optimal forces, and whether they were added."""
    import os
    import tempfile

    names = request["coordinates"]
    shift = float((request.get("loads") or {}).get("shift_s", 0.0))
    t = np.array(request["t"]) + shift
    z = np.array(request["z"], dtype=float)
    muscles = request.get("muscles") or []
    model = model_from(osim, request["plant"], muscles=bool(muscles))
    if muscles:
        reserves, added = muscle_reserves(osim, model, names, RESERVE_OPTIMAL_FORCE, CONTROL_BOUND)
    else:
        reserves, added = [(name + "_torque", name) for name in names], False
        for actuator in torque_driven(osim, model, names, "_torque"):
            actuator.setOptimalForce(OPTIMAL_FORCE)
            actuator.setMinControl(-CONTROL_BOUND)
            actuator.setMaxControl(CONTROL_BOUND)
    model.finalizeConnections()
    model.initSystem()
    paths = coordinate_paths(model, names)
    with tempfile.TemporaryDirectory(prefix="fdbench-cmc-") as folder:
        kinematics = os.path.join(folder, "desired.sto")
        osim.STOFileAdapter.write(radians_table(osim, names, t, z), kinematics)
        tasks = osim.CMC_TaskSet()
        for name in names:
            task = osim.CMC_Joint()
            task.setName(name)
            task.setCoordinateName(name)
            task.setKP(TASK_KP, 1.0, 1.0)
            task.setKV(TASK_KV, 1.0, 1.0)
            task.setActive(True, False, False)
            task.setWeight(1.0, 1.0, 1.0)
            tasks.cloneAndAppend(task)
        tasks_file = os.path.join(folder, "tasks.xml")
        tasks.printToXML(tasks_file)
        tool = osim.CMCTool()
        tool.setName("fdbench")
        tool.setModel(model)
        tool.setDesiredKinematicsFileName(kinematics)
        tool.setTaskSetFileName(tasks_file)
        tool.setInitialTime(float(t[0]))
        tool.setFinalTime(float(t[-1]))
        tool.setTimeWindow(TIME_WINDOW)
        tool.setUseFastTarget(True)
        tool.setLowpassCutoffFrequency(-1.0)
        tool.setResultsDir(os.path.join(folder, "results"))
        tool.setReplaceForceSet(False)
        loads = loads_file(request.get("loads"))
        if loads is not None:
            tool.setExternalLoadsFileName(loads)
        failure = None
        began = time.perf_counter()
        try:
            tool.run()
        except RuntimeError as exc:
            failure = " ".join(str(exc).split())[:200]
        run_s = time.perf_counter() - began
        states = _read(osim, os.path.join(folder, "results", "fdbench_states.sto"))
        forces = _read(osim, os.path.join(folder, "results", "fdbench_Actuation_force.sto"))
    if states is None or forces is None:
        return {"z": [], "torque": [], "t_end": 0.0, "run_s": run_s, "steps": 0,
                "failure": failure or "CMC wrote no states"}
    times, column = states
    values = np.column_stack([column(path + "/value") for path in paths])
    rates = np.column_stack([column(path + "/speed") for path in paths])
    force_times, force = forces
    reached = t[(t >= times[0] - 1e-12) & (t <= times[-1] + 1e-12)]
    angles, _ = hermite(times, values, rates, reached)
    at = lambda series, label: np.interp(reached, force_times, series(label))  # noqa: E731
    reserve = np.zeros((len(reached), len(names)))
    for name, coordinate in reserves:
        if coordinate in names:  # a user's actuator on a coordinate fdbench's description lacks: not a torque here
            reserve[:, names.index(coordinate)] += at(force, name)
    answer = {"z": angles.tolist(), "torque": reserve.tolist(), "t_start": float(reached[0] - shift),
              "t_end": float(reached[-1] - shift), "run_s": run_s,
              "steps": int(len(times) - 1), "failure": failure}
    if muscles:
        kept = [m.getName() for m in model.getMuscles() if m.get_appliesForce()]
        tension = np.column_stack([at(force, name) for name in kept])
        arms = _moment_arms(osim, request["plant"], names, kept, angles)
        answer.update(torque=(reserve + np.einsum("kmj,km->kj", arms, tension)).tolist(), muscles=kept,
                      muscle_kinds=sorted({model.getMuscles().get(name).getConcreteClassName() for name in kept}),
                      activation=np.column_stack([np.interp(reached, times, column(f"/forceset/{name}/activation"))
                                                  for name in kept]).tolist(),
                      reserve=reserve.tolist(), reserve_names=[name for name, _ in reserves],
                      reserve_coordinates=[coordinate for _, coordinate in reserves],
                      reserve_forces=optimal_forces(osim, model, reserves), reserves_added=added)
    return answer


def _moment_arms(osim, content: str, names, muscles, angles) -> np.ndarray:
    """OpenSim's moment arms (m, (k, M, J)) of the ``muscles`` about the coordinates ``names`` at
    the angles (rad, (k, J)), on a fresh copy of the model."""
    model = model_from(osim, content, muscles=True)
    state = model.initSystem()
    coordinates = [model.getCoordinateSet().get(name) for name in names]
    found = [model.getMuscles().get(name) for name in muscles]
    out = np.empty((len(angles), len(found), len(names)))
    for k, row in enumerate(angles):
        for coordinate, value in zip(coordinates, row):
            coordinate.setValue(state, float(value), False)
        model.realizePosition(state)
        out[k] = [[muscle.computeMomentArm(state, coordinate) for coordinate in coordinates] for muscle in found]
    return out


def _read(osim, path):
    """(times (s), column(label) -> values) of a .sto file CMC wrote (a time may repeat where its
    last window ends, which OpenSim's own TimeSeriesTable refuses); None where it is missing."""
    import os

    if not os.path.exists(path):
        return None
    with open(path, encoding="utf-8") as handle:
        lines = handle.read().splitlines()
    start = next(k for k, line in enumerate(lines) if line.strip().lower() == "endheader") + 1
    labels = lines[start].split()
    values = np.loadtxt(lines[start + 1:], dtype=float, ndmin=2)
    return values[:, 0], lambda label: values[:, labels.index(label)]
