"""Indicators in mixed units (a free joint's x, y in m beside angles in rad) are never pooled:

- a control run on a free pelvis reports ``rmse_rot_deg`` over the angles, ``rmse_trans_cm`` over
  the translations, ``rmse_torque_nm`` / ``rmse_force_n`` over their generalized forces, and
  per-coordinate fields named by unit, all equal to the RMSEs recomputed from its saved trajectory;
  the trajectory gives translations in m, m/s, m/s^2 (the minimum-jerk closed form) and forces in N
  (the body's weight at rest);
- eq. 18 of such a model is RMSE_rot (deg) + RMSE_trans (cm) + the penalty;
- ``--noise-deg`` leaves translations noise-free and draws the angles' noise unchanged;
- a model of angles only keeps its record keys and numbers (the old pooled RMSE, to the last bit).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from helpers.models import hopper_model

from fdbench.multibody import simulation as sim

START = (0.0, 0.0, 0.0, 0.2, -0.3)  # tilt (rad), tx, ty (m), hip, knee (rad)
GOAL = (0.2, 0.1, -0.05, 0.6, -0.8)
DURATION = 0.5  # s
ANGLES, TRANSLATIONS = ("tilt", "hip", "knee"), ("tx", "ty")


def hopper_with_step():
    from fdbench.multibody.model import MotionSpec

    model = hopper_model()
    step = MotionSpec("step", "minimum-jerk", DURATION, tuple(zip(model.coordinates, START)),
                      tuple(zip(model.coordinates, GOAL)))
    return dataclasses.replace(model, motions=(step,))


def minimum_jerk(t):
    """Position, velocity, acceleration of the step, shape (n, 5), from the closed form."""
    s, d = np.asarray(t)[:, None] / DURATION, np.subtract(GOAL, START)
    return (START + d * (10 * s**3 - 15 * s**4 + 6 * s**5), d / DURATION * (30 * s**2 - 60 * s**3 + 30 * s**4),
            d / DURATION**2 * (60 * s - 180 * s**2 + 120 * s**3))


def cli(*args):
    from typer.testing import CliRunner

    from fdbench.cli import app

    result = CliRunner().invoke(app, [*args, "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.fixture(scope="module")
def free_run(tmp_path_factory):
    """(record, trajectory columns) of PD control of the hopper's step on a plant with a heavier pelvis."""
    from fdbench.multibody.model_files import to_toml

    folder = tmp_path_factory.mktemp("units")
    (folder / "hopper.toml").write_text(to_toml(hopper_with_step()))
    record = cli("control", "--model", str(folder / "hopper.toml"), "--plant", "pelvis.mass=12",
                 "--save-trajectory", str(folder / "trajectory.csv"))
    table = np.genfromtxt(folder / "trajectory.csv", delimiter=",", names=True)
    return record, table


def rms(values) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def test_a_free_base_record_splits_angles_from_translations(free_run):
    record, table = free_run
    assert record["status"] == "success"
    err = {c: table[c] - table[f"{c}_desired"] for c in ANGLES + TRANSLATIONS}  # deg, or m
    force = {c: table[f"{c}_torque"] - table[f"{c}_torque_inverse"] for c in ANGLES + TRANSLATIONS}
    assert record["rmse_rot_deg"] == pytest.approx(rms([err[c] for c in ANGLES]), rel=1e-9)
    assert record["rmse_trans_cm"] == pytest.approx(100 * rms([err[c] for c in TRANSLATIONS]), rel=1e-9)
    assert record["rmse_torque_nm"] == pytest.approx(rms([force[c] for c in ANGLES]), rel=1e-9)
    assert record["rmse_force_n"] == pytest.approx(rms([force[c] for c in TRANSLATIONS]), rel=1e-9)
    for c in ANGLES:
        assert record[f"rmse_rot_deg_{c}"] == pytest.approx(rms(err[c]), rel=1e-9)
        assert record[f"rmse_torque_nm_{c}"] == pytest.approx(rms(force[c]), rel=1e-9)
    for c in TRANSLATIONS:
        assert record[f"rmse_trans_cm_{c}"] == pytest.approx(100 * rms(err[c]), rel=1e-9)
        assert record[f"rmse_force_n_{c}"] == pytest.approx(rms(force[c]), rel=1e-9)
        assert f"rmse_rot_deg_{c}" not in record and f"rmse_torque_nm_{c}" not in record
    assert record["rmse_trans_cm"] > 0.01 and record["rmse_force_n"] > 1.0  # the heavier pelvis shows


