"""The multibody engine (fdbench.multibody.engine) against the forearm's and the arm's closed forms,
its minimal equations against its penalty accelerations, and a hanging leg through -90 deg.

Tolerances. The penalty formulation's solution is that of the constrained equations to
O(m / (alpha d^2)) (d a body's length), hence, with alpha = 1e9, 1e-6 for the forearm and a tree and
1e-4 for random chains against M(z)^-1 (tau - h).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import forearm_closed_form as forearm
from fdbench.multibody import engine as mb
from fdbench.multibody.layout import CONSTRAINT, NONFINITE, OK
from fdbench.multibody.engine import Engine

from fdbench.multibody.model import GROUND, Body, Joint, Load, Model


def forearm_model() -> Model:
    """Table 1's forearm, as the description contract writes it."""
    return Model("forearm", (0.0, -9.81), (Body("forearm", 1.0, (0.11, 0.0), 0.04 - 1.0 * 0.11**2),),
                 (Joint("theta", "pin", GROUND, "forearm", (0.0, 0.0), (0.0, 0.0)),),
                 (Load("forearm", (0.33, 0.0), (0.0, -15.0)),))


def arm2_model() -> Model:
    """The two-segment arm (the constants of tests/helpers/arm2_closed_form.py)."""
    return Model("arm2", (0.0, -9.81),
                 (Body("upper_arm", 2.0, (0.13, 0.0), 0.06 - 2.0 * 0.13**2),
                  Body("forearm", 1.0, (0.11, 0.0), 0.04 - 1.0 * 0.11**2)),
                 (Joint("shoulder", "pin", GROUND, "upper_arm", (0.0, 0.0), (0.0, 0.0)),
                  Joint("elbow", "pin", "upper_arm", "forearm", (0.30, 0.0), (0.0, 0.0))),
                 (Load("forearm", (0.33, 0.0), (0.0, -15.0)),))


def leg3_model() -> Model:
    """A three-segment leg hanging from the hip: thigh, shank, foot (the foot's end at the toes)."""
    return Model("leg3", (0.0, -9.81),
                 (Body("thigh", 7.5, (0.19, 0.0), 0.12), Body("shank", 3.5, (0.18, 0.0), 0.05),
                  Body("foot", 1.0, (0.05, 0.0), 0.004, end=(0.15, 0.0))),
                 (Joint("hip", "pin", GROUND, "thigh", (0.0, 0.0), (0.0, 0.0)),
                  Joint("knee", "pin", "thigh", "shank", (0.43, 0.0), (0.0, 0.0)),
                  Joint("ankle", "pin", "shank", "foot", (0.42, 0.0), (0.0, 0.0))))


def tree_model() -> Model:
    """A tree with an offset, a ground point away from the origin, a joint away from its parent's
    basic points (an extra point), an end key and a load."""
    return Model("tree", (0.0, -9.81),
                 (Body("a", 2.0, (0.1, 0.02), 0.05), Body("b", 1.0, (0.15, -0.01), 0.02),
                  Body("c", 0.5, (0.05, 0.0), 0.01), Body("d", 0.7, (0.0, 0.1), 0.01, end=(0.02, 0.2))),
                 (Joint("j0", "pin", GROUND, "a", (0.1, 0.2), (0.0, 0.0), offset=-1.0),
                  Joint("j1", "pin", "a", "b", (0.3, 0.0), (0.0, 0.0), offset=0.3),
                  Joint("j2", "pin", "a", "c", (0.15, 0.05), (0.01, 0.0)),
                  Joint("j3", "pin", "b", "d", (0.2, 0.01), (0.0, 0.0))),
                 (Load("c", (0.1, 0.0), (1.0, -2.0)),))


def joint_accelerations(engine: Engine, yd: np.ndarray) -> np.ndarray:
    """z'' (rad/s^2) from a state derivative: differences of the absolute angles' accelerations."""
    phidd = yd[engine.n_q + engine.n_p:]
    parent = engine.joint_parent
    return phidd - np.where(parent >= 0, phidd[np.maximum(parent, 0)], 0.0)


