"""The report's "Beyond the paper" table: stored and resumed by spec hash, selectable with
--beyond/--no-beyond, its numbers those of the individual commands."""

from __future__ import annotations

import io
import json
import sqlite3

import pandas as pd
from typer.testing import CliRunner

from fdbench.cli import app

runner = CliRunner()
SMALL = ["report", "--no-control", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--seeds", "1",
         "--budget", "5", "--quiet", "--jobs", "1"]


def invoke(args):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.stderr
    return result.stdout


def stored_runs(db) -> int:
    with sqlite3.connect(db) as connection:
        return connection.execute("SELECT COUNT(*) FROM runs").fetchone()[0]


def test_beyond_rows_are_stored_resumed_and_match_the_commands(tmp_path):
    db = tmp_path / "runs.sqlite"
    first = pd.read_csv(io.StringIO(invoke([*SMALL, "--db", db, "--format", "csv"])))
    beyond = first[first["table"] == "beyond"].set_index("torque")
    assert list(beyond.index) == ["computed-torque", "lqr", "collocate"]
    assert not beyond["in_paper"].any() and (beyond["success_rate"] == 1).all()
    assert stored_runs(db) == 4  # the optimisation and the three methods
    again = pd.read_csv(io.StringIO(invoke([*SMALL, "--db", db, "--format", "csv"])))
    assert stored_runs(db) == 4  # nothing run again: the stored runs are reused, runtimes included
    pd.testing.assert_frame_equal(first, again)
    lqr = json.loads(invoke(["control", "--controller", "lqr", "-f", "json"]))
    assert beyond.loc["lqr", "rmse_rot_deg_median"] == lqr["rmse_rot_deg"]
    collocation = json.loads(invoke(["collocate", "-f", "json"]))
    assert beyond.loc["collocate", "rmse_rot_deg_median"] == collocation["rmse_rot_deg"]


def test_no_beyond_leaves_the_section_out(tmp_path):
    db = tmp_path / "runs.sqlite"
    with_section = invoke([*SMALL, "--db", db])
    assert "## Beyond the paper" in with_section
    for name in ("Computed torque", "LQR", "Direct collocation"):
        assert name in with_section
    without = invoke([*SMALL, "--db", db, "--no-beyond"])
    assert "Beyond the paper" not in without and "Table 2" in without
