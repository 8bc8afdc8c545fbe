"""One runner per command of the paper's forearm (control, optimize, collocate, simulate, inverse):
``run(spec)`` carries a spec out and turns it into a flat record; every other model's runs are
``fdbench.multibody.runs``' (``RunSpec._runs``)."""

from __future__ import annotations

import hashlib
import time

import numpy as np

from . import __version__
from .integrate import SimulationResult
from .method_options import options_text
from .records import RunOutcome, base_record, explained, fill_result
from .spec import RunSpec


def run(spec: RunSpec, on_evaluation=None, on_start=None) -> RunOutcome:
    """Carry out a control or optimisation run. ``on_evaluation(count, best)`` reports progress;
    ``on_start(budget)`` is called once compilation and imports are done."""
    spec.validate()
    if spec.command == "peer":  # OpenSim's and Moco's runs (fdbench.peers)
        from .peers import run as run_peer

        return explained(run_peer(spec), spec)
    if spec._runs() is not None:
        return explained(spec._runs().run(spec, on_evaluation, on_start), spec)
    if spec.command == "control":
        return explained(_run_control(spec), spec)
    if spec.command == "optimize":
        return explained(_run_optimize(spec, on_evaluation, on_start), spec)
    if spec.command == "collocate":
        return explained(_run_collocate(spec), spec)
    raise ValueError("simulate runs are carried out by run_simulation")


def _run_control(spec: RunSpec) -> RunOutcome:
    if spec.controller not in (None, "pd"):
        return _run_controller(spec)
    from .control import feedforward
    from .integrate import simulate, warm_up

    settings = spec.settings()
    warm_up()
    start = time.perf_counter()
    inverse = spec.reference()
    result = simulate(feedforward(settings), settings, spec.kp, spec.kd)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    record.update(torque="id", kp=spec.kp, kd=spec.kd, evaluations=1, runtime_s=runtime, controller="pd")
    return RunOutcome(record, result, inverse)


def _run_controller(spec: RunSpec) -> RunOutcome:
    """A registered controller other than the paper's PD: its design (feedback gains, Riccati
    solution) is part of the runtime."""
    from .control import track
    from .controllers import make_controller
    from .integrate import warm_up

    settings = spec.settings()
    controller = make_controller(spec.controller, **dict(spec.method_options))
    warm_up()
    controller.warm_up()
    start = time.perf_counter()
    inverse = spec.reference()
    result = track(controller, settings)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    record.update(torque=controller.feedforward_label, evaluations=1, runtime_s=runtime, controller=spec.controller,
                  controller_options=options_text(spec.method_options))
    return RunOutcome(record, result, inverse)


def _run_collocate(spec: RunSpec) -> RunOutcome:
    """Direct collocation, then the torque found replayed by fdbench's own forward simulation:
    the three indicators are the replay's; the collocation's own tracking error, IPOPT's status,
    iterations and solve time stand beside them. ``extra['collocation']`` holds the solution."""
    from .collocation import collocate, record_fields
    from .integrate import simulate, warm_up

    settings = spec.settings()
    options = dict(spec.method_options)
    warm_up()
    import casadi  # noqa: F401  (its import is not part of the runtime)

    start = time.perf_counter()
    inverse = spec.reference()
    solution = collocate(settings, **options)
    result = simulate(solution.torque_function(), settings)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    theta_d = np.interp(solution.t, inverse.t, inverse.theta)
    own = float(np.sqrt(np.mean(np.degrees(solution.theta - theta_d) ** 2)))
    record.update(runtime_s=runtime, **record_fields(solution, options, own, result.message))
    return RunOutcome(record, result, inverse, extra={"collocation": solution})


def _run_optimize(spec: RunSpec, on_evaluation, on_start) -> RunOutcome:
    from .integrate import warm_up
    from .optimizers import make_optimizer
    from .problem import TrackingProblem
    from .torques import make_torque

    from .torques import TORQUES

    settings = spec.settings()
    optimizer = make_optimizer(spec.optimizer, **dict(spec.optimizer_options))
    warm_up()
    optimizer.warm_up()
    TORQUES[spec.torque].warm_up()
    if spec.gradient == "exact":
        from .gradient import warm_up as gradient_warm_up

        gradient_warm_up()
    if settings.integrator == "rk4":  # every evaluation on RK4 runs the population kernel, alone or together
        from .population import warm_up as population_warm_up

        population_warm_up()
    if on_start:
        on_start(spec.budget)
    start = time.perf_counter()
    torque_options = dict(spec.torque_options)
    extra = {}
    if torque_options.get("hidden") == "auto":
        from .inverse import inverse_dynamics
        from .torques.ann import select_hidden

        inv = inverse_dynamics(None, settings.nominal_model, settings.kinematics)
        torque_options["hidden"], extra["hidden_fits"] = select_hidden(inv.t, inv.torque)
    torque = make_torque(spec.torque, **torque_options)
    problem = TrackingProblem(torque, settings, spec.feedforward, spec.penalty_weight)
    gradient = problem.value_and_gradient_scaled if spec.gradient == "exact" else None
    batch = problem.objectives_scaled if problem.batched else None
    opt = optimizer.minimize(problem.objective_scaled, problem.x0, spec.budget, spec.seed, on_evaluation, gradient,
                             batch)
    params = opt.x * problem.scale
    result = problem.simulate(params)
    runtime = time.perf_counter() - start
    reference = spec.reference()
    record = fill_result(base_record(spec), result, reference)
    record.update(
        torque=spec.torque, optimizer=spec.optimizer, seed=spec.seed, budget=spec.budget,
        evaluations=opt.evaluations, best_objective=opt.fun, stop_reason=opt.stop_reason,
        n_params=problem.n_params, runtime_s=runtime, penalty_weight=spec.penalty_weight,
        torque_options=options_text(sorted(torque_options.items())),
        optimizer_options=options_text(spec.optimizer_options), gradient=spec.gradient,
    )
    record["initial_objective"] = problem.objective(problem.p0)
    return RunOutcome(record, result, reference, opt.history, params, extra)


