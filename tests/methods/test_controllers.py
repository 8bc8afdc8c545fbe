"""Controllers (PD, computed-torque, LQR) designed once and applied by the engine's compiled
feedback laws, on the paper's forearm: closed-form error dynamics, the forearm's closed-form
torque, the algebraic Riccati equation of its closed-form linearisation, and the command line
(registry, bad options)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm, solve_continuous_are
from typer.testing import CliRunner

from helpers import forearm_closed_form as cf
from fdbench.cli import app
from fdbench.controllers import CONTROLLERS, Controller, make_controller
from fdbench.controllers.base import Design, Plan
from fdbench.spec import OMITTED_AT_DEFAULT, control_spec
from fdbench.models import with_changes
from fdbench.multibody.motions import desired_motion, sample_times
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import PerJoint, joint_motion

runner = CliRunner()
MODEL = find_model("forearm")
ENGINE = Engine(MODEL)
G = cf.load_moment()  # N m, from Table 1


def plan(kinematics: str = "paper", model=MODEL) -> Plan:
    return Plan(Engine(model) if model is not MODEL else ENGINE, model, joint_motion(kinematics, model))


def track(controller, kinematics: str = "paper", start=None, **options) -> sim.Simulation:
    """The forearm under ``controller`` (a name or an instance) towards eq. 5, as a run applies it."""
    controller = make_controller(controller) if isinstance(controller, str) else controller
    known = plan(kinematics)
    design = controller.design(known)
    return sim.simulate(design.feedforward, ENGINE, known.motion, design.kp, design.kd, gains=design.gains,
                        computed=design.computed, start=start, **options)


def perturbed_start(kinematics: str, offset: float) -> np.ndarray:
    """A state on the constraints with theta = theta_d(0) + offset (rad) and the desired velocity."""
    theta, w, _ = desired_motion(0.0, kinematics)
    return ENGINE.state_from_joints([float(theta) + offset], [float(w)])


def desired_theta(kinematics: str) -> np.ndarray:
    return desired_motion(sample_times(), kinematics)[0][:, None]


@pytest.mark.parametrize("bandwidth, damping", [(20.0, 1.0), (10.0, 1.0), (30.0, 0.5), (40.0, 1.5)])
def test_computed_torque_imposes_the_second_order_error_dynamics(bandwidth, damping):
    """Exact model, exact kinematics: e = theta_d - theta obeys e'' + 2 zeta w e' + w^2 e = 0,
    so from e(0) = e0, e'(0) = 0 it follows exp(A t) [e0, 0], A = [[0, 1], [-w^2, -2 zeta w]]."""
    e0 = 0.05  # rad
    result = track(make_controller("computed-torque", bandwidth=bandwidth, damping=damping), "exact",
                   start=perturbed_start("exact", -e0))
    assert result.success, result.status
    t = sample_times()
    error = desired_motion(t, "exact")[0] - result.z[:, 0]
    A = np.array([[0.0, 1.0], [-bandwidth**2, -2 * damping * bandwidth]])
    expected = np.array([(expm(A * ti) @ [e0, 0.0])[0] for ti in t[::10]])
    assert np.max(np.abs(error[::10] - expected)) < 2e-4 * e0
    # the rate: after 8 time constants of the slowest pole the error is gone
    slow = bandwidth * (damping - np.sqrt(max(damping**2 - 1, 0.0)))
    late = t > 8 / slow
    assert np.max(np.abs(error[late])) < 0.01 * e0


@settings(max_examples=25, deadline=None)
@given(bandwidth=st.floats(8.0, 60.0), damping=st.floats(0.4, 1.5),
       e0=st.floats(-0.1, 0.1).filter(lambda v: abs(v) > 1e-3))
def test_computed_torque_error_follows_the_closed_form_for_any_gains(bandwidth, damping, e0):
    """The same property over many gains and offsets (the error dynamics are linear in e0)."""
    result = track(make_controller("computed-torque", bandwidth=bandwidth, damping=damping), "exact",
                   start=perturbed_start("exact", -e0))
    assert result.success, result.status
    t = sample_times()[::20]
    error = desired_motion(t, "exact")[0] - result.z[::20, 0]
    A = np.array([[0.0, 1.0], [-bandwidth**2, -2 * damping * bandwidth]])
    expected = np.array([(expm(A * ti) @ [e0, 0.0])[0] for ti in t])
    assert np.max(np.abs(error - expected)) < 5e-4 * abs(e0)


