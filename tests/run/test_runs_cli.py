"""``fdbench runs list|show|export|compare``: what a results database holds, read without changing
it. Two small databases are filled with real runs; every answer is checked against the stored
rows read directly with sqlite, and every database's bytes and mtime against their state before."""

from __future__ import annotations

import csv
import io
import json
import os
import sqlite3
import statistics
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fdbench.cli import app

from helpers.cli_checks import assert_one_line_error
from helpers.paths import ROOT


runner = CliRunner()


def invoke(*args, code=0, env=None):
    result = runner.invoke(app, [str(a) for a in args], env=env)
    assert "Traceback" not in result.stderr, result.stderr
    assert result.exit_code == code, f"exit {result.exit_code}; stderr: {result.stderr!r}"
    return result


def refused(*args, contains=()) -> str:
    """Exit 2, nothing on stdout, one line on stderr holding every word of ``contains``."""
    return assert_one_line_error(invoke(*args, code=2), *contains)


# ---- two databases of real runs ---------------------------------------------------------------

OPTIMIZE = ("optimize", "--torque", "cs", "--opt", "bfgs", "--budget", "5", "-q", "-f", "json")


@pytest.fixture(scope="module")
def databases(tmp_path_factory):
    """A: PD, LQR, CS + BFGS with seeds 0 and 1. B: PD (same settings as A's), LQR with another
    q_angle, computed torque, CS + BFGS with seed 0. Returned as (A, B)."""
    folder = tmp_path_factory.mktemp("stores")
    a, b = folder / "a.sqlite", folder / "b.sqlite"
    for args in (("control",), ("control", "--controller", "lqr"), (*OPTIMIZE, "--seed", "0"),
                 (*OPTIMIZE, "--seed", "1")):
        invoke(*args, "-q", "-f", "json", "--db", a)
    for args in (("control",), ("control", "--controller", "lqr", "--q-angle", "1000"),
                 ("control", "--controller", "computed-torque"), (*OPTIMIZE, "--seed", "0")):
        invoke(*args, "-q", "-f", "json", "--db", b)
    return a, b


def stored(path: Path, where: str = "1", args=()) -> list[dict]:
    """The rows of the runs table matching an SQL condition, read directly."""
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    con.row_factory = sqlite3.Row
    try:
        return [dict(row) for row in con.execute(f"SELECT * FROM runs WHERE {where} ORDER BY id", args)]
    finally:
        con.close()


def state(*paths: Path) -> dict:
    """Each database's bytes and modification time (ns)."""
    return {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in paths}


@pytest.fixture
def unchanged(databases):
    """The databases must be byte for byte and mtime for mtime what they were before the test."""
    before = state(*databases)
    yield databases
    assert state(*databases) == before


# ---- list -------------------------------------------------------------------------------------

PD = "command = 'control' AND coalesce(json_extract(spec_json, '$.controller'), 'pd') = 'pd'"
FILTERS = {
    (): "1",
    ("--command", "optimize"): "command = 'optimize'",
    ("--command", "control"): "command = 'control'",
    ("--controller", "pd"): PD,
    ("--controller", "lqr"): "json_extract(spec_json, '$.controller') = 'lqr'",
    ("--torque", "cs", "--opt", "bfgs"): "json_extract(spec_json, '$.torque') = 'cs' AND "
                                         "json_extract(spec_json, '$.optimizer') = 'bfgs'",
    ("--model", "forearm", "--status", "success"): "status = 'success'",
}


@pytest.mark.parametrize("filters", list(FILTERS), ids=lambda f: " ".join(f) or "none")
def test_list_shows_exactly_the_runs_matching_its_filters(unchanged, filters):
    a, _ = unchanged
    listed = json.loads(invoke("runs", "list", "--db", a, *filters, "-f", "json").stdout)
    expected = stored(a, FILTERS[filters])
    assert expected, "each filter must select some runs"
    assert [row["id"] for row in listed] == [row["id"] for row in expected]