def relative_error(found, expected) -> float:
    return float(np.max(np.abs(np.asarray(found) - expected)) / np.max(np.abs(expected)))


# ---------------------------------------------------------------------- the forearm and the arm
def test_forearm_accelerations_are_the_minimal_equation_s():
    """On the constraint manifold the penalty accelerations are eq. 7's of the minimal equation's
    theta'' = (tau - G cos theta) / I1, to the penalty's O(m / (alpha L12^2)) = 1e-8 (alpha = 1e9)."""
    engine = Engine(forearm_model(), alpha=1e9)
    rng = np.random.default_rng(1)
    for _ in range(200):
        theta, w, tau = rng.uniform(-1.3, 1.3), rng.uniform(-5, 5), rng.uniform(-20, 20)
        dw = (tau - forearm.GRAVITY_TORQUE * math.cos(theta)) / forearm.I1
        c, s, L = math.cos(theta), math.sin(theta), forearm.L12
        expected = [-L * (c * w**2 + s * dw), L * (-s * w**2 + c * dw), dw]
        found = engine.accelerations(engine.state_from_joints([theta], [w]), [tau])[3:]
        assert relative_error(found, expected) < 1e-6


def test_forearm_constraint_violation_is_eq_9s_largest_residual():
    """Off the manifold: the violation is max |x2^2 + y2^2 - L12^2|, |y2 - L12 sin theta| (eq. 9;
    the sin form wherever |cos theta| >= 0.2)."""
    engine, rng = Engine(forearm_model()), np.random.default_rng(2)
    for _ in range(100):
        y = forearm.mixed_state(rng.uniform(-1.3, 1.3), rng.uniform(-5, 5)) + rng.normal(0.0, 1e-4, 6)
        x2, y2, theta = y[:3]
        expected = max(abs(x2**2 + y2**2 - forearm.L12**2), abs(y2 - forearm.L12 * math.sin(theta)))
        assert engine.constraint_violation(y) == pytest.approx(expected, rel=1e-9)


def test_the_forearm_state_is_eq_7s():
    engine = Engine(forearm_model())
    np.testing.assert_allclose(engine.state_from_joints([0.4], [-1.5]), forearm.mixed_state(0.4, -1.5),
                               rtol=0, atol=1e-15)


def test_forearm_inverse_dynamics_is_the_closed_form():
    engine, rng = Engine(forearm_model()), np.random.default_rng(3)
    theta, w, dw = rng.uniform(-2, 2, (3, 50, 1))
    expected = forearm.torque_along(theta, w, dw)
    np.testing.assert_allclose(engine.inverse_dynamics(theta, w, dw), expected, rtol=1e-12, atol=1e-12)
    assert engine.inverse_dynamics([0.1], [0.2], [0.3]).shape == (1,)


