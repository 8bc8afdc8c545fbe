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
MAX_SEEDS = 1000  # runs per cell of a report
MAX_JOBS = 256  # worker processes
KINEMATICS_HELP = ("Desired motion: 'paper' (eq. 5 with its derivatives as printed; reproduces the paper), 'exact' (eq. 5 "
                   "differentiated by the chain rule through t*), or a CSV file of a recorded joint angle: columns t (s) "
                   "and theta (deg; --radians), optionally theta_vel and theta_acc (deg/s, deg/s^2), any duration and "
                   "sampling. --kinematics is an older name.")
INTEGRATOR_HELP = "rk4 (compiled, fixed step) or a scipy solve_ivp method: rk45, dop853, lsoda, radau, bdf."


class BadInput(Exception):
    """Bad usage or input: exit code 2 with this one-line message."""


class FdbenchGroup(TyperGroup):
    """Routes every error to one line on stderr with the contract's exit codes."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except BrokenPipeError:  # before click turns it into a silent exit code 1
            raise _StdoutClosed from None

    def main(self, args=None, prog_name=None, **extra):
        extra.pop("standalone_mode", None)
        self.help_requested = any(a in ("-h", "--help") for a in (sys.argv[1:] if args is None else args))
        code = 0
        import warnings

        # numerical trouble (overflow in a torque of 1e308...) is reported by a run's status, once
        warnings.filterwarnings("ignore", category=RuntimeWarning)
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
        except (BrokenPipeError, _StdoutClosed):
            code = _closed_stdout()
        except Exception as exc:  # noqa: BLE001 - the contract: one line, never a traceback
            if hasattr(exc, "exit_code") and hasattr(exc, "format_message"):  # click usage errors
                message = exc.format_message().strip()
                if not message:  # no arguments: the help was shown, nothing more to say
                    sys.exit(exc.exit_code)
                context = getattr(exc, "ctx", None)
                where = f"{context.command_path}: " if context is not None else ""
                code = _error(where + message, exc.exit_code)
            elif type(exc).__name__ == "StoreError":  # the database became unusable during the work
                code = _error(f"--db: {exc}", 2)
            elif os.environ.get("FDBENCH_DEBUG"):
                raise
            else:
                code = _error(f"{type(exc).__name__}: {exc}", 1)
        sys.exit(code)


    def get_command(self, ctx, cmd_name):
        command = super().get_command(ctx, cmd_name)
        if command is not None and getattr(self, "help_requested", False):
            _show_choices(command, ctx)
        return command

    def format_help(self, ctx, formatter):
        _show_choices(self, ctx)
        return super().format_help(ctx, formatter)


def _choices(name: str, command: str):
    """The valid values of an option, from the registries (plugins included), for --help."""
    if name == "torque":
        from .torques import TORQUES

        return list(TORQUES)
    if name == "opt":
        from .optimizers import OPTIMIZERS

        return list(OPTIMIZERS)
    if name == "integrator":
        from .integrate import INTEGRATORS

        return list(INTEGRATORS)
    if name == "smoothing":
        from .motion import SMOOTHING

        return list(SMOOTHING)
    if name == "kinematics":
        from .motion import KINEMATICS

        return list(KINEMATICS) + ["FILE"]
    if name == "backend":
        from .execution import BACKENDS

        return list(BACKENDS)
    if name == "controller":
        from .controllers import CONTROLLERS

        return list(CONTROLLERS)
    if name == "scheme":
        from .collocation import SCHEMES

        return list(SCHEMES)
    if name == "fmt":
        return list(REPORT_FORMATS if command == "report" else FORMATS)
    return None


def _show_choices(command, ctx) -> None:
    """Help only: show registered names as an option's choices ('[ann|cs|pf]') and no type for
    on/off flags (computed when help is asked for, so plugins appear and other commands stay fast)."""
    params = list(getattr(command, "params", []))
    help_option = command.get_help_option(ctx) if hasattr(command, "get_help_option") else None
    for param in params + ([help_option] if help_option is not None else []):
        if getattr(param, "is_flag", False) and getattr(param, "metavar", None) is None:
            param.metavar = ""
            continue
        if getattr(param, "param_type_name", None) != "option" or param.metavar is not None:
            continue
        if param.name == "hidden":
            param.metavar = "<int>|auto"
            continue
        try:
            choices = _choices(param.name, command.name)
        except PluginError:
            return  # the command itself reports it
        if choices:
            param.metavar = "[" + "|".join(choices) + "]"


class _StdoutClosed(Exception):
    """Standard output was closed (``>&-``): nothing can be written there."""


SIGPIPE_EXIT = 141  # 128 + SIGPIPE: what a shell tool exits with when its reader went away


def _closed_stdout() -> int:
    """A reader that stopped reading (``| head``) or a closed stdout is a normal end: no message,
    and no second failure when Python flushes stdout at exit."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
    except OSError:
        pass
    return SIGPIPE_EXIT


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

