"""The minimal equations in CasADi (fdbench.multibody.symbolic) and the methods built on them, the
collocation (fdbench.collocation) and the time-varying LQR (fdbench.multibody.lqr), for any
model description:

- M(z), h(z, z') and the inverse dynamics against the engine's (compiled eq. 3, composite bodies) and the independent
  reference (tests/helpers/reference_dynamics.py) on random chains and trees, to 1e-9 relative;
- the arm's M and h against the closed form of Lagrange's equations (the values of arm2.toml);
- the linearisation against central differences of the forward dynamics;
- collocation of a minimum-jerk motion on the library's arm2 and leg3: solved, tracked;
- the Functions built on first use: a collocation never forms the symbolic solve of M;
- the LQR's gain about a held posture (a long horizon) against scipy's algebraic Riccati gain of a
  linearisation by finite differences of the engine's dynamics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import reference_dynamics as ref
from helpers.multibody_strategies import models_and_states, models_with_paths_and_free_joints

from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.symbolic import MinimalDynamics


def assert_relative(actual, expected, rel, what, floor=1e-12):
    """max |actual - expected| <= rel * RMS(expected) + floor (rounding where the values are all ~0)."""
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape}, expected {expected.shape}"
    scale = float(np.sqrt(np.mean(expected**2))) if expected.any() else 1.0
    error = float(np.max(np.abs(actual - expected)))
    assert error <= rel * scale + floor, f"{what}: error {error:.3g} > {rel:g} x {scale:.3g}"


class MinimumJerk:
    """Every joint from ``start`` to ``goal`` (rad) in ``duration`` s, from rest to rest."""

    def __init__(self, start, goal, duration=1.0):
        self.start, self.goal, self.duration = np.asarray(start, float), np.asarray(goal, float), float(duration)

    def __call__(self, t):
        u = np.clip(np.asarray(t, dtype=float) / self.duration, 0.0, 1.0)[..., None]
        span, T = self.goal - self.start, self.duration
        return (self.start + span * (10 * u**3 - 15 * u**4 + 6 * u**5), span * (30 * u**2 - 60 * u**3 + 30 * u**4) / T,
                span * (60 * u - 180 * u**2 + 120 * u**3) / T**2)


class Hold:
    """The joints held at ``angles`` (rad) for ``duration`` s."""

    def __init__(self, angles, duration):
        self.angles, self.duration = np.asarray(angles, dtype=float), float(duration)

    def __call__(self, t):
        shape = np.shape(t) + self.angles.shape
        return np.broadcast_to(self.angles, shape).copy(), np.zeros(shape), np.zeros(shape)


def random_states(n_joints, count, seed):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-math.pi, math.pi, (count, n_joints)), rng.uniform(-5, 5, (count, n_joints)),
            rng.uniform(-50, 50, (count, n_joints)))


# ----------------------------------------------------------------------------- M, h, inverse dynamics


@settings(max_examples=25, deadline=None)
@given(case=models_and_states())
def test_mass_matrix_bias_inverse_and_forward_match_the_engine_and_the_reference(case):
    model, _ = case
    dynamics, engine, tree = MinimalDynamics(model), Engine(model), ref.tree(model)
    z, zd, zdd = random_states(model.n_joints, 4, seed=len(model.joints))
    for actual, numpy_engine, reference, what in (
            (dynamics.mass_matrix(z), engine.mass_matrix(z), ref.mass_matrix(tree, z), "M"),
            (dynamics.bias(z, zd), engine.bias(z, zd), ref.bias(tree, z, zd), "h"),
            (dynamics.inverse(z, zd, zdd), engine.inverse_dynamics(z, zd, zdd), ref.inverse_dynamics(tree, z, zd, zdd),
             "inverse")):
        assert_relative(actual, numpy_engine, 1e-9, f"{what} against the engine")
        assert_relative(actual, reference, 1e-9, f"{what} against the reference")
    assert_relative(dynamics.inverse(z[0], zd[0], zdd[0]), ref.inverse_dynamics(tree, z[0], zd[0], zdd[0]), 1e-9,
                    "inverse of one state (J,)")
    tau = zdd[1]  # any torques (N m)
    assert_relative(dynamics.forward(z[1], zd[1], tau), ref.forward_dynamics(tree, z[1], zd[1], tau), 1e-9, "forward")


def test_forward_dynamics_inverts_the_inverse_dynamics_on_the_leg():
    dynamics = MinimalDynamics(find_model("leg3"))
    z, zd, zdd = random_states(3, 6, seed=3)
    tau = dynamics.inverse(z, zd, zdd)
    assert_relative(dynamics.forward(z, zd, tau), zdd, 1e-12, "forward(inverse)")
    assert dynamics.forward(z[0], zd[0], tau[0]).shape == (3,)


def test_the_arms_mass_matrix_and_bias_are_lagranges_closed_form():
    model = find_model("arm2")
    upper, fore = model.body("upper_arm"), model.body("forearm")
    m0, L0G, m, L1G = upper.mass, upper.com[0], fore.mass, fore.com[0]
    I0, I1 = upper.inertia + m0 * L0G**2, fore.inertia + m * L1G**2  # about the shoulder, the elbow
    L01, (load,) = model.joints[1].at_parent[0], model.loads
    L12, F, g = load.at[0], -load.force[1], -model.gravity[1]
    b, G = m * L01 * L1G, m * g * L1G + F * L12
    z, zd, _ = random_states(2, 5, seed=7)
    s, e, ws, we = z[:, 0], z[:, 1], zd[:, 0], zd[:, 1]
    M = np.stack([np.stack([I0 + I1 + m * L01**2 + 2 * b * np.cos(e), I1 + b * np.cos(e)], axis=-1),
                  np.stack([I1 + b * np.cos(e), np.full_like(e, I1)], axis=-1)], axis=-2)
    upper_moment = m0 * g * L0G + (m * g + F) * L01
    h = np.stack([-b * np.sin(e) * (2 * ws * we + we**2) + upper_moment * np.cos(s) + G * np.cos(s + e),
                  b * np.sin(e) * ws**2 + G * np.cos(s + e)], axis=-1)
    dynamics = MinimalDynamics(model)
    assert_relative(dynamics.mass_matrix(z), M, 1e-12, "M")
    assert_relative(dynamics.bias(z, zd), h, 1e-12, "h")


@pytest.mark.parametrize("name", ["forearm", "leg3"])
def test_linearisation_is_the_derivative_of_the_forward_dynamics(name):
    dynamics = MinimalDynamics(find_model(name))
    J = dynamics.n_joints
    z, zd, zdd = (v[0] for v in random_states(J, 1, seed=11))
    tau = dynamics.inverse(z, zd, zdd)
    A, B = dynamics.linearisation(z, zd, tau)
    assert A.shape == (2 * J, 2 * J) and B.shape == (2 * J, J)
    step = 1e-6

    def rate(x, u):
        return np.concatenate([x[J:], dynamics.forward(x[:J], x[J:], u)])

    x = np.concatenate([z, zd])
    A_fd = np.stack([(rate(x + d, tau) - rate(x - d, tau)) / (2 * step) for d in step * np.eye(2 * J)], axis=-1)
    B_fd = np.stack([(rate(x, tau + d) - rate(x, tau - d)) / (2 * step) for d in step * np.eye(J)], axis=-1)
    assert_relative(A, A_fd, 1e-6, "A")
    assert_relative(B, B_fd, 1e-6, "B")
    A_k, B_k = dynamics.linearisation(z[None], zd[None], tau[None])  # k states: the same, stacked
    assert np.array_equal(A_k[0], A) and np.array_equal(B_k[0], B)


# ----------------------------------------------------------------------------- collocation


@pytest.mark.parametrize("name, start, goal", [
    ("arm2", [-0.35, 0.52], [0.26, 0.96]),
    ("leg3", [0.0, -0.2, 0.0], [0.8, -1.0, 0.2]),  # the thigh swings forward from hanging
])
def test_collocation_tracks_a_minimum_jerk_motion(name, start, goal):
    from fdbench.collocation import collocate

    model, motion = find_model(name), MinimumJerk(start, goal)
    result = collocate(model, motion, nodes=30)
    assert result.success, result.message
    assert result.angles.shape == result.velocities.shape == result.torque.shape == (31, model.n_joints)
    assert result.torque_mid.shape == (30, model.n_joints)
    error = result.angles - motion(result.t)[0]
    assert math.degrees(float(np.sqrt(np.mean(error**2)))) < 1e-2  # deg: the regularisation's price only
    torques = MinimalDynamics(model).inverse(*motion(result.t))
    inside = slice(0, 25)  # the free final state lets the last nodes' torques drift from the inverse dynamics
    assert np.max(np.abs(result.torque - torques)[inside]) < 1e-2 * np.max(np.abs(torques))


def test_the_collocation_builds_the_inverse_dynamics_alone():
    """The Functions are built on first use: a collocation (implicit dynamics) never forms the
    symbolic solve of M behind the forward dynamics and the linearisation, the costly part for many
    coordinates; asking for the forward dynamics builds it then."""
    import dataclasses

    from fdbench.collocation import collocate
    from fdbench.multibody import symbolic

    model = dataclasses.replace(find_model("leg3"), name="leg3_lazy")  # a model no other test has built
    built = symbolic._forward_expression.cache_info().misses
    assert collocate(model, MinimumJerk([0.0, -0.2, 0.0], [0.3, -0.5, 0.1]), nodes=10).success
    assert symbolic._forward_expression.cache_info().misses == built
    z, zd, zdd = random_states(3, 2, seed=1)
    dynamics = MinimalDynamics(model)
    assert_relative(dynamics.forward(z, zd, dynamics.inverse(z, zd, zdd)), zdd, 1e-10, "forward(inverse)")
    assert symbolic._forward_expression.cache_info().misses == built + 1


def test_collocation_refuses_a_motion_of_other_joints_before_any_work():
    from fdbench.collocation import collocate

    with pytest.raises(ValueError, match="hip, knee, ankle"):
        collocate(find_model("leg3"), MinimumJerk([0.0, 0.0], [0.1, 0.1]))
    with pytest.raises(ValueError, match="--nodes"):
        collocate(find_model("leg3"), MinimumJerk([0.0] * 3, [0.1] * 3), nodes=1)


# ----------------------------------------------------------------------------- LQR


def engine_linearisation(engine, z, tau, step=1e-6):
    """A, B by central differences of the engine's numpy dynamics z'' = M^-1 (tau - h) at rest."""
    J = engine.n_joints

    def rate(x, u):
        zdd = np.linalg.solve(engine.mass_matrix(x[:J]), u - engine.bias(x[:J], x[J:]))
        return np.concatenate([x[J:], zdd])

    x = np.concatenate([z, np.zeros(J)])
    A = np.stack([(rate(x + d, tau) - rate(x - d, tau)) / (2 * step) for d in step * np.eye(2 * J)], axis=-1)
    B = np.stack([(rate(x, tau + d) - rate(x, tau - d)) / (2 * step) for d in step * np.eye(J)], axis=-1)
    return A, B


