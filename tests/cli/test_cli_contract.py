"""The command-line contract (DESIGN.md section 5), tested from the outside.

* bad usage or input: exit code 2, exactly one line ``fdbench: error: ...`` on stderr, nothing
  on stdout, never a traceback, and no work done (nothing written);
* a fuzz of every command's numeric and name options: either a result (exit 0) or a one-line
  error (exit 2), never exit 1 and never a traceback;
* stdout carries only the result (JSON / CSV parse), ``--output``, ``--quiet``, ``--version``,
  ``NO_COLOR``;
* the JSON keys and CSV header every run reports;
* a run that does not reach t = 1 s still exits 0 and says so in ``status`` and ``t_end``.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import fdbench
from fdbench.cli import app

PREFIX = "fdbench: error:"
CONTRACT_KEYS = (
    "command", "kinematics", "integrator", "torque", "optimizer", "feedforward", "seed", "budget",
    "rmse_rot_deg", "rmse_torque_nm", "runtime_s", "evaluations", "t_end", "status", "fdbench_version",
)
KINEMATICS = ("paper", "exact")
INTEGRATORS = ("rk4", "rk45", "dop853", "lsoda", "radau", "bdf")
TORQUES = ("ann", "cs", "pf")
OPTIMIZERS = ("cmaes", "bfgs", "nelder-mead", "lbfgsb")
FORMATS = ("table", "json", "csv")
REPORT_FORMATS = ("md", "csv", "json")
ANSI = re.compile(r"\x1b\[")

runner = CliRunner()


def invoke(args, **kwargs):
    return runner.invoke(app, [str(a) for a in args], **kwargs)


def assert_no_traceback(result):
    assert "Traceback" not in result.stdout and "Traceback" not in result.stderr, result.stderr
    # an exception that escaped FdbenchGroup would show here (CliRunner catches it)
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)


def assert_bad_input(result, contains=()):
    """Exit 2, nothing on stdout, one non-empty 'fdbench: error: ...' line on stderr."""
    assert_no_traceback(result)
    assert result.exit_code == 2, f"exit {result.exit_code}; stderr: {result.stderr!r}"
    assert result.stdout == "", f"stdout not empty: {result.stdout[:300]!r}"
    lines = result.stderr.splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got {len(lines)}: {result.stderr!r}"
    line = lines[0]
    assert line.startswith(PREFIX), line
    assert line[len(PREFIX):].strip(), f"empty message: {line!r}"
    for word in contains:
        assert word in line, f"{word!r} missing from {line!r}"
    return line


# ---- files used by the bad-input cases ---------------------------------------------------------

BAD_FILES = {
    "empty.csv": "",
    "blank_lines.csv": "\n\n   \n",
    "header_only.csv": "t,torque\n",
    "malformed.csv": "t,torque\n0,1\n0.5,abc\n1,2\n",
    "ragged.csv": "t,torque\n0,1,\n1\n",
    "wrong_header.csv": "time,tau\n0,1\n1,1\n",
    "one_column.csv": "t\n0\n1\n",
    "non_increasing.csv": "t,torque\n0,1\n0.5,1\n0.5,1\n1,1\n",
    "decreasing.csv": "t,torque\n1,1\n0.5,1\n0,1\n",
    "short_end.csv": "t,torque\n0,1\n0.5,1\n",
    "late_start.csv": "t,torque\n0.1,1\n1,1\n",
    "one_row.csv": "t,torque\n0,1\n",
    "nan_torque.csv": "t,torque\n0,nan\n1,1\n",
    "inf_time.csv": "t,torque\n0,1\ninf,1\n",
    "binary.csv": b"\x00\xff\xfe\x00",
    "bad.json": "{",
    "empty.json": "",
    "empty_object.json": "{}",
    "list.json": "[1, 2]",
    "wrong_count.json": json.dumps({"torque": "cs", "torque_options": {"knots": 11}, "params": [1, 2],
                                    "feedforward": False, "kinematics": "paper"}),
    "unknown_torque.json": json.dumps({"torque": "zz", "params": [1, 2], "feedforward": False,
                                       "kinematics": "paper"}),
    "string_params.json": json.dumps({"torque": "cs", "params": "abc", "feedforward": False,
                                      "kinematics": "paper"}),
    "nan_params.json": '{"torque": "cs", "torque_options": {"knots": 4}, "params": [1, NaN, 1, 1], '
                       '"feedforward": false, "kinematics": "paper"}',
    "bad_knots.json": json.dumps({"torque": "cs", "torque_options": {"knots": 3}, "params": [1, 2, 3],
                                  "feedforward": False, "kinematics": "paper"}),
    "bad_kinematics.json": json.dumps({"torque": "cs", "torque_options": {"knots": 4}, "params": [1, 2, 3, 4],
                                       "feedforward": False, "kinematics": "weird"}),
    "corrupt.sqlite": "this is not a database at all, just some text\n" * 4,
}


def make_files(directory: Path) -> None:
    for name, content in BAD_FILES.items():
        path = directory / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)
    other = sqlite3.connect(directory / "other.sqlite")  # SQLite, but not an fdbench database
    other.execute("CREATE TABLE foo (x INTEGER)")
    other.commit()
    other.close()
    (directory / "a_directory").mkdir()


# ---- the bad-input table -----------------------------------------------------------------------

def case(case_id, args, contains=()):
    """One bad-input case; ``{tmp}`` in an argument is the test's tmp_path."""
    return pytest.param(list(args), tuple(contains), id=case_id)