def test_computed_torque_applies_its_formula():
    """The applied torque equals I1 (theta''_d + kp e + kd e') + G cos(theta) at every sample (the
    closed form's; 1e-9 N m: the engine's inverse dynamics is the closed form to rounding)."""
    w, z = 20.0, 1.0
    result = track(make_controller("computed-torque", bandwidth=w, damping=z), "paper")
    th_d, w_d, a_d = desired_motion(sample_times(), "paper")
    theta, rate = result.z[:, 0], result.zd[:, 0]
    expected = cf.I1 * (a_d + w**2 * (th_d - theta) + 2 * z * w * (w_d - rate)) + G * np.cos(theta)
    assert np.max(np.abs(result.torque[:, 0] - expected)) < 1e-9


@pytest.mark.parametrize("I1, kp, kd", [(0.04, 80.0, 0.3), (0.08, 160.0, 0.6), (0.02, 40.0, 0.15)])
def test_pd_gains_are_the_papers_scaled_by_the_elbow_inertia(I1, kp, kd):
    """The paper's 80 N m/rad and 0.3 N m s/rad were tuned for I1 = 0.04 kg m^2: a forearm of
    another inertia gets them scaled by I1 / 0.04; given gains are taken as they are."""
    design = make_controller("pd").design(plan(model=with_changes("forearm", (("I1", I1),))))
    np.testing.assert_allclose([design.kp[0], design.kd[0]], [kp, kd], rtol=1e-12)
    given_gains = make_controller("pd", kp=50.0, kd=1.0).design(plan())
    assert (given_gains.kp[0], given_gains.kd[0]) == (50.0, 1.0)


@pytest.mark.parametrize("theta0", [-0.6, 0.0, 0.4])
@pytest.mark.parametrize("q_angle, q_rate, r", [(1e4, 1.0, 1.0), (100.0, 0.0, 0.01), (1.0, 5.0, 3.0)])
def test_lqr_gains_about_a_held_angle_are_the_algebraic_riccati_solution(theta0, q_angle, q_rate, r):
    """About a held angle the forearm's linearisation is the closed form's, theta'' = (G sin(theta0)
    / I1) dtheta + dtau / I1: the LQR gain is the infinite-horizon gain of scipy's
    solve_continuous_are (rtol 1e-5: the Riccati ODE's tolerance 1e-8, its horizon ~20 time constants)."""
    from fdbench.multibody.lqr import lqr_gains

    held = PerJoint([theta0], MODEL.coordinates)
    a21 = G * np.sin(theta0) / cf.I1
    A = np.array([[0.0, 1.0], [a21, 0.0]])
    B = np.array([[0.0], [1.0 / cf.I1]])
    Q = np.diag([q_angle, q_rate])
    P = solve_continuous_are(A, B, Q, np.array([[r]]))
    K = (B.T @ P / r).ravel()
    got = lqr_gains(MODEL, held, q_angle, q_rate, r)(np.array([0.0]))
    assert got.shape == (1, 1, 2)
    np.testing.assert_allclose(got[0, 0], K, rtol=1e-5)
    # and it stabilises: the closed-loop matrix has eigenvalues in the left half-plane
    assert np.all(np.linalg.eigvals(A - B @ K[None, :]).real < 0)


def test_lqr_tracks_exact_motion_and_beats_open_loop_on_paper_motion():
    assert sim.rmse_deg(track("lqr", "exact"), desired_theta("exact"))[0] < 0.01
    paper = joint_motion("paper", MODEL)
    open_loop = sim.rmse_deg(sim.simulate(sim.feedforward(ENGINE, paper), ENGINE, paper), desired_theta("paper"))[0]
    closed = track("lqr", "paper")
    assert closed.success and sim.rmse_deg(closed, desired_theta("paper"))[0] < open_loop / 2


def test_pd_spec_hash_is_that_of_the_first_release():
    """Fields added for new methods stay out of the hash at their defaults: stored PD runs are reused."""
    spec = control_spec(80.0, 0.3)
    old = {k: v for k, v in spec.as_dict().items() if k not in OMITTED_AT_DEFAULT}
    digest = hashlib.sha256(json.dumps(old, sort_keys=True, default=str).encode()).hexdigest()[:16]
    assert spec.hash() == digest
    assert control_spec(controller="lqr").hash() != control_spec(controller="computed-torque").hash()


