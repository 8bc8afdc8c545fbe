"""Muscles in model files: their lengths and moment arms against OpenSim's (``getLength``,
``computeMomentArm``) on a planar model with a free base, a knee on a spline path and an ankle turned
by an offset; moment arms against finite differences of the lengths and a polynomial path's against
its derivative by hand; a path of points' Hessian against finite differences of the moment arms and
a closed form; paths through the engine's own body points; the checker's one-line errors; and
muscles written back and read again equal."""

from __future__ import annotations

import copy
import importlib.util
import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import ModelError, model_from_dict, to_dict
from fdbench.multibody.model_files import load_model, to_toml
from fdbench.multibody.muscle_paths import muscle_geometry, path_hessians
from fdbench.multibody.muscles import Muscle, PathPoint, PointPath, PolynomialPath, Term

from helpers.cli_checks import assert_one_line_error
from helpers.models import LEG
from helpers.osim_files import body, joint, path_knee_model
from helpers.paths import ROOT
from helpers.opensim_child import run_opensim

runner = CliRunner()

# ---------------------------------------------------------------- a leg with a free base, a path and an offset

MUSCLE = {"max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.2}
PATHS = {  # name: points (body, x, y), m in the body's frame
    "long": [("ground", 0.05, 0.1), ("thigh", 0.04, -0.1), ("thigh", 0.03, -0.38), ("shank", 0.02, -0.05),
             ("foot", 0.12, 0.03)],
    "vasti": [("thigh", 0.03, -0.2), ("thigh", 0.045, -0.39), ("shank", 0.04, -0.06)],
    "soleus": [("shank", -0.03, -0.1), ("shank", -0.04, -0.4), ("foot", -0.04, 0.02)],
}


def leg_with_muscles(paths=PATHS) -> dict:
    data = copy.deepcopy(LEG)
    data["muscles"] = [MUSCLE | {"name": name, "path": {"points": [{"body": b, "at": [x, y]} for b, x, y in points]}}
                       for name, points in paths.items()]
    return data


def leg_osim(tmp_path):
    """LEG as an OpenSim model file: path_knee_model's free pelvis and knee, and the ankle a PinJoint
    whose parent frame is turned by the offset."""
    path = path_knee_model(tmp_path / "leg.osim")
    text = path.read_text().replace("</objects></BodySet>", body("foot", 1.0, (0.05, 0, 0), (0.01,) * 3 + (0,) * 3)
                                    + "</objects></BodySet>")
    ankle = joint("PinJoint", "ankle", "shank", "foot", [("ankle_angle", 0.0, False)], parent_at=(0.01, -0.42, 0),
                  parent_rotation=(0, 0, 0.3), child_at=(-0.02, 0.01, 0))
    path.write_text(text.replace("</objects></JointSet>", ankle + "</objects></JointSet>"))
    return path


OPENSIM_MUSCLES = """
model = osim.Model(request["path"])
for name, points in request["muscles"].items():
    muscle = osim.DeGrooteFregly2016Muscle()
    muscle.setName(name)
    for k, (owner, x, y) in enumerate(points):
        frame = model.getGround() if owner == "ground" else model.getBodySet().get(owner)
        muscle.addNewPathPoint(f"{name}_{k}", frame, osim.Vec3(x, y, 0.0))
    model.addForce(muscle)
state = model.initSystem()
coordinates = [model.getCoordinateSet().get(name) for name in request["coordinates"]]
muscles = [model.getMuscles().get(name) for name in request["muscles"]]
out = []
for values in request["q"]:
    for coordinate, value in zip(coordinates, values):
        coordinate.setValue(state, value, False)
    model.realizePosition(state)
    out.append([[m.getLength(state)] + [m.computeMomentArm(state, c) for c in coordinates] for m in muscles])
print(json.dumps(out))
"""


def opensim_lengths_and_arms(path, paths: dict, coordinates, q) -> tuple[np.ndarray, np.ndarray]:
    """OpenSim's lengths (n, M) and moment arms (n, M, J) of DeGrooteFregly2016Muscles through the
    points of ``paths`` added to the model at ``path``, at the coordinates q (n, J), in a child
    process (OpenSim's CasADi cannot share this one)."""
    request = {"path": str(path), "muscles": paths, "coordinates": list(coordinates),
               "q": np.asarray(q).tolist()}
    out = np.array(run_opensim(OPENSIM_MUSCLES, request, timeout=300))
    return out[..., 0], out[..., 1:]


def random_q(rng, count: int) -> np.ndarray:
    """(count, 6): the pelvis tilt, x, y, the knee (its path's span and beyond) and the ankle."""
    return np.column_stack([rng.uniform(-0.8, 0.8, count), rng.uniform(-0.5, 0.5, count), rng.uniform(0.5, 1.2, count),
                            rng.uniform(-2.3, 1.2, count), rng.uniform(-0.8, 0.8, count)])


@pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="the opensim package is not installed")
def test_lengths_and_moment_arms_are_opensim_s(tmp_path):
    """Paths over via points on a free base, a knee on a spline and an offset ankle: fdbench's lengths
    and moment arms (every coordinate, the pelvis translations too) equal OpenSim's getLength and
    computeMomentArm to 1e-9 m at 30 random states."""
    model = model_from_dict(leg_with_muscles(), "leg")
    q = random_q(np.random.default_rng(5), 30)
    theirs_length, theirs_arms = opensim_lengths_and_arms(leg_osim(tmp_path), PATHS, model.coordinates, q)
    ours_length, ours_arms = muscle_geometry(model, q)
    assert ours_length.shape == (30, 3) and ours_arms.shape == (30, 3, 5)
    assert np.abs(theirs_arms).max() > 0.05 and np.abs(theirs_arms).min() == 0.0  # some zero (the vasti's hip)
    np.testing.assert_allclose(ours_length, theirs_length, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours_arms, theirs_arms, rtol=0, atol=1e-9)


