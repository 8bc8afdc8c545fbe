"""Eq. 12 by numpy for free and path joints (fdbench.multibody.general):

- on models of pin joints only, the dense assembly and solve equal the compiled kernel's state
  derivative (a different assembly and solve of the same equations) to their rounding, 1e-14 times
  the dense leading matrix's condition number (relative);
- on random models with free and path joints, the engine's state from joint values lies on the
  constraints (positions and velocities, to rounding), and eq. 12's accelerations there converge to
  the reference's minimal forward dynamics (tests/reference_dynamics.GeneralTree) as 1/alpha;
- the engine's ``rates`` (the adaptive integrators' right-hand side) is the RK4 driver's derivative.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import reference_dynamics as ref
from multibody_strategies import models, models_with_paths_and_free_joints

from fdbench.multibody.engine import Engine
from fdbench.multibody.general import DensePenalty


def random_joint_state(engine, seed):
    rng = np.random.default_rng(seed)
    J = engine.n_joints
    return rng.uniform(-2.5, 2.5, J), rng.uniform(-3, 3, J), rng.uniform(-20, 20, J)


@settings(max_examples=20, deadline=None)
@given(model=models(), seed=st.integers(0, 2**16))
def test_the_dense_assembly_equals_the_compiled_kernel_on_pin_joints(model, seed):
    engine = Engine(model, alpha=1e5)  # the same equations at any alpha; a small one keeps the rounding small
    z, zd, tau = random_joint_state(engine, seed)
    rng = np.random.default_rng(seed + 1)
    y = engine.state_from_joints(z, zd) + rng.normal(0, 1e-4, engine.n_state)  # off the manifold a little
    penalty = DensePenalty(engine)
    code, dense = penalty.derivative(y, tau)
    compiled = engine.accelerations(y, tau)
    assert code == 0
    _, J, _ = penalty.constraints(y[:engine.n_q], y[engine.n_q:])
    condition = np.linalg.cond(penalty.mass + penalty.alpha * J.T @ J)  # the two solves' rounding grows with it
    assert np.abs(dense - compiled).max() <= max(1e-12, 1e-14 * condition) * np.abs(compiled).max()
    assert abs(penalty.violation(y) - engine.constraint_violation(y)) <= 1e-12


@settings(max_examples=15, deadline=None)
@given(model=models_with_paths_and_free_joints(max_bodies=4), seed=st.integers(0, 2**16))
def test_on_the_constraints_eq_12_converges_to_the_minimal_forward_dynamics(model, seed):
    t = ref.GeneralTree(model)
    z, zd, tau = random_joint_state(Engine(model), seed)
    expected = t.forward_dynamics(z, zd, tau)
    errors = []
    for alpha in (1e5, 1e7):  # low enough that the penalty's error stays above the solve's rounding
        engine = Engine(model, alpha=alpha)
        y = engine.state_from_joints(z, zd)
        dense = engine.dense_penalty
        Phi, J, _ = dense.constraints(y[:engine.n_q], y[engine.n_q:])
        assert np.abs(Phi).max() < 1e-12 and np.abs(J @ y[engine.n_q:]).max() < 1e-11
        rate, _ = engine.rates(y[None], tau[None], *(np.zeros((1, engine.n_joints)),) * 3, 0.0, 0.0)
        zdd = engine.joints_from_state(rate[0])[1]  # [q', q''] read as a state: its second half gives z''
        errors.append(np.abs(zdd - expected).max() / max(1.0, np.abs(expected).max()))
        rounding = 1e-14 * np.linalg.cond(dense.mass + dense.alpha * J.T @ J)
    # the penalty's error shrinks as 1/alpha, down to the solve's rounding
    assert errors[1] < 1e-2 and (errors[1] < errors[0] / 30 or errors[1] < rounding), (errors, rounding)


@settings(max_examples=5, deadline=None)
@given(model=models_with_paths_and_free_joints(max_bodies=3), seed=st.integers(0, 2**16))
def test_rates_are_the_drivers_derivative_under_pd(model, seed):
    engine = Engine(model)
    z, zd, tau = random_joint_state(engine, seed)
    y = engine.state_from_joints(z, zd)
    kp, kd = np.full(engine.n_joints, 50.0), np.full(engine.n_joints, 5.0)
    ref_z, ref_zd = z + 0.1, zd - 0.2
    rate, applied = engine.rates(y[None], tau[None], ref_z[None], ref_zd[None], np.zeros((1, engine.n_joints)), kp, kd)
    np.testing.assert_allclose(applied[0], tau + kp * 0.1 - kd * 0.2, rtol=1e-12, atol=1e-12)
    code, expected = engine.dense_penalty.derivative(y, applied[0])
    assert code == 0 and np.array_equal(rate[0], expected)


def test_control_runs_on_a_free_base_with_a_knee_path(tmp_path):
    """``fdbench control`` (PD with computed feedforward) on a model file with a free pelvis and a
    knee on a path: the run completes, and tracks its minimum-jerk motion (the pelvis's x and y
    included) to a small fraction of the motion."""
    import dataclasses
    import json

    from test_multibody_reference import hopper_model
    from typer.testing import CliRunner

    from fdbench.cli import app
    from fdbench.multibody.description import MotionSpec, to_toml

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


def test_exact_gradients_on_a_free_base_are_refused_before_any_work(tmp_path):
    """The compiled sensitivities do not take free or path joints yet: ``optimize --gradient exact``
    on such a model is refused in one line naming the joints, exit code 2, and writes nothing."""
    import dataclasses

    from test_multibody_reference import hopper_model
    from typer.testing import CliRunner

    from fdbench.cli import app
    from fdbench.multibody.description import MotionSpec, to_toml

    model = hopper_model()
    rest = tuple((name, 0.0) for name in model.coordinates)
    path = tmp_path / "hopper.toml"
    path.write_text(to_toml(dataclasses.replace(model, motions=(MotionSpec("still", "minimum-jerk", 0.2, rest, rest),))))
    out = tmp_path / "out.json"
    result = CliRunner().invoke(app, ["optimize", "--model", str(path), "--gradient", "exact", "--budget", "3",
                                      "--output", str(out)])
    assert result.exit_code == 2 and not out.exists()
    assert len(result.stderr.strip().splitlines()) == 1 and "free" in result.stderr and "--gradient exact" in result.stderr
