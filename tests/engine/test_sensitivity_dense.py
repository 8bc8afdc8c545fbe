"""Exact gradients on models with free or path joints and external loads: the dense solve's forward
sensitivities (``fdbench.multibody.kernels.rk4_sensitivity`` with paths, free joints or loads)
checked against

- the banded solve's sensitivities (another derivation: the angle rows eliminated by hand, one
  direction at a time) on random models of pin joints, which both solves take (the dense one when
  ``free`` is an empty array rather than None);
- central differences of the simulation itself on the hopper (a free pelvis, a knee on a path,
  three loads in ground's and in moving frames): their error falls as h^2 towards the
  sensitivities, the sign of a derivative, not an approximation, being checked;
- central differences of eq. 18 through ``TrackingProblem.value_and_gradient`` (the angles' RMSE in
  deg plus the translations' in cm), and on the command line.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from helpers.multibody_strategies import models
from helpers.models import hopper_loads, hopper_model

from fdbench.multibody.engine import Engine
from fdbench.multibody.sensitivity import rk4_sensitivity

STEPS, DT = 40, 0.002


def _torques(engine, seed, scale=2.0):
    """Random smooth torques on the half-step grid (2 STEPS + 1, J) and parameters moving them: per
    coordinate a constant and a ramp (G (rows, 2 J), param_col (2 J,))."""
    rows, J = 2 * STEPS + 1, engine.n_joints
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, rows)[:, None]
    tau = scale * (rng.normal(size=(1, J)) + rng.normal(size=(1, J)) * np.sin(3 * t))
    G = np.zeros((rows, 2 * J))
    G[:, 0::2], G[:, 1::2] = 1.0, t
    return tau, G, np.repeat(np.arange(J), 2).astype(np.int64)


def dense_run(engine, y0, tau, G, param_col, sensitivities=True):
    """(states, dz, steps done) of the dense solve's open-loop RK4 with sensitivities."""
    J, P, rows = engine.n_joints, G.shape[1], 2 * STEPS + 1
    states, rates = np.empty((STEPS + 1, engine.n_state)), np.empty((STEPS + 1, engine.n_state))
    dz = np.empty((STEPS + 1, J, P))
    zero = np.zeros((rows, J))
    free = np.zeros(0, dtype=np.int64) if engine.free is None else engine.free  # the dense solve
    _, done = rk4_sensitivity(y0, DT, STEPS, tau, zero, zero, G, param_col, 1, engine.layout, engine.paths, free,
                              engine.loads_at(np.arange(rows) * DT / 2), states, rates, np.empty((STEPS + 1, J)), dz)
    return states, dz, done


@settings(max_examples=15, deadline=None)
@given(model=models(max_bodies=4), seed=st.integers(0, 2**16))
def test_the_dense_sensitivities_equal_the_banded_ones_on_pin_joints(model, seed):
    engine = Engine(model, alpha=1e5)
    J = engine.n_joints
    rng = np.random.default_rng(seed)
    y0 = engine.state_from_joints(rng.uniform(-1, 1, J), rng.uniform(-1, 1, J))
    tau, G, param_col = _torques(engine, seed)
    states, dz, done = dense_run(engine, y0, tau, G, param_col)
    rows = 2 * STEPS + 1
    banded_states, rates = np.empty((STEPS + 1, engine.n_state)), np.empty((STEPS + 1, engine.n_state))
    banded_dz = np.empty((STEPS + 1, J, G.shape[1]))
    _, banded_done = rk4_sensitivity(y0, DT, STEPS, tau, np.zeros((rows, J)), np.zeros((rows, J)), G, param_col, 1,
                                     *engine.kernel_args(), None, banded_states, rates, np.empty((STEPS + 1, J)),
                                     banded_dz)
    assert done == banded_done
    scale = np.abs(banded_dz[:done + 1]).max()
    assert scale > 0
    # the two kernels' rounding differs, and a light body (inertia 1e-4 kg m^2) amplifies it over the
    # run to about 1e-7; a wrong term of the derivative would show at 1e-2 or more
    np.testing.assert_allclose(dz[:done + 1], banded_dz[:done + 1], rtol=0, atol=1e-5 * scale)


def test_the_sensitivities_on_a_free_base_with_a_knee_path_and_loads_are_the_derivative():
    """Central differences of the coordinates (rad, m) over the run converge as h^2 to the
    sensitivities, for every parameter (alpha 1e3 keeps the differences' rounding below their
    truncation error)."""
    engine = Engine(hopper_model(), alpha=1e3, loads=hopper_loads(0))
    J = engine.n_joints
    rng = np.random.default_rng(1)
    y0 = engine.state_from_joints(0.2 * rng.normal(size=J), 0.5 * rng.normal(size=J))
    tau, G, param_col = _torques(engine, 2, scale=1.0)
    states, dz, done = dense_run(engine, y0, tau, G, param_col)
    assert done == STEPS

    def coordinates(p):
        moved = tau.copy()
        for q, column in enumerate(param_col):
            moved[:, column] += G[:, q] * p[q]
        return engine.joints_from_state(dense_run(engine, y0, moved, G, param_col)[0])[0]

    def error(h):
        worst = 0.0
        for q in range(G.shape[1]):
            step = np.zeros(G.shape[1])
            step[q] = h
            difference = (coordinates(step) - coordinates(-step)) / (2 * h)
            worst = max(worst, np.abs(difference - dz[:, :, q]).max() / np.abs(dz[:, :, q]).max())
        return worst

    coarse, fine = error(0.1), error(0.05)
    assert fine < 1e-5 and fine < coarse / 3, (coarse, fine)


