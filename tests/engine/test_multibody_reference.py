"""The multibody engine (fdbench.multibody.engine, the paper's mixed coordinates and penalty
formulation) against the independent minimal-coordinate reference (tests/helpers/reference_dynamics.py:
recursive Newton-Euler and the kinetic energy's mass matrix, DOP853 at rtol = atol = 1e-12), on the
built-in forearm and arm and on random chains and trees of 1 to 6 bodies (tests/helpers/multibody_strategies.py):

- inverse dynamics, M(z) and h(z, z') to 1e-9 relative (of the RMS of the reference's values);
- forward dynamics: the engine's compiled RK4 (dt 1e-4 s) under a per-joint PD law with feedforward
  torques to 1e-4 degrees of the reference's solution over 0.5 s: the forearm and the arm at the
  paper's penalty (alpha 1e7, omega 10 rad/s), random chains and trees at alpha 1e7, omega 3e3.

Why random trees need the larger omega. A body's angle coordinate carries no mass: its constraint's
violation Phi_b follows Phi'' + 2 xi omega Phi' + omega^2 Phi = tau_b / (alpha dPhi_b/dphi_b) under the
net joint torque tau_b on the body, so the angle lags its body by about
tau_b / (alpha omega^2 d_b^2 cos^2) (d_b: its points' distance; cos^2 >= 0.04, sin^2 in the cos
form), while the points, hence the bodies, move right. A 5 cm body carrying hundreds of N m lags by
up to 0.24 deg at (1e7, 10) and still 2.5e-3 deg at (1e9, 10): a larger alpha alone misses 1e-4,
and it costs digits where a body's mass sits at its joint (the leading matrix's condition grows
with alpha over the end point's mass I_joint / d^2: 6.1 kg at the pivot with 1e-4 kg m^2 departs
by 9e-6 deg at alpha 1e7, 1.5e-4 at 1e8, 1.8e-3 at 1e9, whatever omega and dt). The lag falls as
1 / (alpha omega^2) and the rounding grows with alpha only, so omega carries the factor, up to
where RK4 (dt 1e-4 s) no longer follows the constraint's own motion at omega: at omega dt = 1 a
light leaf (0.1 kg, 5 cm) departs by 7.5e-5 deg (3.4e-6 at dt 5e-5, 1.4e-7 at 2.5e-5; NaN at
omega dt = 3). Random trees run at (1e7, 3e3), omega dt = 0.3: that leaf 4e-6 deg, the 0.24 deg
tree 9.5e-6, the worst of 30 draws 9.8e-6 and a 60-draw search steered to the largest deviation
(hypothesis.target) 3.3e-6: a factor 10 under 1e-4 deg. The strategies keep their full ranges.

The two share nothing but the model description: no points, constraints or penalties on the
reference's side, and the reference is itself checked in tests/engine/test_reference_dynamics.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdbench.multibody import engine as engine_module

from helpers import reference_dynamics as ref
from helpers.models import hopper_model
from helpers.multibody_strategies import (arm2_model, forearm_model, models, models_and_motions, models_and_states,
                                  models_with_paths_and_free_joints)

BUILT_IN = {"forearm": forearm_model, "arm2": arm2_model}
DT = 1e-4  # s, RK4's step: its error (O(dt^4)) is far below 1e-4 degrees at the models' frequencies
DURATION = 0.5  # s
BANDWIDTH = 10.0  # rad/s, of each joint's PD loop
TOLERANCE_DEG = 1e-4
RANDOM_ALPHA, RANDOM_OMEGA = 1e7, 3e3  # eq. 12 on random trees: omega dt = 0.3 (see the module docstring)


def assert_relative(actual, expected, rel, what, floor=0.0):
    """max |actual - expected| <= rel * RMS(expected) (or rel when expected is all zero) + floor
    (the rounding of values that nearly cancel)."""
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape}, expected {expected.shape}"
    scale = float(np.sqrt(np.mean(expected**2))) if expected.any() else 1.0
    error = float(np.max(np.abs(actual - expected)))
    assert error <= rel * scale + floor, f"{what}: error {error:.3g} > {rel:g} x {scale:.3g} + {floor:.3g}"


def random_states(n_joints, count, seed):
    """count random (z, z', z'') rows, shapes (count, J): anywhere, up to 5 rad/s and 50 rad/s^2."""
    rng = np.random.default_rng(seed)
    return (rng.uniform(-math.pi, math.pi, (count, n_joints)), rng.uniform(-5, 5, (count, n_joints)),
            rng.uniform(-50, 50, (count, n_joints)))


# ----------------------------------------------------------------------------- inverse dynamics, M, h


def check_inverse_dynamics(model, seed):
    engine, t = engine_module.Engine(model), ref.tree(model)
    assert engine.joints == tuple(joint.name for joint in model.joints) and engine.n_joints == len(model.joints)
    z, zd, zdd = random_states(t.n_joints, 10, seed)
    expected = ref.inverse_dynamics(t, z, zd, zdd)
    assert_relative(engine.inverse_dynamics(z, zd, zdd), expected, 1e-9, "inverse dynamics (n, J)")
    assert_relative(engine.inverse_dynamics(z[0], zd[0], zdd[0]), expected[0], 1e-9, "inverse dynamics (J,)")


def check_mass_matrix_and_bias(model, z, zd):
    engine, t = engine_module.Engine(model), ref.tree(model)
    M = engine.mass_matrix(z)
    assert_relative(M, ref.mass_matrix(t, z), 1e-9, "M(z)")
    assert np.allclose(M, M.T, rtol=1e-12, atol=0) and np.linalg.eigvalsh(M).min() > 0
    # h can nearly cancel (slow motion, little gravity): rounding at the scale of its terms, M z'^2 and M g
    terms = float(np.sqrt(np.mean(M**2))) * (1.0 + float(np.sum(np.asarray(zd) ** 2)))
    assert_relative(engine.bias(z, zd), ref.bias(t, z, zd), 1e-9, "h(z, z')", floor=1e-12 * terms)


@pytest.mark.parametrize("name", BUILT_IN)
def test_built_in_inverse_dynamics_mass_matrix_and_bias(name):
    model = BUILT_IN[name]()
    check_inverse_dynamics(model, seed=0)
    z, zd, _ = random_states(len(model.joints), 1, seed=1)
    check_mass_matrix_and_bias(model, z[0], zd[0])


@settings(max_examples=25, deadline=None)
@given(model=models(), seed=st.integers(0, 2**16))
def test_inverse_dynamics_matches_the_reference(model, seed):
    check_inverse_dynamics(model, seed)


@settings(max_examples=25, deadline=None)
@given(case=models_and_states())
def test_mass_matrix_and_bias_match_the_reference(case):
    model, (z, zd, _) = case
    check_mass_matrix_and_bias(model, z, zd)


# ----------------------------------------------------------------------------- forward dynamics under PD


def pd_gains(t, z):
    """Per-joint gains (N m/rad, N m s/rad), shape (J,) each, for a closed loop that is stable about
    the posture z whatever the model and not stiffer than it needs: kp_j = BANDWIDTH^2 m_j plus the
    absolute row sum of the potential's Hessian (gravity and loads; by Gershgorin the stiffness
    kp + Hessian stays positive definite), kd_j = 2 sqrt(kp_j m_j) (critically damped on its own),
    with m_j = 1 / (M^-1)_jj the inertia joint j drives when the other joints are free (M_jj instead
    would make a light body on a heavy one ring at hundreds of rad/s)."""
    inertia = 1.0 / np.diag(np.linalg.inv(ref.mass_matrix(t, z)))
    step = 1e-6
    rest = np.zeros_like(z)
    hessian = np.stack([(ref.bias(t, z + e, rest) - ref.bias(t, z - e, rest)) / (2 * step)
                        for e in step * np.eye(len(z))], axis=-1)
    kp = BANDWIDTH**2 * inertia + np.abs(hessian).sum(axis=1)
    return kp, 2 * np.sqrt(kp * inertia)


def check_pd_simulation(model, centre, amplitude, frequency, phase, alpha=1e7, omega=10.0):
    """The engine's simulate_pd (penalty factor ``alpha``, natural frequency ``omega`` rad/s) against
    the reference's PD simulation:
    the joints track ref_j(t) = centre_j + amplitude_j sin(2 pi frequency_j t + phase_j) from
    0.05 rad off it, under the reference motion's inverse-dynamics torques plus a 3 Hz disturbance
    of 20 kp_j / BANDWIDTH^2 N m (about 0.2 rad of tracking error)."""
    engine, t = engine_module.Engine(model, alpha=alpha, omega=omega), ref.tree(model)
    J = t.n_joints

    def motion(time):
        """ref, ref', ref'' (..., J) at times (...) s."""
        arg = 2 * np.pi * frequency * np.asarray(time)[..., None] + phase
        w = 2 * np.pi * frequency
        return (centre + amplitude * np.sin(arg), amplitude * w * np.cos(arg), -amplitude * w**2 * np.sin(arg))

    kp, kd = pd_gains(t, centre + amplitude * np.sin(phase))
    push = 20 * kp / BANDWIDTH**2

    def feedforward(time):
        """N m, shape (..., J)."""
        arg = 6 * np.pi * np.asarray(time)[..., None] + np.arange(J)
        return ref.inverse_dynamics(t, *motion(time)) + push * np.sin(arg)

    n_steps = round(DURATION / DT)
    half = np.arange(2 * n_steps + 1) * (DT / 2)
    z0, zd0, _ = motion(0.0)
    z0 = z0 + 0.05 * (-1.0) ** np.arange(J)
    result = engine.simulate_pd(z0, zd0, DT, n_steps, feedforward(half), motion(half)[0], motion(half)[1], kp, kd)
    assert (result.status, result.steps_done) == (0, n_steps), f"status {result.status} at step {result.steps_done}"
    every = 100  # compare every 10 ms
    times = np.arange(0, n_steps + 1, every) * DT
    expected, _ = ref.simulate_pd(t, z0, zd0, DURATION, lambda time: feedforward(time),
                                  lambda time: motion(time)[:2], kp, kd, times)
    difference = np.degrees(np.angle(np.exp(1j * (np.asarray(result.z)[::every] - expected))))
    assert np.degrees(np.abs(expected - motion(times)[0])).max() > 1.0  # the disturbance is felt
    assert np.abs(difference).max() < TOLERANCE_DEG, f"max deviation {np.abs(difference).max():.3g} deg"


@pytest.mark.parametrize("name", BUILT_IN)
def test_built_in_pd_simulation_matches_the_reference(name):
    model = BUILT_IN[name]()
    J = len(model.joints)
    check_pd_simulation(model, np.full(J, 0.3), np.full(J, 0.4), np.full(J, 1.0), np.zeros(J))


@settings(max_examples=5, deadline=None)
@given(case=models_and_motions())
def test_pd_simulation_on_random_trees_matches_the_reference(case):
    model, motion = case
    check_pd_simulation(model, *motion, alpha=RANDOM_ALPHA, omega=RANDOM_OMEGA)


# ----------------------------------------------------------------------------- free bases and joint paths


def check_general_inverse_dynamics(model, seed):
    """Inverse dynamics, M(z) and h of a model with free and path joints against the reference's
    jets (tests/helpers/reference_dynamics.GeneralTree), to 1e-9 relative."""
    engine, t = engine_module.Engine(model), ref.GeneralTree(model)
    assert engine.joints == model.coordinates and engine.n_joints == t.n_joints
    rng = np.random.default_rng(seed)
    z, zd, zdd = rng.uniform(-3, 3, (4, t.n_joints)), rng.uniform(-5, 5, (4, t.n_joints)), rng.uniform(
        -50, 50, (4, t.n_joints))
    assert_relative(engine.inverse_dynamics(z, zd, zdd), t.inverse_dynamics(z, zd, zdd), 1e-9, "inverse dynamics")
    M = engine.mass_matrix(z)
    assert_relative(M, t.mass_matrix(z), 1e-9, "M(z)")
    assert np.allclose(M, np.swapaxes(M, 1, 2), rtol=0, atol=1e-12 * np.abs(M).max())
    assert np.linalg.eigvalsh(M).min() > 0
    assert_relative(engine.bias(z, zd), t.bias(z, zd), 1e-9, "h(z, z')")
    assert_relative(engine.inverse_torques(z[0], zd[0], zdd[0]), t.inverse_dynamics(z[0], zd[0], zdd[0]), 1e-9,
                    "inverse_torques")


@settings(max_examples=25, deadline=None)
@given(model=models_with_paths_and_free_joints(), seed=st.integers(0, 2**16))
def test_free_and_path_joints_inverse_dynamics_match_the_reference(model, seed):
    check_general_inverse_dynamics(model, seed)


@settings(max_examples=10, deadline=None)
@given(model=models(), seed=st.integers(0, 2**16))
def test_the_reference_s_jets_agree_with_its_newton_euler_on_pin_joints(model, seed):
    """The two constructions of the reference agree where both apply (pin joints only)."""
    t, general = ref.tree(model), ref.GeneralTree(model)
    z, zd, zdd = random_states(t.n_joints, 3, seed)
    assert_relative(general.inverse_dynamics(z, zd, zdd), ref.inverse_dynamics(t, z, zd, zdd), 1e-12, "tau")
    assert_relative(general.mass_matrix(z), ref.mass_matrix(t, z), 1e-12, "M")


@settings(max_examples=10, deadline=None)
@given(model=models_with_paths_and_free_joints(), seed=st.integers(0, 2**16))
def test_free_and_path_joint_states_round_trip(model, seed):
    """joints_from_state(state_from_joints(z, z')) gives z, z' back (a free joint's x, y from its
    child's point), and the state satisfies the constraints of the pin joints' bodies."""
    engine = engine_module.Engine(model)
    rng = np.random.default_rng(seed)
    z, zd = rng.uniform(-3, 3, engine.n_joints), rng.uniform(-5, 5, engine.n_joints)
    back = engine.joints_from_state(engine.state_from_joints(z, zd))
    np.testing.assert_allclose(back[0], z, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back[1], zd, rtol=0, atol=1e-12)


def test_free_base_and_knee_path_pd_simulation_matches_the_reference():
    """The engine's RK4 of eq. 12 (the dense kernels for these joints, dt 1 ms) under PD with feedforward and a
    3 Hz disturbance against the reference's DOP853 of the minimal equations, over 0.3 s: within
    1e-4 deg (angles) and 1e-6 m (the pelvis's x, y) at alpha 1e9, and the penalty's departure
    shrinks as 1/alpha (between 30x and 300x larger at alpha 1e7)."""
    model = hopper_model()
    t = ref.GeneralTree(model)
    J = t.n_joints
    centre, amplitude = np.array([0.1, 0.0, 0.0, 0.3, -0.5]), np.array([0.2, 0.05, 0.03, 0.4, 0.4])

    def motion(time):
        arg, w = 2 * np.pi * np.asarray(time)[..., None], 2 * np.pi
        return centre + amplitude * np.sin(arg), amplitude * w * np.cos(arg), -amplitude * w**2 * np.sin(arg)

    kp = np.array([400.0, 2000.0, 2000.0, 200.0, 100.0])
    kd = 2 * np.sqrt(kp * np.array([0.5, 18.0, 18.0, 0.5, 0.2]))
    nominal = engine_module.Engine(model)

    def feedforward(time):  # any torque history will do: both sides get the same
        return nominal.inverse_dynamics(*motion(time)) + 0.1 * kp * np.sin(6 * np.pi * np.asarray(time)[..., None]
                                                                           + np.arange(J))

    dt, n_steps, every = 1e-3, 300, 50
    half = np.arange(2 * n_steps + 1) * (dt / 2)
    z0, zd0, _ = motion(0.0)
    z0 = z0 + 0.02
    times = np.arange(0, n_steps + 1, every) * dt
    expected, _ = ref.simulate_pd(t, z0, zd0, n_steps * dt, feedforward, lambda time: motion(time)[:2], kp, kd, times,
                                  tolerance=1e-10)
    assert np.abs(expected - motion(times)[0]).max() > 0.05  # the disturbance is felt
    errors = {}
    for alpha in (1e7, 1e9):
        result = engine_module.Engine(model, alpha=alpha).simulate_pd(z0, zd0, dt, n_steps, feedforward(half),
                                                                      motion(half)[0], motion(half)[1], kp, kd)
        assert (result.status, result.steps_done) == (0, n_steps)
        errors[alpha] = np.abs(result.z[::every] - expected).max(axis=0)
    angles = [0, 3, 4]
    assert np.degrees(errors[1e9][angles]).max() < 1e-4 and errors[1e9][1:3].max() < 1e-6, errors
    assert 30 < errors[1e7].max() / errors[1e9].max() < 300, errors
