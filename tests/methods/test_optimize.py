"""Optimisers, the tracking problem (eq. 18) and the ``optimize`` command, checked with our own
counting of objective calls, convex quadratics, an independent evaluation of eq. 18, repeated runs
and the command-line contract of DESIGN.md section 5 (never against the code's own output)."""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.api import run
from fdbench.spec import optimize_spec
from helpers import forearm_closed_form as forearm
from fdbench.multibody.motions import eq5
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.optimizers import OPTIMIZERS, Optimizer, make_optimizer
from fdbench.problem import TrackingProblem
from fdbench.torques import TORQUES, TorqueParameterisation

BUILTIN_OPTIMIZERS = ("cmaes", "bfgs", "lbfgsb", "nelder-mead")
OPTIMIZER_NAMES = sorted(OPTIMIZERS)
CONTRACT_KEYS = (
    "command", "kinematics", "integrator", "torque", "optimizer", "feedforward", "seed", "budget",
    "rmse_rot_deg", "rmse_torque_nm", "runtime_s", "evaluations", "t_end", "status", "fdbench_version",
)


class Counting:
    """Wraps an objective and records every call (x, f) made through it."""

    def __init__(self, objective):
        self.objective = objective
        self.xs: list[np.ndarray] = []
        self.fs: list[float] = []

    def __call__(self, x):
        f = float(self.objective(x))
        self.xs.append(np.array(x, dtype=float, copy=True))
        self.fs.append(f)
        return f

    @property
    def calls(self) -> int:
        return len(self.fs)


def quadratic(n=10):
    """A convex quadratic with minimum 0 at c; returns (f, c)."""
    d = np.geomspace(0.5, 8.0, n)
    c = np.linspace(-2.0, 2.0, n)
    return (lambda x: float(np.sum(d * (np.asarray(x) - c) ** 2))), c


def check_result(result, counter: Counting, budget: int):
    """The budget was obeyed and the result is the best point of those evaluated."""
    assert 1 <= counter.calls <= budget
    assert result.evaluations == counter.calls
    fs = np.array([f if math.isfinite(f) else math.inf for f in counter.fs])
    best = int(np.argmin(fs))
    assert result.fun == fs[best]
    np.testing.assert_array_equal(result.x, counter.xs[best])
    # history: best-so-far objective after each evaluation
    assert len(result.history) == counter.calls
    np.testing.assert_array_equal(result.history, np.minimum.accumulate(fs))


FOREARM = Engine(find_model("forearm"))
PAPER = joint_motion("paper", find_model("forearm"))


def ForearmProblem(torque="cs", feedforward=False, penalty_weight=1.0):
    """The paper's tracking problem: the forearm on eq. 5, 11 spline knots for cs."""
    return TrackingProblem(torque, FOREARM, PAPER, feedforward, penalty_weight)


@pytest.fixture(scope="module")
def theta_desired():
    """Eq. 5's elbow angle (rad) on the 1 ms samples, shape (1001,)."""
    return eq5(np.linspace(0.0, 1.0, 1001), "paper")[0]


@pytest.fixture(scope="module")
def cs_problem():
    return ForearmProblem("cs")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


# ----------------------------------------------------------------------------- the budget


def test_builtin_optimizers_registered():
    for name in BUILTIN_OPTIMIZERS:
        assert name in OPTIMIZERS


@pytest.mark.parametrize("name", OPTIMIZER_NAMES)
@pytest.mark.parametrize("budget", [1, 2, 3, 7, 10, 11, 12, 25, 60])
def test_budget_never_exceeded_on_quadratic(name, budget):
    """n = 10: budgets up to 10 are smaller than one forward-difference gradient (n + 1 calls)."""
    f, _ = quadratic(10)
    counter = Counting(f)
    reported = []
    result = make_optimizer(name).minimize(counter, np.zeros(10), budget, seed=3,
                                           on_evaluation=lambda count, best: reported.append((count, best)))
    check_result(result, counter, budget)
    if budget <= 11:  # no optimiser can converge on 10 unknowns before it has a gradient
        assert counter.calls == budget
        assert "budget" in result.stop_reason
    # progress: one report per evaluation, with our own best-so-far
    assert [c for c, _ in reported] == list(range(1, counter.calls + 1))
    np.testing.assert_array_equal([b for _, b in reported], np.minimum.accumulate(counter.fs))


