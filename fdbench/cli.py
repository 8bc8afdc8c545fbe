"""The ``fdbench`` command line. Rendering with rich happens here only; heavy imports are made
inside the commands so that ``fdbench --help`` is instant.

Contract: results on stdout (or ``--output FILE``), progress and messages on stderr; exit code 0
when a result was produced, 2 for bad usage or input (one line on stderr), 1 for anything else,
130 on Ctrl-C.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from typer.core import TyperGroup

from . import __version__
from .registry import PluginError

_STARTED = time.perf_counter()

FORMATS = ("table", "json", "csv")
KINEMATICS_HELP = "Desired motion: 'paper' (eq. 5 as printed; reproduces the paper) or 'exact' (chain rule through t*)."
INTEGRATOR_HELP = "rk4 (compiled, fixed step) or a scipy solve_ivp method: rk45, dop853, lsoda, radau, bdf."


class BadInput(Exception):
    """Bad usage or input: exit code 2 with this one-line message."""


class FdbenchGroup(TyperGroup):
    """Routes every error to one line on stderr with the contract's exit codes."""

    def main(self, args=None, prog_name=None, **extra):
        extra.pop("standalone_mode", None)
        code = 0
        try:
            returned = super().main(args=args, prog_name=prog_name or "fdbench", standalone_mode=False, **extra)
            code = returned if isinstance(returned, int) else 0
            if code == 130:
                _error("interrupted")
        except BadInput as exc:
            code = _error(str(exc), 2)
        except PluginError as exc:
            code = _error(str(exc), 2)
        except KeyboardInterrupt:
            code = _error("interrupted", 130)
        except Exception as exc:  # noqa: BLE001 - the contract: one line, never a traceback
            if hasattr(exc, "exit_code") and hasattr(exc, "format_message"):  # click usage errors
                message = exc.format_message().strip()
                if not message:  # no arguments: the help was shown, nothing more to say
                    sys.exit(exc.exit_code)
                context = getattr(exc, "ctx", None)
                where = f"{context.command_path}: " if context is not None else ""
                code = _error(where + message, exc.exit_code)
            elif os.environ.get("FDBENCH_DEBUG"):
                raise
            else:
                code = _error(f"{type(exc).__name__}: {exc}", 1)
        sys.exit(code)


def _error(message: str, code: int = 1) -> int:
    message = " ".join(message.split())  # one line, whatever a path or a library put in it
    sys.stderr.write(f"fdbench: error: {message}\n")
    sys.stderr.flush()
    return code


app = typer.Typer(
    cls=FdbenchGroup,
    help="Benchmark of trajectory-tracking methods for the forward dynamic simulation of a 1-DOF forearm: "
    "PD control with computed feedforward against optimised torque histories (ANN, cubic spline, "
    "parametric function) by CMA-ES, BFGS and more. Run 'fdbench report' for the paper's whole comparison.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool):
    if value:
        typer.echo(f"fdbench {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")] = False,
):
    """fdbench: trajectory tracking in forward dynamics, benchmarked."""


# ---- options shared by several commands ------------------------------------------------------

