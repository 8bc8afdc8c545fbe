"""Controllers (PD, computed-torque, LQR) on one compiled feedback law: closed-form error
dynamics, the algebraic Riccati equation, agreement of the compiled and scipy paths, and the
command line (registry, bad options)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict

import numpy as np
import pytest

from fdbench.experiment import OMITTED_AT_DEFAULT
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm, solve_continuous_are
from typer.testing import CliRunner

from fdbench import dynamics
from fdbench.cli import app
from fdbench.control import pd_control, track
from fdbench.controllers import CONTROLLERS, Controller, make_controller
from fdbench.controllers.lqr import riccati_gains
from fdbench.experiment import control_spec
from fdbench.indicators import rmse_rot_deg
from fdbench.integrate import (FeedbackLaw, Settings, constants, half_step_reference, initial_state, simulate,
                               steps)
from fdbench.inverse import Feedforward, inverse_dynamics
from fdbench.model import Forearm
from fdbench.motion import desired_motion, sample_times

runner = CliRunner()
MODEL = Forearm()
G = MODEL.F_ext * MODEL.L12 + MODEL.m * MODEL.g * MODEL.L1G  # N m, from Table 1


def perturbed_start(kinematics: str, offset: float) -> np.ndarray:
    """A state on the constraints with theta = theta_d(0) + offset and the desired velocity."""
    theta, w, _ = desired_motion(0.0, kinematics)
    q, qd, _ = MODEL.coordinates(theta + offset, w, 0.0)
    return np.concatenate([q, qd])


@pytest.mark.parametrize("bandwidth, damping", [(20.0, 1.0), (10.0, 1.0), (30.0, 0.5), (40.0, 1.5)])
def test_computed_torque_imposes_the_second_order_error_dynamics(bandwidth, damping):
    """Exact model, exact kinematics: e = theta_d - theta obeys e'' + 2 zeta w e' + w^2 e = 0,
    so from e(0) = e0, e'(0) = 0 it follows exp(A t) [e0, 0], A = [[0, 1], [-w^2, -2 zeta w]]."""
    e0 = 0.05  # rad
    settings = Settings(kinematics="exact")
    result = track(make_controller("computed-torque", bandwidth=bandwidth, damping=damping), settings,
                   start=perturbed_start("exact", -e0))
    assert result.success, result.message
    t = sample_times()
    error = desired_motion(t, "exact")[0] - result.theta
    A = np.array([[0.0, 1.0], [-bandwidth**2, -2 * damping * bandwidth]])
    expected = np.array([(expm(A * ti) @ [e0, 0.0])[0] for ti in t[::10]])
    assert np.max(np.abs(error[::10] - expected)) < 2e-4 * e0
    # the rate: after 8 time constants of the slowest pole the error is gone
    slow = bandwidth * (damping - np.sqrt(max(damping**2 - 1, 0.0)))
    late = t > 8 / slow
    assert np.max(np.abs(error[late])) < 0.01 * e0


@settings(max_examples=25)
@given(bandwidth=st.floats(8.0, 60.0), damping=st.floats(0.4, 1.5),
       e0=st.floats(-0.1, 0.1).filter(lambda v: abs(v) > 1e-3), kinematics=st.sampled_from(["exact"]))
def test_computed_torque_error_follows_the_closed_form_for_any_gains(bandwidth, damping, e0, kinematics):
    """The same property over many gains and offsets (the error dynamics are linear in e0)."""
    result = track(make_controller("computed-torque", bandwidth=bandwidth, damping=damping),
                   Settings(kinematics=kinematics), start=perturbed_start(kinematics, -e0))
    assert result.success, result.message
    t = sample_times()[::20]
    error = desired_motion(t, kinematics)[0] - result.theta[::20]
    A = np.array([[0.0, 1.0], [-bandwidth**2, -2 * damping * bandwidth]])
    expected = np.array([(expm(A * ti) @ [e0, 0.0])[0] for ti in t])
    assert np.max(np.abs(error - expected)) < 5e-4 * abs(e0)


def test_computed_torque_applies_its_formula():
    """The applied torque equals I1 (theta''_d + kp e + kd e') + G cos(theta) at every sample."""
    w, z = 20.0, 1.0
    result = track(make_controller("computed-torque", bandwidth=w, damping=z), Settings(kinematics="paper"))
    t = sample_times()
    th_d, w_d, a_d = desired_motion(t, "paper")
    theta, rate = result.q[:, 2], result.qd[:, 2]
    expected = MODEL.I1 * (a_d + w**2 * (th_d - theta) + 2 * z * w * (w_d - rate)) + G * np.cos(theta)
    assert np.max(np.abs(result.torque - expected)) < 1e-9


