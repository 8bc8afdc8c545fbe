"""Direct collocation of the two-segment arm: the CasADi equations of motion against the model's
own inverse dynamics, the defects at the solution (recomputed here with numpy), tracking on the
reach and its replay by the forward simulation, the local error of the two transcriptions as
the nodes double, the forearm recovered with the shoulder held at 0, and the command line."""

from __future__ import annotations

import json

import casadi as ca
import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.collocation import collocate as collocate_forearm
from fdbench.experiment import collocate_spec, run
from fdbench.integrate import Settings
from fdbench.models import arm2_collocation as ac
from fdbench.models.arm2 import Arm2
from fdbench.models.arm2_motion import PerJoint, Reach

runner = CliRunner()
ARM = Arm2()
EYE = np.eye(2)


def numpy_accelerations(arm: Arm2, z, w, tau):
    """z'' from the model's numpy inverse dynamics alone: h(z, z') = Q(z, z', 0), the columns of
    M(z) = Q(z, 0, e_i) - Q(z, 0, 0); shapes (k, 2)."""
    zero = np.zeros_like(z)
    gravity = arm.joint_torques(z, zero, zero)
    mass = np.stack([arm.joint_torques(z, zero, np.broadcast_to(e, z.shape)) - gravity for e in EYE], axis=-1)
    return np.linalg.solve(mass, (tau - arm.joint_torques(z, w, zero))[..., None])[..., 0]


def casadi_function(expression, k):
    z, w, a = (ca.SX.sym(name, k, 2) for name in ("z", "w", "a"))
    return ca.Function("f", [z, w, a], [expression(z, w, a)])


@pytest.mark.parametrize("arm", [ARM, Arm2(L01=0.25, L0G=0.2, m0=3.1, I0=0.09, L12=0.4, L1G=0.05, m=1.7, I1=0.02,
                                           F_ext=-4.0, g=3.7)])
def test_casadi_equations_of_motion_are_the_models_inverse_dynamics(arm):
    k = 200
    rng = np.random.default_rng(7)
    z, w, a = rng.uniform(-np.pi, np.pi, (k, 2)), rng.uniform(-8, 8, (k, 2)), rng.uniform(-60, 60, (k, 2))
    torque = np.array(casadi_function(lambda z_, w_, a_: ac.joint_torques(arm, z_, w_, a_), k)(z, w, a))
    np.testing.assert_allclose(torque, arm.joint_torques(z, w, a), rtol=1e-12, atol=1e-12)
    # the forward dynamics undoes the inverse dynamics
    tau = arm.joint_torques(z, w, a)
    back = np.array(casadi_function(lambda z_, w_, t_: ac.accelerations(arm, z_, w_, t_), k)(z, w, tau))
    np.testing.assert_allclose(back, a, rtol=1e-10, atol=1e-10)


def defects(sol) -> np.ndarray:
    """The scheme's defects at the solution, recomputed with ``numpy_accelerations``."""
    h = sol.t[1] - sol.t[0]
    z, w, u = sol.angles, sol.velocities, sol.torque
    a = numpy_accelerations(ARM, z, w, u)
    if sol.torque_mid is None:
        return np.concatenate([z[1:] - z[:-1] - h / 2 * (w[:-1] + w[1:]), w[1:] - w[:-1] - h / 2 * (a[:-1] + a[1:])])
    z_m = (z[:-1] + z[1:]) / 2 + h / 8 * (w[:-1] - w[1:])
    w_m = (w[:-1] + w[1:]) / 2 + h / 8 * (a[:-1] - a[1:])
    a_m = numpy_accelerations(ARM, z_m, w_m, sol.torque_mid)
    return np.concatenate([z[1:] - z[:-1] - h / 6 * (w[:-1] + 4 * w_m + w[1:]),
                           w[1:] - w[:-1] - h / 6 * (a[:-1] + 4 * a_m + a[1:])])


@pytest.mark.parametrize("scheme", ["hermite-simpson", "trapezoidal"])
def test_defects_vanish_and_the_initial_state_is_the_motions(scheme):
    sol = ac.collocate(ARM, "reach", 40, scheme)
    assert sol.success, sol.message
    assert sol.angles.shape == sol.velocities.shape == sol.torque.shape == (41, 2)
    assert np.max(np.abs(defects(sol))) < 1e-8
    z0, w0, _ = Reach()(0.0)
    np.testing.assert_allclose(sol.angles[0], z0, atol=1e-12)
    np.testing.assert_allclose(sol.velocities[0], w0, atol=1e-12)
    assert sol.torque_function()(np.linspace(0, 1, 7)).shape == (7, 2)


def test_the_reach_is_tracked_by_the_collocation_and_by_its_replay():
    """Default options (100 intervals, Hermite-Simpson). Measured: 0.0005 deg at the nodes and
    0.0022 deg for the replay by the penalty formulation's RK4 (the open-loop arm amplifies the
    small difference between the two models); the bounds keep a margin of about 4."""
    outcome = run(collocate_spec(kinematics="reach", model_name="arm2"))
    record = outcome.record
    assert record["status"] == "success" and record["ipopt_status"] == "Solve_Succeeded", record["message"]
    assert record["t_end"] == pytest.approx(1.0) and record["nodes"] == 100 and record["scheme"] == "hermite-simpson"
    assert record["collocation_rmse_rot_deg"] < 0.002
    assert record["rmse_rot_deg"] < 0.01
    joints = np.array([record["rmse_rot_deg_shoulder"], record["rmse_rot_deg_elbow"]])
    assert record["rmse_rot_deg"] == pytest.approx(np.sqrt(np.mean(joints**2)), rel=1e-12)
    assert record["ipopt_iterations"] >= 1 and record["solve_time_s"] > 0 and record["runtime_s"] > 0