Kinematics = Annotated[str, typer.Option("--kinematics", help=KINEMATICS_HELP)]
Integrator = Annotated[str, typer.Option("--integrator", help=INTEGRATOR_HELP)]
Dt = Annotated[float, typer.Option("--dt", help="RK4 step, s, in [1e-6, 0.1].")]
Rtol = Annotated[float, typer.Option("--rtol", help="Relative tolerance (solve_ivp integrators).")]
Atol = Annotated[float, typer.Option("--atol", help="Absolute tolerance (solve_ivp integrators).")]
Alpha = Annotated[float, typer.Option("--alpha", help="Penalty factor of eq. 12, in [1, 1e15].")]
Xi = Annotated[float, typer.Option("--xi", help="Penalty damping ratio of eq. 12.")]
Omega = Annotated[float, typer.Option("--omega", help="Penalty natural frequency of eq. 12, rad/s.")]
Format = Annotated[str, typer.Option("--format", "-f", help="Output: table (for a person), json or csv.")]
Output = Annotated[Optional[Path], typer.Option("--output", "-o", help="Write the result to FILE instead of stdout.")]
SaveHistory = Annotated[Optional[Path], typer.Option("--save-history", help="Write the run's time history (1001 rows) as CSV to FILE.")]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress or messages on stderr.")]
Db = Annotated[Optional[Path], typer.Option("--db", help="Also store the run in this results database (SQLite).")]
Budget = Annotated[int, typer.Option("--budget", help="Objective evaluations (forward simulations) per optimisation, gradient evaluations included.")]
Hidden = Annotated[str, typer.Option("--hidden", help="ANN hidden neurons in [1, 50], or 'auto' to choose the smallest count that fits the inverse-dynamics torque.")]
Knots = Annotated[int, typer.Option("--knots", help="Cubic-spline knots in [4, 1000], equally spaced over [0, 1] s.")]
Terms = Annotated[int, typer.Option("--terms", help="Parametric-function terms (Gaussian bumps) in [1, 100], 3 parameters each.")]
Sigma0 = Annotated[float, typer.Option("--sigma0", help="CMA-ES initial step size, in scaled parameter units.")]
Popsize = Annotated[Optional[int], typer.Option("--popsize", help="CMA-ES population size (default: cma's 4 + 3 ln n).")]
PenaltyWeight = Annotated[float, typer.Option("--penalty-weight", help="w_penal of eq. 18: objective = RMSE_rot_deg + w_penal (1 - t_end).")]
# Execution of many runs (report, study): where they run and how many at once.
BackendName = Annotated[str, typer.Option("--backend", help="Where runs are carried out: 'local' (worker processes on this machine, --jobs of them) or 'dask' (a Dask cluster: the scheduler at --scheduler, or a local cluster of --jobs workers; needs pip install 'fdbench[dask]').")]
Scheduler = Annotated[Optional[str], typer.Option("--scheduler", metavar="ADDRESS", help="Address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (with --backend dask; its workers need the same fdbench version).", show_default=False)]
Jobs = Annotated[Optional[int], typer.Option("--jobs", "-j", help="Runs at once: worker processes of the local backend, or of a local Dask cluster (default: the number of cores).", show_default=False)]


def _common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega) -> dict:
    return dict(kinematics=kinematics, integrator=integrator, dt=dt, rtol=rtol, atol=atol, alpha=alpha, xi=xi, omega=omega)


def _check_choice(option: str, value: str, valid) -> str:
    if value not in valid:
        from .registry import unknown_name_message

        raise BadInput(f"{option}: " + unknown_name_message("value", value, list(valid)))
    return value


def _check_outputs(fmt: str, valid=FORMATS, **paths) -> None:
    """Validate --format and every output path before any work starts."""
    from .files import BadFile, check_writable

    _check_choice("--format", fmt, valid)
    for option, path in paths.items():
        if path is not None:
            try:
                check_writable(path, "--" + option.replace("_", "-"))
            except BadFile as exc:
                raise BadInput(str(exc)) from None


def _validated(spec):
    try:
        return spec.validate()
    except ValueError as exc:
        raise BadInput(_with_option(str(exc))) from None


def _with_option(message: str) -> str:
    """Messages from the library name parameters plainly (dt, kp); name them as options."""
    for name in ("dt", "rtol", "atol", "alpha", "xi", "omega", "kp", "kd"):
        if message.startswith(name + " "):
            return f"--{name}: " + message[len(name) + 1 :]
    for name in ("kinematics", "integrator", "torque", "optimizer"):
        if message.startswith(f"unknown {name} "):
            option = "--opt" if name == "optimizer" else f"--{name}"
            return f"{option}: {message}"
    return message


def _console(stderr: bool = True):
    from rich.console import Console

    return Console(stderr=stderr, highlight=False)


def _say(quiet: bool, text: str) -> None:
    if not quiet:
        _console().print(text, soft_wrap=True)


def _jsonable(record: dict) -> dict:
    from .files import finite_or_none

    return {k: finite_or_none(float(v)) if isinstance(v, float) else v for k, v in record.items()}


