"""Helpers of every command: input and output checks, rendering, writing, the results store,
method-option checks and the progress bar."""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Optional

from .app import FORMATS, STARTED, BadInput, bad_input, write_stdout


def check_choice(option: str, value: str, valid) -> str:
    if value not in valid:
        from ..registry import unknown_name_message

        raise BadInput(f"{option}: " + unknown_name_message("value", value, list(valid)))
    return value


def check_count(option: str, value: int | None, most: int) -> None:
    """A count given to ``option`` (None: its default) in [1, ``most``]."""
    if value is not None and not 1 <= value <= most:
        raise BadInput(f"{option} must be an integer in [1, {most}], got {value}")


def check_finite(**values) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise BadInput(f"--{name.replace('_', '-')} must be a finite number, got {value}")


def given(ctx, name: str) -> bool:
    """Whether the option ``name`` was given (on the command line or by an environment variable)."""
    return getattr(ctx.get_parameter_source(name), "name", None) in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


# output options with two names: errors name both
OUTPUT_LABELS = {"save_history": "--save-trajectory (--save-history)", "history": "--save-convergence (--history)"}


def check_outputs(fmt: str, valid=FORMATS, inputs: dict | None = None, db=None, **paths) -> None:
    """Validate --format and every output path before any work starts: each can be written, and
    none names an input file, the results database ``db`` or another output."""
    from ..files import check_distinct, check_writable

    check_choice("--format", fmt, valid)
    outputs = {OUTPUT_LABELS.get(option, "--" + option.replace("_", "-")): path for option, path in paths.items()
               if option != "output" or str(path) != "-"}  # '-o -' is stdout
    for option, path in outputs.items():
        if path is not None:
            check_writable(path, option)
    check_distinct(outputs, inputs, db)


def with_option(message) -> str:
    """Messages from the library name parameters plainly (dt, kp); name them as options."""
    message = str(message)
    for name in ("dt", "rtol", "atol", "alpha", "xi", "omega", "kp", "kd"):
        if message.startswith(name + " "):
            return f"--{name}: " + message[len(name) + 1 :]
    for name in ("kinematics", "integrator", "torque", "optimizer"):
        if message.startswith(f"unknown {name} "):
            option = "--opt" if name == "optimizer" else f"--{name}"
            return f"{option}: {message}"
    return message


def validated(spec):
    with bad_input(wording=with_option):
        return spec.validate()


def _console(stderr: bool = True):
    from rich.console import Console

    return Console(stderr=stderr, highlight=False)


def text_console():
    """A console that renders results into text (``capture``) and never writes standard output:
    as wide as the terminal, with its colours, when stdout is one; otherwise plain text of
    $COLUMNS (default 80) columns, as a script reading a pipe or a file expects."""
    import io

    from rich.console import Console

    if sys.stdout is not None and sys.stdout.isatty():
        return _console(stderr=False)
    columns = os.environ.get("COLUMNS", "")
    width = int(columns) if columns.isdigit() and int(columns) > 0 else 80
    return Console(file=io.StringIO(), width=width, color_system=None, highlight=False)


def _printed(table, console=None) -> str:
    console = console or text_console()
    with console.capture() as capture:
        console.print(table)
    return capture.get()


def say(quiet: bool, text: str) -> None:
    if not quiet:
        _console().print(text, soft_wrap=True)


def render(record: dict, fmt: str, title: str) -> str:
    """A record {field: value} as JSON, CSV (a header and one row) or a person's table."""
    from ..files import csv_text, finite_or_none

    if fmt == "json":
        return json.dumps({k: finite_or_none(float(v)) if isinstance(v, float) else v for k, v in record.items()},
                          indent=2) + "\n"
    if fmt == "csv":
        return csv_text(list(record), [list(record.values())])
    from rich.table import Table

    table = Table(title=title, show_header=True)
    table.add_column("field")
    table.add_column("value", overflow="fold")
    for key, value in record.items():
        if value is not None and value != "":
            table.add_row(key, f"{value:.6g}" if isinstance(value, float) else str(value))
    return _printed(table)


def _cell(column: str, value) -> str:
    if column == "created_at" and value:
        return str(value)[:16].replace("T", " ")  # to the minute
    return number_text(value)


def number_text(value) -> str:
    """A table's cell: 4 significant digits of a float, nothing for None."""
    if value is None:
        return ""
    return f"{value:.4g}" if isinstance(value, float) else str(value)


LONG_WORD = 24  # characters: a longer word (a file path) may be folded to fit a table