@pytest.mark.parametrize("theta0", [-0.6, 0.0, 0.4])
@pytest.mark.parametrize("q_angle, q_rate, r", [(1e4, 1.0, 1.0), (100.0, 0.0, 0.01), (1.0, 5.0, 3.0)])
def test_lqr_gains_converge_to_the_algebraic_riccati_solution(theta0, q_angle, q_rate, r):
    """Time-invariant linearisation about a fixed angle, a long horizon and P(T) = 0: K(0) is
    the infinite-horizon gain of scipy's solve_continuous_are."""
    a21 = G * np.sin(theta0) / MODEL.I1
    Q = np.diag([q_angle, q_rate])
    kp, kd = riccati_gains(lambda t: a21, MODEL.I1, Q, r, np.zeros((2, 2)), 0.0, 20.0)
    A = np.array([[0.0, 1.0], [a21, 0.0]])
    B = np.array([[0.0], [1.0 / MODEL.I1]])
    P = solve_continuous_are(A, B, Q, np.array([[r]]))
    K = (B.T @ P / r).ravel()
    got = np.array([kp(np.array([0.0]))[0], kd(np.array([0.0]))[0]])
    np.testing.assert_allclose(got, K, rtol=1e-5)
    # and it stabilises: the closed-loop matrix has eigenvalues in the left half-plane
    assert np.all(np.linalg.eigvals(A - B @ K[None, :]).real < 0)


def test_lqr_tracks_exact_motion_and_beats_open_loop_on_paper_motion():
    exact = Settings(kinematics="exact")
    inv = inverse_dynamics(kinematics="exact")
    assert rmse_rot_deg(track("lqr", exact), inv.theta) < 0.01
    paper = Settings(kinematics="paper")
    inv = inverse_dynamics(kinematics="paper")
    open_loop = rmse_rot_deg(simulate(Feedforward(MODEL, "paper"), paper), inv.theta)
    closed = track("lqr", paper)
    assert closed.success and rmse_rot_deg(closed, inv.theta) < open_loop / 2


def test_constant_gains_as_arrays_give_the_scalar_kernel_bit_for_bit():
    """PD through rk4_feedback with gain arrays on the half-step grid = the scalar rk4 kernel."""
    settings = Settings(kinematics="paper")
    n = steps(settings.dt)
    half, ref_th, ref_w = half_step_reference(n, settings.kinematics)
    tau = np.array(Feedforward(MODEL, "paper")(half))
    out = []
    for kp, kd in ((80.0, 0.3), (np.full(2 * n + 1, 80.0), np.full(2 * n + 1, 0.3))):
        buffers = (np.full((n + 1, 6), np.nan), np.full((n + 1, 3), np.nan), np.full(n + 1, np.nan))
        if np.ndim(kp) == 0:
            dynamics.rk4(initial_state("paper", MODEL), 1.0 / n, n, tau, ref_th, ref_w, kp, kd,
                         constants(settings), *buffers)
        else:
            dynamics.rk4_feedback(initial_state("paper", MODEL), 1.0 / n, n, tau, ref_th, ref_w, kp, kd, 0.0,
                                  constants(settings), *buffers)
        out.append(buffers)
    for a, b in zip(*out):
        assert np.array_equal(a, b)
    # and the law with gains as functions of time agrees with the constant gains
    law = FeedbackLaw(lambda t: np.full_like(t, 80.0), lambda t: np.full_like(t, 0.3))
    by_law = simulate(Feedforward(MODEL, "paper"), settings, law=law)
    assert np.array_equal(by_law.q, pd_control(80.0, 0.3, settings).q)


@pytest.mark.parametrize("name", ["computed-torque", "lqr"])
def test_scipy_integrator_agrees_with_compiled_rk4(name):
    """The Python path of the adaptive integrators evaluates the same law as the kernel."""
    inv = inverse_dynamics(kinematics="paper")
    rk4 = track(name, Settings(kinematics="paper"))
    dop = track(name, Settings(kinematics="paper", integrator="dop853", rtol=1e-9, atol=1e-12))
    assert dop.success and rk4.success
    assert np.max(np.abs(np.degrees(rk4.theta - dop.theta))) < 1e-5
    assert abs(rmse_rot_deg(rk4, inv.theta) - rmse_rot_deg(dop, inv.theta)) < 1e-6


def test_pd_spec_hash_is_that_of_the_first_release():
    """Fields added for new methods stay out of the hash at their defaults: stored PD runs are reused."""
    spec = control_spec(80.0, 0.3)
    old = {k: v for k, v in asdict(spec).items() if k not in OMITTED_AT_DEFAULT}
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

    def design(self, settings):
        return Feedforward(settings.model, settings.kinematics), FeedbackLaw()


def test_a_registered_controller_reaches_the_command_line():
    CONTROLLERS.register("open-loop-test")(OpenLoop)
    try:
        result = runner.invoke(app, ["control", "--controller", "open-loop-test", "-f", "json"])
        assert result.exit_code == 0, result.stderr
        record = json.loads(result.stdout)
        assert record["controller"] == "open-loop-test"
        simulated = json.loads(runner.invoke(app, ["simulate", "-f", "json"]).stdout)
        assert record["rmse_rot_deg"] == pytest.approx(simulated["rmse_rot_deg"], rel=1e-12)
        assert "open-loop-test" in runner.invoke(app, ["methods"]).stdout
    finally:
        CONTROLLERS.unregister("open-loop-test")
    bad_input(["control", "--controller", "open-loop-test"], "--controller")


@pytest.mark.parametrize("name", ["pd", "computed-torque", "lqr"])
def test_every_controller_reports_the_contract_keys(name):
    result = runner.invoke(app, ["control", "--controller", name, "--kinematics", "exact", "-f", "json"])
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["controller"] == name and record["status"] == "success"
    assert record["rmse_rot_deg"] < 0.01 and record["runtime_s"] > 0