def _render(record: dict, fmt: str, title: str) -> str:
    if fmt == "json":
        return json.dumps(_jsonable(record), indent=2) + "\n"
    if fmt == "csv":
        from .files import csv_text

        return csv_text(list(record), [["" if v is None else v for v in record.values()]])
    from rich.table import Table

    table = Table(title=title, show_header=True)
    table.add_column("field")
    table.add_column("value", overflow="fold")
    for key, value in record.items():
        if value is None or value == "":
            continue
        table.add_row(key, _format_value(value))
    console = _console(stderr=False)
    with console.capture() as capture:
        console.print(table)
    return capture.get()


def _format_value(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _emit(text: str, output: Optional[Path]) -> None:
    if output is None:
        sys.stdout.write(text)
        sys.stdout.flush()
    else:
        from .files import write_atomic

        write_atomic(output, text)


def _finish(record: dict, fmt: str, output, title: str, quiet: bool) -> None:
    record["command_time_s"] = time.perf_counter() - _STARTED
    _emit(_render(record, fmt, title), output)
    if output is not None:
        _say(quiet, f"wrote {output}")
    if record.get("status") not in (None, "success"):
        _say(quiet, f"[yellow]warning:[/] {record['message']}")


def _history_text(outcome) -> str:
    import numpy as np

    from .files import csv_text

    r, inv = outcome.result, outcome.inverse
    columns = [r.t, r.q[:, 2], inv.theta, r.qd[:, 2], inv.theta_dot, r.torque, inv.torque, r.q[:, 0], r.q[:, 1]]
    rows = np.column_stack(columns)
    header = ["t", "theta", "theta_desired", "theta_dot", "theta_dot_desired", "torque", "torque_inverse", "x2", "y2"]
    return csv_text(header, ([f"{v:.10g}" for v in row] for row in rows))


def _save_history(outcome, path) -> None:
    if path is not None:
        from .files import write_atomic

        write_atomic(path, _history_text(outcome), "--save-history")


def _check_store(db: Optional[Path]) -> None:
    """Refuse an unusable --db before any work starts."""
    if db is not None:
        from .store import StoreError, open_store

        try:
            with open_store(db):
                pass
        except StoreError as exc:
            raise BadInput(f"--db: {exc}") from None


def _store(outcome, spec, db: Optional[Path], quiet: bool) -> None:
    if db is None:
        return
    from .store import StoreError, open_store

    try:
        with open_store(db) as store:
            store.add(spec, outcome)
    except StoreError as exc:
        raise BadInput(f"--db: {exc}") from None
    _say(quiet, f"stored in {db}")


# ---- commands ---------------------------------------------------------------------------------


@app.command()
def inverse(
    kinematics: Kinematics = "paper",
    fmt: Format = "table",
    output: Output = None,
    quiet: Quiet = False,
):
    """Inverse dynamics (eq. 3): the elbow torque that should produce the desired motion.

    The table and JSON give a summary; --format csv gives the whole history (t, theta, theta_dot, theta_ddot, torque; 1001 rows, SI units)."""
    _check_outputs(fmt, output=output)
    try:
        from .motion import check_kinematics

        check_kinematics(kinematics)
    except ValueError as exc:
        raise BadInput(_with_option(str(exc))) from None
    import numpy as np

    from .inverse import inverse_dynamics

    start = time.perf_counter()
    inv = inverse_dynamics(None, kinematics=kinematics)
    runtime = time.perf_counter() - start
    if fmt == "csv":
        from .files import csv_text

        rows = np.column_stack([inv.t, inv.theta, inv.theta_dot, inv.theta_ddot, inv.torque])
        text = csv_text(["t", "theta", "theta_dot", "theta_ddot", "torque"], ([f"{v:.10g}" for v in row] for row in rows))
        _emit(text, output)
        return
    record = {
        "command": "inverse", "kinematics": kinematics, "samples": len(inv.t),
        "theta_start_deg": float(np.degrees(inv.theta[0])), "theta_end_deg": float(np.degrees(inv.theta[-1])),
        "torque_min_nm": float(inv.torque.min()), "torque_max_nm": float(inv.torque.max()),
        "torque_start_nm": float(inv.torque[0]), "torque_end_nm": float(inv.torque[-1]),
        "torque_rms_nm": float(np.sqrt(np.mean(inv.torque**2))), "runtime_s": runtime,
        "fdbench_version": __version__,
    }
    _finish(record, fmt, output, "fdbench inverse", quiet)


@app.command()
def simulate(
    torque_file: Annotated[Optional[Path], typer.Option("--torque-file", help="CSV with columns t (s) and torque (N m) covering [0, 1] s, linearly interpolated. Default: the inverse-dynamics torque.")] = None,
    params: Annotated[Optional[Path], typer.Option("--params", help="Parameters saved by 'fdbench optimize --save-params'.")] = None,
    kinematics: Kinematics = "paper",
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
    quiet: Quiet = False,
):
    """Open-loop forward dynamics (eq. 12) driven by a torque history: by default the inverse-dynamics torque, whose drift from the desired motion motivates the paper."""
    from .experiment import RunSpec

    _check_outputs(fmt, output=output, save_history=save_history)
    if torque_file is not None and params is not None:
        raise BadInput("--torque-file and --params: give one of them, not both")
    spec = _validated(RunSpec(command="simulate", **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega)))
    from .experiment import run_simulation
    from .files import BadFile

    try:
        outcome = run_simulation(spec, torque_file=torque_file, params_file=params)
    except BadFile as exc:
        raise BadInput(str(exc)) from None
    _save_history(outcome, save_history)
    _finish(outcome.record, fmt, output, "fdbench simulate", quiet)


