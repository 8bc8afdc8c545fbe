"""``fdbench muscles``: its CSV's documented columns, one row per sample and muscle; JSON the same
rows; the table for a person; bad input one line and exit 2."""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.models import find_model
from fdbench.multibody.muscle_paths import muscle_geometry

from helpers.cli_checks import assert_one_line_error

runner = CliRunner()
ARM26 = find_model("arm26")
COLUMNS = ["t", "muscle", "length", "fiber_length", "pennation_angle", "normalized_fiber_velocity",
           "active_fiber_force", "passive_fiber_force", "r_shoulder_elev_moment_arm", "r_elbow_flex_moment_arm"]


def invoke(args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def motion(tmp_path_factory):
    """An arm26 motion file of 11 samples over 0.5 s (deg), linear: the derivative estimate's low-pass
    filter and spline keep it to 1e-9."""
    path = tmp_path_factory.mktemp("muscles") / "reach.csv"
    t = np.linspace(0.0, 0.5, 11)
    rows = [f"{s!r},{20 + 40 * s!r},{30 + 80 * s!r}" for s in t.tolist()]
    path.write_text("t,r_shoulder_elev,r_elbow_flex\n" + "\n".join(rows) + "\n")
    return path


@pytest.fixture(scope="module")
def outputs(motion):
    done = {fmt: invoke(["muscles", "--model", "arm26", "--motion", motion, "-f", fmt, "-q"])
            for fmt in ("csv", "json", "table")}
    for result in done.values():
        assert result.exit_code == 0, result.stderr
    return done


def test_the_csv_has_one_row_per_sample_and_muscle_with_the_documented_columns(outputs):
    rows = list(csv.DictReader(io.StringIO(outputs["csv"].stdout)))
    assert list(rows[0]) == COLUMNS
    names = [m.name for m in ARM26.muscles]
    assert len(rows) == 11 * 6 and [r["muscle"] for r in rows] == names * 11
    t = np.array([float(r["t"]) for r in rows]).reshape(11, 6)
    np.testing.assert_allclose(t, np.linspace(0.0, 0.5, 11)[:, None] * np.ones(6), atol=1e-12)
    # the path's length and moment arms at the file's angles
    q = np.radians(np.column_stack([20 + 40 * t[:, 0], 30 + 80 * t[:, 0]]))
    lengths, arms = muscle_geometry(ARM26, q)
    np.testing.assert_allclose(np.array([float(r["length"]) for r in rows]).reshape(11, 6), lengths, rtol=1e-7)
    got_arms = np.array([[float(r[c]) for c in COLUMNS[-2:]] for r in rows]).reshape(11, 6, 2)
    np.testing.assert_allclose(got_arms, arms, rtol=1e-7, atol=1e-10)
    assert "--help" in invoke(["muscles", "--help"]).stdout and all(
        c in " ".join(invoke(["muscles", "--help"]).stdout.split()) for c in COLUMNS[:-2] + ["<coordinate>_moment_arm"])


def test_the_json_holds_the_csv_s_rows(outputs):
    rows = json.loads(outputs["json"].stdout)
    table = list(csv.DictReader(io.StringIO(outputs["csv"].stdout)))
    assert len(rows) == len(table) and list(rows[0]) == COLUMNS
    for ours, theirs in zip(rows, table):
        assert ours["muscle"] == theirs["muscle"]
        assert all(math.isclose(ours[c], float(theirs[c]), rel_tol=0, abs_tol=0) for c in COLUMNS if c != "muscle")


def test_the_table_names_every_muscle(outputs):
    text = outputs["table"].stdout
    assert all(m.name in text for m in ARM26.muscles) and "11 samples" in text


@pytest.mark.parametrize("args, words", [
    (["--model", "forearm"], ["model 'forearm' has no muscles"]),
    ([], ["model 'forearm' has no muscles"]),
    (["--model", "nosuch"], ["--model", "nosuch"]),
    (["--model", "arm26", "--motion", "missing.csv"], ["--motion", "missing.csv"]),
    (["--model", "arm26", "-f", "xml"], ["--format"]),
])
def test_bad_input_is_one_line_and_exit_2(args, words):
    assert_one_line_error(invoke(["muscles", *args]), *words)


def test_a_bad_motion_file_is_one_line_and_exit_2(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("t,r_shoulder_elev\n0,1\n0.1,oops\n")
    assert_one_line_error(invoke(["muscles", "--model", "arm26", "--motion", path]), "--motion")
