"""Checks shared by the population tests of the forearm and of the arm."""

import numpy as np
import pytest

from fdbench.population import set_threads, threads


@pytest.fixture(autouse=True)
def restore_threads():
    """The thread count of population evaluation as it was before the test."""
    before = threads()
    yield
    set_threads(before)


def assert_population_equals_one_by_one(problem, X) -> None:
    """objectives_scaled of the population X (lam, n_params), in any size and order, equals
    objective_scaled of its rows one by one, to the last bit, on 1, 2 and 3 threads."""
    one_by_one = np.array([problem.objective_scaled(x) for x in X])
    for count in (1, 2, 3):
        set_threads(count)
        assert np.array_equal(problem.objectives_scaled(X), one_by_one)
        # any size and order of population: each candidate's number is its own
        assert np.array_equal(problem.objectives_scaled(X[::-1])[::-1], one_by_one)
        assert np.array_equal(problem.objectives_scaled(X[3:5]), one_by_one[3:5])


def assert_objectives_are(problem, X, eq18) -> None:
    """objectives_scaled of the population X (lam, n_params) equals, within 1e-12 relative,
    eq18(p) of each row's parameters p = x * scale, eq. 18 computed independently by the test."""
    values = problem.objectives_scaled(X)
    for x, value in zip(X, values):
        assert value == pytest.approx(eq18(x * problem.scale), rel=1e-12, abs=1e-12)


def assert_one_step_calls_change_nothing(problem, X, monkeypatch) -> None:
    """objectives_scaled of X evaluated in kernel calls of one step each (every candidate's
    simulation resumed from its last state at every step, as after Ctrl-C could have struck) equals
    it evaluated in one call, to the last bit, on 1, 2 and 3 threads."""
    from fdbench.multibody import engine

    set_threads(1)
    monkeypatch.setattr(engine, "FIRST_CHUNK_VALUES", 2**62)  # the whole population in one call
    whole = problem.objectives_scaled(X)
    budgets, kernel = [], problem._population.kernel

    def counted(*args):
        budgets.append(args[-1])
        return kernel(*args)

    monkeypatch.setattr(problem._population, "kernel", counted)
    monkeypatch.setattr(engine, "FIRST_CHUNK_VALUES", 1)
    monkeypatch.setattr(engine, "CHUNK_S", 0.0)
    for count in (1, 2, 3):
        set_threads(count)
        assert np.array_equal(problem.objectives_scaled(X), whole)
    assert set(budgets) == {1} and len(budgets) >= 3 * problem._n_steps
