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