@pytest.mark.parametrize("name", OPTIMIZER_NAMES)
@pytest.mark.parametrize("budget", [1, 2, 7, 11, 15])
def test_budget_never_exceeded_on_tracking_problem(name, budget, cs_problem):
    """The real objective (11 spline knots; 11 < n + 1 = 12), scaled as the runs scale it."""
    counter = Counting(cs_problem.objective_scaled)
    result = make_optimizer(name).minimize(counter, cs_problem.x0, budget, seed=0)
    check_result(result, counter, budget)
    if budget <= 12:
        assert counter.calls == budget
    # the result's objective is that of its parameters
    assert cs_problem.objective_scaled(result.x) == result.fun


def test_gradient_methods_start_from_x0(cs_problem):
    """BFGS and L-BFGS-B evaluate x0 first: with a budget of 1 the result is x0 itself."""
    for name in ("bfgs", "lbfgsb"):
        counter = Counting(cs_problem.objective_scaled)
        result = make_optimizer(name).minimize(counter, cs_problem.x0, 1)
        np.testing.assert_array_equal(result.x, cs_problem.x0)
        assert result.fun == cs_problem.objective(cs_problem.p0)


def test_budget_below_one_rejected():
    f, _ = quadratic(3)
    for budget in (0, -1):
        with pytest.raises(ValueError):
            make_optimizer("bfgs").minimize(f, np.zeros(3), budget)


def test_optimizer_that_never_evaluates_still_reports_x0():
    class Lazy(Optimizer):
        name = "lazy"

        def run(self, f, x0, seed):
            return "did nothing"

    f, _ = quadratic(4)
    counter = Counting(f)
    result = Lazy().minimize(counter, np.ones(4), 5)
    assert counter.calls == 1
    np.testing.assert_array_equal(result.x, np.ones(4))
    assert result.fun == f(np.ones(4))


# ----------------------------------------------------------------------------- they minimise


@pytest.mark.parametrize(("name", "factor"), [("bfgs", 1e-8), ("lbfgsb", 1e-8), ("nelder-mead", 0.2), ("cmaes", 0.2)])
def test_optimizers_minimise_a_convex_quadratic(name, factor):
    f, c = quadratic(5)
    x0 = np.zeros(5)
    counter = Counting(f)
    result = make_optimizer(name).minimize(counter, x0, 200, seed=1)
    check_result(result, counter, 200)
    assert result.fun <= factor * f(x0)
    if factor < 1e-6:
        np.testing.assert_allclose(result.x, c, atol=1e-4)


# ----------------------------------------------------------------------------- seeds


def test_cmaes_same_seed_same_result_different_seed_differs():
    f, _ = quadratic(6)
    runs = {}
    for key, seed in (("a", 7), ("b", 7), ("c", 8)):
        counter = Counting(f)
        result = make_optimizer("cmaes").minimize(counter, np.zeros(6), 40, seed=seed)
        runs[key] = (result, counter)
    (ra, ca), (rb, cb), (rc, cc) = runs["a"], runs["b"], runs["c"]
    np.testing.assert_array_equal(np.array(ca.xs), np.array(cb.xs))
    np.testing.assert_array_equal(ra.x, rb.x)
    assert ra.fun == rb.fun and ra.history == rb.history
    assert not np.array_equal(np.array(ca.xs), np.array(cc.xs))
    assert ra.fun != rc.fun


NUMBERS = ("rmse_rot_deg", "rmse_torque_nm", "evaluations", "best_objective", "initial_objective",
           "t_end", "status", "max_violation", "n_params", "stop_reason", "spec_hash")


@pytest.mark.parametrize(("torque", "optimizer"), [("cs", "cmaes"), ("ann", "bfgs")])
def test_full_run_same_seed_same_record(torque, optimizer):
    first = run(optimize_spec(torque, optimizer, seed=4, budget=30))
    again = run(optimize_spec(torque, optimizer, seed=4, budget=30))
    for key in NUMBERS:
        assert first.record[key] == again.record[key], key
    assert first.history == again.history
    np.testing.assert_array_equal(first.params, again.params)
    if optimizer == "cmaes":
        other = run(optimize_spec(torque, optimizer, seed=5, budget=30))
        assert other.record["spec_hash"] != first.record["spec_hash"]
        assert other.record["rmse_rot_deg"] != first.record["rmse_rot_deg"]


