"""Torque parameterisations (paper section 4.1, eq. 20, Figures 3-4), checked against closed forms,
polynomials a not-a-knot spline must reproduce, the inverse-dynamics torque and the counts of
parameters the paper gives (never against the code's own output)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import forearm_closed_form as cf
from fdbench.multibody.motions import desired_motion, sample_times
from fdbench.torques import TORQUES, make_torque
from fdbench.torques.ann import AnnTorque, select_hidden
from fdbench.torques.cs import CubicSplineTorque
from fdbench.torques.pf import GaussianSumTorque

# the torques registered by the package itself (tests may register more, temporarily)
BUILTIN = ("ann", "cs", "pf")
# every registered torque with a few option sets
VARIANTS = [(name, {}) for name in sorted(TORQUES)] + [
    ("ann", {"hidden": 1}), ("ann", {"hidden": 6}),
    ("cs", {"knots": 4}), ("cs", {"knots": 21}),
    ("pf", {"terms": 1}), ("pf", {"terms": 7}),
]
DENSE = np.linspace(0.0, 1.0, 2001)  # the half-step grid of the 1 ms RK4


def elbow_torque(t):
    """The forearm's inverse-dynamics torque (N m) on eq. 5's paper motion at times t (s), by the closed form."""
    theta, _, dw = desired_motion(t, "paper")
    return cf.elbow_torque(theta, dw)


@pytest.fixture(scope="module")
def inv():
    """The target torques of an optimisation: the forearm's elbow torque on the 1001 samples."""
    return SimpleNamespace(t=sample_times(), torque=elbow_torque(sample_times()))


def relative_rmse(a, b):
    """RMSE of a - b over the range of b."""
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.ptp(b))


# ----------------------------------------------------------------------------- the registry


def test_builtin_torques_registered():
    for name in BUILTIN:
        assert name in TORQUES
    assert TORQUES["ann"] is AnnTorque
    assert TORQUES["cs"] is CubicSplineTorque
    assert TORQUES["pf"] is GaussianSumTorque


def test_unknown_torque_lists_valid_names():
    with pytest.raises(ValueError) as info:
        make_torque("spline")
    for name in BUILTIN:
        assert name in str(info.value)


# ----------------------------------------------------------------------------- cubic spline


def cubic(t):
    return 2.0 - 3.0 * t + 5.0 * t**2 - 4.0 * t**3


@pytest.mark.parametrize("knots", [4, 5, 11, 17])
def test_cs_reproduces_a_cubic_exactly(knots):
    """A not-a-knot spline through the values of a cubic at its knots is that cubic (a natural
    spline would not be: this cubic has non-zero second derivatives at both ends)."""
    torque = make_torque("cs", knots=knots)
    t_knots = np.linspace(0.0, 1.0, knots)  # 'equally spaced instants of [0, 1] s'
    p = cubic(t_knots)
    t = np.concatenate([DENSE, np.random.default_rng(1).uniform(0, 1, 200)])
    np.testing.assert_allclose(torque.evaluate(p, t), cubic(t), rtol=0, atol=1e-12)
    np.testing.assert_allclose(torque.on_grid(t)(p), cubic(t), rtol=0, atol=1e-12)


@settings(max_examples=30)
@given(knots=st.integers(4, 25), seed=st.integers(0, 2**32 - 1))
def test_cs_passes_through_its_knot_values(knots, seed):
    torque = make_torque("cs", knots=knots)
    p = np.random.default_rng(seed).uniform(-20, 20, knots)
    t_knots = np.linspace(0.0, 1.0, knots)
    np.testing.assert_allclose(torque.evaluate(p, t_knots), p, rtol=0, atol=1e-10)


def test_cs_is_linear_in_its_knot_values():
    torque = make_torque("cs")
    rng = np.random.default_rng(2)
    p, q = rng.normal(size=(2, 11))
    np.testing.assert_allclose(torque.evaluate(2 * p - 3 * q, DENSE),
                               2 * torque.evaluate(p, DENSE) - 3 * torque.evaluate(q, DENSE), atol=1e-11)


