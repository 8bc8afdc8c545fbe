"""The core commands (inverse, simulate, control) in every format, through the CLI."""

import io
import json
import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from helpers import forearm_closed_form as cf
from fdbench.cli import app
from fdbench.multibody.motions import desired_motion

runner = CliRunner()


def invoke(*args):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.stderr
    return result


@pytest.mark.parametrize("kinematics", ["paper", "exact"])
def test_inverse_csv_is_the_whole_history(kinematics):
    table = pd.read_csv(io.StringIO(invoke("inverse", "--format", "csv", "--kinematics", kinematics).stdout))
    # s, deg, deg/s, deg/s^2, N m
    assert list(table.columns) == ["t", "theta", "theta_vel", "theta_acc", "theta_torque"]
    assert len(table) == 1001 and table.theta[0] == pytest.approx(-45.0)
    np.testing.assert_allclose(np.diff(table.t), 1e-3, atol=1e-12)
    expected = cf.elbow_torque(np.radians(table.theta), np.radians(table.theta_acc))
    np.testing.assert_allclose(table.theta_torque, expected, rtol=1e-8)


def test_inverse_summary_formats_agree():
    summary = json.loads(invoke("inverse", "--format", "json").stdout)
    history = pd.read_csv(io.StringIO(invoke("inverse", "--format", "csv").stdout))
    assert summary["samples"] == 1001
    assert summary["torque_max_nm_theta"] == pytest.approx(history.theta_torque.max(), rel=1e-8)
    assert summary["torque_min_nm_theta"] == pytest.approx(history.theta_torque.min(), rel=1e-8)
    assert summary["torque_rms_nm"] == pytest.approx(math.sqrt(np.mean(history.theta_torque**2)), rel=1e-8)
    # the largest torque holds the load at rest at theta = 0 (the motion's end): F_ext L12 + m g L1G
    assert summary["torque_max_nm_theta"] == pytest.approx(cf.load_moment(), rel=1e-12)
    assert "torque_rms_nm" in invoke("inverse").stdout  # the table for a person


def test_control_formats_carry_the_same_numbers(tmp_path):
    as_json = json.loads(invoke("control", "--format", "json").stdout)
    as_csv = pd.read_csv(io.StringIO(invoke("control", "--format", "csv").stdout))
    table = invoke("control").stdout
    assert len(as_csv) == 1
    for key in ("rmse_rot_deg", "rmse_torque_nm", "t_end"):
        assert as_csv[key][0] == pytest.approx(as_json[key], rel=1e-12)
    assert f"{as_json['rmse_rot_deg']:.6g}" in table
    # the paper's PD figures (section 5), within 5 %
    assert as_json["rmse_rot_deg"] == pytest.approx(0.116, rel=0.05)
    assert as_json["rmse_torque_nm"] == pytest.approx(0.149, rel=0.05)
    assert as_json["status"] == "success" and as_json["max_violation"] < 1e-6


def test_control_history_is_consistent_with_the_indicators(tmp_path):
    path = tmp_path / "history.csv"
    record = json.loads(invoke("control", "--format", "json", "--save-history", path).stdout)
    history = pd.read_csv(path)
    assert len(history) == 1001
    assert history.theta[0] == pytest.approx(-45.0)  # degrees, like a motion file
    rmse_rot = math.sqrt(np.mean((history.theta - history.theta_desired) ** 2))
    rmse_torque = math.sqrt(np.mean((history.theta_torque - history.theta_torque_inverse) ** 2))
    assert rmse_rot == pytest.approx(record["rmse_rot_deg"], rel=1e-6)
    assert rmse_torque == pytest.approx(record["rmse_torque_nm"], rel=1e-6)
    # the inverse-dynamics torque is the closed form's on eq. 5's paper motion
    theta_d, _, accelerations = desired_motion(history.t.to_numpy(), "paper")
    np.testing.assert_allclose(history.theta_desired, np.degrees(theta_d), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(history.theta_torque_inverse, cf.elbow_torque(theta_d, accelerations), rtol=1e-9)
    # the applied torque is feedforward plus PD: torque - torque_inverse = kp e + kd e' (gains per rad)
    pd_term = np.radians(80 * (history.theta_desired - history.theta)
                         + 0.3 * (history.theta_vel_desired - history.theta_vel))
    np.testing.assert_allclose(history.theta_torque - history.theta_torque_inverse, pd_term, atol=1e-6)


def test_control_exact_kinematics_tracks_and_integrators_agree():
    rk4 = json.loads(invoke("control", "--kinematics", "exact", "--format", "json").stdout)
    assert rk4["rmse_rot_deg"] < 0.01
    paper_rk4 = json.loads(invoke("control", "--format", "json").stdout)
    paper_dop = json.loads(invoke("control", "--format", "json", "--integrator", "dop853",
                                  "--rtol", "1e-10", "--atol", "1e-12").stdout)
    assert paper_dop["integrator"] == "dop853"
    assert paper_dop["rmse_rot_deg"] == pytest.approx(paper_rk4["rmse_rot_deg"], rel=1e-4)


def test_simulate_reproduces_the_drift_and_reads_a_torque_file(tmp_path):
    drift = json.loads(invoke("simulate", "--format", "json").stdout)
    assert drift["torque"] == "id" and drift["rmse_torque_nm"] == pytest.approx(0.0, abs=1e-12)
    assert drift["rmse_rot_deg"] > 1.0  # open loop drifts (the paper's motivation)
    exact = json.loads(invoke("simulate", "--format", "json", "--kinematics", "exact").stdout)
    assert exact["rmse_rot_deg"] < 1e-3  # ...unless the kinematics are consistent
    torque_file = tmp_path / "id.csv"
    torque_file.write_text(invoke("inverse", "--format", "csv").stdout)
    from_file = json.loads(invoke("simulate", "--torque-file", torque_file, "--format", "json").stdout)
    assert from_file["torque"].startswith("file:")
    # linear interpolation between 1 ms samples of a smooth torque changes little
    assert from_file["rmse_rot_deg"] == pytest.approx(drift["rmse_rot_deg"], rel=1e-3)
    # a forearm torque file may name its column 'torque' (the first releases' name)
    old_name = tmp_path / "torque.csv"
    pd.read_csv(torque_file).rename(columns={"theta_torque": "torque"})[["t", "torque"]].to_csv(old_name, index=False)
    from_old = json.loads(invoke("simulate", "--torque-file", old_name, "--format", "json").stdout)
    assert from_old["rmse_rot_deg"] == pytest.approx(from_file["rmse_rot_deg"], rel=1e-12)
    as_csv = pd.read_csv(io.StringIO(invoke("simulate", "--torque-file", torque_file, "--format", "csv").stdout))
    assert as_csv.rmse_rot_deg[0] == pytest.approx(from_file["rmse_rot_deg"], rel=1e-12)
    assert "rmse_rot_deg" in invoke("simulate").stdout
