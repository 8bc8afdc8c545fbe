"""Reading a results database without changing it (``fdbench runs``): its stored runs as rows to
list, show, export and compare. The database is opened read-only (``mode=ro``); one that is not
the user's own is read as ``immutable`` (SQLite writes nothing at all; changes still in another
user's ``-wal`` are not seen, with a warning). A damaged run is skipped with a warning.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sqlite3
import sys
from pathlib import Path
from urllib.parse import quote

from .store import (OPEN_PATIENCE_S, SCHEMA_NAME, SCHEMA_VERSION, SUPERSEDED, DamagedRow, StoreError, check_header,
                    companions, foreign, parse_stored, resolve)

# the columns of ``fdbench runs list``, in order
LIST_COLUMNS = ("id", "created_at", "command", "model", "method", "seed", "rmse_rot_deg", "rmse_torque_nm",
                "runtime_s", "t_end", "status")

# what ``fdbench runs`` can filter on: option -> what it is called in messages
FILTERS = {"command": "command", "model": "model", "torque": "torque", "opt": "optimizer",
           "controller": "controller", "status": "status"}

INDICATORS = ("rmse_rot_deg", "rmse_torque_nm", "runtime_s")

# the columns of ``fdbench runs compare`` (CSV): per indicator its median in A and in B and B / A
COMPARE_COLUMNS = ("method", "conditions", "found", "runs_a", "runs_b") + tuple(
    f"{name}_{side}" for name in INDICATORS for side in ("a", "b", "ratio")) + ("cell_a", "cell_b")

_COLUMNS = ("id", "spec_hash", "command", "seed", "spec_json", "record_json", "created_at", "machine", "git_commit",
            "fdbench_version", "jobs", "versions_json", "status")


class BadQuery(ValueError):
    """A filter or run id that matches nothing stored; the message says what is there."""


# ---- opening --------------------------------------------------------------------------------


def open_read_only(path, say_unseen: bool = True) -> sqlite3.Connection:
    """A read-only connection to the fdbench results database at ``path``; StoreError with one
    line for a missing file, a directory, a device, or a file that is not an fdbench database.
    ``say_unseen``: warn if changes in another user's ``-wal`` are not seen (see ``_own``)."""
    path = Path(path)
    if str(path) in ("", ":memory:"):
        raise StoreError(f"{str(path) or 'an empty name'} is not a results database file")
    if os.path.islink(path) and not path.exists():
        raise StoreError(f"no results database at {path} (a symbolic link to {os.readlink(path)}, which does not exist)")
    if not path.exists():
        raise StoreError(f"no results database at {path}")
    if path.is_dir():
        raise StoreError(f"{path} is a directory, not a results database")
    if not path.is_file():
        raise StoreError(f"{path} is not a regular file (a device or a pipe holds no results)")
    if path.stat().st_size == 0:
        raise StoreError(f"{path} is empty: no runs are stored there")
    check_header(path)
    target = resolve(path)
    uri = f"file:{quote(str(target.resolve()))}?mode=ro" + ("" if _own(target, say_unseen) else "&immutable=1")
    try:
        db = sqlite3.connect(uri, uri=True, timeout=OPEN_PATIENCE_S, isolation_level=None)
    except sqlite3.Error as exc:
        raise StoreError(f"{path} cannot be opened ({exc})") from None
    try:
        db.execute("PRAGMA query_only = 1")
        _check_fdbench(db, path)
    except sqlite3.OperationalError as exc:
        db.close()
        if "locked" in str(exc) or "busy" in str(exc):
            raise StoreError(f"{path} is locked by another program; try again when it is done") from None
        raise StoreError(f"{path} cannot be read ({exc})") from None
    except sqlite3.DatabaseError as exc:
        db.close()
        raise StoreError(f"{path} is not an fdbench results database ({exc})") from None
    except BaseException:
        db.close()
        raise
    return db


def _own(target: Path, say_unseen: bool = True) -> bool:
    """Whether ``target`` and its companions are the user's own, in a folder the user can write (else
    it is read as immutable, with a warning if its ``-wal`` holds changes then not seen)."""
    files = companions(target)
    if all(foreign(file, st) is None for file, st in [(target, os.stat(target))] + files) and \
            os.access(target.parent, os.W_OK):
        return True
    wal = [file for file, st in files if str(file).endswith("-wal") and st.st_size > 0]
    if wal and say_unseen:
        warn(f"{target} is not your own database: it is read without writing anything, and the changes its "
             f"writer has not yet moved from {wal[0].name} into it are not shown")
    return False


