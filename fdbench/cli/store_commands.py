"""``fdbench runs``: look at a results database without changing it: list its runs, show one,
export them all, compare two databases cell by cell."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated, Optional

import typer

from .app import FORMATS, BadInput, subcommands
from .common import check_outputs, emit, number_text, render, text_table, to_file, wrote
from .options import Output, format_option, option_group, with_groups

runs_app = subcommands("runs", "Look at stored runs without changing the database: list, show, export, compare.",
                       no_args_is_help=True)
SHOW_FORMATS = ("table", "json")
EXPORT_FORMATS = ("csv", "json", "parquet")

ReadDb = Annotated[Optional[Path], typer.Option("--db", help="Results database, opened read-only (default: $FDBENCH_DB or ./fdbench-results.sqlite).", show_default=False)]


@option_group(None)
class RunFilter:
    """The stored runs a command looks at: those of a command, model, method or status (None: any)."""

    command: Annotated[Optional[str], typer.Option("--command", metavar="NAME", help="Only runs of this command: control, optimize, collocate, ...", show_default=False)] = None
    model: Annotated[Optional[str], typer.Option("--model", metavar="NAME", help="Only runs of this model: forearm, arm2, leg3 or a model file's path, as stored", show_default=False)] = None
    torque: Annotated[Optional[str], typer.Option("--torque", metavar="NAME", help="Only optimisations of this torque parameterisation: ann, cs, pf, ...", show_default=False)] = None
    opt: Annotated[Optional[str], typer.Option("--opt", metavar="NAME", help="Only optimisations by this optimiser: cmaes, bfgs, ...", show_default=False)] = None
    controller: Annotated[Optional[str], typer.Option("--controller", metavar="NAME", help="Only control runs of this controller: pd, computed-torque, lqr, ...", show_default=False)] = None
    status: Annotated[Optional[str], typer.Option("--status", metavar="NAME", help="Only runs that ended with this status: success, singular, constraint, ...", show_default=False)] = None

    def select(self, runs: list[dict], present_in=None) -> list[dict]:
        """The ``runs`` that pass; a value no run of ``present_in`` (default: ``runs``) has is bad input."""
        from ..store_queries import select

        return select(runs, dataclasses.asdict(self), present_in)


def _database(db: Optional[Path], fmt: str, formats: tuple, output: Optional[Path]) -> tuple[Path, str]:
    """The database to read and how errors name it, once --format and --output are checked."""
    from ..store import default_path

    path, label = (db, "--db") if db is not None else (default_path(), "--db (default)")
    check_outputs(fmt, formats, db=path, output=output)
    if fmt == "parquet":
        _check_parquet(output)
    return path, label


def _read(path: Path, label: str, superseded: bool = False, damaged: dict | None = None) -> list[dict]:
    from ..store import StoreError
    from ..store_queries import read_runs

    try:
        return read_runs(path, superseded, damaged)
    except StoreError as exc:
        hint = "; name one with --db or $FDBENCH_DB" if label == "--db (default)" and not path.exists() else ""
        raise BadInput(f"{label}: {exc}{hint}") from None


# a person's table names its columns in a few words (json and csv keep the fields' names)
HEADINGS = {"created_at": "date (UTC)", "rmse_rot_deg": "rot (deg)", "rmse_torque_nm": "torque (N m)",
            "runtime_s": "runtime (s)", "t_end": "t_end (s)"}


def _write(fmt: str, output, rows, columns, what: str, table=None, document=None) -> None:
    """``rows`` as JSON (``document`` in their place if given), as CSV of ``columns``, as Parquet or
    as the person's table ``table()``; then the line saying what an output file holds."""
    if fmt == "parquet":
        from ..files import write_atomic

        write_atomic(output, _parquet_bytes(rows))
    elif fmt == "json":
        emit(json.dumps(rows if document is None else document, indent=2) + "\n", output)
    elif fmt == "csv":
        from ..files import csv_text

        emit(csv_text(list(columns), [[row.get(c) for c in columns] for row in rows]), output)
    else:
        emit(table(), output)
    wrote(output, False, what)


