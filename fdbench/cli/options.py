"""Options declared once and shared by the commands.

- Single options (``Kinematics``, ``Output``, ``Quiet``...): ``Annotated`` types a command's
  parameter takes.
- Option groups (``Simulation``, ``RunOutputs``, ``Execution``, ``Cells``, ``Optimisation``):
  frozen dataclasses whose fields are options or other groups (``runs.OneRun``, ``sweeps.Batch``).
  A command takes one by a parameter annotated with it; ``with_groups`` puts the group's options in
  the command's signature (typer reads ``__signature__``), shown under the group's panel in --help,
  and hands the command one instance.
- Method options (``--kp``, ``--knots``, ``--sigma0``...): generated from what the registered
  methods declare (``fdbench.method_options.MethodOption``), by ``methods_command``, when the
  command runs or shows its help: a method registered by a plugin gets its flags without a change
  here, and ``fdbench --help`` imports no registry.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import inspect
import typing
from pathlib import Path
from typing import Annotated, Optional

import typer
from typer.core import TyperCommand

from .app import BadInput
from .common import check_outputs, check_store, finish, store_run, write_trajectory
from .conditions import MOTION_PANEL, run_fields

MAX_THREADS = 1024
KINEMATICS_HELP = ("Desired motion: 'paper' (eq. 5 with its derivatives as printed; reproduces the paper; the default), "
                   "'exact' (eq. 5 differentiated by the chain rule through t*), or a CSV file of a recorded joint angle: "
                   "columns t (s) and theta (deg; --radians), optionally theta_vel and theta_acc (deg/s, deg/s^2), any "
                   "duration and sampling, as 'fdbench inverse --format csv' and --save-trajectory write them. With another model (--model arm2, leg3 or a file): "
                   "one of the motions its file declares (the library's: 'fdbench models show NAME'; the first is the default) or a "
                   "CSV file t,<joint>... with one angle column per joint (optionally <joint>_vel, <joint>_acc). --kinematics is an older name.")
INTEGRATOR_HELP = "rk4 (compiled, fixed step) or a scipy solve_ivp method: rk45, dop853, lsoda, radau, bdf."

Kinematics = Annotated[Optional[str], typer.Option("--motion", "--kinematics", help=KINEMATICS_HELP, show_default=False,
                                                   rich_help_panel=MOTION_PANEL)]
Dt = Annotated[float, typer.Option("--dt", help="RK4 step, s, in [1e-6, 0.1].")]
Alpha = Annotated[float, typer.Option("--alpha", help="Penalty factor of eq. 12, in [1, 1e15].")]
Xi = Annotated[float, typer.Option("--xi", help="Penalty damping ratio of eq. 12.")]
Omega = Annotated[float, typer.Option("--omega", help="Penalty natural frequency of eq. 12, rad/s.")]
Format = Annotated[str, typer.Option("--format", "-f", help="Output: table (for a person), json or csv.")]
Output = Annotated[Optional[Path], typer.Option("--output", "-o", help="Write the result to FILE instead of stdout ('-': stdout). A regular file is replaced atomically, a symlink written through, a device written in place; a read-only file, an input of the command or the results database is refused.")]
SaveHistory = Annotated[Optional[Path], typer.Option("--save-trajectory", "--save-history", help="Write the run's trajectory, its time history (one row per sample of the motion, 1001 for eq. 5), as CSV to FILE in a motion file's units, so that --motion reads back the simulated angle and --torque-file the applied torque: t (s), theta, theta_desired (deg), theta_vel, theta_vel_desired (deg/s), theta_acc, theta_acc_desired (deg/s^2), theta_torque, theta_torque_inverse (N m); another model: the same per joint, <joint>, <joint>_desired, <joint>_vel, <joint>_vel_desired, <joint>_acc, <joint>_acc_desired, <joint>_torque, <joint>_torque_inverse (a free joint's translations in m, m/s, m/s^2 and N). --save-history is an older name.")]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress or messages on stderr.")]
NoiseSeed = Annotated[int, typer.Option("--seed", help="Seed of the --noise-deg noise; the same seed gives the same noisy motion.")]
Db = Annotated[Optional[Path], typer.Option("--db", help="Also store the run in this results database (SQLite).")]


def format_option(choices, help_text: str):
    """--format of a command whose formats are fixed (its help lists them as choices)."""
    return typer.Option("--format", "-f", metavar="[" + "|".join(choices) + "]", help=help_text)


Threads = Annotated[Optional[int], typer.Option("--threads", help=f"Threads evaluating a CMA-ES population at once, in [1, {MAX_THREADS}] (default: the cores available); the numbers do not depend on it.", show_default=False)]


# ---- option groups ------------------------------------------------------------------------------

def option_group(panel: str | None):
    """Class decorator: a frozen dataclass whose fields are options (``Annotated[type,
    typer.Option(...)] = default``) or groups, shown under ``panel`` in --help (None: an option's own
    panel, or none)."""

    def make(cls):
        cls = dataclasses.dataclass(frozen=True)(cls)
        cls.panel = panel
        return cls

    return make


def _is_group(annotation) -> bool:
    return isinstance(annotation, type) and hasattr(annotation, "panel") and dataclasses.is_dataclass(annotation)


def _group_parameters(group, panel: str | None = None) -> tuple[list, typing.Callable]:
    """The options of ``group`` and of the groups among its fields as keyword-only parameters, each
    under its own panel, else its group's, else ``panel``; and the function that makes the group
    from the command's keyword arguments (taking its options out of them)."""
    hints = typing.get_type_hints(group, include_extras=True)
    panel = group.panel or panel
    parameters, makers = [], {}
    for field in dataclasses.fields(group):
        if _is_group(hints[field.name]):
            inner, makers[field.name] = _group_parameters(hints[field.name], panel)
            parameters += inner
            continue
        kind, info = typing.get_args(hints[field.name])
        info = copy.copy(info)  # an option shared with a command outside the group keeps its own panel
        info.rich_help_panel = info.rich_help_panel or panel
        parameters.append(inspect.Parameter(field.name, inspect.Parameter.KEYWORD_ONLY, default=field.default,
                                            annotation=Annotated[kind, info]))
        makers[field.name] = None  # an option: its value as given
    return parameters, lambda kwargs: group(**{name: kwargs.pop(name) if make is None else make(kwargs)
                                               for name, make in makers.items()})