MISSING = "{tmp}/no_such_dir/out"
DB = ["--db", "{tmp}/report.sqlite"]
OPT = ["optimize", "--budget", "5"]

BAD_INPUT_CASES = [
    # -- root
    case("root-unknown-command", ["nosuch"], ["nosuch"]),
    case("root-unknown-option", ["--bogus"], ["--bogus"]),
    # -- inverse
    case("inverse-kinematics-unknown", ["inverse", "--kinematics", "foo"], KINEMATICS),
    case("inverse-kinematics-case", ["inverse", "--kinematics", "Paper"], KINEMATICS),
    case("inverse-format-unknown", ["inverse", "--format", "xml"], FORMATS),
    case("inverse-output-missing-dir", ["inverse", "--format", "csv", "--output", MISSING], ["--output"]),
    case("inverse-output-is-dir", ["inverse", "--output", "{tmp}/a_directory"], ["--output"]),
    case("inverse-unknown-option", ["inverse", "--kp", "1"], ["--kp"]),
    case("inverse-extra-argument", ["inverse", "extra"], ["extra"]),
    # -- simulate: numbers
    case("simulate-dt-zero", ["simulate", "--dt", "0"], ["--dt"]),
    case("simulate-dt-too-large", ["simulate", "--dt", "0.2"], ["--dt"]),
    case("simulate-dt-negative", ["simulate", "--dt", "-1"], ["--dt"]),
    case("simulate-dt-nan", ["simulate", "--dt", "nan"], ["--dt"]),
    case("simulate-dt-inf", ["simulate", "--dt", "inf"], ["--dt"]),
    case("simulate-dt-text", ["simulate", "--dt", "fast"], ["--dt"]),
    case("simulate-rtol-zero", ["simulate", "--integrator", "rk45", "--rtol", "0"], ["--rtol"]),
    case("simulate-atol-negative", ["simulate", "--integrator", "rk45", "--atol", "-1"], ["--atol"]),
    case("simulate-alpha-zero", ["simulate", "--alpha", "0"], ["--alpha"]),
    case("simulate-alpha-nan", ["simulate", "--alpha", "nan"], ["--alpha"]),
    case("simulate-xi-negative", ["simulate", "--xi", "-1"], ["--xi"]),
    case("simulate-omega-zero", ["simulate", "--omega", "0"], ["--omega"]),
    case("simulate-omega-inf", ["simulate", "--omega", "inf"], ["--omega"]),
    # -- simulate: names
    case("simulate-integrator-unknown", ["simulate", "--integrator", "euler"], INTEGRATORS),
    case("simulate-kinematics-unknown", ["simulate", "--kinematics", "bar"], KINEMATICS),
    case("simulate-format-unknown", ["simulate", "--format", "yaml"], FORMATS),
    case("simulate-unknown-option", ["simulate", "--torque", "cs"], ["--torque"]),
    # -- simulate --torque-file
    case("torque-file-missing", ["simulate", "--torque-file", "{tmp}/missing.csv"], ["--torque-file"]),
    case("torque-file-directory", ["simulate", "--torque-file", "{tmp}/a_directory"], ["--torque-file"]),
    case("torque-file-empty", ["simulate", "--torque-file", "{tmp}/empty.csv"], ["--torque-file"]),
    case("torque-file-blank-lines", ["simulate", "--torque-file", "{tmp}/blank_lines.csv"], ["--torque-file"]),
    case("torque-file-header-only", ["simulate", "--torque-file", "{tmp}/header_only.csv"], ["--torque-file"]),
    case("torque-file-malformed", ["simulate", "--torque-file", "{tmp}/malformed.csv"], ["--torque-file"]),
    case("torque-file-ragged", ["simulate", "--torque-file", "{tmp}/ragged.csv"], ["--torque-file"]),
    case("torque-file-wrong-header", ["simulate", "--torque-file", "{tmp}/wrong_header.csv"], ["--torque-file"]),
    case("torque-file-one-column", ["simulate", "--torque-file", "{tmp}/one_column.csv"], ["--torque-file"]),
    case("torque-file-non-increasing", ["simulate", "--torque-file", "{tmp}/non_increasing.csv"], ["increasing"]),
    case("torque-file-decreasing", ["simulate", "--torque-file", "{tmp}/decreasing.csv"], ["increasing"]),
    case("torque-file-short-end", ["simulate", "--torque-file", "{tmp}/short_end.csv"], ["[0, 1]"]),
    case("torque-file-late-start", ["simulate", "--torque-file", "{tmp}/late_start.csv"], ["[0, 1]"]),
    case("torque-file-one-row", ["simulate", "--torque-file", "{tmp}/one_row.csv"], ["--torque-file"]),
    case("torque-file-nan", ["simulate", "--torque-file", "{tmp}/nan_torque.csv"], ["--torque-file"]),
    case("torque-file-inf-time", ["simulate", "--torque-file", "{tmp}/inf_time.csv"], ["--torque-file"]),
    case("torque-file-binary", ["simulate", "--torque-file", "{tmp}/binary.csv"], ["--torque-file"]),
    case("torque-file-and-params", ["simulate", "--torque-file", "{tmp}/short_end.csv", "--params", "{tmp}/bad.json"],
         ["--torque-file", "--params"]),
    case("torque-file-newline-in-path", ["simulate", "--torque-file", "{tmp}/line\nbreak.csv"], ["--torque-file"]),
    # -- simulate --params
    case("params-missing", ["simulate", "--params", "{tmp}/missing.json"], ["--params"]),
    case("params-directory", ["simulate", "--params", "{tmp}/a_directory"], ["--params"]),
    case("params-malformed-json", ["simulate", "--params", "{tmp}/bad.json"], ["--params"]),
    case("params-empty-file", ["simulate", "--params", "{tmp}/empty.json"], ["--params"]),
    case("params-empty-object", ["simulate", "--params", "{tmp}/empty_object.json"], ["--params"]),
    case("params-list", ["simulate", "--params", "{tmp}/list.json"], ["--params"]),
    case("params-wrong-count", ["simulate", "--params", "{tmp}/wrong_count.json"], ["--params"]),
    case("params-unknown-torque", ["simulate", "--params", "{tmp}/unknown_torque.json"], TORQUES),
    case("params-string-params", ["simulate", "--params", "{tmp}/string_params.json"], ["--params"]),
    case("params-nan-params", ["simulate", "--params", "{tmp}/nan_params.json"], ["--params"]),
    case("params-bad-knots", ["simulate", "--params", "{tmp}/bad_knots.json"], ["--knots"]),
    case("params-bad-kinematics", ["simulate", "--params", "{tmp}/bad_kinematics.json"], ["--params"]),
    # -- simulate outputs
    case("simulate-output-missing-dir", ["simulate", "--output", MISSING], ["--output"]),
    case("simulate-save-history-missing-dir", ["simulate", "--save-history", MISSING], ["--save-history"]),
    # -- control
    case("control-kp-negative", ["control", "--kp", "-1"], ["--kp"]),
    case("control-kp-nan", ["control", "--kp", "nan"], ["--kp"]),
    case("control-kp-inf", ["control", "--kp", "inf"], ["--kp"]),
    case("control-kp-text", ["control", "--kp", "x"], ["--kp"]),
    case("control-kp-empty", ["control", "--kp", ""], ["--kp"]),
    case("control-kp-missing-value", ["control", "--kp"], ["--kp"]),
    case("control-kd-negative", ["control", "--kd", "-0.3"], ["--kd"]),
    case("control-kd-nan", ["control", "--kd", "nan"], ["--kd"]),
    case("control-kd-minus-inf", ["control", "--kd", "-inf"], ["--kd"]),
    case("control-dt-zero", ["control", "--dt", "0"], ["--dt"]),
    case("control-dt-too-large", ["control", "--dt", "0.2"], ["--dt"]),
    case("control-dt-negative", ["control", "--dt", "-1"], ["--dt"]),
    case("control-dt-tiny", ["control", "--dt", "1e-300"], ["--dt"]),
    case("control-alpha-subnormal", ["control", "--alpha", "5e-324"], ["--alpha"]),
    case("simulate-omega-huge", ["simulate", "--omega", "1e300"], ["--omega"]),
    case("control-rtol-below-scipy-floor", ["control", "--integrator", "rk45", "--rtol", "1e-20"], ["--rtol"]),
    case("control-rtol-zero", ["control", "--rtol", "0"], ["--rtol"]),
    case("control-atol-negative", ["control", "--atol", "-1"], ["--atol"]),
    case("control-alpha-negative", ["control", "--alpha", "-5"], ["--alpha"]),
    case("control-xi-nan", ["control", "--xi", "nan"], ["--xi"]),
    case("control-omega-negative", ["control", "--omega", "-1"], ["--omega"]),
    case("control-integrator-case", ["control", "--integrator", "RK4"], INTEGRATORS),
    case("control-kinematics-unknown", ["control", "--kinematics", "PAPER"], KINEMATICS),
    case("control-format-unknown", ["control", "--format", "yaml"], FORMATS),
    case("control-unknown-option", ["control", "--gain", "3"], ["--gain"]),
    case("control-output-missing-dir", ["control", "--output", MISSING], ["--output"]),
    case("control-output-is-dir", ["control", "-o", "{tmp}/a_directory"], ["--output"]),
    case("control-save-history-missing-dir", ["control", "--save-history", MISSING], ["--save-history"]),
    case("control-db-missing-dir", ["control", "--db", MISSING], ["--db"]),
    case("control-db-corrupt", ["control", "--db", "{tmp}/corrupt.sqlite"], ["--db"]),
    # -- optimize
    case("optimize-budget-zero", [*OPT, "--budget", "0"], ["--budget"]),
    case("optimize-budget-negative", [*OPT, "--budget", "-3"], ["--budget"]),
    case("optimize-budget-text", [*OPT, "--budget", "many"], ["--budget"]),
    case("optimize-budget-float", [*OPT, "--budget", "2.5"], ["--budget"]),
    case("optimize-seed-negative", [*OPT, "--seed", "-1"], ["--seed"]),
    case("optimize-seed-too-large-for-cmaes", [*OPT, "--opt", "cmaes", "--seed", str(2**32)], ["--seed"]),
    case("optimize-seed-huge", [*OPT, "--seed", str(10**30)], ["--seed"]),
    case("optimize-hidden-zero", [*OPT, "--torque", "ann", "--hidden", "0"], ["--hidden"]),
    case("optimize-hidden-text", [*OPT, "--torque", "ann", "--hidden", "x"], ["--hidden"]),
    case("optimize-hidden-huge", [*OPT, "--torque", "ann", "--hidden", "1000000000000"], ["--hidden"]),
    case("optimize-knots-three", [*OPT, "--torque", "cs", "--knots", "3"], ["--knots"]),
    case("optimize-knots-huge", [*OPT, "--torque", "cs", "--knots", "1000000000000"], ["--knots"]),
    case("optimize-terms-zero", [*OPT, "--torque", "pf", "--terms", "0"], ["--terms"]),
    case("optimize-sigma0-zero", [*OPT, "--opt", "cmaes", "--sigma0", "0"], ["--sigma0"]),
    case("optimize-sigma0-nan", [*OPT, "--sigma0", "nan"], ["--sigma0"]),
    case("optimize-popsize-one", [*OPT, "--opt", "cmaes", "--popsize", "1"], ["--popsize"]),
    case("optimize-penalty-weight-negative", [*OPT, "--penalty-weight", "-1"], ["--penalty-weight"]),
    case("optimize-penalty-weight-inf", [*OPT, "--penalty-weight", "inf"], ["--penalty-weight"]),
    case("optimize-torque-unknown", [*OPT, "--torque", "spline"], TORQUES),
    case("optimize-opt-unknown", [*OPT, "--opt", "adam"], OPTIMIZERS),
    case("optimize-dt-too-large", [*OPT, "--dt", "0.5"], ["--dt"]),
    case("optimize-alpha-zero", [*OPT, "--alpha", "0"], ["--alpha"]),
    case("optimize-integrator-unknown", [*OPT, "--integrator", "rk5"], INTEGRATORS),
    case("optimize-kinematics-unknown", [*OPT, "--kinematics", "exactly"], KINEMATICS),
    case("optimize-format-unknown", [*OPT, "--format", "md"], FORMATS),
    case("optimize-unknown-option", [*OPT, "--generations", "3"], ["--generations"]),
    case("optimize-output-missing-dir", [*OPT, "--output", MISSING], ["--output"]),
    case("optimize-save-history-missing-dir", [*OPT, "--save-history", MISSING], ["--save-history"]),
    case("optimize-history-missing-dir", [*OPT, "--history", MISSING], ["--history"]),
    case("optimize-save-params-missing-dir", [*OPT, "--save-params", MISSING], ["--save-params"]),
    case("optimize-db-corrupt", [*OPT, "--db", "{tmp}/corrupt.sqlite"], ["--db"]),
    # -- report (always with a database in tmp_path)
    case("report-seeds-zero", ["report", *DB, "--seeds", "0"], ["--seeds"]),
    case("report-seeds-text", ["report", *DB, "--seeds", "x"], ["--seeds"]),
    case("report-jobs-zero", ["report", *DB, "--jobs", "0"], ["--jobs"]),
    case("report-budget-zero", ["report", *DB, "--budget", "0"], ["--budget"]),
    case("report-kp-negative", ["report", *DB, "--kp", "-1"], ["--kp"]),
    case("report-kd-inf", ["report", *DB, "--kd", "inf"], ["--kd"]),
    case("report-hidden-zero", ["report", *DB, "--hidden", "0"], ["--hidden"]),
    case("report-knots-three", ["report", *DB, "--knots", "3"], ["--knots"]),
    case("report-terms-zero", ["report", *DB, "--terms", "0"], ["--terms"]),
    case("report-sigma0-zero", ["report", *DB, "--sigma0", "0"], ["--sigma0"]),
    case("report-sigma0-nan", ["report", *DB, "--sigma0", "nan"], ["--sigma0"]),
    case("report-popsize-one", ["report", *DB, "--popsize", "1"], ["--popsize"]),
    case("report-penalty-weight-negative", ["report", *DB, "--penalty-weight", "-1"], ["--penalty-weight"]),
    case("report-dt-zero", ["report", *DB, "--dt", "0"], ["--dt"]),
    case("report-alpha-nan", ["report", *DB, "--alpha", "nan"], ["--alpha"]),
    case("report-torque-unknown", ["report", *DB, "--torque", "cs", "--torque", "nn"], TORQUES),
    case("report-opt-unknown", ["report", *DB, "--opt", "sgd"], OPTIMIZERS),
    case("report-integrator-unknown", ["report", *DB, "--integrator", "leapfrog"], INTEGRATORS),
    case("report-kinematics-unknown", ["report", *DB, "--kinematics", "approx"], KINEMATICS),
    case("report-format-table", ["report", *DB, "--format", "table"], REPORT_FORMATS),
    case("report-output-missing-dir", ["report", *DB, "--output", MISSING], ["--output"]),
    case("report-figures-missing-dir", ["report", *DB, "--figures", "{tmp}/no_such_dir/figures"], ["--figures"]),
    case("report-db-missing-dir", ["report", "--db", MISSING], ["--db"]),
    case("report-db-directory", ["report", "--db", "{tmp}/a_directory"], ["--db"]),
    case("report-db-corrupt", ["report", "--db", "{tmp}/corrupt.sqlite", "--seeds", "1", "--budget", "5"], ["--db"]),
    case("report-db-other-sqlite", ["report", "--db", "{tmp}/other.sqlite", "--seeds", "1", "--budget", "5"],
         ["--db"]),
    case("report-unknown-option", ["report", *DB, "--tables", "2"], ["--tables"]),
]


