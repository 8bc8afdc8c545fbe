"""The ``moco`` peer: OpenSim Moco's MocoTrack on ``fdbench collocate``'s model, motion and mesh,
its solution replayed by fdbench's forward simulation as ``collocate``'s is.

Torque-driven (a model without muscles): CoordinateActuators (1 N m, unbounded); the desired states
in a .sto (speeds weighted 0, the guess only); squared angle errors (rad^2) plus ``regularization``
/ (180/pi)^2 times squared torques (as ``collocate`` in deg); initial state fixed; Hermite-Simpson
on ``nodes`` intervals; IPOPT with ``tolerance``, serial. The torque is interpolated as
``collocate``'s (piecewise quadratic).

Muscle-driven (a model with muscles), as ``collocate --actuation muscles``: the model's muscles
(``ModOpReplaceMusclesWithDeGrooteFregly2016``, ``ModOpIgnoreTendonCompliance``: tendons rigid) and
its reserves (its CoordinateActuators, else one per coordinate of 1 N m per unit control), each
activation starting at its excitation (``MocoInitialActivationGoal``, a constraint); the control
effort goal weighs the excitations and the reserves' controls by collocate's default effort
weight / (180/pi)^2. The excitations at the mesh points (linear between) and the reserve torques
are replayed with rigid tendons."""

from __future__ import annotations

import math
import time

import numpy as np

from .child import (call, coordinate_paths, loads_file, model_from, muscle_reserves, optimal_forces, radians_table,
                    torque_driven)

DEG2 = (180.0 / math.pi) ** 2
DEFAULT_TOLERANCE = 1e-4  # IPOPT's convergence and constraint tolerance in MocoTrack (Moco's own default is 1e-2)
STATE_BOUND = 20.0  # rad (and 10x that in rad/s): bounds loose enough never to bind
RESERVE_OPTIMAL_FORCE = 1.0  # N m per unit control: a muscle-driven model's reserves without actuators (collocate's)
RESERVE_CONTROL_BOUND = 1e3  # the reserves' controls' bounds, never reached
SUMMARY = ("OpenSim Moco's MocoTrack, torque-driven (CoordinateActuators) or, on a model with muscles, "
           "muscle-driven (De Groote muscles, tendons rigid, the same reserves), Hermite-Simpson on the mesh of "
           "'fdbench collocate', tracking the same motion's angles with the same regularisation or effort weight; "
           "its torque (or its excitations and reserves) replayed by fdbench's forward simulation exactly as "
           "collocate's")


def run(spec):
    """The peer's run (``RunOutcome``): MocoTrack in a child process, its solution replayed by
    fdbench; Moco's own RMSE_rot, status, iterations and times beside the replay's indicators."""
    from ..collocation import CollocationResult  # lazy: OpenSim's child imports this module, not the engine
    from ..models import joints
    from ..run_inputs import nominal as description
    from .common import desired, loads_request, osim_texts, replay, warm_up

    options = dict(spec.method_options)
    names = joints(spec.model_name)
    nominal, _ = osim_texts(spec)  # Moco tracks with the nominal model; the replay simulates the plant
    samples = spec.motions()[0].samples
    z, zd, _ = desired(spec, samples)
    muscles = [muscle.name for muscle in description(spec).muscles]
    request = {"peer": "moco", "nominal": nominal, "coordinates": list(names), "t": np.asarray(samples).tolist(),
               "z": z.tolist(), "zd": zd.tolist(), "nodes": options["nodes"],
               "effort_weight": options["regularization"] / DEG2, "tolerance": options["tolerance"],
               "max_iter": options["max_iter"], "loads": loads_request(spec)}
    if muscles:
        return _run_muscles(spec, request, muscles)
    answer = call(request)
    warm_up(spec)
    times, controls = np.array(answer["t"]), np.array(answer["controls"]).reshape(len(answer["t"]), len(names))
    solution = _as_collocation(CollocationResult, times, controls, answer)
    began = time.perf_counter()
    outcome = replay(spec, solution.torque_function())
    replay_s = time.perf_counter() - began
    _moco_fields(spec, outcome.record, answer, solution, options, replay_s)
    outcome.record["regularization"] = options["regularization"]
    outcome.extra["collocation"] = solution
    return outcome


