"""``fdbench report``: the CSV and Markdown reports against the paper's published figures, the
numbers of single ``optimize``/``control`` runs and the stored runs; resuming from the store (also
after SIGKILL); the statistics; and bad usage. Every database lives in tmp_path."""

from __future__ import annotations

import io
import json
import math
import re
import signal
import sqlite3
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import fdbench.report.paper_methods
import fdbench.execution
from fdbench.report.paper_methods import PAPER_CELLS, PAPER_CONTROL, succeeded, summarise
from fdbench.cli import app
from fdbench.report import CSV_COLUMNS
from helpers.processes import GATED_OPTIMIZER, Gate, children, wait_until
from helpers.paths import ROOT

# The paper's published figures, typed in from its text (section 5, Tables 2 and 3):
# (RMSE_rot deg, RMSE_torque N m, runtime s).
PAPER_PD = (0.116, 0.149, 0.075)
PAPER_TABLE2 = {("ann", "cmaes"): (1.250, 0.149, 411.56), ("ann", "bfgs"): (0.310, 0.121, 449.37),
                ("cs", "cmaes"): (0.558, 0.118, 29.03), ("cs", "bfgs"): (0.197, 0.116, 41.59)}
PAPER_TABLE3 = {("ann", "cmaes"): (27.383, 0.366, 2439.15), ("ann", "bfgs"): (2.079, 0.009, 1482.89),
                ("cs", "cmaes"): (1.284, 0.105, 35.53), ("cs", "bfgs"): (0.696, 0.046, 35.67),
                ("pf", "cmaes"): (1.829, 0.012, 24.11), ("pf", "bfgs"): (1.816, 0.095, 17.09)}

INDICATOR_COLUMNS = ["rmse_rot_deg_median", "rmse_rot_deg_iqr", "rmse_torque_nm_median", "rmse_torque_nm_iqr",
                     "runtime_s_median", "runtime_s_iqr", "success_rate"]
PAPER_COLUMNS = ["paper_rmse_rot_deg", "paper_rmse_torque_nm", "paper_runtime_s"]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def invoke(*args, code=0):
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == code, result.stderr
    return result


def read_csv(text: str) -> pd.DataFrame:
    """Parse exactly: pandas >= 3 round-trips floats by default (and deprecates the option)."""
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    return pd.read_csv(io.StringIO(text), **exact)


def db_rows(path: Path, columns="id, spec_hash, seed, created_at, record_json, rmse_rot_deg, rmse_torque_nm"):
    con = sqlite3.connect(path)
    try:
        return con.execute(f"SELECT {columns} FROM runs ORDER BY id").fetchall()
    finally:
        con.close()


def db_count(path: Path) -> int:
    con = sqlite3.connect(path)
    try:
        return con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
    finally:
        con.close()


def stored_values(path: Path, torque, optimizer, feedforward, column="rmse_rot_deg") -> dict:
    """{seed: value} of the stored optimisation runs of one cell, straight from SQLite."""
    out = {}
    for seed, spec_json, value in db_rows(path, f"seed, spec_json, {column}"):
        spec = json.loads(spec_json)
        if (spec["command"], spec["torque"], spec["optimizer"], spec["feedforward"]) == \
                ("optimize", torque, optimizer, feedforward):
            out[seed] = value
    return out


def cell_row(frame: pd.DataFrame, torque, optimizer, feedforward) -> pd.Series:
    match = frame[(frame.torque == torque) & (frame.optimizer == optimizer) & (frame.feedforward == feedforward)]
    assert len(match) == 1
    return match.iloc[0]


def control_row(frame: pd.DataFrame) -> pd.Series:
    match = frame[frame.table.astype(str) == "control"]
    assert len(match) == 1
    return match.iloc[0]


CS_BFGS = ["--torque", "cs", "--opt", "bfgs"]


# ----------------------------------------------------------------------------- CSV


def test_csv_report_one_row_per_cell_with_the_papers_values(tmp_path):
    db = tmp_path / "r.sqlite"
    result = invoke("report", "--no-beyond", "--db", db, *CS_BFGS, "--seeds", 2, "--budget", 15, "--jobs", 1, "--format", "csv", "-q")
    assert result.stdout.splitlines()[0] == ",".join(CSV_COLUMNS)
    frame = read_csv(result.stdout)
    assert list(frame.columns) == list(CSV_COLUMNS)
    assert len(frame) == 3  # PD control, CS + BFGS without and with feedforward
    for column in INDICATOR_COLUMNS + PAPER_COLUMNS + ["speedup_vs_paper", "dt"]:
        assert pd.api.types.is_float_dtype(frame[column]), column
    assert np.isfinite(frame[INDICATOR_COLUMNS + PAPER_COLUMNS + ["speedup_vs_paper"]].to_numpy()).all()
    assert (frame.rmse_rot_deg_median > 0).all() and (frame.rmse_torque_nm_median > 0).all()
    assert (frame.runtime_s_median > 0).all()
    assert ((frame.success_rate >= 0) & (frame.success_rate <= 1)).all()
    assert (frame.in_paper == True).all()  # noqa: E712
    assert (frame.kinematics == "paper").all() and (frame.integrator == "rk4").all() and (frame.dt == 1e-3).all()

    control = control_row(frame)
    assert (control.runs, control.seeds) == (1, 1)
    assert (control.paper_rmse_rot_deg, control.paper_rmse_torque_nm, control.paper_runtime_s) == PAPER_PD
    assert PAPER_CONTROL == PAPER_PD
    assert control.rmse_rot_deg_iqr == 0 and control.runtime_s_iqr == 0

    for feedforward, table, paper in ((False, 2, PAPER_TABLE2), (True, 3, PAPER_TABLE3)):
        row = cell_row(frame, "cs", "bfgs", feedforward)
        assert str(row.table) == str(table)
        assert (row.runs, row.seeds, row.budget) == (2, 2, 15)
        published = (row.paper_rmse_rot_deg, row.paper_rmse_torque_nm, row.paper_runtime_s)
        assert published == paper[("cs", "bfgs")] == PAPER_CELLS[("cs", "bfgs", feedforward)]
        assert row.speedup_vs_paper == pytest.approx(row.paper_runtime_s / row.runtime_s_median, rel=1e-12)
        # medians and IQRs are those of the stored runs of the cell
        for name in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"):
            values = list(stored_values(db, "cs", "bfgs", feedforward, name).values())
            assert len(values) == 2
            q1, q3 = np.percentile(values, [25, 75])
            assert row[f"{name}_median"] == pytest.approx(statistics.median(values), rel=1e-12, abs=1e-15)
            assert row[f"{name}_iqr"] == pytest.approx(q3 - q1, rel=1e-12, abs=1e-15)
    assert db_count(db) == 5


