"""The Python entry points of ``fdbench`` agree with the command line that does the same thing."""

from __future__ import annotations

import io
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import fdbench
from fdbench.cli import app


def cli(*args) -> str:
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.stderr
    return result.stdout


def test_simulate_of_a_function_equals_simulate_of_the_same_torque_as_a_file(tmp_path):
    # a torque of our own, linear between samples, given once as a CSV file and once as a function
    t = np.linspace(0.0, 1.0, 201)
    torque = 5.0 + 0.8 * np.sin(3 * t)
    path = tmp_path / "torque.csv"
    path.write_text("t,torque\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, torque)))
    from_file = json.loads(cli("simulate", "--torque-file", path, "--format", "json", "-q"))
    from_function = fdbench.simulate(lambda times: np.interp(times, t, torque)).record
    for key in ("rmse_rot_deg", "rmse_torque_nm", "t_end", "status"):
        assert from_function[key] == from_file[key], key


def test_simulate_and_run_give_the_commands_numbers():
    assert fdbench.simulate().record["rmse_rot_deg"] == json.loads(cli("simulate", "-f", "json", "-q"))["rmse_rot_deg"]
    exact = fdbench.simulate(kinematics="exact").record
    assert exact["kinematics"] == "exact" and exact["rmse_rot_deg"] < 1e-4  # consistent kinematics track
    control = fdbench.run(fdbench.control_spec(80.0, 0.3)).record
    alone = json.loads(cli("control", "--kp", 80, "--kd", 0.3, "-f", "json", "-q"))
    for key in ("rmse_rot_deg", "rmse_torque_nm", "t_end", "status", "spec_hash"):
        assert control[key] == alone[key], key
    with pytest.raises(ValueError):
        fdbench.simulate(kinematics="wrong")


def test_load_report_equals_the_csv_report_and_load_runs_lists_every_stored_run(tmp_path):
    db = tmp_path / "api.sqlite"
    args = ["--torque", "cs", "--opt", "bfgs", "--seeds", 2, "--budget", 10, "--jobs", 1, "--no-beyond", "-q"]
    frame = pd.read_csv(io.StringIO(cli("report", "--db", db, *args, "--format", "csv")))
    loaded = fdbench.load_report(db, torques=["cs"], optimizers=["bfgs"], seeds=2, budget=10)
    assert list(loaded.columns) == list(frame.columns)
    assert loaded["cell"].tolist() == frame["cell"].tolist()
    for column in ("rmse_rot_deg_median", "rmse_torque_nm_median", "runtime_s_median", "success_rate"):
        assert loaded[column].astype(float).tolist() == pytest.approx(frame[column].tolist(), rel=1e-12), column
    runs = fdbench.load_runs(db)
    assert len(runs) == 5 and {"id", "created_at", "machine", "rmse_rot_deg"} <= set(runs.columns)
    with pytest.raises(LookupError, match="not stored"):
        fdbench.load_report(db, torques=["cs"], optimizers=["bfgs"], seeds=3, budget=10)
    with pytest.raises(FileNotFoundError):
        fdbench.load_runs(tmp_path / "missing.sqlite")


def test_the_arm_through_the_python_api():
    """model_name='arm2' takes the arm's own motion; a torque function of the arm's inverse
    dynamics (its closed form, tests/helpers/arm2_closed_form.py) gives the default open-loop run."""
    import fdbench
    from helpers.arm2_closed_form import joint_torques, reach

    default = fdbench.simulate(model_name="arm2")
    given = fdbench.simulate(lambda t: joint_torques(*reach(t)), model_name="arm2")
    assert default.record["kinematics"] == "reach" and default.record["model"] == "arm2"
    # two correct torque functions differ by 1e-14 N m, which the arm's open loop amplifies to 1e-7 deg
    assert given.record["rmse_rot_deg"] == pytest.approx(default.record["rmse_rot_deg"], rel=1e-4)
    assert default.record["rmse_rot_deg"] > 0
    assert fdbench.RunSpec(model_name="arm2").hash() == fdbench.RunSpec(model_name="arm2", kinematics="reach").hash()