def warn(message: str) -> None:
    """One line on stderr: something read was not used, and why."""
    sys.stderr.write(f"fdbench: warning: {' '.join(message.split())}\n")
    sys.stderr.flush()


def _check_fdbench(db: sqlite3.Connection, path: Path) -> None:
    tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if "fdbench_meta" not in tables or "runs" not in tables:
        found = f"tables: {', '.join(sorted(tables))}" if tables else "no tables"
        raise StoreError(f"{path} is not an fdbench results database ({found})")
    meta = dict(db.execute("SELECT key, value FROM fdbench_meta"))
    if meta.get("schema") != SCHEMA_NAME:
        raise StoreError(f"{path} is not an fdbench results database")
    if meta.get("version") != SCHEMA_VERSION:
        raise StoreError(f"{path} has results schema version {meta.get('version')}; this fdbench reads "
                         f"version {SCHEMA_VERSION}")


# ---- reading --------------------------------------------------------------------------------


def read_runs(path, superseded: bool = False, damaged: dict | None = None) -> list[dict]:
    """Every stored run at ``path``, oldest first (with ``superseded``, the replaced ones after,
    ``run["superseded"]`` True); a damaged one is skipped, into ``damaged`` ({id: why}) or a warning."""
    db = open_read_only(path)
    try:
        tables = ["runs"]
        if superseded and db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?",
                                     (SUPERSEDED,)).fetchone():
            tables.append(SUPERSEDED)
        rows = [(table, row) for table in tables
                for row in db.execute(f"SELECT {', '.join(_COLUMNS)} FROM {table} ORDER BY id").fetchall()]
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"cannot read the results database {path}: {exc}") from None
    finally:
        db.close()
    runs = []
    for table, row in rows:
        try:
            runs.append(dict(_run(dict(zip(_COLUMNS, row))), superseded=table != "runs"))
        except DamagedRow as exc:
            if damaged is not None:
                damaged[row[0]] = str(exc)
            else:
                where = "" if table == "runs" else f" (in {table})"
                warn(f"{path}: stored run id {row[0]}{where} is damaged ({exc}); skipped")
    return runs


def _run(row: dict) -> dict:
    """A stored run from its row; DamagedRow if a JSON column cannot be read."""
    spec = parse_stored(row.pop("spec_json"), "spec_json")
    record = parse_stored(row.pop("record_json"), "record_json")
    versions = parse_stored(row.pop("versions_json") or None, "versions_json", (dict, type(None)))
    run = dict(row, spec=spec, record=record, versions=versions)
    run["status"] = row["status"] if row["status"] is not None else record.get("status")
    run["model"] = spec.get("model_name") or "forearm"
    run["method"] = method_label(spec)
    return run


def read_run_data(path, run_id: int, superseded: bool = False) -> tuple[list, list | None]:
    """The convergence history (best objective per evaluation, deg) and the best parameters of
    stored run ``run_id`` (None for a run without parameters), from the superseded runs if asked."""
    db = open_read_only(path, say_unseen=False)  # said when its runs were read
    try:
        table = SUPERSEDED if superseded else "runs"
        row = db.execute(f"SELECT history_json, params_json FROM {table} WHERE id = ?", (run_id,)).fetchone()
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"cannot read the results database {path}: {exc}") from None
    finally:
        db.close()
    try:
        return parse_stored(row[0], "history_json", (list,)), parse_stored(row[1] or None, "params_json",
                                                                           (list, type(None)))
    except DamagedRow as exc:
        raise StoreError(f"{path}: stored run id {run_id} is damaged ({exc})") from None