# ----------------------------------------------------------------------------- on_grid = evaluate


@pytest.mark.parametrize("feedforward", [False, True])
@pytest.mark.parametrize(("name", "options"), VARIANTS, ids=lambda v: str(v))
@settings(max_examples=20)
@given(data=st.data())
def test_on_grid_equals_evaluate(name, options, feedforward, data, inv):
    torque = make_torque(name, **options)
    if feedforward or name != "pf":  # pf's least-squares pre-fit is slow and not what is tested
        torque.prepare(inv.t, inv.torque, feedforward)
    values = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)
    p = np.array(data.draw(st.lists(values, min_size=torque.n_params, max_size=torque.n_params)))
    extra = np.array(data.draw(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=30)))
    for t in (DENSE, np.sort(extra)):
        fast = torque.on_grid(t)
        expected = torque.evaluate(p, t)
        assert np.shape(fast(p)) == t.shape
        np.testing.assert_allclose(fast(p), expected, rtol=1e-10, atol=1e-10)
        # the evaluator is reusable: a second parameter vector on the same grid
        np.testing.assert_allclose(fast(0.5 * p), torque.evaluate(0.5 * p, t), rtol=1e-10, atol=1e-10)


# ----------------------------------------------------------------------------- on_grid_batch = on_grid, row by row


@pytest.mark.parametrize("feedforward", [False, True])
@pytest.mark.parametrize(("name", "options"), VARIANTS, ids=lambda v: str(v))
@settings(max_examples=15)
@given(data=st.data())
def test_population_torques_equal_one_candidate_exactly(name, options, feedforward, data, inv):
    """Row c of a population's torques is that candidate's torque on its own, to the last bit,
    whatever the population's size and order, huge and non-finite parameters included."""
    torque = make_torque(name, **options)
    if feedforward or name != "pf":  # pf's least-squares pre-fit is slow and not what is tested
        torque.prepare(inv.t, inv.torque, feedforward)
    values = st.one_of(st.floats(-3.0, 3.0), st.floats(allow_nan=True, allow_infinity=True))
    lam = data.draw(st.integers(1, 9))
    P = np.array(data.draw(st.lists(st.lists(values, min_size=torque.n_params, max_size=torque.n_params),
                                    min_size=lam, max_size=lam)))
    t = DENSE if data.draw(st.booleans()) else np.sort(data.draw(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=30)))
    batch, single = torque.on_grid_batch(t), torque.on_grid(t)
    with np.errstate(all="ignore"):
        together = batch(P)
        reversed_ = batch(P[::-1])[::-1]
        alone = np.array([single(p) for p in P])
    assert together.shape == (lam, len(t))
    np.testing.assert_array_equal(together, alone)  # NaN where NaN, every other entry equal
    np.testing.assert_array_equal(reversed_, alone)


def test_default_population_evaluator_runs_evaluate_row_by_row():
    """A parameterisation that defines only ``evaluate`` gets a population evaluator for free."""
    from fdbench.torques.base import TorqueParameterisation

    class Ramp(TorqueParameterisation):
        n_params = 2

        def prepare(self, t, target, feedforward):
            return np.zeros(2)

        def evaluate(self, p, t):
            return p[0] + p[1] * np.asarray(t)

    t = np.linspace(0.0, 1.0, 5)
    P = np.array([[1.0, 2.0], [-3.0, 0.5]])
    np.testing.assert_array_equal(Ramp().on_grid_batch(t)(P), [1.0 + 2.0 * t, -3.0 + 0.5 * t])
    np.testing.assert_array_equal(Ramp().on_grid(t)(P[1]), -3.0 + 0.5 * t)


# ----------------------------------------------------------------------------- ANN closed form


def ann_closed_form(p, t, n_h, offset, span):
    """offset + span (sum_j v_j tanh(w_j x + b_j) + c), x = 2 t - 1, neuron by neuron;
    p = [w_1..w_n, b_1..b_n, v_1..v_n, c] (Figure 3, 3 n_h + 1 parameters)."""
    x = 2 * t - 1
    total = np.full_like(t, p[3 * n_h])
    for j in range(n_h):
        w, b, v = p[j], p[n_h + j], p[2 * n_h + j]
        total = total + v * np.tanh(w * x + b)
    return offset + span * total