def text_table(title: str, rows: list[dict], columns, headings: dict | None = None) -> str:
    """A person's table of ``rows`` as text, as wide as the terminal (off a terminal: $COLUMNS or
    80 columns), ``headings`` naming columns: its words wrap within their columns (one longer
    than LONG_WORD is folded); a number is never cut, so a table that cannot fit is as wide as its
    numbers need."""
    from rich import box
    from rich.table import Table

    titles = [(headings or {}).get(c, c) for c in columns]
    cells = [[_cell(c, row.get(c)) for c in columns] for row in rows]
    texts = [[title] + [row[i] for row in cells] for i, title in enumerate(titles)]
    widest = [max(len(text) for text in column) for column in texts]
    numbers = [all(_is_number(text) for text in column[1:]) for column in texts]
    narrowest = [max(len(word) for j, text in enumerate(column) for word in
                     ([text] if numbers[i] and j else text.split() or [""])) for i, column in enumerate(texts)]
    narrowest = [n if numbers[i] else min(n, LONG_WORD) for i, n in enumerate(narrowest)]
    table = Table(title=title, show_header=True, box=box.SIMPLE_HEAD, pad_edge=False)
    for heading in titles:
        table.add_column(heading, overflow="fold")  # a word longer than LONG_WORD (a path) is folded
    for row in cells:
        table.add_row(*row)
    console = text_console()
    target, console.width = console.width, 10_000  # measured without a bound
    room = target - (console.measure(table).maximum - sum(widest))  # less padding and rules
    for column, width in zip(table.columns, _fit(widest, narrowest, room)):
        column.width = width
    console.width = max(target, console.measure(table).maximum)
    return _printed(table, console)


def _fit(widest: list, narrowest: list, room: int) -> list:
    """Column widths (characters) from ``widest`` down to no less than ``narrowest``, the widest
    column narrowed first, until they sum to ``room`` or can be narrowed no more."""
    widths = list(widest)
    while sum(widths) > room:
        shrinkable = [k for k in range(len(widths)) if widths[k] > narrowest[k]]
        if not shrinkable:
            break
        widths[max(shrinkable, key=lambda k: widths[k])] -= 1
    return widths


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return text == ""
    return True


def to_file(output: Optional[Path]) -> bool:
    """Whether --output names a file (not None, nor '-': standard output)."""
    return output is not None and str(output) != "-"


def emit(text: str, output: Optional[Path]) -> None:
    if to_file(output):
        from ..files import write_atomic

        write_atomic(output, text)
    else:
        write_stdout(text)


def wrote(output: Optional[Path], quiet: bool, what: str = "") -> None:
    """One line on stderr once an output file is written (``what`` it holds), as every command says."""
    if to_file(output):
        say(quiet, f"wrote {output}" + (f" ({what})" if what else ""))


def finish(record: dict, fmt: str, output, title: str, quiet: bool) -> None:
    record["command_time_s"] = time.perf_counter() - STARTED
    emit(render(record, fmt, title), output)
    wrote(output, quiet)
    if record.get("status") not in (None, "success"):
        say(quiet, f"[yellow]warning:[/] {record['message']}")


def history_csv(header, rows) -> str:
    """CSV text of a history table: a header and rows of numbers, each written with the digits that
    read back as the same float (a written motion read back as ``--motion`` is the same motion)."""
    from ..files import csv_text

    return csv_text(header, ([repr(float(v)) for v in row] for row in rows))


def write_trajectory(outcome, path) -> None:
    if path is not None:
        from ..files import write_atomic

        write_atomic(path, history_csv(*outcome.trajectory()), OUTPUT_LABELS["save_history"])


def check_store(db: Optional[Path]) -> None:
    """Refuse an unusable --db before any work starts: not a database, damaged, read-only,
    locked, planted by another user (a StoreError, bad input). A new name is only checked: the
    database is made when the run is stored, so a command that fails leaves none behind."""
    if db is not None:
        from ..store import check_path, open_store

        if not os.path.lexists(db):
            check_path(db)
            return
        with open_store(db) as store:
            store.check_usable()


def store_run(outcome, spec, db: Optional[Path], quiet: bool) -> None:
    if db is not None:
        from ..store import open_store

        with open_store(db) as store:
            store.add(spec, outcome)
        say(quiet, f"stored in {db}")


def check_gradient(gradient: str, optimizers=None) -> None:
    """A valid --gradient; for the commands that select optimisers (``optimizers``: the names
    given, None for the default set), exact gradients need one that uses them."""
    from ..validation import GRADIENTS

    if gradient not in GRADIENTS:
        raise BadInput(f"--gradient must be one of {', '.join(GRADIENTS)}, got {gradient!r}")
    if gradient == "exact" and optimizers:
        from ..optimizers import OPTIMIZERS

        users = [n for n, c in OPTIMIZERS.items() if getattr(c, "uses_gradient", False)]
        if not any(name in users for name in optimizers):
            raise BadInput(f"--gradient exact applies to gradient-based optimisers ({', '.join(users)}); "
                           f"none is selected by --opt {' --opt '.join(optimizers)}")


