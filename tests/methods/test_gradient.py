"""Exact gradients (forward sensitivities of the engine's RK4 map) on the paper's forearm against
central differences, and the command line's gradient options."""

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.numerics import richardson
from fdbench.cli import app
from fdbench.spec import optimize_spec
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.optimizers import make_optimizer
from fdbench.problem import TrackingProblem

FOREARM = Engine(find_model("forearm"))
PAPER = joint_motion("paper", find_model("forearm"))


def ForearmProblem(torque, feedforward):
    """The paper's tracking problem: the forearm on eq. 5."""
    return TrackingProblem(torque, FOREARM, PAPER, feedforward)


@pytest.mark.parametrize("torque", ["cs", "pf", "ann"])
@pytest.mark.parametrize("feedforward", [False, True])
def test_gradient_matches_central_differences(torque, feedforward):
    problem = ForearmProblem(torque, feedforward)
    x = problem.x0 + 0.01 * np.random.default_rng(1).standard_normal(problem.n_params)
    f, g = problem.value_and_gradient_scaled(x)
    assert f == problem.objective_scaled(x)  # the same simulation, to the last bit
    assert problem.simulate(x * problem.scale).success
    fd = richardson(problem.objective_scaled, x)
    assert np.max(np.abs(g - fd)) / np.max(np.abs(fd)) < 1e-6


def test_failing_simulation_gradient_is_the_rmse_gradient_over_the_samples_reached():
    problem = ForearmProblem("cs", True)
    x = np.linspace(2.5, 3.5, problem.n_params)  # a torque that spins the forearm until the constraint breaks
    result = problem.simulate(x * problem.scale)
    assert not result.success and 0 < result.t_end < 1
    f, g = problem.value_and_gradient_scaled(x)
    assert f == problem.objective_scaled(x)
    penalty = 1.0 - result.t_end
    assert f > penalty and np.any(g != 0)
    h = 1e-4  # small enough that the failure stays in the same step: the penalty term is constant
    for e in np.eye(problem.n_params)[:: 3]:
        assert problem.simulate((x + h * e) * problem.scale).t_end == result.t_end
    fd = richardson(problem.objective_scaled, x, h)
    # near the failure the differences are noisier than where the run is smooth
    assert np.max(np.abs(g - fd)) / np.max(np.abs(fd)) < 1e-5


def test_a_value_and_gradient_pass_counts_as_one_evaluation():
    calls = []

    def value_and_gradient(x):
        calls.append(1)
        return float(x @ x), 2 * x

    for name in ("bfgs", "lbfgsb"):
        calls.clear()
        result = make_optimizer(name).minimize(lambda x: float(x @ x), np.ones(3), 7, gradient=value_and_gradient)
        assert result.evaluations == len(calls) <= 7
        assert result.fun < 1e-12  # a quadratic with its exact gradient: found at once


def test_exact_gradient_beats_finite_differences_on_the_spline():
    from fdbench.api import run

    exact = run(optimize_spec("cs", "bfgs", budget=200, gradient="exact")).record
    fd = run(optimize_spec("cs", "bfgs", budget=200)).record
    assert exact["evaluations"] <= 200 and exact["gradient"] == "exact"
    assert exact["rmse_rot_deg"] <= 0.005 < fd["rmse_rot_deg"]


def test_exact_gradient_runs_hash_apart_and_default_runs_keep_their_hash():
    default = optimize_spec("cs", "bfgs")
    assert "gradient" not in default.canonical()
    assert optimize_spec("cs", "bfgs", gradient="exact").hash() != default.hash()


@pytest.mark.parametrize("args, words", [
    (["--opt", "cmaes", "--gradient", "exact"], "gradient-based"),
    (["--gradient", "sometimes"], "--gradient must be one of fd, exact"),
    (["--gradient", "exact", "--integrator", "rk45"], "needs --integrator rk4"),
])
def test_bad_gradient_options_are_one_line_errors(args, words):
    result = CliRunner().invoke(app, ["optimize", *args])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and words in lines[0]
