"""Commands that carry out one run: inverse, simulate, control, collocate, optimize, methods."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .app import BadInput, MAX_THREADS, app
from .options import (
    Alpha, Atol, Budget, Db, Dt, Format, Gradient, Hidden, Integrator, Kinematics, Knots, NoiseSeed, Omega,
    Output, PenaltyWeight, Popsize, Quiet, Rtol, SaveHistory, Sigma0, Terms, Threads, Xi, _common,
    _noise_seed, _spec_inputs, _with_conditions,
)
from .common import (
    OUTPUT_LABELS, _bracketed, _check_finite, _check_gradient, _check_method_options, _check_outputs,
    _check_store, _emit, _finish, _methods_text, _parse_hidden, _progress, _save_history, _say, _store,
    _table_text, _validated,
)


@app.command()
@_with_conditions
def inverse(
    kinematics: Kinematics = None,
    seed: NoiseSeed = 0,
    fmt: Format = "table",
    output: Output = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Inverse dynamics (eq. 3): the joint torques that should produce the desired motion, with the nominal model.

    The table and JSON give a summary; --format csv gives the whole history on the motion's samples (eq. 5: 1001 rows) as a motion file that --motion and --torque-file read back: t (s), theta (deg), theta_vel (deg/s), theta_acc (deg/s^2), torque (N m); another model: t, then <joint>, <joint>_vel, <joint>_acc, <joint>_torque for each of its joints."""
    from ..api import inverse_run
    from ..spec import RunSpec

    _check_outputs(fmt, output=output, inputs=_spec_inputs(conditions, kinematics))
    spec = _validated(RunSpec(command="simulate", **_noise_seed(conditions, seed),
                              **_common(kinematics, "rk4", 1e-3, 1e-6, 1e-9, 1e7, 1.0, 10.0, conditions)))
    record, header, rows = inverse_run(spec)
    if fmt == "csv":
        _emit(_table_text(header, rows), output)
        return
    _finish(record, fmt, output, "fdbench inverse", quiet)


@app.command()
@_with_conditions
def simulate(
    torque_file: Annotated[Optional[Path], typer.Option("--torque-file", help="CSV with columns t (s) and the joint's torque (N m): theta, theta_torque or torque for the forearm, one column per joint (<joint> or <joint>_torque) for another model; covering the motion's span (eq. 5: [0, 1] s), linearly interpolated. Default: the inverse-dynamics torque.")] = None,
    params: Annotated[Optional[Path], typer.Option("--params", help="Parameters saved by 'fdbench optimize --save-params'.")] = None,
    kinematics: Kinematics = None,
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    seed: NoiseSeed = 0,
    fmt: Format = "table",
    output: Output = None,
    save_history: SaveHistory = None,
    db: Db = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Open-loop forward dynamics (eq. 12) driven by a torque history: by default the inverse-dynamics torque, whose drift from the desired motion motivates the paper."""
    from ..spec import RunSpec

    _check_outputs(fmt, output=output, save_history=save_history, db=db,
                   inputs=_spec_inputs(conditions, kinematics, **{"--torque-file": torque_file, "--params": params}))
    if torque_file is not None and params is not None:
        raise BadInput("--torque-file and --params: give one of them, not both")
    spec = _validated(RunSpec(command="simulate", **_noise_seed(conditions, seed),
                              **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)))
    from ..api import run_simulation
    from ..files import BadFile

    _check_store(db)
    try:
        outcome = run_simulation(spec, torque_file=torque_file, params_file=params)
    except BadFile as exc:
        raise BadInput(str(exc)) from None
    _store(outcome, outcome.extra.get("spec", spec), db, quiet)  # stored before any output is written
    _save_history(outcome, save_history)
    _finish(outcome.record, fmt, output, "fdbench simulate", quiet)


@app.command()
@_with_conditions
def control(
    ctx: typer.Context,
    controller: Annotated[str, typer.Option("--controller", help="pd (the paper's), computed-torque, lqr, or one registered by a plugin (see 'fdbench methods'); NAME[KEY=VALUE,...] passes any option its class takes, e.g. 'lqr[q_angle=1e5]'.")] = "pd",
    kp: Annotated[Optional[float], typer.Option("--kp", help="pd: proportional gain, N m/rad, on every joint (default: the paper's 80 on the forearm; on another model 80 per 0.04 kg m^2 of each joint's inertia).", show_default=False)] = None,
    kd: Annotated[Optional[float], typer.Option("--kd", help="pd: derivative gain, N m s/rad, on every joint (default: the paper's 0.3 on the forearm; on another model 0.3 per 0.04 kg m^2 of each joint's inertia).", show_default=False)] = None,
    bandwidth: Annotated[float, typer.Option("--bandwidth", help="computed-torque: error-dynamics natural frequency omega_n, rad/s.")] = 20.0,
    damping: Annotated[float, typer.Option("--damping", help="computed-torque: error-dynamics damping ratio zeta.")] = 1.0,
    q_angle: Annotated[float, typer.Option("--q-angle", help="lqr: weight of the squared angle error, rad^-2 (1e4: 0.01 rad costs as much as 1 N m).")] = 1e4,
    q_rate: Annotated[float, typer.Option("--q-rate", help="lqr: weight of the squared rate error, s^2 rad^-2.")] = 1.0,
    r_torque: Annotated[float, typer.Option("--r-torque", help="lqr: weight of the squared torque correction, (N m)^-2; positive.")] = 1.0,
    kinematics: Kinematics = None,
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Format = "table",
    output: Output = None,
    save_history: SaveHistory = None,
    db: Db = None,
    seed: NoiseSeed = 0,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Feedback control: PD with computed feedforward (eqs. 13-14, the default), computed-torque control or time-varying LQR about the desired motion."""
    from ..api import run
    from ..spec import control_spec

    _check_outputs(fmt, output=output, save_history=save_history, db=db, inputs=_spec_inputs(conditions, kinematics))
    from ..controllers import CONTROLLERS

    options = dict(kp=kp, kd=kd, bandwidth=bandwidth, damping=damping, q_angle=q_angle, q_rate=q_rate, r_torque=r_torque)
    controller, options = _bracketed(ctx, controller, "--controller", options, CONTROLLERS, "controller")
    _check_controller(controller, options)

    options = _applicable(ctx, options, CONTROLLERS, controller, "--controller")
    spec = _validated(control_spec(kp, kd, controller, options, **_noise_seed(conditions, seed),
                                   **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)))
    if controller == "lqr":
        _casadi_ready("control --controller lqr")
    _check_store(db)
    outcome = run(spec)
    _store(outcome, spec, db, quiet)  # the run is stored before any output is written
    _save_history(outcome, save_history)
    _finish(outcome.record, fmt, output, "fdbench control", quiet)


