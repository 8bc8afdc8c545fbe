"""Eq. 12 for free and path joints by the kernels' dense solve (fdbench.multibody.kernels):

- on models of pin joints only, the dense solve's state derivative, constraint violation and
  computed torque equal the banded solve's (another assembly and solve of the same equations) to
  their rounding, 1e-14 times the dense leading matrix's condition number (relative);
- on random models with free and path joints, the engine's state from joint values lies on the
  constraints (positions and velocities, to rounding), and eq. 12's accelerations there converge to
  the reference's minimal forward dynamics (tests/helpers/reference_dynamics.GeneralTree) as 1/alpha;
- external loads (``fdbench.multibody.loads``) in eq. 12 converge to the minimal forward dynamics
  under their generalised forces, and the compiled inverse dynamics with the loads inverts it;
- the population of open-loop candidates gives eq. 18 of each candidate's own simulation;
- the feedback laws: ``rates`` applies PD's closed form; GAINS with K = [diag kp, diag kd] is PD
  to the bit;
  computed torque through a nominal model other than the plant follows the reference's minimal
  equations under the reference's own inverse dynamics of that nominal model (scipy's DOP853).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import reference_dynamics as ref
from helpers.multibody_strategies import models, models_with_paths_and_free_joints
from helpers.population_checks import restore_threads  # noqa: F401 - a fixture
from helpers.dense_checks import dense_args, leading_matrix, load_forces, residuals
from helpers.models import hopper_loads, hopper_model

from fdbench.multibody import kernels
from fdbench.multibody.engine import Engine
from fdbench.multibody.layout import COMPUTED, GAINS, PD, Law


def random_joint_state(engine, seed):
    rng = np.random.default_rng(seed)
    J = engine.n_joints
    return rng.uniform(-2.5, 2.5, J), rng.uniform(-3, 3, J), rng.uniform(-20, 20, J)


def dense_rates(engine, y, tau, mode=PD, kp=0.0, kd=0.0, ref_z=None):
    """The dense solve's state derivative and applied forces at one state (PD with zero gains by default)."""
    J = engine.n_joints
    zero = np.zeros((1, J))
    ref_z = zero if ref_z is None else ref_z[None]
    kp, kd = np.full(J, kp), np.full(J, kd)
    out, applied = np.empty((1, engine.n_state)), np.empty((1, J))
    loads = engine.loads_at(np.zeros(1))
    law = Law(tau[None], ref_z, zero, zero, kp, kd, mode, np.zeros((1, J, 2 * J)))
    kernels.derivatives(y[None], law, *dense_args(engine), loads, engine.layout, engine.paths, loads, out, applied)
    return out[0], applied[0]


@settings(max_examples=20, deadline=None)
@given(model=models(), seed=st.integers(0, 2**16))
def test_the_dense_kernels_equal_the_banded_kernels_on_pin_joints(model, seed):
    engine = Engine(model, alpha=1e5)  # the same equations at any alpha; a small one keeps the rounding small
    z, zd, tau = random_joint_state(engine, seed)
    rng = np.random.default_rng(seed + 1)
    y = engine.state_from_joints(z, zd) + rng.normal(0, 1e-4, engine.n_state)  # off the manifold a little
    dense, _ = dense_rates(engine, y, tau)
    banded = engine.accelerations(y, tau)
    condition = np.linalg.cond(leading_matrix(engine, y))  # the two solves' rounding grows with it
    assert np.abs(dense - banded).max() <= max(1e-12, 1e-14 * condition) * np.abs(banded).max()
    assert abs(residuals(engine, y)[0] - engine.constraint_violation(y)) <= 1e-12
    # computed torque: the dense inverse dynamics inside the law equals the banded one
    ref_z = z + 0.1
    dense_ct, applied = dense_rates(engine, y, tau, COMPUTED, 30.0, 3.0, ref_z)
    zero = np.zeros((1, engine.n_joints))
    banded_ct, banded_applied = engine.rates(y[None], tau[None], ref_z[None], zero, zero, 30.0, 3.0, COMPUTED)
    np.testing.assert_allclose(applied, banded_applied[0], rtol=1e-12, atol=1e-12 * np.abs(applied).max())