class MethodValues(dict):
    """The values of a command's method options, {registry: {option: value}} (``methods_command``)."""


METHOD_VALUES = "fdbench.method_values"


def with_groups(command):
    """A command whose parameters annotated with an option group take the group's options (each
    handed over as one instance of the group) and whose ``MethodValues`` parameter receives its
    method options (see ``methods_command``)."""
    signature = inspect.signature(command, eval_str=True)  # annotations as objects, as typer reads them
    flat, groups, methods, context = [], {}, None, None
    for parameter in signature.parameters.values():
        annotation = parameter.annotation
        if _is_group(annotation):
            fields, groups[parameter.name] = _group_parameters(annotation)
            flat += fields
            continue
        if annotation is MethodValues:
            methods = parameter.name
            continue
        if annotation is typer.Context:
            context = parameter.name
        flat.append(parameter.replace(kind=inspect.Parameter.KEYWORD_ONLY))

    @functools.wraps(command)
    def wrapper(**kwargs):
        for name, make in groups.items():
            kwargs[name] = make(kwargs)
        if methods is not None:
            kwargs[methods] = kwargs[context].meta.get(METHOD_VALUES, MethodValues())
        return command(**kwargs)

    wrapper.__signature__ = signature.replace(parameters=flat)
    wrapper.__annotations__ = {p.name: p.annotation for p in flat}
    return wrapper