def test_arm_inverse_dynamics_is_the_closed_form():
    from helpers.arm2_closed_form import joint_torques

    engine, rng = Engine(arm2_model()), np.random.default_rng(4)
    z, zd, zdd = rng.uniform(-2, 2, (3, 40, 2))
    np.testing.assert_allclose(engine.inverse_dynamics(z, zd, zdd), joint_torques(z, zd, zdd), rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------------- random chains
@st.composite
def chains(draw):
    """A chain of 1 to 6 bodies with random geometry, offsets, ends and loads."""
    n = draw(st.integers(1, 6))
    length = st.floats(0.1, 0.6)
    small = st.floats(-0.05, 0.05)
    bodies, joints, loads = [], [], []
    for k in range(n):
        L = draw(length)
        end = (L, draw(small)) if draw(st.booleans()) else None
        bodies.append(Body(f"b{k}", draw(st.floats(0.2, 8.0)), (draw(st.floats(0.1, 0.3)), draw(small)),
                           draw(st.floats(0.002, 0.2)), end))
        parent = GROUND if k == 0 else f"b{k - 1}"
        at_parent = (draw(small), draw(small)) if k == 0 else (joints[-1].at_child[0] + draw(length), draw(small))
        joints.append(Joint(f"q{k}", "pin", parent, f"b{k}", at_parent, (draw(small), draw(small)),
                            offset=draw(st.floats(-1.0, 1.0))))
        if draw(st.booleans()):
            force = (draw(st.floats(-20, 20)), draw(st.floats(-20, 20)))
            loads.append(Load(f"b{k}", (draw(length), draw(small)), force))
    return Model("chain", (0.0, -9.81), tuple(bodies), tuple(joints), tuple(loads))


@settings(max_examples=40, deadline=None)
@given(chains(), st.integers(0, 2**32 - 1))
def test_minimal_equations_agree_with_inverse_dynamics_and_the_penalty_accelerations(model, seed):
    engine, rng = Engine(model), np.random.default_rng(seed)
    J = engine.n_joints
    z, zd, zdd, tau = rng.uniform(-1.5, 1.5, J), rng.uniform(-2, 2, J), rng.uniform(-5, 5, J), rng.uniform(-5, 5, J)
    M, h = engine.mass_matrix(z), engine.bias(z, zd)
    np.testing.assert_allclose(M, M.T, rtol=0, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(M) > 0)
    tau_inv = engine.inverse_dynamics(z, zd, zdd)
    np.testing.assert_allclose(M @ zdd + h, tau_inv, rtol=1e-10, atol=1e-10 * np.max(np.abs(tau_inv)))
    y = engine.state_from_joints(z, zd)
    assert engine.constraint_violation(y) < 1e-12
    np.testing.assert_allclose(engine.joints_from_state(y), (z, zd), rtol=0, atol=1e-12)
    stiff = Engine(model, alpha=1e9)  # the penalty's error, O(m / (alpha d^2)), below the tolerance
    found = joint_accelerations(stiff, stiff.accelerations(stiff.state_from_joints(z, zd), tau))
    assert relative_error(found, np.linalg.solve(M, tau - h)) < 1e-4


def test_a_tree_with_a_joint_off_its_parents_points_agrees_with_its_minimal_equations():
    engine, rng = Engine(tree_model(), alpha=1e9), np.random.default_rng(5)
    assert len(engine.lin_const) == 2  # one extra point, two linear constraints
    for _ in range(20):
        z, zd, tau = rng.uniform(-1, 1, 4), rng.uniform(-2, 2, 4), rng.uniform(-5, 5, 4)
        y = engine.state_from_joints(z, zd)
        assert engine.constraint_violation(y) < 1e-12
        expected = np.linalg.solve(engine.mass_matrix(z), tau - engine.bias(z, zd))
        assert relative_error(joint_accelerations(engine, engine.accelerations(y, tau)), expected) < 1e-6


def test_point_positions_name_every_body_s_joint_and_end():
    points = Engine(arm2_model()).point_positions([0.0, math.pi / 2])
    np.testing.assert_allclose(points["forearm.joint"], [0.30, 0.0], atol=1e-15)
    np.testing.assert_allclose(points["forearm.end"], [0.30, 0.33], atol=1e-15)
    np.testing.assert_allclose(points["upper_arm.end"], [0.30, 0.0], atol=1e-15)


# ---------------------------------------------------------------------- the compiled RK4
@pytest.mark.parametrize("kinematics", ["paper", "exact"])
def test_simulate_pd_agrees_with_dop853_on_the_forearm_s_minimal_equation(kinematics):
    """The engine's RK4 (1 ms) on the forearm under eq. 5's closed-form torque and PD 80 / 0.3 against
    scipy's DOP853 (rtol 1e-11) on I1 theta'' = tau - G cos theta. They differ by 2.1e-7 deg (the
    penalty's O(1e-6) relative error; RK4's O(dt^4) is below it): 1e-5 deg is far below the 0.22 deg
    by which the paper's kinematics (derivatives in t*) leave eq. 5's angle."""
    from scipy.integrate import solve_ivp

    from fdbench.multibody.motions import eq5

    n = 1000
    half = np.linspace(0.0, 1.0, 2 * n + 1)
    ref, ref_w, ref_a = eq5(half, kinematics)
    result = Engine(forearm_model()).simulate_pd([ref[0]], [ref_w[0]], 1.0 / n, n,
                                                 forearm.torque_along(ref, ref_w, ref_a)[:, None], ref[:, None],
                                                 ref_w[:, None], [80.0], [0.3])
    assert (result.status, result.steps_done) == (OK, n)

    def drive(t, theta, w):
        r, rw, ra = (float(v[0]) for v in eq5(np.array([t]), kinematics))
        return forearm.torque_along(r, rw, ra) + 80.0 * (r - theta) + 0.3 * (rw - w)

    exact = solve_ivp(forearm.feedback_rhs(drive), (0.0, 1.0), [ref[0], ref_w[0]], method="DOP853", rtol=1e-11,
                      atol=1e-12, t_eval=half[::2])
    assert np.max(np.abs(np.degrees(result.z[:, 0] - exact.y[0]))) < 1e-5
    assert result.max_violation < 1e-6


def _leg_motion(t):
    """A slow swing of the leg: the thigh through -90 deg, knee and ankle bending (rad, rad/s, rad/s^2)."""
    centre, amplitude, rate = np.array([-math.pi / 2, -0.3, 1.4]), np.array([0.3, 0.2, 0.15]), 2 * math.pi
    t = np.asarray(t, dtype=float)[:, None]
    return (centre + amplitude * np.sin(rate * t), amplitude * rate * np.cos(rate * t),
            -amplitude * rate**2 * np.sin(rate * t))


def test_a_hanging_leg_swings_through_minus_90_degrees_open_loop():
    engine, n = Engine(leg3_model(), alpha=1e8), 1000  # 12 kg hanging: the violation is about 16 / alpha (m^2)
    dt = 1.0 / n
    half = np.linspace(0.0, 1.0, 2 * n + 1)
    z, zd, zdd = _leg_motion(half)
    tau = engine.inverse_dynamics(z, zd, zdd)
    zero = np.zeros(3)
    result = engine.simulate_pd(z[0], zd[0], dt, n, tau, z, zd, zero, zero)
    assert (result.status, result.steps_done) == (OK, n)
    thigh = result.z[:, 0]
    assert thigh.min() < -math.pi / 2 < thigh.max()  # it went through the sin form's singularity
    rmse = math.sqrt(np.mean(np.degrees(result.z - z[::2]) ** 2))
    assert rmse < 0.01
    assert result.max_violation < 1e-6


def test_the_sin_form_alone_would_be_singular_where_the_leg_hangs():
    engine = Engine(leg3_model(), alpha=1e9)
    z, zd, tau = [-math.pi / 2, 0.0, math.pi / 2], [0.5, -0.2, 0.1], [1.0, 2.0, 3.0]
    expected = np.linalg.solve(engine.mass_matrix(z), tau - engine.bias(z, zd))
    y = engine.state_from_joints(z, zd)
    assert relative_error(joint_accelerations(engine, engine.accelerations(y, tau)), expected) < 1e-5
    engine.params[mb.SWITCH_COS] = 0.0  # the paper's form for every body
    with np.errstate(all="ignore"):
        assert not relative_error(joint_accelerations(engine, engine.accelerations(y, tau)), expected) < 1.0


def test_simulate_pd_stops_on_a_constraint_violation():
    engine = Engine(forearm_model(), alpha=1.0)  # a penalty too weak to hold the constraint
    result = engine.simulate_pd([0.0], [0.0], 1e-3, 1000, np.full((2001, 1), 200.0), np.zeros((2001, 1)),
                                np.zeros((2001, 1)), [0.0], [0.0])
    assert result.status == CONSTRAINT
    assert result.steps_done < 1000
    assert np.isnan(result.z[-1, 0]) and np.isfinite(result.z[result.steps_done, 0])


# ---------------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, message", [
    (lambda e: e.accelerations(np.zeros(12), [0.0]), r"tau must have shape \(2,\)"),
    (lambda e: e.accelerations(np.zeros(11), [0.0, 0.0]), r"the state must have shape \(12,\)"),
    (lambda e: e.constraint_violation(np.zeros(6)), r"the state must have shape \(12,\)"),
    (lambda e: e.state_from_joints([0.0], [0.0]), r"z must have shape \(2,\)"),
    (lambda e: e.joints_from_state(np.zeros(6)), r"states must have shape \(12,\)"),
    (lambda e: e.inverse_dynamics([0.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3), r"joint values must have shape \(2,\)"),
    (lambda e: e.mass_matrix(np.zeros((3, 1))), r"joint values must have shape \(2,\)"),
    (lambda e: e.simulate_pd([0.0, 0.0], [0.0, 0.0], 1e-3, 10, np.zeros((20, 2)), np.zeros((21, 2)),
                             np.zeros((21, 2)), [1.0, 1.0], [0.0, 0.0]), r"tau_half must have shape \(21, 2\)"),
    (lambda e: e.simulate_pd([0.0, 0.0], [0.0, 0.0], 1e-3, 10, np.zeros((21, 2)), np.zeros((21, 2)),
                             np.zeros((21, 2)), [1.0], [0.0, 0.0]), r"kp must have shape \(2,\)"),
    (lambda e: e.simulate_pd([0.0, 0.0], [0.0, 0.0], float("nan"), 10, np.zeros((21, 2)), np.zeros((21, 2)),
                             np.zeros((21, 2)), [1.0, 1.0], [0.0, 0.0]), "dt must be a positive number"),
    (lambda e: e.simulate_pd([0.0, 0.0], [0.0, 0.0], 1e-3, 0, np.zeros((1, 2)), np.zeros((1, 2)),
                             np.zeros((1, 2)), [1.0, 1.0], [0.0, 0.0]), "n_steps must be a positive integer"),
])
def test_arrays_of_the_wrong_shape_are_refused_before_a_kernel_reads_them(call, message):
    with pytest.raises(ValueError, match=message):
        call(Engine(arm2_model()))


