"""The ``opensim`` peer: OpenSim's forward simulation of the same model under the same PD law with
computed feedforward as ``fdbench control``.

The feedforward is OpenSim's own inverse dynamics (its InverseDynamicsSolver on the nominal model)
of the desired motion at the simulation's step times, applied by a PrescribedController through a
CoordinateActuator per coordinate, linear between the step times. OpenSim offers no continuous PD
controller usable from Python, so the feedback is a second CoordinateActuator per coordinate whose
torque, kp (z_d - z) + kd (z_d' - z'), is computed at each step time and held over the step: the
Manager (Runge-Kutta-Merson, accuracy ``ACCURACY``) is stepped every ``--dt``. The gains are
fdbench's PD's for the model (``fdbench.multibody.runs.pd_gains``; the forearm's 80 and 0.3).
Runtime: OpenSim's inverse dynamics and forward simulation, in its process (start-up and model
building excluded, as fdbench excludes compilation)."""

from __future__ import annotations

import time

import numpy as np

ACCURACY = 1e-6  # OpenSim's integrator accuracy (its default is 1e-5)
SUMMARY = ("OpenSim's forward simulation of the same model (exported with CoordinateActuators, or the user's "
           ".osim) under the same PD gains, its feedforward OpenSim's inverse dynamics; the feedback is held over "
           "each step of --dt (OpenSim has no continuous PD controller usable from Python)")


def gains(spec) -> tuple[np.ndarray, np.ndarray]:
    """Kp (N m/rad) and Kd (N m s/rad) per joint, shape (J,): fdbench's PD's for this spec."""
    from ..multibody.runs import pd_gains

    return pd_gains(spec)


def run(spec):
    """The peer's run (``RunOutcome``): OpenSim's PD simulation in a child process, its indicators
    on the motion's samples against the same reference as fdbench's PD."""
    from ..records import RunOutcome, base_record
    from .child import call
    from ..models import joints
    from .common import desired, grid, indicators, osim_texts, reference

    names = joints(spec.model_name)
    kp, kd = gains(spec)
    nominal, plant = osim_texts(spec)
    t = grid(spec)
    z, zd, zdd = desired(spec, t)
    request = {"peer": "opensim", "nominal": nominal, "plant": plant, "coordinates": list(names), "t": t.tolist(),
               "z": z.tolist(), "zd": zd.tolist(), "zdd": zdd.tolist(), "kp": kp.tolist(), "kd": kd.tolist(),
               "accuracy": ACCURACY}
    answer = call(request)
    record = base_record(spec)
    angles, torque = np.array(answer["z"], dtype=float), np.array(answer["torque"], dtype=float)
    fields, table = indicators(spec, t[: len(angles)], angles, torque, answer["t_end"])
    done = answer["t_end"] >= t[-1] - 1e-12
    message = (f"OpenSim {answer['version']} forward simulation (Runge-Kutta-Merson, accuracy {ACCURACY:g}) stepped "
               f"every {spec.dt:g} s, the PD feedback held over each step (OpenSim has no continuous PD controller "
               "usable from Python); feedforward: OpenSim's inverse dynamics")
    if not done:
        message = f"stopped at t = {answer['t_end']:.4g} s: {answer.get('failure')}; " + message
    record.update(fields, torque="id", controller="pd", evaluations=1, runtime_s=answer["id_s"] + answer["forward_s"],
                  status="success" if done else "error", message=message, peer="opensim",
                  opensim_version=answer["version"], opensim_inverse_s=answer["id_s"],
                  opensim_forward_s=answer["forward_s"], opensim_accuracy=ACCURACY,
                  **({"kp": spec.kp, "kd": spec.kd} if len(names) == 1 else {
                      "kp": spec.kp, "kd": spec.kd, **{f"kp_{j}": float(v) for j, v in zip(names, kp)},
                      **{f"kd_{j}": float(v) for j, v in zip(names, kd)}}))
    return RunOutcome(record, None, reference(spec)[0], table=table)


# ---------------------------------------------------------------------------------------- the child


