"""Self-checks of the minimal-coordinate reference (tests/helpers/reference_dynamics.py), independent of the
multibody engine, so that the engine's tests compare against something known to be right:

- the forearm and the two-segment arm against their closed forms (Lagrange's equations written by
  hand: the elbow torque of the paper, tests/helpers/arm2_closed_form.py);
- the two constructions of the reference against each other and against Lagrange's equations: the
  RNEA's torques equal M z'' + h with M from the kinetic energy, and d/dt dT/dz' - dT/dz + dV/dz
  (derivatives of the energies by central differences) on random trees;
- physics no formula can fake: M(z) symmetric positive definite, the energy of the free motion
  conserved over 1 s by DOP853, and the power balance dE/dt = tau . z' under random torques.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import reference_dynamics as ref
from fdbench.multibody import model as d
from helpers.arm2_closed_form import joint_torques
from helpers.multibody_strategies import arm2_model, forearm_model, models, models_and_states

GRAVITY = 9.81  # m/s^2, the built-in models'


def assert_relative(actual, expected, rel, scale=0.0):
    """max |actual - expected| <= rel * max(RMS(expected), scale) (rel alone when both are zero):
    ``scale`` is the size of the terms ``expected`` was summed from, when they may cancel. A scale
    under 1e-100 (a state drawn near the floating-point floor, whose squares underflow) counts as
    1e-100: far below any physical torque, and where relative rounding no longer holds."""
    expected = np.asarray(expected)
    scale = max(float(np.sqrt(np.mean(expected**2))), scale, 1.0 if not expected.any() and not scale else 1e-100)
    error = float(np.max(np.abs(np.asarray(actual) - expected)))
    assert error <= rel * scale, f"error {error:.3g} > {rel:g} x {scale:.3g}"


def random_states(n_joints, count=20, seed=0):
    """count random (z, z', z'') rows, shapes (count, J): anywhere, up to 5 rad/s and 50 rad/s^2."""
    rng = np.random.default_rng(seed)
    return (rng.uniform(-math.pi, math.pi, (count, n_joints)), rng.uniform(-5, 5, (count, n_joints)),
            rng.uniform(-50, 50, (count, n_joints)))


# ----------------------------------------------------------------------------- known models


@settings(max_examples=50)
@given(theta=st.floats(-math.pi, math.pi), w=st.floats(-10, 10), dw=st.floats(-100, 100))
def test_forearm_matches_its_closed_form(theta, w, dw):
    """tau = I1 theta'' + cos(theta) (F_ext L12 + m g L1G), I1 = 0.04 about the elbow; w has no effect."""
    t = ref.tree(forearm_model())
    expected = 0.04 * dw + math.cos(theta) * (15.0 * 0.33 + 1.0 * GRAVITY * 0.11)
    tau = ref.inverse_dynamics(t, [theta], [w], [dw])
    assert tau.shape == (1,)
    assert tau[0] == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert ref.mass_matrix(t, [theta]) == pytest.approx(np.array([[0.04]]), rel=1e-12)


@settings(max_examples=50)
@given(at_child=st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)),
       com=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)), at=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)),
       force=st.tuples(st.floats(-50, 50), st.floats(-50, 50)), offset=st.floats(-math.pi, math.pi),
       theta=st.floats(-math.pi, math.pi), w=st.floats(-10, 10), dw=st.floats(-100, 100))
def test_pendulum_matches_its_closed_form(at_child, com, at, force, offset, theta, w, dw):
    """One body on a pin at P = (0.1, -0.2), its frame at angle phi = theta + offset, the pin at
    at_child in it: tau = I_P theta'' - (R(phi)(com - at_child)) x m g - (R(phi)(at - at_child)) x F,
    I_P = inertia + m |com - at_child|^2 (the frame conventions, offsets and loads of fdbench.multibody.model)."""
    m, inertia, g = 2.5, 0.07, (0.3, -9.81)
    model = d.Model(name="pendulum", gravity=g, bodies=(d.Body("b", mass=m, com=com, inertia=inertia),),
                    joints=(d.Joint("q", "pin", d.GROUND, "b", (0.1, -0.2), at_child, offset=offset),),
                    loads=(d.Load("b", at=at, force=force),))
    c, s = math.cos(theta + offset), math.sin(theta + offset)

    def world(v):  # R(phi) (v - at_child)
        x, y = v[0] - at_child[0], v[1] - at_child[1]
        return c * x - s * y, s * x + c * y

    def cross(a, b):
        return a[0] * b[1] - a[1] * b[0]

    lever = world(com)
    expected = ((inertia + m * (lever[0] ** 2 + lever[1] ** 2)) * dw - cross(lever, (m * g[0], m * g[1]))
                - cross(world(at), force))
    t = ref.tree(model)
    assert ref.inverse_dynamics(t, [theta], [w], [dw])[0] == pytest.approx(expected, rel=1e-12, abs=1e-11)