@pytest.mark.parametrize("penalty, message", [({"alpha": 0.0}, "alpha must be in"), ({"omega": float("nan")}, "omega"),
                                              ({"xi": -1.0}, "xi must be in")])
def test_penalty_parameters_out_of_range_are_refused(penalty, message):
    with pytest.raises(ValueError, match=message):
        Engine(forearm_model(), **penalty)


@pytest.mark.parametrize("model", [forearm_model, arm2_model])  # the unrolled 2 x 2 solve and the general one
def test_a_non_finite_start_stops_as_non_finite(model):
    engine = Engine(model())
    J, nan_first = engine.n_joints, np.r_[float("nan"), np.zeros(engine.n_joints - 1)]
    result = engine.simulate_pd(nan_first, np.zeros(J), 1e-3, 10, np.zeros((21, J)), np.zeros((21, J)),
                                np.zeros((21, J)), np.ones(J), np.zeros(J))
    assert (result.status, result.steps_done) == (NONFINITE, 0)


# ---------------------------------------------------------------------- one stage code for every kernel
def _tree_run(engine: Engine, n: int = 200, alpha_torque: float = 1.0):
    """A PD run of the tree model (linear constraints, both angle forms) and its inputs."""
    half = np.linspace(0.0, 0.2, 2 * n + 1)[:, None]
    z = np.array([0.3, -0.5, 0.8, 1.2]) + 0.4 * np.sin(8 * half)
    zd = np.broadcast_to(3.2 * np.cos(8 * half), z.shape).copy()
    tau = alpha_torque * engine.inverse_dynamics(z, zd, np.zeros_like(z))
    kp, kd = np.full(4, 40.0), np.full(4, 2.0)
    return engine.simulate_pd(z[0], zd[0], 0.2 / n, n, tau, z, zd, kp, kd), tau, z, zd, kp, kd