Kinematics = Annotated[str, typer.Option("--motion", "--kinematics", help=KINEMATICS_HELP)]
Integrator = Annotated[str, typer.Option("--integrator", help=INTEGRATOR_HELP)]
Dt = Annotated[float, typer.Option("--dt", help="RK4 step, s, in [1e-6, 0.1].")]
Rtol = Annotated[float, typer.Option("--rtol", help="Relative tolerance (solve_ivp integrators), in [2.2e-14, 1).")]
Atol = Annotated[float, typer.Option("--atol", help="Absolute tolerance (solve_ivp integrators), in [1e-30, 1].")]
Alpha = Annotated[float, typer.Option("--alpha", help="Penalty factor of eq. 12, in [1, 1e15].")]
Xi = Annotated[float, typer.Option("--xi", help="Penalty damping ratio of eq. 12.")]
Omega = Annotated[float, typer.Option("--omega", help="Penalty natural frequency of eq. 12, rad/s.")]
Format = Annotated[str, typer.Option("--format", "-f", help="Output: table (for a person), json or csv.")]
Output = Annotated[Optional[Path], typer.Option("--output", "-o", help="Write the result to FILE instead of stdout ('-': stdout). A regular file is replaced atomically, a symlink written through, a device written in place; a read-only file, an input of the command or the results database is refused.")]
SaveHistory = Annotated[Optional[Path], typer.Option("--save-trajectory", "--save-history", help="Write the run's trajectory, its time history (t, theta, theta_desired, torque, ...; one row per sample of the motion, 1001 for eq. 5), as CSV to FILE. --save-history is an older name.")]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress or messages on stderr.")]
NoiseSeed = Annotated[int, typer.Option("--seed", help="Seed of the --noise-deg noise; the same seed gives the same noisy motion.")]
Db = Annotated[Optional[Path], typer.Option("--db", help="Also store the run in this results database (SQLite).")]
Budget = Annotated[int, typer.Option("--budget", help="Objective evaluations (forward simulations) per optimisation, in [1, 1000000], gradient evaluations included.")]
Hidden = Annotated[str, typer.Option("--hidden", help="ANN hidden neurons in [1, 50], or 'auto' to choose the smallest count that fits the inverse-dynamics torque.")]
Knots = Annotated[int, typer.Option("--knots", help="Cubic-spline knots in [4, 1000], equally spaced over the motion's span (eq. 5: [0, 1] s).")]
Terms = Annotated[int, typer.Option("--terms", help="Parametric-function terms (Gaussian bumps) in [1, 100], 3 parameters each.")]
Sigma0 = Annotated[Optional[float], typer.Option("--sigma0", help="CMA-ES initial step size, in scaled parameter units (default: per torque, cs 0.05, ann 0.2, pf 0.03).", show_default=False)]
Popsize = Annotated[Optional[int], typer.Option("--popsize", help="CMA-ES population size, in [2, 10000] (default: per torque, cs and ann 8, pf cma's 4 + 3 ln n).")]
MAX_THREADS = 1024
Threads = Annotated[Optional[int], typer.Option("--threads", help=f"Threads evaluating a CMA-ES population at once, in [1, {MAX_THREADS}] (default: the cores available); the numbers do not depend on it.", show_default=False)]
Gradient = Annotated[str, typer.Option("--gradient", metavar="fd|exact", help="Gradients for gradient-based optimisers (bfgs, lbfgsb): fd, finite differences (the paper's method), or exact, forward sensitivities of the RK4 simulation (rk4 only; one simulation with its sensitivities counts as one evaluation).")]
PenaltyWeight = Annotated[float, typer.Option("--penalty-weight", help="w_penal of eq. 18: objective = RMSE_rot_deg + w_penal (1 - t_end / T), T the motion's duration (eq. 5: 1 s).")]
# Execution of many runs (report, study): where they run and how many at once.
BackendName = Annotated[str, typer.Option("--backend", help="Where runs are carried out: 'local' (worker processes on this machine, --jobs of them) or 'dask' (a Dask cluster: the scheduler at --scheduler, or a local cluster of --jobs workers; needs pip install 'fdbench\\[dask]').")]
Scheduler = Annotated[Optional[str], typer.Option("--scheduler", metavar="ADDRESS", help="Address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (with --backend dask; its workers need the same fdbench version).", show_default=False)]
Jobs = Annotated[Optional[int], typer.Option("--jobs", "-j", help="Runs at once, in [1, 256]: worker processes of the local backend, or of a local Dask cluster (default: the number of cores).", show_default=False)]


# Options of the commands that run many specs (report, study)
TorqueSelection = Annotated[Optional[list[str]], typer.Option("--torque", help="Only these torques (repeat the option); default ann, cs, pf.")]
OptSelection = Annotated[Optional[list[str]], typer.Option("--opt", help="Only these optimisers (repeat the option); default cmaes, bfgs.")]
FeedforwardSelection = Annotated[Optional[bool], typer.Option("--feedforward/--no-feedforward", help="Only the cells with feedforward (Table 3) or without (Table 2); default both.", show_default=False)]
WithControl = Annotated[bool, typer.Option("--control/--no-control", help="Include PD control.")]
AllCells = Annotated[bool, typer.Option("--all-cells", help="Also run the cells the paper left out (PF without feedforward).")]
StoreDb = Annotated[Optional[Path], typer.Option("--db", help="Results database (default: $FDBENCH_DB or ./fdbench-results.sqlite).", show_default=False)]
Rerun = Annotated[bool, typer.Option("--rerun", help="Run everything again instead of reusing stored runs.")]
Kp = Annotated[float, typer.Option("--kp", help="PD proportional gain, N m/rad.")]
Kd = Annotated[float, typer.Option("--kd", help="PD derivative gain, N m s/rad.")]


# Options of the motion, its noise and the model, shared by every command that simulates: declared once
# here and added to a command by @_with_conditions, which hands them over as one dict ``conditions``
# of RunSpec fields.
CONDITIONS = {
    "radians": (bool, False, typer.Option("--radians", help="The motion file's angles (and derivatives) are in radians, not degrees.")),
    "cutoff_hz": (float, 6.0, typer.Option("--cutoff", help="Derivative estimate: -3 dB frequency (Hz) of the zero-lag 4th-order Butterworth low-pass (Winter's), applied to a recorded or noisy angle before an interpolating spline is differentiated.")),
    "smoothing": (str, "butterworth", typer.Option("--smoothing", help="Derivative estimate: 'butterworth' (low-pass, then spline) or 'spline' (a smoothing spline, factor by generalised cross-validation or --spline-lambda).")),
    "spline_lambda": (Optional[float], None, typer.Option("--spline-lambda", help="Smoothing factor of --smoothing spline (> 0; default: chosen by generalised cross-validation).", show_default=False)),
    "sample_dt": (Optional[float], None, typer.Option("--sample-dt", help="Report the histories and indicators every SAMPLE_DT s (default: the motion's own samples; eq. 5: 1 ms).", show_default=False)),
    "noise_deg": (float, 0.0, typer.Option("--noise-deg", help="White Gaussian noise (deg, in [0, 45], seeded by --seed) added to the captured angle before the derivative estimate; indicators stay measured against the noise-free motion.")),
    "capture_hz": (float, 100.0, typer.Option("--capture-hz", help="Capture rate (Hz) of the noisy samples of 'paper' or 'exact' (a file keeps its own samples).")),
    "plant": (Optional[list[str]], None, typer.Option("--plant", metavar="KEY=VALUE", help="KEY=VALUE (repeatable): change the simulated body only (keys L12, L1G, m, I1, F_ext, g; SI units); inverse dynamics and model-based controllers keep the nominal model.", show_default=False)),
    "model": (Optional[list[str]], None, typer.Option("--model", metavar="NAME|KEY=VALUE", help="The model, forearm (Table 1, default) or arm2 (shoulder + elbow; inverse, simulate and control, motion 'reach' or a file t,shoulder,elbow), and KEY=VALUE (repeatable) changes of its constants for the nominal model and the simulated body (forearm: keys as --plant; arm2: L01, L0G, m0, I0 and the forearm's).", show_default=False)),
    "model_file": (Optional[Path], None, typer.Option("--model-file", help="TOML or JSON file of KEY = VALUE pairs setting the nominal model (--model applies on top).", show_default=False)),
}


