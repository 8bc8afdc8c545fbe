"""The engine's forward dynamics (eq. 12) of the paper's forearm and its integration, checked against
the forearm's closed form, the inverse-dynamics motion, convergence orders, a second integrator,
scipy's DOP853 on the minimal ODE and the paper's figures.

Tolerances. Eq. 12's leading matrix has a condition number near alpha L12^4 / I1 (about 3e6 with
alpha 1e7), so float64 solves are accurate to ~1e-9 relative; the penalty formulation's solution is
the constrained one's to O(m_eff / (alpha L12^2)) with m_eff = I1 / L12^2 (its constraint force
divided by alpha: ~3 / alpha relative), hence 1e-8 + 30 / alpha relative on the accelerations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import forearm_closed_form as cf
from fdbench.integrate import Status
from fdbench.models import with_changes
from fdbench.multibody.motions import desired_motion, sample_times
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion

KINEMATICS = ("paper", "exact")
# the paper's published PD figures (section 5): RMSE_rot = 0.116 deg, RMSE_torque = 0.149 N m
PAPER_RMSE_ROT_DEG = 0.116
PAPER_RMSE_TORQUE_NM = 0.149
MODEL = find_model("forearm")
ENGINE = Engine(MODEL)


def motion(kinematics):
    return joint_motion(kinematics, MODEL)


def reference(kinematics):
    """The desired angles (rad) and the closed-form elbow torques (N m) on the samples, shape (1001, 1)."""
    theta, _, dw = desired_motion(sample_times(), kinematics)
    return theta[:, None], cf.elbow_torque(theta, dw)[:, None]


def indicators(result, kinematics):
    theta, torque = reference(kinematics)
    return sim.rmse_deg(result, theta)[0], sim.rmse_torque_nm(result, torque)[0]


def pd_control(kinematics="paper", **options):
    """The paper's PD (kp 80 N m/rad, kd 0.3 N m s/rad) on the feedforward of the motion."""
    m = motion(kinematics)
    return sim.simulate(sim.feedforward(ENGINE, m), ENGINE, m, 80.0, 0.3, **options)


@pytest.fixture(scope="module")
def pd_runs():
    """PD control with compiled RK4 (dt 1 ms) and tight scipy RK45, per kinematics."""
    return {k: (pd_control(k), pd_control(k, integrator="rk45", rtol=1e-10, atol=1e-12)) for k in KINEMATICS}


# ----------------------------------------------------------------------------- eq. 12


@settings(max_examples=100, deadline=None)
@given(
    theta=st.floats(-math.pi, math.pi),
    w=st.floats(-5.0, 5.0),
    tau=st.floats(-50.0, 50.0),
    log_alpha=st.floats(5.0, 9.0),
    xi=st.floats(0.0, 2.0),
    omega=st.floats(1.0, 50.0),
    F_ext=st.floats(0.0, 30.0),
)
def test_accelerations_on_the_manifold_are_the_minimal_odes(theta, w, tau, log_alpha, xi, omega, F_ext):
    """On consistent coordinates eq. 12 gives theta'' = (tau - G cos theta) / I1 for any penalty
    (also at theta = +-pi/2, where the paper's closed-form solve was singular), and the hand's
    accelerations are those of a point turning at radius L12."""
    engine = Engine(with_changes("forearm", (("F_ext", F_ext),)), 10.0**log_alpha, xi, omega)
    y = engine.state_from_joints([theta], [w])
    x_dd, y_dd, theta_dd = engine.accelerations(y, [tau])[3:]
    expected = (tau - cf.load_moment(F_ext=F_ext) * math.cos(theta)) / cf.I1
    scale = (abs(tau) + cf.load_moment(F_ext=F_ext)) / cf.I1 + w * w
    # the penalty's departure falls as 1/alpha; rounding grows as alpha (the leading matrix's
    # condition number is about alpha L12^2 / I1): at alpha 1e9, 1e-15 alpha is 1e-6 of the scale
    tolerance = (1e-8 + 30.0 / 10.0**log_alpha + 1e-15 * 10.0**log_alpha) * scale
    assert abs(theta_dd - expected) <= tolerance
    s, c = math.sin(theta), math.cos(theta)
    hand = cf.L12 * np.array([-s * expected - c * w * w, c * expected - s * w * w])  # m/s^2, turning at radius L12
    np.testing.assert_allclose([x_dd, y_dd], hand, rtol=0, atol=tolerance * cf.L12)


# ----------------------------------------------------------------------------- open loop


def test_open_loop_exact_inverse_torque_reproduces_exact_motion():
    """Inverse dynamics and forward dynamics are inverses when the kinematics is consistent."""
    m = motion("exact")
    result = sim.simulate(sim.feedforward(ENGINE, m), ENGINE, m)
    assert result.success, result.status
    theta, torque = reference("exact")
    assert sim.rmse_deg(result, theta)[0] < 1e-4
    # open loop: the applied torque is the inverse-dynamics torque, the closed form's to rounding
    np.testing.assert_allclose(result.torque, torque, rtol=0, atol=1e-10)
    assert np.max(np.abs(np.degrees(result.z - theta))) < 1e-4


# ----------------------------------------------------------------------------- convergence


