"""Commands that carry out one run: inverse, simulate, control, collocate, optimize, methods."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .app import BadInput, app, bad_input
from .common import (
    OUTPUT_LABELS, Progress, applicable_options, bracketed, check_choice, check_count, check_finite, check_gradient,
    check_method_ranges, check_outputs, emit, finish, history_csv, methods_text, say, shooting_methods, validated,
)
from .conditions import noise_seed, spec_inputs, with_conditions
from .options import (
    MAX_THREADS, Format, Kinematics, MethodValues, NoiseSeed, Optimisation, Output, Quiet, RunOutputs, Simulation,
    Threads, methods_command, option_group, with_groups,
)


@option_group(None)
class OneRun:
    """A command of one run: its motion, the seed of its noise, how it integrates, where it writes."""

    kinematics: Kinematics = None
    seed: NoiseSeed = 0
    sim: Simulation = None
    out: RunOutputs = None

    def check(self, conditions: dict, inputs: dict | None = None, **paths) -> None:
        """The outputs ``out`` and ``paths`` checked before any work, against the motion's, the
        model's and the command's ``inputs`` files."""
        self.out.check(spec_inputs(conditions, self.kinematics, **(inputs or {})), **paths)

    def fields(self, conditions: dict) -> dict:
        """The RunSpec fields of the run under ``conditions``."""
        return {**noise_seed(conditions, self.seed), **self.sim.spec_fields(self.kinematics, conditions)}


@app.command()
@with_conditions
def inverse(
    kinematics: Kinematics = None,
    seed: NoiseSeed = 0,
    fmt: Format = "table",
    output: Output = None,
    quiet: Quiet = False,
    muscles: Annotated[bool, typer.Option("--muscles", help="Static optimisation of the model's muscles, as OpenSim's StaticOptimization: at each sample the activations in [0, 1] minimising the sum of activation^p (reserves' controls included) such that muscles plus one reserve per coordinate meet the inverse-dynamics torques; each muscle's force is its active force at the motion's length and speed with a rigid tendon. A model with [[actuators]]: they are the reserves, and a coordinate without one has none: the torque its muscles cannot meet is reported (<joint>_unmet, a warning naming the muscles at full activation). --format csv: t, <muscle>_activation, <muscle>_force (N), <joint>_reserve (N m), or <joint>_unmet.")] = False,
    activation_exponent: Annotated[Optional[float], typer.Option("--activation-exponent", help="With --muscles: the exponent p of the objective, > 0 (default 2: a quadratic programme solved exactly).", show_default=False)] = None,
    reserve_optimal_force: Annotated[Optional[float], typer.Option("--reserve-optimal-force", help="With --muscles: each reserve's torque per unit control (N m; N for a translation), > 0 (default 1, as OpenSim's arm26 examples). On a model with [[actuators]] it overrides every actuator's optimal_force (default: each actuator's own); coordinates without an actuator stay without a reserve.", show_default=False)] = None,
    passive_forces: Annotated[bool, typer.Option("--passive-forces", help="With --muscles: count the muscles' passive forces, which OpenSim's StaticOptimization leaves out.")] = False,
    fiber_force: Annotated[bool, typer.Option("--fiber-force", help="With --muscles: a muscle's active force as the fibre's, not times cos(pennation), as OpenSim 4.6's DeGrooteFregly2016Muscle gives it to StaticOptimization (to compare with OpenSim).")] = False,
    conditions: dict = None,
):
    """Inverse dynamics (eq. 3): the joint torques that should produce the desired motion, with the nominal model.

    The table and JSON give a summary; --format csv gives the whole history on the motion's samples (eq. 5: 1001 rows) as a motion file that --motion and --torque-file read back: t (s), theta (deg), theta_vel (deg/s), theta_acc (deg/s^2), torque (N m); another model: t, then <joint>, <joint>_vel, <joint>_acc, <joint>_torque for each of its joints."""
    from ..method_runs import inverse_run
    from ..spec import RunSpec

    check_outputs(fmt, output=output, inputs=spec_inputs(conditions, kinematics))
    so_options = _static_optimization_options(muscles, activation_exponent, reserve_optimal_force, passive_forces,
                                              fiber_force)
    spec = validated(RunSpec(command="simulate", **noise_seed(conditions, seed),
                             **Simulation().spec_fields(kinematics, conditions)))
    if muscles:
        from ..method_runs import muscles_run

        with bad_input(ValueError):
            record, header, rows = muscles_run(spec, **so_options)
        if record.get("unmet", "none") != "none":
            say(quiet, f"[yellow]warning:[/] torque the muscles cannot meet (no reserve): {record['unmet']}")
        title = "fdbench inverse --muscles"
    else:
        record, header, rows = inverse_run(spec)
        title = "fdbench inverse"
    if fmt == "csv":
        emit(history_csv(header, rows), output)
        return
    finish(record, fmt, output, title, quiet)