def _casadi_ready(command: str) -> None:
    """Import casadi before any work: bad input (one line naming LD_LIBRARY_PATH) where another
    libcasadi found first clashes with it; one line naming the package where it is missing."""
    from ..casadi_loader import CasadiClash, casadi

    try:
        casadi()
    except CasadiClash as exc:
        raise BadInput(str(exc)) from None
    except ImportError as exc:
        raise ImportError(f"'fdbench {command}' needs casadi (pip install casadi): {exc}") from None


def _applicable(ctx: typer.Context, options: dict, registry, name: str, choice: str) -> dict:
    """Of a command's method options (parameter name: value), those the method ``name`` takes.
    One the user gave (on the command line or from the environment, not a default) that it does
    not take is bad input: ``--kp`` does not apply to ``--controller lqr``."""
    from ..method_options import taken_options

    taken = taken_options(registry, name)
    for key in options:
        source = ctx.get_parameter_source(key)
        if key not in taken and getattr(source, "name", None) in ("COMMANDLINE", "ENVIRONMENT"):
            allowed = ", ".join("--" + k.replace("_", "-") for k in taken if k in options) or "no options"
            raise BadInput(f"--{key.replace('_', '-')} does not apply to {choice} {name} (it takes {allowed})")
    return {k: v for k, v in options.items() if k in taken}


def _check_controller(name: str, options: dict) -> None:
    """An unknown --controller, or an out-of-range option of any registered controller that
    takes it (``--bandwidth -1`` with ``--controller pd`` too), is bad input."""
    import inspect

    from ..controllers import CONTROLLERS
    from ..registry import UnknownName

    try:
        CONTROLLERS[name]
    except UnknownName as exc:
        raise BadInput(f"--controller: {exc}") from None
    for _, cls in CONTROLLERS.items():
        accepted = inspect.signature(cls).parameters
        given = {k: v for k, v in options.items() if k in accepted and v is not None}
        if given:
            try:
                cls(**given)
            except ValueError as exc:
                raise BadInput(str(exc)) from None


