"""Shooting optimisation on the engine's models (the arm of the library): one parameter block per
joint, eq. 18 over every joint, the registered optimisers unchanged, the budget kept, and population
evaluation (one compiled call for many candidates, the same numbers as one by one, whatever the
thread count)."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from fdbench.api import run
from fdbench.spec import optimize_spec
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.problem import TrackingProblem
from fdbench.optimizers import make_optimizer
from fdbench.population import set_threads
from helpers.population_checks import (assert_objectives_are, assert_population_equals_one_by_one,  # noqa: F401
                               restore_threads)

ARM = Engine(find_model("arm2"))
REACH = joint_motion("reach", find_model("arm2"))


def ArmTrackingProblem(torque, feedforward=False, penalty_weight=1.0, **options):
    """The arm's tracking problem of its reach."""
    return TrackingProblem(torque, ARM, REACH, feedforward, penalty_weight, **options)


def optimize(problem, optimizer, budget, seed):
    found = make_optimizer(optimizer).minimize(problem.objective_scaled, problem.x0, budget, seed,
                                               batch=problem.objectives_scaled if problem.batched else None)
    p = np.asarray(found.x) * problem.scale
    return p, found, problem.simulate(p), None


@pytest.fixture(scope="module")
def cs_ff():
    return ArmTrackingProblem("cs", feedforward=True, knots=8)


def test_one_block_per_joint(cs_ff):
    assert cs_ff.n_params == 16 and list(cs_ff.blocks) == [0, 8, 16]
    p = np.zeros(16)
    p[3] = 1.0  # one shoulder knot
    change = cs_ff.torques_on_grid(p) - cs_ff.torques_on_grid(np.zeros(16))
    assert np.abs(change[:, 0]).max() > 0.9 and np.all(change[:, 1] == 0.0)


def test_the_initial_guess_with_feedforward_is_the_inverse_dynamics_torque(cs_ff):
    assert np.all(cs_ff.p0 == 0.0)
    direct = sim.simulate(sim.feedforward(ARM, REACH), ARM, REACH)
    expected, _ = sim.rmse_deg(direct, cs_ff.inverse.angles)
    assert cs_ff.objective(cs_ff.p0) == pytest.approx(expected, rel=1e-9)


def test_eq18_penalises_the_part_not_reached():
    problem = ArmTrackingProblem("pf", feedforward=True, terms=2, penalty_weight=2.0)
    p = problem.p0.copy()
    p[0] = 50.0  # a 50 N m bump on the shoulder throws the arm over
    result = problem.simulate(p)
    assert not result.success
    rmse, _ = sim.rmse_deg(result, problem.inverse.angles)
    assert problem.objective(p) == pytest.approx(rmse + 2.0 * (1 - result.t_end), rel=1e-12)


@pytest.mark.parametrize("optimizer", ["cmaes", "bfgs"])
def test_optimisers_keep_the_budget_and_return_the_best_point(cs_ff, optimizer):
    p, found, result, _ = optimize(cs_ff, optimizer, budget=30, seed=3)
    assert found.evaluations == 30 and len(found.history) == 30
    assert found.fun == min(found.history) == pytest.approx(cs_ff.objective(p), rel=1e-12)
    assert cs_ff.objective_of(result) == pytest.approx(found.fun, rel=1e-12)


def test_bfgs_improves_on_the_feedforward():
    problem = ArmTrackingProblem("pf", feedforward=True, terms=4)
    _, found, result, _ = optimize(problem, "bfgs", budget=120, seed=0)
    assert result.success and found.fun < 0.8 * problem.objective(problem.p0)


CELLS = [("cs", False), ("cs", True), ("pf", False), ("pf", True), ("ann", False), ("ann", True)]
SMALL = {"cs": {"knots": 11}, "pf": {"terms": 2}, "ann": {"hidden": 3}}


@pytest.fixture(scope="module")
def problems():
    """One arm tracking problem per cell, made once, with few parameters (cs: enough knots for the
    start's open-loop run to reach the end)."""
    return {cell: ArmTrackingProblem(cell[0], feedforward=cell[1], **SMALL[cell[0]]) for cell in CELLS}


def population(problem, seed=3):
    """Scaled candidates: the start, tiny steps from it (full runs, mostly) and large ones
    (simulations that fail part-way), shape (9, n_params)."""
    rng = np.random.default_rng(seed)
    return problem.x0 + np.concatenate([np.zeros((1, problem.n_params)),
                                        1e-5 * rng.standard_normal((4, problem.n_params)),
                                        0.5 * rng.standard_normal((4, problem.n_params))])