def test_every_paper_cell_of_the_default_matrix_carries_its_published_figures():
    from fdbench.report.paper_methods import default_cells

    cells = default_cells()
    assert {c.key for c in cells} == {(t, o, False) for t, o in PAPER_TABLE2} | {(t, o, True) for t, o in PAPER_TABLE3}
    for cell in cells:
        assert cell.paper == (PAPER_TABLE3 if cell.feedforward else PAPER_TABLE2)[(cell.torque, cell.optimizer)]


def test_cell_outside_the_paper_has_no_paper_values(tmp_path):
    db = tmp_path / "pf.sqlite"
    args = ["report", "--no-beyond", "--db", db, "--torque", "pf", "--opt", "bfgs", "--no-feedforward", "--no-control", "--seeds", 1,
            "--budget", 10, "--jobs", 1, "-q"]
    frame = read_csv(invoke(*args, "--format", "csv").stdout)
    assert len(frame) == 1
    row = frame.iloc[0]
    assert (row.torque, row.optimizer, bool(row.feedforward), bool(row.in_paper)) == ("pf", "bfgs", False, False)
    assert all(math.isnan(row[c]) for c in PAPER_COLUMNS + ["speedup_vs_paper"])
    (cell,) = json.loads(invoke(*args, "--format", "json").stdout)["cells"]  # no PD control, no Table 3
    assert (cell["table"], cell["in_paper"], cell["paper_rmse_rot_deg"]) == (2, False, None)
    assert {v["verdict"] for v in cell["vs_paper"].values()} == {None}
    text = invoke(*args, "--format", "md").stdout  # the star, and what it means
    assert _table_line(_section(text, "## Table 2"), "PF (4 terms) + BFGS quasi-Newton*")
    assert "Cells marked * are not in the paper." in text


# ----------------------------------------------------------------------------- Markdown


def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n## ", start + 1)
    return text[start:] if end < 0 else text[start:end]


def _table_line(section: str, name: str) -> list[str]:
    lines = [line for line in section.splitlines() if line.startswith(f"| {name} ")]
    assert len(lines) == 1, section
    return [cell.strip() for cell in lines[0].strip("|").split("|")]


def test_markdown_sections_tables_and_figures(tmp_path):
    db = tmp_path / "md.sqlite"
    out = tmp_path / "out" / "report.md"
    out.parent.mkdir()
    figures = tmp_path / "figs"
    result = invoke("report", "--no-beyond", "--db", db, *CS_BFGS, "--seeds", 2, "--budget", 15, "--jobs", 1,
                    "--figures", figures, "--output", out, "-q")
    assert result.stdout == ""
    text = out.read_text()
    headings = [line for line in text.splitlines() if line.startswith("## ")]
    expected = ["## Settings", "## Inverse dynamics", "## PD control", "## Table 2", "## Table 3", "## Comparison",
                "## Where we differ from the paper, and why", "## When and where the runs were made", "## Figures"]
    assert [next(h for h in headings if h.startswith(e)) for e in expected] == \
        [h for h in headings if any(h.startswith(e) for e in expected)]
    assert len(headings) == len(expected)

    report = json.loads(invoke("report", "--no-beyond", "--db", db, *CS_BFGS, "--seeds", 2, "--budget", 15, "--jobs", 1,
                               "-f", "json", "-q").stdout)
    assert [(c["table"], c["budget"], c["runs"], c["kinematics"]) for c in report["cells"]] == \
        [("control", None, 1, "paper"), (2, 15, 2, "paper"), (3, 15, 2, "paper")]

    pd_section = _section(text, "## PD control")
    assert "Kp = 80.0" in pd_section and "Kd = 0.3" in pd_section
    header_line = next(line for line in pd_section.splitlines() if line.startswith("| method |"))
    header = [c.strip() for c in header_line.strip("|").split("|")]
    assert header[:3] == ["method", "RMSE_rot (deg)", "paper"] and header.count("paper") == 3
    pd_cells = _table_line(pd_section, "PD control + feedforward")
    assert (pd_cells[2], pd_cells[5]) == ("0.116", "0.149")

    for heading, paper in (("## Table 2", PAPER_TABLE2), ("## Table 3", PAPER_TABLE3)):
        section = _section(text, heading)
        assert "| method | RMSE_rot (deg) | paper |" in section and "success |" in section
        cells = _table_line(section, "CS (11 points) + BFGS quasi-Newton")
        rot, torque, runtime = paper[("cs", "bfgs")]
        assert (cells[2], cells[5], cells[8]) == (f"{rot:.3f}", f"{torque:.3f}", f"{runtime:.2f}")
        # BFGS from a fixed start: both seeds give the same run, shown once (no "± 0.000")
        assert cells[-1] == "2/2, identical"
        assert "±" not in cells[1] and "±" not in cells[4] and "±" in cells[7]  # runtimes still vary

    facts = report["comparison"]
    assert facts["rows"] == 3 and facts["most_accurate"]["name"] in _section(text, "## Comparison")
    assert facts["fastest"]["name"] in _section(text, "## Comparison")
    assert facts["best_per_table"].keys() == {"2", "3"} and facts["vs_paper_rmse_rot"] is not None

    # one link per figure, each to a non-empty PNG, relative to the report's directory
    links = re.findall(r"!\[([^\]]+)\]\(([^)]+)\)", _section(text, "## Figures"))
    assert len(links) == 5
    linked = set()
    for _, target in links:
        path = (out.parent / target).resolve()
        assert not Path(target).is_absolute()
        assert path.parent == figures.resolve()
        assert path.stat().st_size > 1000 and path.read_bytes()[:8] == PNG_MAGIC
        linked.add(path.name)
    assert linked == {p.name for p in figures.iterdir()} == {
        "figure2_inverse_dynamics.png", "figure5_tracking.png", "figure6_tracking.png",
        "convergence_table2.png", "convergence_table3.png"}

    # the same runs, Table 2 only: no Table 3 section, nothing computed
    text2 = invoke("report", "--no-beyond", "--db", db, *CS_BFGS, "--seeds", 2, "--budget", 15, "--jobs", 1,
                   "--no-feedforward", "--no-control", "-q").stdout
    assert "## Table 2" in text2 and "## Table 3" not in text2 and "## PD control" not in text2
    assert "## Figures" not in text2
    assert db_count(db) == 5


