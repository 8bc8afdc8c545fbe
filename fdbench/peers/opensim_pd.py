"""The ``opensim`` peer: OpenSim's forward simulation of the same model under ``fdbench control``'s
PD law with computed feedforward, one Manager and one ``integrate`` over the whole motion.

tau = tau_ff(t) + kp (z_d - z) + kd (z_d' - z') splits into u(t) = tau_ff + kp z_d + kd z_d',
a PrescribedController on a CoordinateActuator per coordinate (1 N m, linear between the step
times), and -kp z - kd z', a SpringGeneralizedForce (stiffness kp, viscosity kd): the feedback acts
continuously. tau_ff is OpenSim's InverseDynamicsSolver on the nominal model. Runge-Kutta-Merson at
``ACCURACY``; states cubic-Hermite onto the step times. With ``--loads`` both models get the same
ExternalLoads. Runtime: the ``integrate`` call, best of ``REPEATS`` (inverse dynamics apart as
``opensim_inverse_s``)."""

from __future__ import annotations

import time

import numpy as np

from .child import call, coordinate_paths, model_from, torque_driven, with_loads

ACCURACY = 1e-5  # OpenSim's integrator accuracy: its default, as its users run it
REPEATS = 3  # the integrate call is timed this many times (from the same initial state), the best kept
SUMMARY = ("OpenSim's forward simulation of the same model (exported with CoordinateActuators, or the user's "
           ".osim) under the same PD law inside OpenSim (a PrescribedController for the feedforward and the "
           "set point, a SpringGeneralizedForce for the feedback), one Manager and one integrate over the whole "
           "motion; its feedforward OpenSim's inverse dynamics")


def run(spec):
    """The peer's run (``RunOutcome``): OpenSim's PD simulation in a child process, its indicators
    on the motion's samples against the same reference as fdbench's PD."""
    from ..models import joints  # lazy: OpenSim's child imports this module, not the engine
    from ..records import RunOutcome, base_record
    from ..run_inputs import pd_gains
    from .common import desired, grid, indicators, loads_request, osim_texts

    names = joints(spec.model_name)
    kp, kd = pd_gains(spec)  # N m/rad, N m s/rad per joint: fdbench's PD's
    nominal, plant = osim_texts(spec)
    t = grid(spec)
    z, zd, zdd = desired(spec, t)
    request = {"peer": "opensim", "nominal": nominal, "plant": plant, "coordinates": list(names), "t": t.tolist(),
               "z": z.tolist(), "zd": zd.tolist(), "zdd": zdd.tolist(), "kp": kp.tolist(), "kd": kd.tolist(),
               "accuracy": ACCURACY, "loads": loads_request(spec)}
    answer = call(request)
    record = base_record(spec)
    angles, torque = np.array(answer["z"], dtype=float), np.array(answer["torque"], dtype=float)
    fields, table = indicators(spec, t[: len(angles)], angles, torque, answer["t_end"])
    done = answer["t_end"] >= t[-1] - 1e-12
    message = (f"OpenSim {answer['version']} forward simulation (Runge-Kutta-Merson, accuracy {ACCURACY:g}, "
               f"{answer['steps']} steps), one integrate over the motion, PD inside OpenSim; feedforward: OpenSim's "
               f"inverse dynamics; runtime: the integrate call, best of {REPEATS}")
    if not done:
        message = f"stopped at t = {answer['t_end']:.4g} s: {answer.get('failure')}; " + message
    record.update(fields, torque="id", controller="pd", evaluations=1, runtime_s=answer["forward_s"],
                  status="success" if done else "error", message=message, peer="opensim",
                  opensim_version=answer["version"], opensim_inverse_s=answer["id_s"],
                  opensim_forward_s=answer["forward_s"], opensim_accuracy=ACCURACY,
                  opensim_steps=answer["steps"],
                  **({"kp": spec.kp, "kd": spec.kd} if len(names) == 1 else {
                      "kp": spec.kp, "kd": spec.kd, **{f"kp_{j}": float(v) for j, v in zip(names, kp)},
                      **{f"kd_{j}": float(v) for j, v in zip(names, kd)}}))
    return RunOutcome(record, None, spec.reference(), table=table)


# ---------------------------------------------------------------------------------------- the child


