"""Torque actuators of model files (``[[actuators]]``): read, checked in one line and written back;
static optimisation where a coordinate has no reserve (one muscle on one pin: the closed form, the
torque left unmet exact beyond full activation; arm26 with a reserve on the shoulder only: the
torques balance and the elbow's unmet torque only where its flexors are saturated); ``simulate
--torque-file`` beside muscles driving the actuated coordinates only; a compliant tendon's failed
run naming the step; ``models show`` listing them."""

from __future__ import annotations

import copy
import csv
import io
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.models import find_model, library
from fdbench.multibody.actuators import Actuator
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import ModelError, model_from_dict, to_dict
from fdbench.multibody.model_files import load_model, to_toml
from fdbench.multibody.muscle import active_force_length, force_velocity
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.multibody.static_optimization import static_optimization, unmet_notes

from helpers.cli_checks import assert_one_line_error

runner = CliRunner()
ARM, F0, L_OPT, L_SLACK = 0.03, 400.0, 0.1, 0.2  # m, N, m, m: the flexor's moment arm and constants
TWO = {  # two pins, one muscle across the elbow: l = 0.3 - 0.03 elbow (m), the fibre at l_opt at elbow = 0
    "name": "two", "gravity": [0.0, -9.81],
    "bodies": [{"name": "upper", "mass": 2.0, "com": [0.15, 0.0], "inertia": 0.02},
               {"name": "lower", "mass": 1.0, "com": [0.15, 0.0], "inertia": 0.01}],
    "joints": [{"name": "shoulder", "parent": "ground", "child": "upper", "at_parent": [0.0, 0.0]},
               {"name": "elbow", "parent": "upper", "child": "lower", "at_parent": [0.3, 0.0]}],
    "motions": [{"name": "move", "duration": 0.2, "start": {"shoulder": 0.0, "elbow": 0.0},
                 "goal": {"shoulder": 0.5, "elbow": 1.0}}],
    "muscles": [{"name": "flexor", "max_isometric_force": F0, "optimal_fiber_length": L_OPT,
                 "tendon_slack_length": L_SLACK, "path": {"length": {"coordinates": ["elbow"], "terms": [
                     {"coefficient": L_SLACK + L_OPT, "powers": [0]}, {"coefficient": -ARM, "powers": [1]}]}}}],
    "actuators": [{"coordinate": "shoulder", "optimal_force": 3.0}],
}


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def with_actuators(*entries, data=TWO) -> dict:
    changed = copy.deepcopy(data)
    changed["actuators"] = list(entries)
    return changed


# ---------------------------------------------------------------- the file


def test_actuators_read_with_their_defaults_and_write_back_equal(tmp_path):
    model = model_from_dict(with_actuators({"coordinate": "elbow"}, {"coordinate": "shoulder", "optimal_force": 2.5,
                                                                     "name": "motor"}), "two")
    assert model.actuators == (Actuator("elbow_reserve", "elbow", 1.0), Actuator("motor", "shoulder", 2.5))
    for text, name in ((to_toml(model), "two.toml"), (json.dumps(to_dict(model)), "two.json")):
        (tmp_path / name).write_text(text)
        assert load_model(tmp_path / name) == model
    # a model without the table writes none, as before
    assert "actuators" not in to_dict(find_model("arm26")) and "[[actuators]]" not in to_toml(find_model("arm26"))


BAD = [
    ("an unknown coordinate", {"coordinate": "wrist"},
     ("actuators[0].coordinate", "unknown coordinate 'wrist'", "valid: shoulder, elbow")),
    ("a zero force", {"coordinate": "elbow", "optimal_force": 0.0}, ("actuators[0].optimal_force", "positive", "got 0")),
    ("a negative force", {"coordinate": "elbow", "optimal_force": -2.0}, ("actuators[0].optimal_force", "got -2")),
    ("an infinite force", {"coordinate": "elbow", "optimal_force": math.inf}, ("actuators[0].optimal_force", "finite")),
    ("a text force", {"coordinate": "elbow", "optimal_force": "5 N m"}, ("actuators[0].optimal_force", "the text")),
    ("no coordinate", {"optimal_force": 2.0}, ("actuators[0].coordinate", "missing")),
    ("an unknown key", {"coordinate": "elbow", "force": 2.0}, ("actuators[0].force", "unknown key")),
    ("a muscle's name", {"coordinate": "elbow", "name": "Flexor"}, ("actuators[0].name", "already the name of a muscle")),
    ("a body's name", {"coordinate": "elbow", "name": "upper"}, ("actuators[0].name", "already the name of a body")),
]