@app.command()
def control(
    kp: Annotated[float, typer.Option("--kp", help="Proportional gain, N m/rad (paper: 80).")] = 80.0,
    kd: Annotated[float, typer.Option("--kd", help="Derivative gain, N m s/rad (paper: 0.3).")] = 0.3,
    kinematics: Kinematics = "paper",
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
    quiet: Quiet = False,
):
    """PD control with computed feedforward (eqs. 13-14): the inverse-dynamics torque plus PD feedback on the elbow rotation."""
    from .experiment import control_spec, run

    _check_outputs(fmt, output=output, save_history=save_history, db=db)
    spec = _validated(control_spec(kp, kd, **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega)))
    _check_store(db)
    outcome = run(spec)
    _save_history(outcome, save_history)
    _store(outcome, spec, db, quiet)
    _finish(outcome.record, fmt, output, "fdbench control", quiet)


def _check_method_options(torque_options: dict, optimizer_options: dict) -> None:
    """Reject an out-of-range method option even when the chosen method does not use it
    (``--terms 0`` with ``--torque cs``): every registered class that takes it checks it."""
    import inspect

    from .optimizers import OPTIMIZERS
    from .torques import TORQUES

    for registry, options in ((TORQUES, torque_options), (OPTIMIZERS, optimizer_options)):
        for _, cls in registry.items():
            accepted = inspect.signature(cls).parameters
            given = {k: v for k, v in options.items() if k in accepted and v is not None and v != "auto"}
            if given:
                try:
                    cls(**given)
                except ValueError as exc:
                    raise BadInput(str(exc)) from None


def _check_finite(**values) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise BadInput(f"--{name.replace('_', '-')} must be a finite number, got {value}")


def _parse_hidden(hidden: str):
    if hidden == "auto":
        return "auto"
    try:
        value = int(hidden)
    except ValueError:
        raise BadInput(f"--hidden must be an integer >= 1 or 'auto', got {hidden!r}") from None
    if value < 1:
        raise BadInput(f"--hidden must be an integer >= 1 or 'auto', got {value}")
    return value


def _methods_text() -> str:
    from .optimizers import OPTIMIZERS
    from .torques import TORQUES

    lines = ["torques (--torque):"]
    lines += [f"  {name:<12} {cls.summary}" for name, cls in TORQUES.items()]
    lines += ["optimizers (--opt):"]
    lines += [f"  {name:<12} {cls.summary}" for name, cls in OPTIMIZERS.items()]
    return "\n".join(lines) + "\n"


@app.command()
def methods():
    """List the registered torque parameterisations and optimisers, one line each."""
    _emit(_methods_text(), None)