def test_rates_at_a_run_s_states_are_the_run_s_rates_to_the_bit():
    engine = Engine(tree_model())
    result, tau, z, zd, kp, kd = _tree_run(engine)
    assert (result.status, result.steps_done) == (OK, 200)
    rates, applied = engine.rates(result.states, tau[::2], z[::2], zd[::2], np.zeros_like(z[::2]), kp, kd)
    assert np.array_equal(rates, result.rates) and np.array_equal(applied, result.applied)


def test_constraint_violation_is_the_largest_residual_of_the_constraints():
    engine = Engine(tree_model())
    y = engine.state_from_joints([0.3, -0.5, 0.8, 1.2], [0.1, 0.2, -0.3, 0.4])
    y += np.random.default_rng(3).normal(0.0, 1e-4, y.shape)
    residuals = []
    for b in range(engine.n_joints):
        xy = [engine.pt_fixed[pt] if engine.pt_index[pt] < 0 else y[engine.pt_index[pt]:engine.pt_index[pt] + 2]
              for pt in engine.body_pts[b]]
        (dx, dy), (d, beta) = xy[1] - xy[0], engine.body_geom[b]
        psi = y[engine.n_p + b] + beta
        angle = dy - d * math.sin(psi) if abs(math.cos(psi)) >= mb.SIN_FORM_MIN_COS else dx - d * math.cos(psi)
        residuals += [dx * dx + dy * dy - d * d, angle]
    for idx, coef, const in zip(engine.lin_idx, engine.lin_coef, engine.lin_const):
        residuals.append(const + sum(c * y[k] for k, c in zip(idx, coef) if k >= 0))
    expected = max(abs(r) for r in residuals)
    assert expected > 1e-5
    assert engine.constraint_violation(y) == pytest.approx(expected, rel=1e-12)