@settings(max_examples=15, deadline=None)
@given(model=models_with_paths_and_free_joints(max_bodies=4), seed=st.integers(0, 2**16))
def test_on_the_constraints_eq_12_converges_to_the_minimal_forward_dynamics(model, seed):
    t = ref.GeneralTree(model)
    z, zd, tau = random_joint_state(Engine(model), seed)
    expected = t.forward_dynamics(z, zd, tau)
    errors = []
    for alpha in (1e5, 1e6, 1e7):  # low enough that the penalty's error stays above the solve's rounding
        engine = Engine(model, alpha=alpha)
        y = engine.state_from_joints(z, zd)
        worst, _, jv = residuals(engine, y)
        assert worst < 1e-12 and np.abs(jv).max() < 1e-11
        rate, _ = engine.rates(y[None], tau[None], *(np.zeros((1, engine.n_joints)),) * 3, 0.0, 0.0)
        zdd = engine.joints_from_state(rate[0])[1]  # [q', q''] read as a state: its second half gives z''
        errors.append(np.abs(zdd - expected).max() / max(1.0, np.abs(expected).max()))
        rounding = 1e-14 * np.linalg.cond(leading_matrix(engine, y))
    # the penalty's error shrinks as 1/alpha (ten times a decade), down to the solve's rounding, once
    # alpha is large beside the model's stiffness: a 6 cm body of inertia 2 kg m^2 on a path is still
    # on its way at 1e5 (0.59, 0.43, 0.12 at 1e4, 1e5, 1e6), and leaves 1.4 % at 1e7, 0.15 % at 1e8
    assert errors[2] < errors[1] / 5 or errors[2] < rounding, (errors, rounding)


@pytest.mark.parametrize("seed", [0, 1])
def test_external_loads_in_eq_12_converge_to_the_minimal_forward_dynamics(seed):
    """External loads (force and point in ground's or a body's frame, a free moment) on the hopper:
    on the constraints, eq. 12's accelerations at a time t converge as 1/alpha to the reference's
    minimal forward dynamics under tau plus the loads' generalised forces (the compiled eq. 3's at
    rest without gravity); the inverse dynamics with the loads of that motion is tau again."""
    model, loads = hopper_model(), hopper_loads(seed)
    t = ref.GeneralTree(model)
    engine = Engine(model, loads=loads)
    z, zd, tau = random_joint_state(engine, seed)
    z, zd = 0.3 * z, 0.3 * zd
    time = 0.37
    applied = load_forces(engine, z, time)
    assert np.abs(applied).max() > 1.0
    expected = t.forward_dynamics(z, zd, tau + applied)
    errors = []
    for alpha in (1e6, 1e8):
        engine = Engine(model, alpha=alpha, loads=loads)
        y = engine.state_from_joints(z, zd)
        zero = np.zeros((1, engine.n_joints))
        rate, _ = engine.rates(y[None], tau[None], zero, zero, zero, 0.0, 0.0, t=np.array([time]))
        errors.append(np.abs(engine.joints_from_state(rate[0])[1] - expected).max() / np.abs(expected).max())
    assert errors[1] < 1e-4 and errors[1] < errors[0] / 30, errors
    np.testing.assert_allclose(engine.inverse_dynamics(z, zd, expected, time), tau, rtol=0,
                               atol=1e-9 * max(np.abs(tau).max(), np.abs(applied).max()))