def test_list_csv_carries_the_stored_indicators(unchanged):
    a, _ = unchanged
    rows = list(csv.DictReader(io.StringIO(invoke("runs", "list", "--db", a, "-f", "csv").stdout)))
    expected = stored(a)
    assert len(rows) == len(expected) == 4
    for row, run in zip(rows, expected):
        assert (int(row["id"]), row["command"], row["status"]) == (run["id"], run["command"], run["status"])
        for name in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s", "t_end"):
            assert float(row[name]) == run[name]
        assert row["seed"] == ("" if run["seed"] is None else str(run["seed"]))
    assert {row["method"] for row in rows} == {"pd", "lqr", "cs + bfgs"}


def test_the_table_shows_every_run_and_its_method(unchanged):
    a, _ = unchanged
    text = invoke("runs", "list", "--db", a, env={"COLUMNS": "200"}).stdout
    assert "4 runs" in text and "cs + bfgs" in text and "lqr" in text


def test_a_table_into_a_pipe_keeps_to_80_columns_where_it_can_and_never_cuts_a_number(unchanged):
    """Off a terminal (CliRunner's stdout is not one) and without COLUMNS, a table wraps its words to
    about 80 columns (157 to 206 before); every indicator stored still shows whole, as the CSV has it."""
    a, _ = unchanged
    text = invoke("runs", "list", "--db", a, env={"COLUMNS": None}).stdout
    assert max(len(line) for line in text.splitlines()) <= 110, text  # 11 columns: their longest words need 103
    words = set(text.split())
    for row in csv.DictReader(io.StringIO(invoke("runs", "list", "--db", a, "-f", "csv").stdout)):
        for name in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"):
            assert f"{float(row[name]):.4g}" in words, (name, row[name], text)
    assert "--------" not in text and "…" not in text  # nothing cut short


@pytest.mark.parametrize("option, value, present", [
    ("--model", "arm2", "forearm"), ("--status", "singular", "success"), ("--torque", "ann", "cs"),
    ("--controller", "computed-torque", "lqr, pd"), ("--command", "collocate", "control, optimize"),
])
def test_a_filter_value_no_run_has_is_refused_naming_the_values_present(unchanged, option, value, present):
    a, _ = unchanged
    line = refused("runs", "list", "--db", a, option, value, contains=(option, value, present))
    assert "present" in line


# ---- show -------------------------------------------------------------------------------------


def test_show_gives_the_stored_record_settings_provenance_and_history(unchanged):
    a, _ = unchanged
    for run in stored(a):
        for key in (run["id"], run["spec_hash"]):
            shown = json.loads(invoke("runs", "show", key, "--db", a, "-f", "json").stdout)
            assert shown["id"] == run["id"] and shown["spec_hash"] == run["spec_hash"]
            assert shown["record"] == json.loads(run["record_json"])
            assert shown["settings"] == json.loads(run["spec_json"])
            assert shown["history"] == json.loads(run["history_json"])
            assert shown["params"] == (json.loads(run["params_json"]) if run["params_json"] else None)
            provenance = shown["provenance"]
            for name in ("created_at", "machine", "git_commit", "fdbench_version", "jobs"):
                assert provenance[name] == run[name]
            assert provenance["versions"] == json.loads(run["versions_json"])


def test_show_table_names_the_run_its_settings_and_where_it_was_made(unchanged):
    a, _ = unchanged
    run = stored(a, "command = 'optimize'")[0]
    text = invoke("runs", "show", run["id"], "--db", a, env={"COLUMNS": "200"}).stdout
    for expected in (run["spec_hash"], run["machine"], run["created_at"], "bfgs", "budget", "provenance"):
        assert expected in text


@pytest.mark.parametrize("key", ["99", "0", "abc", "1.0"])
def test_show_of_an_unknown_run_is_refused(unchanged, key):
    a, _ = unchanged
    refused("runs", "show", key, "--db", a, contains=(key, "ids 1 to 4"))


# ---- export -----------------------------------------------------------------------------------