def _snapshot(directory: Path) -> dict:
    return {p.relative_to(directory): p.stat().st_size if p.is_file() else -1 for p in directory.rglob("*")}


@pytest.mark.parametrize("args, contains", BAD_INPUT_CASES)
def test_bad_input(args, contains, tmp_path, monkeypatch):
    make_files(tmp_path)
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)  # nothing a case might write lands in the repository
    monkeypatch.setenv("FDBENCH_DB", str(tmp_path / "env.sqlite"))
    before = _snapshot(tmp_path)
    result = invoke([a.replace("{tmp}", str(tmp_path)) for a in args])
    assert_bad_input(result, contains)
    assert _snapshot(tmp_path) == before, "bad input must be refused before any file is written"


def test_bad_input_table_size():
    families = {values[0][0] for values in (p.values for p in BAD_INPUT_CASES)}
    assert len(BAD_INPUT_CASES) >= 45
    assert {"inverse", "simulate", "control", "optimize", "report"} <= families


def test_report_nonfinite_message_names_option_once(tmp_path):
    line = assert_bad_input(invoke(["report", "--db", tmp_path / "r.sqlite", "--sigma0", "nan"]), ["--sigma0"])
    assert "----" not in line


def test_no_arguments_shows_help_without_empty_error():
    result = invoke([])
    assert_no_traceback(result)
    assert "Usage" in result.stdout or "Usage" in result.stderr
    for line in result.stderr.splitlines():  # an error line, if any, must say something
        assert not re.fullmatch(r"fdbench: error: ?[\w ]*: ?", line), line