@pytest.mark.parametrize("case, entry, words", BAD, ids=[case[0] for case in BAD])
def test_a_bad_actuator_is_one_line_naming_the_file_and_the_key(tmp_path, case, entry, words):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(with_actuators(entry)))
    assert_one_line_error(invoke("models", "show", path), str(path), *words)
    with pytest.raises(ModelError):
        load_model(path)


def test_the_readme_actuator_reads_as_it_says(tmp_path):
    import re

    from helpers.paths import ROOT

    readme = (ROOT / "README.md").read_text()
    (example,) = re.findall(r"```\n(\[\[actuators\]\].*?)```", readme[readme.index("\n## Muscles\n"):],
                            flags=re.DOTALL)
    path = tmp_path / "arm26.toml"
    path.write_text(library()["arm26"].read_text() + "\n" + example)
    assert load_model(path).actuators == (Actuator("r_shoulder_elev_reserve", "r_shoulder_elev", 10.0),)


def test_two_actuators_on_a_coordinate_or_of_one_name_are_refused():
    with pytest.raises(ModelError, match=r"actuators\[1\].coordinate: 'elbow' already has actuators\[0\]"):
        model_from_dict(with_actuators({"coordinate": "elbow"}, {"coordinate": "elbow", "name": "other"}), "two")
    with pytest.raises(ModelError, match=r"actuators\[1\].name: 'M' is already the name of actuators\[0\]"):
        model_from_dict(with_actuators({"coordinate": "elbow", "name": "m"}, {"coordinate": "shoulder", "name": "M"}),
                        "two")


def test_models_show_lists_the_actuators(tmp_path):
    path = tmp_path / "two.json"
    path.write_text(json.dumps(TWO))
    shown = invoke("models", "show", path)
    assert shown.exit_code == 0
    line = next(line for line in shown.stdout.splitlines() if "shoulder_reserve" in line)
    assert line.split() == ["shoulder_reserve", "shoulder", "3", "N", "m"]


# ---------------------------------------------------------------- static optimisation without a reserve


def test_one_muscle_without_a_reserve_takes_the_closed_form_and_leaves_the_rest_unmet():
    """The fibre at its optimal length at rest: the muscle gives k = arm F0 f_L(1) f_V(0) per unit
    activation, so a = tau / k up to full activation, beyond it the unmet torque is tau - k, and a
    torque it cannot pull toward (tau < 0) is wholly unmet."""
    model = model_from_dict(TWO, "two")
    k = ARM * F0 * active_force_length(1.0, 1.0) * force_velocity(0.0)
    tau = (np.arange(26) * 0.1 - 0.45) * k  # none at k itself
    t = np.linspace(0.0, 0.25, 26)
    z, zd = np.zeros((26, 2)), np.zeros((26, 2))
    torque = np.column_stack([np.full(26, 4.0), tau])
    so = static_optimization(model, Engine(model).muscle_params, t, z, zd, torque)
    np.testing.assert_array_equal(so.optimal_force, [3.0, 0.0])  # the model's actuator on the shoulder only
    expected = np.clip(tau / k, 0.0, 1.0)
    np.testing.assert_allclose(so.activation[:, 0], expected, rtol=2e-6, atol=1e-12)
    beyond = tau > k
    np.testing.assert_allclose(so.unmet[beyond, 1], tau[beyond] - k, rtol=1e-12)
    np.testing.assert_array_equal(so.unmet[tau < 0, 1], tau[tau < 0])
    assert np.all(np.abs(so.unmet[(tau >= 0) & ~beyond, 1]) <= 2e-6 * np.abs(tau[(tau >= 0) & ~beyond]))
    np.testing.assert_array_equal(so.reserve[:, 1], 0.0)
    np.testing.assert_array_equal(so.reserve[:, 0], 4.0)  # no muscle on the shoulder: its reserve takes it all
    # the notes: where it is unmet, how much and which muscle is saturated
    units = ("N m", "N m")
    pulling = static_optimization(model, Engine(model).muscle_params, t[13:], z[13:], zd[13:], torque[13:])
    (note,) = unmet_notes(pulling, units)
    first = t[13:][beyond[13:]][0]
    assert note == f"elbow: {tau[-1] - k:.3g} N m unmet at t {first:.3g}-{t[-1]:.3g} s, flexor at full activation"
    (pushing,) = unmet_notes(static_optimization(model, Engine(model).muscle_params, t[:5], z[:5], zd[:5],
                                                 torque[:5]), units)
    assert pushing.startswith(f"elbow: {0.45 * k:.3g} N m unmet at t 0-{t[4]:.3g} s, ") and "no muscle acts on it that way" in pushing


