"""Forward dynamics (eq. 12) and its integration, checked against a direct linear solve, the
inverse-dynamics motion, convergence orders, a second integrator and the paper's figures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdbench.control import pd_control
from fdbench.dynamics import accelerations, kernel_constants
from fdbench.indicators import rmse_rot_deg, rmse_torque_nm
from fdbench.integrate import Settings, Status, simulate
from fdbench.inverse import Feedforward, inverse_dynamics
from fdbench.model import Forearm, Penalty
from fdbench.motion import desired_motion, sample_times

KINEMATICS = ("paper", "exact")
# the paper's published PD figures (section 5): RMSE_rot = 0.116 deg, RMSE_torque = 0.149 N m
PAPER_RMSE_ROT_DEG = 0.116
PAPER_RMSE_TORQUE_NM = 0.149


def reference(kinematics):
    inv = inverse_dynamics(kinematics=kinematics)
    return inv.theta, inv.torque


def indicators(result, kinematics):
    theta, torque = reference(kinematics)
    return rmse_rot_deg(result, theta), rmse_torque_nm(result, torque)


@pytest.fixture(scope="module")
def pd_runs():
    """PD control (kp 80, kd 0.3) with compiled RK4 (dt 1 ms) and tight scipy RK45, per kinematics."""
    runs = {}
    for kinematics in KINEMATICS:
        rk4 = pd_control(80.0, 0.3, Settings(kinematics=kinematics))
        rk45 = pd_control(80.0, 0.3, Settings(kinematics=kinematics, integrator="rk45", rtol=1e-10, atol=1e-12))
        runs[kinematics] = (rk4, rk45)
    return runs


# ----------------------------------------------------------------------------- eq. 12


def numpy_accelerations(model: Forearm, penalty: Penalty, q, qd, tau):
    """q'' of eq. 12 by a dense solve, assembled from the model's own matrices."""
    J = model.jacobian(q)
    phi = model.constraints(q)
    phi_dot = J @ qd
    lhs = model.mass_matrix() + penalty.alpha * J.T @ J
    Q = model.external_forces() + np.array([0.0, 0.0, tau])  # eq. 13 with Q_m = [0, 0, tau]
    rhs = Q - penalty.alpha * J.T @ (
        model.jacobian_dot_qdot(q, qd) + 2 * penalty.xi * penalty.omega * phi_dot + penalty.omega**2 * phi
    )
    return np.linalg.solve(lhs, rhs)


@settings(max_examples=200, deadline=None)
@given(
    theta=st.floats(-1.4, 1.4),
    dx=st.floats(-1e-3, 1e-3),
    dy=st.floats(-1e-3, 1e-3),
    v=st.tuples(*[st.floats(-5.0, 5.0)] * 3),
    tau=st.floats(-50.0, 50.0),
    log_alpha=st.floats(3.0, 5.0),
    xi=st.floats(0.0, 2.0),
    omega=st.floats(1.0, 50.0),
    F_ext=st.floats(0.0, 30.0),
)
def test_compiled_accelerations_match_dense_solve(theta, dx, dy, v, tau, log_alpha, xi, omega, F_ext):
    model = Forearm(F_ext=F_ext)
    penalty = Penalty(alpha=10.0**log_alpha, xi=xi, omega=omega)
    q = np.array([model.L12 * math.cos(theta) + dx, model.L12 * math.sin(theta) + dy, theta])
    qd = np.array(v)
    expected = numpy_accelerations(model, penalty, q, qd, tau)
    ax, ay, ath, cos_theta = accelerations(*q, *qd, tau, kernel_constants(model, penalty))
    assert cos_theta == pytest.approx(math.cos(theta), rel=1e-12)
    got = np.array([ax, ay, ath])
    scale = np.max(np.abs(expected))
    np.testing.assert_allclose(got, expected, rtol=1e-7, atol=1e-9 * scale)