def test_paths_through_the_engine_s_body_points_have_their_lengths():
    """A path through each body's joint point and end, as the engine places them, is the sum of the
    distances between those points; one sample or many give the same numbers."""
    model = model_from_dict(LEG, "leg")
    engine = Engine(model)
    # the joint points at at_child, the ends at the next joint's at_parent (thigh, shank) or the centre of mass (foot)
    points = [("thigh", (0.0, 0.0)), ("thigh", (0.0, -0.4)), ("shank", (0.0, 0.0)), ("shank", (0.01, -0.42)),
              ("foot", (0.05, 0.0))]
    keys = ["thigh.joint", "thigh.end", "shank.joint", "shank.end", "foot.end"]
    path = PointPath(tuple(PathPoint(b, at) for b, at in points))
    model = replace(model, muscles=(Muscle("through", 1.0, 0.1, 0.1, path),))
    q = random_q(np.random.default_rng(2), 12)
    lengths, _ = muscle_geometry(model, q)
    where = engine.point_positions(q)
    expected = sum(np.linalg.norm(where[b] - where[a], axis=1) for a, b in zip(keys, keys[1:]))
    np.testing.assert_allclose(lengths[:, 0], expected, rtol=0, atol=1e-14)
    one = np.array([muscle_geometry(model, row)[0][0] for row in q])
    np.testing.assert_array_equal(one, lengths[:, 0])