def end_state(integrator, dt=1e-3):
    m = motion("paper")
    result = sim.simulate(sim.feedforward(ENGINE, m), ENGINE, m, 80.0, 0.3, dt=dt, integrator=integrator,
                          rtol=1e-12, atol=1e-13)
    assert result.success, result.status
    assert result.t[-1] == 1.0
    return result.states[-1]


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
    np.testing.assert_allclose(rk4.states, rk45.states, rtol=0, atol=1e-7)
    np.testing.assert_allclose(rk4.torque, rk45.torque, rtol=0, atol=1e-6)


def test_constraint_violation_small_in_default_pd_run(pd_runs):
    result = pd_runs["paper"][0]
    assert result.success
    assert result.max_violation < 1e-6
    # checked independently on the samples: the hand is L12 from the elbow, along the forearm's angle
    hand = cf.L12 * np.stack([np.cos(result.z[:, 0]), np.sin(result.z[:, 0])], -1)
    assert np.max(np.abs(result.states[:, :2] - hand)) < 1e-6


# ----------------------------------------------------------------------------- through pi/2


class HeldStill:
    """The elbow held at -pi/4 over 0.1 s, sampled every 1 ms: a motion to start from (rad)."""

    name, duration, joints = "held", 0.1, ("theta",)
    samples = np.linspace(0.0, 0.1, 101)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        return np.full(t.shape + (1,), -math.pi / 4), np.zeros(t.shape + (1,)), np.zeros(t.shape + (1,))


def constant_torque(value):
    return lambda t: np.full((len(np.asarray(t)), 1), value)


@pytest.mark.parametrize("integrator", ["rk4", "rk45"])
def test_a_large_torque_swings_the_forearm_through_pi_2_as_the_minimal_ode_does(integrator):
    """50 N m against a ~6 N m load swings the forearm up through theta = pi/2 (the paper's singular
    configuration) at ~50 ms; the engine has none and follows scipy's DOP853 on the minimal ODE
    I1 theta'' = tau - G cos(theta), to the penalty formulation's O(1/alpha) error (the constraint
    force at ~130 rad/s, ~1e3 N, over alpha): ~1e-4 rad at alpha 1e7, 100 times less at 1e9.
    RK4 at 0.1 ms (a local error near 1e-10 rad per step) and RK45 at rtol 1e-10 add far less."""
    from scipy.integrate import solve_ivp

    ode = solve_ivp(cf.minimal_rhs(lambda t: 50.0), (0.0, 0.1), [-math.pi / 4, 0.0], method="DOP853",
                    t_eval=HeldStill.samples, rtol=1e-12, atol=1e-12)
    errors = []
    for alpha in (1e7, 1e9):
        result = sim.simulate(constant_torque(50.0), Engine(MODEL, alpha), HeldStill(), dt=1e-4,
                              integrator=integrator, rtol=1e-10, atol=1e-12)
        assert result.success, (result.status, result.detail)
        assert np.max(result.z) > math.pi / 2 + 1.0
        errors.append((np.max(np.abs(result.z[:, 0] - ode.y[0])), np.max(np.abs(result.zd[:, 0] - ode.y[1]))))
    (angle_7, rate_7), (angle_9, rate_9) = errors
    assert angle_9 < 2e-6 and rate_9 < 4e-4, errors
    assert 50 < angle_7 / angle_9 < 200 and 50 < rate_7 / rate_9 < 200, errors


# ----------------------------------------------------------------------------- failure


@pytest.mark.parametrize("integrator", ["rk4", "rk45"])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_non_finite_torque_is_reported_as_non_finite(integrator, value):
    result = sim.simulate(constant_torque(value), ENGINE, motion("paper"), integrator=integrator)
    assert result.status is Status.NONFINITE
    assert result.t_end < 1
    after = result.t > result.t_end + 1e-9
    assert after.sum() > 900
    assert np.all(np.isnan(result.z[after])) and np.all(np.isnan(result.torque[after]))
    assert np.array_equal(result.reached, ~after)


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
    result = pd_control("paper", dt=dt)
    assert result.success
    assert result.t.shape == (1001,) and result.z.shape == (1001, 1) and result.torque.shape == (1001, 1)
    np.testing.assert_allclose(result.t, sample_times(), atol=0)
    assert np.all(np.isfinite(result.states)) and np.all(np.isfinite(result.torque))
    rot, tor = indicators(result, "paper")
    rot_1ms, tor_1ms = indicators(pd_runs["paper"][0], "paper")
    assert rot == pytest.approx(rot_1ms, rel=1e-3)
    assert tor == pytest.approx(tor_1ms, rel=1e-3)
    # the resampled states are close to the 1 ms run sample by sample
    np.testing.assert_allclose(result.states, pd_runs["paper"][0].states, rtol=0, atol=1e-6)


def test_simulated_start_is_the_desired_start(pd_runs):
    for kinematics in KINEMATICS:
        result = pd_runs[kinematics][0]
        theta0, w0, _ = desired_motion(0.0, kinematics)
        assert result.z[0, 0] == pytest.approx(float(theta0), abs=1e-15)
        assert result.zd[0, 0] == pytest.approx(float(w0), abs=1e-15)