def test_reserve_optimal_force_overrides_the_actuators_and_keeps_the_rest_without():
    model = model_from_dict(TWO, "two")
    t, z = np.zeros(1), np.zeros((1, 2))
    so = static_optimization(model, Engine(model).muscle_params, t, z, z, np.array([[4.0, 1.0]]),
                             reserve_optimal_force=7.0)
    np.testing.assert_array_equal(so.optimal_force, [7.0, 0.0])
    bare = model_from_dict({key: value for key, value in TWO.items() if key != "actuators"}, "two")
    so = static_optimization(bare, Engine(bare).muscle_params, t, z, z, np.array([[4.0, 1.0]]))
    np.testing.assert_array_equal(so.optimal_force, [1.0, 1.0])  # no table: a reserve of 1 on every coordinate


def test_arm26_with_a_shoulder_reserve_only_leaves_the_elbow_unmet_where_its_flexors_are_saturated(tmp_path):
    """A heavy hand (30 kg) with a reserve on the shoulder only: the CSV's forces times the moment
    arms, plus the reserve and the unmet torque, are plain inverse dynamics; the elbow is unmet only
    where every muscle that flexes it is at full activation, and a warning names them."""
    path = tmp_path / "arm26.toml"
    path.write_text(library()["arm26"].read_text() + '\n[[actuators]]\ncoordinate = "r_shoulder_elev"\n'
                                                      "optimal_force = 10.0\n")
    args = ["inverse", "--model", path, "--model", "r_ulna_radius_hand.mass=30", "--sample-dt", "0.02", "-f", "csv"]
    so, plain = invoke(*args, "--muscles"), invoke(*args)
    assert so.exit_code == 0 and plain.exit_code == 0, so.stderr
    warning = " ".join(so.stderr.split())
    assert warning.startswith("warning: torque the muscles cannot meet (no reserve): r_elbow_flex: ")
    assert "BIClong, BICshort, BRA at full activation" in warning
    rows = list(csv.DictReader(io.StringIO(so.stdout)))
    plain_rows = list(csv.DictReader(io.StringIO(plain.stdout)))
    assert "r_elbow_flex_reserve" not in rows[0] and "r_shoulder_elev_unmet" not in rows[0]
    model = find_model("arm26")
    muscles = [m.name for m in model.muscles]
    angles = np.radians([[float(r[j]) for j in model.coordinates] for r in plain_rows])
    torque = np.array([[float(r[f"{j}_torque"]) for j in model.coordinates] for r in plain_rows])
    _, arms = muscle_geometry(model, angles)
    force = np.array([[float(r[f"{m}_force"]) for m in muscles] for r in rows])
    reserve = np.array([float(r["r_shoulder_elev_reserve"]) for r in rows])
    unmet = np.array([float(r["r_elbow_flex_unmet"]) for r in rows])
    np.testing.assert_allclose(np.einsum("nmj,nm->nj", arms, force) + np.column_stack([reserve, unmet]), torque,
                               atol=1e-9)
    activation = np.array([[float(r[f"{m}_activation"]) for m in muscles] for r in rows])
    short = np.abs(unmet) > 1e-3 + 1e-4 * np.abs(torque[:, 1])
    assert short.sum() >= 5 and np.all(unmet[short] > 0)  # the hand too heavy to hold up
    flexors = arms[short][:, :, 1] > 0
    assert np.all(activation[short][flexors] == 1.0)