def _static_optimization_options(muscles: bool, exponent, reserve, passive: bool, fiber: bool) -> dict:
    """The options of ``inverse --muscles``, checked (bad input: given without --muscles, or <= 0)."""
    given = [name for name, value in (("--activation-exponent", exponent), ("--reserve-optimal-force", reserve),
                                      ("--passive-forces", passive or None), ("--fiber-force", fiber or None))
             if value is not None]
    if given and not muscles:
        raise BadInput(f"{given[0]} needs --muscles")
    exponent = 2.0 if exponent is None else exponent  # the reserves' force: None, the model's own (or 1)
    check_finite(activation_exponent=exponent, **({} if reserve is None else {"reserve_optimal_force": reserve}))
    for name, value in (("--activation-exponent", exponent), ("--reserve-optimal-force", reserve)):
        if value is not None and not value > 0:
            raise BadInput(f"{name} must be > 0, got {value:g}")
    return {"exponent": exponent, "reserve_optimal_force": reserve, "passive": passive, "along_tendon": not fiber}


@app.command()
@with_conditions
@with_groups
def simulate(
    torque_file: Annotated[Optional[Path], typer.Option("--torque-file", help="CSV with columns t (s) and the joint's torque (N m): theta, theta_torque or torque for the forearm, one column per joint (<joint> or <joint>_torque) for another model; covering the motion's span (eq. 5: [0, 1] s), linearly interpolated. Default: the inverse-dynamics torque. With --excitation-file on a model with [[actuators]]: columns only for the actuated coordinates, each the actuator's torque in N m (N for a translation), not its control; an actuated coordinate without a column is held at zero.")] = None,
    params: Annotated[Optional[Path], typer.Option("--params", help="Parameters saved by 'fdbench optimize --save-params'.")] = None,
    one: OneRun = None,
    conditions: dict = None,
    excitation_file: Annotated[Optional[Path], typer.Option("--excitation-file", help="CSV with columns t (s) and one per muscle of the model (its [[muscles]] names), each excitation in [0, 1], covering the motion's span, linear between samples: the muscles act on the joints, the torques are --torque-file's or zero (a model with [[actuators]]: torques on the actuated coordinates only); the run starts on the motion's first sample, each activation at its first excitation; --save-trajectory adds <muscle>_activation, _excitation and _force (N).")] = None,
):
    """Open-loop forward dynamics (eq. 12) driven by a torque history: by default the inverse-dynamics torque, whose drift from the desired motion motivates the paper."""
    from ..spec import RunSpec

    one.check(conditions, {"--torque-file": torque_file, "--params": params, "--excitation-file": excitation_file})
    if torque_file is not None and params is not None:
        raise BadInput("--torque-file and --params: give one of them, not both")
    spec = validated(RunSpec(command="simulate", **one.fields(conditions)))
    from ..method_runs import run_simulation

    one.out.check_store()
    outcome = run_simulation(spec, torque_file=torque_file, params_file=params, excitation_file=excitation_file,
                             warn=lambda text: say(one.out.quiet, f"[yellow]warning:[/] {text}"))
    one.out.deliver(outcome, outcome.extra.get("spec", spec), "fdbench simulate")


