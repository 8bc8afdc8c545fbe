"""The two-segment arm (arm2): its penalty-formulation kernel against a dense solve of eq. 12, its
forward and inverse dynamics against an independent minimal-coordinate Lagrange model, constraint
properties and drift, the reach motion, and the forearm recovered with the shoulder held still."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from fdbench.control import pd_control
from fdbench.indicators import rmse_rot_deg, rmse_torque_nm
from fdbench.integrate import Settings, Status
from fdbench.inverse import inverse_dynamics as forearm_inverse
from fdbench.model import Forearm, Penalty
from fdbench.models import MODELS, model_class
from fdbench.models import arm2_kernels as kernels
from fdbench.models import arm2_sim as sim
from fdbench.models.arm2 import Arm2, arm2_with
from fdbench.models.arm2_motion import PerJoint, Reach, as_joint_motion
from fdbench.registry import UnknownName

ARM = Arm2()
REACH = Reach()


# ----------------------------------------------------------------------------- the reference model


def lagrange(arm: Arm2, z, w):
    """Minimal-coordinate model of the arm from its Lagrangian in z = [shoulder, elbow]:
    T = 1/2 I0 s'^2 + 1/2 m |v_G|^2 + 1/2 (I1 - m L1G^2) (s' + e')^2, V = gravity and the load.
    Returns M(z) (2, 2) and the velocity and gravity terms h(z, z') (2,) of M z'' + h = tau."""
    s, e = z
    ws, we = w
    k = arm.m * arm.L01 * arm.L1G
    M = np.array([[arm.I0 + arm.I1 + arm.m * arm.L01**2 + 2 * k * math.cos(e), arm.I1 + k * math.cos(e)],
                  [arm.I1 + k * math.cos(e), arm.I1]])
    coriolis = k * math.sin(e) * np.array([-(2 * ws * we + we**2), ws**2])
    far = arm.m * arm.g * arm.L1G + arm.F_ext * arm.L12  # moment of the forearm's weight and load
    near = arm.m0 * arm.g * arm.L0G + (arm.m * arm.g + arm.F_ext) * arm.L01
    gravity = np.array([near * math.cos(s) + far * math.cos(s + e), far * math.cos(s + e)])
    return M, coriolis + gravity


def lagrange_simulation(arm, torque, motion, kp=0.0, kd=0.0):
    """The reference solution: scipy DOP853 at rtol = atol = 1e-12 of the Lagrange equations
    under torque(t) plus the same per-joint PD law; joint angles on the motion's samples (n, 2)."""

    def rhs(t, y):
        z_d, w_d, _ = motion(np.array(t))
        tau = torque(np.array([t]))[0] + kp * (z_d - y[:2]) + kd * (w_d - y[2:])
        M, h = lagrange(arm, y[:2], y[2:])
        return np.concatenate([y[2:], np.linalg.solve(M, tau - h)])

    z0, w0, _ = motion(np.array(0.0))
    sol = solve_ivp(rhs, (0.0, motion.duration), np.concatenate([z0, w0]), method="DOP853", rtol=1e-12,
                    atol=1e-12, t_eval=motion.samples)
    assert sol.success
    return sol.y[:2].T


def wobbly(arm, motion):
    """A non-trivial torque history: the reach's inverse-dynamics torques plus sinusoids (N m)."""
    ff = sim.feedforward(arm, motion)
    return lambda t: ff(t) + np.stack([2.0 * np.sin(6 * np.pi * t), np.cos(4 * np.pi * t)], axis=-1)


# ----------------------------------------------------------------------------- forward dynamics


@pytest.mark.parametrize("arm, kp, kd", [(ARM, 80.0, 0.3), (Arm2(g=0.0, F_ext=0.0), 0.0, 0.0)],
                         ids=["pd-gravity-load", "open-loop-weightless"])
def test_forward_dynamics_matches_lagrange(arm, kp, kd):
    torque = wobbly(arm, REACH)
    reference = lagrange_simulation(arm, torque, REACH, kp, kd)
    desired = sim.inverse_dynamics(None, arm, REACH).angles
    assert np.degrees(np.abs(reference - desired)).max() > 3.0  # the torque history moves the arm off the reach
    result = sim.simulate(torque, arm, REACH, kp, kd)
    assert result.status is Status.SUCCESS and result.t_end == pytest.approx(1.0)
    assert np.degrees(np.abs(result.angles - reference)).max() < 1e-4


def dense_accelerations(arm: Arm2, penalty: Penalty, q, qd, tau):
    """q'' of eq. 12 by a dense 6x6 solve assembled from the model's own matrices."""
    J = arm.jacobian(q)
    phi = arm.constraints(q)
    lhs = arm.mass_matrix() + penalty.alpha * J.T @ J
    Q = arm.external_forces() + np.array([0.0, 0.0, 0.0, 0.0, tau[0], tau[1]])
    c = arm.jacobian_dot_qdot(q, qd) + 2 * penalty.xi * penalty.omega * (J @ qd) + penalty.omega**2 * phi
    return np.linalg.solve(lhs, Q - penalty.alpha * J.T @ c)


angle = st.floats(-1.2, 1.2)
rate = st.floats(-5.0, 5.0)


@settings(max_examples=60, deadline=None)
@given(s=angle, a=angle, ws=rate, we=rate, ts=st.floats(-30, 30), te=st.floats(-30, 30),
       off=st.lists(st.floats(-1e-3, 1e-3), min_size=6, max_size=6), alpha=st.sampled_from([1e5, 1e7]))
def test_kernel_solves_eq12(s, a, ws, we, ts, te, off, alpha):
    """The kernel's elimination equals a dense solve of eq. 12, also off the constraint manifold."""
    penalty = Penalty(alpha=alpha)
    q, qd, _ = ARM.coordinates([s, a - s], [ws, we], [0.0, 0.0])
    q = q + np.array(off)
    qd = qd + 10 * np.array(off)
    expected = dense_accelerations(ARM, penalty, q, qd, (ts, te))
    out = np.empty(12)
    kernels.accelerations(np.concatenate([q, qd]), ts, te, kernels.kernel_constants(ARM, penalty), out)
    assert np.allclose(out[:6], qd)
    scale = 1.0 + np.abs(expected)
    assert np.all(np.abs(out[6:] - expected) <= 1e-6 * scale)


def test_singular_configuration_stops_the_simulation():
    """Driving the forearm's absolute angle to 90 deg ends the run with SINGULAR, not garbage."""
    up = PerJoint((0.0, math.radians(60.0)))
    result = sim.simulate(lambda t: np.tile([0.0, 20.0], (len(t), 1)), ARM, up)
    assert result.status is Status.SINGULAR and result.t_end < 1.0
    assert np.all(np.isnan(result.angles[~result.reached]))


@pytest.mark.parametrize("bandwidth", [10.0, 20.0])
def test_computed_torque_imposes_the_error_dynamics(bandwidth):
    """Computed-torque control with the full mass matrix from 2 and -3 deg off the reach, critically
    damped: each joint's error follows e0 (1 + w t) exp(-w t) (the closed form of
    e'' + 2 w e' + w^2 e = 0 from rest) however the joints couple."""
    z, w, dw = REACH(np.array(0.0))
    offset = np.radians([2.0, -3.0])
    q, qd, _ = ARM.coordinates(z + offset, w, dw)
    result = sim.simulate(None, ARM, REACH, bandwidth**2, 2 * bandwidth, start=np.concatenate([q, qd]), computed=True)
    assert result.success
    t = result.t[:, None]
    expected = -offset * (1 + bandwidth * t) * np.exp(-bandwidth * t)
    error = sim.inverse_dynamics(None, ARM, REACH).angles - result.angles
    assert np.degrees(np.abs(error - expected)).max() < 1e-5


def test_computed_torque_believes_the_nominal_model():
    """With a heavier upper arm than the law believes, the error no longer decays as designed;
    with the same arm passed as both, the results are those of the default."""
    same = sim.simulate(None, ARM, REACH, 400.0, 40.0, computed=True, nominal=Arm2())
    default = sim.simulate(None, ARM, REACH, 400.0, 40.0, computed=True)
    assert np.array_equal(same.angles, default.angles)
    heavy = sim.simulate(None, Arm2(m0=3.0), REACH, 400.0, 40.0, computed=True, nominal=ARM)
    desired = sim.inverse_dynamics(None, ARM, REACH).angles
    assert sim.rmse_deg(heavy, desired)[0] > 100 * sim.rmse_deg(default, desired)[0]


def test_lqr_gains_at_a_held_posture_are_the_algebraic_riccati_solution():
    """Holding a posture, the time-varying Riccati solution stays at the algebraic one: its gains
    equal those of scipy's ARE solver on a linearisation of the test's own Lagrange model."""
    from scipy.linalg import solve_continuous_are

    from fdbench.models.arm2_lqr import lqr_gains

    z0 = np.radians([-10.0, 40.0])
    M, h = lagrange(ARM, z0, [0.0, 0.0])
    step = 1e-6
    A = np.zeros((4, 4))
    A[:2, 2:] = np.eye(2)
    for i in range(2):
        e = step * np.eye(2)[i]
        plus, minus = lagrange(ARM, z0 + e, [0.0, 0.0]), lagrange(ARM, z0 - e, [0.0, 0.0])
        acc = [np.linalg.solve(Mi, h - hi) for Mi, hi in (plus, minus)]  # tau = h(z0) holds z0
        A[2:, i] = (acc[0] - acc[1]) / (2 * step)
    B = np.vstack([np.zeros((2, 2)), np.linalg.inv(M)])
    Q = np.diag([1e4, 1e4, 1.0, 1.0])
    expected = B.T @ solve_continuous_are(A, B, Q, np.eye(2))
    gains = lqr_gains(ARM, PerJoint(tuple(z0)), q_angle=1e4, q_rate=1.0, r_torque=1.0)(np.array([0.0, 0.5, 1.0]))
    assert np.allclose(gains, expected, rtol=1e-5, atol=1e-6)


def test_lqr_brings_the_arm_back_to_the_reach():
    from fdbench.models.arm2_lqr import lqr_gains

    z, w, dw = REACH(np.array(0.0))
    q, qd, _ = ARM.coordinates(z + np.radians([2.0, -3.0]), w, dw)
    result = sim.simulate(sim.feedforward(ARM, REACH), ARM, REACH, start=np.concatenate([q, qd]),
                          gains=lqr_gains(ARM, REACH))
    error = np.degrees(np.abs(sim.inverse_dynamics(None, ARM, REACH).angles - result.angles))
    assert result.success and error[0].max() == pytest.approx(3.0) and error[-300:].max() < 1e-3


# ----------------------------------------------------------------------------- inverse dynamics


def test_inverse_dynamics_matches_lagrange_on_the_reach():
    inv = sim.inverse_dynamics(None, ARM, REACH)
    for k in range(0, len(inv.t), 50):
        M, h = lagrange(ARM, inv.angles[k], inv.velocities[k])
        assert np.allclose(inv.torque[k], M @ inv.accelerations[k] + h, rtol=1e-12, atol=1e-10)


@settings(max_examples=100, deadline=None)
@given(z=st.lists(st.floats(-3, 3), min_size=2, max_size=2), w=st.lists(rate, min_size=2, max_size=2),
       dw=st.lists(st.floats(-50, 50), min_size=2, max_size=2), m0=st.floats(0.1, 10), F_ext=st.floats(-50, 50))
def test_inverse_dynamics_matches_lagrange_anywhere(z, w, dw, m0, F_ext):
    arm = Arm2(m0=m0, F_ext=F_ext)
    M, h = lagrange(arm, z, w)
    assert np.allclose(arm.joint_torques(z, w, dw), M @ np.array(dw) + h, rtol=1e-10, atol=1e-9)


# ----------------------------------------------------------------------------- constraints


@settings(max_examples=50, deadline=None)
@given(z=st.lists(st.floats(-3, 3), min_size=2, max_size=2), w=st.lists(rate, min_size=2, max_size=2),
       dw=st.lists(st.floats(-50, 50), min_size=2, max_size=2))
def test_coordinates_satisfy_the_constraints_and_their_derivatives(z, w, dw):
    q, qd, qdd = ARM.coordinates(z, w, dw)
    J = ARM.jacobian(q)
    assert np.allclose(ARM.constraints(q), 0.0, atol=1e-14)
    assert np.allclose(J @ qd, 0.0, atol=1e-12)  # Phi' = 0
    assert np.allclose(J @ qdd + ARM.jacobian_dot_qdot(q, qd), 0.0, atol=1e-10)  # Phi'' = 0
    R = ARM.velocity_transform(z)
    assert np.allclose(J @ R, 0.0, atol=1e-14) and np.allclose(R @ w, qd, atol=1e-12)


def test_jacobian_is_the_derivative_of_the_constraints():
    rng = np.random.default_rng(3)
    q = rng.normal(size=6) * 0.3
    h = 1e-6
    numeric = np.stack([(ARM.constraints(q + h * e) - ARM.constraints(q - h * e)) / (2 * h) for e in np.eye(6)], axis=1)
    assert np.allclose(ARM.jacobian(q), numeric, atol=1e-8)


def test_constraint_drift_stays_bounded():
    """Under the wobbly torque and PD the constraints stay satisfied to 1e-6 (m^2, m) throughout."""
    result = sim.simulate(wobbly(ARM, REACH), ARM, REACH, 80.0, 0.3)
    assert result.success and result.max_violation < 1e-6
    drift = np.abs(ARM.constraints(result.q)).max(axis=1)  # per sample, over the four constraints
    assert drift.max() < 1e-6
    assert drift[-100:].max() < 2 * drift[:-100].max()  # no growth towards the end


# ----------------------------------------------------------------------------- the forearm recovered


@pytest.mark.parametrize("kinematics", ["paper", "exact"])
def test_shoulder_held_still_reproduces_the_forearm(kinematics):
    """Shoulder at 0 under a stiff PD, elbow on eq. 5 with PD 80 / 0.3 and computed feedforward:
    the elbow's figures are the 1-DOF forearm's (whose elbow sits at the origin, as the arm's
    sits at (L01, 0) here, with gravity and load acting the same way)."""
    forearm = pd_control(80.0, 0.3, Settings(kinematics=kinematics))
    f_inv = forearm_inverse(kinematics=kinematics)
    motion = PerJoint((0.0, kinematics))
    inv = sim.inverse_dynamics(None, ARM, motion)
    assert np.allclose(inv.torque[:, 1], f_inv.torque, rtol=1e-12, atol=1e-12)
    result = sim.simulate(sim.feedforward(ARM, motion), ARM, motion, (1e4, 80.0), (100.0, 0.3))
    assert result.success
    _, rot = sim.rmse_deg(result, inv.angles)
    _, torque = sim.rmse_torque_nm(result, inv.torque)
    assert np.degrees(np.abs(result.angles[:, 0])).max() < 0.01  # the shoulder stays still
    if kinematics == "paper":  # 0.113 deg and 0.147 N m (the paper: 0.116, 0.149)
        assert rot[1] == pytest.approx(rmse_rot_deg(forearm, f_inv.theta), rel=0.01)
        assert torque[1] == pytest.approx(rmse_torque_nm(forearm, f_inv.torque), rel=0.01)
        assert np.degrees(np.abs(result.angles[:, 1] - forearm.theta)).max() < 0.005
    else:  # both track to within 1e-6 deg
        assert rot[1] < 1e-6 and rmse_rot_deg(forearm, f_inv.theta) < 1e-6


# ----------------------------------------------------------------------------- motion, registry


def test_reach_is_smooth_rest_to_rest_and_clear_of_singularities():
    z, w, dw = REACH(REACH.samples)
    assert REACH.duration == 1.0 and len(REACH.samples) == 1001
    assert np.allclose(w[[0, -1]], 0.0) and np.allclose(dw[[0, -1]], 0.0)
    assert np.all(np.abs(z[-1] - z[0]) > math.radians(20))  # both joints move
    assert np.degrees(np.abs(z[:, 0])).max() <= 70 and np.degrees(np.abs(z.sum(axis=1))).max() <= 70
    assert np.degrees(z[:, 1]).min() > 29.99  # the elbow never straightens
    dt = REACH.samples[1]
    assert np.allclose(np.gradient(z, dt, axis=0)[1:-1], w[1:-1], atol=1e-5)
    assert np.allclose(np.gradient(w, dt, axis=0)[1:-1], dw[1:-1], atol=1e-4)


def test_pd_tracks_the_reach():
    inv = sim.inverse_dynamics(None, ARM, REACH)
    result = sim.simulate(sim.feedforward(ARM, REACH), ARM, REACH, 80.0, 0.3)
    overall, per_joint = sim.rmse_deg(result, inv.angles)
    assert result.success and overall < 1e-5 and per_joint.shape == (2,)
    assert overall == pytest.approx(math.sqrt(np.mean(per_joint**2)))


def test_model_registry():
    assert list(MODELS)[:2] == ["forearm", "arm2"]
    assert model_class("forearm") is Forearm and model_class("arm2") is Arm2
    with pytest.raises(UnknownName, match="valid: forearm, arm2.*did you mean 'arm2'"):
        model_class("arm3")
    with pytest.raises(ValueError, match="arm motion"):
        as_joint_motion("wave")


def test_arm2_constants_are_checked():
    assert arm2_with([("m0", "2.5")]) == Arm2(m0=2.5)
    for changes, message in [([("L0G", "0.4")], "L0G"), ([("m0", "-1")], "positive"), ([("mass", "1")], "unknown arm2 constant .mass.; valid: L01"), ([("m00", "1")], "did you mean .m0."),
                             ([("g", "nan")], "finite"), ([("I0", "x")], "number")]:
        with pytest.raises(ValueError, match=message):
            arm2_with(changes)


def test_a_step_off_the_sample_grid_is_interpolated():
    """dt = 0.3 ms puts no step on most 1 ms samples: the histories are interpolated between steps
    and agree with those of dt = 1 ms to 1e-5 deg."""
    torque = wobbly(ARM, REACH)
    coarse = sim.simulate(torque, ARM, REACH, 80.0, 0.3)
    fine = sim.simulate(torque, ARM, REACH, 80.0, 0.3, dt=3e-4)
    assert coarse.success and fine.success and fine.t_end == pytest.approx(1.0)
    assert np.degrees(np.abs(fine.angles - coarse.angles)).max() < 1e-5
    assert np.abs(fine.torque - coarse.torque).max() < 1e-3


def test_lqr_linearisation_on_the_move_matches_the_lagrange_model():
    """A and B of the compiled linearisation about a moving point of the reach against central
    differences of the test's own Lagrange model under the inverse-dynamics torques."""
    from fdbench.model import Penalty
    from fdbench.models.arm2_kernels import kernel_constants
    from fdbench.models.arm2_lqr import linearisation

    z, w, dw = (v.reshape(2) for v in REACH(np.array(0.4)))
    M, h = lagrange(ARM, z, w)
    tau = M @ dw + h

    def acc(zi, wi):
        Mi, hi = lagrange(ARM, zi, wi)
        return np.linalg.solve(Mi, tau - hi)

    step = 1e-5
    expected = np.zeros((4, 4))
    expected[:2, 2:] = np.eye(2)
    for i, e in enumerate(step * np.eye(2)):
        expected[2:, i] = (acc(z + e, w) - acc(z - e, w)) / (2 * step)
        expected[2:, 2 + i] = (acc(z, w + e) - acc(z, w - e)) / (2 * step)
    A, B = np.empty((4, 4)), np.empty((4, 2))
    linearisation(z, w, dw, kernel_constants(ARM, Penalty()), A, B)
    assert np.allclose(A, expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
    assert np.allclose(B, np.vstack([np.zeros((2, 2)), np.linalg.inv(M)]), rtol=1e-10, atol=0)