@settings(max_examples=30)
@given(offsets=st.tuples(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi)), seed=st.integers(0, 2**16))
def test_offsets_shift_the_coordinates(offsets, seed):
    """The arm with joint offsets at z is the closed-form arm at z + offsets."""
    import dataclasses

    model = arm2_model()
    joints = tuple(dataclasses.replace(joint, offset=off) for joint, off in zip(model.joints, offsets))
    t = ref.tree(dataclasses.replace(model, joints=joints))
    z, w, dw = random_states(2, seed=seed)
    assert_relative(ref.inverse_dynamics(t, z, w, dw), joint_torques(z + np.array(offsets), w, dw), 1e-12)


@settings(max_examples=30)
@given(m0=st.floats(0.1, 10), F_ext=st.floats(-50, 50), g=st.floats(0, 20), L01=st.floats(0.1, 0.6),
       seed=st.integers(0, 2**16))
def test_arm_matches_the_closed_form_arm(m0, F_ext, g, L01, seed):
    """The RNEA's torques and M(z) equal those of the arm's closed form (Lagrange's equations written
    by hand, tests/helpers/arm2_closed_form.py) at random states, batched, for changed constants."""
    changes = dict(m0=m0, F_ext=F_ext, g=g, L01=L01)
    t = ref.tree(arm2_model(**changes))
    z, w, dw = random_states(2, seed=seed)
    assert_relative(ref.inverse_dynamics(t, z, w, dw), joint_torques(z, w, dw, **changes), 1e-12)
    columns = [joint_torques(z, 0 * w, unit + 0 * dw, **changes) - joint_torques(z, 0 * w, 0 * dw, **changes)
               for unit in np.eye(2)]
    assert_relative(ref.mass_matrix(t, z), np.stack(columns, axis=-1), 1e-12)


# ----------------------------------------------------------------------------- the two constructions


@settings(max_examples=40)
@given(case=models_and_states())
def test_rnea_equals_mass_matrix_times_acceleration_plus_bias(case):
    """RNEA(z, z', z'') = M(z) z'' + RNEA(z, z', 0), with M from the kinetic energy, and
    T = 1/2 z'^T M z' (M symmetric positive definite)."""
    model, (z, zd, zdd) = case
    t = ref.tree(model)
    M = ref.mass_matrix(t, z)
    assert np.allclose(M, M.T, rtol=1e-13, atol=0)
    assert np.linalg.eigvalsh(M).min() > 0
    np.linalg.cholesky(M)
    assert_relative(ref.inverse_dynamics(t, z, zd, zdd), M @ zdd + ref.bias(t, z, zd), 1e-12)
    assert ref.kinetic_energy(t, z, zd) == pytest.approx(0.5 * zd @ M @ zd, rel=1e-12, abs=1e-14)


def _gradient(f, x, h):
    """Central differences of the scalar f at x (n,), shape (n,)."""
    return np.array([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])