def test_markdown_shows_the_published_pd_runtime(tmp_path):
    text = invoke("report", "--db", tmp_path / "pd.sqlite", *CS_BFGS, "--no-feedforward", "--seeds", 1,
                  "--budget", 5, "--jobs", 1, "-q").stdout
    cells = _table_line(_section(text, "## PD control"), "PD control + feedforward")
    assert float(cells[8]) == PAPER_PD[2]


def test_figures_without_output_are_linked_relative_to_the_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = invoke("report", "--db", "fig.sqlite", *CS_BFGS, "--no-feedforward", "--no-control", "--seeds", 1,
                  "--budget", 5, "--jobs", 1, "--figures", "figs", "-q").stdout
    links = re.findall(r"!\[[^\]]+\]\(([^)]+)\)", text)
    assert links and all((tmp_path / link).is_file() and (tmp_path / link).stat().st_size > 0 for link in links)
    assert all(Path(link).parts[0] == "figs" for link in links)


# ----------------------------------------------------------------------------- resume and --rerun


def test_resume_computes_nothing_and_rerun_recomputes(tmp_path, monkeypatch):
    db = tmp_path / "resume.sqlite"
    args = ["report", "--no-beyond", "--db", db, *CS_BFGS, "--seeds", 2, "--budget", 15, "--jobs", 2, "--format", "csv", "-q"]
    first = invoke(*args).stdout
    before = db_rows(db)
    assert len(before) == 5 and len({r[1] for r in before}) == 5

    def no_work(spec):
        raise AssertionError(f"run {spec.hash()} recomputed")

    monkeypatch.setattr(fdbench.execution, "run_spec", no_work)
    second = invoke(*args).stdout
    assert second == first
    assert db_rows(db) == before  # same ids, timestamps and records

    monkeypatch.undo()
    third = invoke(*args, "--rerun").stdout
    after = db_rows(db)
    assert len(after) == 5
    assert {r[1] for r in after} == {r[1] for r in before}
    assert min(r[0] for r in after) > max(r[0] for r in before)  # every row replaced
    frames = read_csv(first), read_csv(third)
    for column in ("rmse_rot_deg_median", "rmse_rot_deg_iqr", "rmse_torque_nm_median", "success_rate"):
        assert frames[1][column].tolist() == frames[0][column].tolist()  # deterministic runs, same numbers


# ----------------------------------------------------------------------------- agreement with single runs


def _json_run(*args) -> dict:
    return json.loads(invoke(*args, "--format", "json", "-q").stdout)


def test_report_numbers_equal_single_optimize_and_control_runs(tmp_path):
    db = tmp_path / "same.sqlite"
    frame = read_csv(invoke("report", "--db", db, *CS_BFGS, "--no-feedforward", "--seeds", 2, "--budget", 15,
                            "--jobs", 2, "--format", "csv", "-q").stdout)
    alone = [_json_run("optimize", *CS_BFGS, "--seed", s, "--budget", 15) for s in (0, 1)]
    pd_alone = _json_run("control")
    for run in alone:
        assert run["status"] == "success" and run["budget"] == 15

    # each stored run equals the run made alone with its seed (worker processes change nothing)
    stored = stored_values(db, "cs", "bfgs", False)
    stored_torque = stored_values(db, "cs", "bfgs", False, "rmse_torque_nm")
    for seed, run in enumerate(alone):
        assert stored[seed] == run["rmse_rot_deg"]
        assert stored_torque[seed] == run["rmse_torque_nm"]

    row = cell_row(frame, "cs", "bfgs", False)
    assert row.rmse_rot_deg_median == pytest.approx(statistics.median(r["rmse_rot_deg"] for r in alone), rel=1e-12)
    assert row.rmse_torque_nm_median == pytest.approx(statistics.median(r["rmse_torque_nm"] for r in alone), rel=1e-12)
    control = control_row(frame)
    assert control.rmse_rot_deg_median == pd_alone["rmse_rot_deg"]
    assert control.rmse_torque_nm_median == pd_alone["rmse_torque_nm"]


def test_one_seed_cell_median_is_the_single_run(tmp_path):
    frame = read_csv(invoke("report", "--db", tmp_path / "one.sqlite", *CS_BFGS, "--feedforward", "--no-control",
                            "--seeds", 1, "--budget", 15, "--jobs", 1, "--format", "csv", "-q").stdout)
    alone = _json_run("optimize", *CS_BFGS, "--feedforward", "--seed", 0, "--budget", 15)
    row = cell_row(frame, "cs", "bfgs", True)
    assert row.rmse_rot_deg_median == alone["rmse_rot_deg"]
    assert row.rmse_torque_nm_median == alone["rmse_torque_nm"]
    assert row.rmse_rot_deg_iqr == 0 and row.runs == 1


def test_runs_stored_by_optimize_and_control_are_reused_by_report(tmp_path, monkeypatch):
    db = tmp_path / "shared.sqlite"
    single = _json_run("optimize", *CS_BFGS, "--seed", 0, "--budget", 15, "--db", db)
    _json_run("control", "--db", db)
    assert db_count(db) == 2

    def no_work(spec):
        raise AssertionError(f"run {spec.hash()} recomputed")

    monkeypatch.setattr(fdbench.execution, "run_spec", no_work)
    frame = read_csv(invoke("report", "--no-beyond", "--db", db, *CS_BFGS, "--no-feedforward", "--seeds", 1, "--budget", 15,
                            "--format", "csv", "-q").stdout)
    assert db_count(db) == 2
    assert cell_row(frame, "cs", "bfgs", False).rmse_rot_deg_median == single["rmse_rot_deg"]


def test_seeded_cell_statistics_across_seeds(tmp_path):
    # CMA-ES depends on its seed, so the median and IQR over seeds are not trivial
    db = tmp_path / "cma.sqlite"
    frame = read_csv(invoke("report", "--no-beyond", "--db", db, "--torque", "cs", "--opt", "cmaes", "--no-feedforward",
                            "--no-control", "--seeds", 3, "--budget", 12, "--jobs", 1, "--format", "csv", "-q").stdout)
    values = stored_values(db, "cs", "cmaes", False)
    assert sorted(values) == [0, 1, 2]
    assert len(set(values.values())) > 1
    row = cell_row(frame, "cs", "cmaes", False)
    q1, q3 = np.percentile(list(values.values()), [25, 75])
    assert row.rmse_rot_deg_median == statistics.median(values.values())
    assert row.rmse_rot_deg_iqr == pytest.approx(q3 - q1, rel=1e-12)
    assert row.rmse_rot_deg_iqr > 0
    alone = _json_run("optimize", "--torque", "cs", "--opt", "cmaes", "--seed", 2, "--budget", 12)
    assert values[2] == alone["rmse_rot_deg"]