def _run_muscles(spec, request: dict, muscles: list):
    """The muscle-driven MocoTrack (``request`` the torque-driven one's, the muscles named) and its
    replay (``common.muscle_replay``: rigid tendons, the excitations and reserves)."""
    from ..collocation import DEFAULT_EXCITATION_WEIGHT, MuscleCollocationResult
    from ..run_inputs import nominal as description
    from .common import muscle_replay, rigid_plant, simulate_muscles

    options = dict(spec.method_options)
    request.update(muscles=muscles, effort_weight=DEFAULT_EXCITATION_WEIGHT / DEG2)
    answer = call(request)
    body = rigid_plant(spec)
    J, M = len(request["coordinates"]), len(muscles)
    t = np.array(answer["t"])
    shape = lambda key, n: np.array(answer[key], dtype=float).reshape(len(t), n)  # noqa: E731
    angles, speeds, reserve = shape("angles", J), shape("speeds", J), shape("reserve", J)
    activation, excitation = shape("activation", M), shape("excitation", M)
    hs = _hermite_simpson(t)
    nodes = slice(None, None, 2 if hs else 1)
    forces = np.zeros(J)
    for coordinate, force in zip(answer["reserve_coordinates"], answer["reserve_forces"]):
        if coordinate in request["coordinates"]:
            forces[request["coordinates"].index(coordinate)] += force
    compliant = tuple(m.name for m in description(spec).muscles if m.tendon == "compliant")
    solution = MuscleCollocationResult(
        "hermite-simpson" if hs else "trapezoidal", t[nodes], angles[nodes], speeds[nodes], reserve[nodes],
        reserve[1::2] if hs else None, answer["objective"], answer["status"], answer["iterations"], answer["solve_s"],
        0.0, muscles=tuple(muscles), activation=activation[nodes], excitation=excitation[nodes], reserve_forces=forces,
        effort_weight=DEFAULT_EXCITATION_WEIGHT, rigid_tendons=compliant)
    began = time.perf_counter()
    result = simulate_muscles(spec, body, solution)
    replay_s = time.perf_counter() - began
    outcome = muscle_replay(spec, result, solution)
    _moco_fields(spec, outcome.record, answer, solution, options, replay_s)
    outcome.record.update(effort_weight=DEFAULT_EXCITATION_WEIGHT, moco_muscle_kinds=", ".join(answer["muscle_kinds"]),
                          reserves=", ".join(f"{name} ({force:g} N m)" for name, force in
                                             zip(answer["reserve_names"], answer["reserve_forces"])))
    outcome.record["message"] += (f"; muscle-driven: {M} muscles, tendons rigid (ModOpIgnoreTendonCompliance), "
                                  f"reserves {outcome.record['reserves']}")
    return outcome


def _moco_fields(spec, record: dict, answer: dict, solution, options: dict, replay_s: float) -> None:
    """The fields a Moco run adds to its replay's record: MocoTrack's own RMSE_rot at its mesh
    points, IPOPT's status and iterations, Moco's times (s) and the runtime (its run plus the
    replay); status 'collocation_failed' where IPOPT did not solve the problem."""
    truth = spec.motions()[1]
    wanted = np.asarray(truth(solution.t)[0]).reshape(solution.angles.shape)
    own = float(np.sqrt(np.mean(np.degrees(solution.angles - wanted) ** 2)))
    success = answer["status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    record.update(torque="moco", evaluations=1, runtime_s=answer["run_s"] + replay_s, peer="moco",
                  nodes=options["nodes"], scheme="hermite-simpson", tolerance=options["tolerance"],
                  collocation_rmse_rot_deg=own, ipopt_status=answer["status"], ipopt_iterations=answer["iterations"],
                  solve_time_s=answer["solve_s"], moco_run_s=answer["run_s"],
                  moco_solver_duration_s=answer["solver_duration_s"], replay_time_s=replay_s,
                  opensim_version=answer["version"])
    if not success:
        record.update(status="collocation_failed",
                      message=f"MocoTrack did not solve the problem: {answer['status']} after {answer['iterations']} "
                              f"iterations; the replay of its last iterate: {record.get('message')}")
    else:
        record["message"] = (f"MocoTrack (OpenSim {answer['version']}): {answer['status']} in {answer['iterations']} "
                             f"iterations; replay: {record.get('message')}")