@settings(max_examples=30)
@given(case=models_and_states())
def test_rnea_satisfies_lagrange_equations(case):
    """tau = d/dt (M z') - 1/2 d(z'^T M z')/dz + dV/dz, the z derivatives by central differences
    (h = 1e-6 rad): Lagrange's equations, from the energies alone, agree with the RNEA to 1e-6."""
    model, (z, zd, zdd) = case
    t = ref.tree(model)
    h = 1e-6
    M = ref.mass_matrix(t, z)
    dM = [(ref.mass_matrix(t, z + h * e) - ref.mass_matrix(t, z - h * e)) / (2 * h) for e in np.eye(len(z))]
    momentum_rate = M @ zdd + sum(dMk * zk for dMk, zk in zip(dM, zd)) @ zd
    kinetic_slope = np.array([0.5 * zd @ dMk @ zd for dMk in dM])
    potential_slope = _gradient(lambda x: ref.potential_energy(t, x), z, h)
    lagrange = momentum_rate - kinetic_slope + potential_slope
    terms = max(float(np.sqrt(np.mean(term**2))) for term in (momentum_rate, kinetic_slope, potential_slope))
    assert_relative(ref.inverse_dynamics(t, z, zd, zdd), lagrange, 1e-6, scale=terms)


# ----------------------------------------------------------------------------- physics


@settings(max_examples=10)
@given(model=models(), state=st.integers(0, 2**16))
def test_free_motion_conserves_energy(model, state):
    """With no torques and no loads, T + V stays constant over 1 s under DOP853 to 1e-9 of the
    energy exchanged (the largest kinetic energy reached)."""
    model = type(model)(name=model.name, gravity=model.gravity, bodies=model.bodies, joints=model.joints)
    t = ref.tree(model)
    z0, zd0, _ = (v[0] for v in random_states(t.n_joints, count=1, seed=state))
    zd0 = zd0 / 5  # up to 1 rad/s
    times = np.linspace(0.0, 1.0, 11)
    z, zd = ref.simulate(t, z0, zd0, 1.0, lambda time, z, zd: np.zeros(t.n_joints), times)
    kinetic = ref.kinetic_energy(t, z, zd)
    energy = kinetic + ref.potential_energy(t, z)
    assert np.abs(energy - energy[0]).max() <= 1e-9 * max(kinetic.max(), 1e-3)


@settings(max_examples=40)
@given(case=models_and_states(), tau=st.lists(st.floats(-50, 50), min_size=6, max_size=6).map(np.array))
def test_power_balance(case, tau):
    """dE/dt = tau . z' at any state under any torques, E = T + V with gravity and the loads: the
    rate of E along the forward dynamics, by central differences of the energies (h = 1e-6)."""
    model, (z, zd, _) = case
    t = ref.tree(model)
    tau = tau[:t.n_joints]
    zdd = ref.forward_dynamics(t, z, zd, tau)

    def energy(x):
        return ref.kinetic_energy(t, x[:t.n_joints], x[t.n_joints:]) + ref.potential_energy(t, x[:t.n_joints])

    x, xd = np.concatenate([z, zd]), np.concatenate([zd, zdd])
    slope = _gradient(energy, x, 1e-6)
    rounding = 1e-9 * (1.0 + abs(energy(x))) * np.abs(xd).sum()  # of the differences, eps |E| / h
    assert abs(slope @ xd - tau @ zd) <= 1e-6 * (np.abs(slope) @ np.abs(xd)) + rounding


# ----------------------------------------------------------------------------- the random models


def test_random_models_reach_every_kind_of_tree():
    """The strategy's models include what the engine must handle: in 300 draws (a fixed sequence)
    there are bodies with two children, several bodies on ground, joints off the parent's end,
    loads, joint offsets, explicit and default ends, and six-body chains."""
    kinds = {
        "two children": lambda m: any(sum(j.parent == b.name for j in m.joints) >= 2 for b in m.bodies),
        "two on ground": lambda m: sum(j.parent == "ground" for j in m.joints) >= 2,
        "off the end": lambda m: any(j.parent != "ground" and m.body(j.parent).end not in (None, j.at_parent)
                                     for j in m.joints),
        "loads": lambda m: len(m.loads) > 0,
        "offsets": lambda m: any(j.offset != 0 for j in m.joints),
        "explicit and default ends": lambda m: {b.end is None for b in m.bodies} == {True, False},
        "six in a chain": lambda m: [j.parent for j in m.joints] == ["ground"] + [f"b{k}" for k in range(5)],
    }
    seen = set()

    @settings(max_examples=300, derandomize=True, database=None)
    @given(model=st.one_of(models(), models(chain=True)))
    def draw(model):
        seen.update(kind for kind, holds in kinds.items() if holds(model))

    draw()
    assert seen == set(kinds)