# ----------------------------------------------------------------------------- SIGKILL and resume


def _count_or_zero(db: Path) -> int:
    if not db.exists():
        return 0
    try:
        con = sqlite3.connect(db, timeout=5)
        try:
            return con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        finally:
            con.close()
    except sqlite3.OperationalError:  # the table is not created yet
        return 0


def _gated_sweep(db: Path, seeds: int, jobs: int) -> list[str]:
    """A report of one cell whose runs from seed 2 on wait for the test's gate (see processes.py)."""
    return [sys.executable, "-m", "fdbench.cli", "report", "--no-beyond", "--db", str(db), "--torque", "cs",
            "--opt", GATED_OPTIMIZER, "--no-feedforward", "--no-control", "--seeds", str(seeds), "--budget", "60",
            "--jobs", str(jobs), "--format", "csv"]


def test_sigkill_then_resume_stores_each_run_once(tmp_path):
    db, seeds, gate = tmp_path / "killed.sqlite", 6, Gate(tmp_path, from_seed=2)
    cmd = _gated_sweep(db, seeds, jobs=1) + ["-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=tmp_path, env=gate.env)
    try:
        wait_until(lambda: _count_or_zero(db) == 2, "seeds 0 and 1 were stored", proc)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    before = db_rows(db)
    assert sorted(r[2] for r in before) == [0, 1]  # killed while seed 2 was running
    max_id = max(r[0] for r in before)

    gate.open()
    out = tmp_path / "report.csv"
    done = subprocess.run(cmd + ["--output", str(out)], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env=gate.env)
    assert done.returncode == 0, done.stderr
    after = db_rows(db)
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    con.close()
    assert len(after) == len({r[1] for r in after}) == seeds
    assert sorted(r[2] for r in after) == list(range(seeds))
    new = [r for r in after if r[0] > max_id]
    assert len(before) + len(new) == seeds  # only the missing runs were computed
    assert [r for r in after if r[0] <= max_id] == before  # the runs stored before the kill are untouched
    frame = read_csv(out.read_text())
    assert len(frame) == 1 and frame.iloc[0].runs == seeds


def test_ctrl_c_stops_with_130_and_keeps_every_stored_run(tmp_path):
    db, seeds, gate = tmp_path / "interrupted.sqlite", 6, Gate(tmp_path, from_seed=2)
    cmd = _gated_sweep(db, seeds, jobs=2)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            env=gate.env)
    try:  # Ctrl-C with seeds 0 and 1 stored and both workers inside a run of a later seed
        wait_until(lambda: _count_or_zero(db) == 2 and len(children(proc.pid)) >= 2,
                   "seeds 0 and 1 were stored with the workers running", proc)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130
    assert stdout == "" and stderr.strip().splitlines()[-1] == "fdbench: error: interrupted"
    assert "Traceback" not in stderr
    kept = db_rows(db)
    assert sorted(r[2] for r in kept) == [0, 1]
    gate.open()
    done = subprocess.run(cmd + ["-q"], capture_output=True, text=True, timeout=300, cwd=tmp_path, env=gate.env)
    assert done.returncode == 0, done.stderr
    after = db_rows(db)
    assert len(after) == len({r[1] for r in after}) == seeds
    assert [r for r in after if r[0] <= max(r[0] for r in kept)] == kept  # nothing stored was lost or redone


# ----------------------------------------------------------------------------- summarise


def _records(values, **extra):
    return [dict({"rmse_rot_deg": v, "rmse_torque_nm": v, "runtime_s": v, "status": "success"}, **extra)
            for v in values]


def test_summarise_median_and_iqr_by_hand_and_numpy():
    # [1, 2, 3, 4]: median 2.5; quartiles by linear interpolation 1.75 and 3.25, IQR 1.5
    s = summarise(_records([4.0, 1.0, 3.0, 2.0]))
    assert s["runs"] == 4
    for name in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"):
        assert s[f"{name}_median"] == 2.5 and s[f"{name}_iqr"] == 1.5
    s = summarise(_records([3.0, 1.0, 2.0]))
    assert (s["rmse_rot_deg_median"], s["rmse_rot_deg_iqr"]) == (2.0, 1.0)
    s = summarise(_records([0.7]))
    assert (s["rmse_rot_deg_median"], s["rmse_rot_deg_iqr"]) == (0.7, 0.0)
    rng = np.random.default_rng(7)
    for n in (2, 5, 10, 11):
        values = rng.lognormal(size=n)
        s = summarise(_records(values.tolist()))
        assert s["rmse_rot_deg_median"] == pytest.approx(np.median(values), rel=1e-15)
        assert s["rmse_rot_deg_iqr"] == pytest.approx(np.subtract(*np.percentile(values, [75, 25])), rel=1e-12)


def test_summarise_ignores_missing_and_non_finite_values():
    s = summarise(_records([1.0, None, 3.0, float("nan"), float("inf")]))
    assert s["runs"] == 5
    assert s["rmse_rot_deg_median"] == 2.0 and s["rmse_rot_deg_iqr"] == 1.0
    s = summarise(_records([None, None]))
    assert math.isnan(s["rmse_rot_deg_median"]) and math.isnan(s["rmse_rot_deg_iqr"])
    s = summarise([])
    assert s["runs"] == 0 and math.isnan(s["success_rate"])


def test_success_rate_counts_successful_runs_that_beat_the_initial_guess():
    records = [
        {"status": "success", "best_objective": 1.0, "initial_objective": 2.0},  # yes
        {"status": "success", "best_objective": 0.5, "initial_objective": 0.6},  # yes
        {"status": "success", "best_objective": 2.0, "initial_objective": 2.0},  # no improvement
        {"status": "success", "best_objective": 3.0, "initial_objective": 2.0},  # worse
        {"status": "penalty", "best_objective": 1.0, "initial_objective": 2.0},  # did not reach t = 1 s
        {"status": "solver", "best_objective": 1.0, "initial_objective": 2.0},
        {"status": None, "best_objective": 1.0, "initial_objective": 2.0},
        {"status": "success"},  # a control run: nothing to beat
    ]
    expected = [True, True, False, False, False, False, False, True]
    assert [succeeded(r) for r in records] == expected
    assert summarise(records)["success_rate"] == 3 / 8
    assert summarise(records[:2])["success_rate"] == 1.0
    assert summarise(records[2:7])["success_rate"] == 0.0


# ----------------------------------------------------------------------------- bad usage


