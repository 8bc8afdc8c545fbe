"""The examples in examples/ run as a user would run them, and produce what they promise.

The shell scripts call the installed ``fdbench`` command: the directory of this interpreter
(the virtualenv's bin/) goes first on PATH so that it is found.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from helpers.processes import python_path
from helpers.paths import ROOT

EXAMPLES = ROOT / "examples"
SCIPY_INTEGRATORS = ("rk45", "dop853", "lsoda", "radau", "bdf")

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="the shell examples need bash")


def example_env() -> dict:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env.pop("FDBENCH_DEBUG", None)
    return env


def run_example(args, cwd) -> subprocess.CompletedProcess:
    out = subprocess.run([str(a) for a in args], cwd=cwd, env=example_env(), capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, f"exit {out.returncode}\nstdout:\n{out.stdout}\nstderr:\n{out.stderr}"
    assert "Traceback" not in out.stderr
    return out


def test_fdbench_on_path():
    found = shutil.which("fdbench", path=example_env()["PATH"])
    assert found, "the fdbench console script is not installed next to this interpreter"


def test_sweep_gains(tmp_path):
    target = tmp_path / "results" / "gains.csv"
    target.parent.mkdir()
    out = run_example(["bash", EXAMPLES / "sweep_gains.sh", target], cwd=tmp_path)
    frame = pd.read_csv(target)
    assert len(frame) == 12  # Kp 20 40 80 160 x Kd 0.1 0.3 1.0, one header
    for column in ("command", "kp", "kd", "rmse_rot_deg", "rmse_torque_nm", "runtime_s", "t_end", "status"):
        assert column in frame.columns, column
    assert set(zip(frame.kp, frame.kd)) == {(kp, kd) for kp in (20, 40, 80, 160) for kd in (0.1, 0.3, 1.0)}
    assert (frame.command == "control").all() and (frame.status == "success").all()
    for column in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"):
        assert frame[column].map(math.isfinite).all() and (frame[column] >= 0).all(), column
    # stiffer proportional feedback tracks better (at the paper's Kd)
    at_paper_kd = frame[frame.kd == 0.3].sort_values("kp")
    assert at_paper_kd.rmse_rot_deg.is_monotonic_decreasing
    paper = frame[(frame.kp == 80) & (frame.kd == 0.3)].iloc[0]
    assert paper.rmse_rot_deg == pytest.approx(0.113, abs=0.01)  # section 5 of the paper: 0.116 deg
    assert "wrote" in out.stderr
    assert sorted(p.name for p in target.parent.iterdir()) == ["gains.csv"], "temporary file left behind"


def test_sweep_gains_default_output_and_extra_options(tmp_path):
    env_args = ["env", "KP_VALUES=80", "KD_VALUES=0.3 1.0"]
    run_example([*env_args, "bash", EXAMPLES / "sweep_gains.sh"], cwd=tmp_path)
    frame = pd.read_csv(tmp_path / "gains.csv")
    assert len(frame) == 2 and (frame.kinematics == "paper").all()
    run_example([*env_args, "bash", EXAMPLES / "sweep_gains.sh", "exact.csv", "--kinematics", "exact"], cwd=tmp_path)
    assert (pd.read_csv(tmp_path / "exact.csv").kinematics == "exact").all()


def test_compare_integrators(tmp_path):
    target = tmp_path / "integrators.csv"
    out = run_example(["bash", EXAMPLES / "compare_integrators.sh", target], cwd=tmp_path)
    frame = pd.read_csv(target)
    for column in ("command", "kinematics", "integrator", "rmse_rot_deg", "rmse_torque_nm", "runtime_s",
                   "t_end", "status"):
        assert column in frame.columns, column
    assert len(frame) == 12
    assert set(zip(frame.command, frame.integrator)) == {
        (c, i) for c in ("control", "simulate") for i in ("rk4", *SCIPY_INTEGRATORS)
    }
    assert (frame.status == "success").all() and (frame.t_end == 1.0).all()
    for column in ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"):
        assert frame[column].map(math.isfinite).all(), column
    for command, rows in frame.groupby("command"):
        rk4 = rows[rows.integrator == "rk4"].iloc[0]
        scipy = rows[rows.integrator != "rk4"]
        # RK4 agrees with the adaptive methods (speed is measured in benchmarks/, not here)
        assert (scipy.rmse_rot_deg - rk4.rmse_rot_deg).abs().max() < 1e-3, command
    assert "wrote" in out.stderr
    assert sorted(p.name for p in target.parent.iterdir()) == ["integrators.csv"], "temporary file left behind"


def test_custom_torque(tmp_path):
    out = run_example([sys.executable, EXAMPLES / "custom_torque.py", "20"], cwd=tmp_path)
    values = dict()
    sections = out.stdout.split("through fdbench.run")
    assert len(sections) == 2, out.stdout
    for name, text in zip(("library", "experiment"), sections):
        values[name] = dict(re.findall(r"^\s+(\w+) = (\S+)$", text, flags=re.MULTILINE))
    for name in ("library", "experiment"):
        found = values[name]
        for key in ("rmse_rot_deg", "rmse_torque_nm"):
            assert math.isfinite(float(found[key])), (name, key, found)
        assert int(found["evaluations"]) == 20
        assert found["status"] == "success"
    assert values["experiment"]["torque"] == "pwl"
    assert math.isfinite(float(values["experiment"]["runtime_s"]))
    # the library and experiment.run do the same thing: the same numbers
    assert float(values["library"]["rmse_rot_deg"]) == pytest.approx(float(values["experiment"]["rmse_rot_deg"]))
    # the optimisation improved on the initial guess
    assert float(values["library"]["rmse_rot_deg"]) < float(values["library"]["initial_rmse_rot_deg"])
    assert list(tmp_path.iterdir()) == []  # it writes nothing


def test_plugin_module_methods_reach_the_report(tmp_path):
    """examples/my_methods.py, named in FDBENCH_PLUGINS, gives report cells outside the paper."""
    env = dict(example_env(), PYTHONPATH=python_path(EXAMPLES), FDBENCH_PLUGINS="my_methods")
    args = ["fdbench", "report", "--db", tmp_path / "plugin.sqlite", "--torque", "linear", "--opt", "random",
            "--no-control", "--seeds", "2", "--budget", "10", "--jobs", "1", "-q"]
    out = subprocess.run([str(a) for a in args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = [line for line in out.stdout.splitlines() if line.startswith("| linear + random*")]
    assert len(lines) == 2  # Table 2 and Table 3
    cells = [c.strip() for c in lines[0].strip("|").split("|")]
    heads = [line for line in out.stdout.splitlines() if line.startswith("| method |")]
    # no paper figures for these cells: the tables have no paper columns
    assert len(cells) == 5 and heads and not any("paper" in head for head in heads), heads
    assert "Cells marked * are not in the paper." in out.stdout
