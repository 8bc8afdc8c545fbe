"""What a new user meets: --help texts that say what the commands do and write, a budget too small
for one optimiser iteration said as such, hints that do not mislead, simulate storing its run, and
a machine's first compilation announced on a terminal only."""

from __future__ import annotations

import csv
import io
import json
import re
import sqlite3
import tomllib

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.models import named_motions, names

WIDE = {"COLUMNS": "250"}


def invoke(args):
    return CliRunner().invoke(app, [str(a) for a in args], env=WIDE)


def commands():
    """(path, click command) of every command and subcommand, as typer builds them afresh."""
    found = []

    def walk(command, path):
        found.append((path, command))
        for name, sub in getattr(command, "commands", {}).items():
            walk(sub, [*path, name])

    walk(typer.main.get_command(app), [])
    return found


def normal(text: str) -> str:
    """Help text without the box drawing and line breaks of its rich panels."""
    return " ".join(re.sub(r"[│╭╮╰╯─]", " ", text).split())


# ---- --help -------------------------------------------------------------------------------------


@pytest.mark.parametrize("path, command", commands(), ids=lambda x: " ".join(x) if isinstance(x, list) else "")
def test_every_bracketed_example_of_a_help_text_survives_in_help(path, command):
    texts = [command.help or ""] + [getattr(p, "help", None) or "" for p in command.params]
    examples = {m for text in texts for m in re.findall(r"[\w.'-]*\[[A-Za-z_][^\]\s]*\][\w']*", text.replace("\\[", "["))}
    shown = normal(invoke([*path, "--help"]).stdout)
    for example in examples:
        assert example in shown, (path, example)


def test_the_examples_that_rich_markup_used_to_eat_are_shown():
    assert "'cs[knots=21]'" in normal(invoke(["optimize", "--help"]).stdout)
    report = normal(invoke(["report", "--help"]).stdout)
    assert "'cs[knots=21]'" in report and "'cmaes[sigma0=0.1]'" in report and "'.[dask]'" in report
    assert "\\[" not in report


def save_trajectory_help() -> str:
    (option,) = [p for _, c in commands() if c.name == "simulate" for p in c.params if p.name == "save_history"]
    return option.help


def test_save_trajectory_help_names_exactly_the_columns_written(tmp_path):
    text = save_trajectory_help()
    forearm_part, other_part = text.split("another model")
    said = set(re.findall(r"\b(t|theta\w*)\b", forearm_part.split(": ", 1)[1]))
    assert invoke(["simulate", "--save-trajectory", tmp_path / "f.csv", "-q", "-f", "json"]).exit_code == 0
    written = (tmp_path / "f.csv").read_text().splitlines()[0].split(",")
    assert said == set(written)
    per_joint = re.findall(r"<joint>(\w*)", other_part)
    assert invoke(["simulate", "--model", "arm2", "--save-trajectory", tmp_path / "a.csv", "-q", "-f", "json"]).exit_code == 0
    written = (tmp_path / "a.csv").read_text().splitlines()[0].split(",")
    assert set(written) == {"t"} | {joint + suffix for joint in ("shoulder", "elbow") for suffix in per_joint}


def test_motion_choices_list_every_named_motion_of_the_library():
    shown = normal(invoke(["simulate", "--help"]).stdout)
    (choices,) = re.findall(r"--motion,--kinematics \[([^\]]+)\]", shown)
    listed = choices.split("|")
    assert "swing" in listed and "reach" in listed and listed[-1] == "FILE"
    for model in names():
        assert set(named_motions(model)) <= set(listed), model


