"""The forearm on the engine (its coordinates, M(z), h and inverse dynamics), the desired motion,
checked against closed forms, numerical derivatives and constraint properties (never against the
code's own output)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import forearm_closed_form as cf
from fdbench.models import with_changes
from fdbench.multibody.motions import desired_motion, sample_times, warped_time
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion

KINEMATICS = ("paper", "exact")
MODEL = find_model("forearm")
ENGINE = Engine(MODEL)
theta_values = st.floats(-math.pi, math.pi, allow_nan=False)
rates = st.floats(-20.0, 20.0, allow_nan=False)
times = st.floats(0.0, 1.0, allow_nan=False)


# ----------------------------------------------------------------------------- inverse dynamics


@pytest.mark.parametrize("kinematics", KINEMATICS)
def test_inverse_torque_equals_closed_form(kinematics):
    motion = joint_motion(kinematics, MODEL)
    result = sim.inverse_dynamics(None, ENGINE, motion)
    np.testing.assert_allclose(result.t, np.linspace(0.0, 1.0, 1001), rtol=0, atol=1e-15)
    theta, w, dw = desired_motion(result.t, kinematics)
    np.testing.assert_array_equal(result.angles[:, 0], theta)
    np.testing.assert_array_equal(result.velocities[:, 0], w)
    np.testing.assert_array_equal(result.accelerations[:, 0], dw)
    expected = cf.elbow_torque(theta, dw)[:, None]
    np.testing.assert_allclose(result.torque, expected, rtol=1e-12, atol=1e-12)
    # the feedforward torque function gives the same torque, on any grid
    np.testing.assert_allclose(sim.feedforward(ENGINE, motion)(result.t), expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sim.feedforward(ENGINE, motion)(result.t[:5]), expected[:5], rtol=1e-12, atol=1e-12)


def test_inverse_torque_at_rest_points():
    """At t = 0 the motion is at rest at -pi/4 with theta'' = 0 in both variants: the torque only
    holds the static load, cos(pi/4) (F_ext L12 + m g L1G)."""
    static = np.cos(np.pi / 4) * (15.0 * 0.33 + 1.0 * 9.81 * 0.11)
    for kinematics in KINEMATICS:
        torque = sim.inverse_dynamics([0.0], ENGINE, joint_motion(kinematics, MODEL)).torque
        assert torque[0, 0] == pytest.approx(static, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    L12=st.floats(0.1, 1.0),
    frac=st.floats(0.0, 1.0),
    m=st.floats(0.1, 10.0),
    extra_inertia=st.floats(1e-3, 1.0),
    F_ext=st.floats(-50.0, 50.0),
    g=st.floats(0.0, 20.0),
    kinematics=st.sampled_from(KINEMATICS),
    t=st.lists(times, min_size=1, max_size=20),
)
def test_inverse_torque_closed_form_random_constants(L12, frac, m, extra_inertia, F_ext, g, kinematics, t):
    """Table 1's constants changed through the short keys (I1 above m L1G^2: a positive inertia
    about the centre of mass)."""
    L1G = frac * L12
    I1 = m * L1G**2 + extra_inertia
    model = with_changes("forearm", (("L12", L12), ("L1G", L1G), ("m", m), ("I1", I1), ("F_ext", F_ext), ("g", g)))
    t = np.array(t)
    result = sim.inverse_dynamics(t, Engine(model), joint_motion(kinematics, model))
    theta, _, dw = desired_motion(t, kinematics)
    expected = cf.elbow_torque(theta, dw, I1=I1, L12=L12, L1G=L1G, m=m, F_ext=F_ext, g=g)
    scale = I1 * np.abs(dw) + abs(F_ext * L12) + m * g * L1G
    assert np.all(np.abs(result.torque[:, 0] - expected) <= 1e-11 * (scale + 1e-3))


@settings(max_examples=100, deadline=None)
@given(theta=theta_values, w=rates)
def test_mass_matrix_and_bias_are_the_closed_forms(theta, w):
    """The minimal equations I1 theta'' + G cos(theta) = tau: M(z) = I1 and h(z, z') = G cos(theta)
    whatever the rate (a rod pinned at a fixed point has no velocity terms)."""
    np.testing.assert_allclose(ENGINE.mass_matrix([theta]), [[cf.I1]], rtol=1e-12)
    np.testing.assert_allclose(ENGINE.bias([theta], [w]), [cf.load_moment() * math.cos(theta)], rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- coordinates


@settings(max_examples=100, deadline=None)
@given(theta=theta_values, w=rates)
def test_the_state_is_the_hand_and_the_angle_with_their_rates(theta, w):
    """Eq. 7's mixed coordinates q = [x2, y2, theta] with the hand at L12 (cos, sin)(theta), and
    q' = (dq/dtheta) theta' (dq/dtheta by central differences of the state's positions)."""
    y = ENGINE.state_from_joints([theta], [w])
    np.testing.assert_allclose(y[:3], [cf.L12 * math.cos(theta), cf.L12 * math.sin(theta), theta], rtol=0, atol=1e-15)
    h = 1e-6
    dq = (ENGINE.state_from_joints([theta + h], [0.0])[:3] - ENGINE.state_from_joints([theta - h], [0.0])[:3]) / (2 * h)
    np.testing.assert_allclose(y[3:], dq * w, rtol=0, atol=1e-8 * (1 + abs(w)))
    z, zd = ENGINE.joints_from_state(y)
    assert (float(z[0]), float(zd[0])) == pytest.approx((theta, w), abs=1e-14)
    assert ENGINE.constraint_violation(y) <= 1e-15  # consistent coordinates satisfy the constraints


def test_a_hand_off_the_forearm_violates_the_constraints():
    """1e-4 m of the hand away from radius L12 is a violation of about that size (m or m^2)."""
    y = ENGINE.state_from_joints([0.3], [0.0])
    y[:2] *= 1 + 1e-4 / cf.L12
    assert 1e-9 < ENGINE.constraint_violation(y) < 1e-3


# ----------------------------------------------------------------------------- desired motion

t_inner = np.linspace(0.0, 1.0, 41)


def central(f, t, h):
    return (f(t + h) - f(t - h)) / (2 * h)


def test_exact_motion_derivatives_are_numerical_derivatives():
    def pos(t):
        return desired_motion(t, "exact")[0]

    def vel(t):
        return desired_motion(t, "exact")[1]

    theta, w, dw = desired_motion(t_inner, "exact")
    np.testing.assert_allclose(central(pos, t_inner, 1e-5), w, rtol=0, atol=1e-8)
    h = 1e-4
    second = (pos(t_inner + h) - 2 * theta + pos(t_inner - h)) / h**2
    np.testing.assert_allclose(second, dw, rtol=0, atol=1e-4)
    np.testing.assert_allclose(central(vel, t_inner, 1e-5), dw, rtol=0, atol=1e-7)


def test_paper_motion_derivatives_are_with_respect_to_warped_time():
    def pos(t):
        return desired_motion(t, "paper")[0]

    def vel(t):
        return desired_motion(t, "paper")[1]

    _, w, dw = desired_motion(t_inner, "paper")
    _, dts = warped_time(t_inner)
    # dt*/dt itself is the derivative of t*
    np.testing.assert_allclose(central(lambda t: warped_time(t)[0], t_inner, 1e-5), dts, atol=1e-9)
    np.testing.assert_allclose(central(pos, t_inner, 1e-5), w * dts, rtol=0, atol=1e-8)
    np.testing.assert_allclose(central(vel, t_inner, 1e-5), dw * dts, rtol=0, atol=1e-7)
    # and the paper velocity is not the time derivative (away from t = 0.5 where dt*/dt = 1
    # and from the ends where the velocity vanishes)
    away = (np.abs(dts - 1) > 0.2) & (np.abs(w) > 0.05)
    assert away.sum() > 10
    assert np.all(np.abs(central(pos, t_inner, 1e-5)[away] - w[away]) > 1e-2)


@pytest.mark.parametrize("kinematics", KINEMATICS)
def test_desired_motion_end_points(kinematics):
    theta, w, _ = desired_motion(np.array([0.0, 1.0]), kinematics)
    np.testing.assert_allclose(theta, [-np.pi / 4, 0.0], atol=1e-15)
    np.testing.assert_allclose(w, [0.0, 0.0], atol=1e-14)  # starts and ends at rest
    theta = desired_motion(sample_times(), kinematics)[0]
    assert np.all(np.diff(theta) >= 0)  # monotonic rise
    assert theta.shape == (1001,)


def test_warped_time_end_points():
    ts, dts = warped_time(np.array([0.0, 1.0]))
    np.testing.assert_allclose(ts, [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(dts, [0.05, 1.95], atol=1e-15)