@option_group("Simulation")
class Simulation:
    """How every run integrates: the integrator, its step and tolerances, and eq. 12's penalty."""

    integrator: Annotated[str, typer.Option("--integrator", help=INTEGRATOR_HELP)] = "rk4"
    dt: Dt = 1e-3
    rtol: Annotated[float, typer.Option("--rtol", help="Relative tolerance (solve_ivp integrators), in [100 eps, 1) (100 eps = 2.220446e-14).")] = 1e-6
    atol: Annotated[float, typer.Option("--atol", help="Absolute tolerance (solve_ivp integrators), in [1e-30, 1].")] = 1e-9
    alpha: Alpha = 1e7
    xi: Xi = 1.0
    omega: Omega = 10.0

    def spec_fields(self, kinematics: str, conditions: dict | None) -> dict:
        """RunSpec fields of a run on ``kinematics`` under ``conditions`` (see ``run_fields``)."""
        return run_fields(kinematics, **dataclasses.asdict(self), conditions=conditions)


@option_group("Output")
class RunOutputs:
    """Where a command of one run writes: its record, the trajectory, the results database."""

    fmt: Format = "table"
    output: Output = None
    save_history: SaveHistory = None
    db: Db = None
    quiet: Quiet = False

    def check(self, inputs: dict, **paths) -> None:
        """The format and every output checked before any work (see ``common.check_outputs``)."""
        check_outputs(self.fmt, output=self.output, save_history=self.save_history, db=self.db, inputs=inputs, **paths)

    def check_store(self) -> None:
        check_store(self.db)

    def deliver(self, outcome, spec, title: str, write_more=None) -> None:
        """Store the run (before any output is written), write its trajectory, the command's own
        files (``write_more()``), then its record."""
        store_run(outcome, spec, self.db, self.quiet)
        write_trajectory(outcome, self.save_history)
        if write_more is not None:
            write_more()
        finish(outcome.record, self.fmt, self.output, title, self.quiet)


@option_group("Execution")
class Execution:
    """Where the runs of a report or a study are carried out and stored."""

    jobs: Annotated[Optional[int], typer.Option("--jobs", "-j", help="Runs at once, in [1, 256]: worker processes of the local backend, or of a local Dask cluster (default: the number of cores).", show_default=False)] = None
    backend: Annotated[str, typer.Option("--backend", help="Where runs are carried out: 'local' (worker processes on this machine, --jobs of them) or 'dask' (a Dask cluster: the scheduler at --scheduler, or a local cluster of --jobs workers; needs pip install '.[dask]' in fdbench's source folder).")] = "local"
    scheduler: Annotated[Optional[str], typer.Option("--scheduler", metavar="ADDRESS", help="Address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (with --backend dask; its workers need the same fdbench version). Whoever reaches a tcp:// scheduler can run code on its workers: across a network or a shared machine use tls://HOST:PORT, with the client's files in Dask's configuration (DASK_DISTRIBUTED__COMM__TLS__CA_FILE, __CLIENT__CERT, __CLIENT__KEY; see the README).", show_default=False)] = None
    db: Annotated[Optional[Path], typer.Option("--db", help="Results database (default: $FDBENCH_DB or ./fdbench-results.sqlite).", show_default=False)] = None
    rerun: Annotated[bool, typer.Option("--rerun", help="Run everything again instead of reusing stored runs.")] = False

    @property
    def db_path(self) -> Path:
        from ..store import default_path

        return self.db if self.db is not None else default_path()

    def executor(self):
        """The execution backend of --backend/--jobs/--scheduler, checked before any work."""
        from ..execution import make_backend

        return make_backend(self.backend, jobs=self.jobs, scheduler=self.scheduler)


@option_group("Cells")
class Cells:
    """The cells of the paper's tables a report or a study runs."""

    torque: Annotated[Optional[list[str]], typer.Option("--torque", help="Only these torques (repeat the option); default ann, cs, pf. NAME[KEY=VALUE,...] passes options, e.g. 'cs[knots=21]'.")] = None
    opt: Annotated[Optional[list[str]], typer.Option("--opt", help="Only these optimisers (repeat the option); default cmaes, bfgs. NAME[KEY=VALUE,...] passes options, e.g. 'cmaes[sigma0=0.1]'.")] = None
    feedforward: Annotated[Optional[bool], typer.Option("--feedforward/--no-feedforward", help="Only the cells with feedforward (Table 3) or without (Table 2); default both.", show_default=False)] = None
    control: Annotated[bool, typer.Option("--control/--no-control", help="Include PD control.")] = True
    all_cells: Annotated[bool, typer.Option("--all-cells", help="Also run the cells the paper left out (PF without feedforward).")] = False