def solve(osim, request: dict) -> dict:
    """In OpenSim's process: inverse dynamics of the desired motion on the nominal model, then the
    plant's forward simulation under feedforward + held PD feedback; angles (rad) and applied
    torques (N m) at the step times, shape (m, J), and the times taken (s)."""
    from .child import model_from

    names = request["coordinates"]
    t = np.array(request["t"])
    z, zd, zdd = (np.array(request[key], dtype=float) for key in ("z", "zd", "zdd"))
    began = time.perf_counter()
    feedforward = _inverse_dynamics(osim, model_from(osim, request["nominal"]), names, z, zd, zdd)
    id_s = time.perf_counter() - began
    model = model_from(osim, request["plant"])
    feedback = _drive(osim, model, names, t, feedforward)
    state = model.initSystem()
    coordinates = [model.getCoordinateSet().get(name) for name in names]
    for coordinate, angle, rate in zip(coordinates, z[0], zd[0]):
        coordinate.setValue(state, float(angle), False)
        coordinate.setSpeedValue(state, float(rate))
    for actuator in feedback:
        actuator.overrideActuation(state, True)
    kp, kd = np.array(request["kp"]), np.array(request["kd"])
    angles, torques, failure = [], [], None
    began = time.perf_counter()
    for k in range(len(t)):
        now = np.array([c.getValue(state) for c in coordinates])
        rate = np.array([c.getSpeedValue(state) for c in coordinates])
        held = kp * (z[k] - now) + kd * (zd[k] - rate)
        angles.append(now.tolist())
        torques.append((feedforward[k] + held).tolist())
        if k == len(t) - 1 or not np.all(np.isfinite(now)):
            break
        for actuator, value in zip(feedback, held):
            actuator.setOverrideActuation(state, float(value))
        manager = osim.Manager(model)  # a fresh integrator from the held torque: no step reuses the last one's
        manager.setIntegratorAccuracy(request["accuracy"])
        state.setTime(float(t[k]))
        manager.initialize(state)
        try:
            state = osim.State(manager.integrate(float(t[k + 1])))
        except RuntimeError as exc:
            failure = " ".join(str(exc).split())[:200]
            break
    forward_s = time.perf_counter() - began
    reached = len(angles) - 1 if failure is None and np.all(np.isfinite(angles[-1])) else max(len(angles) - 2, 0)
    return {"z": angles[: reached + 1], "torque": torques[: reached + 1], "t_end": float(t[reached]), "id_s": id_s,
            "forward_s": forward_s, "failure": failure}


def _inverse_dynamics(osim, model, names, z, zd, zdd) -> np.ndarray:
    """OpenSim's generalised forces (N m) of the coordinates ``names`` at the states given (rad,
    rad/s, rad/s^2, each (m, J)): its InverseDynamicsSolver, shape (m, J)."""
    state = model.initSystem()
    coordinates = [model.getCoordinateSet().get(name) for name in names]
    index = []
    for coordinate in coordinates:  # the coordinate's place among the system's speeds
        coordinate.setSpeedValue(state, 1.0)
        index.append(next(i for i in range(state.getNU()) if state.getU().get(i) == 1.0))
        coordinate.setSpeedValue(state, 0.0)
    solver = osim.InverseDynamicsSolver(model)
    out = np.empty_like(z)
    udot = osim.Vector(state.getNU(), 0.0)
    for k in range(len(z)):
        for coordinate, i, angle, rate, acceleration in zip(coordinates, index, z[k], zd[k], zdd[k]):
            coordinate.setValue(state, float(angle), False)
            coordinate.setSpeedValue(state, float(rate))
            udot.set(i, float(acceleration))
        model.realizeVelocity(state)
        tau = solver.solve(state, udot)
        out[k] = [tau.get(i) for i in index]
    return out


def _drive(osim, model, names, t, feedforward) -> list:
    """Add the feedforward actuators (a PrescribedController, linear between the step times) and
    the feedback actuators (overridden at each step); returns the feedback ones."""
    from .child import torque_driven

    controller = osim.PrescribedController()
    controller.setName("fdbench_feedforward")
    for j, actuator in enumerate(torque_driven(osim, model, names, "_feedforward")):
        controller.addActuator(actuator)
        history = osim.PiecewiseLinearFunction()
        for time_s, value in zip(t, feedforward[:, j]):
            history.addPoint(float(time_s), float(value))
        controller.prescribeControlForActuator(actuator.getName(), history)
    model.addController(controller)
    return torque_driven(osim, model, names, "_feedback")