ARM_COMMANDS = ("inverse", "simulate", "control", "optimize")  # the commands that take --model arm2 so far


def _with_conditions(command):
    """Add the CONDITIONS options to a command; it receives them as ``conditions`` (a dict of
    RunSpec fields), the motion and model files among ``conditions['_inputs']``."""
    import functools
    import inspect

    signature = inspect.signature(command, eval_str=True)  # the annotations as objects, as typer reads them
    added = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default,
                               annotation=Annotated[kind, option])
             for name, (kind, default, option) in CONDITIONS.items()]
    kept = [p for p in signature.parameters.values() if p.name != "conditions"]

    @functools.wraps(command)
    def wrapper(**kwargs):
        values = {name: kwargs.pop(name) for name in CONDITIONS}
        conditions = _conditions(**values)
        if conditions["_model_name"] != "forearm" and command.__name__ not in ARM_COMMANDS:
            raise BadInput(f"--model {conditions['_model_name']}: not available with '{command.__name__}' yet "
                           f"(only {', '.join(ARM_COMMANDS)})")
        return command(conditions=conditions, **kwargs)

    wrapper.__signature__ = signature.replace(parameters=kept + added)
    wrapper.__annotations__ = {p.name: p.annotation for p in kept + added}
    return wrapper


def _conditions(radians, cutoff_hz, smoothing, spline_lambda, sample_dt, noise_deg, capture_hz, plant, model,
                model_file) -> dict:
    """RunSpec fields from the CONDITIONS options (KEY=VALUE pairs parsed, the model file read)."""
    names = [item.strip() for item in model or [] if "=" not in item]
    pairs = _model_file(model_file) if model_file is not None else []
    pairs += _key_values("--model", [item for item in model or [] if "=" in item])
    return dict(radians=radians, cutoff_hz=cutoff_hz, smoothing=smoothing, spline_lambda=spline_lambda,
                sample_dt=sample_dt, noise_deg=noise_deg, capture_hz=capture_hz,
                plant=tuple(_key_values("--plant", plant or [])), model=tuple(pairs),
                _inputs={"--model-file": model_file}, _model_name=_model_name(names))


def _model_name(names: list) -> str:
    """The one model named by --model (default: forearm)."""
    from .models import MODELS

    if len(set(names)) > 1:
        raise BadInput(f"--model: name one model, got {', '.join(names)}")
    name = names[0] if names else "forearm"
    if name not in MODELS:
        from .registry import unknown_name_message

        raise BadInput(f"--model: {unknown_name_message('model', name, list(MODELS))} (or KEY=VALUE)")
    return name


def _key_values(option: str, items) -> list:
    pairs = []
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise BadInput(f"{option}: expected KEY=VALUE (keys L12, L1G, m, I1, F_ext, g), got {item!r}")
        try:
            pairs.append((key.strip(), float(value)))
        except ValueError:
            raise BadInput(f"{option}: {key.strip()} must be a number, got {value!r}") from None
    return pairs


def _model_file(path: Path) -> list:
    """(key, value) pairs of a TOML or JSON model file (a table of numbers, or one table of them)."""
    from .files import BadFile, read_input_text

    try:
        text = read_input_text(path, "--model-file", 2**20)
    except BadFile as exc:
        raise BadInput(str(exc)) from None
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            import tomllib

            data = tomllib.loads(text)
    except (ValueError, RecursionError) as exc:
        raise BadInput(f"--model-file: cannot read {path} as {'JSON' if path.suffix.lower() == '.json' else 'TOML'}: "
                       f"{' '.join(str(exc).split())[:200]}") from None
    if isinstance(data, dict) and len(data) == 1 and isinstance(next(iter(data.values())), dict):
        data = next(iter(data.values()))  # [forearm] L12 = 0.3 ...
    if not isinstance(data, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                             for v in data.values()):
        raise BadInput(f"--model-file: {path} must hold KEY = number pairs (keys L12, L1G, m, I1, F_ext, g)")
    return [(str(k), float(v)) for k, v in data.items()]


def _spec_inputs(conditions: dict, kinematics: str, **others) -> dict:
    """The input files of a command (for the output checks): the motion file, the model file, others."""
    from .motion import KINEMATICS

    inputs = dict(conditions.get("_inputs", {}))
    if kinematics not in KINEMATICS:
        inputs["--motion"] = Path(kinematics)
    return {**inputs, **others}


def _fields(conditions: dict) -> dict:
    return {k: v for k, v in conditions.items() if not k.startswith("_")}


def _common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions: dict | None = None) -> dict:
    """RunSpec fields shared by every command that simulates (a motion file enters by its digest)."""
    fields = dict(kinematics=kinematics, integrator=integrator, dt=dt, rtol=rtol, atol=atol, alpha=alpha, xi=xi,
                  omega=omega, **_fields(conditions or {}))
    from .motion import KINEMATICS

    if kinematics not in KINEMATICS:
        from .experiment import motion_digest
        from .files import BadFile

        try:
            fields["inputs"] = (("--motion", motion_digest(kinematics)),)
        except BadFile as exc:
            raise BadInput(str(exc)) from None
    return fields


def _noise_seed(conditions: dict, seed: int) -> dict:
    """The seed field of a command whose only randomness is the motion's noise (none without it)."""
    return {"seed": seed} if conditions.get("noise_deg") else {}


def _check_choice(option: str, value: str, valid) -> str:
    if value not in valid:
        from .registry import unknown_name_message

        raise BadInput(f"{option}: " + unknown_name_message("value", value, list(valid)))
    return value


# output options with two names: errors name both
OUTPUT_LABELS = {"save_history": "--save-trajectory (--save-history)", "history": "--save-convergence (--history)"}


def _check_outputs(fmt: str, valid=FORMATS, inputs: dict | None = None, db=None, **paths) -> None:
    """Validate --format and every output path before any work starts: each can be written, and
    none names an input file, the results database ``db`` or another output."""
    from .files import BadFile, check_distinct, check_writable

    _check_choice("--format", fmt, valid)
    outputs = {OUTPUT_LABELS.get(option, "--" + option.replace("_", "-")): path for option, path in paths.items()
               if not (option == "output" and str(path) == "-")}  # '-o -' is stdout
    try:
        for option, path in outputs.items():
            if path is not None:
                check_writable(path, option)
        check_distinct(outputs, inputs, db)
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
    if output is None or str(output) == "-":
        if sys.stdout is None:
            raise _StdoutClosed
        sys.stdout.write(text)
        sys.stdout.flush()
    else:
        from .files import write_atomic

        write_atomic(output, text)