def test_state_from_joints_gives_a_fresh_state_at_every_call():
    engine = Engine(arm2_model())
    first = engine.state_from_joints([0.2, 0.4], [0.0, 1.0])
    expected = first.copy()
    first[:] = 99.0  # a caller's change must not reach the next call
    assert np.array_equal(engine.state_from_joints([0.2, 0.4], [0.0, 1.0]), expected)
    assert not np.array_equal(engine.state_from_joints([0.2, 0.5], [0.0, 1.0]), expected)
    assert np.array_equal(engine.state_from_joints([0.2, 0.4], [0.0, 1.0]), expected)


def test_sensitivities_stop_on_a_constraint_violation_where_rk4_does():
    from fdbench.multibody.sensitivity import rk4_sensitivity

    engine, n = Engine(forearm_model(), alpha=1.0), 1000  # a penalty too weak to hold the constraint
    tau, rows = np.full((2 * n + 1, 1), 200.0), np.zeros((2 * n + 1, 1))
    y0 = engine.state_from_joints([0.0], [0.0])
    expected = engine.simulate(y0, 1e-3, n, tau, rows, rows, rows, 0.0, 0.0)
    assert expected.status == CONSTRAINT
    states, rates = np.full((n + 1, 6), np.nan), np.full((n + 1, 6), np.nan)
    applied, dz = np.full((n + 1, 1), np.nan), np.full((n + 1, 1, 1), np.nan)
    code, done = rk4_sensitivity(y0, 1e-3, n, tau, rows, rows, np.ones((2 * n + 1, 1)), np.zeros(1, dtype=np.int64),
                                 1, *engine.kernel_args(), None, states, rates, applied, dz)
    assert (code, done) == (expected.status, expected.steps_done)
    assert np.array_equal(states, expected.states, equal_nan=True)
    assert np.isfinite(dz[done, 0, 0]) and np.isnan(dz[done + 1, 0, 0])