@runs_app.command("list")
@with_groups
def list_runs(
    db: ReadDb = None,
    only: RunFilter = None,
    fmt: Annotated[str, format_option(FORMATS, "Output: table (for a person), json or csv.")] = "table",
    output: Output = None,
):
    """One line per stored run: id, date, command, model, method, seed, the three indicators, t_end and status."""
    from ..store_queries import LIST_COLUMNS, list_row

    path, label = _database(db, fmt, FORMATS, output)
    rows = [list_row(run) for run in only.select(_read(path, label))]
    _write(fmt, output, rows, LIST_COLUMNS, f"{len(rows)} runs",
           lambda: text_table(f"{len(rows)} runs in {path}", rows, LIST_COLUMNS, HEADINGS))


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

    path, label = _database(db, fmt, SHOW_FORMATS, output)
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
    _write(fmt, output, shown, (), f"run {shown['id']}", lambda: _show_text(shown))


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
@with_groups
def export_runs(
    db: ReadDb = None,
    only: RunFilter = None,
    fmt: Annotated[str, format_option(EXPORT_FORMATS, "csv, json, or parquet (needs pyarrow or fastparquet, and -o).")] = "csv",
    output: Output = None,
):
    """Every field of the stored records, one row per run, with its provenance and settings: for pandas, R or a spreadsheet."""
    from ..store_queries import export_rows

    path, label = _database(db, fmt, EXPORT_FORMATS, output)
    rows = export_rows(only.select(_read(path, label)), nested=fmt == "json")
    _write(fmt, output, rows, list(dict.fromkeys(k for row in rows for k in row)), f"{len(rows)} runs")


def _check_parquet(output: Optional[Path]) -> None:
    import importlib.util

    if not to_file(output):
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
@with_groups
def compare_runs(
    database_a: Annotated[Path, typer.Argument(metavar="A", help="The first results database (the reference).", show_default=False)],
    database_b: Annotated[Path, typer.Argument(metavar="B", help="The second results database.", show_default=False)],
    only: RunFilter = None,
    fmt: Annotated[str, format_option(FORMATS, "Output: table (for a person), json or csv.")] = "table",
    output: Output = None,
):
    """The same cells of two databases side by side: per cell, the median RMSE_rot, RMSE_torque and runtime in A and in B and the ratio B/A.

    Cells are matched by their settings (the seed aside) or, failing that, by method and conditions; cells found in one database only are listed as such."""
    from ..files import check_distinct
    from ..store_queries import COMPARE_COLUMNS, compare

    check_outputs(fmt, FORMATS, db=database_a, output=output)
    check_distinct({"--output": output} if to_file(output) else {}, None, database_b)
    runs_a, runs_b = _read(database_a, "A"), _read(database_b, "B")
    rows = compare(only.select(runs_a, runs_a + runs_b), only.select(runs_b, runs_a + runs_b))
    _write(fmt, output, rows, COMPARE_COLUMNS, f"{len(rows)} cells",
           lambda: text_table(f"A = {database_a}, B = {database_b}", [_side_by_side(row) for row in rows],
                              ("method", "conditions", "found", "runs", *INDICATOR_HEADINGS.values())),
           {"a": str(database_a), "b": str(database_b), "cells": rows})


INDICATOR_HEADINGS = {"rmse_rot_deg": "RMSE rot (deg): A -> B", "rmse_torque_nm": "RMSE torque (N m): A -> B",
                      "runtime_s": "runtime (s): A -> B"}


def _side_by_side(row: dict) -> dict:
    """A compared cell for a person: runs 'A/B' and each indicator as 'a -> b (x ratio)'."""
    out = {"method": row["method"], "conditions": row["conditions"], "found": row["found"],
           "runs": f"{row['runs_a']}/{row['runs_b']}"}
    for name, heading in INDICATOR_HEADINGS.items():
        a, b, ratio = (number_text(row[f"{name}_{side}"]) or "-" for side in ("a", "b", "ratio"))
        out[heading] = f"{a} -> {b}" + (f" (x{ratio})" if ratio != "-" else "")
    return out