def method_label(spec: dict) -> str:
    """A run's method in a few words: 'cs + bfgs + ff' (torque + optimiser, with feedforward),
    the controller ('pd', 'lqr'; 'open loop' for PD with Kp = Kd = 0), 'collocation', the peer ('opensim', 'moco'), or the command."""
    command = spec.get("command")
    if command == "optimize":
        return f"{spec.get('torque')} + {spec.get('optimizer')}" + (" + ff" if spec.get("feedforward") else "")
    if command == "control":
        controller = spec.get("controller") or "pd"
        if controller == "pd" and spec.get("kp") == 0 and spec.get("kd") == 0:
            return "open loop"  # the walk's: the feedforward alone, as PD with no gains
        return controller
    if command == "collocate":
        return "collocation"
    if command == "peer":  # its name among its options: 'opensim', 'moco'
        return str(dict(spec.get("method_options") or ()).get("peer", command))
    return str(command)


def filter_value(run: dict, option: str):
    """The value of ``run`` that the filter ``--option`` compares (None where it does not apply)."""
    spec = run["spec"]
    if option == "torque":
        return spec.get("torque") if run["command"] == "optimize" else None
    if option == "opt":
        return spec.get("optimizer") if run["command"] == "optimize" else None
    if option == "controller":
        return (spec.get("controller") or "pd") if run["command"] == "control" else None
    return run[option]


def select(runs: list[dict], filters: dict, present_in: list[dict] | None = None) -> list[dict]:
    """The runs matching every filter ({option: value or None}); BadQuery for a value that no
    run of ``present_in`` (default: ``runs``) has, naming the values present."""
    pool = runs if present_in is None else present_in
    for option, wanted in filters.items():
        if wanted is None:
            continue
        present = sorted({str(v) for v in (filter_value(r, option) for r in pool) if v is not None})
        if wanted not in present:
            raise BadQuery(f"--{option}: no stored run has {FILTERS[option]} {wanted!r}; "
                           f"present: {', '.join(present) or 'none'}")
        runs = [r for r in runs if str(filter_value(r, option)) == wanted]
    return runs


def find_run(runs: list[dict], key: str) -> dict:
    """The run with id ``key`` (an integer) or settings hash ``key``; BadQuery if none."""
    for run in runs:
        if key == str(run["id"]) or key == run["spec_hash"]:
            return run
    ids = [r["id"] for r in runs]
    held = f"ids {min(ids)} to {max(ids)}" if ids else "no runs"
    raise BadQuery(f"no stored run has id or settings hash {key!r} (the database holds {held})")


# ---- rows -----------------------------------------------------------------------------------