def test_accelerations_flag_singular_theta():
    consts = kernel_constants(Forearm(), Penalty())
    L = Forearm().L12
    for theta in (math.pi / 2, -math.pi / 2 + 1e-5):
        *_, cos_theta = accelerations(0.0, L * math.sin(theta), theta, 0.0, 0.0, 0.0, 1.0, consts)
        assert abs(cos_theta) < consts[6]  # the caller's test for the singular leading matrix


# ----------------------------------------------------------------------------- open loop


def test_open_loop_exact_inverse_torque_reproduces_exact_motion():
    """Inverse dynamics and forward dynamics are inverses when the kinematics is consistent."""
    settings_ = Settings(kinematics="exact")
    result = simulate(Feedforward(settings_.model, "exact"), settings_)
    assert result.success, result.message
    theta, torque = reference("exact")
    assert rmse_rot_deg(result, theta) < 1e-4
    # open loop: the applied torque is the inverse-dynamics torque itself
    np.testing.assert_allclose(result.torque, torque, rtol=0, atol=1e-12)
    assert np.max(np.abs(np.degrees(result.theta - theta))) < 1e-4


# ----------------------------------------------------------------------------- convergence


def end_state(integrator, dt=1e-3):
    settings_ = Settings(kinematics="paper", integrator=integrator, dt=dt, rtol=1e-12, atol=1e-13)
    result = simulate(Feedforward(settings_.model, "paper"), settings_, 80.0, 0.3)
    assert result.success, result.message
    assert result.t[-1] == 1.0
    return np.concatenate([result.q[-1], result.qd[-1]])


def test_rk4_fourth_order_convergence():
    """PD-controlled paper motion (smooth torque, no penalty transient since the initial state
    is consistent): the end-state error of RK4 falls by 2^4 per halving of dt."""
    exact = end_state("rk4", 1 / 4000)
    # the fine RK4 reference agrees with an independent high-order adaptive integrator
    np.testing.assert_allclose(end_state("dop853"), exact, rtol=0, atol=1e-8)
    errors = [np.linalg.norm(end_state("rk4", dt) - exact) for dt in (1 / 125, 1 / 250, 1 / 500)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 3.5) & (orders < 4.5)), (errors, orders)


# ----------------------------------------------------------------------------- RK4 vs RK45


@pytest.mark.parametrize("kinematics", KINEMATICS)
def test_rk4_and_rk45_agree(pd_runs, kinematics):
    rk4, rk45 = pd_runs[kinematics]
    assert rk4.success and rk45.success
    assert rk4.integrator == "rk4" and rk45.integrator == "rk45"
    rot4, tor4 = indicators(rk4, kinematics)
    rot45, tor45 = indicators(rk45, kinematics)
    # With exact kinematics both errors are ~1e-7 (truncation noise of each integrator), where a
    # relative comparison means nothing: the absolute floor covers that case.
    assert rot4 == pytest.approx(rot45, rel=1e-4, abs=1e-6)
    assert tor4 == pytest.approx(tor45, rel=1e-4, abs=1e-6)
    # the trajectories themselves agree, sample by sample
    np.testing.assert_allclose(rk4.q, rk45.q, rtol=0, atol=1e-8)
    np.testing.assert_allclose(rk4.torque, rk45.torque, rtol=0, atol=1e-6)


def test_constraint_violation_small_in_default_pd_run():
    result = pd_control()
    assert result.success
    assert result.max_violation < 1e-6
    # checked independently on the samples with the model's constraint equations
    assert np.max(np.abs(Forearm().constraints(result.q))) < 1e-6


# ----------------------------------------------------------------------------- failure


def constant_torque(value):
    return lambda t: np.full_like(np.asarray(t, dtype=float), value)