def test_models_show_lists_the_paths_the_readme_names_with_the_files_values():
    from fdbench.models import library

    out = invoke(["models", "show", "leg3"])
    assert out.exit_code == 0, out.stderr
    rows = dict(re.findall(r"^\s+([a-z_]+\.[\w.]+|loads\[\d+\]\.[\w.]+)\s+(-?[\d.e+-]+)\s*$", out.stdout, flags=re.M))
    data = tomllib.loads(library()["leg3"].read_text())
    thigh = next(b for b in data["bodies"] if b["name"] == "thigh")
    knee = next(j for j in data["joints"] if j["name"] == "knee")
    assert float(rows["thigh.mass"]) == pytest.approx(thigh["mass"], rel=1e-6)
    assert float(rows["knee.at_parent.x"]) == pytest.approx(knee["at_parent"][0], rel=1e-6)
    assert float(rows["gravity.y"]) == pytest.approx(data.get("gravity", [0.0, -9.81])[1], rel=1e-6)
    shown = json.loads(invoke(["models", "show", "leg3", "-f", "json"]).stdout)["paths"]
    assert shown["thigh.mass"] == pytest.approx(thigh["mass"])
    # every path listed is one --model PATH=VALUE takes
    for path in ("thigh.mass", "knee.at_parent.x", "gravity.y"):
        assert invoke(["inverse", "--model", "leg3", "--model", f"{path}={float(rows[path]) * 1.01}", "-f", "json",
                       "-q"]).exit_code == 0


# ---- a budget too small for one iteration ------------------------------------------------------


@pytest.mark.parametrize("method", ["BFGS", "L-BFGS-B"])
def test_scipys_first_iteration_costs_at_least_two_values_and_gradients(method):
    """The bound fdbench states, 2 (n + 1) evaluations with forward differences, checked on scipy
    itself: a separable quadratic, the evaluations counted until the first iteration's callback."""
    from scipy.optimize import minimize

    from fdbench.optimizers import make_optimizer

    for n in (3, 5, 11):
        calls, first = [], []
        weights = 1.0 + np.arange(n)
        minimize(lambda x: calls.append(1) or float(np.sum(weights * (x - np.arange(n)) ** 2)), np.zeros(n),
                 method=method, callback=lambda *a: first.append(len(calls)), options={"maxiter": 2})
        bound = make_optimizer("bfgs" if method == "BFGS" else "lbfgsb").smallest_budget(n)
        assert first[0] >= bound == 2 * (n + 1)
        if n <= 5:  # the first trial point accepted: the bound is reached
            assert first[0] == bound


def test_a_budget_below_one_iteration_says_so_and_a_sufficient_one_does_not():
    short = invoke(["optimize", "--torque", "cs", "--opt", "bfgs", "--budget", "23", "-f", "json", "-q"])
    record = json.loads(short.stdout)
    assert record["n_params"] == 11 and record["status"] == "success"
    assert record["stop_reason"].startswith("no iteration completed") and "24" in record["stop_reason"]
    assert "--gradient exact" in record["stop_reason"]
    assert "completed no iteration" in record["message"]
    enough = json.loads(invoke(["optimize", "--torque", "cs", "--opt", "lbfgsb", "--budget", "24", "-f", "json",
                                "-q"]).stdout)
    assert "no iteration" not in enough["stop_reason"] and "no iteration" not in enough["message"]
    exact = json.loads(invoke(["optimize", "--torque", "cs", "--opt", "bfgs", "--gradient", "exact", "--budget", "2",
                               "-f", "json", "-q"]).stdout)
    assert "no iteration" not in exact["stop_reason"]


# ---- simulate --db --------------------------------------------------------------------------------


def test_simulate_stores_its_run_and_a_torque_file_by_content(tmp_path):
    db = tmp_path / "r.sqlite"
    first = tmp_path / "a.csv"
    first.write_text("t,torque\n0,1\n1,1\n")
    second = tmp_path / "b.csv"
    second.write_text("t,torque\n0,2\n1,2\n")
    for torque_file in (first, second, first):
        out = invoke(["simulate", "--torque-file", torque_file, "--db", db, "-f", "json"])
        assert out.exit_code == 0, out.stderr
        assert f"stored in {db}" in out.stderr
    with sqlite3.connect(db) as connection:
        rows = connection.execute("SELECT command, spec_hash, record_json FROM runs").fetchall()
    assert [r[0] for r in rows] == ["simulate", "simulate"]  # the same file twice is one run
    assert len({r[1] for r in rows}) == 2
    assert {json.loads(r[2])["spec_hash"] for r in rows} == {r[1] for r in rows}