def test_help_is_not_an_error():
    for command in ([], ["inverse"], ["simulate"], ["control"], ["optimize"], ["report"], ["methods"]):
        result = invoke([*command, "--help"])
        assert result.exit_code == 0, (command, result.stderr)
        assert "Usage" in result.stdout and result.stderr == ""


# ---- stiff settings with an adaptive integrator -------------------------------------------------

def test_scipy_integrator_with_huge_gain_finishes(monkeypatch):
    """An explicit integrator on a hopelessly stiff loop gives up with a status, never hangs (the
    cap on right-hand side evaluations is lowered so the test is quick)."""
    import fdbench.integrate

    monkeypatch.setattr(fdbench.integrate, "MAX_RHS_EVALUATIONS", 2000)
    result = invoke(["control", "--integrator", "rk45", "--kp", "1e9", "--quiet", "--format", "json"])
    assert result.exit_code == 0 and result.stderr == "", result.stderr
    record = json.loads(result.stdout)
    assert record["status"] == "solver" and "stiff" in record["message"] and record["t_end"] < 1


# ---- fuzz: random option values never give a traceback or exit 1 -------------------------------
#
# Each example gives some options a valid value and (in about half of the examples) one or two
# options a wild one: a random float (nan, inf, negative, huge, subnormal), a random int or a
# random short string. Values that only make examples slow (tiny --dt, huge counts, the scipy
# integrators on stiff settings) are left out; CMA-ES is left out because importing cma takes seconds.