def eq18(problem, p) -> float:
    """Eq. 18 written out here from the candidate's Simulation: RMSE (deg) over both joints and
    the samples reached, plus the penalty of the fraction of the motion not reached."""
    result = problem.simulate(p)
    rmse, _ = sim.rmse_deg(result, problem.inverse.angles)
    rmse = rmse if np.isfinite(rmse) else 0.0
    return rmse + problem.penalty_weight * (1.0 - result.t_end / problem.duration)


def test_the_arm_problem_is_batched(problems):
    assert all(problem.batched for problem in problems.values())


@pytest.mark.parametrize("cell", CELLS, ids=str)
def test_population_equals_one_by_one_exactly(cell, problems):
    problem = problems[cell]
    X = population(problem)
    t_end = [problem.simulate(x * problem.scale).t_end for x in X]
    assert min(t_end) < max(t_end)  # simulations ending at different steps
    assert_population_equals_one_by_one(problem, X)


@pytest.mark.parametrize("cell", CELLS, ids=str)
def test_population_objectives_are_eq18_of_each_simulation(cell, problems):
    problem = problems[cell]
    assert_objectives_are(problem, population(problem, seed=5), lambda p: eq18(problem, p))


def test_the_penalty_weight_is_the_problems():
    problem = ArmTrackingProblem("pf", feedforward=True, terms=2, penalty_weight=3.0)
    p = problem.p0.copy()
    p[0] = 50.0  # a 50 N m bump on the shoulder throws the arm over
    assert not problem.simulate(p).success
    assert problem.objective(p) == pytest.approx(eq18(problem, p), rel=1e-12)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.integers(1, 7), spread=st.sampled_from([1e-6, 1e-3, 0.3]),
       cell=st.sampled_from(CELLS), count=st.integers(1, 3))
def test_any_population_equals_its_candidates(problems, seed, size, spread, cell, count):
    problem = problems[cell]
    X = problem.x0 + spread * np.random.default_rng(seed).standard_normal((size, problem.n_params))
    set_threads(count)
    together = problem.objectives_scaled(X)
    set_threads(1)
    assert np.array_equal(together, [problem.objective_scaled(x) for x in X])


@pytest.mark.parametrize("cell", [("cs", True), ("ann", False)], ids=str)
def test_population_torques_equal_each_candidates_exactly(cell, problems):
    problem = problems[cell]
    P = population(problem) * problem.scale
    together = problem.torques_on_grid_batch(P)
    assert together.shape == (len(P), len(problem._half), 2)
    for c, p in enumerate(P):
        assert np.array_equal(together[c], problem.torques_on_grid(p))


def test_a_motion_off_the_grid_is_evaluated_one_by_one():
    problem = ArmTrackingProblem("pf", feedforward=True, terms=2, dt=4e-3)  # 250 steps, 1001 samples
    assert not problem.batched
    X = problem.x0 + 1e-5 * np.random.default_rng(1).standard_normal((3, problem.n_params))
    assert np.array_equal(problem.objectives_scaled(X), [problem.objective_scaled(x) for x in X])
    assert problem.objective_scaled(X[0]) == pytest.approx(eq18(problem, X[0] * problem.scale), rel=1e-12)


def test_cmaes_with_population_evaluation_takes_the_same_path(problems):
    problem = problems[("cs", True)]
    plain = make_optimizer("cmaes").minimize(lambda x: eq18(problem, x * problem.scale), problem.x0, 40, seed=4)
    set_threads(2)
    batched = make_optimizer("cmaes").minimize(problem.objective_scaled, problem.x0, 40, seed=4,
                                               batch=problem.objectives_scaled)
    assert batched.evaluations == plain.evaluations == 40
    np.testing.assert_allclose(batched.history, plain.history, rtol=1e-12)


def test_thread_count_does_not_change_an_arm_run():
    spec = optimize_spec("cs", "cmaes", True, seed=2, budget=30, torque_options={"knots": 6}, model_name="arm2")
    records = []
    for count in (1, 2):
        set_threads(count)
        records.append(run(spec).record)
    for name in ("rmse_rot_deg", "rmse_torque_nm", "best_objective", "evaluations", "t_end", "initial_objective"):
        assert records[0][name] == records[1][name]


def test_an_enormous_torque_ends_the_simulation_instead_of_raising():
    """A 1e15 N m shoulder offset once lost a pivot of the point system to cancellation (a
    division by an exact zero); the run now stops at the start and pays the whole penalty."""
    problem = ArmTrackingProblem("pf", feedforward=False)
    p = problem.p0.copy()
    p[0] += 1e15
    result = problem.simulate(p)
    assert not result.success and result.t_end == 0.0
    assert problem.objective(p) == 1.0