# ---- a hint that does not mislead ------------------------------------------------------------------


def test_a_constraint_failure_far_off_the_motion_blames_the_torques_not_alpha(tmp_path):
    torques = tmp_path / "arm2.csv"
    assert invoke(["inverse", "--model", "arm2", "-f", "csv", "-o", torques]).exit_code == 0
    trajectory = tmp_path / "traj.csv"
    out = invoke(["simulate", "--model", "arm2", "--model", "m0=2.5", "--torque-file", torques, "--save-trajectory",
                  trajectory, "-f", "json", "-q"])
    record = json.loads(out.stdout)
    assert record["status"] == "constraint", record["message"]
    assert "--alpha" in record["message"] and "larger --alpha" not in record["message"]
    assert "torque history made for another model" in record["message"]
    rows = list(csv.DictReader(io.StringIO(trajectory.read_text())))
    reached = [r for r in rows if float(r["t"]) <= record["t_end"]]
    drift = max(abs(float(r[j]) - float(r[f"{j}_desired"])) for r in reached for j in ("shoulder", "elbow"))
    shown = float(re.search(r"an angle was ([\d.e+]+) deg off", record["message"])[1])
    assert drift > 10 and shown == pytest.approx(drift, rel=6e-3)  # shown to 3 digits


def test_a_drift_below_the_threshold_keeps_the_alpha_hint():
    from fdbench.integrate import Status
    from fdbench.outcomes import DRIFT_DEG
    from fdbench.outcomes import drift_hint as _drift_hint
    from fdbench.records import ALPHA_HINT

    class Result:
        reached = np.ones(3, dtype=bool)
        angles = np.radians([[0.0], [1.0], [2.0]])

    desired = np.radians([[0.0], [0.0], [DRIFT_DEG - 1.0 + 2.0]])
    assert _drift_hint(Status.CONSTRAINT.value, Result, desired, ["angle"]) == Status.CONSTRAINT.value
    assert ALPHA_HINT in Status.CONSTRAINT.value
    far = np.radians([[0.0], [0.0], [2.0 + DRIFT_DEG + 1.0]])
    assert ALPHA_HINT not in _drift_hint(Status.CONSTRAINT.value, Result, far, ["angle"])


# ---- the first compilation on a terminal ---------------------------------------------------------------


@pytest.fixture
def notice(monkeypatch, capsys):
    """The compilation notice as on a terminal, its state fresh; what it wrote on stderr."""
    import fdbench.jit as jit

    monkeypatch.setattr(jit, "_stderr_is_terminal", lambda: True)
    for name, value in (("enabled", True), ("spinner", True), ("started", None), ("status", None), ("compiled", 0),
                        ("depth", 0)):
        monkeypatch.setattr(jit._CompileNotice, name, value)
    capsys.readouterr()
    return jit, lambda: capsys.readouterr().err


def test_a_compilation_on_a_terminal_is_said_once(notice):
    jit, stderr = notice
    import numba

    jit._configure()
    numba.njit(lambda x: x + 1.0)(1.0)
    numba.njit(lambda x: x * 2.0)(1.0)
    lines = stderr().splitlines()
    said = [line for line in lines if line.startswith("fdbench: compiling the kernels")]
    assert len(said) == 1 and "once per fdbench version" in said[0]
    assert jit._CompileNotice.compiled >= 2 and jit._CompileNotice.status is None  # the spinner stopped


def test_no_notice_off_a_terminal_or_when_quiet(notice, monkeypatch):
    jit, stderr = notice
    import numba

    jit._configure()
    monkeypatch.setattr(jit, "_stderr_is_terminal", lambda: False)
    numba.njit(lambda x: x - 1.0)(1.0)
    monkeypatch.setattr(jit, "_stderr_is_terminal", lambda: True)
    jit.quiet()
    numba.njit(lambda x: x - 2.0)(1.0)
    assert stderr() == ""