# ----------------------------------------------------------------------------- eq. 18 and failures


def eq18(result, theta_desired, penalty_weight):
    """RMSE of rotation (deg) over the samples reached + w (1 - t_end), computed here."""
    reached = np.isfinite(result.z[:, 0])
    error = np.degrees(result.z[reached, 0] - theta_desired[reached])
    return float(np.sqrt(np.mean(error**2))) + penalty_weight * (1.0 - result.t_end)


@pytest.mark.parametrize("penalty_weight", [1.0, 3.5])
@pytest.mark.parametrize("value", [500.0, -500.0])
def test_failing_simulation_objective(value, penalty_weight, theta_desired):
    problem = ForearmProblem("cs", penalty_weight=penalty_weight)
    p = np.full(11, value)  # a huge constant elbow torque, N m
    result = problem.simulate(p)
    assert not result.success
    assert result.status.code != "success"
    assert 0.0 <= result.t_end < 1.0
    reached = np.isfinite(result.z[:, 0])
    assert reached.sum() == round(result.t_end * 1000) + 1  # the 1 ms samples up to t_end
    expected = eq18(result, theta_desired, penalty_weight)
    objective = problem.objective(p)
    assert math.isfinite(objective)
    assert objective == pytest.approx(expected, rel=1e-12)
    assert problem.objective_of(result) == pytest.approx(expected, rel=1e-12)
    assert problem.objective_scaled(p / problem.scale) == pytest.approx(expected, rel=1e-12)
    assert objective > penalty_weight * 0.5  # the penalty term is there: it stopped early


@pytest.mark.parametrize("feedforward", [False, True])
def test_successful_simulation_objective_is_rmse(feedforward, theta_desired):
    """Reaching t = 1 s, eq. 18 is the RMSE of rotation; with feedforward and the zero initial
    guess it is that of the closed-form elbow torque of eq. 5, simulated on its own here."""
    problem = ForearmProblem("cs", feedforward=feedforward)
    result = problem.simulate(problem.p0)
    assert result.success and result.t_end == 1.0
    assert problem.objective(problem.p0) == pytest.approx(eq18(result, theta_desired, 1.0), rel=1e-12)
    if feedforward:
        alone = sim.simulate(lambda t: forearm.torque_along(*eq5(t, "paper"))[:, None], FOREARM, PAPER)
        # the closed form and the engine's inverse dynamics differ by rounding (1e-15 relative),
        # which the open-loop run amplifies to 4e-11 of its RMSE
        assert problem.objective(problem.p0) == pytest.approx(eq18(alone, theta_desired, 1.0), rel=1e-9)


@pytest.mark.parametrize("name", ["bfgs", "lbfgsb", "nelder-mead"])
def test_failing_simulations_do_not_crash_optimizer(name, cs_problem):
    x0 = np.full(11, 500.0) / cs_problem.scale
    counter = Counting(cs_problem.objective_scaled)
    result = make_optimizer(name).minimize(counter, x0, 20, seed=0)
    check_result(result, counter, 20)
    assert math.isfinite(result.fun)
    assert result.fun <= cs_problem.objective_scaled(x0)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # scipy's differences of inf values
@pytest.mark.parametrize("name", ["nelder-mead", "bfgs", "cmaes"])
def test_non_finite_objective_is_never_the_result(name):
    """A NaN objective (a failed evaluation) counts as +inf: the minimum of the quadratic, at
    x_0 = -2, lies beyond x_0 = -0.3, where the objective is NaN; the result stays outside."""
    f, _ = quadratic(3)
    counter = Counting(lambda x: math.nan if x[0] < -0.3 else f(x))
    result = make_optimizer(name).minimize(counter, np.zeros(3), 60)
    check_result(result, counter, 60)
    assert any(math.isnan(v) for v in counter.fs)  # it did step into the NaN region
    assert math.isfinite(result.fun) and result.x[0] >= -0.3
    assert result.fun < f(np.zeros(3))


# ----------------------------------------------------------------------------- new methods


