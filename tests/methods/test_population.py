"""Population evaluation on the paper's forearm (a one-joint model of the engine): one compiled call
for many candidates, the same numbers as one by one, whatever the thread count. The arm's are in
tests/methods/test_multibody_problem.py."""

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from helpers import forearm_closed_form as forearm
from fdbench.api import run
from fdbench.spec import optimize_spec
from fdbench.multibody.motions import eq5
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.population import set_threads
from fdbench.problem import TrackingProblem
from helpers.population_checks import (assert_objectives_are, assert_one_step_calls_change_nothing,  # noqa: F401
                               assert_population_equals_one_by_one, restore_threads)


CELLS = [("cs", False), ("cs", True), ("pf", False), ("pf", True), ("ann", False), ("ann", True)]


@pytest.fixture(scope="module")
def problems():
    """One tracking problem per cell, made once (pf's pre-fit takes a moment)."""
    model = find_model("forearm")
    return {cell: TrackingProblem(cell[0], Engine(model), joint_motion("paper", model), feedforward=cell[1])
            for cell in CELLS}


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


@pytest.mark.parametrize("cell", [("cs", False), ("ann", True)], ids=str)
def test_population_in_calls_of_one_step_equals_one_call_exactly(cell, problems, monkeypatch):
    """Each candidate's simulation cut at every step (as Ctrl-C may stop it between two calls) and
    resumed from its last state gives the numbers of one call, failing candidates included."""
    assert_one_step_calls_change_nothing(problems[cell], population(problems[cell]), monkeypatch)


@pytest.mark.parametrize("cell", CELLS, ids=str)
def test_population_objectives_are_eq18_of_each_simulation(cell, problems):
    """Checked against eq. 18 written out here from each candidate's simulated elbow angle and eq. 5."""
    problem = problems[cell]

    def eq18(p):
        result = problem.simulate(p)
        reached = np.isfinite(result.z[:, 0])  # the motion's samples up to t_end
        desired = eq5(result.t[reached], "paper")[0]
        rmse = np.sqrt(np.mean(np.degrees(result.z[reached, 0] - desired) ** 2)) if reached.any() else 0.0
        return rmse + 1.0 - result.t_end / 1.0

    assert_objectives_are(problem, population(problem, seed=5), eq18)


@pytest.mark.parametrize("cell", CELLS, ids=str)
def test_population_torques_equal_each_candidates_exactly(cell, problems):
    problem = problems[cell]
    P = population(problem) * problem.scale
    together = problem.torques_on_grid_batch(P)[:, :, 0]
    for c, p in enumerate(P):
        assert np.array_equal(together[c], problem.torques_on_grid(p)[:, 0])
    if cell[1]:  # with feedforward: the closed-form inverse-dynamics torque plus the parameterisation's own
        own = problem.parts[0].on_grid(problem._half)(P[0])
        closed_form = forearm.torque_along(*eq5(problem._half, "paper"))
        np.testing.assert_allclose(together[0], own + closed_form, rtol=0, atol=1e-9)


@pytest.mark.parametrize("torque, feedforward", [("cs", False), ("pf", True), ("ann", False)])
def test_thread_count_does_not_change_a_run(torque, feedforward):
    spec = optimize_spec(torque, "cmaes", feedforward, seed=2, budget=60)
    records = []
    for count in (1, 2):
        set_threads(count)
        records.append(run(spec).record)
    for name in ("rmse_rot_deg", "rmse_torque_nm", "best_objective", "evaluations", "t_end"):
        assert records[0][name] == records[1][name]


def test_cma_work_in_its_own_thread_does_not_change_a_run(monkeypatch):
    """From IN_THREAD_FROM parameters (a 1000-body model's), cma's ask and tell run in a thread of
    their own so that Ctrl-C is acted on during them: here from the forearm's few, the same run."""
    from fdbench.optimizers import cmaes

    spec = optimize_spec("cs", "cmaes", False, seed=2, budget=60)
    here = run(spec)
    real, calls = cmaes._interruptible, []

    def counted(call, *args):
        calls.append(call)
        return real(call, *args)

    monkeypatch.setattr(cmaes, "IN_THREAD_FROM", 0)
    monkeypatch.setattr(cmaes, "_interruptible", counted)
    apart = run(spec)
    assert len(calls) > 10  # the constructor, then stop, ask and tell every generation
    assert np.array_equal(apart.history, here.history) and np.array_equal(apart.params, here.params)
    for name in ("rmse_rot_deg", "rmse_torque_nm", "best_objective", "evaluations", "stop_reason"):
        assert apart.record[name] == here.record[name]


def test_bad_thread_count_is_a_one_line_error():
    result = CliRunner().invoke(app, ["optimize", "--opt", "cmaes", "--threads", "0"])
    assert result.exit_code == 2
    assert result.output.strip().startswith("fdbench: error: --threads must be an integer")
