"""The report's "Beyond the paper" table: stored and resumed by spec hash, selectable with
--beyond/--no-beyond, its numbers those of the individual commands."""

from __future__ import annotations

import io
import json
import sqlite3

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.controllers.cmc import COMPLIANT_MAX_STEP
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.model_files import to_toml
from fdbench.multibody.motions.named import MinimumJerk
from fdbench.multibody.muscle import MIN_ACTIVATION
from fdbench.multibody.simulation import compliant_step_limits
from fdbench.report.methods import CMC, beyond_methods

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


def test_on_a_model_with_muscles_cmc_joins_the_section_with_the_muscles_table_and_figure(tmp_path):
    """On the forearm with a flexor and an extensor, "Beyond the paper" adds computed muscle control
    and muscle-driven collocation; CMC's row, its muscles' table and the activations figure give what
    ``control --controller cmc`` gives on its own."""
    from fdbench.multibody.model import model_from_dict
    from fdbench.multibody.model_files import to_toml

    from helpers.models import forearm_with_muscles_data

    model = tmp_path / "pin.toml"
    model.write_text(to_toml(model_from_dict(forearm_with_muscles_data(), "pin.toml")))
    db, figures = tmp_path / "runs.sqlite", tmp_path / "figures"
    common = ["--model", model, "--motion", "swing"]
    text = invoke([*SMALL, *common, "--db", db, "--figures", figures, "--output", tmp_path / "report.md"])
    report = (tmp_path / "report.md").read_text()
    alone = json.loads(invoke(["control", *common, "--controller", "cmc", "-f", "json", "--quiet"]))
    cells = json.loads(invoke([*SMALL, *common, "--db", db, "--format", "json"]))["cells"]
    driven = [cell for cell in cells if "muscles" in cell]
    assert [cell["cell"].split(" (")[0] for cell in driven] == [
        "Computed muscle control", "Direct collocation of the muscles", "CS excitations + CMA-ES + ff",
        "CS excitations + BFGS + ff, exact gradient"]
    cmaes, bfgs = driven[2:]  # the optimisations of excitations reach the end; BFGS ends below its start
    assert cmaes["reached_end"] == 1 and bfgs["success_rate"] == 1.0, (cmaes, bfgs)
    cmc = driven[:1]
    assert cmc[0]["rmse_rot_deg_median"] == alone["rmse_rot_deg"]
    assert cmc[0]["muscles"]["effort"] == alone["effort"]
    assert cmc[0]["muscles"]["activation_mean"] == {m: alone[f"{m}_activation_mean"] for m in ("flexor", "extensor")}
    assert 0.0 <= alone["flexor_activation_mean"] <= 1.0 and 0.0 <= alone["extensor_activation_mean"] <= 1.0
    assert "flexor mean a" in report and "extensor mean a" in report
    assert (figures / "activations.png").stat().st_size > 0 and "activations.png" in report
    assert text == ""  # the report went to --output


def test_cmc_takes_rigid_tendons_where_compliant_ones_need_steps_below_its_own(tmp_path):
    """The report's CMC keeps arm26's compliant tendons (their stable RK4 step at the least
    activation, 9.8e-5 s, is above CMC's 5e-5 s) and takes them as rigid, saying why, once stiffer
    tendons (strain 0.01 at one normalised force) would need steps below CMC's."""
    def cmc_of(data, name):
        path = tmp_path / name
        path.write_text(to_toml(model_from_dict(data, name)))
        body = Engine(model_from_dict(data, name))
        z, zd, _ = MinimumJerk(body.model.motions[0], body.joints)(np.zeros(1))
        stiffest = min(compliant_step_limits(body, z[0], zd[0], np.full(body.n_muscles, MIN_ACTIVATION)),
                       key=lambda pair: pair[1])
        found = next(m for m in beyond_methods(**{"model_name": str(path)})[0] if m.key == CMC)
        return found, stiffest

    as_filed, stiff = to_dict(find_model("arm26")), to_dict(find_model("arm26"))
    for entry in stiff["muscles"]:
        entry["tendon_strain"] = 0.01
    kept, limit = cmc_of(as_filed, "arm.toml")
    assert limit[1] > COMPLIANT_MAX_STEP and dict(kept.spec.method_options).get("tendons") is None
    rigid, limit = cmc_of(stiff, "stiff.toml")
    assert limit[1] < COMPLIANT_MAX_STEP and dict(rigid.spec.method_options)["tendons"] == "rigid"
    assert "tendons taken as rigid" in rigid.description and limit[0] in rigid.description


@pytest.mark.parametrize("args, words", [(["--tendons", "rigid"], ["--tendons", "no computed muscle control"]),
                                         (["--model", "arm26", "--tendons", "soft"], ["--tendons", "model, rigid"]),
                                         (["--model", "arm26", "--window", "-1"], ["--window"])])
def test_cmc_s_options_in_a_report_are_checked_before_any_work(tmp_path, args, words):
    """CMC's options are refused in one line, before the database is made: a bad value, or a report
    that runs no CMC (the forearm has no muscles)."""
    db = tmp_path / "runs.sqlite"
    done = runner.invoke(app, ["report", *args, "--db", str(db)])
    assert done.exit_code == 2, done.output
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and all(w in lines[0] for w in words), lines
    assert not db.exists()