@settings(max_examples=5, deadline=None)
@given(model=models_with_paths_and_free_joints(max_bodies=3), seed=st.integers(0, 2**16))
def test_rates_apply_pd_and_are_the_drivers_derivative(model, seed):
    engine = Engine(model)
    z, zd, tau = random_joint_state(engine, seed)
    y = engine.state_from_joints(z, zd)
    kp, kd = np.full(engine.n_joints, 50.0), np.full(engine.n_joints, 5.0)
    ref_z, ref_zd = z + 0.1, zd - 0.2
    zero = np.zeros((1, engine.n_joints))
    rate, applied = engine.rates(y[None], tau[None], ref_z[None], ref_zd[None], zero, kp, kd)
    np.testing.assert_allclose(applied[0], tau + kp * 0.1 - kd * 0.2, rtol=1e-12, atol=1e-12)
    rows = np.repeat
    run = engine.simulate(y, 1e-4, 1, rows(tau[None], 3, 0), rows(ref_z[None], 3, 0), rows(ref_zd[None], 3, 0),
                          np.zeros((3, engine.n_joints)), kp, kd)
    assert np.array_equal(run.rates[0], rate[0]) and np.array_equal(run.applied[0], applied[0])


def test_gains_of_diagonal_blocks_are_pd_on_a_free_base_with_a_knee_path():
    engine = Engine(hopper_model())
    J, n_steps = engine.n_joints, 100
    rng = np.random.default_rng(3)
    y0 = engine.state_from_joints(rng.uniform(-0.3, 0.3, J), rng.uniform(-0.5, 0.5, J))
    tau, ref_z, ref_zd = (rng.normal(0, 1, (2 * n_steps + 1, J)) for _ in range(3))
    kp, kd = rng.uniform(10, 100, J), rng.uniform(1, 10, J)
    gains = np.tile(np.hstack([np.diag(kp), np.diag(kd)]), (2 * n_steps + 1, 1, 1))
    pd = engine.simulate(y0, 1e-3, n_steps, tau, ref_z, ref_zd, np.zeros_like(tau), kp, kd)
    by_gains = engine.simulate(y0, 1e-3, n_steps, tau, ref_z, ref_zd, np.zeros_like(tau), 0.0, 0.0, GAINS, gains)
    assert (pd.status, pd.steps_done) == (by_gains.status, by_gains.steps_done) == (0, n_steps)
    assert np.array_equal(by_gains.states, pd.states) and np.array_equal(by_gains.applied, pd.applied)


def test_computed_torque_through_another_nominal_model_follows_the_reference():
    """A hopper whose shank is 20 % heavier than the nominal model computed torque believes: the
    engine's RK4 (dt 1 ms, alpha 1e9) against the reference's DOP853 of the plant's minimal
    equations under the reference's inverse dynamics of the nominal model, over 0.2 s from off the
    motion: within 1e-5 rad and 1e-6 m, while the mismatch moves the motion by more than 1e-3."""
    from scipy.integrate import solve_ivp

    nominal_model = hopper_model()
    bodies = list(nominal_model.bodies)
    bodies[2] = dataclasses.replace(bodies[2], mass=1.2 * bodies[2].mass, inertia=1.2 * bodies[2].inertia)
    plant_model = dataclasses.replace(nominal_model, bodies=tuple(bodies))
    plant, believed = ref.GeneralTree(plant_model), ref.GeneralTree(nominal_model)
    J = plant.n_joints
    centre, amplitude = np.array([0.1, 0.0, 0.0, 0.3, -0.5]), np.array([0.2, 0.05, 0.03, 0.4, 0.4])
    kp, kd = np.full(J, 100.0), np.full(J, 20.0)

    def motion(time):
        arg, w = 2 * np.pi * np.asarray(time)[..., None], 2 * np.pi
        return centre + amplitude * np.sin(arg), amplitude * w * np.cos(arg), -amplitude * w**2 * np.sin(arg)

    def rhs(time, x):
        z, zd = x[:J], x[J:]
        r, rd, rdd = motion(time)
        tau = believed.inverse_dynamics_one(z, zd, rdd + kp * (r - z) + kd * (rd - zd))
        return np.concatenate([zd, plant.forward_dynamics(z, zd, tau)])

    dt, n_steps = 1e-3, 200
    z0, zd0, _ = motion(0.0)
    z0 = z0 + 0.02
    expected = solve_ivp(rhs, (0, n_steps * dt), np.concatenate([z0, zd0]), method="DOP853", rtol=1e-10,
                         atol=1e-12).y[:J, -1]
    engine = Engine(plant_model, alpha=1e9)
    half = np.arange(2 * n_steps + 1) * (dt / 2)
    r, rd, rdd = motion(half)
    result = engine.simulate(engine.state_from_joints(z0, zd0), dt, n_steps, np.zeros_like(r), r, rd, rdd, kp, kd,
                             COMPUTED, nominal=Engine(nominal_model))
    assert (result.status, result.steps_done) == (0, n_steps)
    matched = engine.simulate(engine.state_from_joints(z0, zd0), dt, n_steps, np.zeros_like(r), r, rd, rdd, kp, kd,
                              COMPUTED)
    assert np.abs(matched.z[-1] - result.z[-1]).max() > 1e-3  # the mismatch is felt
    error = np.abs(result.z[-1] - expected)
    assert error[[0, 3, 4]].max() < 1e-5 and error[1:3].max() < 1e-6, error


