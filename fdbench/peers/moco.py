"""The ``moco`` peer: OpenSim Moco's MocoTrack, torque-driven, on ``fdbench collocate``'s model,
motion and mesh, its torque replayed by fdbench's forward simulation as ``collocate``'s is.

CoordinateActuators (1 N m, unbounded); the desired states in a .sto (speeds weighted 0, the guess
only); squared angle errors (rad^2) plus ``regularization`` / (180/pi)^2 times squared torques (as
``collocate`` in deg); initial state fixed; Hermite-Simpson on ``nodes`` intervals; IPOPT with
``tolerance``, serial. The torque is interpolated as ``collocate``'s (piecewise quadratic)."""

from __future__ import annotations

import math
import time

import numpy as np

from .child import call, coordinate_paths, loads_file, model_from, radians_table, torque_driven

DEG2 = (180.0 / math.pi) ** 2
DEFAULT_TOLERANCE = 1e-4  # IPOPT's convergence and constraint tolerance in MocoTrack (Moco's own default is 1e-2)
STATE_BOUND = 20.0  # rad (and 10x that in rad/s): bounds loose enough never to bind
SUMMARY = ("OpenSim Moco's MocoTrack, torque-driven (CoordinateActuators), Hermite-Simpson on the mesh of "
           "'fdbench collocate', tracking the same motion's angles with the same torque regularisation; its "
           "torque is replayed by fdbench's forward simulation exactly as collocate's is")


def run(spec):
    """The peer's run (``RunOutcome``): MocoTrack in a child process, its torque replayed by fdbench;
    Moco's own RMSE_rot, status, iterations and times beside the replay's indicators."""
    from ..collocation import CollocationResult  # lazy: OpenSim's child imports this module, not the engine
    from ..models import joints
    from ..run_inputs import nominal as description
    from .common import desired, loads_request, osim_texts, replay, warm_up

    options = dict(spec.method_options)
    names = joints(spec.model_name)
    nominal, _ = osim_texts(spec)  # Moco tracks with the nominal model; the replay simulates the plant
    samples = spec.motions()[0].samples
    z, zd, _ = desired(spec, samples)
    request = {"peer": "moco", "nominal": nominal, "coordinates": list(names), "t": np.asarray(samples).tolist(),
               "z": z.tolist(), "zd": zd.tolist(), "nodes": options["nodes"],
               "effort_weight": options["regularization"] / DEG2, "tolerance": options["tolerance"],
               "max_iter": options["max_iter"], "loads": loads_request(spec)}
    answer = call(request)
    warm_up(spec)
    times, controls = np.array(answer["t"]), np.array(answer["controls"]).reshape(len(answer["t"]), len(names))
    solution = _as_collocation(CollocationResult, times, controls, answer)
    began = time.perf_counter()
    outcome = replay(spec, solution.torque_function())
    replay_s = time.perf_counter() - began
    truth = spec.motions()[1]
    mesh = solution.t
    angles = np.array(answer["angles"]).reshape(len(times), len(names))[:: 2 if solution.torque_mid is not None else 1]
    wanted = np.asarray(truth(mesh)[0]).reshape(len(mesh), len(names))
    own = float(np.sqrt(np.mean(np.degrees(angles - wanted) ** 2)))
    record = outcome.record
    success = answer["status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    record.update(torque="moco", evaluations=1, runtime_s=answer["run_s"] + replay_s, peer="moco",
                  nodes=options["nodes"], scheme="hermite-simpson", regularization=options["regularization"],
                  tolerance=options["tolerance"], collocation_rmse_rot_deg=own, ipopt_status=answer["status"],
                  ipopt_iterations=answer["iterations"], solve_time_s=answer["solve_s"], moco_run_s=answer["run_s"],
                  moco_solver_duration_s=answer["solver_duration_s"], replay_time_s=replay_s,
                  opensim_version=answer["version"])
    if not success:
        record.update(status="collocation_failed",
                      message=f"MocoTrack did not solve the problem: {answer['status']} after {answer['iterations']} "
                              f"iterations; the replay of its last iterate: {record.get('message')}")
    else:
        record["message"] = (f"MocoTrack (OpenSim {answer['version']}): {answer['status']} in {answer['iterations']} "
                             f"iterations; replay: {record.get('message')}")
    muscles = len(description(spec).muscles)
    if muscles:  # MocoTrack muscle-driven is not done yet: say that this one is not
        record["message"] += f"; torque-driven: the model's {muscles} muscles left out"
    outcome.extra["collocation"] = solution
    return outcome


def _as_collocation(result_class, times: np.ndarray, controls: np.ndarray, answer: dict):
    """Moco's solution as a ``collocation.CollocationResult`` (node arrays (N + 1, J) and midpoint
    torques (N, J)), so that its torque is interpolated as collocate's: Hermite-Simpson gives the
    mesh points and the interval midpoints (2 N + 1 times)."""
    angles = np.array(answer["angles"]).reshape(controls.shape)
    speeds = np.array(answer["speeds"]).reshape(controls.shape)
    if len(times) % 2 == 1 and np.allclose(times[1::2], (times[:-1:2] + times[2::2]) / 2):
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
    model = model_from(osim, request["nominal"])
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
    controls = solution.getControlsTrajectoryMat()[:, [control_labels.index(f"/forceset/{n}_torque") for n in names]]
    return {"t": (np.asarray(solution.getTimeMat()) - shift).tolist(), "controls": controls.tolist(),
            "angles": states[:, columns("/value")].tolist(), "speeds": states[:, columns("/speed")].tolist(),
            "status": solution.getStatus(), "iterations": int(solution.getNumIterations()),
            "objective": float(solution.getObjective()), "solve_s": solve_s, "run_s": run_s,
            "solver_duration_s": float(solution.getSolverDuration())}