def _hermite_simpson(times: np.ndarray) -> bool:
    """Whether Moco's solution times (s) are Hermite-Simpson's: the mesh points and every interval's
    midpoint between them (2 N + 1 times)."""
    return len(times) % 2 == 1 and len(times) > 1 and bool(np.allclose(times[1::2], (times[:-1:2] + times[2::2]) / 2))


def _as_collocation(result_class, times: np.ndarray, controls: np.ndarray, answer: dict):
    """Moco's solution as a ``collocation.CollocationResult`` (node arrays (N + 1, J) and midpoint
    torques (N, J)), so that its torque is interpolated as collocate's: Hermite-Simpson gives the
    mesh points and the interval midpoints (2 N + 1 times)."""
    angles = np.array(answer["angles"]).reshape(controls.shape)
    speeds = np.array(answer["speeds"]).reshape(controls.shape)
    if _hermite_simpson(times):
        return result_class("hermite-simpson", times[::2], angles[::2], speeds[::2], controls[::2], controls[1::2],
                            answer["objective"], answer["status"], answer["iterations"], answer["solve_s"], 0.0)
    return result_class("trapezoidal", times, angles, speeds, controls, None, answer["objective"], answer["status"],
                        answer["iterations"], answer["solve_s"], 0.0)


# ---------------------------------------------------------------------------------------- the child