def solve(osim, request: dict) -> dict:
    """In OpenSim's process: the nominal model's inverse dynamics, then the plant's integrate under
    the PD law (timed ``REPEATS`` times); angles (rad) and torques (N m) at the step times reached
    (m, J), the last time reached (s) and the times taken (s)."""
    names = request["coordinates"]
    shift = float((request.get("loads") or {}).get("shift_s", 0.0))
    t = np.array(request["t"]) + shift
    z, zd, zdd = (np.array(request[key], dtype=float) for key in ("z", "zd", "zdd"))
    kp, kd = np.array(request["kp"], dtype=float), np.array(request["kd"], dtype=float)
    began = time.perf_counter()
    nominal = with_loads(osim, model_from(osim, request["nominal"]), request.get("loads"))
    feedforward = _inverse_dynamics(osim, nominal, names, t, z, zd, zdd)
    id_s = time.perf_counter() - began
    drive = feedforward + kp * z + kd * zd  # the law's part of time alone, N m
    model = with_loads(osim, model_from(osim, request["plant"]), request.get("loads"))
    _drive(osim, model, names, t, drive, kp, kd)
    initial = model.initSystem()
    initial.setTime(float(t[0]))
    paths = coordinate_paths(model, names)
    for name, angle, rate in zip(names, z[0], zd[0]):
        coordinate = model.getCoordinateSet().get(name)
        coordinate.setValue(initial, float(angle), False)
        coordinate.setSpeedValue(initial, float(rate))
    forward_s, failure = np.inf, None
    for _ in range(int(request.get("repeats", REPEATS))):
        state = osim.State(initial)
        manager = osim.Manager(model)
        manager.setIntegratorAccuracy(request["accuracy"])
        manager.initialize(state)
        began = time.perf_counter()
        try:
            manager.integrate(float(t[-1]))
        except RuntimeError as exc:
            failure = " ".join(str(exc).split())[:200]
        forward_s = min(forward_s, time.perf_counter() - began)
        if failure is not None:
            break
    table = manager.getStatesTable()
    times = np.array(table.getIndependentColumn(), dtype=float)
    column = lambda label: table.getDependentColumn(label).to_numpy()  # noqa: E731
    values = np.column_stack([column(path + "/value") for path in paths])
    rates = np.column_stack([column(path + "/speed") for path in paths])
    finite = np.all(np.isfinite(values) & np.isfinite(rates), axis=1)
    last = len(times) if finite.all() else int(np.argmin(finite))
    times, values, rates = times[:last], values[:last], rates[:last]
    reached = t[t <= times[-1] + 1e-12] if len(times) else t[:1]
    angles, speeds = hermite(times, values, rates, reached) if len(times) > 1 else (z[:1], zd[:1])
    torque = drive[: len(reached)] - kp * angles - kd * speeds
    return {"z": angles.tolist(), "torque": torque.tolist(), "t_end": float(reached[-1] - shift), "id_s": id_s,
            "forward_s": forward_s, "steps": int(len(times) - 1), "failure": failure}


def hermite(times, values, rates, at):
    """Angles and rates (shape (len(at), J)) at the times ``at`` (s) by cubic Hermite interpolation
    of the integrator's steps: ``values`` (rad) and ``rates`` (rad/s), shape (n, J), at ``times``
    (a time recorded twice counted once)."""
    keep = np.concatenate([[True], np.diff(times) > 0])
    times, values, rates = times[keep], values[keep], rates[keep]
    k = np.clip(np.searchsorted(times, at, side="right") - 1, 0, len(times) - 2)
    h = (times[k + 1] - times[k])[:, None]
    s = ((at - times[k])[:, None]) / h
    p0, p1, m0, m1 = values[k], values[k + 1], rates[k] * h, rates[k + 1] * h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    angle = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
    rate = ((6 * s**2 - 6 * s) * p0 + (3 * s**2 - 4 * s + 1) * m0 + (-6 * s**2 + 6 * s) * p1
            + (3 * s**2 - 2 * s) * m1) / h
    return angle, rate


def _inverse_dynamics(osim, model, names, t, z, zd, zdd) -> np.ndarray:
    """OpenSim's generalised forces (N m) of the coordinates ``names`` at the times t (s, shape
    (m,)) and states given (rad, rad/s, rad/s^2, each (m, J)), the model's applied forces (its
    external loads) accounted for: its InverseDynamicsSolver, shape (m, J)."""
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
        state.setTime(float(t[k]))
        for coordinate, i, angle, rate, acceleration in zip(coordinates, index, z[k], zd[k], zdd[k]):
            coordinate.setValue(state, float(angle), False)
            coordinate.setSpeedValue(state, float(rate))
            udot.set(i, float(acceleration))
        model.realizeVelocity(state)
        tau = solver.solve(state, udot)
        out[k] = [tau.get(i) for i in index]
    return out


def _drive(osim, model, names, t, drive, kp, kd) -> None:
    """Add the law: a CoordinateActuator per coordinate under a PrescribedController whose control
    is ``drive`` (N m, shape (m, J), linear between the step times t), and a SpringGeneralizedForce
    per coordinate (stiffness kp, viscosity kd, rest length 0: -kp z - kd z')."""
    controller = osim.PrescribedController()
    controller.setName("fdbench_feedforward")
    for j, actuator in enumerate(torque_driven(osim, model, names, "_drive")):
        controller.addActuator(actuator)
        history = osim.PiecewiseLinearFunction()
        for time_s, value in zip(t, drive[:, j]):
            history.addPoint(float(time_s), float(value))
        controller.prescribeControlForActuator(actuator.getName(), history)
    model.addController(controller)
    for name, stiffness, viscosity in zip(names, kp, kd):
        spring = osim.SpringGeneralizedForce(name)
        spring.setName(name + "_feedback")
        spring.setStiffness(float(stiffness))
        spring.setViscosity(float(viscosity))
        spring.setRestLength(0.0)
        model.addForce(spring)