@pytest.mark.parametrize("name, posture, weights", [
    ("arm2", [0.3, 0.8], {}),
    ("leg3", [0.5, -0.8, 0.2], {}),
    ("leg3", [0.5, -0.8, 0.2], {"q_angle": [1e4, 3e3, 1e3], "q_rate": 2.0, "r_torque": [0.5, 1.0, 4.0]}),  # per joint
])
def test_lqr_gain_about_a_held_posture_is_the_algebraic_riccati_gain(name, posture, weights):
    from scipy.linalg import solve_continuous_are

    from fdbench.multibody.lqr import lqr_gains, warm_up

    model = find_model(name)
    warm_up(model)
    engine, J, z = Engine(model), model.n_joints, np.array(posture)
    q = np.concatenate([np.broadcast_to(weights.get("q_angle", 1e4), J),
                        np.broadcast_to(weights.get("q_rate", 1.0), J)])
    r = np.broadcast_to(weights.get("r_torque", 1.0), J)
    A, B = engine_linearisation(engine, z, engine.bias(z, np.zeros(J)))  # held by the gravity torques
    P = solve_continuous_are(A, B, np.diag(q), np.diag(r))
    expected = np.diag(1 / r) @ B.T @ P
    gains = lqr_gains(model, Hold(z, duration=3.0), **weights)(np.array([0.0, 1.5, 3.0]))
    assert gains.shape == (3, J, 2 * J)
    for K in gains:
        assert_relative(K, expected, 1e-5, "K")