def bracketed(ctx, entries, option: str, flags: dict, registry, kind: str) -> tuple[list | None, dict]:
    """The ``NAME[KEY=VALUE,...]`` entries of --torque, --opt or --controller: their names (None:
    the default selection) and one set of options for them all, ``flags`` (the command's own
    option flags of that kind) with the brackets' options on top, so that a method, a plugin's
    included, receives any option its class takes (each keeps those it takes). A key it does not
    take, one also given as its own flag on the command line, or one given two values in two
    brackets is bad input."""
    from ..method_options import check_method_options
    from ..registry import parse_method

    if not entries:
        return entries, flags
    names, merged, given_by = [], dict(flags), {}
    for entry in entries:
        with bad_input(wording=lambda exc: str(exc) if str(exc).startswith(option) else f"{option}: {exc}"):
            name, options = parse_method(entry, option)
            check_method_options(registry, name, options, kind)
        names.append(name)
        for key, value in options.items():
            if key in flags and given(ctx, key):
                raise BadInput(f"{option}: {key} is given both in {name}[...] and as --{key.replace('_', '-')}")
            if key in given_by and merged[key] != value:
                raise BadInput(f"{option}: {key} is {merged[key]} in {given_by[key]}[...] and {value} in "
                               f"{name}[...]; give one value")
            merged[key], given_by[key] = value, name
    return names, merged


def check_method_ranges(registry, options: dict) -> None:
    """Reject an out-of-range method option even when the chosen method does not use it
    (``--terms 0`` with ``--torque cs``, ``--bandwidth -1`` with ``--controller pd``): every
    registered class that takes it checks it."""
    from ..method_options import taken_options

    for name, cls in registry.items():
        taken = taken_options(registry, name)
        chosen = {k: v for k, v in options.items() if k in taken and v is not None and v != "auto"}
        if chosen:
            with bad_input():
                cls(**chosen)


def applicable_options(ctx, options: dict, registry, name: str, choice: str) -> dict:
    """Of a command's method options (parameter name: value), those the method ``name`` takes.
    One the user gave (on the command line or from the environment, not a default) that it does
    not take is bad input: ``--kp`` does not apply to ``--controller lqr``."""
    from ..method_options import taken_options

    taken = taken_options(registry, name)
    for key in options:
        if key not in taken and given(ctx, key):
            allowed = ", ".join("--" + k.replace("_", "-") for k in taken if k in options) or "no options"
            raise BadInput(f"--{key.replace('_', '-')} does not apply to {choice} {name} (it takes {allowed})")
    return {k: v for k, v in options.items() if k in taken}


def methods_text() -> str:
    from ..optimizers import OPTIMIZERS
    from ..torques import TORQUES

    lines = ["torques (--torque):"] + [f"  {name:<12} {cls.summary}" for name, cls in TORQUES.items()]
    lines += ["optimizers (--opt):"] + [f"  {name:<12} {cls.summary}" for name, cls in OPTIMIZERS.items()]
    from ..controllers import CONTROLLERS
    from ..models import names, summary

    lines += ["controllers (control --controller):"] + [f"  {name:<15} {cls.summary}" for name, cls in CONTROLLERS.items()]
    lines += ["models (--model NAME, or a model file):"] + [f"  {name:<12} {summary(name)}" for name in names()]
    return "\n".join(lines) + "\n"


def shooting_methods(ctx, torques, optimizers, flags: dict, penalty_weight: float) -> tuple:
    """The torques and optimisers selected (``NAME[KEY=VALUE,...]`` entries; None: the default
    set) and their options, {registry: {option: value}} in ``flags``, checked before any work:
    (torque names, optimiser names, torque options, optimiser options)."""
    from ..optimizers import OPTIMIZERS
    from ..registry import UnknownName
    from ..torques import TORQUES

    check_finite(**{k: v for k, v in flags["optimizers"].items() if isinstance(v, float)},
                 penalty_weight=penalty_weight)
    torques, torque_options = bracketed(ctx, torques, "--torque", flags["torques"], TORQUES, "torque")
    optimizers, optimizer_options = bracketed(ctx, optimizers, "--opt", flags["optimizers"], OPTIMIZERS, "optimizer")
    with bad_input(UnknownName, with_option):
        for name in torques or ():
            TORQUES[name]
        for name in optimizers or ():
            OPTIMIZERS[name]
    check_method_ranges(TORQUES, torque_options)
    check_method_ranges(OPTIMIZERS, optimizer_options)
    return torques, optimizers, torque_options, optimizer_options


class Progress:
    """A rich progress bar on stderr: evaluations done and the best objective so far."""

    def __init__(self, quiet: bool, label: str):
        self.quiet, self.label = quiet, label
        self.bar = self.task = None

    def __enter__(self):
        return self

    def start(self, total: int, show_best: bool = True) -> None:
        if self.quiet or not sys.stderr.isatty():  # a bar only for a person watching
            return
        from ..jit import no_spinner

        no_spinner()  # the bar owns the last line now: a compilation is said in one line above it
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
