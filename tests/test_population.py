"""Population evaluation: one compiled call for many candidates, the same numbers as one by one,
whatever the thread count."""

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.experiment import optimize_spec, run
from fdbench.optimizers import make_optimizer
from fdbench.population import set_threads, threads
from fdbench.problem import TrackingProblem
from fdbench.torques import make_torque


@pytest.fixture(autouse=True)
def restore_threads():
    before = threads()
    yield
    set_threads(before)


@pytest.mark.parametrize("torque, feedforward", [("cs", False), ("cs", True), ("pf", True), ("ann", False)])
def test_population_equals_one_by_one_exactly(torque, feedforward):
    problem = TrackingProblem(make_torque(torque), feedforward=feedforward)
    rng = np.random.default_rng(3)
    # small steps (full runs) and large ones (simulations that fail part-way)
    X = problem.x0 + np.concatenate([0.02 * rng.standard_normal((6, problem.n_params)),
                                     3.0 * rng.standard_normal((5, problem.n_params))])
    one_by_one = np.array([problem.objective_scaled(x) for x in X])
    reached = [problem.simulate(x * problem.scale).success for x in X]
    assert any(reached) and not all(reached)  # both kinds present
    for count in (1, 2, 3):
        set_threads(count)
        assert np.array_equal(problem.objectives_scaled(X), one_by_one)


def test_cmaes_with_population_evaluation_takes_the_same_path():
    problem = TrackingProblem(make_torque("cs"))
    optimizer = make_optimizer("cmaes")
    plain = optimizer.minimize(problem.objective_scaled, problem.x0, 60, seed=4)
    set_threads(2)
    batched = optimizer.minimize(problem.objective_scaled, problem.x0, 60, seed=4, batch=problem.objectives_scaled)
    assert batched.history == plain.history and np.array_equal(batched.x, plain.x)
    assert batched.evaluations == plain.evaluations == 60


def test_thread_count_does_not_change_a_run():
    spec = optimize_spec("pf", "cmaes", True, seed=2, budget=60)
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