def _finish(record: dict, fmt: str, output, title: str, quiet: bool) -> None:
    record["command_time_s"] = time.perf_counter() - _STARTED
    _emit(_render(record, fmt, title), output)
    if output is not None and str(output) != "-":
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

        write_atomic(path, _history_text(outcome), OUTPUT_LABELS["save_history"])


def _check_store(db: Optional[Path]) -> None:
    """Refuse an unusable --db before any work starts: not a database, damaged, read-only,
    locked."""
    if db is not None:
        from .store import StoreError, open_store

        try:
            with open_store(db) as store:
                store.check_usable()
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


def _arm_only(**options) -> None:
    """Options the arm does not take yet (value, the only value allowed): bad input otherwise."""
    for name, (value, allowed) in options.items():
        if value != allowed:
            raise BadInput(f"--{name.replace('_', '-')}: not available with --model arm2 yet (only {allowed})")


def _arm(command, conditions, kinematics, fmt, output, save_history, quiet, **run) -> None:
    """inverse, simulate and control on the two-segment arm (fdbench.models.arm2_run)."""
    from .files import BadFile, csv_text

    refused = {"sample_dt": None, "noise_deg": 0.0, **({"plant": ()} if command == "optimize" else {})}
    for name, default in refused.items():
        if conditions[name] != default:
            raise BadInput(f"--{name.replace('_', '-')}: not available with --model arm2 {command} yet")
    if command in ("simulate", "control"):
        run["plant_pairs"] = conditions["plant"]
    torque_file = run.pop("torque_file", None)
    convergence = run.pop("convergence", None)
    inputs = dict(conditions["_inputs"])
    if kinematics not in ("paper", "reach"):
        inputs["--motion"] = Path(kinematics)
    _check_outputs(fmt, output=output, save_history=save_history, history=convergence,
                   inputs={**inputs, "--torque-file": torque_file})
    from .models import arm2_run

    estimate = dict(cutoff_hz=conditions["cutoff_hz"], smoothing=conditions["smoothing"],
                    spline_lambda=conditions["spline_lambda"])
    try:
        motion = arm2_run.arm_motion("reach" if kinematics == "paper" else kinematics, conditions["radians"], **estimate)
        if command == "inverse":
            record, header, rows = arm2_run.inverse_run(conditions["model"], motion)
        elif command == "optimize":
            with _progress(quiet, f"arm2: {run['torque']} + {run['optimizer']}") as progress:
                progress.start(run["budget"])
                record, header, rows, best = arm2_run.optimize_run(conditions["model"], motion,
                                                                   on_evaluation=progress.update, **run)
        else:
            torque = None if torque_file is None else arm2_run.read_arm_torque_csv(torque_file, motion.duration)
            record, header, rows = arm2_run.tracking_run(command, conditions["model"], motion, torque=torque, **run)
    except BadFile as exc:
        raise BadInput(str(exc)) from None
    except ValueError as exc:
        raise BadInput(_with_option(str(exc))) from None
    history = csv_text(header, ([f"{v:.10g}" for v in row] for row in rows))
    if command == "inverse" and fmt == "csv":
        _emit(history, output)
        return
    from .files import write_atomic

    if save_history is not None:
        write_atomic(save_history, history, OUTPUT_LABELS["save_history"])
    if convergence is not None:
        write_atomic(convergence, csv_text(["evaluation", "best_objective"], enumerate(best, start=1)),
                     OUTPUT_LABELS["history"])
    _finish(record, fmt, output, f"fdbench {command} (arm2)", quiet)


# ---- commands ---------------------------------------------------------------------------------