def test_export_csv_has_one_row_per_run_with_every_field_of_its_record(unchanged):
    a, _ = unchanged
    rows = list(csv.DictReader(io.StringIO(invoke("runs", "export", "--db", a, "-f", "csv").stdout)))
    expected = stored(a)
    assert len(rows) == len(expected)
    for row, run in zip(rows, expected):
        record = json.loads(run["record_json"])
        assert int(row["id"]) == run["id"]
        for name, value in record.items():
            if value is None:
                assert row[name] == ""
            elif isinstance(value, float):
                assert float(row[name]) == value, name
            else:
                assert row[name] == str(value), name
        assert json.loads(row["settings"]) == json.loads(run["spec_json"])
        assert (row["machine"], row["git_commit"] or None) == (run["machine"], run["git_commit"])  # CSV: None is ""


def test_export_json_to_a_file_has_every_record(unchanged, tmp_path):
    a, _ = unchanged
    out = tmp_path / "runs.json"
    invoke("runs", "export", "--db", a, "--command", "optimize", "-f", "json", "-o", out)
    rows = json.loads(out.read_text())
    expected = stored(a, "command = 'optimize'")
    assert len(rows) == len(expected) == 2
    for row, run in zip(rows, expected):
        assert {k: row[k] for k in json.loads(run["record_json"])} == json.loads(run["record_json"])
        assert row["settings"] == json.loads(run["spec_json"])


def _parquet_engine() -> bool:
    import importlib.util

    return any(importlib.util.find_spec(name) for name in ("pyarrow", "fastparquet"))


def test_parquet_goes_to_a_file_only(unchanged):
    a, _ = unchanged
    refused("runs", "export", "--db", a, "-f", "parquet", contains=("parquet", "-o"))


@pytest.mark.skipif(_parquet_engine(), reason="pandas can write Parquet here")
def test_parquet_without_an_engine_says_what_to_install(unchanged, tmp_path):
    a, _ = unchanged
    out = tmp_path / "runs.parquet"
    refused("runs", "export", "--db", a, "-f", "parquet", "-o", out, contains=("pyarrow", "pip install"))
    assert not out.exists()


@pytest.mark.skipif(not _parquet_engine(), reason="needs pyarrow or fastparquet")
def test_parquet_round_trips(unchanged, tmp_path):
    import pandas as pd

    a, _ = unchanged
    out = tmp_path / "runs.parquet"
    invoke("runs", "export", "--db", a, "-f", "parquet", "-o", out)
    frame = pd.read_parquet(out)
    assert list(frame["id"]) == [run["id"] for run in stored(a)]
    assert list(frame["rmse_rot_deg"]) == [run["rmse_rot_deg"] for run in stored(a)]
    assert [None if pd.isna(v) else v for v in frame["seed"]] == [run["seed"] for run in stored(a)]


# ---- compare ----------------------------------------------------------------------------------


def _cells(a: Path, b: Path, *args) -> dict:
    cells = json.loads(invoke("runs", "compare", a, b, *args, "-f", "json").stdout)["cells"]
    return {(cell["method"], cell["found"]): cell for cell in cells}


def test_compare_pairs_the_same_cells_with_ratios_b_over_a(unchanged):
    a, b = unchanged
    cells = _cells(a, b)
    assert set(cells) == {("pd", "settings"), ("cs + bfgs", "settings"), ("lqr", "method and conditions"),
                          ("computed-torque", "only in B")}
    for method, where in (("pd", PD), ("cs + bfgs", "command = 'optimize' AND seed = 0")):
        cell = cells[(method, "settings")]
        runs_a, runs_b = stored(a, where), stored(b, where)
        if method == "cs + bfgs":
            runs_a = stored(a, "command = 'optimize'")  # seeds 0 and 1: one cell
        assert (cell["runs_a"], cell["runs_b"]) == (len(runs_a), len(runs_b))
        assert cell["run_ids_a"] == [r["id"] for r in runs_a] and cell["run_ids_b"] == [r["id"] for r in runs_b]
        for name in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"):
            median_a = statistics.median(r[name] for r in runs_a)
            median_b = statistics.median(r[name] for r in runs_b)
            assert cell[f"{name}_a"] == pytest.approx(median_a, rel=1e-12)
            assert cell[f"{name}_b"] == pytest.approx(median_b, rel=1e-12)
            assert cell[f"{name}_ratio"] == pytest.approx(median_b / median_a, rel=1e-12)
    alone = cells[("computed-torque", "only in B")]
    assert (alone["runs_a"], alone["runs_b"], alone["rmse_rot_deg_a"], alone["rmse_rot_deg_ratio"]) == (0, 1, None, None)


