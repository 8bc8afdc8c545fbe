"""The ``opensim-cmc`` peer: OpenSim's Computed Muscle Control (``CMCTool``) on the torque-driven
model, beside ``fdbench control``: a CoordinateActuator per coordinate (``OPTIMAL_FORCE`` N m,
controls within +-``CONTROL_BOUND``), the desired angles as a .sto in radians, one CMC_Joint task
per coordinate (kp ``TASK_KP``, kv ``TASK_KV``: critically damped), window ``TIME_WINDOW``. CMC
ends one window before the motion; the indicators are taken over the samples it reached, on its
own states and actuator forces. Runtime: the whole ``CMCTool.run()``."""

from __future__ import annotations

import time

import numpy as np

from .child import call, coordinate_paths, loads_file, model_from, radians_table, torque_driven
from .opensim_pd import hermite

OPTIMAL_FORCE = 100.0  # N m per unit control
CONTROL_BOUND = 1e3  # CMC's controls' bounds: 1e5 N m, never reached
TASK_KP, TASK_KV = 100.0, 20.0  # CMC_Joint gains (1/s^2, 1/s), those of OpenSim's examples
TIME_WINDOW = 0.01  # s: CMC's default look-ahead
SUMMARY = ("OpenSim's CMCTool (Computed Muscle Control, its fast target) on the same model made torque-driven "
           f"(CoordinateActuators, optimal force {OPTIMAL_FORCE:g} N m), tracking the desired angles with CMC_Joint "
           f"tasks (kp {TASK_KP:g}, kv {TASK_KV:g}), time window {TIME_WINDOW:g} s; time: its whole run")


def run(spec):
    """The peer's run (``RunOutcome``): CMCTool in a child process, its indicators on the motion's
    samples against the same reference as fdbench's control."""
    from ..models import joints  # lazy: OpenSim's child imports this module, not the engine
    from ..records import RunOutcome, base_record
    from .common import desired, grid, indicators, loads_request, osim_texts

    names = joints(spec.model_name)
    _, plant = osim_texts(spec)
    t = grid(spec)
    z, zd, _ = desired(spec, t)
    answer = call({"peer": "opensim-cmc", "plant": plant, "coordinates": list(names), "t": t.tolist(),
                   "z": z.tolist(), "zd": zd.tolist(), "loads": loads_request(spec)})
    angles, torque = np.array(answer["z"], dtype=float), np.array(answer["torque"], dtype=float)
    fields, table = indicators(spec, t[: len(angles)], angles, torque, answer["t_end"])
    last = t[t <= t[-1] - TIME_WINDOW + 1e-9][-1]  # the last step time before CMC's end, one window before the motion's
    done = answer["t_end"] >= last - 1e-9
    message = (f"OpenSim {answer['version']} CMCTool, {answer['steps']} integration steps, time window "
               f"{TIME_WINDOW:g} s (CMC looks one window ahead and so ends at t = {answer['t_end']:.4g} s, the "
               "indicators taken over the samples it reached); runtime: its whole run")
    if not done:
        message = f"stopped at t = {answer['t_end']:.4g} s: {answer.get('failure')}; " + message
    record = base_record(spec)
    record.update(fields, torque="cmc", controller="cmc", evaluations=1, runtime_s=answer["run_s"],
                  status="success" if done else "error", message=message, peer="opensim-cmc",
                  opensim_version=answer["version"], cmc_time_window_s=TIME_WINDOW, cmc_task_kp=TASK_KP,
                  cmc_task_kv=TASK_KV, cmc_optimal_force_nm=OPTIMAL_FORCE, opensim_steps=answer["steps"])
    return RunOutcome(record, None, spec.reference(), table=table)


# ---------------------------------------------------------------------------------------- the child


def solve(osim, request: dict) -> dict:
    """In OpenSim's process: CMCTool on the torque-driven plant (external loads on their own clock);
    angles (rad) and torques (N m) at the step times reached (m, J), the last time, steps, wall time."""
    import os
    import tempfile

    names = request["coordinates"]
    shift = float((request.get("loads") or {}).get("shift_s", 0.0))
    t = np.array(request["t"]) + shift
    z = np.array(request["z"], dtype=float)
    model = model_from(osim, request["plant"])
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
    applied = np.column_stack([force(name + "_torque") for name in names])
    reached = t[(t >= times[0] - 1e-12) & (t <= times[-1] + 1e-12)]
    angles, _ = hermite(times, values, rates, reached)
    torque = np.stack([np.interp(reached, force_times, applied[:, j]) for j in range(len(names))], axis=-1)
    return {"z": angles.tolist(), "torque": torque.tolist(), "t_end": float(reached[-1] - shift), "run_s": run_s,
            "steps": int(len(times) - 1), "failure": failure}


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