def _as_number(text: str, kind=float):
    """The number the option parser may read from ``text`` (ints are read leniently: '3.0' is 3)."""
    try:
        return kind(text)
    except (ValueError, OverflowError):
        pass
    if kind is int:
        value = _as_number(text, float)
        if value is not None and math.isfinite(value) and value == int(value):
            return int(value)
    return None


JUNK = st.text(max_size=6)
SPECIAL_FLOATS = st.sampled_from([0.0, -0.0, -1.0, 1e-3, 0.05, 0.1, 0.3, 1.0, 10.0, 80.0, 1e7, 1e300, -1e300,
                                  math.inf, -math.inf, math.nan, 5e-324])


def wild_floats(allowed=lambda x: True):
    """Option text for a float option: random floats (nan, inf, negatives, huge), special values
    and random short strings; ``allowed`` excludes values of known bugs."""
    numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), SPECIAL_FLOATS).filter(allowed).map(repr)
    junk = JUNK.filter(lambda s: _as_number(s) is None or allowed(_as_number(s)))
    return st.one_of(numbers, junk)


def wild_ints(high=None):
    """Option text for an int option: random ints (any size unless ``high``), small ones, junk."""
    ints = st.integers() if high is None else st.integers(max_value=high)
    small = st.integers(-5, 5 if high is None else min(5, high))
    junk = JUNK.filter(lambda s: high is None or (_as_number(s, int) or 0) <= high)
    return st.one_of(ints.map(str), small.map(str), junk)


def wild_names(*valid, exclude=()):
    return st.one_of(st.sampled_from(valid), JUNK.filter(lambda s: s not in exclude))


def floats_in(low=None, high=None, special=()):
    values = st.floats(min_value=low, max_value=high, allow_nan=False, allow_infinity=False)
    return st.one_of(values, st.sampled_from(special)).map(repr) if special else values.map(repr)


def ints_in(low, high):
    return st.integers(low, high).map(str)


