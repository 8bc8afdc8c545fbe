"""``fdbench runs``: look at a results database without changing it: list its runs, show one,
export them all, compare two databases cell by cell."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Optional

import typer

from .app import BadInput, SubcommandGroup, app
from .common import check_outputs, emit, render, say
from .options import Output, format_option


runs_app = typer.Typer(
    cls=SubcommandGroup,
    help="Look at stored runs without changing the database: list, show, export, compare.",
    no_args_is_help=True,
)
app.add_typer(runs_app, name="runs")

LIST_FORMATS = ("table", "json", "csv")
SHOW_FORMATS = ("table", "json")
EXPORT_FORMATS = ("csv", "json", "parquet")

ReadDb = Annotated[Optional[Path], typer.Option("--db", help="Results database, opened read-only (default: $FDBENCH_DB or ./fdbench-results.sqlite).", show_default=False)]
Command = Annotated[Optional[str], typer.Option("--command", metavar="NAME", help="Only runs of this command: control, optimize, collocate, ...", show_default=False)]
Model = Annotated[Optional[str], typer.Option("--model", metavar="NAME", help="Only runs of this model: forearm, arm2, leg3 or a model file's path, as stored", show_default=False)]
Torque = Annotated[Optional[str], typer.Option("--torque", metavar="NAME", help="Only optimisations of this torque parameterisation: ann, cs, pf, ...", show_default=False)]
Opt = Annotated[Optional[str], typer.Option("--opt", metavar="NAME", help="Only optimisations by this optimiser: cmaes, bfgs, ...", show_default=False)]
Controller = Annotated[Optional[str], typer.Option("--controller", metavar="NAME", help="Only control runs of this controller: pd, computed-torque, lqr, ...", show_default=False)]
Status = Annotated[Optional[str], typer.Option("--status", metavar="NAME", help="Only runs that ended with this status: success, singular, constraint, ...", show_default=False)]


def _filters(command, model, torque, opt, controller, status) -> dict:
    return {"command": command, "model": model, "torque": torque, "opt": opt, "controller": controller,
            "status": status}


def _database(db: Optional[Path]) -> tuple[Path, str]:
    """The database to read and how errors name it."""
    from ..store import default_path

    return (db, "--db") if db is not None else (default_path(), "--db (default)")


def _read(path: Path, label: str, superseded: bool = False, damaged: dict | None = None) -> list[dict]:
    from ..store import StoreError
    from ..store_queries import read_runs

    try:
        return read_runs(path, superseded, damaged)
    except StoreError as exc:
        hint = "; name one with --db or $FDBENCH_DB" if label == "--db (default)" and not path.exists() else ""
        raise BadInput(f"{label}: {exc}{hint}") from None


def _select(runs: list[dict], filters: dict, present_in=None) -> list[dict]:
    from ..store_queries import BadQuery, select

    try:
        return select(runs, filters, present_in)
    except BadQuery as exc:
        raise BadInput(str(exc)) from None


def _number(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


# a person's table names its columns in a few words (json and csv keep the fields' names)
HEADINGS = {"created_at": "date (UTC)", "rmse_rot_deg": "rot (deg)", "rmse_torque_nm": "torque (N m)",
            "runtime_s": "runtime (s)", "t_end": "t_end (s)"}


def _cell(column: str, value) -> str:
    if column == "created_at" and value:
        return str(value)[:16].replace("T", " ")  # to the minute
    return _number(value)


def text_table(title: str, rows: list[dict], columns, headings=HEADINGS) -> str:
    """A person's table of ``rows`` as text, as wide as the terminal (off a terminal: $COLUMNS or
    80 columns): its words wrap within their columns (one longer than LONG_WORD is folded); a
    number is never cut, so a table that cannot fit is as wide as its numbers need."""
    from rich import box
    from rich.table import Table

    from .common import text_console

    titles = [headings.get(c, c) for c in columns]
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
    with console.capture() as capture:
        console.print(table)
    return capture.get()


LONG_WORD = 24  # characters: a longer word (a file path) may be folded to fit a table


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


def _wrote(output: Optional[Path], what: str) -> None:
    """One line on stderr once an output file is written, as every command says."""
    if output is not None and str(output) != "-":
        say(False, f"wrote {output} ({what})")


def _csv(rows: list[dict], columns) -> str:
    from ..files import csv_text

    return csv_text(list(columns), [["" if row.get(c) is None else row.get(c) for c in columns] for row in rows])


@runs_app.command("list")
def list_runs(
    db: ReadDb = None,
    command: Command = None,
    model: Model = None,
    torque: Torque = None,
    opt: Opt = None,
    controller: Controller = None,
    status: Status = None,
    fmt: Annotated[str, format_option(LIST_FORMATS, "Output: table (for a person), json or csv.")] = "table",
    output: Output = None,
):
    """One line per stored run: id, date, command, model, method, seed, the three indicators, t_end and status."""
    from ..store_queries import LIST_COLUMNS, list_row

    path, label = _database(db)
    check_outputs(fmt, LIST_FORMATS, db=path, output=output)
    runs = _select(_read(path, label), _filters(command, model, torque, opt, controller, status))
    rows = [list_row(run) for run in runs]
    if fmt == "json":
        text = json.dumps(rows, indent=2) + "\n"
    elif fmt == "csv":
        text = _csv(rows, LIST_COLUMNS)
    else:
        text = text_table(f"{len(rows)} runs in {path}", rows, LIST_COLUMNS)
    emit(text, output)
    _wrote(output, f"{len(rows)} runs")


@runs_app.command("show")
def show_run(
    run: Annotated[str, typer.Argument(metavar="ID", help="The run's id (from 'fdbench runs list') or its settings hash.", show_default=False)],
    db: ReadDb = None,
    fmt: Annotated[str, format_option(SHOW_FORMATS, "Output: table (for a person) or json (with the convergence history and the best parameters).")] = "table",
    output: Output = None,
):
    """Everything stored about one run: its record, its settings and where, when and by what it was made."""
    from ..store import StoreError
    from ..store_queries import BadQuery, find_run, read_run_data, show

    path, label = _database(db)
    check_outputs(fmt, SHOW_FORMATS, db=path, output=output)
    damaged = {}
    runs = _read(path, label, superseded=True, damaged=damaged)  # an id a report cites may have been replaced since
    if run.strip() in {str(key) for key in damaged}:
        raise BadInput(f"ID: stored run id {run.strip()} of {path} is damaged ({damaged[int(run.strip())]})")
    try:
        found = find_run(runs, run.strip())
        history, params = read_run_data(path, found["id"], found["superseded"])
    except BadQuery as exc:
        raise BadInput(f"ID: {exc}") from None
    except StoreError as exc:
        raise BadInput(f"{label}: {exc}") from None
    shown = show(found, history, params)
    emit(json.dumps(shown, indent=2) + "\n" if fmt == "json" else _show_text(shown), output)
    _wrote(output, f"run {shown['id']}")


def _show_text(shown: dict) -> str:
    provenance = dict(shown["provenance"])
    versions = provenance.pop("versions") or {}
    provenance["dependencies"] = ", ".join(f"{k} {v}" for k, v in versions.items() if v)
    provenance["spec_hash"] = shown["spec_hash"]
    history = shown["history"]
    if history:
        provenance["convergence"] = (f"{len(history)} evaluations stored, best objective {history[0]:.6g} "
                                     f"-> {history[-1]:.6g} deg")
    settings = {k: (json.dumps(v) if isinstance(v, (list, dict)) else v) for k, v in shown["settings"].items()}
    title = f"run {shown['id']}: {shown['method']}" + (" (replaced by a later --rerun)" if shown["superseded"] else "")
    return (render(shown["record"], "table", f"{title}, record") + render(settings, "table", "settings")
            + render(provenance, "table", "provenance"))


@runs_app.command("export")
def export_runs(
    db: ReadDb = None,
    command: Command = None,
    model: Model = None,
    torque: Torque = None,
    opt: Opt = None,
    controller: Controller = None,
    status: Status = None,
    fmt: Annotated[str, format_option(EXPORT_FORMATS, "csv, json, or parquet (needs pyarrow or fastparquet, and -o).")] = "csv",
    output: Output = None,
):
    """Every field of the stored records, one row per run, with its provenance and settings: for pandas, R or a spreadsheet."""
    path, label = _database(db)
    check_outputs(fmt, EXPORT_FORMATS, db=path, output=output)
    if fmt == "parquet":
        _check_parquet(output)
    runs = _select(_read(path, label), _filters(command, model, torque, opt, controller, status))
    from ..store_queries import export_rows

    rows = export_rows(runs, nested=fmt == "json")
    if fmt == "parquet":
        from ..files import write_atomic

        write_atomic(output, _parquet_bytes(rows))
    elif fmt == "json":
        emit(json.dumps(rows, indent=2) + "\n", output)
    else:
        emit(_csv(rows, list(dict.fromkeys(k for row in rows for k in row))), output)
    _wrote(output, f"{len(rows)} runs")


def _check_parquet(output: Optional[Path]) -> None:
    import importlib.util

    if output is None or str(output) == "-":
        raise BadInput("--format parquet: Parquet is binary; name a file with -o")
    if not any(importlib.util.find_spec(name) for name in ("pyarrow", "fastparquet")):
        raise BadInput("--format parquet needs pyarrow or fastparquet, which are not installed: pip install pyarrow "
                       "(or use --format csv or json)")


def _parquet_bytes(rows: list[dict]) -> bytes:
    """The rows as a Parquet file: whole numbers stay integers (missing values as nulls), and a
    column holding values of several types is stored as text."""
    import io

    import pandas as pd

    frame = pd.DataFrame(rows, dtype=object)
    for column in frame.columns:
        values = [None if v is None or v is pd.NA else v for v in frame[column]]
        kinds = {type(v) for v in values if v is not None}
        if kinds == {int}:
            frame[column] = pd.array(values, dtype="Int64")
        elif kinds & {list, dict} or (len(kinds) > 1 and not kinds <= {int, float}):
            frame[column] = [None if v is None else str(v) for v in values]
    buffer = io.BytesIO()
    frame.to_parquet(buffer, index=False)
    return buffer.getvalue()


@runs_app.command("compare")
def compare_runs(
    database_a: Annotated[Path, typer.Argument(metavar="A", help="The first results database (the reference).", show_default=False)],
    database_b: Annotated[Path, typer.Argument(metavar="B", help="The second results database.", show_default=False)],
    command: Command = None,
    model: Model = None,
    torque: Torque = None,
    opt: Opt = None,
    controller: Controller = None,
    status: Status = None,
    fmt: Annotated[str, format_option(LIST_FORMATS, "Output: table (for a person), json or csv.")] = "table",
    output: Output = None,
):
    """The same cells of two databases side by side: per cell, the median RMSE_rot, RMSE_torque and runtime in A and in B and the ratio B/A.

    Cells are matched by their settings (the seed aside) or, failing that, by method and conditions; cells found in one database only are listed as such."""
    from ..files import BadFile, check_distinct
    from ..store_queries import COMPARE_COLUMNS, compare

    check_outputs(fmt, LIST_FORMATS, db=database_a, output=output)
    try:
        check_distinct({"--output": output} if output is not None and str(output) != "-" else {}, None, database_b)
    except BadFile as exc:
        raise BadInput(str(exc)) from None
    runs_a, runs_b = _read(database_a, "A"), _read(database_b, "B")
    filters = _filters(command, model, torque, opt, controller, status)
    rows = compare(_select(runs_a, filters, runs_a + runs_b), _select(runs_b, filters, runs_a + runs_b))
    if fmt == "json":
        emit(json.dumps({"a": str(database_a), "b": str(database_b), "cells": rows}, indent=2) + "\n", output)
    elif fmt == "csv":
        emit(_csv(rows, COMPARE_COLUMNS), output)
    else:
        emit(text_table(f"A = {database_a}, B = {database_b}", [_side_by_side(row) for row in rows],
                     ("method", "conditions", "found", "runs", *INDICATOR_HEADINGS.values())), output)
    _wrote(output, f"{len(rows)} cells")


INDICATOR_HEADINGS = {"rmse_rot_deg": "RMSE rot (deg): A -> B", "rmse_torque_nm": "RMSE torque (N m): A -> B",
                      "runtime_s": "runtime (s): A -> B"}


def _side_by_side(row: dict) -> dict:
    """A compared cell for a person: runs 'A/B' and each indicator as 'a -> b (x ratio)'."""
    out = {"method": row["method"], "conditions": row["conditions"], "found": row["found"],
           "runs": f"{row['runs_a']}/{row['runs_b']}"}
    for name, heading in INDICATOR_HEADINGS.items():
        a, b, ratio = (_number(row[f"{name}_{side}"]) or "-" for side in ("a", "b", "ratio"))
        out[heading] = f"{a} -> {b}" + (f" (x{ratio})" if ratio != "-" else "")
    return out