def _hopper_problem(feedforward=True, residual_weight=0.05):
    """The hopper tracking a minimum-jerk motion that moves every coordinate (the pelvis's x and y in
    m), under the loads, with cubic splines per coordinate and eq. 18's residual term."""
    from fdbench.multibody.model import MotionSpec
    from fdbench.multibody.motions import MinimumJerk
    from fdbench.problem import TrackingProblem

    model = hopper_model()
    start = tuple((name, 0.0) for name in model.coordinates)
    end = tuple((name, 0.05 if name in ("tx", "ty") else 0.2) for name in model.coordinates)
    motion = MinimumJerk(MotionSpec("move", "minimum-jerk", 0.2, start, end), model.coordinates)
    engine = Engine(model, alpha=1e4, loads=hopper_loads(1))
    return TrackingProblem("cs", engine, motion, feedforward, residual_weight=residual_weight)


def test_eq_18_and_its_exact_gradient_on_a_free_base_are_those_of_the_simulation():
    from helpers.numerics import richardson

    problem = _hopper_problem()
    x = problem.x0 + 0.05 * np.random.default_rng(3).standard_normal(problem.n_params)
    f, g = problem.value_and_gradient_scaled(x)
    assert f == problem.objective_scaled(x)  # the same simulation, to the last bit
    assert problem.simulate(x * problem.scale).success
    errors = [np.max(np.abs(g - fd)) / np.max(np.abs(fd))  # the better of two steps, as on pin joints
              for fd in (richardson(problem.objective_scaled, x, h) for h in (1e-3, 1e-4))]
    assert min(errors) < 2e-6, errors


def test_the_residual_term_is_the_weighted_rms_of_the_base_forces():
    """Eq. 18 with the residual term minus eq. 18 without it is the weight times the RMS of the base's
    force (FX, FY, N) plus that of its moment (MZ, N m), the torque history read from the torque
    function at the half-step times (another evaluation of the splines than the grid's)."""
    with_term, without = _hopper_problem(residual_weight=0.05), _hopper_problem(residual_weight=0.0)
    p = with_term.p0 + 0.3 * np.random.default_rng(4).standard_normal(with_term.n_params)
    tau = with_term.torque_function(p)(with_term._half)
    c = hopper_model().coordinates.index("tilt")  # the free joint's angle, then its x and y
    force = np.sqrt(np.mean(tau[:, c + 1] ** 2 + tau[:, c + 2] ** 2))
    moment = np.sqrt(np.mean(tau[:, c] ** 2))
    assert force > 1.0 and moment > 0.1
    assert with_term.objective(p) - without.objective(p) == pytest.approx(0.05 * (force + moment), rel=1e-9)


def test_optimize_with_exact_gradients_on_a_free_base_runs_and_improves(tmp_path):
    """``optimize --gradient exact`` takes a model with a free base and a knee path, and BFGS lowers
    eq. 18 from its start."""
    from fdbench.cli import app
    from fdbench.multibody.model import MotionSpec
    from fdbench.multibody.model_files import to_toml

    model = hopper_model()
    start = tuple((name, 0.0) for name in model.coordinates)
    end = tuple((name, 0.05 if name in ("tx", "ty") else 0.2) for name in model.coordinates)
    path = tmp_path / "hopper.toml"
    path.write_text(to_toml(dataclasses.replace(model, motions=(MotionSpec("move", "minimum-jerk", 0.2, start,
                                                                           end),))))
    result = CliRunner().invoke(app, ["optimize", "--model", str(path), "--torque", "cs", "--opt", "bfgs",
                                      "--gradient", "exact", "--budget", "8", "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout)
    assert record["gradient"] == "exact" and record["evaluations"] <= 8
    assert record["best_objective"] < record["initial_objective"]


def test_a_recording_off_the_grid_is_refused_with_the_step_that_fits(tmp_path):
    """Samples at 60 Hz (times rounded as a .mot's) do not fall on a 1 ms grid: exact gradients are
    refused in one line that names the step putting them on it, 1/60 s / 17, and nothing is written."""
    from fdbench.cli import app
    from fdbench.multibody.simulation import dt_on_samples

    t = np.round(np.arange(31) / 60, 8)
    assert dt_on_samples(1e-3, t) == pytest.approx(1 / 1020, rel=1e-9)
    assert dt_on_samples(1e-3, np.linspace(0.0, 0.5, 501)) == 1e-3  # already on the grid
    motion = tmp_path / "swing.csv"
    angles = 20 * np.sin(2 * t)
    motion.write_text("t,hip,knee,ankle\n" + "".join(f"{a},{b},{b},{b}\n" for a, b in zip(t.tolist(), angles.tolist())))
    out = tmp_path / "run.json"
    result = CliRunner().invoke(app, ["optimize", "--model", "leg3", "--motion", str(motion), "--opt", "bfgs",
                                      "--gradient", "exact", "--output", str(out)])
    assert result.exit_code == 2 and not out.exists()
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and f"--dt {1 / 1020!r}" in lines[0], result.output