def test_the_trajectory_gives_translations_in_metres_and_their_forces_in_newtons(free_run):
    _, table = free_run
    position, velocity, acceleration = minimum_jerk(table["t"])
    for k, c in enumerate(("tilt", "tx", "ty", "hip", "knee")):
        unit = np.degrees(1.0) if c in ANGLES else 1.0
        assert np.allclose(table[f"{c}_desired"], unit * position[:, k], rtol=1e-9, atol=1e-12)
        assert np.allclose(table[f"{c}_vel_desired"], unit * velocity[:, k], rtol=1e-9, atol=1e-9)
        assert np.allclose(table[f"{c}_acc_desired"], unit * acceleration[:, k], rtol=1e-9, atol=1e-9)
    # at rest at t = 0 the base carries the nominal body's weight, 18 kg: no pull sideways
    assert table["ty_torque_inverse"][0] == pytest.approx(18.0 * 9.81, rel=1e-5)
    assert abs(table["tx_torque_inverse"][0]) < 1e-5 * 18.0 * 9.81


def test_eq18_of_a_free_base_adds_the_translations_in_cm_to_the_angles_in_deg():
    from fdbench.multibody.engine import Engine
    from fdbench.multibody.motions import joint_motion
    from fdbench.problem import TrackingProblem

    model = hopper_with_step()
    heavier = dataclasses.replace(model, bodies=(dataclasses.replace(model.bodies[0], mass=12.0),) + model.bodies[1:])
    problem = TrackingProblem("cs", Engine(heavier), joint_motion("step", model), True, 2.0, knots=4,
                              nominal=Engine(model))
    result = problem.simulate(problem.p0)
    done = result.reached
    error = result.angles[done] - problem.inverse.angles[done]
    rot, trans = rms(np.degrees(error[:, [0, 3, 4]])), 100 * rms(error[:, [1, 2]])
    assert trans > 0.01
    assert problem.objective(problem.p0) == pytest.approx(rot + trans + 2.0 * (1 - result.t_end / DURATION),
                                                          rel=1e-12)


def test_noise_is_added_to_the_angles_only():
    from fdbench.multibody.motions import joint_motion, noisy_joints

    model = hopper_with_step()
    step = joint_motion("step", model)
    split = noisy_joints(step, 2.0, 5, 100.0, model.coordinate_kinds)
    pooled = noisy_joints(step, 2.0, 5, 100.0)
    truth, _, _ = step(np.array(split.parts[0]._t))
    for k, (a, b) in enumerate(zip(split.parts, pooled.parts)):
        if model.coordinate_kinds[k] == "translation":
            assert np.array_equal(a.recorded, truth[:, k])
        else:
            assert np.array_equal(a.recorded, b.recorded) and not np.array_equal(a.recorded, truth[:, k])


def test_an_angle_only_model_keeps_its_record_keys():
    record = cli("control", "--model", "arm2", "--motion", "reach")
    assert sorted(key for key in record if key.startswith("rmse_")) == sorted(
        ["rmse_rot_deg", "rmse_torque_nm", "rmse_rot_deg_shoulder", "rmse_rot_deg_elbow", "rmse_torque_nm_shoulder",
         "rmse_torque_nm_elbow"])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), n_joints=st.integers(1, 5), translations=st.lists(st.booleans(), min_size=5,
                                                                                          max_size=5))