def test_compare_filters_and_formats(unchanged):
    a, b = unchanged
    assert set(_cells(a, b, "--command", "optimize")) == {("cs + bfgs", "settings")}
    assert set(_cells(a, b, "--controller", "computed-torque")) == {("computed-torque", "only in B")}
    rows = list(csv.DictReader(io.StringIO(invoke("runs", "compare", a, b, "-f", "csv").stdout)))
    assert len(rows) == 4 and {"rmse_rot_deg_ratio", "runtime_s_a", "runtime_s_b", "found"} <= set(rows[0])
    text = invoke("runs", "compare", a, b).stdout
    assert "only in B" in text and "cs + bfgs" in text
    refused("runs", "compare", a, b, "--torque", "ann", contains=("--torque", "ann", "cs"))


# ---- read-only, refusals ------------------------------------------------------------------------


def test_no_output_may_name_a_database_or_its_journal(unchanged):
    a, b = unchanged
    for args in (("runs", "list", "--db", a, "-o", a), ("runs", "export", "--db", a, "-o", f"{a}-wal"),
                 ("runs", "show", "1", "--db", a, "-o", a), ("runs", "compare", a, b, "-o", b),
                 ("runs", "compare", a, b, "-o", a)):
        refused(*args, contains=("--output", "results database"))


def test_every_command_leaves_the_databases_as_they_were(databases, tmp_path):
    a, b = databases
    before = state(a, b)
    for args in (("list", "--db", a), ("list", "--db", a, "-f", "csv"), ("show", "1", "--db", a),
                 ("show", "2", "--db", b, "-f", "json"), ("export", "--db", a),
                 ("export", "--db", b, "-f", "json", "-o", tmp_path / "b.json"), ("compare", a, b),
                 ("compare", b, a, "-f", "csv")):
        invoke("runs", *args)
    refused("runs", "list", "--db", a, "--model", "nope")
    assert state(a, b) == before


