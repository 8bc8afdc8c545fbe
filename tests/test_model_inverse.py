"""The forearm model, the desired motion and inverse dynamics, checked against closed forms,
numerical derivatives and constraint properties (never against the code's own output)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdbench.inverse import Feedforward, elbow_torque, inverse_dynamics
from fdbench.model import Forearm
from fdbench.motion import desired_motion, sample_times, warped_time

KINEMATICS = ("paper", "exact")
theta_values = st.floats(-1.5, 1.5, allow_nan=False)
rates = st.floats(-20.0, 20.0, allow_nan=False)
times = st.floats(0.0, 1.0, allow_nan=False)


def closed_form_torque(model: Forearm, theta, theta_ddot):
    """Elbow torque of a rod pinned at the elbow: I1 theta'' plus the moments of gravity at the
    centre of mass and of the vertical load at the hand (derived by hand from eqs. 3-4)."""
    return model.I1 * theta_ddot + np.cos(theta) * (model.F_ext * model.L12 + model.m * model.g * model.L1G)


# ----------------------------------------------------------------------------- inverse dynamics


@pytest.mark.parametrize("kinematics", KINEMATICS)
def test_inverse_torque_equals_closed_form(kinematics):
    model = Forearm()
    result = inverse_dynamics(model=model, kinematics=kinematics)
    np.testing.assert_allclose(result.t, np.linspace(0.0, 1.0, 1001), rtol=0, atol=1e-15)
    theta, w, dw = desired_motion(result.t, kinematics)
    np.testing.assert_array_equal(result.theta, theta)
    expected = closed_form_torque(model, theta, dw)
    np.testing.assert_allclose(result.torque, expected, rtol=1e-12, atol=1e-12)
    # the other entry points give the same torque
    np.testing.assert_allclose(elbow_torque(result.t, model, kinematics), expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Feedforward(model, kinematics)(result.t), expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Feedforward(model, kinematics)(result.t[:5]), expected[:5], rtol=1e-12, atol=1e-12)


def test_inverse_torque_at_rest_points():
    """At t = 0 the motion is at rest at -pi/4 with theta'' = 0 in both variants: the torque only
    holds the static load, cos(pi/4) (F_ext L12 + m g L1G)."""
    model = Forearm()
    static = np.cos(np.pi / 4) * (15.0 * 0.33 + 1.0 * 9.81 * 0.11)
    for kinematics in KINEMATICS:
        assert elbow_torque(np.array([0.0]), model, kinematics)[0] == pytest.approx(static, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    L12=st.floats(0.1, 1.0),
    frac=st.floats(0.0, 1.0),
    m=st.floats(0.1, 10.0),
    I1=st.floats(1e-3, 1.0),
    F_ext=st.floats(-50.0, 50.0),
    g=st.floats(0.0, 20.0),
    kinematics=st.sampled_from(KINEMATICS),
    t=st.lists(times, min_size=1, max_size=20),
)
def test_inverse_torque_closed_form_random_constants(L12, frac, m, I1, F_ext, g, kinematics, t):
    model = Forearm(L12=L12, L1G=frac * L12, m=m, I1=I1, F_ext=F_ext, g=g)
    t = np.array(t)
    result = inverse_dynamics(t, model, kinematics)
    theta, _, dw = desired_motion(t, kinematics)
    expected = closed_form_torque(model, theta, dw)
    scale = model.I1 * np.abs(dw) + abs(model.F_ext * model.L12) + model.m * model.g * model.L1G
    assert np.all(np.abs(result.torque - expected) <= 1e-11 * (scale + 1e-3))


# ----------------------------------------------------------------------------- model kinematics


@settings(max_examples=100, deadline=None)
@given(theta=theta_values, w=rates, dw=rates)
def test_velocity_transform_consistent(theta, w, dw):
    model = Forearm()
    q, qd, _ = model.coordinates(theta, w, dw)
    R = model.velocity_transform(theta)
    np.testing.assert_allclose(R * w, qd, rtol=1e-13, atol=1e-14)
    # R = dq/dtheta, by central differences of q(theta)
    h = 1e-6
    numeric = (model.coordinates(theta + h, 0, 0)[0] - model.coordinates(theta - h, 0, 0)[0]) / (2 * h)
    np.testing.assert_allclose(R, numeric, rtol=0, atol=1e-8)
    # q'' = R theta'' + (dR/dtheta) theta'^2
    dR = (model.velocity_transform(theta + h) - model.velocity_transform(theta - h)) / (2 * h)
    np.testing.assert_allclose(model.coordinates(theta, w, dw)[2], R * dw + dR * w**2, rtol=1e-7, atol=1e-6)


@settings(max_examples=100, deadline=None)
@given(theta=theta_values, w=rates)
def test_constraints_satisfied_on_consistent_coordinates(theta, w):
    model = Forearm()
    q, qd, _ = model.coordinates(theta, w, 0.0)
    np.testing.assert_allclose(model.constraints(q), 0.0, atol=1e-15)
    np.testing.assert_allclose(model.jacobian(q) @ qd, 0.0, atol=1e-13)


@settings(max_examples=60, deadline=None)
@given(
    q=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
    qd=st.tuples(*[st.floats(-5.0, 5.0)] * 3),
)
def test_jacobian_is_derivative_of_constraints(q, qd):
    """Phi_q is dPhi/dq (directional central difference along qd), for any q, consistent or not."""
    model = Forearm()
    q, qd = np.array(q), np.array(qd)
    h = 1e-6
    numeric = (model.constraints(q + h * qd) - model.constraints(q - h * qd)) / (2 * h)
    np.testing.assert_allclose(model.jacobian(q) @ qd, numeric, rtol=1e-7, atol=1e-8)


@settings(max_examples=60, deadline=None)
@given(
    q=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
    qd=st.tuples(*[st.floats(-5.0, 5.0)] * 3),
)
def test_jacobian_dot_qdot_along_straight_path(q, qd):
    """d/dt Phi_q(q + t qd) at t = 0, times qd, for any (q, qd)."""
    model = Forearm()
    q, qd = np.array(q), np.array(qd)
    h = 1e-6
    dJ = (model.jacobian(q + h * qd) - model.jacobian(q - h * qd)) / (2 * h)
    np.testing.assert_allclose(model.jacobian_dot_qdot(q, qd), dJ @ qd, rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("t", [0.05, 0.3, 0.5, 0.77, 0.95])
def test_jacobian_dot_qdot_along_desired_motion(t):
    model = Forearm()

    def q_qd(time):
        return model.coordinates(*desired_motion(time, "exact"))[:2]

    q, qd = q_qd(t)
    h = 1e-6
    dJ = (model.jacobian(q_qd(t + h)[0]) - model.jacobian(q_qd(t - h)[0])) / (2 * h)
    np.testing.assert_allclose(model.jacobian_dot_qdot(q, qd), dJ @ qd, rtol=1e-6, atol=1e-7)
    # and the exact motion keeps the constraint acceleration at zero: Phi_q q'' + Phi_q' q' = 0
    qdd = model.coordinates(*desired_motion(t, "exact"))[2]
    np.testing.assert_allclose(model.jacobian(q) @ qdd + model.jacobian_dot_qdot(q, qd), 0.0, atol=1e-12)


def test_mass_and_forces_table_1():
    model = Forearm()
    np.testing.assert_allclose(model.mass_matrix(), np.diag([0.04 / 0.33**2] * 2 + [0.0]), rtol=1e-15)
    np.testing.assert_allclose(model.external_forces(), [0.0, -15.0 - 9.81 * 0.11 / 0.33, 0.0], rtol=1e-15)


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