BAD = {
    "seeds-0": (["--seeds", "0"], "--seeds"),
    "seeds-negative": (["--seeds", "-3"], "--seeds"),
    "jobs-0": (["--jobs", "0"], "--jobs"),
    "unknown-torque": (["--torque", "spline"], "--torque"),
    "unknown-opt": (["--opt", "adam"], "--opt"),
    "format-xml": (["--format", "xml"], "--format"),
    "budget-0": (["--budget", "0"], "--budget"),
    "figures-missing-parent": (["--figures", "{tmp}/missing/figs"], "--figures"),
    "output-missing-parent": (["--output", "{tmp}/missing/report.md"], "--output"),
    "db-missing-parent": (["--db", "{tmp}/missing/r.sqlite"], "--db"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_usage_exits_2_with_one_line(tmp_path, case, monkeypatch):
    monkeypatch.chdir(tmp_path)
    extra, option = BAD[case]
    extra = [a.replace("{tmp}", str(tmp_path)) for a in extra]
    args = ["report", *CS_BFGS, "--seeds", "1", "--budget", "5", "--jobs", "1", "-q"]
    if "--db" not in extra:
        args += ["--db", str(tmp_path / "bad.sqlite")]
    result = CliRunner().invoke(app, args + extra)
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error: ")
    assert option in lines[0]
    assert result.stdout == ""
    assert list(tmp_path.iterdir()) == []  # nothing created: no database, no report, no figures


# ----------------------------------------------------------------------------- judging against the paper

from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from fdbench.report import SAME_FACTOR, Row, first_reached, judgement  # noqa: E402

positive = st.floats(min_value=1e-6, max_value=1e4, allow_nan=False, allow_infinity=False)


@given(positive, positive)
def test_judgement_says_same_within_the_factor_and_otherwise_how_many_times(ours, paper):
    j = judgement(ours, paper)
    ratio = ours / paper
    if 1 / SAME_FACTOR <= ratio <= SAME_FACTOR:
        assert j["verdict"] == "same" and j["factor"] == pytest.approx(ratio)
    elif ratio < 1:
        assert j["verdict"] == "lower" and j["factor"] == pytest.approx(paper / ours) and j["factor"] > SAME_FACTOR
    else:
        assert j["verdict"] == "higher" and j["factor"] == pytest.approx(ratio) and j["factor"] > SAME_FACTOR
    # swapping ours and the paper's swaps lower and higher, by the same factor
    swapped = judgement(paper, ours)
    flip = {"same": "same", "lower": "higher", "higher": "lower"}
    assert swapped["verdict"] == flip[j["verdict"]]
    if j["verdict"] != "same":
        assert swapped["factor"] == pytest.approx(j["factor"])


@given(st.lists(positive, min_size=2, max_size=8), st.floats(min_value=0, max_value=1))
def test_a_paper_figure_within_the_range_of_our_runs_is_reproduced(runs, where):
    paper = min(max(runs), min(runs) + where * (max(runs) - min(runs)))  # rounding must not leave the range
    assert judgement(float(np.median(runs)), paper, runs)["verdict"] == "same"


def test_judgement_without_a_paper_figure_is_none():
    assert judgement(0.5, None)["verdict"] is None and judgement(None, 0.5)["verdict"] is None
    assert judgement(float("nan"), 0.5)["verdict"] is None


@given(st.lists(st.floats(min_value=0.01, max_value=10), min_size=1, max_size=50), positive)
def test_first_reached_is_the_first_evaluation_at_or_below_the_level(values, level):
    history = list(np.minimum.accumulate(values))
    n = first_reached(history, level)
    if n is None:
        assert min(history) > level
    else:
        assert history[n - 1] <= level and all(v > level for v in history[: n - 1])


def _row(records):
    return Row("m", 2, None, summarise(records), (1.0, 1.0, 1.0), records)


def test_identical_runs_are_detected_from_the_data():
    same = {"rmse_rot_deg": 0.5, "rmse_torque_nm": 0.1, "best_objective": 0.5, "t_end": 1.0, "status": "success"}
    assert _row([dict(same, runtime_s=t) for t in (0.1, 0.2, 0.3)]).identical  # runtimes may differ
    assert not _row([same]).identical  # one run: nothing to compare
    assert not _row([same, dict(same, rmse_rot_deg=0.5000001)]).identical  # seeds that matter


def _numbers_of_column(section_text: str, column: int) -> list[str]:
    lines = [line for line in section_text.splitlines() if line.startswith("| ") and not line.startswith("| method")]
    return [[c.strip() for c in line.strip("|").split("|")][column] for line in lines]


def test_each_column_has_one_number_format_and_stochastic_cells_keep_their_spread(tmp_path):
    text = invoke("report", "--db", tmp_path / "fmt.sqlite", "--torque", "cs", "--seeds", 3, "--budget", 12,
                  "--jobs", 1, "-q").stdout
    one = r"(\d+\.\d{3}|< 0\.001)"
    for heading in ("## Table 2", "## Table 3"):
        section = _section(text, heading)
        for column in (1, 4, 7):  # RMSE_rot, RMSE_torque, runtime
            for cell in _numbers_of_column(section, column):
                assert re.fullmatch(f"{one}( ± {one})?", cell), (heading, column, cell)
        cma = _table_line(section, "CS (11 points) + CMA-ES")
        assert "±" in cma[1] and "identical" not in cma[-1]  # CMA-ES depends on its seed
        bfgs = _table_line(section, "CS (11 points) + BFGS quasi-Newton")
        assert "±" not in bfgs[1] and bfgs[-1].endswith("identical")


def test_vs_paper_column_agrees_with_the_published_figures(tmp_path):
    db = tmp_path / "vs.sqlite"
    text = invoke("report", "--db", db, *CS_BFGS, "--seeds", 1, "--budget", 200, "--jobs", 1, "-q").stdout
    for heading, paper, feedforward in (("## Table 2", PAPER_TABLE2, False), ("## Table 3", PAPER_TABLE3, True)):
        cells = _table_line(_section(text, heading), "CS (11 points) + BFGS quasi-Newton")
        ours = stored_values(db, "cs", "bfgs", feedforward)[0]
        published = paper[("cs", "bfgs")][0]
        found = re.fullmatch(r"([\d.]+)× (lower|higher)|≈ \(×([\d.]+)\)", cells[3])
        assert found, cells[3]
        if found[3]:
            assert abs(ours / published - 1) <= 0.25 and float(found[3]) == pytest.approx(ours / published, abs=0.01)
        else:
            factor = published / ours if found[2] == "lower" else ours / published
            assert (ours < published) == (found[2] == "lower")
            assert float(found[1]) == pytest.approx(factor, rel=0.05)


# ----------------------------------------------------------------------------- where we differ, provenance


def _stored_history(db: Path, torque, optimizer, feedforward, seed=0) -> list:
    for spec_json, history in db_rows(db, "spec_json, history_json"):
        spec = json.loads(spec_json)
        if (spec["command"], spec["torque"], spec["optimizer"], spec["feedforward"], spec["seed"]) == \
                ("optimize", torque, optimizer, feedforward, seed):
            return json.loads(history)
    raise AssertionError("no such run")


def test_differences_name_when_each_run_passed_the_papers_figure(tmp_path):
    db = tmp_path / "differ.sqlite"
    text = invoke("report", "--db", db, *CS_BFGS, "--seeds", 1, "--budget", 200, "--jobs", 1, "-q").stdout
    differ = _section(text, "## Where we differ from the paper, and why")
    for feedforward, table, paper in ((False, 2, PAPER_TABLE2), (True, 3, PAPER_TABLE3)):
        history = _stored_history(db, "cs", "bfgs", feedforward)
        level = paper[("cs", "bfgs")][0]
        first = next(i for i, v in enumerate(history, start=1) if v <= level)
        line = next(l for l in differ.splitlines() if l.startswith("- **CS (11 points) + BFGS") and f"(Table {table})" in l)
        assert f"after {first} of 200 evaluations" in line
    assert "Not explained:" in differ and "the commands that show it" in differ

    short = invoke("report", "--db", db, *CS_BFGS, "--no-feedforward", "--no-control", "--seeds", 1, "--budget", 15,
                   "--jobs", 1, "-q").stdout
    rows = [json.loads(h) for s, h in db_rows(db, "spec_json, history_json") if json.loads(s).get("budget") == 15]
    assert len(rows) == 1 and min(rows[0]) > PAPER_TABLE2[("cs", "bfgs")][0]
    assert "No run reaches the paper's figure within 15 evaluations." in short
    assert "these runs differ (budget 15)" in short and "Not explained:" not in short


def test_the_report_says_when_and_where_its_runs_were_made(tmp_path):
    db = tmp_path / "when.sqlite"
    args = ["report", "--db", db, *CS_BFGS, "--no-feedforward", "--seeds", 2, "--budget", 5, "--jobs", 1, "--no-beyond",
            "-q"]
    made = [m for cell in json.loads(invoke(*args, "-f", "json").stdout)["cells"] for m in cell["made"]]
    rows = db_rows(db, "id, created_at, machine, jobs")
    assert sorted((m["id"], m["created_at"], m["machine"], m["jobs"]) for m in made) == sorted(rows)
    assert len({r[2] for r in rows}) == 1 and {r[3] for r in rows} == {1}
    text = _section(invoke(*args).stdout, "## When and where the runs were made")
    assert rows[0][2] in text and "--rerun" in text  # where, and how to refresh them
    # runs from another machine: a table, one line per cell and session
    con = sqlite3.connect(db)
    con.execute("UPDATE runs SET machine = 'elsewhere', created_at = '2020-01-02T03:04:05+00:00' WHERE seed = 1")
    con.commit()
    con.close()
    made = _section(invoke(*args).stdout, "## When and where the runs were made")
    assert "several sessions" in made
    assert "| CS (11 points) + BFGS quasi-Newton | 2 | 1 | 2020-01-02 03:04 | elsewhere | 1 |" in made


def test_first_report_in_a_folder_says_it_creates_the_database(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("FDBENCH_DB", raising=False)
    args = ["report", *CS_BFGS, "--no-feedforward", "--no-control", "--seeds", 1, "--budget", 5, "--jobs", 1,
            "--format", "csv"]
    first = invoke(*args)
    assert first.stderr.splitlines().count(
        "creating results database fdbench-results.sqlite (choose another with --db or $FDBENCH_DB)") == 1
    assert (tmp_path / "fdbench-results.sqlite").is_file()
    assert "creating" not in invoke(*args).stderr  # only the first time
    quiet = invoke("report", "--db", tmp_path / "other.sqlite", *args[1:], "-q")
    assert quiet.stderr == "" and (tmp_path / "other.sqlite").is_file()
    named = invoke("report", "--db", tmp_path / "named.sqlite", *args[1:])
    assert f"creating results database {tmp_path / 'named.sqlite'}\n" in named.stderr


# ----------------------------------------------------------------------------- JSON


def test_json_report_has_the_cells_of_the_csv_and_the_ids_of_their_runs(tmp_path):
    db = tmp_path / "json.sqlite"
    common = ["report", "--db", db, "--torque", "cs", "--seeds", 2, "--budget", 12, "--jobs", 1, "--no-beyond", "-q"]
    csv_frame = read_csv(invoke(*common, "--format", "csv").stdout)
    result = subprocess.run([sys.executable, "-m", "fdbench.cli", *map(str, common), "-f", "json"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout, parse_constant=lambda c: pytest.fail(f"non-standard JSON {c}"))
    assert report["command"] == "report" and report["settings"]["kinematics"] == "paper"
    cells = report["cells"]
    assert len(cells) == len(csv_frame) == 5
    ids = {spec_hash: row_id for row_id, spec_hash, *_ in db_rows(db)}
    for cell, (_, row) in zip(cells, csv_frame.iterrows()):
        assert cell["cell"] == row.cell
        for column in INDICATOR_COLUMNS:
            assert cell[column] == pytest.approx(row[column], rel=1e-12, abs=1e-15)
        assert cell["run_ids"] == [ids[h] for h in cell["spec_hashes"]]
        assert len(cell["run_ids"]) == cell["runs"]
        assert cell["successes"] == round(cell["success_rate"] * cell["runs"])
        assert cell["identical"] == (cell["optimizer"] == "bfgs")
        ratio = cell["rmse_rot_deg_median"] / cell["paper_rmse_rot_deg"]
        verdict = cell["vs_paper"]["rmse_rot_deg"]["verdict"]
        if 0.8 <= ratio <= 1.25:
            assert verdict == "same"
        elif verdict != "same":  # "same" also when the paper's figure lies within the range of our runs
            assert verdict == ("lower" if ratio < 1 else "higher")
            assert cell["vs_paper"]["rmse_rot_deg"]["factor"] == pytest.approx(max(ratio, 1 / ratio))
    assert sorted(i for c in cells for i in c["run_ids"]) == sorted(ids.values())


# ----------------------------------------------------------------------------- figures


def test_figures_keep_one_style_per_method_and_pd_as_reference(tmp_path, monkeypatch):
    import fdbench.figures as figures

    drawn = {"tracking": [], "convergence": []}
    monkeypatch.setattr(figures, "tracking_figure",
                        lambda inverse, curves, path, title: drawn["tracking"].append((title, curves)))
    monkeypatch.setattr(figures, "convergence_figure",
                        lambda series, path, title, reference=None: drawn["convergence"].append((series, reference)))
    db = tmp_path / "fig.sqlite"
    invoke("report", "--db", db, "--opt", "cmaes", "--opt", "bfgs", "--torque", "cs", "--torque", "ann",
           "--seeds", 1, "--budget", 8, "--jobs", 1, "--figures", tmp_path / "figs", "-q")
    styles = {}
    for _, curves in drawn["tracking"]:
        for label, style, theta, torque in curves:
            assert theta.shape == torque.shape == (1001,)
            styles.setdefault(label, []).append(style)
    for series, reference in drawn["convergence"]:
        for label, style, histories in series:
            styles.setdefault(label, []).append(style)
        control = [json.loads(r) for s, r in db_rows(db, "spec_json, record_json") if json.loads(s)["command"] == "control"]
        assert reference == control[0]["rmse_rot_deg"]
    assert len(drawn["tracking"]) == len(drawn["convergence"]) == 2
    for label, used in styles.items():
        assert all(s == used[0] for s in used), label  # the same method looks the same everywhere
    distinct = {(s[0]["color"], str(s[0]["linestyle"])) for s in styles.values()}
    assert len(distinct) == len(styles) == 5  # PD and four methods, each its own look


def test_method_styles_are_stable_across_processes_for_plugin_names():
    code = "from fdbench.figures import method_style as m; print(m('my-torque', 'my-opt'), m('cs', 'bfgs'))"
    outs = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout
            for _ in range(2)}
    assert len(outs) == 1 and "tab:green" in outs.pop()


# ----------------------------------------------------------------------------- the dated experiments


def _measured(title: str) -> str:
    from fdbench.report import MEASURED

    return next(item for item in MEASURED if item.startswith(f"- **{title}"))


def _figures(text: str) -> list[float]:
    return [float(v) for v in re.findall(r"\d+\.\d+|\d+e-\d+", text)]


def test_the_experiments_quote_no_measured_number():
    """Every number in the experiments' prose is the paper's, a setting (budget, step, factor) or a
    command's; measured numbers are left to the commands that produce them."""
    from fdbench.report import MEASURED, SAME_FACTOR, UNEXPLAINED

    published = {f"{v:g}" for figures in (PAPER_PD, *PAPER_TABLE2.values(), *PAPER_TABLE3.values()) for v in figures}
    settings = {"2", "3", "15", "30", "60", "100", "200", "400", "1000", "0.2", "0.6", "1", "5", "18", "17", "2439",  # tables, settings
                f"{SAME_FACTOR:g}"}
    for text in MEASURED + UNEXPLAINED:
        prose = re.sub(r"`[^`]*`", "", text)  # commands and option names
        for number in re.findall(r"\d+(?:\.\d+)?(?:e-?\d+)?", prose):
            assert number in published | settings, (number, text[:40])


def test_the_kinematics_experiment_holds():
    text = _measured("Kinematics")
    exact, paper = _json_run("control", "--kinematics", "exact"), _json_run("control")
    assert "more than a thousand times more closely" in text
    assert exact["rmse_rot_deg"] < PAPER_PD[0] / 1000 and exact["rmse_torque_nm"] < PAPER_PD[1] / 1000
    assert "within a factor 1.25 of the paper's" in text
    assert 1 / 1.25 < paper["rmse_rot_deg"] / PAPER_PD[0] < 1.25 and 1 / 1.25 < paper["rmse_torque_nm"] / PAPER_PD[1] < 1.25
    assert "less than a thousandth of a degree" in text
    assert _json_run("simulate", "--kinematics", "exact")["rmse_rot_deg"] < 1e-3


def test_the_budget_experiment_holds():
    text = _measured("Budget")
    budgets = [int(b) for b in re.search(r"budgets of ([\d, and]+) evaluations", text)[1].replace("and", ",").split(",")
               if b.strip()]
    values = [_json_run("optimize", *CS_BFGS, "--budget", budget)["rmse_rot_deg"] for budget in budgets]
    assert all(a > b for a, b in zip(values, values[1:])), values  # improves steadily with the budget
    assert "lies between our budgets of 100 and 200" in text
    assert values[budgets.index(100)] > PAPER_TABLE2[("cs", "bfgs")][0] > values[budgets.index(200)]


def test_the_cmaes_step_experiment_holds(tmp_path):
    text = _measured("Initial step")
    assert "with the largest step most runs still end better than the zero additional torque" in text
    medians, successes = [], []
    for sigma in (1, 3):  # the two large steps
        frame = read_csv(invoke("report", "--db", tmp_path / "sigma.sqlite", "--torque", "ann", "--opt", "cmaes",
                                "--feedforward", "--no-control", "--no-beyond", "--sigma0", sigma, "--seeds", 5,
                                "--jobs", 1, "--format", "csv", "-q").stdout)
        medians.append(frame.iloc[0].rmse_rot_deg_median)
        successes.append(round(frame.iloc[0].success_rate * 5))
    assert medians[1] > medians[0] and successes[1] >= 3


# ----------------------------------------------------------------------------- what happened


NOISY = ["--noise-deg", 0.5, "--plant", "I1=0.044", "--torque", "cs", "--opt", "bfgs", "--feedforward", "--seeds", 2,
         "--budget", 5, "--jobs", 1, "--no-beyond", "-q"]


def _settings(text: str) -> dict:
    section = _section(text, "## Settings")
    return dict(re.findall(r"^\| ([^|]+?) \| (.+) \|$", section, flags=re.M)[1:])


def test_noise_and_plant_stand_in_the_settings_csv_and_json(tmp_path):
    db = tmp_path / "noisy.sqlite"
    settings = _settings(invoke("report", "--db", db, *NOISY).stdout)
    assert {"noise", "plant"} <= settings.keys() and "noise-free" in settings["RMSE_rot against"]
    frame = read_csv(invoke("report", "--db", db, *NOISY, "-f", "csv").stdout)
    assert (frame.noise_deg == 0.5).all() and (frame.plant == "I1=0.044").all() and (frame.model == "forearm").all()
    assert list(frame.noise_seeds.astype(str)) == ["0", "0, 1"]  # PD control draws seed 0's noise
    cells = json.loads(invoke("report", "--db", db, *NOISY, "-f", "json").stdout)["cells"]
    assert [(c["noise_deg"], c["plant"], c["noise_seeds"]) for c in cells] == [(0.5, "I1=0.044", "0"),
                                                                                (0.5, "I1=0.044", "0, 1")]


def test_a_motion_file_stands_with_its_digest_convention_and_filtered_reference(tmp_path):
    import hashlib

    motion = ROOT / "examples" / "elbow_flexion.csv"
    args = ["report", "--db", tmp_path / "file.sqlite", "--motion", motion, "--torque", "cs", "--opt", "bfgs",
            "--feedforward", "--no-control", "--no-beyond", "--seeds", 1, "--budget", 2, "--jobs", 1, "-q"]
    text = invoke(*args).stdout
    settings = _settings(text)
    digest = hashlib.sha256(motion.read_bytes()).hexdigest()
    assert digest[:16] in settings["motion"] and "2.5 s" in settings["motion"]
    assert "from the horizontal +x axis" in settings["angle convention"]
    assert settings["RMSE_rot against"].startswith("the filtered angle")
    assert "(t = 2.5 s)" in text and "t = 1 s" not in text
    frame = read_csv(invoke(*args, "-f", "csv").stdout)
    assert frame.motion_sha256.tolist() == [digest] and frame.motion.tolist() == ["file:elbow_flexion.csv"]


def test_figure2_draws_a_recordings_raw_samples_and_says_what_rmse_is_against():
    from fdbench.spec import RunSpec, with_motion_file
    from fdbench.figures import figure2_samples

    motion = ROOT / "examples" / "elbow_flexion.csv"
    raw = np.loadtxt(motion, delimiter=",", skiprows=1)
    samples, note, reference = figure2_samples(with_motion_file(RunSpec(kinematics=str(motion))))
    assert np.allclose(samples[1][:, 0], np.radians(raw[:, 1])) and np.allclose(samples[0], raw[:, 0] - raw[0, 0])
    assert reference == "filtered" and "against the filtered angle" in note
    noisy, note, reference = figure2_samples(RunSpec(noise_deg=0.5, seed=3))
    assert len(noisy[0]) == 101 and reference == "noise-free" and "seed 3" in note
    assert figure2_samples(RunSpec()) == (None, "", "")


def test_a_control_run_with_noise_records_its_seed():
    assert _json_run("control", "--noise-deg", 0.5, "--seed", 3)["seed"] == 3
    assert _json_run("control", "--noise-deg", 0.5)["seed"] == 0
    assert _json_run("control")["seed"] is None  # draws nothing


def _failing_cell() -> "fdbench.report.Row":
    """A cell of five runs: two singular, one non-finite, one that ended no better than its
    start, one success."""
    from fdbench.report.paper_methods import Cell
    from fdbench.report import Row

    singular = {"status": "singular", "t_end": 0.4, "message": "theta reached +-pi/2", "rmse_rot_deg": 9.0}
    records = [dict(singular), dict(singular, t_end=0.5),
               {"status": "nonfinite", "t_end": 0.2, "message": "the state became non-finite", "rmse_rot_deg": 8.0},
               {"status": "success", "t_end": 1.0, "best_objective": 3.0, "initial_objective": 3.0, "rmse_rot_deg": 3.0},
               {"status": "success", "t_end": 1.0, "best_objective": 1.0, "initial_objective": 3.0, "rmse_rot_deg": 1.0}]
    return Row("CS + BFGS", 2, Cell("cs", "bfgs", False), summarise(records), None, records)


def test_a_failing_cells_outcomes_sum_to_its_runs_with_status_t_end_and_message():
    from fdbench.report import csv_rows, failure_lines, json_report

    row = _failing_cell()
    values = dict(zip(CSV_COLUMNS, csv_rows([row])[0]))
    counts = {name: int(n) for n, name in (part.split(" ", 1) for part in values["status"].split(", "))}
    assert counts == {"success": 1, "singular": 2, "nonfinite": 1, "no-better-than-start": 1}
    assert sum(counts.values()) == values["runs"] == 5 and values["reached_end"] == 2
    assert values["t_end"] == 0.5 and values["message"] == "theta reached +-pi/2"
    (line,) = failure_lines([row])
    assert "2 of 5 reached the end" in line and "2 singular" in line and "1 ended no better than their start" in line
    cell = json_report([row], {})["cells"][0]
    assert sum(cell["status_counts"].values()) == 5 and cell["message"] == "theta reached +-pi/2"


def test_markdown_has_no_legend_line_for_an_absent_column(tmp_path):
    text = invoke("report", "--db", tmp_path / "noisy.sqlite", *NOISY).stdout
    assert "vs paper" not in text and "speed-up" not in text
    for absent in ("**paper**", "**vs paper**", "**speed-up**"):
        assert absent not in text
    assert "(t = 1 s)" in text
    from fdbench.report import legend

    arm = "\n".join(legend([_failing_cell()], ("shoulder", "elbow"), 1.0, "reach"))
    assert "joint angles" in arm and "elbow rotation" not in arm and "paper's kinematics" not in arm


def test_the_comparison_counts_every_row_and_every_cell():
    from fdbench.report.paper_methods import Cell
    from fdbench.report import Row, _comparison, comparison_facts

    def row(name, table, rot, cell=None, status="success"):
        record = {"status": status, "rmse_rot_deg": rot, "runtime_s": 0.1, "t_end": 1.0}
        return Row(name, table, cell, summarise([record]), None, [record])

    rows = [row("PD", "control", 0.1)]
    rows += [row(f"cell {i}", 2 + i % 2, 0.05 if i < 3 else 5.0, Cell("cs", "bfgs", bool(i % 2)),
                 "success" if i < 5 else "singular") for i in range(10)]
    rows.append(row("Direct collocation", "beyond", 0.00015))
    facts = comparison_facts(rows)
    assert facts["rows"] == 12 and facts["most_accurate"]["name"] == "Direct collocation"
    beat = facts["beat_pd_control"]
    assert (len(beat["beaten"]), beat["cells"], len(beat["without_success"])) == (3, 10, 5)
    assert beat["beaten"] == ["cell 0", "cell 1", "cell 2"] and beat["pd_rmse_rot_deg"] == 0.1
    assert facts["left_out"] == [f"cell {i} (Table {2 + i % 2})" for i in range(5, 10)]
    assert facts["best_per_table"]["2"]["name"] == "cell 0" and facts["best_per_table"]["3"]["name"] == "cell 1"
    # the sentence that carries the count
    assert "3 of 10 optimisation cells track more accurately than PD control" in "\n".join(_comparison(rows))