def list_row(run: dict) -> dict:
    """One row of ``fdbench runs list``: the columns of LIST_COLUMNS."""
    record = run["record"]
    out = {"id": run["id"], "created_at": run["created_at"], "command": run["command"], "model": run["model"],
           "method": run["method"], "seed": run["seed"]}
    out.update({name: _finite(record.get(name)) for name in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s", "t_end")})
    out["status"] = run["status"]
    return out


def show(run: dict, history: list, params) -> dict:
    """Everything stored about one run: its record, settings and provenance, its convergence
    history and best parameters."""
    return {
        "id": run["id"], "spec_hash": run["spec_hash"], "method": run["method"],
        "superseded": run.get("superseded", False),
        "record": {k: _finite(v) for k, v in run["record"].items()},
        "settings": run["spec"],
        "provenance": {"created_at": run["created_at"], "machine": run["machine"], "git_commit": run["git_commit"],
                       "fdbench_version": run["fdbench_version"], "jobs": run["jobs"], "versions": run["versions"]},
        "evaluations_stored": len(history), "history": [_finite(v) for v in history],
        "params": None if params is None else [_finite(v) for v in params],
    }


def export_rows(runs: list[dict], nested: bool = False) -> list[dict]:
    """One row per run: id, time, method, the union of the records' fields, provenance and settings
    (lists and objects as JSON text unless ``nested``)."""
    fields = list(dict.fromkeys(k for run in runs for k in run["record"]))
    rows = []
    for run in runs:
        row = {"id": run["id"], "created_at": run["created_at"], "method": run["method"]}
        row.update({k: _finite(run["record"].get(k)) for k in fields if k not in row})
        row.update(spec_hash=run["spec_hash"], machine=run["machine"],
                   git_commit=run["git_commit"], versions=run["versions"], settings=run["spec"])
        if not nested:  # a flat table: lists and objects as JSON text
            row = {k: json.dumps(v, sort_keys=True) if isinstance(v, (list, dict)) else v for k, v in row.items()}
        rows.append(row)
    return rows


# ---- comparing two databases ----------------------------------------------------------------


def cell_key(spec: dict) -> str:
    """The digest of a run's canonical settings without its seed (16 hex digits): the runs of one
    cell, one per seed, share it, in any database."""
    from .spec import RunSpec  # lazy: the spec brings the engine (numba); reading a store does not need it

    try:
        canonical = RunSpec(**spec).canonical()
    except (TypeError, ValueError):  # settings of another fdbench version: taken as stored
        canonical = dict(spec)
    canonical.pop("seed", None)
    return hashlib.sha256(json.dumps(canonical, sort_keys=True, default=str).encode()).hexdigest()[:16]


def conditions_text(run: dict) -> str:
    """The conditions of a run in a few words: model, motion, budget, and whatever else differs
    from the defaults (noise, plant, model constants, integrator, step)."""
    spec, record = run["spec"], run["record"]
    parts = [run["model"], str(record.get("motion") or spec.get("kinematics"))]
    if spec.get("budget"):
        parts.append(f"budget {spec['budget']}")
    if spec.get("noise_deg"):
        parts.append(f"noise {spec['noise_deg']:g} deg")
    if record.get("plant"):
        parts.append(f"plant {record['plant']}")
    if record.get("model_options"):
        parts.append(f"model {record['model_options']}")
    if spec.get("integrator", "rk4") != "rk4":
        parts.append(spec["integrator"])
    elif spec.get("dt", 1e-3) != 1e-3:
        parts.append(f"dt {spec['dt']:g} s")
    return ", ".join(parts)


def _cells(runs: list[dict]) -> dict:
    """{cell key: runs of the cell}, in the order of their first run."""
    cells: dict = {}
    for run in runs:
        cells.setdefault(cell_key(run["spec"]), []).append(run)
    return cells


def compare(runs_a: list[dict], runs_b: list[dict]) -> list[dict]:
    """The cells of two databases side by side, matched by settings (seed aside) or else by method
    and conditions one to one: per cell each indicator's median in A and B and B / A."""
    cells_a, cells_b = _cells(runs_a), _cells(runs_b)
    pairs = [(key, key, "settings") for key in cells_a if key in cells_b]
    alone_a = [k for k in cells_a if k not in cells_b]
    alone_b = [k for k in cells_b if k not in cells_a]
    by_label_a = _by_label(cells_a, alone_a)
    by_label_b = _by_label(cells_b, alone_b)
    for label, keys in by_label_a.items():
        if len(keys) == 1 and len(by_label_b.get(label, ())) == 1:
            pairs.append((keys[0], by_label_b[label][0], "method and conditions"))
            alone_a.remove(keys[0])
            alone_b.remove(by_label_b[label][0])
    rows = [_compare_row(cells_a[a], cells_b[b], found) for a, b, found in pairs]
    rows += [_compare_row(cells_a[a], [], "only in A") for a in alone_a]
    rows += [_compare_row([], cells_b[b], "only in B") for b in alone_b]
    return rows


def _by_label(cells: dict, keys: list) -> dict:
    out: dict = {}
    for key in keys:
        first = cells[key][0]
        out.setdefault((first["command"], first["method"], conditions_text(first)), []).append(key)
    return out


def _compare_row(a: list[dict], b: list[dict], found: str) -> dict:
    from .report.paper_methods import summarise  # lazy: as RunSpec above

    first = (a or b)[0]
    row = {"method": first["method"], "conditions": conditions_text(first), "found": found,
           "runs_a": len(a), "runs_b": len(b)}
    summary_a = summarise([r["record"] for r in a]) if a else {}
    summary_b = summarise([r["record"] for r in b]) if b else {}
    for name in INDICATORS:
        value_a = _finite(summary_a.get(f"{name}_median"))
        value_b = _finite(summary_b.get(f"{name}_median"))
        row[f"{name}_a"], row[f"{name}_b"] = value_a, value_b
        row[f"{name}_ratio"] = value_b / value_a if value_a and value_b is not None else None
    row["cell_a"] = cell_key(a[0]["spec"]) if a else None
    row["cell_b"] = cell_key(b[0]["spec"]) if b else None
    row["run_ids_a"] = [r["id"] for r in a]
    row["run_ids_b"] = [r["id"] for r in b]
    return row


def _finite(value):
    """JSON-safe: NaN and infinities become None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