def test_lqr_refuses_weights_of_another_number_of_joints():
    from fdbench.multibody.lqr import lqr_gains

    with pytest.raises(ValueError, match="q_angle must be one number or 3"):
        lqr_gains(find_model("leg3"), Hold([0.0, 0.0, 0.0], duration=1.0), q_angle=[1.0, 2.0])


@settings(max_examples=8, deadline=None)
@given(model=models_with_paths_and_free_joints(max_bodies=3), seed=st.integers(0, 2**16))
def test_free_and_path_joints_match_the_reference(model, seed):
    """The CasADi equations of models with free joints and joint paths (the spline by if_else) against
    the reference's jets: inverse dynamics, M, h to 1e-9 relative, and the forward dynamics inverts
    the inverse dynamics."""
    dynamics, t = MinimalDynamics(model), ref.GeneralTree(model)
    rng = np.random.default_rng(seed)
    J = t.n_joints
    z, zd, zdd = rng.uniform(-3, 3, (3, J)), rng.uniform(-5, 5, (3, J)), rng.uniform(-50, 50, (3, J))
    assert_relative(dynamics.inverse(z, zd, zdd), t.inverse_dynamics(z, zd, zdd), 1e-9, "inverse dynamics")
    assert_relative(dynamics.mass_matrix(z), t.mass_matrix(z), 1e-9, "M(z)")
    assert_relative(dynamics.bias(z, zd), t.bias(z, zd), 1e-9, "h(z, z')")
    tau = t.inverse_dynamics(z, zd, zdd)
    assert_relative(dynamics.forward(z, zd, tau), zdd, 1e-8, "forward dynamics")