@app.command(cls=methods_command("controllers"))
@with_conditions
@with_groups
def control(
    ctx: typer.Context,
    controller: Annotated[str, typer.Option("--controller", help="pd (the paper's), computed-torque, lqr, or one registered by a plugin (see 'fdbench methods'); NAME[KEY=VALUE,...] passes any option its class takes, e.g. 'lqr[q_angle=1e5]'.")] = "pd",
    one: OneRun = None,
    methods: MethodValues = None,
    conditions: dict = None,
):
    """Feedback control: PD with computed feedforward (eqs. 13-14, the default), computed-torque control or time-varying LQR about the desired motion."""
    from ..controllers import CONTROLLERS
    from ..method_runs import run
    from ..spec import control_spec
    from ..registry import UnknownName

    one.check(conditions)
    (controller,), options = bracketed(ctx, [controller], "--controller", methods["controllers"], CONTROLLERS,
                                       "controller")
    with bad_input(UnknownName, lambda exc: f"--controller: {exc}"):
        CONTROLLERS[controller]
    check_method_ranges(CONTROLLERS, options)
    options = applicable_options(ctx, options, CONTROLLERS, controller, "--controller")
    spec = validated(control_spec(options.get("kp"), options.get("kd"), controller, options, **one.fields(conditions)))
    if controller == "lqr":
        _casadi_ready("control --controller lqr")
    one.out.check_store()
    one.out.deliver(run(spec), spec, "fdbench control")


def _casadi_ready(command: str) -> None:
    """Import casadi before any work: bad input (one line naming LD_LIBRARY_PATH) where another
    libcasadi found first clashes with it; one line naming the package where it is missing."""
    from ..casadi_loader import CasadiClash, casadi

    try:
        casadi()
    except CasadiClash as exc:  # an ImportError too
        raise BadInput(str(exc)) from None
    except ImportError as exc:
        raise ImportError(f"'fdbench {command}' needs casadi (pip install casadi): {exc}") from None


@app.command()
@with_conditions
@with_groups
def collocate(
    nodes: Annotated[int, typer.Option("--nodes", help="Collocation intervals N over the motion's span (eq. 5: [0, 1] s), >= 2.")] = 100,
    scheme: Annotated[str, typer.Option("--scheme", help="Transcription: hermite-simpson (piecewise-quadratic torque) or trapezoidal (piecewise-linear).")] = "hermite-simpson",
    regularization: Annotated[Optional[float], typer.Option("--regularization", help="Weight of the integral of torque^2 beside the integral of the squared rotation error in deg^2: deg^2/(N m)^2; default 1e-6, which makes 1 N m weigh as much as 0.001 deg (torques only).", show_default=False)] = None,
    max_iter: Annotated[int, typer.Option("--max-iter", help="IPOPT iteration limit, in [1, 1000000].")] = 1000,
    max_time: Annotated[float, typer.Option("--max-time", help="IPOPT CPU-time limit, s.")] = 60.0,
    residual_force_weight: Annotated[Optional[float], typer.Option("--residual-force-weight", help="A floating base's residual force: weight of the integral of FX^2 + FY^2 beside the squared errors (deg^2, and cm^2 of translations), deg^2/N^2; default 1e-3 with --loads, the --regularization without (the residuals then carry the body's weight).", show_default=False)] = None,
    residual_moment_weight: Annotated[Optional[float], typer.Option("--residual-moment-weight", help="A floating base's residual moment: weight of the integral of MZ^2, deg^2/(N m)^2; default 1e-3 with --loads, the --regularization without.", show_default=False)] = None,
    save_torque: Annotated[Optional[Path], typer.Option("--save-torque", help="Write the torque found as CSV (t, torque; another model: t and one column per joint, e.g. t, shoulder, elbow) to FILE, readable by 'fdbench simulate --torque-file'.")] = None,
    actuation: Annotated[str, typer.Option("--actuation", metavar="torques|muscles", help="What drives the model: torques (the inverse dynamics of the states found) or muscles, the model's muscles (activations, excitations in [0, 1], De Groote's activation dynamics; tendons rigid, a compliant one taken as rigid) and one reserve torque per coordinate (the model's [[actuators]], none on a coordinate without one; 1 N m per coordinate on a model without), as Moco's MocoTrack; the excitations and reserves are replayed (rk4 only). The record adds effort (mean of the summed squared activations), reserve_rms_nm, <muscle>_activation_mean, tendons; --save-trajectory adds <muscle>_activation, _excitation, _force (N) and <joint>_reserve (N m).")] = "torques",
    effort_weight: Annotated[Optional[float], typer.Option("--effort-weight", help="With --actuation muscles: weight of the integral of the summed squared excitations and squared reserve controls (r / optimal force) beside the squared rotation error: deg^2 per excitation^2, >= 0 (default 0.01: the motion's torque must be made whatever the weight, which only keeps the muscles from co-contracting).", show_default=False)] = None,
    one: OneRun = None,
    conditions: dict = None,
):
    """Direct-collocation tracking (as OpenSim Moco, bioptim, Drake): states and accelerations are the unknowns of one sparse problem solved by IPOPT, the torque their inverse dynamics (external loads of --loads included); the torque found is then replayed by fdbench's forward simulation, whose indicators are reported."""
    from ..method_runs import run
    from ..spec import collocate_spec

    from ..spec import ACTUATIONS

    one.check(conditions, save_torque=save_torque)
    check_choice("--actuation", actuation, ACTUATIONS)
    if actuation == "muscles" and save_torque is not None:
        raise BadInput("--save-torque writes joint torques; with --actuation muscles use --save-trajectory")
    with bad_input():
        made = collocate_spec(nodes, scheme, regularization, max_iter, max_time, residual_force_weight,
                              residual_moment_weight, actuation, effort_weight, **one.fields(conditions))
    spec = validated(made)
    _casadi_ready("collocate")
    one.out.check_store()
    outcome = run(spec)

    def write_torque():
        if save_torque is not None:
            from ..files import write_atomic

            write_atomic(save_torque, _collocation_torque_text(outcome.extra["collocation"], spec), "--save-torque")

    one.out.deliver(outcome, spec, "fdbench collocate", write_torque)


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
    emit(methods_text(), None)