POSITIVE = floats_in(5e-324, 1e300, special=(1e-3, 1.0, 10.0, 1e7, 1e300))
NON_NEGATIVE = floats_in(0.0, 1e300, special=(0.0, 0.3, 1.0, 80.0, 1e300))
ANY_FLOAT = wild_floats()
FORMAT = (st.sampled_from(FORMATS), wild_names(*FORMATS))
COMMON = {  # option: (valid values, wild values)
    "--kinematics": (st.sampled_from(KINEMATICS), wild_names(*KINEMATICS)),
    # only rk4: the scipy integrators hang on stiff settings (test_scipy_integrator_with_huge_gain_finishes)
    "--integrator": (st.just("rk4"), wild_names("rk4", exclude=INTEGRATORS[1:])),
    # 1e-4 s (10 000 steps) at the least keeps every example cheap
    "--dt": (floats_in(1e-4, 0.1, special=(1e-3, 0.1)), wild_floats(lambda x: not (0 < x < 1e-4))),
    "--rtol": (floats_in(1e-12, 0.5, special=(1e-6, 1e-3)), ANY_FLOAT),
    "--atol": (POSITIVE, ANY_FLOAT),
    "--alpha": (floats_in(1e-300, 1e300, special=(1e-300, 1.0, 1e7, 1e300)),
                wild_floats(lambda x: not (0 < x < 1e-300))),
    "--xi": (NON_NEGATIVE, ANY_FLOAT),
    "--omega": (floats_in(5e-324, 1e150, special=(5e-324, 1.0, 10.0, 1e150)),
                wild_floats(lambda x: not (1e150 < x < math.inf))),
}


@st.composite
def option_tokens(draw, spec: dict):
    """Command-line tokens: a random subset of the options with valid values, and in about half
    of the examples one or two options (given or not) with wild values."""
    keys = list(spec)
    given_keys = draw(st.lists(st.sampled_from(keys), unique=True, max_size=len(keys)))
    wild = draw(st.lists(st.sampled_from(keys), unique=True, max_size=2)) if draw(st.booleans()) else []
    tokens = []
    for key in keys:
        if key in wild:
            tokens += [key, draw(spec[key][1])]
        elif key in given_keys:
            tokens += [key, draw(spec[key][0])]
    return tokens


def check_fuzz_outcome(result, command: str, tokens: list[str]):
    """Exit 0 with a result on stdout, or exit 2 with one error line; never exit 1 or a traceback."""
    context = (f"fdbench {command} {' '.join(map(repr, tokens))}\nexit {result.exit_code}\n"
               f"stdout: {result.stdout[:500]!r}\nstderr: {result.stderr[:500]!r}")
    assert_no_traceback(result)
    assert result.exit_code in (0, 2), context
    if result.exit_code == 2:
        assert_bad_input(result)
        return
    assert result.stderr == "", "--quiet: " + context
    fmt = "table"
    for i, token in enumerate(tokens[:-1]):
        if token in ("--format", "-f"):
            fmt = tokens[i + 1]
    if fmt == "json":
        record = json.loads(result.stdout)
        assert record["command"] == command, context
        if command != "inverse":
            assert record["status"] in ("success", "nonfinite", "singular", "constraint", "solver"), context
            assert record["t_end"] is None or 0 <= record["t_end"] <= 1, context
    elif fmt == "csv":
        frame = pd.read_csv(io.StringIO(result.stdout))
        assert len(frame) == (1001 if command == "inverse" else 1), context
    else:
        assert command in result.stdout, context


def examples(default: int) -> int:
    """Examples per fuzz test; FDBENCH_FUZZ_EXAMPLES=500 for a longer hunt."""
    return int(os.environ.get("FDBENCH_FUZZ_EXAMPLES", default))


def fuzz(command: str, tokens: list[str]):
    result = invoke([command, *tokens, "--quiet"])
    event(f"exit {result.exit_code}")  # pytest --hypothesis-show-statistics: how the examples ended
    check_fuzz_outcome(result, command, tokens)


@settings(max_examples=examples(30), database=None, deadline=None)
@given(option_tokens({"--kinematics": COMMON["--kinematics"], "--format": FORMAT}))
def test_fuzz_inverse(tokens):
    fuzz("inverse", tokens)


@settings(max_examples=examples(40), database=None, deadline=None)
@given(option_tokens({**COMMON, "--format": FORMAT}))
def test_fuzz_simulate(tokens):
    fuzz("simulate", tokens)


@settings(max_examples=examples(40), database=None, deadline=None)
@given(option_tokens({"--kp": (NON_NEGATIVE, ANY_FLOAT), "--kd": (NON_NEGATIVE, ANY_FLOAT), **COMMON,
                      "--format": FORMAT}))
def test_fuzz_control(tokens):
    fuzz("control", tokens)


OPTIMIZE_OPTIONS = {
    "--torque": (st.sampled_from(TORQUES), wild_names(*TORQUES)),
    "--opt": (st.sampled_from(["bfgs", "nelder-mead", "lbfgsb"]),  # not cmaes: cma's import is slow
              wild_names("bfgs", "nelder-mead", "lbfgsb", exclude=("cmaes",))),
    "--seed": (ints_in(0, 10**6), wild_ints()),
    # ANN pre-training costs grow with the neurons, pf's fit with the terms
    "--hidden": (st.one_of(st.just("auto"), ints_in(1, 5)), st.one_of(wild_ints(high=5), JUNK)
                 .filter(lambda s: (_as_number(s, int) or 0) <= 5)),
    "--knots": (ints_in(4, 30), wild_ints(high=30)),
    "--terms": (ints_in(1, 2), wild_ints(high=2)),
    "--sigma0": (POSITIVE, ANY_FLOAT),
    "--popsize": (ints_in(2, 20), wild_ints()),
    "--penalty-weight": (NON_NEGATIVE, ANY_FLOAT),
    "--budget": (ints_in(1, 5), wild_ints(high=5)),
    **COMMON,
    "--format": FORMAT,
}