@app.command()
@_with_conditions
def inverse(
    kinematics: Kinematics = "paper",
    seed: NoiseSeed = 0,
    fmt: Format = "table",
    output: Output = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Inverse dynamics (eq. 3): the elbow torque that should produce the desired motion, with the nominal model.

    The table and JSON give a summary; --format csv gives the whole history (t, theta, theta_dot, theta_ddot, torque on the motion's samples, SI units; eq. 5: 1001 rows)."""
    from .experiment import RunSpec

    if conditions["_model_name"] != "forearm":
        return _arm("inverse", conditions, kinematics, fmt, output, None, quiet)
    _check_outputs(fmt, output=output, inputs=_spec_inputs(conditions, kinematics))
    spec = _validated(RunSpec(command="simulate", **_noise_seed(conditions, seed),
                              **_common(kinematics, "rk4", 1e-3, 1e-6, 1e-9, 1e7, 1.0, 10.0, conditions)))
    import numpy as np

    from .inverse import inverse_dynamics

    settings = spec.settings()
    desired, _ = spec.motions()
    start = time.perf_counter()
    inv = inverse_dynamics(desired.samples, settings.nominal_model, desired)
    runtime = time.perf_counter() - start
    if fmt == "csv":
        from .files import csv_text

        rows = np.column_stack([inv.t, inv.theta, inv.theta_dot, inv.theta_ddot, inv.torque])
        text = csv_text(["t", "theta", "theta_dot", "theta_ddot", "torque"], ([f"{v:.10g}" for v in row] for row in rows))
        _emit(text, output)
        return
    record = {
        "command": "inverse", "kinematics": kinematics, **spec.describe(),
        "theta_start_deg": float(np.degrees(inv.theta[0])), "theta_end_deg": float(np.degrees(inv.theta[-1])),
        "torque_min_nm": float(inv.torque.min()), "torque_max_nm": float(inv.torque.max()),
        "torque_start_nm": float(inv.torque[0]), "torque_end_nm": float(inv.torque[-1]),
        "torque_rms_nm": float(np.sqrt(np.mean(inv.torque**2))), "runtime_s": runtime,
        "fdbench_version": __version__,
    }
    _finish(record, fmt, output, "fdbench inverse", quiet)


@app.command()
@_with_conditions
def simulate(
    torque_file: Annotated[Optional[Path], typer.Option("--torque-file", help="CSV with columns t (s) and torque (N m) covering the motion's span (eq. 5: [0, 1] s), linearly interpolated. Default: the inverse-dynamics torque.")] = None,
    params: Annotated[Optional[Path], typer.Option("--params", help="Parameters saved by 'fdbench optimize --save-params'.")] = None,
    kinematics: Kinematics = "paper",
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
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Open-loop forward dynamics (eq. 12) driven by a torque history: by default the inverse-dynamics torque, whose drift from the desired motion motivates the paper."""
    from .experiment import RunSpec

    if conditions["_model_name"] != "forearm":
        _arm_only(integrator=(integrator, "rk4"), params=(params, None))
        return _arm("simulate", conditions, kinematics, fmt, output, save_history, quiet, torque_file=torque_file,
                    dt=dt, alpha=alpha, xi=xi, omega=omega)
    _check_outputs(fmt, output=output, save_history=save_history,
                   inputs=_spec_inputs(conditions, kinematics, **{"--torque-file": torque_file, "--params": params}))
    if torque_file is not None and params is not None:
        raise BadInput("--torque-file and --params: give one of them, not both")
    spec = _validated(RunSpec(command="simulate", **_noise_seed(conditions, seed),
                              **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)))
    from .experiment import run_simulation
    from .files import BadFile

    try:
        outcome = run_simulation(spec, torque_file=torque_file, params_file=params)
    except BadFile as exc:
        raise BadInput(str(exc)) from None
    _save_history(outcome, save_history)
    _finish(outcome.record, fmt, output, "fdbench simulate", quiet)


@app.command()
@_with_conditions
def control(
    controller: Annotated[str, typer.Option("--controller", help="pd (the paper's), computed-torque, lqr, or one registered by a plugin (see 'fdbench methods').")] = "pd",
    kp: Annotated[float, typer.Option("--kp", help="pd: proportional gain, N m/rad (paper: 80).")] = 80.0,
    kd: Annotated[float, typer.Option("--kd", help="pd: derivative gain, N m s/rad (paper: 0.3).")] = 0.3,
    bandwidth: Annotated[float, typer.Option("--bandwidth", help="computed-torque: error-dynamics natural frequency omega_n, rad/s.")] = 20.0,
    damping: Annotated[float, typer.Option("--damping", help="computed-torque: error-dynamics damping ratio zeta.")] = 1.0,
    q_angle: Annotated[float, typer.Option("--q-angle", help="lqr: weight of the squared angle error, rad^-2 (1e4: 0.01 rad costs as much as 1 N m).")] = 1e4,
    q_rate: Annotated[float, typer.Option("--q-rate", help="lqr: weight of the squared rate error, s^2 rad^-2.")] = 1.0,
    r_torque: Annotated[float, typer.Option("--r-torque", help="lqr: weight of the squared torque correction, (N m)^-2; positive.")] = 1.0,
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
    seed: NoiseSeed = 0,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Feedback control: PD with computed feedforward (eqs. 13-14, the default), computed-torque control or time-varying LQR about the desired motion."""
    from .experiment import control_spec, run

    if conditions["_model_name"] != "forearm":
        _arm_only(integrator=(integrator, "rk4"), db=(db, None))
        options = dict(kp=kp, kd=kd, bandwidth=bandwidth, damping=damping, q_angle=q_angle, q_rate=q_rate,
                       r_torque=r_torque)
        _check_controller(controller, options)
        if controller not in ("pd", "computed-torque", "lqr"):
            raise BadInput(f"--controller {controller}: not available with --model arm2 yet (pd, computed-torque, lqr)")
        return _arm("control", conditions, kinematics, fmt, output, save_history, quiet, dt=dt, alpha=alpha, xi=xi,
                    omega=omega, controller=controller, **options)
    _check_outputs(fmt, output=output, save_history=save_history, db=db, inputs=_spec_inputs(conditions, kinematics))
    options = dict(kp=kp, kd=kd, bandwidth=bandwidth, damping=damping, q_angle=q_angle, q_rate=q_rate, r_torque=r_torque)
    _check_controller(controller, options)
    spec = _validated(control_spec(kp, kd, controller, options, **_noise_seed(conditions, seed),
                                   **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)))
    _check_store(db)
    outcome = run(spec)
    _save_history(outcome, save_history)
    _store(outcome, spec, db, quiet)
    _finish(outcome.record, fmt, output, "fdbench control", quiet)


def _check_controller(name: str, options: dict) -> None:
    """An unknown --controller, or an out-of-range option of any registered controller that
    takes it (``--bandwidth -1`` with ``--controller pd`` too), is bad input."""
    import inspect

    from .controllers import CONTROLLERS
    from .registry import UnknownName

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
    max_iter: Annotated[int, typer.Option("--max-iter", help="IPOPT iteration limit.")] = 1000,
    max_time: Annotated[float, typer.Option("--max-time", help="IPOPT CPU-time limit, s.")] = 60.0,
    save_torque: Annotated[Optional[Path], typer.Option("--save-torque", help="Write the torque found as CSV (t, torque) to FILE, readable by 'fdbench simulate --torque-file'.")] = None,
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
    seed: NoiseSeed = 0,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Direct-collocation tracking (as OpenSim Moco, bioptim, Drake): states and torque are the unknowns of one sparse problem solved by IPOPT; the torque found is then replayed by fdbench's forward simulation, whose indicators are reported."""
    from .experiment import collocate_spec, run

    _check_outputs(fmt, output=output, save_history=save_history, save_torque=save_torque, db=db,
                   inputs=_spec_inputs(conditions, kinematics))
    spec = _validated(collocate_spec(nodes, scheme, regularization, max_iter, max_time, **_noise_seed(conditions, seed),
                                     **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)))
    try:
        import casadi  # noqa: F401
    except ImportError as exc:
        raise ImportError(f"'fdbench collocate' needs casadi (pip install casadi): {exc}") from None
    _check_store(db)
    outcome = run(spec)
    _save_history(outcome, save_history)
    if save_torque is not None:
        from .files import write_atomic

        write_atomic(save_torque, _collocation_torque_text(outcome.extra["collocation"], spec), "--save-torque")
    _store(outcome, spec, db, quiet)
    _finish(outcome.record, fmt, output, "fdbench collocate", quiet)


def _collocation_torque_text(solution, spec) -> str:
    """The torque found on the half-step grid of the run's RK4 (so that 'simulate --torque-file'
    with the same --dt replays exactly what collocate replayed), as CSV t (s), torque (N m)."""
    from .files import csv_text
    from .integrate import half_step_reference, steps

    half, _, _ = half_step_reference(steps(spec.dt), spec.kinematics)
    torque = solution.torque_samples(half)
    return csv_text(["t", "torque"], ([f"{t:.17g}", f"{q:.17g}"] for t, q in zip(half, torque)))


def _check_gradient(gradient: str) -> None:
    from .experiment import GRADIENTS

    if gradient not in GRADIENTS:
        raise BadInput(f"--gradient must be one of {', '.join(GRADIENTS)}, got {gradient!r}")


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
    from .controllers import CONTROLLERS

    lines += ["controllers (control --controller):"]
    lines += [f"  {name:<15} {cls.summary}" for name, cls in CONTROLLERS.items()]
    from .models import MODELS, summary

    lines += ["models (--model):"] + [f"  {name:<12} {summary(name)}" for name in MODELS]
    return "\n".join(lines) + "\n"


@app.command()
def methods():
    """List the registered torque parameterisations, optimisers, controllers and models, one line each."""
    _emit(_methods_text(), None)


@app.command()
@_with_conditions
def optimize(
    torque: Annotated[str, typer.Option("--torque", help="Torque parameterisation (see 'fdbench methods').")] = "cs",
    opt: Annotated[str, typer.Option("--opt", help="Optimiser (see 'fdbench methods').")] = "bfgs",
    feedforward: Annotated[bool, typer.Option("--feedforward/--no-feedforward", help="Add the inverse-dynamics torque (Table 3) or not (Table 2).")] = False,
    budget: Budget = 200,
    seed: Annotated[int, typer.Option("--seed", help="Seed of every stochastic step; the same seed gives the same numbers.")] = 0,
    hidden: Hidden = "4",
    knots: Knots = 11,
    terms: Terms = 4,
    sigma0: Sigma0 = None,
    popsize: Popsize = None,
    gradient: Gradient = "fd",
    threads: Threads = None,
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
    from .experiment import optimize_spec, run

    _check_outputs(fmt, output=output, save_history=save_history, history=history, save_params=save_params, db=db,
                   inputs=_spec_inputs(conditions, kinematics))
    _check_finite(sigma0=sigma0 if sigma0 is not None else 1.0, penalty_weight=penalty_weight)
    torque_options = {"hidden": _parse_hidden(hidden), "knots": knots, "terms": terms}
    optimizer_options = {"sigma0": sigma0, "popsize": popsize}
    _check_method_options(torque_options, optimizer_options)
    _check_gradient(gradient)
    if threads is not None and not 1 <= threads <= MAX_THREADS:
        raise BadInput(f"--threads must be an integer in [1, {MAX_THREADS}], got {threads}")
    arm = conditions["_model_name"] != "forearm"
    checked = {**conditions, "model": (), "plant": ()} if arm else conditions  # the arm's constants: checked later
    spec = _validated(optimize_spec(  # for the arm: the checks of names, budget, seed and settings
        torque, opt, feedforward, seed, budget, torque_options=torque_options, optimizer_options=optimizer_options,
        penalty_weight=penalty_weight, gradient=gradient, **_common("paper" if arm else kinematics, integrator, dt, rtol,
                                                                    atol, alpha, xi, omega, checked),
    ))
    if arm:
        _arm_only(integrator=(integrator, "rk4"), db=(db, None), save_params=(save_params, None),
                  gradient=(gradient, "fd"))
        if hidden == "auto":
            raise BadInput("--hidden auto: not available with --model arm2 yet (give a number of neurons)")
        return _arm("optimize", conditions, kinematics, fmt, output, save_history, quiet, convergence=history,
                    torque=torque, optimizer=opt, feedforward=feedforward, seed=seed, budget=budget,
                    torque_options=torque_options, optimizer_options=optimizer_options,
                    penalty_weight=penalty_weight, dt=dt, alpha=alpha, xi=xi, omega=omega)
    _check_store(db)
    if opt == "cmaes":
        from .population import set_threads

        set_threads(threads)
    with _progress(quiet, f"{torque} + {opt}") as progress:
        outcome = run(spec, on_evaluation=progress.update, on_start=progress.start)
    if "hidden_fits" in outcome.extra:
        fits = ", ".join(f"{n}: {err:.2e}" for n, err in outcome.extra["hidden_fits"])
        _say(quiet, f"--hidden auto: fit RMSE / torque range by neurons: {fits}")
    _save_history(outcome, save_history)
    if history is not None:
        from .files import csv_text, write_atomic

        write_atomic(history, csv_text(["evaluation", "best_objective"], enumerate(outcome.history, start=1)), OUTPUT_LABELS["history"])
    if save_params is not None:
        from .files import write_atomic
        from .params_file import params_json

        write_atomic(save_params, params_json(spec, outcome), "--save-params")
    _store(outcome, spec, db, quiet)
    _finish(outcome.record, fmt, output, "fdbench optimize", quiet)


@app.command()
@_with_conditions
def report(
    torque: TorqueSelection = None,
    opt: OptSelection = None,
    feedforward: FeedforwardSelection = None,
    control: WithControl = True,
    beyond: Annotated[bool, typer.Option("--beyond/--no-beyond", help="Include the table 'Beyond the paper': computed-torque and LQR control, direct collocation.")] = True,
    all_cells: AllCells = False,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per cell, in [1, 1000]: seeds 0..N-1; medians and IQRs over them.")] = 5,
    budget: Budget = 200,
    jobs: Jobs = None,
    backend: BackendName = "local",
    scheduler: Scheduler = None,
    db: StoreDb = None,
    rerun: Rerun = False,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write PNG figures into DIR (created if missing) and link them.")] = None,
    kp: Kp = 80.0,
    kd: Kd = 0.3,
    hidden: Hidden = "4",
    knots: Knots = 11,
    terms: Terms = 4,
    sigma0: Sigma0 = None,
    popsize: Popsize = None,
    gradient: Gradient = "fd",
    penalty_weight: PenaltyWeight = 1.0,
    kinematics: Kinematics = "paper",
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Annotated[str, typer.Option("--format", "-f", help="Report format: md (Markdown), csv (one row per cell) or json (settings and cells with medians, IQRs, success counts and the ids of their stored runs).")] = "md",
    output: Output = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """The paper's whole comparison: PD control, Table 2 and Table 3, with our figures beside the published ones, as Markdown or CSV.

    Every run is stored in the results database; stored runs are reused, so an interrupted report resumes and a repeated one returns at once."""
    from .benchmark import default_cells, make_plan
    from .store import default_path

    db_path = db if db is not None else default_path()
    _check_outputs(fmt, REPORT_FORMATS, db=db_path, output=output, inputs=_spec_inputs(conditions, kinematics))
    if figures is not None:
        _check_figures_dir(figures, output, db_path)
    torque_options, optimizer_options = _sweep_options(seeds, jobs, torque, opt, hidden, knots, terms, sigma0, popsize,
                                                       penalty_weight)
    executor = _backend(backend, jobs, scheduler)
    cells = default_cells(torque, opt, feedforward, all_cells)
    if not cells and not control and not beyond:
        raise BadInput("nothing to run: the options select no cell, --no-control and --no-beyond")
    _check_gradient(gradient)
    plan = make_plan(
        cells, seeds, budget, control, kp, kd, torque_options=torque_options,
        optimizer_options=optimizer_options, penalty_weight=penalty_weight,
        **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions),
    )  # Tables 2 and 3 keep the paper's finite differences; exact gradients go to "Beyond the paper"
    for spec in ([plan.control] if plan.control else []) + [plan.specs[c][0] for c in plan.cells]:
        _validated(spec)
    from .store import open_store

    jobs = jobs or os.cpu_count() or 1
    methods = None
    if beyond:
        from .beyond import beyond_methods

        methods = beyond_methods(**_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions))
    if gradient == "exact":
        from .beyond import exact_gradient_methods

        methods = (methods or []) + exact_gradient_methods(
            plan.cells, budget, torque_options, optimizer_options, penalty_weight,
            **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions))
        for method in methods:
            _validated(method.spec)
    extra = [m.spec for m in methods] if methods else []
    runs = _run_specs(plan.all_specs() + extra, db_path, db is None, executor, rerun, quiet)
    from .report import build_rows

    start = time.perf_counter()
    inverse = (plan.control or plan.all_specs()[0]).reference()
    inverse_runtime = time.perf_counter() - start
    with open_store(db_path) as store:
        made = store.provenance(runs)
    rows = build_rows(plan, runs, made)
    extra_rows = []
    if methods:
        from .beyond import beyond_rows

        extra_rows = beyond_rows(methods, runs)
    _emit(_report_text(fmt, plan, runs, rows, extra_rows, methods, inverse, inverse_runtime, seeds,
                       _parallelism(backend, jobs, scheduler), figures, output, quiet), output)
    if output is not None and str(output) != "-":
        _say(quiet, f"wrote {output} ({len(plan.all_specs())} runs, database {db_path})")


