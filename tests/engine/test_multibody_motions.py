"""Joint motions of any model (fdbench.multibody.motions) and the short keys of model files
(fdbench.multibody.model_changes.with_short_keys), checked against values worked out by hand."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.files import BadFile
from fdbench.models import find_model
from fdbench.multibody.model import ModelError, MotionSpec
from fdbench.multibody.model_changes import short_key_values, with_changes, with_short_keys
from fdbench.multibody.model_files import load_model, to_toml
from fdbench.multibody.motions import (MinimumJerk, PerJoint, SampledMotion, joint_motion, noisy_joints,
                                       read_joint_motion_csv)

ARM = find_model("arm2")
SPEC = MotionSpec("lift", "minimum-jerk", 2.0, (("a", 0.5), ("b", -1.0)), (("a", 1.5), ("b", 1.0)))


# ---- minimum jerk -----------------------------------------------------------------------------


def test_minimum_jerk_starts_and_ends_at_rest_at_its_angles():
    motion = MinimumJerk(SPEC, ("b", "a"))  # the result follows the joints' order given
    z, zd, zdd = motion(np.array([0.0, 1.0, 2.0, 2.5]))
    assert z[0].tolist() == [-1.0, 0.5] and z[2].tolist() == [1.0, 1.5] and z[3].tolist() == [1.0, 1.5]
    assert np.allclose(z[1], [0.0, 1.0])  # halfway in time, halfway in angle
    assert np.all(zd[[0, 2, 3]] == 0) and np.allclose(zdd[[0, 2, 3]], 0)
    # the peak velocity of a minimum-jerk move is 15/8 of the mean one, at halfway
    assert np.allclose(zd[1], np.array([2.0, 1.0]) / 2.0 * 15 / 8)
    assert motion.duration == 2.0 and len(motion.samples) == 2001 and motion.joints == ("b", "a")


def test_the_velocities_and_accelerations_are_the_derivatives_of_the_angles():
    motion = MinimumJerk(SPEC, ("a", "b"))
    t, h = np.linspace(0.05, 1.95, 39), 1e-5
    z_up, zd_up, _ = motion(t + h)
    z_down, zd_down, _ = motion(t - h)
    _, zd, zdd = motion(t)
    assert np.allclose((z_up - z_down) / (2 * h), zd, rtol=0, atol=1e-8)
    assert np.allclose((zd_up - zd_down) / (2 * h), zdd, rtol=0, atol=1e-6)


def test_the_library_motions_are_the_arms_reach_and_the_legs_swing():
    reach = joint_motion("reach", ARM)
    z, _, _ = reach(np.array([0.0, 1.0]))
    assert np.allclose(np.degrees(z), [[-20.0, 30.0], [15.0, 55.0]], rtol=0, atol=1e-12)
    leg = find_model("leg3")
    swing = joint_motion(leg.motions[0].name, leg)
    angles, _, _ = swing(swing.samples)
    thigh = angles[:, 0] + leg.joints[0].offset  # the thigh's angle from +x
    assert thigh.min() < -math.pi / 2 < thigh.max()
    for k, joint in enumerate(leg.joints):
        assert joint.limits[0] <= angles[:, k].min() and angles[:, k].max() <= joint.limits[1]


def test_an_unknown_motion_lists_the_models_motions_or_a_csv_file():
    for name in ("rech", "paper"):
        with pytest.raises(ValueError, match=r"--motion: unknown arm2 motion .*valid: reach.* or a CSV file"):
            joint_motion(name, ARM)
    with pytest.raises(ValueError, match="unknown forearm motion 'swing'; valid: paper, exact or a CSV file"):
        joint_motion("swing", find_model("forearm"))
    with pytest.raises(ValueError, match="no motion named 'swing'.*columns t, theta"):
        joint_motion("swing", replace(find_model("forearm"), motions=()))


# ---- eq. 5, the forearm's named motions ------------------------------------------------------


def eq5_by_hand(t, a1=0.05, amplitude=math.pi / 4):
    """Eq. 5 written out: theta(t) from -45 deg to 0 along t* = a1 t + (1 - a1) t^2, and its first
    two derivatives with respect to t* (as the paper prints them)."""
    ts = a1 * t + (1 - a1) * t**2
    theta = -amplitude + amplitude * (ts - np.sin(2 * np.pi * ts) / (2 * np.pi))
    return theta, amplitude * (1 - np.cos(2 * np.pi * ts)), 2 * np.pi * amplitude * np.sin(2 * np.pi * ts)


def test_the_forearm_names_eq_5_paper_first_and_exact_second():
    forearm = find_model("forearm")
    assert [(m.name, m.type) for m in forearm.motions] == [("paper", "eq5-paper"), ("exact", "eq5-exact")]
    t = np.linspace(0.0, 1.0, 41)
    paper, exact = joint_motion("paper", forearm), joint_motion("exact", forearm)
    by_hand = eq5_by_hand(t)
    for got, want in zip(paper(t), by_hand):
        assert np.allclose(got[:, 0], want, rtol=0, atol=1e-12)
    assert paper.duration == exact.duration == 1.0 and len(paper.samples) == 1001 and paper.name == "paper"
    # 'exact' is the same angle, its rates those of theta(t): central differences of the angle
    h = 1e-6
    up, down = joint_motion("exact", forearm)(t[1:-1] + h), joint_motion("exact", forearm)(t[1:-1] - h)
    z, zd, zdd = exact(t[1:-1])
    assert np.allclose(z[:, 0], by_hand[0][1:-1], rtol=0, atol=1e-12)
    assert np.allclose((up[0] - down[0]) / (2 * h), zd, rtol=0, atol=1e-7)
    assert np.allclose((up[1] - down[1]) / (2 * h), zdd, rtol=0, atol=1e-5)


def test_a_one_joint_model_file_may_name_eq_5_and_a_model_without_it_does_not_know_it(tmp_path):
    forearm = find_model("forearm")
    text = to_toml(replace(forearm, name="elbow", motions=()))
    (tmp_path / "bare.toml").write_text(text)
    bare = load_model(tmp_path / "bare.toml")
    with pytest.raises(ValueError, match="declares no motion named 'paper'"):
        joint_motion("paper", bare)
    (tmp_path / "elbow.toml").write_text(text + '\n[[motions]]\nname = "flex"\ntype = "eq5-exact"\n')
    elbow = load_model(tmp_path / "elbow.toml")
    t = np.linspace(0.0, 1.0, 11)
    for got, want in zip(joint_motion("flex", elbow)(t), joint_motion("exact", forearm)(t)):
        assert np.array_equal(got, want)
    assert load_model(tmp_path / "elbow.toml") == elbow and to_toml(elbow).count("[[motions]]") == 1


def test_a_recorded_angle_may_pass_90_degrees():
    """The engine's angle constraints are regular at any angle: a recording from 0 to 120 deg and
    back is taken as any other, its rates given or estimated."""
    t = np.linspace(0.0, 2.0, 201)
    top, rate = math.radians(120), math.pi / 2
    theta, vel, acc = top * np.sin(rate * t), top * rate * np.cos(rate * t), -top * rate**2 * np.sin(rate * t)
    given = SampledMotion(t, theta, vel, acc)
    for got, want in zip(given(t), (theta, vel, acc)):
        assert np.allclose(got, want, rtol=0, atol=1e-12)
    inner = (t > 0.3) & (t < 1.7)
    estimated = SampledMotion(t, theta)(t)
    assert np.allclose(estimated[1][inner], vel[inner], rtol=0, atol=1e-3 * top * rate)


# ---- recorded motions by joint names ----------------------------------------------------------


def write_csv(path, header, columns):
    rows = [",".join(repr(float(v)) for v in row) for row in np.column_stack(columns)]
    path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")
    return path


def test_a_motion_file_is_read_by_joint_names_in_any_order_and_case(tmp_path):
    t = np.linspace(0.0, 1.0, 101)
    shoulder, elbow = 10 * t, 30 + 5 * t**2  # deg
    path = write_csv(tmp_path / "m.csv", ["ELBOW", "t", "marker_x", "Shoulder"], [elbow, t, 99 + t, shoulder])
    motion = joint_motion(path, ARM)
    z, zd, _ = motion(t[10:90])
    assert motion.joints == ("shoulder", "elbow") and motion.name == "file:m.csv"
    assert np.allclose(np.degrees(z), np.column_stack([shoulder, elbow])[10:90], atol=1e-3)
    assert np.allclose(np.degrees(zd), np.column_stack([10 + 0 * t, 10 * t])[10:90], atol=1e-2)


def test_given_rates_are_taken_as_given(tmp_path):
    t = np.linspace(0.0, 1.0, 21)
    columns = [t, 10 * t, 10 + 0 * t, 0 * t, 30 + 5 * t**2, 10 * t, 10 + 0 * t]
    header = ["t", "shoulder", "shoulder_vel", "shoulder_acc", "elbow", "elbow_vel", "elbow_acc"]
    motion = read_joint_motion_csv(write_csv(tmp_path / "m.csv", header, columns), ARM.coordinates)
    z, zd, zdd = motion(t)
    assert np.allclose(np.degrees(zd[:, 1]), 10 * t) and np.allclose(np.degrees(zdd[:, 0]), 0, atol=1e-9)
    assert motion.describe()["derivatives"] == "given"


def test_a_motion_file_without_a_joints_column_is_one_line_naming_the_file_and_the_joint(tmp_path):
    t = np.linspace(0.0, 1.0, 21)
    path = write_csv(tmp_path / "m.csv", ["t", "shoulder", "elbw"], [t, t, t])
    with pytest.raises(BadFile, match=rf"--motion: {path} has no column for joint 'elbow'; .*columns t, shoulder, elbow"):
        joint_motion(path, ARM)


# ---- noisy captures ---------------------------------------------------------------------------


def test_a_noisy_capture_is_seeded_and_as_noisy_as_asked():
    reach = joint_motion("reach", ARM)
    first, again, other = (noisy_joints(reach, 2.0, seed, 100.0) for seed in (7, 7, 8))
    t = np.linspace(0.0, 1.0, 333)
    assert all(np.array_equal(a, b) for a, b in zip(first(t), again(t)))
    assert not np.array_equal(first(t)[0], other(t)[0])
    truth, _, _ = reach(np.linspace(0.0, 1.0, 101))
    noise = np.degrees(np.column_stack([part.recorded for part in first.parts]) - truth)
    assert noise.shape == (101, 2) and 1.6 < noise.std() < 2.4
    assert np.array_equal(first.samples, reach.samples) and first.name == "reach+noise 2 deg at 100 Hz (seed 7)"
    assert isinstance(first, PerJoint)


# ---- short keys -------------------------------------------------------------------------------


def test_the_arms_short_keys_read_its_constants():
    expected = {"L01": 0.30, "L0G": 0.13, "m0": 2.0, "I0": 0.0262 + 2.0 * 0.13**2, "L12": 0.33, "L1G": 0.11, "m": 1.0,
                "I1": 0.0279 + 0.11**2, "F_ext": 15.0, "g": 9.81}
    assert short_key_values(ARM) == pytest.approx(expected, rel=1e-15)


def test_the_arms_short_keys_give_the_closed_form_arm():
    """M(z) and h(z, z') of the arm's closed form (Lagrange, minimal coordinates) with m0 = 2.5,
    I1 = 0.05, L12 = 0.4, F_ext = 10 and I0 = 0.06 about the shoulder kept."""
    from fdbench.multibody.engine import Engine

    model = with_short_keys(ARM, [("m0", 2.5), ("I1", "0.05"), ("L12", 0.4), ("F_ext", 10)])
    assert model.body("upper_arm").inertia == pytest.approx(0.06 - 2.5 * 0.13**2, rel=1e-12)
    s, e, ws, we, g = 0.2, 0.7, 1.5, -2.0, 9.81
    b = 1.0 * 0.30 * 0.11
    G = 1.0 * g * 0.11 + 10 * 0.4
    M = [[0.06 + 0.05 + 1.0 * 0.30**2 + 2 * b * math.cos(e), 0.05 + b * math.cos(e)], [0.05 + b * math.cos(e), 0.05]]
    h = [-b * math.sin(e) * (2 * ws * we + we**2) + (2.5 * g * 0.13 + (1.0 * g + 10) * 0.30) * math.cos(s)
         + G * math.cos(s + e), b * math.sin(e) * ws**2 + G * math.cos(s + e)]
    engine = Engine(model)
    assert np.allclose(engine.mass_matrix([s, e]), M, rtol=1e-12, atol=0)
    assert np.allclose(engine.bias([s, e], [ws, we]), h, rtol=1e-12, atol=0)


def test_the_forearms_short_keys_set_table_1s_constants():
    forearm = find_model("forearm")
    assert short_key_values(forearm) == pytest.approx({"L12": 0.33, "L1G": 0.11, "m": 1.0, "I1": 0.04,
                                                      "F_ext": 15.0, "g": 9.81}, rel=1e-15)
    changed = with_short_keys(forearm, [("m", 2.0), ("L12", 0.4), ("F_ext", 20), ("g", 3.0)])
    assert changed.body("forearm").inertia == pytest.approx(0.04 - 2.0 * 0.11**2, rel=1e-12)  # I1 kept about the elbow
    assert changed.loads[0].at == (0.4, 0.0) and changed.loads[0].force == (0.0, -20.0)
    assert changed.gravity == (0.0, -3.0)
    assert with_short_keys(forearm, [("I1", 0.05)]).body("forearm").inertia == pytest.approx(0.05 - 0.11**2, rel=1e-12)


def test_a_path_keeps_the_inertia_about_the_centre_of_mass():
    assert with_short_keys(ARM, [("upper_arm.mass", 2.5)]).body("upper_arm").inertia == 0.0262
    assert with_short_keys(ARM, [("L01", 0.35)]).body("upper_arm").inertia == 0.0262  # nothing moved: untouched
    assert with_short_keys(ARM, [("upper_arm.mass", 2.5), ("F_ext", 10)]).body("upper_arm").inertia == 0.0262
    assert with_short_keys(ARM, [("m0", 2.5), ("upper_arm.inertia", 0.03)]).body("upper_arm").inertia == 0.03


def test_changed_models_keep_their_motions_and_short_keys():
    changed = with_changes(ARM, [("forearm.mass", 2.0)])
    assert changed.motions == ARM.motions and changed.keys == ARM.keys


@pytest.mark.parametrize("pairs, words", [
    ([("L02", 0.3)], ("L02=0.3", "unknown key of model 'arm2' 'L02'", "L01 (elbow.at_parent.x)", "upper_arm.mass")),
    ([("m0", -1)], ("m0=-1", "upper_arm.mass", "positive")),
    ([("m0", "abc")], ("m0=abc", "must be a number")),
    ([("I0", 0.01)], ("I0=0.01", "upper_arm.inertia@shoulder", "must be positive")),
    ([("m0", 10)], ("m0=10", "the inertia about shoulder, 0.06", "must be positive")),
    ([("L1G", math.inf)], ("L1G=inf", "forearm.com", "finite")),
])
def test_a_bad_short_key_is_one_line_naming_it(pairs, words):
    with pytest.raises(ModelError) as caught:
        with_short_keys(ARM, pairs)
    message = str(caught.value)
    assert "\n" not in message and all(word in message for word in words), message


def test_models_show_lists_the_motions_and_the_short_keys():
    result = CliRunner().invoke(app, ["models", "show", "arm2"])
    assert result.exit_code == 0, result.stderr
    for words in ("reach (default)", "-20 -> 15", "30 -> 55", "upper_arm.inertia@shoulder", "-loads[0].force.y"):
        assert words in result.stdout
