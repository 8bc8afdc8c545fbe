"""The multibody engine's compiled feedback laws, adaptive integration and population
(fdbench.multibody.kernels, fdbench.multibody.simulation) on library models and random trees:

- the compiled inverse dynamics against the independent reference (tests/helpers/reference_dynamics.py);
- a gain matrix [diag kp, diag kd] gives PD's numbers to the last bit;
- computed torque on a plant equal to its nominal model: the joint error follows
  e'' + kd e' + kp e = 0 from a perturbed start, to the penalty formulation's accuracy;
- the population's objectives equal the one-by-one simulations' and eq. 18 recomputed in numpy;
- DOP853 at tight tolerances and RK4 at a small step agree on the leg swinging through -90 deg;
- results on the motion's samples, on the grid and between its steps.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import reference_dynamics as ref
from helpers.multibody_strategies import models

from fdbench import population
from fdbench.integrate import Status
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import COMPUTED, GAINS, PD, Engine
from fdbench.tracking import rk4_candidates


class Sines:
    """A test motion: z_j(t) = centre_j + amplitude_j sin(2 pi t / period + j) (rad) over
    ``duration`` s, sampled every ``sample_dt`` s."""

    name = "sines"

    def __init__(self, joints, centre, amplitude, period=1.0, duration=0.5, sample_dt=0.01):
        self.joints, self.duration = tuple(joints), duration
        self.centre, self.amplitude, self.rate = np.asarray(centre), np.asarray(amplitude), 2 * math.pi / period
        self.samples = np.linspace(0.0, duration, int(round(duration / sample_dt)) + 1)

    def __call__(self, t):
        phase = self.rate * np.asarray(t, dtype=float)[..., None] + np.arange(len(self.joints))
        return (self.centre + self.amplitude * np.sin(phase), self.amplitude * self.rate * np.cos(phase),
                -self.amplitude * self.rate**2 * np.sin(phase))


def leg():
    """leg3 and a swing of its thigh through -90 deg from +x (hip 0), knee and ankle bending."""
    engine = Engine(find_model("leg3"))
    return engine, Sines(engine.joints, [-0.1, -0.4, 0.1], [0.5, 0.3, 0.2])


def half_steps(motion, n):
    """The half-step grid of n RK4 steps over the motion and the references on it."""
    half = np.linspace(0.0, motion.duration, 2 * n + 1)
    return half, *motion(half)


# ---------------------------------------------------------------------- inverse dynamics
@settings(max_examples=25, deadline=None)
@given(model=models(), seed=st.integers(0, 2**16))
def test_compiled_inverse_dynamics_matches_the_reference(model, seed):
    engine, tree = Engine(model), ref.tree(model)
    rng = np.random.default_rng(seed)
    for _ in range(5):
        z, zd, zdd = rng.uniform(-math.pi, math.pi, engine.n_joints), rng.uniform(-5, 5, engine.n_joints), \
            rng.uniform(-50, 50, engine.n_joints)
        expected = ref.inverse_dynamics(tree, z[None], zd[None], zdd[None])[0]
        scale = max(float(np.sqrt(np.mean(expected**2))), 1.0)
        assert np.max(np.abs(engine.inverse_torques(z, zd, zdd) - expected)) <= 1e-9 * scale


# ---------------------------------------------------------------------- feedback laws
def test_a_gain_matrix_of_diagonal_pd_gains_is_pd_to_the_last_bit():
    engine, motion = leg()
    n = 200
    _, ref_z, ref_zd, ref_zdd = half_steps(motion, n)
    tau = 0.9 * engine.inverse_dynamics(ref_z, ref_zd, ref_zdd)
    kp, kd = np.array([300.0, 120.0, 20.0]), np.array([20.0, 8.0, 1.0])
    gains = np.broadcast_to(np.hstack([np.diag(kp), np.diag(kd)]), (2 * n + 1, 3, 6))
    y0 = engine.state_from_joints(ref_z[0] + 0.05, ref_zd[0])
    pd = engine.simulate(y0, motion.duration / n, n, tau, ref_z, ref_zd, ref_zdd, kp, kd, PD)
    matrix = engine.simulate(y0, motion.duration / n, n, tau, ref_z, ref_zd, ref_zdd, 0.0, 0.0, GAINS, gains)
    assert (pd.status, pd.steps_done) == (0, n)
    assert np.array_equal(pd.states, matrix.states) and np.array_equal(pd.applied, matrix.applied)
    assert np.max(np.abs(pd.applied - tau[::2])) > 0.1  # the feedback acted


def test_computed_torque_error_follows_the_closed_loop_equation():
    """With the plant as its own nominal model, e = z_d - z obeys e'' + kd e' + kp e = 0: for
    kp = w^2, kd = 2 w, e(t) = (e0 + (e0' + w e0) t) exp(-w t)."""
    engine, motion = leg()
    w, n = 20.0, 5000
    _, ref_z, ref_zd, ref_zdd = half_steps(motion, n)
    e0, ed0 = np.array([0.1, -0.08, 0.05]), np.array([-0.5, 0.3, 0.2])
    y0 = engine.state_from_joints(ref_z[0] - e0, ref_zd[0] - ed0)
    result = engine.simulate(y0, motion.duration / n, n, np.zeros_like(ref_z), ref_z, ref_zd, ref_zdd, w * w, 2 * w,
                             COMPUTED)
    assert (result.status, result.steps_done) == (0, n)
    t = np.linspace(0.0, motion.duration, n + 1)[:, None]
    expected = (e0 + (ed0 + w * e0) * t) * np.exp(-w * t)
    error = ref_z[::2] - result.z
    assert np.max(np.abs(np.degrees(error - expected))) < 1e-3  # of an initial error of 5.7 deg
    assert np.max(np.abs(error[-1])) < 1e-3 * np.max(np.abs(e0))  # the error has decayed


def test_computed_torque_believes_its_nominal_model():
    """A nominal model other than the plant changes the torques; a nominal model of other joints is refused."""
    engine, motion = leg()
    n = 50
    _, ref_z, ref_zd, ref_zdd = half_steps(motion, n)
    y0, tau = engine.state_from_joints(ref_z[0], ref_zd[0]), np.zeros_like(ref_z)
    own = engine.simulate(y0, motion.duration / n, n, tau, ref_z, ref_zd, ref_zdd, 100.0, 20.0, COMPUTED)
    same = engine.simulate(y0, motion.duration / n, n, tau, ref_z, ref_zd, ref_zdd, 100.0, 20.0, COMPUTED,
                           nominal=Engine(find_model("leg3")))
    assert np.array_equal(own.states, same.states)
    other = Engine(dataclasses.replace(find_model("leg3"), gravity=(0.0, -9.0)))
    moved = engine.simulate(y0, motion.duration / n, n, tau, ref_z, ref_zd, ref_zdd, 100.0, 20.0, COMPUTED,
                            nominal=other)
    assert np.max(np.abs(moved.applied - own.applied)) > 0.1
    with pytest.raises(ValueError, match="nominal model's joints"):
        engine.simulate(y0, motion.duration / n, n, tau, ref_z, ref_zd, ref_zdd, 1.0, 1.0, COMPUTED,
                        nominal=Engine(find_model("arm2")))


def test_rates_are_the_rk4_drivers_right_hand_side():
    engine, motion = leg()
    n = 500
    _, ref_z, ref_zd, ref_zdd = half_steps(motion, n)
    tau = engine.inverse_dynamics(ref_z, ref_zd, ref_zdd)
    for mode in (PD, COMPUTED):
        run = engine.simulate(engine.state_from_joints(ref_z[0] + 0.02, ref_zd[0]), motion.duration / n, n, tau,
                              ref_z, ref_zd, ref_zdd, 50.0, 5.0, mode)
        assert (run.status, run.steps_done) == (0, n)
        rates, applied = engine.rates(run.states, tau[::2], ref_z[::2], ref_zd[::2], ref_zdd[::2], 50.0, 5.0, mode)
        assert np.array_equal(rates, run.rates) and np.array_equal(applied, run.applied)


@pytest.mark.parametrize("call, message", [
    (lambda e, a: e.simulate(a[0], 0.01, 2, a[1], a[1], a[1], a[1], 1.0, 1.0, 7), "mode must be one of"),
    (lambda e, a: e.simulate(a[0], 0.01, 2, a[1], a[1], a[1], a[1], 1.0, 1.0, GAINS, np.zeros((5, 3, 3))),
     r"gains must have shape \(5, 3, 6\)"),
    (lambda e, a: e.simulate(a[0], 0.01, 2, a[1], a[1], a[1], a[1][:4], 1.0, 1.0), "refdd_half must have shape"),
    (lambda e, a: e.simulate(a[0][:3], 0.01, 2, a[1], a[1], a[1], a[1], 1.0, 1.0), "initial state must have shape"),
    (lambda e, a: e.rates(a[0][None], a[1], a[1][:1], a[1][:1], a[1][:1], 1.0, 1.0), r"tau must have shape \(1, 3\)"),
])
def test_arrays_of_the_wrong_shape_are_refused(call, message):
    engine = leg()[0]
    with pytest.raises(ValueError, match=message):
        call(engine, (engine.state_from_joints(np.zeros(3), np.zeros(3)), np.zeros((5, 3))))


# ---------------------------------------------------------------------- the population
def test_population_objectives_are_the_one_by_one_simulations_and_eq_18():
    engine, motion = leg()
    n, every, weight = 100, 10, 50.0
    _, ref_z, ref_zd, ref_zdd = half_steps(motion, n)
    base = engine.inverse_dynamics(ref_z, ref_zd, ref_zdd)
    rng = np.random.default_rng(3)
    tau = base[None] * (1 + 0.05 * rng.standard_normal((5, 1, 3)))
    tau[4] *= 40.0  # a candidate driven to a failure
    angles = ref_z[::2][::every]
    y0 = engine.state_from_joints(ref_z[0], ref_zd[0])
    args = engine.population_args(y0, motion.duration / n, n, tau, ref_z, ref_zd, every, angles, weight)
    before = population.threads()
    try:
        population.set_threads(2)
        together = population.Population(rk4_candidates, n, engine.population_widths)(5, args)
    finally:
        population.set_threads(before)
    for c in range(5):
        alone = population.Population(rk4_candidates, n, engine.population_widths)(
            1, engine.population_args(y0, motion.duration / n, n, tau[c:c + 1], ref_z, ref_zd, every, angles,
                                      weight))
        assert together[c] == alone[0]
        run = engine.simulate(y0, motion.duration / n, n, tau[c], ref_z, ref_zd, ref_zdd, 0.0, 0.0)
        reached = run.steps_done // every + 1
        error = np.degrees(run.z[::every][:reached] - angles[:reached])
        rmse = np.sqrt(np.mean(error**2)) if np.all(np.isfinite(error)) else 0.0
        assert together[c] == pytest.approx(rmse + weight * (1 - run.steps_done / n), rel=1e-12, abs=1e-12)
    assert together[4] > weight / 2  # the failing candidate pays the penalty


# ---------------------------------------------------------------------- simulation on a motion
def test_adaptive_and_rk4_agree_on_the_leg_swinging_through_minus_90_degrees():
    engine, motion = leg()
    assert np.ptp(np.sign(motion(motion.samples)[0][:, 0])) == 2  # the thigh crosses -90 deg from +x
    torque = sim.feedforward(engine, motion)
    rk4 = sim.simulate(torque, engine, motion, 30.0, 2.0, dt=1e-4, start=engine.state_from_joints([0.1, -0.3, 0.2],
                                                                                                  [0.0, 0.5, 0.0]))
    dop = sim.simulate(torque, engine, motion, 30.0, 2.0, start=rk4.states[0], integrator="dop853", rtol=1e-10,
                       atol=1e-12)
    assert rk4.success and dop.success and dop.integrator == "dop853" and dop.rhs_evaluations > 0
    assert np.max(np.abs(np.degrees(rk4.z - dop.z))) < 1e-5
    assert np.max(np.abs(rk4.torque - dop.torque)) < 1e-5
    assert np.max(np.abs(np.degrees(rk4.z - motion(motion.samples)[0]))) > 1.0  # from another start: a real test


def test_results_are_on_the_motion_s_samples_on_and_off_the_grid():
    engine, motion = leg()
    torque = sim.feedforward(engine, motion)
    on = sim.simulate(torque, engine, motion, 80.0, 4.0, dt=1e-3)  # samples every 10 steps
    n = 500
    _, ref_z, ref_zd, ref_zdd = half_steps(motion, n)
    direct = engine.simulate(on.states[0], motion.duration / n, n, torque(np.linspace(0, motion.duration, 2 * n + 1)),
                             ref_z, ref_zd, ref_zdd, np.full(3, 80.0), np.full(3, 4.0))
    assert sim.samples_on_grid(np.linspace(0, motion.duration, n + 1), motion.samples) == 10
    assert np.array_equal(on.states, direct.states[::10]) and np.array_equal(on.torque, direct.applied[::10])
    assert on.z.shape == on.torque.shape == (len(motion.samples), 3) and on.t is motion.samples
    off = sim.simulate(torque, engine, motion, 80.0, 4.0, dt=0.7e-3)  # Hermite between steps
    assert np.max(np.abs(np.degrees(off.z - on.z))) < 1e-5
    rmse, per_joint = sim.rmse_deg(on, motion(motion.samples)[0])
    assert rmse < 0.01 and per_joint.shape == (3,)
    torque_rmse, _ = sim.rmse_torque_nm(on, torque(motion.samples))
    assert torque_rmse < 0.1
    inverse = sim.inverse_dynamics(None, engine, motion)
    assert inverse.joints == engine.joints and np.array_equal(inverse.torque, torque(motion.samples))


def test_a_failing_simulation_stops_and_leaves_the_samples_after_it_nan():
    engine, motion = leg()
    result = sim.simulate(lambda t: np.full((len(t), 3), 3000.0), engine, motion, dt=1e-3)
    assert result.status in (Status.CONSTRAINT, Status.NONFINITE) and not result.success
    assert 0 < result.t_end < motion.duration
    assert np.all(np.isnan(result.z[motion.samples > result.t_end + 1e-9]))
    assert result.reached[0] and not result.reached[-1]


def test_a_motion_of_other_joints_is_refused():
    engine = leg()[0]
    with pytest.raises(ValueError, match="motion's joints"):
        sim.simulate(None, engine, Sines(("a", "b", "c"), np.zeros(3), np.zeros(3)))