# ---------------------------------------------------------------- simulate beside muscles


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("actuators")
    bare = {key: value for key, value in TWO.items() if key != "actuators"}
    compliant = copy.deepcopy(bare)
    compliant["muscles"][0]["tendon"] = "compliant"
    for name, data in (("two", TWO), ("bare", bare), ("compliant", compliant)):
        (folder / f"{name}.json").write_text(json.dumps(data))
    texts = {"excitation": "t,flexor\n0,0\n0.2,0.5\n", "shoulder": "t,shoulder_torque\n0,1\n0.2,-2\n",
             "both": "t,shoulder,elbow\n0,1,0\n0.2,-2,0\n", "elbow": "t,ELBOW\n0,1\n0.2,-2\n",
             "wrist": "t,shoulder,wrist\n0,1,0\n0.2,-2,0\n"}
    for name, text in texts.items():
        (folder / f"{name}.csv").write_text(text)
    return folder


def test_the_torque_file_drives_the_actuated_coordinates_only(files):
    """The shoulder's actuator driven by the file and the unactuated elbow at zero: the same run,
    to the bit, as the model without actuators given the elbow's zero torque explicitly."""
    def trajectory(model, torque):
        out = files / f"{model}_{torque}.csv"
        done = invoke("simulate", "--model", files / f"{model}.json", "--excitation-file", files / "excitation.csv",
                      "--torque-file", files / f"{torque}.csv", "--save-trajectory", out, "-q")
        assert done.exit_code == 0, done.stderr
        return out.read_text()

    ours = trajectory("two", "shoulder")
    assert ours == trajectory("bare", "both")
    first = next(csv.DictReader(io.StringIO(ours)))
    assert float(first["shoulder_torque"]) != 0.0 and float(first["shoulder_acc"]) != 0.0


@pytest.mark.parametrize("torque, words", [("elbow", ["column 'ELBOW'", "'elbow' has no torque actuator",
                                                      "actuated: shoulder"]),
                                           ("wrist", ["column 'wrist'", "unknown actuated coordinate"])])
def test_a_column_of_an_unactuated_coordinate_is_one_line_and_exit_2(files, torque, words):
    assert_one_line_error(invoke("simulate", "--model", files / "two.json", "--excitation-file",
                                 files / "excitation.csv", "--torque-file", files / f"{torque}.csv"),
                          "--torque-file", *words)


def test_a_compliant_tendon_s_failed_run_suggests_a_smaller_step(files):
    """Warned before the run (the step above RK4's stable one on the tendon's dynamics at the start)
    and told after it; the step suggested runs through without a warning."""
    def run(dt):
        done = invoke("simulate", "--model", files / "compliant.json", "--excitation-file", files / "excitation.csv",
                      "--dt", dt, "-f", "json")
        assert done.exit_code == 0
        return json.loads(done.stdout), " ".join(done.stderr.split())

    record, warnings = run("0.01")
    assert record["status"] == "nonfinite"
    assert "compliant tendons near slack are stiff (flexor): try a smaller --dt than 0.01 s" in record["message"]
    suggested = warnings.split("at the start flexor's tendon needs --dt below ")[1].split("; the run will likely "
                                                                                       "fail: try --dt ")[1].split()[0]
    record, warnings = run(suggested)
    assert record["status"] == "success" and "stiff" not in warnings
