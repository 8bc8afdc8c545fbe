"""Shooting optimisation on the two-segment arm: one parameter block per joint, eq. 18 over both
joints, the registered optimisers unchanged, the budget kept."""

from __future__ import annotations

import numpy as np
import pytest

from fdbench.models import arm2_sim as sim
from fdbench.models.arm2 import Arm2
from fdbench.models.arm2_problem import ArmTrackingProblem, optimize


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
    direct = sim.simulate(sim.feedforward(Arm2(), "reach"), Arm2(), "reach")
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