def test_a_muscle_over_one_pin_is_the_closed_form():
    """The forearm (one pin at the origin) with a muscle from (0, h) on ground to (d, 0) on the
    forearm: l = sqrt(d^2 + h^2 - 2 d h sin(theta)), moment arm d h cos(theta) / l; a model without
    muscles has none."""
    d, h = 0.05, 0.3
    data = to_dict(find_model("forearm")) | {"muscles": [MUSCLE | {"name": "flexor", "path": {"points": [
        {"body": "ground", "at": [0.0, h]}, {"body": "forearm", "at": [d, 0.0]}]}}]}
    model = model_from_dict(data, "forearm")
    theta = np.linspace(-1.5, 1.5, 31)
    lengths, arms = muscle_geometry(model, theta[:, None])
    expected = np.sqrt(d * d + h * h - 2 * d * h * np.sin(theta))
    np.testing.assert_allclose(lengths[:, 0], expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(arms[:, 0, 0], d * h * np.cos(theta) / expected, rtol=0, atol=1e-15)
    curvature = [path_hessians(model, [angle])[0, 0, 0] for angle in theta]  # d2l/dtheta2
    np.testing.assert_allclose(curvature, d * h * np.sin(theta) / expected - (d * h * np.cos(theta))**2 / expected**3,
                               rtol=0, atol=1e-14)
    none = muscle_geometry(find_model("arm2"), np.zeros((3, 2)))
    assert none[0].shape == (3, 0) and none[1].shape == (3, 0, 2)
    with pytest.raises(ValueError, match=r"shape \(1,\) or \(n, 1\)"):
        muscle_geometry(model, np.zeros(2))


@st.composite
def leg_paths(draw):
    """Three to five points on random bodies and frames (ground included), and coordinates."""
    owners = st.sampled_from(["ground", "thigh", "shank", "foot", "heel"])
    xy = st.floats(-0.3, 0.3)
    points = draw(st.lists(st.tuples(owners, xy, xy), min_size=3, max_size=5))
    q = draw(st.lists(st.floats(-1.0, 1.0), min_size=5, max_size=5))
    return points, np.array(q)


def leg_with_path(points, q):
    """LEG with one muscle through ``points`` (body, x, y); hypothesis passes over paths with a point
    twice in a row or a segment shorter than 1 cm at q ((near) zero length: no slope, or a finite
    difference far off)."""
    try:
        model = model_from_dict(leg_with_muscles({"m": points}), "leg")
    except ModelError:  # two equal points in a row
        assume(False)
    segments = [muscle_geometry(replace(model, muscles=(replace(model.muscles[0], path=PointPath(
        model.muscles[0].path.points[k:k + 2])),)), q)[0][0] for k in range(len(points) - 1)]
    assume(min(segments) >= 1e-2)
    return model


@settings(max_examples=60)
@given(leg_paths())
def test_a_moment_arm_is_minus_the_length_s_slope(case):
    """-dl/dq by central differences (step 1e-6) equals the moment arm to 1e-7, for any points on any
    bodies, frames or ground whose segments are 1 cm or longer."""
    points, q = case
    model = leg_with_path(points, q)
    length, arms = muscle_geometry(model, q)
    step = 1e-6
    for j in range(5):
        up, down = q.copy(), q.copy()
        up[j] += step
        down[j] -= step
        slope = (muscle_geometry(model, up)[0] - muscle_geometry(model, down)[0]) / (2 * step)
        assert abs(-slope[0] - arms[0, j]) < 1e-7, (j, -slope, arms[0, j])


def minus_arm_slopes(model, q, step):
    """-d(moment arms)/dq (M, J, J) by central differences of muscle_geometry (step in rad and m)."""
    return np.stack([-(muscle_geometry(model, q + step * e)[1] - muscle_geometry(model, q - step * e)[1]) / (2 * step)
                     for e in np.eye(len(q))], axis=-1)


@settings(max_examples=30)
@given(leg_paths())
def test_a_path_of_points_hessian_is_the_slope_of_its_moment_arms(case):
    """d2l/dq2 (``path_hessians``) of any points on any bodies, frames or ground (the free base's angle
    and translations, the knee's spline path, the ankle's offset) equals minus the central differences
    (step 1e-5: truncation and rounding below 1e-9 here) of muscle_geometry's moment arms within 1e-6
    of its largest entry plus 1e-8 (a path on one body has none), and is symmetric to the bit. The
    knee's spline has no second derivative at its end knots (it goes on as a line), so a knee angle
    within 1e-3 of a knot, where the differences straddle the jump, is passed over."""
    points, q = case
    knots = np.array(LEG["joints"][1]["path"]["angles"])
    assume(np.min(np.abs(q[3] - knots)) > 1e-3)  # q[3]: the knee's angle
    model = leg_with_path(points, q)
    hessian = path_hessians(model, q)
    np.testing.assert_allclose(hessian, minus_arm_slopes(model, q, 1e-5), rtol=0,
                               atol=1e-8 + 1e-6 * np.abs(hessian).max())
    np.testing.assert_array_equal(hessian, np.swapaxes(hessian, 1, 2))


def test_the_hessians_of_points_and_polynomials_side_by_side_are_the_slopes_of_the_moment_arms():
    """LEG's three paths of points, one from ground straight to the heel and a polynomial at 8
    random states (the knee beyond its path's knots too, where the spline runs on straight): every
    pair of coordinates bends some path, and each Hessian is minus the central differences of its
    moment arms within 1e-6 of its largest entry."""
    data = leg_with_muscles(PATHS | {"reach": [("ground", 0.1, -0.2), ("heel", 0.0, 0.0)]})
    data["muscles"].append(MUSCLE | {"name": "poly", "path": POLYNOMIAL})
    model = model_from_dict(data, "leg")
    for q in random_q(np.random.default_rng(8), 8):
        hessian = path_hessians(model, q)
        assert np.all(np.abs(hessian).max(axis=0) > 1e-4)  # every pair of coordinates
        for ours, expected in zip(hessian, minus_arm_slopes(model, q, 1e-5)):
            np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-6 * np.abs(ours).max())
    with pytest.raises(ValueError, match=r"shape \(5,\)"):
        path_hessians(model, np.zeros((2, 5)))