def bad_input(args, *words):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 2, (result.exit_code, result.stderr)
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:"), result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0]


@pytest.mark.parametrize("args, words", [
    (["--controller", "computed-torque", "--bandwidth", -1], ["--bandwidth"]),
    (["--bandwidth", "-5"], ["--bandwidth"]),
    (["--controller", "computed-torque", "--damping", "nan"], ["--damping"]),
    (["--controller", "lqr", "--r-torque", 0], ["--r-torque"]),
    (["--controller", "lqr", "--q-angle", 0], ["--q-angle"]),
    (["--controller", "lqr", "--q-rate", -1], ["--q-rate"]),
    (["--controller", "lqx"], ["--controller", "lqr"]),
    (["--kp", "-1"], ["--kp"]),
])
def test_bad_controller_options_are_one_line_exit_2(args, words, tmp_path):
    out = tmp_path / "out.json"
    bad_input(["control", *args, "--output", out], *words)
    assert not out.exists()


class OpenLoop(Controller):
    """The inverse-dynamics torque without feedback: the same as 'fdbench simulate'."""

    summary = "open loop (a test controller)"

    def design(self, plan):
        return Design(plan.feedforward())


def test_a_registered_controller_reaches_the_command_line():
    CONTROLLERS.register("open-loop-test")(OpenLoop)
    try:
        result = runner.invoke(app, ["control", "--controller", "open-loop-test", "-f", "json"])
        assert result.exit_code == 0, result.stderr
        record = json.loads(result.stdout)
        simulated = json.loads(runner.invoke(app, ["simulate", "-f", "json"]).stdout)
        assert record["rmse_rot_deg"] == pytest.approx(simulated["rmse_rot_deg"], rel=1e-12)
        assert "open-loop-test" in runner.invoke(app, ["methods"]).stdout
    finally:
        CONTROLLERS.unregister("open-loop-test")
    bad_input(["control", "--controller", "open-loop-test"], "--controller")


def test_a_registered_controller_is_recorded_under_its_registered_name():
    CONTROLLERS.register("open-loop-test")(OpenLoop)
    try:
        result = runner.invoke(app, ["control", "--controller", "open-loop-test", "-f", "json"])
        assert result.exit_code == 0, result.stderr
        assert json.loads(result.stdout)["controller"] == "open-loop-test"
    finally:
        CONTROLLERS.unregister("open-loop-test")


@pytest.mark.parametrize("name", ["pd", "computed-torque", "lqr"])
def test_every_controller_reports_the_contract_keys(name):
    result = runner.invoke(app, ["control", "--controller", name, "--kinematics", "exact", "-f", "json"])
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["controller"] == name and record["status"] == "success"
    assert record["rmse_rot_deg"] < 0.01 and record["runtime_s"] > 0


def test_pd_defaults_on_a_floating_base_are_critically_damped_on_each_coordinates_effective_inertia():
    """On a model with a floating base PD's default gains are kp = I_j w^2 and kd = 2 I_j w, with
    I_j = 1 / [M^-1]_jj of the independent reference's mass matrix at the motion's start and w the
    paper's sqrt(80 / 0.04) rad/s; given gains stay as given."""
    from helpers import reference_dynamics as ref
    from helpers.models import hopper_model

    from fdbench.controllers.base import Plan
    from fdbench.controllers.pd import PD
    from fdbench.multibody.engine import Engine
    from fdbench.multibody.motions import PerJoint

    model = hopper_model()
    start = np.array([0.1, 0.02, -0.01, 0.3, -0.5])
    motion = PerJoint(list(start), model.coordinates)
    kp, kd = PD().gains(Plan(Engine(model), model, motion))
    inertia = 1.0 / np.diag(np.linalg.inv(ref.GeneralTree(model).mass_matrix(start)))
    omega = np.sqrt(80.0 / 0.04)
    np.testing.assert_allclose(kp, inertia * omega**2, rtol=1e-9)
    np.testing.assert_allclose(kd, 2 * inertia * omega, rtol=1e-9)
    assert np.all(PD(kp=50.0, kd=2.0).gains(Plan(Engine(model), model, motion))[0] == 50.0)