class RampTorque(TorqueParameterisation):
    """torque(t) = a + b t, least-squares fitted to the target without feedforward."""

    name = "zz-test-ramp"
    summary = "test ramp a + b t"

    def __init__(self):
        self.n_params = 2

    def prepare(self, t, target, feedforward):
        if feedforward:
            return np.zeros(2)
        b, a = np.polyfit(t, target, 1)
        return np.array([a, b])

    def evaluate(self, p, t):
        return p[0] + p[1] * np.asarray(t, dtype=float)


class RandomSearch(Optimizer):
    """x0, then Gaussian steps around the best point, until the budget is spent."""

    name = "zz-test-random-search"
    summary = "test random search"
    calls = 0

    def run(self, f, x0, seed):
        rng = np.random.default_rng(seed)
        best_x, best_f = x0, f(x0)
        RandomSearch.calls += 1
        while True:
            x = best_x + 0.05 * rng.normal(size=x0.shape)
            value = f(x)
            RandomSearch.calls += 1
            if value < best_f:
                best_x, best_f = x, value


@pytest.fixture
def registered():
    TORQUES.register(RampTorque.name)(RampTorque)
    try:
        OPTIMIZERS.register(RandomSearch.name)(RandomSearch)
        try:
            RandomSearch.calls = 0
            yield RampTorque.name, RandomSearch.name
        finally:
            OPTIMIZERS.unregister(RandomSearch.name)
    finally:
        TORQUES.unregister(RampTorque.name)


def test_new_torque_and_optimizer_usable_from_cli(registered):
    torque, optimizer = registered
    listing = invoke("methods")
    assert listing.exit_code == 0
    for name, summary in ((torque, RampTorque.summary), (optimizer, RandomSearch.summary)):
        line = next(line for line in listing.stdout.splitlines() if name in line)
        assert summary in line
    result = invoke("optimize", "--torque", torque, "--opt", optimizer, "--budget", 12, "--seed", 2,
                    "--format", "json", "-q")
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["torque"] == torque and record["optimizer"] == optimizer
    assert record["n_params"] == 2
    assert record["evaluations"] == 12 == RandomSearch.calls  # random search never stops by itself
    assert record["status"] == "success"
    assert record["best_objective"] <= record["initial_objective"]  # it evaluates x0 first
    assert record["best_objective"] == pytest.approx(record["rmse_rot_deg"], rel=1e-9)


def test_unregistered_methods_are_gone():
    assert RampTorque.name not in TORQUES and RandomSearch.name not in OPTIMIZERS
    assert RampTorque.name not in invoke("methods").stdout
    result = invoke("optimize", "--torque", RampTorque.name, "--budget", 3, "-q")
    assert result.exit_code == 2


def test_registry_refuses_a_name_collision():
    with pytest.raises(ValueError):
        TORQUES.register("cs")(RampTorque)
    with pytest.raises(ValueError):
        OPTIMIZERS.register("bfgs")(RandomSearch)
    assert TORQUES["cs"].__name__ == "CubicSplineTorque"


# ----------------------------------------------------------------------------- the optimize command


def test_optimize_json_contract():
    result = invoke("optimize", "--torque", "cs", "--opt", "bfgs", "--budget", 30, "--format", "json")
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    for key in CONTRACT_KEYS:
        assert key in record, key
    assert record["command"] == "optimize"
    assert (record["torque"], record["optimizer"], record["budget"], record["seed"]) == ("cs", "bfgs", 30, 0)
    assert record["feedforward"] is False
    assert record["kinematics"] == "paper" and record["integrator"] == "rk4"
    assert 1 <= record["evaluations"] <= 30
    assert record["runtime_s"] > 0
    assert record["status"] == "success" and record["t_end"] == 1.0
    assert isinstance(record["fdbench_version"], str) and record["fdbench_version"]
    # eq. 18 for the best parameters, simulated again for the record
    assert record["best_objective"] == pytest.approx(record["rmse_rot_deg"] + (1 - record["t_end"]), rel=1e-9)
    assert record["best_objective"] <= record["initial_objective"]


def test_optimize_csv_matches_json():
    as_csv = invoke("optimize", "--torque", "cs", "--budget", 15, "--format", "csv", "-q")
    as_json = invoke("optimize", "--torque", "cs", "--budget", 15, "--format", "json", "-q")
    assert as_csv.exit_code == 0 and as_json.exit_code == 0
    rows = list(csv.DictReader(io.StringIO(as_csv.stdout)))
    assert len(rows) == 1
    row, record = rows[0], json.loads(as_json.stdout)
    for key in CONTRACT_KEYS:
        assert key in row, key
    assert int(row["evaluations"]) == record["evaluations"] <= 15
    assert float(row["rmse_rot_deg"]) == pytest.approx(record["rmse_rot_deg"], rel=1e-12)
    assert row["status"] == record["status"] and row["torque"] == "cs"