@app.command()
def optimize(
    torque: Annotated[str, typer.Option("--torque", help="Torque parameterisation: ann, cs, pf (see 'fdbench methods').")] = "cs",
    opt: Annotated[str, typer.Option("--opt", help="Optimiser: cmaes, bfgs, nelder-mead, lbfgsb (see 'fdbench methods').")] = "bfgs",
    feedforward: Annotated[bool, typer.Option("--feedforward/--no-feedforward", help="Add the inverse-dynamics torque (Table 3) or not (Table 2).")] = False,
    budget: Budget = 200,
    seed: Annotated[int, typer.Option("--seed", help="Seed of every stochastic step; the same seed gives the same numbers.")] = 0,
    hidden: Hidden = "4",
    knots: Knots = 11,
    terms: Terms = 4,
    sigma0: Sigma0 = 0.1,
    popsize: Popsize = None,
    penalty_weight: PenaltyWeight = 1.0,
    kinematics: Kinematics = "paper",
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
    history: Annotated[Optional[Path], typer.Option("--history", help="Write the best-so-far objective per evaluation as CSV to FILE.")] = None,
    save_params: Annotated[Optional[Path], typer.Option("--save-params", help="Write the best parameters as JSON to FILE (reusable by 'fdbench simulate --params').")] = None,
    list_methods: Annotated[bool, typer.Option("--list", help="List the registered torques and optimisers and exit.")] = False,
    db: Db = None,
    quiet: Quiet = False,
):
    """Forward dynamic optimisation (section 4): tune a parameterised torque history so the simulated rotation tracks the desired one (objective of eq. 18)."""
    if list_methods:
        _emit(_methods_text(), None)
        return
    from .experiment import optimize_spec, run

    _check_outputs(fmt, output=output, save_history=save_history, history=history, save_params=save_params, db=db)
    _check_finite(sigma0=sigma0, penalty_weight=penalty_weight)
    torque_options = {"hidden": _parse_hidden(hidden), "knots": knots, "terms": terms}
    optimizer_options = {"sigma0": sigma0, "popsize": popsize}
    _check_method_options(torque_options, optimizer_options)
    spec = _validated(optimize_spec(
        torque, opt, feedforward, seed, budget, torque_options=torque_options, optimizer_options=optimizer_options,
        penalty_weight=penalty_weight, **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega),
    ))
    _check_store(db)
    with _progress(quiet, f"{torque} + {opt}") as progress:
        outcome = run(spec, on_evaluation=progress.update, on_start=progress.start)
    if "hidden_fits" in outcome.extra:
        fits = ", ".join(f"{n}: {err:.2e}" for n, err in outcome.extra["hidden_fits"])
        _say(quiet, f"--hidden auto: fit RMSE / torque range by neurons: {fits}")
    _save_history(outcome, save_history)
    if history is not None:
        from .files import csv_text, write_atomic

        write_atomic(history, csv_text(["evaluation", "best_objective"], enumerate(outcome.history, start=1)), "--history")
    if save_params is not None:
        from .files import write_atomic
        from .params_file import params_json

        write_atomic(save_params, params_json(spec, outcome), "--save-params")
    _store(outcome, spec, db, quiet)
    _finish(outcome.record, fmt, output, "fdbench optimize", quiet)