def test_the_split_rmse_is_the_pooled_one_on_angles_and_scales_translations_to_cm(seed, n_joints, translations):
    """Angles only: the very numbers of the pooled ``rmse_deg`` and ``rmse_torque_nm``; with
    translations, each unit's RMSE is the pooled one over its columns, m taken as cm."""
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    n = 7
    result = SimpleNamespace(angles=rng.normal(size=(n, n_joints)), torque=rng.normal(size=(n, n_joints)),
                             reached=rng.uniform(size=n) < 0.8)
    result.z = result.angles
    desired, reference = rng.normal(size=(n, n_joints)), rng.normal(size=(n, n_joints))
    angles_only = ("angle",) * n_joints
    rot, trans, per = sim.rmse_coordinates(result, desired, angles_only)
    trq, force, per_force = sim.rmse_generalized_forces(result, reference, angles_only)
    pooled, pooled_j = sim.rmse_deg(result, desired)
    pooled_t, pooled_tj = sim.rmse_torque_nm(result, reference)
    assert np.array_equal([rot, trq], [pooled, pooled_t], equal_nan=True) and np.isnan(trans) and np.isnan(force)
    assert np.array_equal(per, pooled_j, equal_nan=True) and np.array_equal(per_force, pooled_tj, equal_nan=True)
    mask = np.array(translations[:n_joints])
    kinds = tuple("translation" if m else "angle" for m in mask)
    rot, trans, per = sim.rmse_coordinates(result, desired, kinds)
    if not result.reached.any():
        assert np.isnan(rot) and np.isnan(trans)
        return
    e = (result.angles - desired)[result.reached]
    assert np.isnan(rot) if mask.all() else rot == pytest.approx(rms(np.degrees(e[:, ~mask])), rel=1e-12)
    assert np.isnan(trans) if not mask.any() else trans == pytest.approx(100 * rms(e[:, mask]), rel=1e-12)
    assert np.allclose(per, np.sqrt(np.mean(e**2, axis=0)) * np.where(mask, 100.0, np.degrees(1.0)), rtol=1e-12)


def test_the_inverse_summary_gives_translations_in_metres_and_their_forces_in_newtons(tmp_path):
    """``inverse``'s summary names a translation's force in N and its ends in m, against the
    minimum-jerk closed form; ``torque_rms_nm`` covers the angles' torques only, ``force_rms_n``
    the translations' forces, each equal to the RMS of the history's own columns."""
    import csv

    from typer.testing import CliRunner

    from fdbench.cli import app
    from fdbench.multibody.model_files import to_toml

    path = tmp_path / "hopper.toml"
    path.write_text(to_toml(hopper_with_step()))
    result = CliRunner().invoke(app, ["inverse", "--model", str(path), "--format", "csv", "--quiet"])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(result.stdout.splitlines()))
    record = cli("inverse", "--model", str(path))
    for j, name in enumerate(("tilt", "tx", "ty", "hip", "knee")):
        translation = name in TRANSLATIONS
        ends = np.array(minimum_jerk([0.0, DURATION])[0])[:, j]
        expected = ends if translation else np.degrees(ends)
        unit = "m" if translation else "deg"
        assert (record[f"{name}_start_{unit}"], record[f"{name}_end_{unit}"]) == pytest.approx(tuple(expected), abs=1e-12)
        column = np.array([float(row[f"{name}_torque"]) for row in rows])
        key = f"force_rms_n_{name}" if translation else f"torque_rms_nm_{name}"
        assert record[key] == pytest.approx(np.sqrt(np.mean(column**2)), rel=1e-12)
        assert f"torque_rms_nm_{name}" not in record if translation else f"force_rms_n_{name}" not in record
    forces = np.array([[float(row[f"{x}_torque"]) for x in TRANSLATIONS] for row in rows])
    torques = np.array([[float(row[f"{a}_torque"]) for a in ANGLES] for row in rows])
    assert record["force_rms_n"] == pytest.approx(np.sqrt(np.mean(forces**2)), rel=1e-12)
    assert record["torque_rms_nm"] == pytest.approx(np.sqrt(np.mean(torques**2)), rel=1e-12)