@app.command(cls=methods_command("torques", "optimizers"))
@with_conditions
@with_groups
def optimize(
    ctx: typer.Context,
    torque: Annotated[str, typer.Option("--torque", help="Torque parameterisation (see 'fdbench methods'); NAME[KEY=VALUE,...] passes any option its class takes, e.g. 'cs[knots=21]'.")] = "cs",
    opt: Annotated[str, typer.Option("--opt", help="Optimiser (see 'fdbench methods'); NAME[KEY=VALUE,...] passes any option its class takes, e.g. 'cmaes[sigma0=0.1,popsize=12]'.")] = "bfgs",
    feedforward: Annotated[bool, typer.Option("--feedforward/--no-feedforward", help="Add the inverse-dynamics torque (Table 3) or not (Table 2). With --actuation muscles: add static optimisation's excitations, each muscle's signal logit(a_SO) (a_SO clipped to [0.02, 0.98], on the RK4 grid) plus the parameterisation's, which starts at zero; without, the parameterisation alone, fitted to that logit.")] = False,
    actuation: Annotated[str, typer.Option("--actuation", metavar="torques|muscles", help="What the parameters drive: torques, one parameterised torque per joint (the paper's), or muscles, one parameterised excitation per muscle of the model (--torque's parameterisation through a logistic into (0, 1); no joint torques and no reserves: the muscles alone move the model; rk4 only). The objective is then eq. 18 plus --effort-weight times the integral of the summed squared excitations; the record adds effort (mean of the summed squared activations), <muscle>_activation_mean, reserve_rms_nm (0), rmse_torque_nm the muscles' generalised forces against the inverse dynamics; --save-trajectory adds <muscle>_activation, _excitation, _force (N).")] = "torques",
    effort_weight: Annotated[Optional[float], typer.Option("--effort-weight", help="With --actuation muscles: w_e, deg per excitation^2 s, >= 0 (default 1: six muscles at excitation 0.3 for 1 s cost about half a degree of tracking error, so tracking comes first and the effort picks among motions that track alike).", show_default=False)] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of every stochastic step; the same seed gives the same numbers.")] = 0,
    threads: Threads = None,
    residual_weight: Annotated[Optional[float], typer.Option("--residual-weight", help="On a floating base: eq. 18's residual term, deg per N of the base's residual force RMS (FX, FY) and per N m of its moment's (MZ), over the torque history; default 0.01 with --loads, 0 without (the residuals then carry the body's weight).", show_default=False)] = None,
    history: Annotated[Optional[Path], typer.Option("--save-convergence", "--history", help="Write the convergence, the best-so-far objective per evaluation, as CSV to FILE. --history is an older name.", rich_help_panel="Output")] = None,
    save_params: Annotated[Optional[Path], typer.Option("--save-params", help="Write the best parameters as JSON to FILE (reusable by 'fdbench simulate --params').", rich_help_panel="Output")] = None,
    list_methods: Annotated[bool, typer.Option("--list", help="List the registered torques and optimisers and exit.")] = False,
    kinematics: Kinematics = None,
    optim: Optimisation = None,
    sim: Simulation = None,
    out: RunOutputs = None,
    methods: MethodValues = None,
    conditions: dict = None,
):
    """Forward dynamic optimisation (section 4): tune a parameterised torque history (or, with --actuation muscles, the muscles' excitations) so the simulated rotation tracks the desired one (objective of eq. 18)."""
    if list_methods:
        emit(methods_text(), None)
        return
    from ..method_runs import run
    from ..optimizers import OPTIMIZERS
    from ..spec import optimize_spec
    from ..torques import TORQUES

    out.check(spec_inputs(conditions, kinematics), history=history, save_params=save_params)
    (torque,), (opt,), torque_options, optimizer_options = shooting_methods(ctx, [torque], [opt], methods,
                                                                            optim.penalty_weight)
    torque_options = applicable_options(ctx, torque_options, TORQUES, torque, "--torque")
    optimizer_options = applicable_options(ctx, optimizer_options, OPTIMIZERS, opt, "--opt")
    check_gradient(optim.gradient)
    check_count("--threads", threads, MAX_THREADS)
    muscle_fields = _actuation(actuation, effort_weight, save_params)
    spec = validated(optimize_spec(
        torque, opt, feedforward, seed, optim.budget, torque_options=torque_options, optimizer_options=optimizer_options,
        penalty_weight=optim.penalty_weight, gradient=optim.gradient, **_residual(residual_weight),
        **muscle_fields, **sim.spec_fields(kinematics, conditions),
    ))
    out.check_store()
    if opt == "cmaes":
        from ..population import set_threads

        set_threads(threads)
    with Progress(out.quiet, f"{torque}{' excitations' if muscle_fields else ''} + {opt}") as progress:
        outcome = run(spec, on_evaluation=progress.update, on_start=progress.start)
    if "hidden_fits" in outcome.extra:
        fits = ", ".join(f"{n}: {err:.2e}" for n, err in outcome.extra["hidden_fits"])
        say(out.quiet, f"--hidden auto: fit RMSE / torque range by neurons: {fits}")

    def write_more():
        from ..files import csv_text, write_atomic

        if history is not None:
            write_atomic(history, csv_text(["evaluation", "best_objective"], enumerate(outcome.history, start=1)),
                         OUTPUT_LABELS["history"])
        if save_params is not None:
            from ..params_file import params_json

            write_atomic(save_params, params_json(spec, outcome), "--save-params")

    out.deliver(outcome, spec, "fdbench optimize", write_more)


def _actuation(actuation: str, effort_weight, save_params) -> dict:
    """The spec fields of --actuation and --effort-weight (none for torques, the default), checked:
    an unknown actuation, --effort-weight without --actuation muscles, a weight not finite, or
    --save-params with muscles (its file holds torque parameters) are bad input."""
    from ..spec import ACTUATIONS

    check_choice("--actuation", actuation, ACTUATIONS)
    if effort_weight is not None and actuation != "muscles":
        raise BadInput("--effort-weight needs --actuation muscles")
    if actuation != "muscles":
        return {}
    if save_params is not None:
        raise BadInput("--save-params writes torque parameters; it does not apply to --actuation muscles")
    if effort_weight is None:
        return {"actuation": actuation}
    check_finite(effort_weight=effort_weight)
    return {"actuation": actuation, "effort_weight": effort_weight}


def _residual(weight) -> dict:
    """The spec field of ``--residual-weight`` (left out when not given, so the default follows the loads)."""
    if weight is None:
        return {}
    check_finite(residual_weight=weight)
    return {"residual_weight": weight}