@app.command()
def report(
    torque: Annotated[Optional[list[str]], typer.Option("--torque", help="Only these torques (repeat the option); default ann, cs, pf.")] = None,
    opt: Annotated[Optional[list[str]], typer.Option("--opt", help="Only these optimisers (repeat the option); default cmaes, bfgs.")] = None,
    feedforward: Annotated[Optional[bool], typer.Option("--feedforward/--no-feedforward", help="Only Table 3 (with) or Table 2 (without); default both.", show_default=False)] = None,
    control: Annotated[bool, typer.Option("--control/--no-control", help="Include the PD control run.")] = True,
    all_cells: Annotated[bool, typer.Option("--all-cells", help="Also run the cells the paper left out (PF without feedforward).")] = False,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per cell, seeds 0..N-1; medians and IQRs over them.")] = 5,
    budget: Budget = 200,
    jobs: Jobs = None,
    backend: BackendName = "local",
    scheduler: Scheduler = None,
    db: Annotated[Optional[Path], typer.Option("--db", help="Results database (default: $FDBENCH_DB or ./fdbench-results.sqlite).", show_default=False)] = None,
    rerun: Annotated[bool, typer.Option("--rerun", help="Run everything again instead of reusing stored runs.")] = False,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write PNG figures into DIR (created if missing) and link them.")] = None,
    kp: Annotated[float, typer.Option("--kp", help="PD proportional gain, N m/rad.")] = 80.0,
    kd: Annotated[float, typer.Option("--kd", help="PD derivative gain, N m s/rad.")] = 0.3,
    hidden: Hidden = "4",
    knots: Knots = 11,
    terms: Terms = 4,
    sigma0: Sigma0 = 0.1,
    popsize: Popsize = None,
    penalty_weight: PenaltyWeight = 1.0,
    kinematics: Kinematics = "paper",
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Annotated[str, typer.Option("--format", "-f", help="Report format: md (Markdown) or csv (one row per cell).")] = "md",
    output: Output = None,
    quiet: Quiet = False,
):
    """The paper's whole comparison: PD control, Table 2 and Table 3, with our figures beside the published ones, as Markdown or CSV.

    Every run is stored in the results database; stored runs are reused, so an interrupted report resumes and a repeated one returns at once."""
    from .benchmark import default_cells, make_plan

    _check_outputs(fmt, ("md", "csv"), output=output, db=db)
    if seeds < 1:
        raise BadInput(f"--seeds must be an integer >= 1, got {seeds}")
    if jobs is not None and jobs < 1:
        raise BadInput(f"--jobs must be an integer >= 1, got {jobs}")
    if figures is not None and not (figures.is_dir() or figures.parent.is_dir()):
        raise BadInput(f"--figures: directory {figures.parent} does not exist")
    _check_finite(sigma0=sigma0, penalty_weight=penalty_weight)
    _check_names(torque, opt)
    executor = _backend(backend, jobs, scheduler)
    cells = default_cells(torque, opt, feedforward, all_cells)
    if not cells and not control:
        raise BadInput("nothing to run: the options select no cell and --no-control")
    torque_options = {"hidden": _parse_hidden(hidden), "knots": knots, "terms": terms}
    optimizer_options = {"sigma0": sigma0, "popsize": popsize}
    _check_method_options(torque_options, optimizer_options)
    plan = make_plan(
        cells, seeds, budget, control, kp, kd, torque_options=torque_options,
        optimizer_options=optimizer_options, penalty_weight=penalty_weight,
        **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega),
    )
    for spec in ([plan.control] if plan.control else []) + [plan.specs[c][0] for c in plan.cells]:
        _validated(spec)
    from .store import StoreError, default_path, open_store

    db_path = db if db is not None else default_path()
    jobs = jobs or os.cpu_count() or 1
    from .execution import BackendError, Terminated, sigterm_as_interrupt

    try:
        with sigterm_as_interrupt(), open_store(db_path) as store:
            with _progress(quiet, "runs") as progress:
                from .benchmark import execute

                def on_done(done, total):
                    if progress.bar is None:
                        progress.start(total, show_best=False)
                    progress.update(done)

                runs = execute(plan, store, rerun=rerun, on_done=on_done, backend=executor)
    except StoreError as exc:
        raise BadInput(f"--db: {exc}") from None
    except BackendError as exc:
        raise BadInput(str(exc)) from None
    except Terminated:
        _error("terminated")
        raise typer.Exit(143) from None
    from .inverse import inverse_dynamics
    from .report import build_rows

    start = time.perf_counter()
    inverse = inverse_dynamics(None, kinematics=kinematics)
    inverse_runtime = time.perf_counter() - start
    rows = build_rows(plan, runs)
    if fmt == "csv":
        from .files import csv_text
        from .report import CSV_COLUMNS, csv_rows

        _emit(csv_text(list(CSV_COLUMNS), csv_rows(rows)), output)
    else:
        from .report import markdown, settings_table

        links = _write_figures(plan, runs, rows, inverse, figures, output, quiet) if figures is not None else None
        _emit(markdown(rows, inverse, inverse_runtime, settings_table(plan, seeds, _parallelism(backend, jobs, scheduler)), links), output)
    if output is not None:
        _say(quiet, f"wrote {output} ({len(plan.all_specs())} runs, database {db_path})")