def test_the_population_on_a_free_base_with_a_knee_path_is_eq_18_of_each_simulation(restore_threads, monkeypatch):
    """CMA-ES's population of open-loop candidates (``tracking.rk4_candidates``) on the
    hopper: each candidate's number is eq. 18 of its own simulation by ``simulate`` (the angles' RMSE
    in deg plus the translations' in cm by numpy, the penalty of the part not reached), one
    candidate thrown off its motion included, and equals the rows one by one to the bit on 1 to 3
    threads, and in calls of one step each."""
    from helpers.population_checks import (assert_objectives_are, assert_one_step_calls_change_nothing,
                                   assert_population_equals_one_by_one)

    from fdbench.multibody.model import MotionSpec
    from fdbench.multibody.motions import joint_motion
    from fdbench.problem import TrackingProblem

    model = hopper_model()
    start = tuple(zip(model.coordinates, (0.0, 0.0, 0.0, 0.2, -0.3)))
    goal = tuple(zip(model.coordinates, (0.2, 0.1, -0.05, 0.6, -0.8)))
    model = dataclasses.replace(model, motions=(MotionSpec("step", "minimum-jerk", 0.2, start, goal),))
    problem = TrackingProblem("cs", Engine(model), joint_motion("step", model), feedforward=True, knots=4)
    assert problem.batched
    X = np.random.default_rng(5).normal(0, 0.01, (6, problem.n_params))
    X[2] *= 1e6  # thrown off: the simulation stops early and eq. 18's penalty counts
    assert problem.simulate(X[2] * problem.scale).t_end < problem.duration
    assert problem.simulate(X[0] * problem.scale).t_end == problem.duration
    assert_objectives_are(problem, X, lambda p: problem.objective_of(problem.simulate(p)))
    assert_population_equals_one_by_one(problem, X)
    assert_one_step_calls_change_nothing(problem, X, monkeypatch)


def test_control_runs_on_a_free_base_with_a_knee_path(tmp_path):
    """``fdbench control`` (PD with computed feedforward) on a model file with a free pelvis and a
    knee on a path: the run completes, and tracks its minimum-jerk motion (the pelvis's x and y
    included) to a small fraction of the motion."""
    import json

    from typer.testing import CliRunner

    from fdbench.cli import app
    from fdbench.multibody.model import MotionSpec
    from fdbench.multibody.model_files import to_toml

    model = hopper_model()
    start = dict(zip(model.coordinates, (0.0, 0.0, 0.0, 0.2, -0.3)))
    goal = dict(zip(model.coordinates, (0.2, 0.1, -0.05, 0.6, -0.8)))
    motion = MotionSpec("step", "minimum-jerk", 0.5, tuple(start.items()), tuple(goal.items()))
    path = tmp_path / "hopper.toml"
    path.write_text(to_toml(dataclasses.replace(model, motions=(motion,))))
    result = CliRunner().invoke(app, ["control", "--model", str(path), "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["status"] == "success" and out["t_end"] == 0.5
    assert out["rmse_rot_deg"] < 0.01 and out["rmse_trans_cm"] < 0.01  # deg over the angles, cm over x and y