def test_optimize_history_file(tmp_path):
    path = tmp_path / "history.csv"
    result = invoke("optimize", "--torque", "cs", "--opt", "nelder-mead", "--budget", 25, "--history", path,
                    "--format", "json", "-q")
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    rows = list(csv.DictReader(path.open()))
    assert len(rows) == record["evaluations"] == 25
    assert [int(r["evaluation"]) for r in rows] == list(range(1, 26))
    best = np.array([float(r["best_objective"]) for r in rows])
    assert np.all(np.diff(best) <= 0)
    assert best[-1] == pytest.approx(record["best_objective"], rel=1e-12)
    assert best[0] == pytest.approx(record["initial_objective"], rel=1e-12)  # nelder-mead starts at x0


@pytest.mark.parametrize(("torque", "feedforward"), [("cs", "--no-feedforward"), ("ann", "--feedforward"), ("pf", "--feedforward")])
def test_saved_params_reproduce_the_run(torque, feedforward, tmp_path):
    path = tmp_path / "params.json"
    optimized = invoke("optimize", "--torque", torque, feedforward, "--budget", 20, "--save-params", path,
                       "--format", "json", "-q")
    assert optimized.exit_code == 0, optimized.stderr
    simulated = invoke("simulate", "--params", path, "--format", "json", "-q")
    assert simulated.exit_code == 0, simulated.stderr
    a, b = json.loads(optimized.stdout), json.loads(simulated.stdout)
    assert b["rmse_rot_deg"] == pytest.approx(a["rmse_rot_deg"], rel=1e-8)
    assert b["rmse_torque_nm"] == pytest.approx(a["rmse_torque_nm"], rel=1e-6, abs=1e-10)
    assert b["t_end"] == a["t_end"] and b["status"] == a["status"]


# ----------------------------------------------------------------------------- bad input


def check_one_line_error(result, *fragments):
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("fdbench: error:")
    assert "Traceback" not in result.stderr
    assert result.stdout == ""
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def test_unknown_torque_lists_valid_names():
    result = invoke("optimize", "--torque", "spline", "--budget", 5)
    check_one_line_error(result, "spline", *("ann", "cs", "pf"))


def test_unknown_optimizer_lists_valid_names():
    result = invoke("optimize", "--opt", "newton", "--budget", 5)
    check_one_line_error(result, "newton", *BUILTIN_OPTIMIZERS)


@pytest.mark.parametrize("args", [
    ["--budget", "0"],
    ["--budget", "-4"],
    ["--hidden", "0"],
    ["--torque", "ann", "--hidden", "0"],
    ["--torque", "ann", "--hidden", "abc"],
    ["--knots", "3"],
    ["--torque", "pf", "--terms", "0"],
    ["--opt", "cmaes", "--sigma0", "0"],
    ["--opt", "cmaes", "--sigma0", "-1"],
    ["--opt", "cmaes", "--sigma0", "nan"],
    ["--sigma0", "nan"],
    ["--opt", "cmaes", "--popsize", "1"],
    ["--seed", "-1"],
    ["--budget", "abc"],
    ["--format", "yaml"],
], ids=" ".join)
def test_bad_input_one_line_exit_2(args):
    option = next(a for a in args if a.startswith("--") and a not in ("--torque", "--opt"))
    if option == "--torque":  # pragma: no cover - every case names the bad option
        option = args[0]
    result = invoke("optimize", *(["--budget", "5"] if "--budget" not in args else []), *args)
    check_one_line_error(result, option)


@pytest.mark.parametrize("args", [
    ["--torque", "cs", "--terms", "0"],
    ["--torque", "ann", "--knots", "3"],
    ["--opt", "bfgs", "--sigma0", "0"],
    ["--opt", "bfgs", "--popsize", "1"],
], ids=" ".join)
def test_bad_option_rejected_even_when_unused(args):
    result = invoke("optimize", "--budget", "2", "-q", *args)
    check_one_line_error(result, args[-2])