def test_a_polynomial_path_and_its_moment_arms_are_the_closed_form():
    """l = 0.3 - 0.02 knee + 0.01 knee^2 ankle + 0.004 ankle^3 (coordinates listed out of the model's
    order): l and -dl/dq by hand; the pelvis coordinates have no moment arm."""
    terms = [{"coefficient": 0.004, "powers": [3, 0]}, {"coefficient": 0.3, "powers": [0, 0]},
             {"coefficient": -0.02, "powers": [0, 1]}, {"coefficient": 0.01, "powers": [1, 2]}]
    data = copy.deepcopy(LEG)
    data["muscles"] = [MUSCLE | {"name": "poly", "path": {"length": {"coordinates": ["ankle_angle", "knee_angle"],
                                                                     "terms": terms}}}]
    model = model_from_dict(data, "leg")
    q = random_q(np.random.default_rng(9), 20)
    knee, ankle = q[:, 3], q[:, 4]
    length, arms = muscle_geometry(model, q)
    np.testing.assert_allclose(length[:, 0], 0.3 - 0.02 * knee + 0.01 * knee**2 * ankle + 0.004 * ankle**3,
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(arms[:, 0, 3], -(-0.02 + 0.02 * knee * ankle), rtol=0, atol=1e-15)
    np.testing.assert_allclose(arms[:, 0, 4], -(0.01 * knee**2 + 0.012 * ankle**2), rtol=0, atol=1e-15)
    assert np.all(arms[:, 0, :3] == 0.0)
    at_zero = muscle_geometry(model, np.zeros(5))  # 0^0 is 1, no 0^-1 anywhere
    assert at_zero[0][0] == 0.3 and at_zero[1][0].tolist() == [0.0, 0.0, 0.0, 0.02, 0.0]


def test_a_polynomial_path_of_three_coordinates_is_the_closed_form():
    """l = 0.3 + 0.05 knee + 0.01 tx knee^2 ankle - 0.02 tx^2 ankle^3 (coordinates pelvis_tx, knee,
    ankle): l and -dl/dq by hand."""
    terms = [{"coefficient": 0.3, "powers": [0, 0, 0]}, {"coefficient": 0.05, "powers": [0, 1, 0]},
             {"coefficient": 0.01, "powers": [1, 2, 1]}, {"coefficient": -0.02, "powers": [2, 0, 3]}]
    data = copy.deepcopy(LEG)
    data["muscles"] = [MUSCLE | {"name": "poly", "path": {"length": {
        "coordinates": ["pelvis_tx", "knee_angle", "ankle_angle"], "terms": terms}}}]
    model = model_from_dict(data, "leg")
    q = random_q(np.random.default_rng(11), 20)
    tx, knee, ankle = q[:, 1], q[:, 3], q[:, 4]
    length, arms = muscle_geometry(model, q)
    np.testing.assert_allclose(length[:, 0], 0.3 + 0.05 * knee + 0.01 * tx * knee**2 * ankle - 0.02 * tx**2 * ankle**3,
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(arms[:, 0, 1], -(0.01 * knee**2 * ankle - 0.04 * tx * ankle**3), rtol=0, atol=1e-15)
    np.testing.assert_allclose(arms[:, 0, 3], -(0.05 + 0.02 * tx * knee * ankle), rtol=0, atol=1e-15)
    np.testing.assert_allclose(arms[:, 0, 4], -(0.01 * tx * knee**2 - 0.06 * tx**2 * ankle**2), rtol=0, atol=1e-15)
    assert np.all(arms[:, 0, [0, 2]] == 0.0)


POLYNOMIAL = {"length": {"coordinates": ["knee_angle", "ankle_angle"], "terms": [
    {"coefficient": 0.3, "powers": [0, 0]}, {"coefficient": -0.02, "powers": [1, 0]}, {"coefficient": 0.01, "powers": [1, 1]}]}}


@settings(max_examples=30)
@given(st.permutations(["long", "vasti", "soleus", "poly", "poly2"]))
def test_a_muscle_s_geometry_does_not_depend_on_the_muscles_beside_it(order):
    """Point and polynomial paths in any order: each muscle's length and moment arms are those of a
    model with that muscle alone."""
    data = leg_with_muscles({name: PATHS[name] for name in order if name in PATHS})
    for name in ("poly", "poly2"):
        data["muscles"].append(MUSCLE | {"name": name, "path": POLYNOMIAL})
    data["muscles"].sort(key=lambda muscle: order.index(muscle["name"]))
    model = model_from_dict(data, "leg")
    q = random_q(np.random.default_rng(4), 6)
    lengths, arms = muscle_geometry(model, q)
    for m, muscle in enumerate(model.muscles):
        alone = muscle_geometry(replace(model, muscles=(muscle,)), q)
        np.testing.assert_array_equal(lengths[:, m], alone[0][:, 0])
        np.testing.assert_array_equal(arms[:, m], alone[1][:, 0])


def test_muscles_read_back_equal_and_models_without_muscles_write_no_key(tmp_path):
    data = leg_with_muscles()
    data["muscles"][1] |= {"tendon": "compliant", "tendon_strain": 0.04, "pennation_angle": 0.2,
                           "fiber_damping": 0.01, "activation_time": 0.01, "deactivation_time": 0.04,
                           "max_contraction_velocity": 12.0, "passive_strain": 0.5}
    data["muscles"].append(MUSCLE | {"name": "poly", "path": {"length": {"coordinates": ["knee_angle"], "terms": [
        {"coefficient": 0.3, "powers": [0]}, {"coefficient": -0.02, "powers": [2]}]}}})
    model = model_from_dict(data, "leg")
    assert model.muscles[1].tendon == "compliant" and model.muscles[0].tendon == "rigid"
    assert model.muscles[0].activation_time == 0.015 and model.muscles[0].tendon_strain == 0.049
    assert model.muscles[3].path == PolynomialPath(("knee_angle",), (Term(0.3, (0,)), Term(-0.02, (2,))))
    (tmp_path / "leg.toml").write_text(to_toml(model))
    (tmp_path / "leg.json").write_text(json.dumps(to_dict(model)))
    assert load_model(tmp_path / "leg.toml") == model and load_model(tmp_path / "leg.json") == model
    for name in ("forearm", "arm2", "leg3"):
        assert "muscles" not in to_dict(find_model(name)) and "muscles" not in to_toml(find_model(name))


def test_models_show_lists_the_muscles(tmp_path):
    data = leg_with_muscles({"vasti": PATHS["vasti"]})
    data["muscles"].append(MUSCLE | {"name": "poly", "path": {"length": {"coordinates": ["knee_angle"], "terms": [
        {"coefficient": 0.3, "powers": [0]}]}}})
    path = tmp_path / "leg.json"
    path.write_text(json.dumps(data))
    shown = runner.invoke(app, ["models", "show", str(path)], env={"COLUMNS": "200"})
    assert shown.exit_code == 0, shown.stderr
    text = shown.stdout[shown.stdout.index("muscles"):]
    assert "vasti" in text and "thigh, thigh, shank" in text and "poly" in text and "knee_angle" in text


# ---------------------------------------------------------------- bad muscles: one line naming the key


def muscle_with(k: int, **keys):
    """A change of leg_with_muscles(): muscle k with the keys given (None: removed)."""
    def change(data):
        for key, value in keys.items():
            if value is None:
                data["muscles"][k].pop(key)
            else:
                data["muscles"][k][key] = value
    return change


def point_of(k: int, i: int, **keys):
    def change(data):
        data["muscles"][k]["path"]["points"][i] |= keys
    return change


def polynomial(**length):
    def change(data):
        data["muscles"][0]["path"] = {"length": {"coordinates": ["knee_angle", "ankle_angle"],
                                                 "terms": [{"coefficient": 0.3, "powers": [0, 0]}]} | length}
    return change


BAD = [
    ("an unknown body", point_of(2, 1, body="radius"),
     ("muscles[2].path.points[1].body", "unknown body 'radius'", "valid: ground, thigh, shank, foot, heel")),
    ("a zero force", muscle_with(0, max_isometric_force=0.0), ("muscles[0].max_isometric_force", "positive", "(N)")),
    ("a negative fibre length", muscle_with(1, optimal_fiber_length=-0.1), ("muscles[1].optimal_fiber_length", "(m)")),
    ("a missing slack length", muscle_with(0, tendon_slack_length=None), ("muscles[0].tendon_slack_length", "missing")),
    ("a text force", muscle_with(0, max_isometric_force="1 kN"), ("muscles[0].max_isometric_force", "the text '1 kN'")),
    ("an infinite force", muscle_with(0, max_isometric_force=math.inf), ("muscles[0].max_isometric_force", "finite")),
    ("an elastic tendon", muscle_with(0, tendon="elastic"), ("muscles[0].tendon", "'elastic'", "valid: rigid, compliant")),
    ("a right pennation", muscle_with(0, pennation_angle=math.pi / 2), ("muscles[0].pennation_angle", "[0, pi/2)")),
    ("a negative damping", muscle_with(0, fiber_damping=-0.1), ("muscles[0].fiber_damping", ">= 0")),
    ("a zero activation time", muscle_with(0, activation_time=0.0), ("muscles[0].activation_time", "(s)")),
    ("an unknown key", muscle_with(0, max_force=10.0), ("muscles[0].max_force", "unknown key",
                                                        "did you mean 'max_isometric_force'")),
    ("a muscle named as a body", muscle_with(1, name="Thigh"), ("muscles[1].name", "already the name of a body")),
    ("two muscles of one name", muscle_with(1, name="LONG"), ("muscles[1].name", "already the name of muscles[0]")),
    ("no path", muscle_with(0, path=None), ("muscles[0].path", "missing", "points")),
    ("both forms", muscle_with(0, path={"points": [], "length": {}}), ("muscles[0].path", "points and length")),
    ("one point", muscle_with(0, path={"points": [{"body": "thigh", "at": [0.0, 0.0]}]}),
     ("muscles[0].path.points", "2 to 100", "a list of 1")),
    ("a point twice", point_of(1, 1, body="thigh", at=[0.03, -0.2]), ("muscles[1].path.points[1]", "zero length")),
    ("a point of three numbers", point_of(1, 0, at=[0.0, 0.1, 0.0]), ("muscles[1].path.points[0].at", "a list of 3")),
    ("a point's unknown key", point_of(1, 0, frame="thigh"), ("muscles[1].path.points[0].frame", "unknown key")),
    ("an unknown coordinate", polynomial(coordinates=["knee_angle", "ankle"]),
     ("muscles[0].path.length.coordinates[1]", "unknown coordinate 'ankle'", "did you mean 'ankle_angle'")),
    ("a coordinate twice", polynomial(coordinates=["knee_angle", "knee_angle"]), ("muscles[0].path.length.coordinates[1]", "once")),
    ("powers of another length", polynomial(terms=[{"coefficient": 0.3, "powers": [0]}]),
     ("muscles[0].path.length.terms[0].powers", "one per coordinate (2)")),
    ("a fractional power", polynomial(terms=[{"coefficient": 0.3, "powers": [0.5, 0]}]),
     ("muscles[0].path.length.terms[0].powers[0]", "an integer 0 to 20", "0.5")),
    ("a negative power", polynomial(terms=[{"coefficient": 0.3, "powers": [0, -1]}]),
     ("muscles[0].path.length.terms[0].powers[1]", "an integer")),
    ("the same powers twice", polynomial(terms=[{"coefficient": 0.3, "powers": [1, 0]},
                                                {"coefficient": 0.1, "powers": [1, 0]}]),
     ("muscles[0].path.length.terms[1].powers", "already the powers of terms[0]")),
    ("no terms", polynomial(terms=[]), ("muscles[0].path.length.terms", "1 to 1000")),
    ("a missing coefficient", polynomial(terms=[{"powers": [1, 0]}]),
     ("muscles[0].path.length.terms[0].coefficient", "missing", "(m)")),
    ("muscles as a table", lambda data: data.update(muscles={"name": "x"}), ("muscles", "a list of tables")),
]


@pytest.mark.parametrize("case, change, words", BAD, ids=[case[0] for case in BAD])
def test_a_bad_muscle_is_one_line_naming_the_file_and_the_key(tmp_path, case, change, words):
    data = leg_with_muscles()
    change(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    line = assert_one_line_error(runner.invoke(app, ["models", "show", str(path)]), str(path), *words)
    assert "Traceback" not in line
    with pytest.raises(ModelError):
        load_model(path)


def test_a_bad_muscle_in_toml_names_the_key(tmp_path):
    model = model_from_dict(leg_with_muscles(), "leg")
    path = tmp_path / "bad.toml"
    path.write_text(to_toml(model).replace('{ body = "foot"', '{ body = "radius"', 1))
    assert_one_line_error(runner.invoke(app, ["models", "show", str(path)]), "muscles[0].path.points[4].body",
                          "unknown body 'radius'")


def test_the_readme_muscle_is_the_polynomial_it_states(tmp_path):
    """The README's polynomial muscle, added to arm2's file, reads and has l = 0.30 - 0.02 elbow
    + 0.004 shoulder elbow^2."""
    import re

    from fdbench.models import library

    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("\n## Muscles\n"):]
    (example,) = re.findall(r"```\n(\[\[muscles\]\].*?)```", section, flags=re.DOTALL)
    path = tmp_path / "arm.toml"
    path.write_text(library()["arm2"].read_text() + "\n" + example)
    model = load_model(path)
    q = np.random.default_rng(1).uniform(-1, 1, (10, 2))
    lengths, _ = muscle_geometry(model, q)
    np.testing.assert_allclose(lengths[:, 0], 0.30 - 0.02 * q[:, 1] + 0.004 * q[:, 0] * q[:, 1] ** 2, rtol=0, atol=1e-15)