@pytest.mark.parametrize("hidden", [1, 3, 5])
def test_ann_equals_closed_form(hidden):
    t = np.linspace(0.0, 1.0, 101)
    target = 10.0 * t - 4.0  # min -4, max 6: mapminmax offset 1, half-range 5
    torque = make_torque("ann", hidden=hidden)
    rng = np.random.default_rng(hidden)
    p0 = torque.prepare(t, target, feedforward=False)
    assert p0.shape == (3 * hidden + 1,)
    for _ in range(5):
        p = rng.normal(0, 2, 3 * hidden + 1)
        np.testing.assert_allclose(torque.evaluate(p, DENSE), ann_closed_form(p, DENSE, hidden, 1.0, 5.0),
                                   rtol=1e-12, atol=1e-12)
    # with feedforward the network is an additional torque: no offset, the same output scaling
    torque.prepare(t, target, feedforward=True)
    p = rng.normal(0, 2, 3 * hidden + 1)
    np.testing.assert_allclose(torque.evaluate(p, DENSE), ann_closed_form(p, DENSE, hidden, 0.0, 5.0),
                               rtol=1e-12, atol=1e-12)


def test_ann_pretraining_fits_inverse_dynamics(inv):
    """The paper's 4 hidden neurons fit the inverse-dynamics torque (the initial guess)."""
    torque = make_torque("ann", hidden=4)
    p0 = torque.prepare(inv.t, inv.torque, feedforward=False)
    fit = torque.evaluate(p0, inv.t)
    assert relative_rmse(fit, inv.torque) < 2e-3  # well below 1 % of the torque range
    assert np.max(np.abs(fit - inv.torque)) < 0.01 * np.ptp(inv.torque)
    # the fit also holds between the samples it was trained on
    np.testing.assert_allclose(torque.evaluate(p0, DENSE), elbow_torque(DENSE), atol=0.01 * np.ptp(inv.torque))


# ----------------------------------------------------------------------------- initial guesses


