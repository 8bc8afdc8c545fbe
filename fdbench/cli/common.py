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


from .app import BadInput, FORMATS, STARTED, write_stdout


def check_choice(option: str, value: str, valid) -> str:
    if value not in valid:
        from ..registry import unknown_name_message

        raise BadInput(f"{option}: " + unknown_name_message("value", value, list(valid)))
    return value


# output options with two names: errors name both
OUTPUT_LABELS = {"save_history": "--save-trajectory (--save-history)", "history": "--save-convergence (--history)"}


def check_outputs(fmt: str, valid=FORMATS, inputs: dict | None = None, db=None, **paths) -> None:
    """Validate --format and every output path before any work starts: each can be written, and
    none names an input file, the results database ``db`` or another output."""
    from ..files import BadFile, check_distinct, check_writable

    check_choice("--format", fmt, valid)
    outputs = {OUTPUT_LABELS.get(option, "--" + option.replace("_", "-")): path for option, path in paths.items()
               if not (option == "output" and str(path) == "-")}  # '-o -' is stdout
    try:
        for option, path in outputs.items():
            if path is not None:
                check_writable(path, option)
        check_distinct(outputs, inputs, db)
    except BadFile as exc:
        raise BadInput(str(exc)) from None


def validated(spec):
    try:
        return spec.validate()
    except ValueError as exc:
        raise BadInput(with_option(str(exc))) from None


def with_option(message: str) -> str:
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


def text_console():
    """A console that renders results into text (``capture``) and never writes standard output:
    as wide as the terminal, with its colours, when stdout is one; otherwise plain text of
    $COLUMNS (default 80) columns, as a script reading a pipe or a file expects."""
    import io
    import os

    from rich.console import Console

    if sys.stdout is not None and sys.stdout.isatty():
        return _console(stderr=False)
    columns = os.environ.get("COLUMNS", "")
    width = int(columns) if columns.isdigit() and int(columns) > 0 else 80
    return Console(file=io.StringIO(), width=width, color_system=None, highlight=False)


def say(quiet: bool, text: str) -> None:
    if not quiet:
        _console().print(text, soft_wrap=True)


def _jsonable(record: dict) -> dict:
    from ..files import finite_or_none

    return {k: finite_or_none(float(v)) if isinstance(v, float) else v for k, v in record.items()}


def render(record: dict, fmt: str, title: str) -> str:
    if fmt == "json":
        return json.dumps(_jsonable(record), indent=2) + "\n"
    if fmt == "csv":
        from ..files import csv_text

        return csv_text(list(record), [["" if v is None else v for v in record.values()]])
    from rich.table import Table

    table = Table(title=title, show_header=True)
    table.add_column("field")
    table.add_column("value", overflow="fold")
    for key, value in record.items():
        if value is None or value == "":
            continue
        table.add_row(key, _format_value(value))
    console = text_console()
    with console.capture() as capture:
        console.print(table)
    return capture.get()