@pytest.mark.parametrize("integrator", ["rk4", "rk45"])
def test_large_torque_stops_the_simulation(integrator):
    """200 N m against a ~6 N m load swings the forearm up through theta = pi/2 in ~30 ms."""
    result = simulate(constant_torque(200.0), Settings(integrator=integrator))
    assert not result.success
    assert result.status is not Status.SUCCESS
    assert 0.0 < result.t_end < 0.1
    assert result.status.value in result.message
    assert "stopped at t" in result.message
    if result.status is Status.SINGULAR:
        assert "pi/2" in result.message
    t = result.t
    after = t > result.t_end + 1e-9
    before = t <= result.t_end - 1e-9
    assert after.sum() > 900
    assert np.all(np.isnan(result.q[after])) and np.all(np.isnan(result.qd[after]))
    assert np.all(np.isnan(result.torque[after]))
    assert np.all(np.isfinite(result.q[before])) and np.all(np.isfinite(result.torque[before]))
    assert np.array_equal(result.reached, ~after)
    theta, torque = reference("paper")
    rot, tor = rmse_rot_deg(result, theta), rmse_torque_nm(result, torque)
    assert math.isfinite(rot) and math.isfinite(tor)
    # the forearm was swinging up towards pi/2 when the simulation stopped
    assert np.nanmax(result.theta) > 1.0


@pytest.mark.parametrize("torque", [10.0, 50.0, 200.0])
def test_rk4_stops_at_the_singularity_like_adaptive_solvers(torque):
    rk4 = simulate(constant_torque(torque), Settings())
    dop = simulate(constant_torque(torque), Settings(integrator="dop853"))
    assert dop.status is Status.SINGULAR
    assert rk4.status is Status.SINGULAR
    assert np.nanmax(rk4.theta) < math.pi / 2
    assert abs(rk4.t_end - dop.t_end) <= 2e-3


# ----------------------------------------------------------------------------- paper figures


def test_pd_exact_kinematics_tracks_almost_perfectly(pd_runs):
    rot, tor = indicators(pd_runs["exact"][0], "exact")
    assert rot < 0.01
    assert tor < 0.01


def test_pd_paper_kinematics_reproduces_published_figures(pd_runs):
    rot, tor = indicators(pd_runs["paper"][0], "paper")
    assert rot == pytest.approx(PAPER_RMSE_ROT_DEG, rel=0.05)
    assert tor == pytest.approx(PAPER_RMSE_TORQUE_NM, rel=0.05)


# ----------------------------------------------------------------------------- step size


@pytest.mark.parametrize("dt", [0.0015, 0.002, 0.0003])
def test_step_not_dividing_the_sampling_still_gives_1001_samples(pd_runs, dt):
    result = pd_control(80.0, 0.3, Settings(kinematics="paper", dt=dt))
    assert result.success
    assert result.t.shape == (1001,) and result.q.shape == (1001, 3) and result.torque.shape == (1001,)
    np.testing.assert_allclose(result.t, sample_times(), atol=0)
    assert np.all(np.isfinite(result.q)) and np.all(np.isfinite(result.torque))
    rot, tor = indicators(result, "paper")
    rot_1ms, tor_1ms = indicators(pd_runs["paper"][0], "paper")
    assert rot == pytest.approx(rot_1ms, rel=1e-3)
    assert tor == pytest.approx(tor_1ms, rel=1e-3)
    # the resampled states are close to the 1 ms run sample by sample
    np.testing.assert_allclose(result.q, pd_runs["paper"][0].q, rtol=0, atol=1e-6)


def test_simulated_start_is_the_desired_start():
    for kinematics in KINEMATICS:
        result = pd_control(settings=Settings(kinematics=kinematics))
        theta0, w0, _ = desired_motion(0.0, kinematics)
        assert result.theta[0] == pytest.approx(float(theta0), abs=1e-15)
        assert result.qd[0, 2] == pytest.approx(float(w0), abs=1e-15)


@pytest.mark.parametrize("integrator", ["rk4", "rk45"])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_non_finite_torque_is_reported_as_non_finite(integrator, value):
    result = simulate(constant_torque(value), Settings(integrator=integrator))
    assert result.status is Status.NONFINITE
    assert result.t_end < 1 and "non-finite" in result.message