def _parallelism(name: str, jobs: int, scheduler: Optional[str]):
    """How the runs were carried out, for the report's settings."""
    if name != "dask":
        return jobs
    return f"Dask scheduler {scheduler}" if scheduler is not None else f"{jobs} (local Dask cluster)"


def _backend(name: str, jobs: Optional[int], scheduler: Optional[str]):
    """The execution backend of --backend/--jobs/--scheduler, checked before any work."""
    from .execution import BackendError, make_backend

    try:
        return make_backend(name, jobs=jobs, scheduler=scheduler)
    except BackendError as exc:
        raise BadInput(str(exc)) from None


def _check_names(torques, optimizers) -> None:
    from .optimizers import OPTIMIZERS
    from .registry import UnknownName
    from .torques import TORQUES

    try:
        for name in torques or ():
            TORQUES[name]
        for name in optimizers or ():
            OPTIMIZERS[name]
    except UnknownName as exc:
        raise BadInput(_with_option(str(exc))) from None


def _write_figures(plan, runs, rows, inverse, directory: Path, output, quiet) -> dict:
    """Write the report's figures; return {title: path relative to the report}."""
    import numpy as np

    from . import figures as fig
    from .experiment import replay, run

    directory.mkdir(exist_ok=True)
    base = output.parent if output is not None else Path(".")
    written = {}

    def link(name, path):
        written[name] = os.path.relpath(path, base)

    path = directory / "figure2_inverse_dynamics.png"
    fig.inverse_figure(inverse, path)
    link("Figure 2: desired rotation and inverse-dynamics torque", path)
    control_curve = []
    if plan.control is not None:
        control_curve = [("PD control + feedforward", run(plan.control).result.theta)]
    for table, title in ((2, "Figure 5: without feedforward"), (3, "Figure 6: with feedforward")):
        curves = list(control_curve)
        series = []
        for row in rows:
            if row.table != table:
                continue
            specs = plan.specs[row.cell]
            stored = [runs[s.hash()] for s in specs]
            values = np.array([r["record"]["rmse_rot_deg"] if r["record"]["rmse_rot_deg"] is not None else np.inf for r in stored])
            median_seed = int(np.argsort(values)[len(values) // 2])
            if stored[median_seed]["params"] is not None:
                curves.append((row.name, replay(specs[median_seed], stored[median_seed]["params"]).theta))
            series.append((row.name, [r["history"] for r in stored if r["history"]]))
        if len(curves) > len(control_curve):
            path = directory / f"figure{5 if table == 2 else 6}_tracking.png"
            fig.tracking_figure(inverse, curves, path, f"{title}: desired rotation and the median run of each method")
            link(title, path)
        if series:
            path = directory / f"convergence_table{table}.png"
            fig.convergence_figure(series, path, f"Convergence, Table {table} (median over seeds, IQR band)")
            link(f"Convergence, Table {table}", path)
    _say(quiet, f"wrote {len(written)} figures to {directory}")
    return written


class _progress:
    """A rich progress bar on stderr: evaluations done and the best objective so far."""

    def __init__(self, quiet: bool, label: str):
        self.quiet, self.label = quiet, label
        self.bar = self.task = None

    def __enter__(self):
        return self

    def start(self, total: int, show_best: bool = True) -> None:
        if self.quiet or not sys.stderr.isatty():  # a bar only for a person watching
            return
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn()]
        if show_best:
            columns.append(TextColumn("best {task.fields[best]}"))
        self.bar = Progress(*columns, TimeElapsedColumn(), console=_console(), transient=True)
        self.task = self.bar.add_task(self.label, total=total, best="-")
        self.bar.start()

    def update(self, count: int, best: float | None = None) -> None:
        if self.bar is not None:
            self.bar.update(self.task, completed=count, best="-" if best is None else f"{best:.4g}")

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.stop()
        return False


def main() -> None:
    """Console-script entry point."""
    typer.main.get_command(app).main(prog_name="fdbench")


if __name__ == "__main__":  # pragma: no cover
    main()