@app.command()
@_with_conditions
def collocate(
    nodes: Annotated[int, typer.Option("--nodes", help="Collocation intervals N over the motion's span (eq. 5: [0, 1] s), >= 2.")] = 100,
    scheme: Annotated[str, typer.Option("--scheme", help="Transcription: hermite-simpson (piecewise-quadratic torque) or trapezoidal (piecewise-linear).")] = "hermite-simpson",
    regularization: Annotated[float, typer.Option("--regularization", help="Weight of the integral of torque^2 beside the integral of the squared rotation error in deg^2: deg^2/(N m)^2; 1e-6 makes 1 N m weigh as much as 0.001 deg.")] = 1e-6,
    max_iter: Annotated[int, typer.Option("--max-iter", help="IPOPT iteration limit, in [1, 1000000].")] = 1000,
    max_time: Annotated[float, typer.Option("--max-time", help="IPOPT CPU-time limit, s.")] = 60.0,
    residual_force_weight: Annotated[Optional[float], typer.Option("--residual-force-weight", help="A floating base's residual force: weight of the integral of FX^2 + FY^2 beside the squared errors (deg^2, and cm^2 of translations), deg^2/N^2; default 1e-3 with --loads, the --regularization without (the residuals then carry the body's weight).", show_default=False)] = None,
    residual_moment_weight: Annotated[Optional[float], typer.Option("--residual-moment-weight", help="A floating base's residual moment: weight of the integral of MZ^2, deg^2/(N m)^2; default 1e-3 with --loads, the --regularization without.", show_default=False)] = None,
    save_torque: Annotated[Optional[Path], typer.Option("--save-torque", help="Write the torque found as CSV (t, torque; another model: t and one column per joint, e.g. t, shoulder, elbow) to FILE, readable by 'fdbench simulate --torque-file'.")] = None,
    kinematics: Kinematics = None,
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Format = "table",
    output: Output = None,
    save_history: SaveHistory = None,
    db: Db = None,
    seed: NoiseSeed = 0,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Direct-collocation tracking (as OpenSim Moco, bioptim, Drake): states and accelerations are the unknowns of one sparse problem solved by IPOPT, the torque their inverse dynamics (external loads of --loads included); the torque found is then replayed by fdbench's forward simulation, whose indicators are reported."""
    from ..api import run
    from ..spec import collocate_spec

    _check_outputs(fmt, output=output, save_history=save_history, save_torque=save_torque, db=db,
                   inputs=_spec_inputs(conditions, kinematics))
    spec = _validated(collocate_spec(nodes, scheme, regularization, max_iter, max_time, residual_force_weight,
                                     residual_moment_weight, **_noise_seed(conditions, seed),
                                     **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)))
    _casadi_ready("collocate")
    _check_store(db)
    outcome = run(spec)
    _store(outcome, spec, db, quiet)  # the run is stored before any output is written
    _save_history(outcome, save_history)
    if save_torque is not None:
        from ..files import write_atomic

        write_atomic(save_torque, _collocation_torque_text(outcome.extra["collocation"], spec), "--save-torque")
    _finish(outcome.record, fmt, output, "fdbench collocate", quiet)


def _collocation_torque_text(solution, spec) -> str:
    """The torque found on the half-step grid of the run's RK4 over the motion's span (so that
    'simulate --torque-file' with the same --dt replays exactly what collocate replayed), as CSV
    t (s) and one torque column per joint (N m): t, theta for the forearm; t, shoulder, elbow for the arm."""
    import numpy as np

    from ..files import csv_text
    from ..integrate import steps
    from ..models import joints

    duration = spec.motions()[0].duration
    half = np.linspace(0.0, duration, 2 * steps(spec.dt, duration) + 1)
    torque = solution.torque_samples(half).reshape(len(half), -1)
    names = list(joints(spec.model_name))
    return csv_text(["t", *names], ([f"{t:.17g}", *(f"{q:.17g}" for q in row)] for t, row in zip(half, torque)))


@app.command()
def methods():
    """List the registered torque parameterisations, optimisers, controllers and models, one line each."""
    _emit(_methods_text(), None)