@st.composite
def optimize_tokens(draw):
    tokens = draw(option_tokens(OPTIMIZE_OPTIONS))
    if "--budget" not in tokens:
        tokens += ["--budget", draw(ints_in(1, 5))]
    flag = draw(st.sampled_from([None, "--feedforward", "--no-feedforward"]))
    return tokens + ([flag] if flag else [])


@settings(max_examples=examples(40), database=None, deadline=None)
@given(optimize_tokens())
def test_fuzz_optimize(tokens):
    fuzz("optimize", tokens)


# ---- stdout carries only the result --------------------------------------------------------------

def test_optimize_json_stdout_is_pure_json():
    result = invoke(["optimize", "--torque", "cs", "--opt", "bfgs", "--budget", "20", "--format", "json"])
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["command"] == "optimize" and record["budget"] == 20
    assert record["evaluations"] <= 20


def test_optimize_csv_stdout_is_one_row():
    result = invoke(["optimize", "--torque", "cs", "--opt", "bfgs", "--budget", "20", "--format", "csv"])
    assert result.exit_code == 0, result.stderr
    frame = pd.read_csv(io.StringIO(result.stdout))
    assert len(frame) == 1
    assert frame.loc[0, "command"] == "optimize" and frame.loc[0, "torque"] == "cs"
    assert math.isfinite(frame.loc[0, "rmse_rot_deg"])


RUN_COMMANDS = {
    "control": ["control"],
    "simulate": ["simulate"],
    "optimize": ["optimize", "--budget", "5"],
}


@pytest.mark.parametrize("fmt", ["json", "csv", "table"])
@pytest.mark.parametrize("command", ["inverse", *RUN_COMMANDS])
def test_output_file_leaves_stdout_empty(command, fmt, tmp_path):
    target = tmp_path / f"result.{fmt}"
    args = RUN_COMMANDS.get(command, [command])
    result = invoke([*args, "--format", fmt, "--output", target])
    assert result.exit_code == 0, result.stderr
    assert result.stdout == ""
    text = target.read_text()
    if fmt == "json":
        assert json.loads(text)["command"] == command
    elif fmt == "csv":
        assert len(pd.read_csv(io.StringIO(text))) == (1001 if command == "inverse" else 1)
    else:
        assert "rmse_rot_deg" in text or command == "inverse"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temporary file left behind"


QUIET_RUNS = [
    ["inverse"],
    ["inverse", "--format", "csv"],
    ["simulate", "--format", "json"],
    ["control", "--format", "csv"],
    ["control", "--save-history", "{tmp}/history.csv", "--output", "{tmp}/out.json", "--format", "json"],
    ["optimize", "--budget", "5", "--format", "json"],
    ["optimize", "--budget", "5", "--torque", "ann", "--hidden", "auto", "--history", "{tmp}/h.csv",
     "--save-params", "{tmp}/p.json", "--db", "{tmp}/runs.sqlite"],
    ["report", "--db", "{tmp}/report.sqlite", "--no-control", "--torque", "cs", "--opt", "bfgs", "--feedforward",
     "--seeds", "1", "--budget", "5", "--jobs", "1", "--format", "csv"],
]