@pytest.mark.parametrize("name", BUILTIN)
def test_initial_guess_with_feedforward_is_zero_torque(name, inv):
    torque = make_torque(name)
    p0 = torque.prepare(inv.t, inv.torque, feedforward=True)
    assert p0.shape == (torque.n_params,)
    assert np.all(np.isfinite(p0))
    np.testing.assert_allclose(torque.evaluate(p0, DENSE), 0.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(torque.on_grid(DENSE)(p0), 0.0, rtol=0, atol=1e-12)


def test_initial_guess_without_feedforward_cs_interpolates_inverse_dynamics(inv):
    torque = make_torque("cs")
    p0 = torque.prepare(inv.t, inv.torque, feedforward=False)
    t_knots = np.linspace(0.0, 1.0, 11)  # every 0.1 s (paper, section 4.1)
    np.testing.assert_allclose(p0, elbow_torque(t_knots), rtol=1e-12)
    assert relative_rmse(torque.evaluate(p0, DENSE), elbow_torque(DENSE)) < 0.01


@pytest.mark.parametrize("name", ["ann", "cs"])
def test_initial_guess_without_feedforward_approximates_inverse_dynamics(name, inv):
    torque = make_torque(name)
    p0 = torque.prepare(inv.t, inv.torque, feedforward=False)
    assert p0.shape == (torque.n_params,)
    assert relative_rmse(torque.evaluate(p0, inv.t), inv.torque) < 0.01


# ----------------------------------------------------------------------------- parameter counts


@pytest.mark.parametrize("n", [1, 2, 4, 9])
def test_n_params(n, inv):
    counts = {"ann": ("hidden", 3 * n + 1), "pf": ("terms", 3 * n)}
    for name, (option, expected) in counts.items():
        torque = make_torque(name, **{option: n})
        assert torque.n_params == expected
        assert np.asarray(torque.scale()).shape == (expected,)
    knots = n + 3  # at least 4
    assert make_torque("cs", knots=knots).n_params == knots
    # the n_params parameters are all used: each one moves the torque
    for name, option, value in (("ann", "hidden", n), ("cs", "knots", knots), ("pf", "terms", n)):
        torque = make_torque(name, **{option: value})
        torque.prepare(inv.t, inv.torque, feedforward=True)
        p = np.random.default_rng(n).uniform(0.5, 1.5, torque.n_params)
        base = torque.evaluate(p, DENSE)
        for i in range(torque.n_params):
            q = p.copy()
            q[i] += 0.1
            assert np.max(np.abs(torque.evaluate(q, DENSE) - base)) > 1e-9, (name, i)


def test_paper_defaults():
    """4 hidden neurons (13 parameters), 11 spline points, 4 Gaussian terms (12 parameters)."""
    assert make_torque("ann").n_params == 13
    assert make_torque("cs").n_params == 11
    assert make_torque("pf").n_params == 12


@pytest.mark.parametrize(("name", "options", "option"), [
    ("ann", {"hidden": 0}, "--hidden"),
    ("ann", {"hidden": -3}, "--hidden"),
    ("ann", {"hidden": 2.5}, "--hidden"),
    ("cs", {"knots": 3}, "--knots"),
    ("cs", {"knots": 0}, "--knots"),
    ("cs", {"knots": -11}, "--knots"),
    ("pf", {"terms": 0}, "--terms"),
    ("pf", {"terms": -1}, "--terms"),
])
def test_invalid_counts_raise(name, options, option):
    with pytest.raises(ValueError) as info:
        make_torque(name, **options)
    message = str(info.value)
    assert option in message and "\n" not in message
    with pytest.raises(ValueError):
        TORQUES[name](**options)


# ----------------------------------------------------------------------------- select_hidden


def check_selection(chosen, tried, tolerance, max_hidden, t, target):
    counts = [n for n, _ in tried]
    assert counts == list(range(1, chosen + 1))  # tried in order, stopping at the chosen one
    for n, error in tried[:-1]:
        assert error > tolerance, f"{n} neurons already fit ({error}) but {chosen} were chosen"
    assert tried[-1][1] <= tolerance or chosen == max_hidden
    # the reported errors are the fits' RMSE over the torque range
    for n, error in tried:
        torque = make_torque("ann", hidden=n)
        p0 = torque.prepare(t, target, feedforward=False)
        assert relative_rmse(torque.evaluate(p0, t), target) == pytest.approx(error, rel=1e-6)


def test_select_hidden_default(inv):
    from fdbench.torques.ann import AUTO_MAX_HIDDEN, AUTO_TOLERANCE

    chosen, tried = select_hidden(inv.t, inv.torque)
    assert 1 <= chosen <= AUTO_MAX_HIDDEN
    check_selection(chosen, tried, AUTO_TOLERANCE, AUTO_MAX_HIDDEN, inv.t, inv.torque)


@pytest.mark.parametrize("tolerance", [0.05, 0.01, 5e-3, 1e-3])
def test_select_hidden_smallest_count_meeting_tolerance(tolerance, inv):
    chosen, tried = select_hidden(inv.t, inv.torque, max_hidden=6, tolerance=tolerance)
    check_selection(chosen, tried, tolerance, 6, inv.t, inv.torque)


def test_select_hidden_tighter_tolerance_never_fewer_neurons(inv):
    chosen = [select_hidden(inv.t, inv.torque, max_hidden=6, tolerance=tol)[0] for tol in (0.05, 0.01, 5e-3, 1e-3)]
    assert chosen == sorted(chosen)


def test_select_hidden_unreachable_tolerance_gives_max(inv):
    chosen, tried = select_hidden(inv.t, inv.torque, max_hidden=2, tolerance=1e-12)
    assert chosen == 2
    assert [n for n, _ in tried] == [1, 2]
    assert all(error > 1e-12 for _, error in tried)