@app.command()
@_with_conditions
def study(
    kind: Annotated[str, typer.Argument(help="noise: the motion captured with white noise of each level (deg); mismatch: one constant of the simulated body changed by each level (percent) while the methods keep the nominal model.", metavar="noise|mismatch")],
    levels: Annotated[str, typer.Option("--levels", help="The levels, comma-separated: deg for noise (e.g. 0,0.25,0.5,1,2), percent for mismatch (e.g. -20,-10,0,10,20).")] = "",
    param: Annotated[str, typer.Option("--param", help="mismatch: the plant constant changed: L12, L1G, m, I1, F_ext or g.")] = "I1",
    torque: TorqueSelection = None,
    opt: OptSelection = None,
    feedforward: FeedforwardSelection = None,
    control: WithControl = True,
    all_cells: AllCells = False,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per method and level, in [1, 1000]: seeds 0..N-1 (the noise realisation and the optimiser's seed).")] = 5,
    budget: Budget = 200,
    jobs: Jobs = None,
    backend: BackendName = "local",
    scheduler: Scheduler = None,
    db: StoreDb = None,
    rerun: Rerun = False,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write one PNG per indicator into DIR (created if missing): level on x, median and IQR band per method.")] = None,
    kp: Kp = 80.0,
    kd: Kd = 0.3,
    hidden: Hidden = "4",
    knots: Knots = 11,
    terms: Terms = 4,
    sigma0: Sigma0 = None,
    popsize: Popsize = None,
    gradient: Gradient = "fd",
    penalty_weight: PenaltyWeight = 1.0,
    kinematics: Kinematics = "paper",
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Annotated[str, typer.Option("--format", "-f", help="md (tables per indicator) or csv (one row per method and level).")] = "md",
    output: Output = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Sweep one condition over the methods: 'fdbench study noise --levels 0,0.25,0.5,1,2 --seeds 10' or 'fdbench study mismatch --param I1 --levels -20,-10,0,10,20'.

    Runs are stored and reused like a report's (resume, --jobs, --rerun); the table gives the median and IQR of each indicator per method and level."""
    from . import study as studies
    from .benchmark import default_cells
    from .store import default_path

    _check_choice("study", kind, studies.KINDS)
    db_path = db if db is not None else default_path()
    _check_outputs(fmt, ("md", "csv"), db=db_path, output=output, inputs=_spec_inputs(conditions, kinematics))
    if not levels:
        raise BadInput("--levels: give the levels to sweep, e.g. --levels " + ("0,0.5,1,2" if kind == "noise" else "-20,0,20"))
    try:
        parsed = studies.parse_levels(levels, kind)
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    if kind == "noise" and conditions["noise_deg"]:
        raise BadInput("--noise-deg: the noise study sets the noise itself (--levels)")
    if kind == "mismatch":
        from .model import MODEL_KEYS

        _check_choice("--param", param, MODEL_KEYS)
    if figures is not None:
        _check_study_figures(figures, output, db_path)
    torque_options, optimizer_options = _sweep_options(seeds, jobs, torque, opt, hidden, knots, terms, sigma0, popsize,
                                                       penalty_weight)
    executor = _backend(backend, jobs, scheduler)
    cells = default_cells(torque, opt, feedforward, all_cells)
    if not cells and not control:
        raise BadInput("nothing to run: the options select no cell and --no-control")
    _check_gradient(gradient)
    try:
        sweep = studies.make_sweep(kind, parsed, seeds, cells, control, kp, kd, budget, torque_options,
                                   optimizer_options, penalty_weight, param if kind == "mismatch" else None,
                                   gradient=gradient,
                                   **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions))
    except ValueError as exc:
        raise BadInput(_with_option(str(exc))) from None
    for key in sweep.specs:
        _validated(sweep.specs[key][0])
    jobs = jobs or os.cpu_count() or 1
    runs = _run_specs(sweep.all_specs(), db_path, db is None, executor, rerun, quiet)
    rows = studies.summary(sweep, runs)
    if fmt == "csv":
        from .files import csv_text

        _emit(csv_text(list(studies.CSV_COLUMNS), studies.csv_rows(sweep, rows)), output)
    else:
        links = None
        if figures is not None:
            written = studies.write_figures(sweep, rows, figures)
            base = output.parent if output is not None else Path(".")
            links = {title: os.path.relpath(path, base) for title, path in written.items()}
            _say(quiet, f"wrote {len(written)} figures to {figures}")
        settings = _study_settings(sweep, seeds, budget, _parallelism(backend, jobs, scheduler), kinematics, integrator, dt)
        _emit(studies.markdown(sweep, rows, settings, links), output)
    if output is not None and str(output) != "-":
        _say(quiet, f"wrote {output} ({len(sweep.all_specs())} runs, database {db_path})")


def _study_settings(sweep, seeds, budget, jobs, kinematics, integrator, dt) -> dict:
    from .store import machine

    spec = sweep.all_specs()[0]
    described = spec.describe()
    return {
        "study": sweep.kind + (f" of {sweep.param}" if sweep.param else ""),
        "levels": ", ".join(f"{v:g}" for v in sweep.levels) + f" {'deg' if sweep.kind == 'noise' else '%'}",
        "motion": f"{kinematics} ({described['duration_s']:g} s, {described['samples']} samples)",
        "derivative estimate": ("Butterworth zero-lag, then spline" if spec.smoothing == "butterworth"
                                else "smoothing spline") + (f", cutoff {spec.cutoff_hz:g} Hz" if spec.smoothing == "butterworth" else ""),
        "integrator": integrator + (f" (dt = {dt} s)" if integrator == "rk4" else ""),
        "seeds": f"{seeds} per method and level (PD: one run where the runs would be identical)",
        "budget": f"{budget} evaluations per optimisation",
        "runs": str(len(sweep.all_specs())),
        "parallel jobs": str(jobs),
        "fdbench": __version__,
        "machine": machine(),
    }


def _check_study_figures(directory: Path, output: Optional[Path], db: Path) -> None:
    """As for the report's --figures: refuse before the work a folder that cannot take them."""
    from .study import FIGURE_NAMES

    _check_figures_dir(directory, output, db, FIGURE_NAMES)


def _sweep_options(seeds, jobs, torques, optimizers, hidden, knots, terms, sigma0, popsize, penalty_weight):
    """The checks shared by the commands that run many specs (report, study), before any work;
    returns the (torque options, optimizer options) of their cells."""
    if not 1 <= seeds <= MAX_SEEDS:
        raise BadInput(f"--seeds must be an integer in [1, {MAX_SEEDS}], got {seeds}")
    if jobs is not None and not 1 <= jobs <= MAX_JOBS:
        raise BadInput(f"--jobs must be an integer in [1, {MAX_JOBS}], got {jobs}")
    _check_finite(sigma0=sigma0 if sigma0 is not None else 1.0, penalty_weight=penalty_weight)
    _check_names(torques, optimizers)
    torque_options = {"hidden": _parse_hidden(hidden), "knots": knots, "terms": terms}
    optimizer_options = {"sigma0": sigma0, "popsize": popsize}
    _check_method_options(torque_options, optimizer_options)
    return torque_options, optimizer_options


def _run_specs(specs, db_path: Path, default_db: bool, executor, rerun: bool, quiet: bool) -> dict:
    """Make sure every spec is stored in the database (missing runs carried out by the backend,
    each stored as it finishes), with a progress bar; {spec hash: stored run}. An unusable
    database or backend is bad input; SIGTERM ends the command like Ctrl-C, exit 143."""
    from .execution import BackendError, Terminated, execute_specs, sigterm_as_interrupt
    from .store import StoreError, open_store

    existed = db_path.exists()
    try:
        with sigterm_as_interrupt(), open_store(db_path) as store:
            store.check_usable()
            if not existed:
                _say_creating(db_path, default_db, quiet)
            with _progress(quiet, "runs") as progress:

                def on_done(done, total):
                    if progress.bar is None:
                        progress.start(total, show_best=False)
                    progress.update(done)

                return execute_specs(specs, store, executor, rerun, on_done)
    except StoreError as exc:
        raise BadInput(f"--db: {exc}") from None
    except BackendError as exc:
        raise BadInput(str(exc)) from None
    except Terminated:
        _error("terminated")
        raise typer.Exit(143) from None


REPORT_FORMATS = ("md", "csv", "json")


def _say_creating(db_path: Path, default: bool, quiet: bool) -> None:
    """One line on stderr when a report has created its results database."""
    hint = " (choose another with --db or $FDBENCH_DB)" if default else ""
    _say(quiet, f"creating results database {db_path}{hint}")


def _report_text(fmt, plan, runs, rows, extra_rows, methods, inverse, inverse_runtime, seeds, jobs, figures, output,
                 quiet) -> str:
    from .report import settings_table

    if fmt == "csv":
        from .beyond import beyond_csv_rows
        from .files import csv_text
        from .report import CSV_COLUMNS, csv_rows

        return csv_text(list(CSV_COLUMNS), csv_rows(rows) + beyond_csv_rows(extra_rows))
    if fmt == "json":
        from .report import json_report

        return json.dumps(json_report(rows + extra_rows, settings_table(plan, seeds, jobs)), indent=2) + "\n"
    from .beyond import beyond_markdown
    from .report import markdown

    links = None
    if figures is not None:
        from .figures import write_report_figures

        links = write_report_figures(plan, runs, rows, inverse, figures, output.parent if output is not None else Path("."))
        _say(quiet, f"wrote {len(links)} figures to {figures}")
    section = beyond_markdown(extra_rows, methods) if methods else None
    return markdown(rows, inverse, inverse_runtime, settings_table(plan, seeds, jobs), links, beyond=section)


def _check_figures_dir(directory: Path, output: Optional[Path], db: Path, names=None) -> None:
    """Refuse, before the work, a --figures folder that cannot take the figures: a file, the
    report's own output, a missing parent, an unwritable folder, or a figure file in it that
    would be refused (read-only, a directory, the database)."""
    from .figures import FIGURE_FILES
    from .files import BadFile, check_distinct, check_writable, same_file

    if directory.exists() and not directory.is_dir():
        raise BadInput(f"--figures: {directory} exists and is not a directory")
    if output is not None and same_file(directory, output):
        raise BadInput(f"--figures: {directory} is also the report's --output; give the figures a folder of their own")
    if not directory.exists():
        if not directory.parent.is_dir():
            raise BadInput(f"--figures: directory {directory.parent} does not exist")
        if not os.access(directory.parent, os.W_OK):
            raise BadInput(f"--figures: directory {directory.parent} is not writable")
        return
    if not os.access(directory, os.W_OK):
        raise BadInput(f"--figures: directory {directory} is not writable")
    try:
        paths = {f"--figures ({name})": directory / name for name in (names or FIGURE_FILES)}
        for option, path in paths.items():
            check_writable(path, option)
        check_distinct({"--output": output, **paths}, database=db)
    except BadFile as exc:
        raise BadInput(str(exc)) from None


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
        from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                   TimeRemainingColumn)

        columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn()]
        if show_best:
            columns.append(TextColumn("best {task.fields[best]}"))
        # elapsed and time left from the first evaluations on: a slow integrator shows at once
        columns += [TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn()]
        self.bar = Progress(*columns, console=_console(), transient=True, speed_estimate_period=10)
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
