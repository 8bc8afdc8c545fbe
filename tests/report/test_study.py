"""fdbench study: one condition swept over the methods, stored and resumed like a report."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from fdbench.report.paper_methods import Cell
from fdbench.cli import app
from fdbench.study import make_sweep, parse_levels

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def study_frame(*args) -> pd.DataFrame:
    result = invoke("study", *args, "-f", "csv", "-q", "--jobs", 1)
    assert result.exit_code == 0, result.stderr
    return pd.read_csv(io.StringIO(result.stdout))


def sweep(kind, levels, seeds=2, cells=(Cell("cs", "bfgs", True),), **common):
    return make_sweep(kind, levels, seeds, list(cells), True, 80.0, 0.3, 20, {"knots": 11}, {}, 1.0,
                      "I1" if kind == "mismatch" else None, **common)


def test_noise_sweep_has_one_spec_per_seed_and_level_and_pd_runs_once_without_noise():
    s = sweep("noise", (0.0, 0.5), seeds=3)
    assert len(s.specs[("PD + feedforward", 0.0)]) == 1  # without noise every seed is the same run
    assert len(s.specs[("PD + feedforward", 0.5)]) == 3
    assert len(s.specs[("CS + bfgs + ff", 0.5)]) == 3
    assert {spec.noise_deg for spec in s.specs[("CS + bfgs + ff", 0.5)]} == {0.5}
    assert len({spec.hash() for spec in s.all_specs()}) == len(s.all_specs())


def test_mismatch_changes_the_plant_only():
    from fdbench.models import value_of
    from fdbench.run_inputs import nominal, plant

    s = sweep("mismatch", (-10.0, 0.0, 10.0))
    for level in (-10.0, 10.0):
        (spec,) = s.specs[("PD + feedforward", level)]
        assert value_of("forearm", plant(spec), "I1") == pytest.approx(0.04 * (1 + level / 100))
        assert value_of("forearm", nominal(spec), "I1") == pytest.approx(0.04)


def test_zero_mismatch_is_the_plain_run(tmp_path):
    frame = study_frame("mismatch", "--levels", "-20,0", "--torque", "cs", "--opt", "bfgs", "--feedforward",
                        "--budget", 10, "--seeds", 1, "--db", tmp_path / "s.sqlite")
    plain = invoke("control", "-f", "csv", "-q")
    pd_value = pd.read_csv(io.StringIO(plain.stdout))["rmse_rot_deg"][0]
    row = frame[(frame["method"] == "PD + feedforward") & (frame["level"] == 0)]
    assert row["rmse_rot_deg_median"].iloc[0] == pytest.approx(pd_value, rel=1e-12)
    lighter = frame[(frame["method"] == "PD + feedforward") & (frame["level"] == -20)]
    assert lighter["rmse_rot_deg_median"].iloc[0] != pytest.approx(pd_value)
    assert set(frame["unit"]) == {"%"} and set(frame["param"]) == {"I1"}


def test_study_resumes_from_the_store(tmp_path):
    args = ("noise", "--levels", "0,1", "--torque", "cs", "--opt", "bfgs", "--feedforward", "--budget", 10,
            "--seeds", 2, "--db", tmp_path / "s.sqlite")
    first = study_frame(*args)
    again = study_frame(*args)
    columns = [c for c in first.columns if not c.startswith("runtime")]
    pd.testing.assert_frame_equal(first[columns], again[columns])
    assert (first["runs"] == [1, 2, 2, 2]).all()  # PD without noise once; each cell over 2 seeds


@pytest.mark.parametrize("text, kind", [("", "noise"), ("a,b", "noise"), ("-1,0", "noise"), ("0,0", "noise"),
                                        ("-100,0", "mismatch"), ("nan", "noise")])
def test_bad_levels_are_refused(text, kind):
    with pytest.raises(ValueError):
        parse_levels(text, kind)


@pytest.mark.parametrize("args, word", [
    (["noise"], "--levels"),
    (["noise", "--levels", "0,x"], "--levels"),
    (["drift", "--levels", "0,1"], "study"),
    (["mismatch", "--levels", "0,10", "--param", "mass"], "--param"),
    (["noise", "--levels", "0,1", "--noise-deg", "1"], "--noise-deg"),
    (["noise", "--levels", "0,1", "--seeds", "0"], "--seeds"),
    (["noise", "--levels", "0,1", "--no-control", "--torque", "cs", "--opt", "nope"], "--opt"),
    (["noise", "--levels", "0,1", "-o", "s.sqlite", "--db", "s.sqlite"], "database"),
    (["noise", "--levels", "0,1", "--gradient", "exact", "--opt", "cmaes"], "gradient-based"),
])
def test_bad_study_input_is_one_line_exit_2(tmp_path, monkeypatch, args, word):
    monkeypatch.chdir(tmp_path)
    result = invoke("study", *args)
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and word in lines[0], lines
    assert list(tmp_path.iterdir()) == []  # nothing written, no database created


def test_study_figures_have_one_per_indicator(tmp_path):
    result = invoke("study", "noise", "--levels", "0,1", "--torque", "cs", "--opt", "bfgs", "--feedforward",
                    "--budget", 10, "--seeds", 2, "--jobs", 1, "--db", tmp_path / "s.sqlite", "--figures",
                    tmp_path / "figs", "-o", tmp_path / "s.md", "-q")
    assert result.exit_code == 0, result.stderr
    names = sorted(p.name for p in (tmp_path / "figs").iterdir())
    assert names == ["study_noise_rmse_rot_deg.png", "study_noise_rmse_torque_nm.png", "study_noise_runtime_s.png"]
    text = (tmp_path / "s.md").read_text()
    assert "figs/study_noise_rmse_rot_deg.png" in text and "| PD + feedforward |" in text
    assert np.all([(tmp_path / "figs" / n).stat().st_size > 1000 for n in names])


def test_a_study_row_counts_why_its_runs_stopped():
    from fdbench.study import CSV_COLUMNS, csv_rows, markdown, summary

    s = sweep("noise", (0.0, 0.5), seeds=3)
    outcomes = iter([{"status": "singular", "t_end": 0.3, "message": "theta reached +-pi/2"},
                     {"status": "success", "t_end": 1.0, "best_objective": 2.0, "initial_objective": 2.0},
                     {"status": "success", "t_end": 1.0, "best_objective": 1.0, "initial_objective": 2.0}] * 10)
    runs = {spec.hash(): {"record": {"rmse_rot_deg": 1.0, "rmse_torque_nm": 0.1, "runtime_s": 0.1, **next(outcomes)}}
            for spec in s.all_specs()}
    rows = summary(s, runs)
    frame = pd.DataFrame(csv_rows(s, rows), columns=list(CSV_COLUMNS))
    for _, row in frame.iterrows():
        counts = [int(part.split(" ")[0]) for part in row.status.split(", ")]
        assert sum(counts) == row.runs
    cell = frame[(frame.method == "CS + bfgs + ff") & (frame.level == 0.5)].iloc[0]
    assert (cell.successes, cell.reached_end) == (1, 2)
    assert cell.message in ("theta reached +-pi/2", "reached the end with objective 2 deg, not below its initial guess's 2 deg")
    text = markdown(s, rows, {})
    assert "## Runs that did not succeed" in text
    line = next(l for l in text.splitlines() if l.startswith("- CS + bfgs + ff at 0.5 deg"))
    assert "2 of 3 reached the end" in line and "1 singular" in line and "1 ended no better than their start" in line


def test_a_studys_conditions_stand_in_its_settings_and_columns(tmp_path):
    args = ("mismatch", "--param", "I1", "--levels", "0", "--seeds", 1, "--torque", "cs", "--opt", "bfgs",
            "--feedforward", "--budget", 2, "--no-control", "--noise-deg", 0.3, "--plant", "m=1.1",
            "--db", tmp_path / "s.sqlite")
    frame = study_frame(*args)
    assert (frame.plant == "m=1.1").all() and (frame.noise_deg == 0.3).all() and (frame.model == "forearm").all()
    text = invoke("study", *args, "-q", "--jobs", 1).stdout
    assert "| noise | 0.3 deg white Gaussian" in text and "| plant | m=1.1 (the simulated body only)" in text
