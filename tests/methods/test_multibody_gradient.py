"""Exact gradients on the engine's models (forward sensitivities of the RK4 map,
``fdbench.multibody.sensitivity``) against central differences of the objective: on a tree (a body
with two children, one of them joined away from its parent's basic points) and on the library's
leg, for every parameterisation with d tau / d p, with and without feedforward; and on the
command line."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.numerics import richardson
from fdbench.cli import app
from fdbench.multibody import model as d
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import MinimumJerk, joint_motion
from fdbench.problem import TrackingProblem


def tree():
    """A trunk hanging from ground near -90 deg from +x (its angle constraint in the cos form) with
    two children in the sin form: one at its end, one at a point between its basic points (a point
    tied to them by linear constraints); a load on the second child. The motion keeps every body in
    its form: the objective is smooth (a form switch changes the dynamics by amounts of the size of
    the constraint violation, which differences across it would see)."""
    bodies = (d.Body("trunk", 5.0, (0.2, 0.02), 0.08, end=(0.4, 0.0)), d.Body("left", 2.0, (0.15, 0.0), 0.02),
              d.Body("right", 1.5, (0.12, 0.01), 0.015, end=(0.25, 0.0)))
    joints = (d.Joint("root", "pin", d.GROUND, "trunk", (0.0, 0.0), (0.0, 0.0), offset=-np.pi / 2),
              d.Joint("left_joint", "pin", "trunk", "left", (0.4, 0.0), (0.0, 0.0), offset=1.2),
              d.Joint("right_joint", "pin", "trunk", "right", (0.2, 0.05), (0.0, 0.0), offset=-1.0))
    model = d.Model("tree", (0.0, -9.81), bodies, joints, loads=(d.Load("right", (0.25, 0.0), (0.0, -5.0)),))
    spec = d.MotionSpec("move", "minimum-jerk", 0.3, (("root", 0.0), ("left_joint", 0.3), ("right_joint", -0.2)),
                        (("root", 0.15), ("left_joint", -0.2), ("right_joint", 0.4)))
    return Engine(model), MinimumJerk(spec, model.coordinates)


TREE = tree()
LEG = (Engine(find_model("leg3")), joint_motion("swing", find_model("leg3")))


def check_against_differences(problem, seed=1):
    """The value is ``objective``'s to the last bit and the gradient that of central differences,
    to 2e-6 relative with the better of two steps (scaled parameters): the differences carry
    truncation errors at the larger step where the objective is strongly curved (ann without
    feedforward) and rounding errors at the smaller."""
    x = problem.x0 + 0.01 * np.random.default_rng(seed).standard_normal(problem.n_params)
    f, g = problem.value_and_gradient_scaled(x)
    assert f == problem.objective_scaled(x)  # the same simulation, to the last bit
    assert problem.simulate(x * problem.scale).success
    errors = [np.max(np.abs(g - fd)) / np.max(np.abs(fd))
              for fd in (richardson(problem.objective_scaled, x, h) for h in (1e-3, 1e-4))]
    assert min(errors) < 2e-6, errors


def test_the_tree_has_linear_constraints_and_both_forms_throughout():
    from fdbench.multibody import simulation as sim

    engine, motion = TREE
    assert engine.lin_const.shape[0] == 2  # the right child's joint point
    states = sim.simulate(sim.feedforward(engine, motion), engine, motion).states
    cos = np.abs(np.cos(states[:, engine.n_p:engine.n_q] + engine.body_geom[:, 1]))
    assert np.all(cos[:, 0] < 0.2) and np.all(cos[:, 1:] > 0.2)  # the trunk's cos form, the children's sin form


@pytest.mark.parametrize("torque", ["cs", "pf", "ann"])
@pytest.mark.parametrize("feedforward", [False, True])
def test_gradient_matches_central_differences_on_a_tree(torque, feedforward):
    engine, motion = TREE
    check_against_differences(TrackingProblem(torque, engine, motion, feedforward))


@pytest.mark.parametrize("torque", ["cs", "pf", "ann"])
@pytest.mark.parametrize("feedforward", [False, True])
def test_gradient_matches_central_differences_on_the_leg(torque, feedforward):
    engine, motion = LEG
    check_against_differences(TrackingProblem(torque, engine, motion, feedforward))


def test_gradient_at_the_initial_guess_is_not_zero():
    engine, motion = LEG
    problem = TrackingProblem("cs", engine, motion)
    f, g = problem.value_and_gradient_scaled(problem.x0)
    assert f == problem.objective_scaled(problem.x0) and np.all(np.isfinite(g)) and np.abs(g).max() > 1.0


def test_failing_simulation_gradient_is_the_rmse_gradient_over_the_samples_reached():
    engine, motion = TREE
    problem = TrackingProblem("cs", engine, motion, feedforward=True)
    x = np.zeros(problem.n_params)
    x[problem.blocks[1]:problem.blocks[2]] = 10.0  # the left child's torque swings it round until it fails
    result = problem.simulate(x * problem.scale)
    assert not result.success and 0 < result.t_end < motion.duration
    f, g = problem.value_and_gradient_scaled(x)
    assert f == problem.objective_scaled(x)
    assert f > 1.0 - result.t_end / motion.duration and np.any(g != 0)
    h = 1e-4  # small enough that the failure stays in the same step: the penalty term is constant
    for e in np.eye(problem.n_params):
        for sign in (-1, 1):
            assert problem.simulate((x + sign * h * e) * problem.scale).t_end == result.t_end
    fd = richardson(problem.objective_scaled, x, h)
    # a body spinning round: the differences are noisier than where the run is smooth
    assert np.max(np.abs(g - fd)) / np.max(np.abs(fd)) < 1e-5


def optimize(*args):
    result = CliRunner().invoke(app, ["optimize", "--model", "leg3", "--torque", "cs", "--opt", "bfgs", "--budget",
                                      "30", "--format", "json", "--quiet", *args])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_exact_gradient_on_the_leg_improves_and_beats_finite_differences():
    exact, fd = optimize("--gradient", "exact"), optimize()
    assert exact["gradient"] == "exact" and exact["evaluations"] <= 30 and exact["status"] == "success"
    assert exact["best_objective"] < exact["initial_objective"] / 5
    assert exact["best_objective"] < fd["best_objective"] / 5


@pytest.mark.parametrize("args, words", [
    (["--opt", "cmaes", "--gradient", "exact"], "gradient-based"),
    (["--opt", "bfgs", "--gradient", "exact", "--integrator", "rk45"], "needs --integrator rk4"),
    (["--opt", "bfgs", "--gradient", "exact", "--dt", "0.003"], "samples on the RK4 grid"),
])
def test_bad_combinations_are_refused_in_one_line(tmp_path, args, words):
    out = tmp_path / "run.json"
    result = CliRunner().invoke(app, ["optimize", "--model", "leg3", "--output", str(out), *args])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and words in lines[0], result.output
    assert not out.exists()