def solve(osim, request: dict) -> dict:
    """In OpenSim's process: MocoTrack of the desired states (external loads on their own clock);
    times (s), controls (N m), angles (rad), speeds (rad/s) at its points (m, J), status,
    iterations, objective, solve and whole-run times (s)."""
    import os
    import tempfile

    names = request["coordinates"]
    muscles = request.get("muscles") or []
    model = model_from(osim, request["nominal"], muscles=bool(muscles))
    if muscles:
        reserves, _ = muscle_reserves(osim, model, names, RESERVE_OPTIMAL_FORCE, RESERVE_CONTROL_BOUND)
    else:
        torque_driven(osim, model, names, "_torque")
    model.finalizeConnections()
    model.initSystem()
    paths = coordinate_paths(model, names)
    shift = float((request.get("loads") or {}).get("shift_s", 0.0))
    t = np.array(request["t"]) + shift
    z, zd = np.array(request["z"]), np.array(request["zd"])
    run_began = time.perf_counter()  # the whole run: MocoTrack's set-up, initialize and solve
    track = osim.MocoTrack()
    track.setName("fdbench_peer")
    processor = osim.ModelProcessor(model)
    kinds = sorted({model.getMuscles().get(name).getConcreteClassName() for name in muscles})
    if muscles:  # as collocate --actuation muscles: De Groote's muscles (Moco refuses to replace one), tendons rigid
        if kinds != ["DeGrooteFregly2016Muscle"]:
            processor.append(osim.ModOpReplaceMusclesWithDeGrooteFregly2016())
        processor.append(osim.ModOpIgnoreTendonCompliance())
    loads = loads_file(request.get("loads"))
    if loads is not None:
        processor.append(osim.ModOpAddExternalLoads(loads))
    track.setModel(processor)
    folder = tempfile.TemporaryDirectory(prefix="fdbench-moco-")
    reference = os.path.join(folder.name, "states.sto")  # the desired states, as MocoTrack reads them
    labels = [path + suffix for suffix in ("/value", "/speed") for path in paths]
    osim.STOFileAdapter.write(radians_table(osim, labels, t, np.hstack([z, zd])), reference)
    track.setStatesReference(osim.TableProcessor(reference))
    track.set_states_global_tracking_weight(1.0)
    weights = osim.MocoWeightSet()
    for path in paths:
        weights.cloneAndAppend(osim.MocoWeight(path + "/speed", 0.0))
    track.set_states_weight_set(weights)
    track.set_track_reference_position_derivatives(False)
    track.set_apply_tracked_states_to_guess(True)
    track.set_control_effort_weight(request["effort_weight"])
    track.set_initial_time(float(t[0]))
    track.set_final_time(float(t[-1]))
    track.set_mesh_interval(float(t[-1] - t[0]) / request["nodes"])
    study = track.initialize()
    folder.cleanup()
    problem = study.updProblem()
    if muscles:  # each activation starts at its excitation, as collocate's and fdbench's simulation start
        start = osim.MocoInitialActivationGoal("initial_activation")
        start.setMode("endpoint_constraint")
        problem.addGoal(start)
    for path, angle, rate in zip(paths, z[0], zd[0]):
        problem.setStateInfo(path + "/value", osim.MocoBounds(-STATE_BOUND, STATE_BOUND),
                             osim.MocoInitialBounds(float(angle)))
        problem.setStateInfo(path + "/speed", osim.MocoBounds(-10 * STATE_BOUND, 10 * STATE_BOUND),
                             osim.MocoInitialBounds(float(rate)))
    solver = osim.MocoCasADiSolver.safeDownCast(study.updSolver())
    solver.set_num_mesh_intervals(int(request["nodes"]))
    solver.set_transcription_scheme("hermite-simpson")
    solver.set_optim_convergence_tolerance(float(request["tolerance"]))
    solver.set_optim_constraint_tolerance(float(request["tolerance"]))
    solver.set_optim_max_iterations(int(request["max_iter"]))
    solver.set_parallel(0)
    solver.set_verbosity(0)
    solver.set_optim_ipopt_print_level(0)
    began = time.perf_counter()
    solution = study.solve()
    ended = time.perf_counter()
    solve_s, run_s = ended - began, ended - run_began
    solution.unseal()  # a failed solve's last iterate is replayed too, as collocate's is
    states = solution.getStatesTrajectoryMat()
    labels = list(solution.getStateNames())
    columns = lambda suffix: [labels.index(path + suffix) for path in paths]  # noqa: E731
    control_labels = list(solution.getControlNames())
    control = lambda names_: solution.getControlsTrajectoryMat()[:, [control_labels.index(f"/forceset/{n}")  # noqa: E731
                                                                      for n in names_]]
    answer = {"t": (np.asarray(solution.getTimeMat()) - shift).tolist(),
              "angles": states[:, columns("/value")].tolist(), "speeds": states[:, columns("/speed")].tolist(),
              "status": solution.getStatus(), "iterations": int(solution.getNumIterations()),
              "objective": float(solution.getObjective()), "solve_s": solve_s, "run_s": run_s,
              "solver_duration_s": float(solution.getSolverDuration())}
    if not muscles:
        return {**answer, "controls": control([n + "_torque" for n in names]).tolist()}
    forces = optimal_forces(osim, model, reserves)
    reserve = np.zeros((len(answer["t"]), len(names)))
    for (name, coordinate), force in zip(reserves, forces):
        if coordinate in names:  # a user's actuator on a coordinate fdbench's description lacks: not a torque here
            reserve[:, names.index(coordinate)] += force * control([name])[:, 0]
    return {**answer, "excitation": control(muscles).tolist(), "reserve": reserve.tolist(),
            "activation": states[:, [labels.index(f"/forceset/{m}/activation") for m in muscles]].tolist(),
            "reserve_names": [name for name, _ in reserves], "reserve_coordinates": [c for _, c in reserves],
            "reserve_forces": forces, "muscle_kinds": kinds}