def test_a_missing_database_is_not_created(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("FDBENCH_DB", raising=False)
    missing = tmp_path / "none.sqlite"
    refused("runs", "list", "--db", missing, contains=("no results database", str(missing)))
    refused("runs", "list", contains=("no results database", "fdbench-results.sqlite", "--db"))
    refused("runs", "compare", missing, missing, contains=("no results database",))
    assert list(tmp_path.iterdir()) == []


def _empty(path):
    path.write_bytes(b"")


def _text(path):
    path.write_text("run,rmse\n1,0.5\n")


def _other_program(path):
    """Another program's SQLite file: its own application_id, no tables."""
    con = sqlite3.connect(path)
    con.execute("PRAGMA application_id = 1234")
    con.commit()
    con.close()


def _only_a_view(path):
    con = sqlite3.connect(path)
    con.execute("CREATE VIEW answers AS SELECT 42 AS answer")
    con.commit()
    con.close()


def _other_tables(path):
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE people (name TEXT)")
    con.commit()
    con.close()


def _future_version(path, source):
    path.write_bytes(source.read_bytes())
    con = sqlite3.connect(path)
    con.execute("UPDATE fdbench_meta SET value = '99' WHERE key = 'version'")
    con.commit()
    con.close()


@pytest.mark.parametrize("make, says", [
    (_empty, "empty"), (_text, "not an fdbench results database"), (_other_program, "not an fdbench"),
    (_only_a_view, "not an fdbench"), (_other_tables, "people"), (_future_version, "version 99"),
])
def test_a_file_that_is_not_an_fdbench_database_is_refused_untouched(databases, tmp_path, make, says):
    path = tmp_path / "other.sqlite"
    make(path, databases[0]) if make is _future_version else make(path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    mtime = path.stat().st_mtime_ns
    refused("runs", "list", "--db", path, contains=("--db", str(path), says))
    refused("runs", "compare", databases[0], path, contains=("B:", says))
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if not p.name.endswith(("-wal", "-shm"))} == before
    assert path.stat().st_mtime_ns == mtime


def test_a_directory_or_a_device_is_refused(tmp_path):
    refused("runs", "list", "--db", tmp_path, contains=("directory",))
    refused("runs", "export", "--db", os.devnull, contains=("not a regular file",))


# ---- help and README ------------------------------------------------------------------------------


@pytest.mark.parametrize("command", ["list", "show", "export", "compare"])
def test_help_shows_formats_and_no_type_noise(command):
    text = invoke("runs", command, "--help", env={"COLUMNS": "200"}).stdout
    assert "<bool>" not in text and "--format" in text


def test_the_readme_commands_run_as_written(databases, tmp_path, monkeypatch):
    import shlex

    readme = (ROOT / "README.md").read_text()
    block = readme.split("### Looking at stored runs\n", 1)[1].split("```")[1]
    lines = [line.split("#")[0] for line in block.splitlines() if line.startswith("fdbench runs ")]
    assert len(lines) == 4
    a, b = databases
    (tmp_path / "fdbench-results.sqlite").write_bytes(a.read_bytes())
    (tmp_path / "old.sqlite").write_bytes(b.read_bytes())
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("FDBENCH_DB", raising=False)
    for line in lines:
        invoke(*shlex.split(line)[1:])
    assert len(list(csv.DictReader(open(tmp_path / "runs.csv")))) == len(stored(a))


def strict_json(text: str):
    """JSON as jq reads it: NaN and Infinity are not JSON."""
    def refuse(name):
        raise ValueError(f"{name} in the JSON output")

    return json.loads(text, parse_constant=refuse)


def test_a_run_that_failed_with_nan_gives_valid_json_everywhere(databases, tmp_path):
    path = tmp_path / "failed.sqlite"
    path.write_bytes(databases[0].read_bytes())
    con = sqlite3.connect(path)
    record = json.loads(con.execute("SELECT record_json FROM runs WHERE id = 3").fetchone()[0])
    record.update(rmse_rot_deg=float("nan"), rmse_torque_nm=float("inf"), status="nonfinite")
    con.execute("UPDATE runs SET record_json = ?, history_json = ?, status = 'nonfinite', rmse_rot_deg = NULL "
                "WHERE id = 3", (json.dumps(record), json.dumps([float("inf"), 2.5])))
    con.commit()
    con.close()
    shown = strict_json(invoke("runs", "show", "3", "--db", path, "-f", "json").stdout)
    assert shown["record"]["rmse_rot_deg"] is None and shown["history"] == [None, 2.5]
    listed = strict_json(invoke("runs", "list", "--db", path, "--status", "nonfinite", "-f", "json").stdout)
    assert [row["id"] for row in listed] == [3] and listed[0]["rmse_torque_nm"] is None
    strict_json(invoke("runs", "export", "--db", path, "-f", "json").stdout)
    strict_json(invoke("runs", "compare", databases[0], path, "-f", "json").stdout)


def test_show_finds_a_run_a_rerun_replaced(tmp_path):
    """A report cites the ids it used; a later --rerun keeps the replaced run, and show finds it."""
    db = tmp_path / "r.sqlite"
    invoke("control", "--db", db, "-q", "-f", "json")
    con = sqlite3.connect(db)
    (old_id, old_rmse), = con.execute("SELECT id, rmse_rot_deg FROM runs").fetchall()
    con.close()
    invoke("report", "--rerun", "--no-beyond", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--seeds", "1",
           "--budget", "3", "--db", db, "-q", "-f", "json")
    shown = json.loads(invoke("runs", "show", old_id, "--db", db, "-f", "json").stdout)
    assert shown["id"] == old_id and shown["superseded"] is True
    assert shown["record"]["rmse_rot_deg"] == old_rmse
    listed = json.loads(invoke("runs", "list", "--db", db, "-f", "json").stdout)
    assert old_id not in [row["id"] for row in listed]  # list shows the current runs only