@pytest.mark.parametrize("args", QUIET_RUNS, ids=lambda a: "-".join(x for x in a if not x.startswith("{")))
def test_quiet_leaves_stderr_empty(args, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = invoke([a.replace("{tmp}", str(tmp_path)) for a in args] + ["--quiet"])
    assert result.exit_code == 0, result.stderr
    assert result.stderr == ""
    assert result.stdout or "--output" in args


def test_saved_params_replay_in_simulate(tmp_path):
    params = tmp_path / "p.json"
    result = invoke(["optimize", "--budget", "5", "--save-params", params, "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.stderr
    replay = invoke(["simulate", "--params", params, "--format", "json", "--quiet"])
    assert replay.exit_code == 0, replay.stderr
    assert json.loads(replay.stdout)["rmse_rot_deg"] == pytest.approx(json.loads(result.stdout)["rmse_rot_deg"],
                                                                      rel=1e-6)


def test_version():
    result = invoke(["--version"])
    assert result.exit_code == 0
    assert result.stdout.strip() == f"fdbench {fdbench.__version__}"
    assert result.stderr == ""


@pytest.mark.parametrize("args", [["control"], ["simulate"], ["inverse"], ["optimize", "--budget", "5"],
                                  ["methods"]])
def test_no_color_table_has_no_ansi(args):
    result = invoke([*args], env={"NO_COLOR": "1"})
    assert result.exit_code == 0, result.stderr
    assert result.stdout.strip()
    assert not ANSI.search(result.stdout) and not ANSI.search(result.stderr)


# ---- the JSON keys and CSV header of every run --------------------------------------------------

@pytest.mark.parametrize("command", list(RUN_COMMANDS))
def test_json_and_csv_carry_the_contract_keys(command):
    args = RUN_COMMANDS[command]
    as_json = invoke([*args, "--format", "json", "--quiet"])
    assert as_json.exit_code == 0, as_json.stderr
    record = json.loads(as_json.stdout)
    assert set(CONTRACT_KEYS) <= set(record), set(CONTRACT_KEYS) - set(record)
    assert record["command"] == command
    assert record["fdbench_version"] == fdbench.__version__
    assert record["status"] == "success" and record["t_end"] == pytest.approx(1.0)
    for key in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"):
        assert math.isfinite(record[key]) and record[key] >= 0

    as_csv = invoke([*args, "--format", "csv", "--quiet"])
    assert as_csv.exit_code == 0, as_csv.stderr
    header = as_csv.stdout.splitlines()[0].split(",")
    assert set(CONTRACT_KEYS) <= set(header), set(CONTRACT_KEYS) - set(header)
    frame = pd.read_csv(io.StringIO(as_csv.stdout))
    assert len(frame) == 1
    assert frame.loc[0, "rmse_rot_deg"] == pytest.approx(record["rmse_rot_deg"], rel=1e-9)
    # the JSON and the CSV name the same fields in the same order (command_time_s excepted)
    assert [k for k in record if k != "command_time_s"] == [k for k in header if k != "command_time_s"]


def test_inverse_json_summary_keys():
    """inverse is not a run of a tracking method: its JSON is a summary of the torque history."""
    result = invoke(["inverse", "--format", "json"])
    assert result.exit_code == 0
    record = json.loads(result.stdout)
    assert {"command", "kinematics", "runtime_s", "fdbench_version"} <= set(record)
    assert record["command"] == "inverse" and record["samples"] == 1001


# ---- a run that does not reach t = 1 s is still a result ----------------------------------------

def test_run_that_stops_early_exits_zero_with_status(tmp_path):
    torque = tmp_path / "strong.csv"
    torque.write_text("t,torque\n0,200\n1,200\n")
    result = invoke(["simulate", "--torque-file", torque, "--format", "json"])
    assert_no_traceback(result)
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["status"] != "success"
    assert record["t_end"] < 1
    assert record["message"] and "stopped at t" in record["message"]
    # the explanation is repeated on stderr, one warning line
    assert "warning" in result.stderr

    quiet = invoke(["simulate", "--torque-file", torque, "--format", "csv", "--quiet"])
    assert quiet.exit_code == 0 and quiet.stderr == ""
    frame = pd.read_csv(io.StringIO(quiet.stdout))
    assert frame.loc[0, "status"] == record["status"] and frame.loc[0, "t_end"] < 1


# ---- the pipe contract: a reader that goes away ---------------------------------------------

FDBENCH = [sys.executable, "-m", "fdbench.cli"]
LONG_CSV = ["inverse", "-f", "csv", "--sample-dt", "1e-4"]  # 10 001 rows, ~585 kB: more than a pipe holds


def _environment(unbuffered: bool) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    if unbuffered:
        env["PYTHONUNBUFFERED"] = "1"  # as in many containers: Python's text layer writes straight to the pipe
    return env


@pytest.mark.parametrize("unbuffered", [True, False], ids=["unbuffered", "buffered"])
def test_a_reader_that_stops_after_one_line_gets_exit_141_and_no_message(tmp_path, unbuffered):
    """``fdbench inverse -f csv | head -1`` on an output longer than the pipe's buffer: the
    command learns the reader went away while writing, and exits 141 without a word, instead of
    exit 0 with its output cut."""
    proc = subprocess.Popen(FDBENCH + LONG_CSV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path,
                            env=_environment(unbuffered))
    try:
        assert proc.stdout.readline().startswith(b"t,")
        proc.stdout.close()
        err = proc.stderr.read()
        assert proc.wait(timeout=120) == 141
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert err == b""


@pytest.fixture(scope="module")
def small_db(tmp_path_factory):
    db = tmp_path_factory.mktemp("pipe") / "small.sqlite"
    made = CliRunner().invoke(app, ["report", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--no-control",
                                    "--no-beyond", "--seeds", "1", "--budget", "5", "--db", str(db), "-q"])
    assert made.exit_code == 0, made.stderr
    return db


@pytest.mark.parametrize("unbuffered", [True, False], ids=["unbuffered", "buffered"])
@pytest.mark.parametrize("command", ["inverse", "optimize", "report"])
def test_every_command_exits_141_when_its_reader_is_gone(tmp_path, small_db, command, unbuffered):
    """stdout is a pipe whose reader has already gone when the result is written."""
    args = {"inverse": LONG_CSV,
            "optimize": ["optimize", "--torque", "cs", "--opt", "bfgs", "--budget", "5", "-f", "json", "-q"],
            "report": ["report", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--no-control", "--no-beyond",
                       "--seeds", "1", "--budget", "5", "--db", str(small_db), "-f", "csv", "-q"]}[command]
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        done = subprocess.run(FDBENCH + args, stdout=write_end, stderr=subprocess.PIPE, cwd=tmp_path,
                              env=_environment(unbuffered), timeout=120)
    finally:
        os.close(write_end)
    assert done.returncode == 141 and done.stderr == b""
