"""``fdbench optimize --actuation muscles``: the excitation problem (``fdbench.excitation_problem``)
from the command line on the arm26 of tests/methods/test_excitation_problem.py (rigid tendons, a
50-ms motion, a spline of 4 knots per muscle: the same compiled kernels), CMA-ES and BFGS with exact
gradients on budgets of 8; the record's muscle fields against the saved trajectory (effort, mean
activations, the muscles' generalised forces from their forces and moment arms, eq. 18 plus the
effort from the trajectory); bad input one line and exit 2; the hashes of existing runs unchanged."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.excitation_problem import DEFAULT_EFFORT_WEIGHT
from fdbench.multibody.model_files import to_toml
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.spec import RunSpec, optimize_spec

from helpers.cli_checks import assert_one_line_error
from helpers.models import short_arm26

runner = CliRunner()
WEIGHT = 2.0  # deg per excitation^2 s, as tests/methods/test_excitation_problem.py's


def invoke(args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """(the model, its file): arm26 with rigid tendons and one motion, 'short', 50 ms."""
    model = short_arm26()
    path = tmp_path_factory.mktemp("arm") / "arm26_rigid.toml"
    path.write_text(to_toml(model))
    return model, path


@pytest.fixture(scope="module")
def runs(arm, tmp_path_factory):
    """{optimiser: (record, trajectory {column: array})} of a CMA-ES and a BFGS (exact gradients) run."""
    folder, done = tmp_path_factory.mktemp("runs"), {}
    for name, extra in (("cmaes", ["--opt", "cmaes[popsize=4]"]), ("bfgs", ["--opt", "bfgs", "--gradient", "exact"])):
        trajectory = folder / f"{name}.csv"
        result = invoke(["optimize", "--model", arm[1], "--actuation", "muscles", "--effort-weight", WEIGHT,
                         "--knots", 4, "--budget", 8, "-f", "json", "-q", "--save-trajectory", trajectory, *extra])
        assert result.exit_code == 0, result.stderr
        with open(trajectory, newline="") as handle:
            rows = list(csv.DictReader(handle))
        done[name] = json.loads(result.stdout), {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    return done


@pytest.mark.parametrize("name", ["cmaes", "bfgs"])
def test_the_record_s_muscle_fields_are_those_of_the_saved_trajectory(arm, runs, name):
    model, _ = arm
    record, columns = runs[name]
    muscles = [m.name for m in model.muscles]
    assert record["status"] == "success" and record["actuation"] == "muscles" and record["evaluations"] <= 8
    assert record["effort_weight"] == WEIGHT and record["reserve_rms_nm"] == 0.0
    assert record["n_params"] == 4 * len(muscles)
    activation = np.column_stack([columns[f"{m}_activation"] for m in muscles])
    excitation = np.column_stack([columns[f"{m}_excitation"] for m in muscles])
    assert np.all((activation >= 0) & (activation <= 1)) and np.all((excitation > 0) & (excitation < 1))
    assert record["effort"] == pytest.approx(np.mean(np.sum(activation**2, axis=1)), rel=1e-12)
    for i, m in enumerate(muscles):
        assert record[f"{m}_activation_mean"] == pytest.approx(np.mean(activation[:, i]), rel=1e-12)
    # the joints' torques are the muscles' generalised forces, moment arm times force along the path
    joints = model.coordinates
    angles = np.radians(np.column_stack([columns[j] for j in joints]))
    force = np.column_stack([columns[f"{m}_force"] for m in muscles])
    _, arms = muscle_geometry(model, angles)
    generalised = np.einsum("nmj,nm->nj", arms, force)
    applied = np.column_stack([columns[f"{j}_torque"] for j in joints])
    np.testing.assert_allclose(applied, generalised, rtol=1e-9, atol=1e-9)
    inverse = np.column_stack([columns[f"{j}_torque_inverse"] for j in joints])
    assert record["rmse_torque_nm"] == pytest.approx(np.sqrt(np.mean((generalised - inverse) ** 2)), rel=1e-9)
    # eq. 18 (RMSE of the angles, no penalty: the run succeeds) plus w_e times the effort integral,
    # here by the trapezoidal rule on the motion's samples (the problem's on RK4's half steps)
    desired = np.column_stack([columns[f"{j}_desired"] for j in joints])
    rmse = np.sqrt(np.mean((np.degrees(angles) - desired) ** 2))
    assert record["rmse_rot_deg"] == pytest.approx(rmse, rel=1e-9)
    squared = np.sum(excitation**2, axis=1)
    integral = float(np.sum(np.diff(columns["t"]) * (squared[1:] + squared[:-1]) / 2))
    assert record["best_objective"] == pytest.approx(rmse + WEIGHT * integral, rel=1e-4)


def test_bfgs_with_exact_gradients_lowers_the_objective_from_its_start(runs):
    record, _ = runs["bfgs"]
    assert record["gradient"] == "exact" and record["best_objective"] < record["initial_objective"]
    assert math.isfinite(runs["cmaes"][0]["best_objective"])


@pytest.mark.parametrize("args, words", [
    (["--actuation", "muscles"], ("--actuation muscles", "'forearm'", "no muscles")),
    (["--model", "arm26", "--actuation", "muscles", "--effort-weight", -1], ("--effort-weight", "non-negative")),
    (["--model", "arm26", "--actuation", "muscles", "--effort-weight", "nan"], ("--effort-weight", "finite")),
    (["--model", "arm26", "--effort-weight", 1], ("--effort-weight needs --actuation muscles",)),
    (["--actuation", "tendons"], ("--actuation", "tendons", "muscles")),
    (["--model", "arm26", "--actuation", "muscles", "--integrator", "rk45"], ("--actuation muscles", "RK4")),
    (["--model", "arm26", "--actuation", "muscles", "--save-params", "p.json"], ("--save-params", "muscles")),
    (["--model", "arm26", "--actuation", "muscles", "--torque", "ann", "--hidden", "auto"], ("--hidden auto",)),
])
def test_bad_input_is_one_line_and_exit_2(args, words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert_one_line_error(invoke(["optimize", "--budget", 1, *args]), *words)


def test_existing_runs_keep_their_hash_and_muscle_runs_get_their_own():
    """Hashes measured before --actuation existed; the default effort weight written out or not is
    one run, another weight another."""
    assert optimize_spec().hash() == "aa62b7460db42ed8"
    assert optimize_spec(model_name="arm26").hash() == "1c718b8b193f7c69"
    assert RunSpec().hash() == "2870560c174e2bfa"
    assert not {"actuation", "effort_weight"} & set(optimize_spec().canonical())
    muscles = optimize_spec(model_name="arm26", actuation="muscles")
    assert muscles.hash() == optimize_spec(model_name="arm26", actuation="muscles",
                                           effort_weight=DEFAULT_EFFORT_WEIGHT).hash()
    assert muscles.hash() not in (optimize_spec(model_name="arm26").hash(),
                                  optimize_spec(model_name="arm26", actuation="muscles", effort_weight=0.5).hash())


def test_the_help_gives_the_effort_weight_s_default():
    text = " ".join(invoke(["optimize", "--help"]).stdout.split())
    assert f"(default {DEFAULT_EFFORT_WEIGHT:g}:" in text and "--actuation" in text