@option_group("Optimisation")
class Optimisation:
    """What every optimisation is given: its budget, its gradients and eq. 18's penalty."""

    budget: Annotated[int, typer.Option("--budget", help="Objective evaluations (forward simulations) per optimisation, in [1, 1000000], gradient evaluations included.")] = 200
    gradient: Annotated[str, typer.Option("--gradient", metavar="fd|exact", help="Gradients for gradient-based optimisers (bfgs, lbfgsb): fd, finite differences (the paper's method), or exact, forward sensitivities of the RK4 simulation (rk4 only; one simulation with its sensitivities counts as one evaluation).")] = "fd"
    penalty_weight: Annotated[float, typer.Option("--penalty-weight", help="w_penal of eq. 18: objective = RMSE_rot_deg + w_penal (1 - t_end / T), T the motion's duration (eq. 5: 1 s).")] = 1.0


# ---- method options from the registries ---------------------------------------------------------

METHOD_PANEL = "Method options"


def methods_command(*sources: str):
    """The click command class of a command whose method options come from the registries:
    ``sources`` name them, 'torques', 'optimizers', 'controllers', or 'controllers:pd' for one
    method's. The options are made when the command is parsed or its help shown; the command
    receives their values by its ``MethodValues`` parameter, {source registry: {option: value}}."""

    class MethodsCommand(TyperCommand):
        def get_params(self, ctx):
            if not hasattr(self, "_method_options"):
                self._method_options = _method_options(sources, {p.name for p in self.params})
                self.params += [option for option, _ in self._method_options.values()]
            return super().get_params(ctx)

        def invoke(self, ctx):
            self.get_params(ctx)
            values = MethodValues()
            for name, (option, registry) in self._method_options.items():
                value = ctx.params.pop(name, None)
                if isinstance(option.metavar, str) and option.metavar.endswith("|auto"):
                    value = parse_count_or_auto(name, value)
                values.setdefault(registry, {})[name] = value
            for registry in (source.partition(":")[0] for source in sources):
                values.setdefault(registry, {})
            ctx.meta[METHOD_VALUES] = values
            return super().invoke(ctx)

    return MethodsCommand


def _method_options(sources, taken: set) -> dict:
    """{option: (click option, registry)} of the methods of ``sources``; an option named as one of
    the command's own (``taken``) or as one already made is left to the brackets."""
    import importlib

    from ..method_options import command_line_options

    made, parameters = {}, []
    for source in sources:
        module, _, only = source.partition(":")
        registry = getattr(importlib.import_module(f"fdbench.{module}"), module.upper())
        for name, (declared, methods) in command_line_options(registry, only.split(",") if only else None).items():
            if name in taken or name in made:
                continue
            option = typer.Option("--" + name.replace("_", "-"), help=f"{', '.join(methods)}: {declared.help}",
                                  show_default=declared.show_default, metavar=declared.metavar,
                                  rich_help_panel=METHOD_PANEL)
            kind = declared.type if declared.default is not None else Optional[declared.type]
            parameters.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=declared.default,
                                                annotation=Annotated[kind, option]))
            made[name] = module
    if not parameters:
        return {}

    def stub(**kwargs):  # typer makes the click options from a signature, as for any command
        """Method options."""

    stub.__signature__ = inspect.Signature(parameters)
    holder = typer.Typer(add_completion=False)
    holder.command()(stub)
    options = typer.main.get_command(holder).params
    return {option.name: (option, made[option.name]) for option in options if option.name in made}


def parse_count_or_auto(name: str, text):
    """The value of a count that may be 'auto' (``--hidden``): an integer >= 1 or 'auto'."""
    option = "--" + name.replace("_", "-")
    if text is None or text == "auto":
        return text
    try:
        value = int(text)
    except ValueError:
        raise BadInput(f"{option} must be an integer >= 1 or 'auto', got {text!r}") from None
    if value < 1:
        raise BadInput(f"{option} must be an integer >= 1 or 'auto', got {value}")
    return value