def _format_value(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def emit(text: str, output: Optional[Path]) -> None:
    if output is None or str(output) == "-":
        write_stdout(text)
    else:
        from ..files import write_atomic

        write_atomic(output, text)


def finish(record: dict, fmt: str, output, title: str, quiet: bool) -> None:
    record["command_time_s"] = time.perf_counter() - STARTED
    emit(render(record, fmt, title), output)
    if output is not None and str(output) != "-":
        say(quiet, f"wrote {output}")
    if record.get("status") not in (None, "success"):
        say(quiet, f"[yellow]warning:[/] {record['message']}")


def history_csv(header, rows) -> str:
    """CSV text of a history table: a header and rows of numbers, each written with the digits that
    read back as the same float (a written motion read back as ``--motion`` is the same motion)."""
    from ..files import csv_text

    return csv_text(header, ([repr(float(v)) for v in row] for row in rows))


def _history_text(outcome) -> str:
    return history_csv(*outcome.trajectory())


def write_trajectory(outcome, path) -> None:
    if path is not None:
        from ..files import write_atomic

        write_atomic(path, _history_text(outcome), OUTPUT_LABELS["save_history"])


def check_store(db: Optional[Path]) -> None:
    """Refuse an unusable --db before any work starts: not a database, damaged, read-only,
    locked, planted by another user. A new name is only checked: the database is made when the
    run is stored, so a command that fails leaves none behind."""
    if db is not None:
        from ..store import StoreError, check_path, open_store

        try:
            if not os.path.lexists(db):
                check_path(db)
                return
            with open_store(db) as store:
                store.check_usable()
        except StoreError as exc:
            raise BadInput(f"--db: {exc}") from None


def store_run(outcome, spec, db: Optional[Path], quiet: bool) -> None:
    if db is None:
        return
    from ..store import StoreError, open_store

    try:
        with open_store(db) as store:
            store.add(spec, outcome)
    except StoreError as exc:
        raise BadInput(f"--db: {exc}") from None
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


def bracketed(ctx, text: str, option: str, flags: dict, registry, kind: str) -> tuple[str, dict]:
    """``NAME[KEY=VALUE,...]`` of --torque, --opt or --controller: (NAME, ``flags`` (the command's
    own option flags of that kind) with the bracket's options on top), so that a method, a plugin's
    included, receives any option its class takes. A key it does not take, or one also given as its
    own flag on the command line, is bad input."""
    name, given = _bracket_options(ctx, text, option, flags, registry, kind)
    return name, {**flags, **given}


def bracketed_all(ctx, entries, option: str, flags: dict, registry, kind: str) -> tuple[list | None, dict]:
    """``bracketed`` for a repeatable selection (report, study): the names (None: the default
    selection) and one set of options for them all, each method keeping those it takes; one key
    given two values in two brackets is bad input."""
    if not entries:
        return entries, flags
    names, merged, given_by = [], dict(flags), {}
    for entry in entries:
        name, given = _bracket_options(ctx, entry, option, flags, registry, kind)
        names.append(name)
        for key, value in given.items():
            if key in given_by and merged[key] != value:
                raise BadInput(f"{option}: {key} is {merged[key]} in {given_by[key]}[...] and {value} in "
                               f"{name}[...]; give one value")
            merged[key], given_by[key] = value, name
    return names, merged


def _bracket_options(ctx, text: str, option: str, flags: dict, registry, kind: str) -> tuple[str, dict]:
    """(NAME, the options of its brackets) of ``NAME[KEY=VALUE,...]``, checked (see ``bracketed``)."""
    from ..method_options import check_method_options
    from ..registry import parse_method

    try:
        name, given = parse_method(text, option)
        check_method_options(registry, name, given, kind)
    except ValueError as exc:
        message = str(exc)
        raise BadInput(message if message.startswith(option) else f"{option}: {message}") from None
    for key in given:
        source = ctx.get_parameter_source(key) if ctx is not None and key in flags else None
        if getattr(source, "name", None) in ("COMMANDLINE", "ENVIRONMENT"):
            raise BadInput(f"{option}: {key} is given both in {name}[...] and as --{key.replace('_', '-')}")
    return name, given


def check_method_ranges(registry, options: dict) -> None:
    """Reject an out-of-range method option even when the chosen method does not use it
    (``--terms 0`` with ``--torque cs``, ``--bandwidth -1`` with ``--controller pd``): every
    registered class that takes it checks it."""
    from ..method_options import taken_options

    for name, cls in registry.items():
        taken = taken_options(registry, name)
        given = {k: v for k, v in options.items() if k in taken and v is not None and v != "auto"}
        if given:
            try:
                cls(**given)
            except ValueError as exc:
                raise BadInput(str(exc)) from None


def applicable_options(ctx, options: dict, registry, name: str, choice: str) -> dict:
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


def check_finite(**values) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise BadInput(f"--{name.replace('_', '-')} must be a finite number, got {value}")


def methods_text() -> str:
    from ..optimizers import OPTIMIZERS
    from ..torques import TORQUES

    lines = ["torques (--torque):"]
    lines += [f"  {name:<12} {cls.summary}" for name, cls in TORQUES.items()]
    lines += ["optimizers (--opt):"]
    lines += [f"  {name:<12} {cls.summary}" for name, cls in OPTIMIZERS.items()]
    from ..controllers import CONTROLLERS

    lines += ["controllers (control --controller):"]
    lines += [f"  {name:<15} {cls.summary}" for name, cls in CONTROLLERS.items()]
    from ..models import names, summary

    lines += ["models (--model NAME, or a model file):"] + [f"  {name:<12} {summary(name)}" for name in names()]
    return "\n".join(lines) + "\n"


def check_names(torques, optimizers) -> None:
    from ..optimizers import OPTIMIZERS
    from ..registry import UnknownName
    from ..torques import TORQUES

    try:
        for name in torques or ():
            TORQUES[name]
        for name in optimizers or ():
            OPTIMIZERS[name]
    except UnknownName as exc:
        raise BadInput(with_option(str(exc))) from None


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