def local_errors(sol, up_to: float = 0.9) -> float:
    """The transcription's error over one interval: max over the intervals ending by ``up_to`` (s)
    of |x(t_k+1) - x_k+1| (rad/s), x the exact solution (DOP853, tight tolerances) of the equation
    of motion from node k's state driven by the solution's own torque. The free final state
    leaves the last nodes' torque to the regularisation, so the end of the motion is left out."""
    t, n = sol.t, len(sol.t) - 1
    torque = sol.torque_function()

    def rhs(s, y):
        z, w = y[: 2 * n].reshape(n, 2), y[2 * n :].reshape(n, 2)
        return np.concatenate([w.ravel(), numpy_accelerations(ARM, z, w, torque(t[:-1] + s)).ravel()])

    y0 = np.concatenate([sol.angles[:-1].ravel(), sol.velocities[:-1].ravel()])
    end = solve_ivp(rhs, (0.0, t[1] - t[0]), y0, method="DOP853", rtol=1e-13, atol=1e-14).y[:, -1]
    inside = t[1:] <= up_to + 1e-12
    return float(np.max(np.abs(end[2 * n :].reshape(n, 2) - sol.velocities[1:])[inside]))


def test_hermite_simpson_converges_faster_than_trapezoidal():
    """Local errors of O(h^3) (trapezoidal) and O(h^5) (Hermite-Simpson): the observed orders as
    the nodes double from 20 to 80."""
    orders = {}
    for scheme in ("trapezoidal", "hermite-simpson"):
        errors = np.array([local_errors(ac.collocate(ARM, "reach", n, scheme)) for n in (20, 40, 80)])
        orders[scheme] = np.log2(errors[:-1] / errors[1:])
    assert np.all((orders["trapezoidal"] > 2.5) & (orders["trapezoidal"] < 4.0)), orders
    assert np.all(orders["hermite-simpson"] > 4.0), orders
    assert np.all(orders["hermite-simpson"] > orders["trapezoidal"] + 1.0), orders


def test_with_the_shoulder_at_0_the_elbow_torque_is_the_forearms():
    """Shoulder held at 0 (tracked, not locked: it stays within 0.011 deg), elbow on eq. 5: the
    forearm part of the arm is Table 1's model with its elbow at (L01, 0), so the arm's elbow
    torque is the forearm collocation's (measured: within 0.0008 N m away from the free final
    state, against a torque range of 1.8 N m)."""
    arm = ac.collocate(ARM, PerJoint([0.0, "paper"]), 100, "hermite-simpson")
    forearm = collocate_forearm(Settings(kinematics="paper"), 100, "hermite-simpson")
    assert arm.success and forearm.success
    assert np.max(np.abs(np.degrees(arm.angles[:, 0]))) < 0.05
    inside = arm.t < 0.9
    np.testing.assert_allclose(arm.torque[inside, 1], forearm.torque[inside], atol=2e-3)
    np.testing.assert_allclose(arm.torque_mid[inside[:-1], 1], forearm.torque_mid[inside[:-1]], atol=2e-3)


def invoke(*args, code=0):
    result = runner.invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.stderr
    assert result.exit_code == code, (result.exit_code, result.stderr)
    return result


def test_collocate_on_the_arm_saves_a_torque_that_simulate_replays(tmp_path):
    path = tmp_path / "torque.csv"
    record = json.loads(invoke("collocate", "--model", "arm2", "--nodes", 50, "-f", "json", "--save-torque", path,
                               "--quiet").stdout)
    assert record["model"] == "arm2" and record["command"] == "collocate" and record["nodes"] == 50
    assert record["status"] == "success" and {"rmse_rot_deg_shoulder", "rmse_torque_nm_elbow"} <= set(record)
    table = pd.read_csv(path)
    assert list(table.columns) == ["t", "shoulder", "elbow"] and len(table) == 2001
    replay = json.loads(invoke("simulate", "--model", "arm2", "--torque-file", path, "-f", "json").stdout)
    for key in ("rmse_rot_deg", "rmse_torque_nm", "rmse_rot_deg_shoulder", "rmse_rot_deg_elbow"):
        assert replay[key] == pytest.approx(record[key], rel=1e-9), key


def test_an_iteration_limit_on_the_arm_is_a_status_with_a_message():
    record = json.loads(invoke("collocate", "--model", "arm2", "--max-iter", 1, "-f", "json").stdout)
    assert record["ipopt_status"] == "Maximum_Iterations_Exceeded" and record["status"] == "collocation_failed"
    assert "--max-iter" in record["message"] and np.isfinite(record["rmse_rot_deg"])


@pytest.mark.parametrize("args, word", [
    (["--nodes", 1], "--nodes"), (["--scheme", "euler"], "--scheme"), (["--regularization", -1], "--regularization"),
    (["--max-iter", 0], "--max-iter"), (["--max-time", 0], "--max-time"), (["--integrator", "dop853", "--atol", 2], "--atol"),
    (["--motion", "paper"], "--motion"), (["--model", "m0=-1"], "m0"),
])
def test_bad_collocate_options_on_the_arm_are_one_line_exit_2(args, word, tmp_path):
    out = tmp_path / "torque.csv"
    result = invoke("collocate", "--model", "arm2", *args, "--save-torque", out, code=2)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and word in lines[0], result.stderr
    assert result.stdout == "" and not out.exists()


def test_the_arms_beyond_the_paper_table_has_direct_collocation():
    from fdbench.beyond import beyond_methods

    specs = [m.spec for m in beyond_methods(kinematics="reach", model_name="arm2")]
    assert [s.command for s in specs] == ["control", "control", "collocate"]
    assert all(s.model_name == "arm2" for s in specs)