@app.command()
@_with_conditions
def optimize(
    ctx: typer.Context,
    torque: Annotated[str, typer.Option("--torque", help="Torque parameterisation (see 'fdbench methods'); NAME[KEY=VALUE,...] passes any option its class takes, e.g. 'cs[knots=21]'.")] = "cs",
    opt: Annotated[str, typer.Option("--opt", help="Optimiser (see 'fdbench methods'); NAME[KEY=VALUE,...] passes any option its class takes, e.g. 'cmaes[sigma0=0.1,popsize=12]'.")] = "bfgs",
    feedforward: Annotated[bool, typer.Option("--feedforward/--no-feedforward", help="Add the inverse-dynamics torque (Table 3) or not (Table 2).")] = False,
    budget: Budget = 200,
    seed: Annotated[int, typer.Option("--seed", help="Seed of every stochastic step; the same seed gives the same numbers.")] = 0,
    hidden: Hidden = "4",
    knots: Knots = None,
    terms: Terms = 4,
    sigma0: Sigma0 = None,
    popsize: Popsize = None,
    gradient: Gradient = "fd",
    threads: Threads = None,
    penalty_weight: PenaltyWeight = 1.0,
    residual_weight: Annotated[Optional[float], typer.Option("--residual-weight", help="On a floating base: eq. 18's residual term, deg per N of the base's residual force RMS (FX, FY) and per N m of its moment's (MZ), over the torque history; default 0.01 with --loads, 0 without (the residuals then carry the body's weight).", show_default=False)] = None,
    kinematics: Kinematics = None,
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Format = "table",
    output: Output = None,
    save_history: SaveHistory = None,
    history: Annotated[Optional[Path], typer.Option("--save-convergence", "--history", help="Write the convergence, the best-so-far objective per evaluation, as CSV to FILE. --history is an older name.")] = None,
    save_params: Annotated[Optional[Path], typer.Option("--save-params", help="Write the best parameters as JSON to FILE (reusable by 'fdbench simulate --params').")] = None,
    list_methods: Annotated[bool, typer.Option("--list", help="List the registered torques and optimisers and exit.")] = False,
    db: Db = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Forward dynamic optimisation (section 4): tune a parameterised torque history so the simulated rotation tracks the desired one (objective of eq. 18)."""
    if list_methods:
        _emit(_methods_text(), None)
        return
    from ..api import run
    from ..spec import optimize_spec

    _check_outputs(fmt, output=output, save_history=save_history, history=history, save_params=save_params, db=db,
                   inputs=_spec_inputs(conditions, kinematics))
    _check_finite(sigma0=sigma0 if sigma0 is not None else 1.0, penalty_weight=penalty_weight)
    from ..optimizers import OPTIMIZERS
    from ..torques import TORQUES

    torque, torque_options = _bracketed(ctx, torque, "--torque", {"hidden": _parse_hidden(hidden), "knots": knots,
                                                                  "terms": terms}, TORQUES, "torque")
    opt, optimizer_options = _bracketed(ctx, opt, "--opt", {"sigma0": sigma0, "popsize": popsize}, OPTIMIZERS,
                                        "optimizer")
    _check_method_options(torque_options, optimizer_options)

    torque_options = _applicable(ctx, torque_options, TORQUES, torque, "--torque")
    optimizer_options = _applicable(ctx, optimizer_options, OPTIMIZERS, opt, "--opt")
    _check_gradient(gradient)
    if threads is not None and not 1 <= threads <= MAX_THREADS:
        raise BadInput(f"--threads must be an integer in [1, {MAX_THREADS}], got {threads}")
    spec = _validated(optimize_spec(
        torque, opt, feedforward, seed, budget, torque_options=torque_options, optimizer_options=optimizer_options,
        penalty_weight=penalty_weight, gradient=gradient, **_residual(residual_weight),
        **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions),
    ))
    _check_store(db)
    if opt == "cmaes":
        from ..population import set_threads

        set_threads(threads)
    with _progress(quiet, f"{torque} + {opt}") as progress:
        outcome = run(spec, on_evaluation=progress.update, on_start=progress.start)
    if "hidden_fits" in outcome.extra:
        fits = ", ".join(f"{n}: {err:.2e}" for n, err in outcome.extra["hidden_fits"])
        _say(quiet, f"--hidden auto: fit RMSE / torque range by neurons: {fits}")
    _store(outcome, spec, db, quiet)  # the run is stored before any output is written
    _save_history(outcome, save_history)
    if history is not None:
        from ..files import csv_text, write_atomic

        write_atomic(history, csv_text(["evaluation", "best_objective"], enumerate(outcome.history, start=1)), OUTPUT_LABELS["history"])
    if save_params is not None:
        from ..files import write_atomic
        from ..params_file import params_json

        write_atomic(save_params, params_json(spec, outcome), "--save-params")
    _finish(outcome.record, fmt, output, "fdbench optimize", quiet)


def _residual(weight) -> dict:
    """The spec field of ``--residual-weight`` (left out when not given, so the default follows the loads)."""
    if weight is None:
        return {}
    _check_finite(residual_weight=weight)
    return {"residual_weight": weight}