def run_simulation(spec: RunSpec, torque_file=None, params_file=None) -> RunOutcome:
    """Open-loop forward dynamics driven by the inverse-dynamics torque, a CSV torque history
    or saved optimisation parameters. Bad files raise ``files.BadFile``."""
    from dataclasses import replace

    from .integrate import simulate, warm_up
    from .inverse import Feedforward

    if spec._runs() is not None:
        return explained(spec._runs().run_simulation(spec, torque_file, params_file), spec)
    settings = spec.settings()
    if torque_file is not None:
        from .files import read_torque_csv

        t_file, q_file = read_torque_csv(torque_file, duration=settings.motion.duration)
        torque, label = (lambda t: np.interp(t, t_file, q_file)), f"file:{torque_file}"
        digest = hashlib.sha256(t_file.tobytes() + q_file.tobytes()).hexdigest()
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--torque-file", digest),))))
    elif params_file is not None:
        from .params_file import load_torque

        torque, label, digest = load_torque(params_file, settings)
        spec = replace(spec, inputs=tuple(sorted(spec.inputs + (("--params", digest),))))
    else:
        torque, label = Feedforward(settings.nominal_model, settings.kinematics), "id"
    warm_up()
    start = time.perf_counter()
    inverse = spec.reference()
    result = simulate(torque, settings)
    runtime = time.perf_counter() - start
    record = fill_result(base_record(spec), result, inverse)
    record.update(torque=label, evaluations=1, runtime_s=runtime)
    return explained(RunOutcome(record, result, inverse), spec)


def replay(spec: RunSpec, params) -> SimulationResult:
    """The simulation of a stored optimisation run's best parameters (for figures)."""
    from .problem import TrackingProblem

    if spec._runs() is not None:
        return spec._runs().replay(spec, params)
    from .torques import make_torque

    settings = spec.settings()
    options = dict(spec.torque_options)
    if options.get("hidden") == "auto":
        options["hidden"] = (len(params) - 1) // 3
    problem = TrackingProblem(make_torque(spec.torque, **options), settings, spec.feedforward, spec.penalty_weight)
    return problem.simulate(np.asarray(params, dtype=float))


INVERSE_HEADER = ("t", "theta", "theta_vel", "theta_acc", "torque")  # s, deg, deg/s, deg/s^2, N m


def inverse_run(spec: RunSpec) -> tuple[dict, list, np.ndarray]:
    """Inverse dynamics of the desired motion with the nominal model: (record, CSV header, rows on
    the motion's samples) with the columns of a motion file (``INVERSE_HEADER``), angles in degrees."""
    if spec._runs() is not None:
        return spec._runs().inverse_run(spec)
    from .inverse import inverse_dynamics

    settings = spec.settings()
    desired, _ = spec.motions()
    start = time.perf_counter()
    inv = inverse_dynamics(desired.samples, settings.nominal_model, desired)
    runtime = time.perf_counter() - start
    record = {
        "command": "inverse", "kinematics": spec.kinematics, **spec.describe(),
        "theta_start_deg": float(np.degrees(inv.theta[0])), "theta_end_deg": float(np.degrees(inv.theta[-1])),
        "torque_min_nm": float(inv.torque.min()), "torque_max_nm": float(inv.torque.max()),
        "torque_start_nm": float(inv.torque[0]), "torque_end_nm": float(inv.torque[-1]),
        "torque_rms_nm": float(np.sqrt(np.mean(inv.torque**2))), "runtime_s": runtime,
        "fdbench_version": __version__,
    }
    rows = np.column_stack([inv.t, *np.degrees([inv.theta, inv.theta_dot, inv.theta_ddot]), inv.torque])
    return record, list(INVERSE_HEADER), rows
