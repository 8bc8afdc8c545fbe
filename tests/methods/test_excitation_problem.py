"""The shooting problem with muscle excitations as inputs (``fdbench.excitation_problem``) on the
library's arm26 with rigid tendons, over a 50-ms motion (50 RK4 steps, a spline of 4 knots per muscle): the logistic map, the
effort term's closed form, a population against its rows one by one, the value of
``value_and_gradient`` against ``objective``, its gradient against central differences (also with
three muscles through points), and a few BFGS iterations lowering the objective; with feedforward, the
start's excitations against static optimisation on the grid and the gradient against central
differences."""

from __future__ import annotations

import numpy as np
import pytest

from fdbench.excitation_problem import START_RANGE, ExcitationProblem, logistic
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.multibody.simulation import inverse_dynamics
from fdbench.multibody.static_optimization import static_optimization
from fdbench.optimizers import make_optimizer

from helpers.models import short_arm26


def arm26_problem(points: bool = False, **options) -> ExcitationProblem:
    """The problem on arm26 with rigid tendons over 50 ms; ``points``: TRIlong, BIClong and BRA through
    points."""
    model = short_arm26(points)
    return ExcitationProblem("cs", Engine(model), joint_motion("short", model), dt=1e-3, effort_weight=2.0, knots=4,
                             **options)


@pytest.fixture(scope="module")
def problem() -> ExcitationProblem:
    return arm26_problem()


@pytest.fixture(scope="module")
def fed() -> ExcitationProblem:
    """The problem with static optimisation's excitations as its feedforward."""
    return arm26_problem(feedforward=True)


def test_the_logistic_maps_every_signal_into_the_unit_interval():
    s = np.array([-1e6, -30.0, -1.0, 0.0, 1.0, 30.0, 1e6])
    e = logistic(s)
    assert e[3] == 0.5 and np.all(np.diff(e) >= 0) and np.all((e >= 0) & (e <= 1))
    np.testing.assert_allclose(e[2:5], 1.0 / (1.0 + np.exp(-s[2:5])), rtol=1e-15)
    np.testing.assert_allclose(e[2] + e[4], 1.0, rtol=1e-15)


def test_the_effort_of_constant_excitations_is_w_m_e2_t(problem):
    """The trapezoidal rule is exact for constants: w_e M c^2 T."""
    M, rows = problem.engine.n_muscles, 2 * problem._n_steps + 1
    for c in (0.0, 0.3, 1.0):
        assert problem.effort(np.full((1, rows, M), c))[0] == pytest.approx(2.0 * M * c * c * 0.05, rel=1e-13)


def test_a_population_is_its_rows_one_by_one_and_the_gradient_s_value_is_the_objective(problem):
    X = problem.x0 + np.random.default_rng(7).normal(0.0, 0.3, (4, problem.n_params))
    values = problem.objectives_scaled(X)
    assert np.ptp(values) > 1e-3
    for x, value in zip(X, values):
        assert problem.objective_scaled(x) == value
        assert problem.value_and_gradient_scaled(x)[0] == value
    assert problem.objective(problem.p0) < 50.0  # the start (static optimisation's activations) moves the arm


@pytest.mark.parametrize("points", [False, True], ids=["polynomials", "points"])
def test_the_exact_gradient_equals_central_differences(problem, points):
    """d f / d x of three parameters (in the blocks of muscles 0, 3 and 5, with ``points`` those
    muscles through points) against central differences (step 1e-4 in the scaled parameters),
    within 1e-5 relative."""
    problem = arm26_problem(points=True) if points else problem
    x = problem.x0 + 0.1
    _, gradient = problem.value_and_gradient_scaled(x)
    for q in (1, 3 * 4 + 2, 5 * 4):
        step = np.zeros_like(x)
        step[q] = 1e-4
        expected = (problem.objective_scaled(x + step) - problem.objective_scaled(x - step)) / 2e-4
        assert abs(expected) > 1e-3
        assert gradient[q] == pytest.approx(expected, rel=1e-5)


def test_bfgs_with_the_exact_gradient_lowers_the_objective(problem):
    """Eight evaluations (value and exact gradient) of BFGS from the start: a quarter off (measured
    2.98 -> 1.62)."""
    found = make_optimizer("bfgs").minimize(problem.objective_scaled, problem.x0, 8, 0,
                                            gradient=problem.value_and_gradient_scaled)
    assert found.fun < 0.75 * problem.objective_scaled(problem.x0)


def test_with_feedforward_the_start_excites_as_static_optimisation_on_the_grid(fed):
    """Zero knots: each excitation on RK4's half steps is static optimisation's activation there
    (clipped to START_RANGE), and the replay's excitations on the motion's samples are those rows."""
    assert np.all(fed.p0 == 0.0)
    grid = fed._grid
    inv = inverse_dynamics(grid.t, fed.engine, fed.motion)
    so = static_optimization(fed.engine.model, fed.engine.muscle_params, grid.t, inv.angles, inv.velocities,
                             inv.torque)
    expected = np.clip(so.activation, *START_RANGE)
    np.testing.assert_allclose(fed.excitations_on_grid(fed.p0), expected, rtol=1e-12, atol=1e-14)
    replay = fed.simulation(fed.p0)
    np.testing.assert_allclose(replay.excitation, expected[::2 * grid.every], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(replay.activation[0], expected[0], rtol=1e-12)


def test_with_feedforward_the_exact_gradient_equals_central_differences(fed):
    x = fed.x0 + 0.05
    _, gradient = fed.value_and_gradient_scaled(x)
    for q in (2, 4 * 4 + 1):
        step = np.zeros_like(x)
        step[q] = 1e-4
        expected = (fed.objective_scaled(x + step) - fed.objective_scaled(x - step)) / 2e-4
        assert abs(expected) > 1e-4
        assert gradient[q] == pytest.approx(expected, rel=1e-5)
