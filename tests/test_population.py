"""Population evaluation: one compiled call for many candidates, the same numbers as one by one,
whatever the thread count."""

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.experiment import optimize_spec, run
from fdbench.optimizers import make_optimizer
from fdbench.population import set_threads
from fdbench.problem import TrackingProblem
from fdbench.torques import make_torque
from population_checks import (assert_objectives_are, assert_population_equals_one_by_one,  # noqa: F401
                               restore_threads)


CELLS = [("cs", False), ("cs", True), ("pf", False), ("pf", True), ("ann", False), ("ann", True)]


@pytest.fixture(scope="module")
def problems():
    """One tracking problem per cell, made once (pf's pre-fit takes a moment)."""
    return {cell: TrackingProblem(make_torque(cell[0]), feedforward=cell[1]) for cell in CELLS}


def population(problem, seed=3):
    """Scaled candidates around the start: small steps (full runs) and large ones (simulations that
    fail part-way), shape (11, n_params)."""
    rng = np.random.default_rng(seed)
    return problem.x0 + np.concatenate([0.02 * rng.standard_normal((6, problem.n_params)),
                                        3.0 * rng.standard_normal((5, problem.n_params))])


@pytest.mark.parametrize("cell", CELLS, ids=str)
def test_population_equals_one_by_one_exactly(cell, problems):
    problem = problems[cell]
    X = population(problem)
    reached = [problem.simulate(x * problem.scale).success for x in X]
    assert any(reached) and not all(reached)  # both kinds present
    assert_population_equals_one_by_one(problem, X)


@pytest.mark.parametrize("cell", CELLS, ids=str)
def test_population_objectives_are_eq18_of_each_simulation(cell, problems):
    """Checked against eq. 18 written out here from each candidate's SimulationResult."""
    problem = problems[cell]

    def eq18(p):
        result = problem.simulate(p)
        reached = np.isfinite(result.q[:, 2])  # the motion's samples up to t_end
        rmse = np.sqrt(np.mean(np.degrees(result.q[reached, 2] - problem.inverse.theta[reached]) ** 2))
        return rmse + 1.0 - result.t_end / problem.duration

    assert_objectives_are(problem, population(problem, seed=5), eq18)


@pytest.mark.parametrize("cell", CELLS, ids=str)
def test_population_torques_equal_each_candidates_exactly(cell, problems):
    problem = problems[cell]
    P = population(problem) * problem.scale
    together = problem.torques_on_grid(P)
    for c, p in enumerate(P):
        assert np.array_equal(together[c], problem.torques_on_grid(p[None])[0])
    if cell[1]:  # with feedforward: the inverse-dynamics torque plus the parameterisation's own
        own = problem.torque.on_grid(problem._half)(P[0])
        np.testing.assert_allclose(together[0], own + problem._ff(problem._half), rtol=0, atol=1e-12)


def test_cmaes_with_population_evaluation_takes_the_same_path():
    problem = TrackingProblem(make_torque("cs"))
    optimizer = make_optimizer("cmaes")
    plain = optimizer.minimize(problem.objective_scaled, problem.x0, 60, seed=4)
    set_threads(2)
    batched = optimizer.minimize(problem.objective_scaled, problem.x0, 60, seed=4, batch=problem.objectives_scaled)
    assert batched.history == plain.history and np.array_equal(batched.x, plain.x)
    assert batched.evaluations == plain.evaluations == 60


@pytest.mark.parametrize("torque, feedforward", [("cs", False), ("pf", True), ("ann", False)])
def test_thread_count_does_not_change_a_run(torque, feedforward):
    spec = optimize_spec(torque, "cmaes", feedforward, seed=2, budget=60)
    records = []
    for count in (1, 2):
        set_threads(count)
        records.append(run(spec).record)
    for name in ("rmse_rot_deg", "rmse_torque_nm", "best_objective", "evaluations", "t_end"):
        assert records[0][name] == records[1][name]


def test_bad_thread_count_is_a_one_line_error():
    result = CliRunner().invoke(app, ["optimize", "--opt", "cmaes", "--threads", "0"])
    assert result.exit_code == 2
    assert result.output.strip().startswith("fdbench: error: --threads must be an integer")
