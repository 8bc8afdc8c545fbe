"""OpenSim models and motions in: ``fdbench import-osim``, ``--model MODEL.osim`` and ``--motion
FILE.mot|FILE.sto``, checked against the .osim files read independently (xml.etree) and against
OpenSim's own inverse dynamics (its InverseDynamicsSolver, muscles removed); fdbench's models out
(``fdbench export-osim``), checked against OpenSim's inverse dynamics and forward simulation."""

from __future__ import annotations

import importlib.util
import io
import math
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from helpers.osim_files import body, joint, osim_file, path_knee_model
from helpers.paths import ROOT
from helpers.opensim_child import run_opensim
from fdbench.cli import app
from fdbench.models import find_model, library
from fdbench.multibody.model import MotionSpec
from fdbench.multibody.model_files import load_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import MinimumJerk

from fdbench.multibody.actuators import Actuator
from fdbench.multibody.osim import import_osim, to_osim
from fdbench.multibody.simulation import simulate

# OpenSim runs in child processes only: its bundled CasADi cannot share a process with the casadi
# package the rest of the suite imports (see fdbench.multibody.osim.import_osim_content).
if importlib.util.find_spec("opensim") is None:
    pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')", allow_module_level=True)

ARM26 = ROOT / "examples" / "opensim" / "arm26.osim"
SUBJECT01 = next((where for where in (folder / "shared" / "data" / "opensim" / "subject01.osim"
                                      for folder in (ROOT.parent, ROOT.parent.parent)) if where.exists()),
                 ROOT.parent / "shared" / "data" / "opensim" / "subject01.osim")  # beside the source folder (or one up)
runner = CliRunner()


def invoke(*args, code=0):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == code, (result.stdout, result.stderr)
    return result


def refused(*args, contains=()):
    """The command exits 2 with one line on stderr holding every text of ``contains``."""
    result = invoke(*args, code=2)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error: "), result.stderr
    assert "Traceback" not in result.stderr
    for text in contains:
        assert text in lines[0], lines[0]
    return lines[0]


def forearm_osim(path: Path) -> Path:
    """Table 1's forearm as OpenSim would hold it: one body on a pin at the origin, no load."""
    return osim_file(path, [body("forearm", 1.0, (0.11, 0, 0), (0.001, 0.0279, 0.0279, 0, 0, 0))],
                     [joint("PinJoint", "elbow", "ground", "forearm", [("theta", 0.0, False)])])


# ---------------------------------------------------------------- OpenSim's inverse dynamics


OPENSIM_ID = """
import numpy as np
model = osim.Model(request["path"])
if not request["keep_forces"]:
    model.updForceSet().clearAndDestroy()
state = model.initSystem()
found = [model.getCoordinateSet().get(name) for name in request["coordinates"]]
index = []
for coordinate in found:  # the coordinate's place among the system's speeds
    coordinate.setSpeedValue(state, 1.0)
    index.append(next(i for i in range(state.getNU()) if state.getU().get(i) == 1.0))
    coordinate.setSpeedValue(state, 0.0)
solver = osim.InverseDynamicsSolver(model)
out = []
for angles, rates, accelerations in zip(request["z"], request["zd"], request["zdd"]):
    udot = osim.Vector(state.getNU(), 0.0)
    for coordinate, k, angle, rate, acceleration in zip(found, index, angles, rates, accelerations):
        coordinate.setValue(state, angle, False)
        coordinate.setSpeedValue(state, rate)
        udot.set(k, acceleration)
    model.realizeVelocity(state)
    tau = solver.solve(state, udot)
    out.append([tau.get(k) for k in index])
print(json.dumps(out))
"""


def opensim_inverse_dynamics(path: Path, coordinates, z, zd, zdd, keep_forces: bool = False) -> np.ndarray:
    """OpenSim's generalised forces (N m) of ``coordinates`` at the samples (rad, rad/s, rad/s^2),
    shape (n, J), by its InverseDynamicsSolver on the model with its forces (muscles) removed unless
    ``keep_forces``, in a child process."""
    request = {"path": str(path), "coordinates": list(coordinates), "keep_forces": keep_forces,
               **{k: np.asarray(v, dtype=float).tolist() for k, v in (("z", z), ("zd", zd), ("zdd", zdd))}}
    return np.array(run_opensim(OPENSIM_ID, request, timeout=300))


def minimum_jerk(model, samples: int = 51):
    """A minimum-jerk motion of every joint of ``model`` (its mid_range), at ``samples`` times."""
    return MinimumJerk(model.motions[0], model.coordinates)(np.linspace(0.0, 1.0, samples))


# ---------------------------------------------------------------- arm26 against its file


def test_arm26_imports_the_bodies_joints_and_gravity_of_its_file():
    model, notes = import_osim(ARM26)
    xml = ET.parse(ARM26).getroot().find("Model")
    bodies = {b.get("name"): b for b in xml.find("BodySet/objects")}
    numbers = lambda e, key: [float(v) for v in e.findtext(key).split()]  # noqa: E731
    assert [b.name for b in model.bodies] == ["r_humerus", "r_ulna_radius_hand"]  # base, welded to ground, is gone
    for found in model.bodies:
        element = bodies[found.name]
        assert found.mass == float(element.findtext("mass"))
        assert list(found.com) == numbers(element, "mass_center")[:2]
        assert found.inertia == numbers(element, "inertia")[2]  # Izz about the centre of mass
    frames = {f.get("name"): numbers(f, "translation") for f in xml.iter("PhysicalOffsetFrame")}
    shoulder, elbow = model.joints
    assert (shoulder.name, shoulder.parent, elbow.name, elbow.parent) == (
        "r_shoulder_elev", "ground", "r_elbow_flex", "r_humerus")
    # the shoulder hangs from base, welded 0.8 m above ground's origin
    assert shoulder.at_parent == pytest.approx(np.add(frames["ground_offset"], frames["base_offset"])[:2], abs=1e-15)
    assert elbow.at_parent == pytest.approx(frames["r_humerus_offset"][:2], abs=1e-15)
    assert shoulder.limits == tuple(numbers(next(xml.iter("Coordinate")), "range"))
    assert model.gravity == tuple(numbers(xml, "gravity")[:2])
    assert "arm26.osim" in model.description and "Holzbaur" in model.description  # the credits travel with it
    axes = [numbers(axis, "axis") for axis in xml.iter("TransformAxis") if axis.get("name") == "rotation1"]
    largest = max(math.degrees(math.acos(a[2] / math.hypot(*a))) for a in axes)
    assert 3 < largest < 4
    assert notes[0] == "dropped 3 markers"  # the muscles are kept, their wrap objects in their fitted paths
    assert "base" in notes[1] and "into ground" in notes[1]
    assert f"{largest:.2f} deg" in notes[2]


def test_arm26_inverse_dynamics_agrees_with_opensim_and_the_axis_projection_explains_the_difference(tmp_path):
    model, _ = import_osim(ARM26)
    z, zd, zdd = minimum_jerk(model)
    ours = Engine(model).inverse_dynamics(z, zd, zdd)
    theirs = opensim_inverse_dynamics(ARM26, model.coordinates, z, zd, zdd)
    # the file's axes are 3.4 and 3.5 deg off the normal: 0.028 N m of torques up to 8 N m
    assert np.abs(ours - theirs).max() < 0.05 and np.abs(ours - theirs).max() < 0.005 * np.abs(theirs).max()
    text = ARM26.read_text()
    for tilted in ("-0.058898020000000002 0.0023 0.99826135999999999", "0.049400010000000001 0.036600010000000002 "
                   "0.99810825000000003"):
        assert tilted in text
        text = text.replace(tilted, "0 0 1")
    exact = tmp_path / "arm26_exact.osim"
    exact.write_text(text.replace("0.99826135999999999 -0 0.058898020000000002", "1 0 0")
                     .replace("0.99810825000000003 0 -0.049400010000000001", "1 0 0"))
    projected, notes = import_osim(exact)
    assert projected.bodies == model.bodies and projected.joints == model.joints
    assert not any(note.startswith("projected") for note in notes)
    exact_theirs = opensim_inverse_dynamics(exact, model.coordinates, z, zd, zdd)
    assert np.abs(ours - exact_theirs).max() < 1e-9  # the whole difference is the projection


def test_a_forearm_written_for_opensim_is_the_library_forearm(tmp_path):
    path = forearm_osim(tmp_path / "forearm.osim")
    model, notes = import_osim(path)
    assert notes == () and model.coordinates == ("theta",) and model.loads == ()
    library = find_model("forearm")
    s = np.linspace(0.0, 1.0, 41)[:, None]
    z, zd, zdd = -0.8 * s, 2.0 - s, -3.0 * s  # rad, rad/s, rad/s^2
    ours = Engine(model).inverse_dynamics(z, zd, zdd)
    hand = 0.33 * 15.0 * np.cos(z)  # the library's load, 15 N down at 0.33 m, which OpenSim's file has not
    np.testing.assert_allclose(ours + hand, Engine(library).inverse_dynamics(z, zd, zdd), rtol=0, atol=1e-9)
    np.testing.assert_allclose(Engine(replace(library, loads=())).inverse_dynamics(z, zd, zdd), ours, rtol=0, atol=1e-9)
    np.testing.assert_allclose(opensim_inverse_dynamics(path, ["theta"], z, zd, zdd), ours, rtol=0, atol=1e-9)


def test_rotated_frames_welds_and_locked_coordinates_map_exactly(tmp_path):
    """Offsets and rotations about z in both joint frames, a weld whose frame also turns about x
    (the hand's inertia then mixes), a locked coordinate and out-of-plane offsets: OpenSim's inverse
    dynamics of the file equals fdbench's of the import."""
    path = osim_file(tmp_path / "arm.osim", [
        body("upper", 2.0, (0.01, -0.13, 0.02), (0.02, 0.003, 0.026, 0.001, 0.0, 0.0)),
        body("forearm", 1.0, (0.0, -0.11, -0.01), (0.01, 0.001, 0.028, 0.0, 0.0, 0.0)),
        body("hand", 0.4, (0.0, -0.05, 0.01), (0.002, 0.003, 0.004, 0.0001, 0.0002, 0.0003)),
        body("ring", 0.1, (0.02, 0.0, 0.0), (0.0001, 0.0001, 0.0001, 0, 0, 0)),
    ], [
        joint("PinJoint", "shoulder_joint", "ground", "upper", [("shoulder", 0.1, False)], (0.1, 0.2, 0.05),
              (0, 0, 0.3), (0, 0.05, 0), (0, 0, -0.2)),
        joint("PinJoint", "elbow_joint", "upper", "forearm", [("elbow", 0.4, False)], (0.02, -0.3, 0.01), (0, 0, 0),
              (0, 0, 0), (0, 0, 0.5)),
        joint("WeldJoint", "wrist_weld", "forearm", "hand", (), (0, -0.25, 0), (0.7, 0, 0.4)),
        joint("PinJoint", "ring_joint", "hand", "ring", [("ring_angle", 0.3, True)], (0.01, -0.08, 0)),
    ])
    model, notes = import_osim(path)
    assert model.coordinates == ("shoulder", "elbow") and [b.name for b in model.bodies] == ["upper", "forearm"]
    assert model.body("forearm").mass == pytest.approx(1.5)
    assert notes == ("welded into their parent: hand (WeldJoint 'wrist_weld') into forearm; ring (joint "
                     "'ring_joint', coordinate ring_angle locked) into forearm",)
    z, zd, zdd = minimum_jerk(model, 31)
    ours = Engine(model).inverse_dynamics(z, zd, zdd)
    theirs = opensim_inverse_dynamics(path, model.coordinates, z, zd, zdd)
    assert np.abs(theirs).max() > 1.0
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)


# ---------------------------------------------------------------- the command line


def test_import_osim_writes_the_model_file_with_its_notes_and_reads_back_equal(tmp_path):
    out = tmp_path / "arm26.toml"
    result = invoke("import-osim", ARM26, "-o", out, "--quiet")
    assert result.stdout == "" and result.stderr == ""
    text = out.read_text()
    assert text.startswith("# Imported from the OpenSim model arm26.osim") and "# note: dropped 3 markers" in text
    assert load_model(out) == import_osim(ARM26)[0]
    assert invoke("import-osim", ARM26).stdout == text  # stdout without -o
    noisy = invoke("import-osim", ARM26, "-o", tmp_path / "again.toml")
    assert "dropped 3 markers" in noisy.stderr and "wrote" in noisy.stderr


def test_model_osim_runs_a_command_with_its_notes_as_warnings():
    table = pd.read_csv(io.StringIO(invoke("inverse", "--model", ARM26, "--format", "csv", "--quiet").stdout))
    model, notes = import_osim(ARM26)
    z, zd, zdd = minimum_jerk(model, 1001)
    expected = Engine(model).inverse_dynamics(z, zd, zdd)
    np.testing.assert_allclose(table[["r_shoulder_elev_torque", "r_elbow_flex_torque"]], expected, rtol=1e-9,
                               atol=1e-9)
    loud = invoke("inverse", "--model", ARM26)
    warnings = [line for line in loud.stderr.splitlines() if "warning" in line]
    assert len(warnings) == len(notes) and all(line.startswith("fdbench: warning: --model: ") for line in warnings)
    shown = invoke("models", "show", ARM26, "--format", "json").stdout
    assert '"r_shoulder_elev"' in shown


def write_storage(path: Path, t, columns: dict, in_degrees: bool) -> Path:
    header = ["Coordinates", "version=1", f"nRows={len(t)}", f"nColumns={len(columns) + 1}",
              f"inDegrees={'yes' if in_degrees else 'no'}", "", "endheader"]
    rows = ["\t".join(["time", *columns])]
    rows += ["\t".join(repr(float(v)) for v in [t[n], *(c[n] for c in columns.values())]) for n in range(len(t))]
    path.write_text("\n".join(header + rows) + "\n")
    return path


def test_motion_mot_in_degrees_or_radians_gives_the_same_run_and_extra_columns_a_note(tmp_path):
    model = import_osim(ARM26)[0]
    t = np.linspace(0.0, 1.0, 101)
    z = MinimumJerk(model.motions[0], model.coordinates)(t)[0]
    extra = {"pelvis_tx": np.full_like(t, 0.6)}
    degrees = write_storage(tmp_path / "reach.mot", t, {"r_shoulder_elev": np.degrees(z[:, 0]), **extra,
                                                        "r_elbow_flex": np.degrees(z[:, 1])}, True)
    radians = write_storage(tmp_path / "reach.sto", t, {"r_elbow_flex": z[:, 1], "r_shoulder_elev": z[:, 0]}, False)
    runs = [invoke("inverse", "--model", ARM26, "--motion", path, "--format", "csv") for path in (degrees, radians)]
    tables = [pd.read_csv(io.StringIO(run.stdout)) for run in runs]
    np.testing.assert_allclose(tables[0].to_numpy(), tables[1].to_numpy(), rtol=1e-9, atol=1e-9)
    # the angles read (low-passed at 6 Hz, as a recording is) are the file's, in radians inside
    np.testing.assert_allclose(np.radians(tables[0]["r_elbow_flex"]), z[:, 1], atol=2e-4)
    assert "--motion: " in runs[0].stderr and "ignored: pelvis_tx" in runs[0].stderr
    assert "ignored" not in runs[1].stderr
    quiet = invoke("inverse", "--model", ARM26, "--motion", degrees, "--quiet")
    assert quiet.stderr == ""


def test_a_mot_without_a_coordinate_is_refused_naming_it(tmp_path):
    t = np.linspace(0.0, 1.0, 11)
    path = write_storage(tmp_path / "half.mot", t, {"r_shoulder_elev": 10 * t}, True)
    out = tmp_path / "out.csv"
    refused("inverse", "--model", ARM26, "--motion", path, "-o", out, contains=("half.mot", "'r_elbow_flex'"))
    assert not out.exists()
    refused("inverse", "--model", ARM26, "--motion", tmp_path / "none.mot", contains=("none.mot",))
    no_header = tmp_path / "plain.mot"
    no_header.write_text("time\tr_shoulder_elev\tr_elbow_flex\n0\t0\t0\n1\t1\t1\n")
    refused("inverse", "--model", ARM26, "--motion", no_header, contains=("endheader",))


# ---------------------------------------------------------------- bad models


def ball_model(path: Path) -> Path:
    return osim_file(path, [body("head", 4.0, (0, 0.1, 0), (0.02, 0.02, 0.02, 0, 0, 0))],
                     [joint("BallJoint", "neck", "ground", "head", [("neck_x", 0, False), ("neck_y", 0, False),
                                                                    ("neck_z", 0, False)])])


def coupled_model(path: Path) -> Path:
    """Two pins whose coordinates a constraint couples."""
    constraint = ('<ConstraintSet name="constraintset"><objects><CoordinateCouplerConstraint name="couple">'
                  "<independent_coordinate_names>shoulder</independent_coordinate_names>"
                  "<dependent_coordinate_name>elbow</dependent_coordinate_name><coupled_coordinates_function>"
                  "<LinearFunction><coefficients>1 0</coefficients></LinearFunction></coupled_coordinates_function>"
                  "</CoordinateCouplerConstraint></objects></ConstraintSet>")
    segment = lambda name: body(name, 1.0, (0.1, 0, 0), (0.01, 0.01, 0.01, 0, 0, 0))  # noqa: E731
    return osim_file(path, [segment("upper"), segment("lower")],
                     [joint("PinJoint", "j1", "ground", "upper", [("shoulder", 0.0, False)]),
                      joint("PinJoint", "j2", "upper", "lower", [("elbow", 0.0, False)], (0.3, 0, 0))], extra=constraint)


@pytest.mark.parametrize("case", ["not xml", "no model", "ball joint", "missing", "path knee", "tilt", "constraint"])
def test_bad_models_are_refused_in_one_line_and_nothing_is_written(tmp_path, case):
    path = tmp_path / "model.osim"
    expected = {"not xml": "not valid XML", "no model": "not an OpenSim model file", "ball joint": "'neck' (BallJoint)",
                "missing": "does not exist",
                "path knee": "'knee' (CustomJoint) has a PiecewiseLinearFunction as translation1 of 'knee_angle'",
                "tilt": "'r_elbow' (CustomJoint) has its axis 3.52 deg off",
                "constraint": "constraint 'couple' (CoordinateCouplerConstraint)"}[case]
    args = ()
    if case == "not xml":
        path.write_text("<OpenSimDocument><Model name='x'>")
    elif case == "no model":
        path.write_text("<?xml version='1.0'?><Storage/>")
    elif case == "ball joint":
        ball_model(path)
    elif case == "path knee":
        path_knee_model(path, spline="<PiecewiseLinearFunction><x> -2 0 1</x><y> 0 0.01 0</y>"
                                     "</PiecewiseLinearFunction>")
    elif case == "constraint":
        coupled_model(path)
    elif case == "tilt":
        path, args = ARM26, ("--max-tilt", "3")
    out = tmp_path / "out.toml"
    refused("import-osim", path, "-o", out, *args, contains=(expected,))
    assert not out.exists()
    if case != "tilt":
        refused("inverse", "--model", path, "-o", out, contains=(expected,))
        assert not out.exists()


# ---------------------------------------------------------------- names in messages


def test_an_endless_body_name_gives_a_short_line(tmp_path):
    name = "b" * 100_000
    path = osim_file(tmp_path / "long.osim", [body(name, 1.0, (0.1, 0, 0), (0.01, 0.01, 0.01, 0, 0, 0))],
                     [joint("PinJoint", "j1", "ground", name, [("q1", 0.0, False)])])
    line = refused("models", "show", path,
                   contains=("long.osim", "'" + "b" * 80 + "...'", "is not a name fdbench accepts"))
    assert len(line) < 300


def test_a_spline_with_knots_out_of_order_names_its_joint_and_coordinate(tmp_path):
    path = path_knee_model(tmp_path / "knee_nonmono.osim",
                           spline="<SimmSpline><x> -2 0 -1 1</x><y> -0.01 -0.005 0 0.001</y></SimmSpline>")
    out = tmp_path / "out.toml"
    refused("import-osim", path, "-o", out, contains=("knee_nonmono.osim", "joint 'knee' (CustomJoint)",
                                                      "coordinate 'knee_angle'",
                                                      "knots (-2 0 -1 1) are not strictly increasing"))
    assert not out.exists()


def random_states(model, count: int, seed: int):
    """count random (z, z', z''), each (count, J): angles in [-1, 0.15] rad (the knees' range), the
    translations about their defaults, rates up to 3 (rad or m)/s, accelerations up to 20 /s^2."""
    rng = np.random.default_rng(seed)
    shape = (count, model.n_joints)
    return rng.uniform(-1.0, 0.15, shape), rng.uniform(-3, 3, shape), rng.uniform(-20, 20, shape)


def test_a_free_pelvis_and_a_knee_on_a_path_import_with_opensim_s_inverse_dynamics(tmp_path):
    """OpenSim's PlanarJoint becomes a free joint (angle, x, y) and a CustomJoint whose translations
    are a SimmSpline and a LinearFunction (scaled by a MultiplierFunction) of the knee angle a pin
    on a path; fdbench's inverse dynamics equals OpenSim's to 1e-9 relative."""
    knee_y = ("<MultiplierFunction><function><LinearFunction><coefficients> 0.02 -0.001</coefficients>"
              "</LinearFunction></function><scale>1.5</scale></MultiplierFunction>")
    path = path_knee_model(tmp_path / "knee.osim", knee_y=knee_y)
    model, _ = import_osim(path)
    hip, knee = model.joints
    assert (hip.type, hip.coordinates, hip.parent) == ("free", ("pelvis_tilt", "pelvis_tx", "pelvis_ty"), "ground")
    assert model.coordinates == ("pelvis_tilt", "pelvis_tx", "pelvis_ty", "knee_angle")
    assert model.coordinate_kinds == ("angle", "translation", "translation", "angle")
    assert knee.path.angles == (-2.0, -1.0, 0.0, 1.0) and knee.path.x == (-0.01, -0.005, 0.0, 0.001)
    assert knee.path.y_angles == (-1.0, 1.0)  # the line through its values at -1 and 1, scaled by 1.5
    assert knee.path.y == pytest.approx((1.5 * (-0.001 - 0.02), 1.5 * (-0.001 + 0.02)), abs=1e-15)
    z, zd, zdd = random_states(model, 8, seed=3)
    ours = Engine(model).inverse_dynamics(z, zd, zdd)
    theirs = opensim_inverse_dynamics(path, model.coordinates, z, zd, zdd)
    assert np.abs(ours - theirs).max() < 1e-9 * np.abs(theirs).max()


@pytest.mark.skipif(not SUBJECT01.exists(), reason="the shared data folder is not beside the source folder")
def test_the_gait_model_imports_with_opensim_s_inverse_dynamics(tmp_path):
    """subject01.osim: the pelvis a free joint, the knees pins on OpenSim's splines (x and y with their
    own knots), muscles kept; its inverse dynamics equals OpenSim's InverseDynamicsSolver's to
    1e-9 relative on random states (forces up to about 2 kN)."""
    model, notes = import_osim(SUBJECT01)
    assert model.coordinates == ("pelvis_tilt", "pelvis_tx", "pelvis_ty", "hip_flexion_r", "hip_flexion_l",
                                 "lumbar_extension", "knee_angle_r", "knee_angle_l", "ankle_angle_r", "ankle_angle_l")
    assert model.joints[0].type == "free" and model.joints[0].name == "ground_pelvis"
    knees = [j for j in model.joints if j.name.startswith("knee")]
    assert len(knees) == 2 and all(len(j.path.angles) == 12 and len(j.path.y_angles) == 7 for j in knees)
    assert notes[0] == "dropped 39 markers" and len(model.muscles) == 18
    z, zd, zdd = random_states(model, 5, seed=0)
    ours = Engine(model).inverse_dynamics(z, zd, zdd)
    theirs = opensim_inverse_dynamics(SUBJECT01, model.coordinates, z, zd, zdd)
    assert np.abs(ours - theirs).max() < 1e-9 * np.abs(theirs).max()


OPENSIM_SPLINE = """
out = []
for x, y in request["samples"]:
    spline = osim.SimmSpline()
    for a, b in zip(x, y):
        spline.addPoint(a, b)
    values = []
    for t in request["at"]:
        v = osim.Vector(1, t)
        values.append([spline.calcValue(v)] + [spline.calcDerivative(osim.StdVectorInt([0] * k), v) for k in (1, 2)])
    out.append(values)
print(json.dumps(out))
"""


def test_the_path_spline_is_opensim_s_simmspline():
    """fdbench.multibody.spline against OpenSim's own SimmSpline (calcValue, calcDerivative of orders
    1 and 2) on random samples of 2 to 12 knots, inside and beyond the knots (its end slopes), to 1e-12
    of the values' scale."""
    from fdbench.multibody.spline import fit

    rng = np.random.default_rng(7)
    samples = []
    for n in (2, 3, 4, 5, 7, 12):
        x = np.cumsum(rng.uniform(0.05, 0.8, n)) - 2.0
        samples.append((x.tolist(), rng.normal(0, 0.03, n).tolist()))
    at = np.linspace(-2.5, 6.0, 121).tolist()
    theirs = np.array(run_opensim(OPENSIM_SPLINE, {"samples": samples, "at": at}, timeout=300))  # (splines, points, order)
    for (x, y), expected in zip(samples, theirs):
        spline = fit(x, y)
        ours = np.stack([spline.evaluate(at, order) for order in range(3)], axis=-1)
        one_by_one = np.array([spline.at(t) for t in at])  # the simulation's path
        scale = np.abs(expected).max(axis=0)
        for values in (ours, one_by_one):
            assert np.all(np.abs(values - expected) <= 1e-12 * scale), (len(x), np.abs(values - expected).max(axis=0))


def test_import_osim_never_writes_over_its_input(tmp_path):
    copy = tmp_path / "arm26.osim"
    copy.write_bytes(ARM26.read_bytes())
    refused("import-osim", copy, "-o", copy)
    assert copy.read_bytes() == ARM26.read_bytes()
    refused("import-osim", ARM26, "--max-tilt", "-1", contains=("--max-tilt",))


def test_without_opensim_the_import_names_the_extra_to_install(tmp_path, monkeypatch):
    path = forearm_osim(tmp_path / "fresh.osim")  # content no import has cached
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "opensim.py").write_text("raise ImportError('No module named opensim')\n")  # the child's opensim
    monkeypatch.syspath_prepend(str(hidden))  # the children import what this process would
    for args in (("import-osim", path), ("inverse", "--model", path), ("models", "show", path)):
        refused(*args, contains=("pip install 'fdbench[opensim]'",))


def test_the_paper_s_forearm_reads_a_mot_as_its_csv(tmp_path):
    t = np.linspace(0.0, 1.0, 201)
    theta = -45.0 * t**2  # deg
    storage = write_storage(tmp_path / "flexion.mot", t, {"theta": theta}, True)
    plain = tmp_path / "flexion.csv"
    plain.write_text("t,theta\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, theta)))
    runs = [invoke("inverse", "--motion", path, "--format", "csv", "--quiet").stdout for path in (storage, plain)]
    assert runs[0] == runs[1]


# ---------------------------------------------------------------- fdbench's models out (export-osim)


def swing(model, samples: int = 51):
    """The model's first motion, or (the forearm has none) every joint from -0.5 to 1.2 rad, in 1 s."""
    spec = model.motions[0] if model.motions else MotionSpec(
        "swing", "minimum-jerk", 1.0, tuple((j, -0.5) for j in model.coordinates),
        tuple((j, 1.2) for j in model.coordinates))
    return MinimumJerk(spec, model.coordinates)(np.linspace(0.0, spec.duration, samples))


@pytest.mark.parametrize("name", ["forearm", "arm2", "leg3"])
def test_an_exported_model_has_opensim_s_inverse_dynamics_and_imports_back(tmp_path, name):
    """OpenSim's InverseDynamicsSolver on the written file (its forces kept: the hand load's
    PrescribedForce, and actuators at zero control) equals fdbench's engine; the file imported
    back gives the same model and torques."""
    model = find_model(name)
    path = tmp_path / f"{name}.osim"
    path.write_text(to_osim(model))
    z, zd, zdd = swing(model)
    ours = Engine(model).inverse_dynamics(z, zd, zdd)
    theirs = opensim_inverse_dynamics(path, model.coordinates, z, zd, zdd, keep_forces=True)
    assert np.abs(theirs).max() > 1.0
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=1e-6)
    if model.loads:  # the load is in the file: without its force OpenSim's torques lack the hand's moment
        unloaded = opensim_inverse_dynamics(path, model.coordinates, z, zd, zdd)
        assert np.abs(unloaded - theirs).max() > 1.0
    back, notes = import_osim(path)
    assert back.loads == model.loads and back.gravity == model.gravity
    # a body's end point of natural coordinates is not OpenSim's: the import puts one only where needed
    assert [replace(b, end=None) for b in back.bodies] == [replace(b, end=None) for b in model.bodies]
    assert [replace(j, limits=None) for j in back.joints] == [replace(j, limits=None) for j in model.joints]
    # a model without [[actuators]] is written with one of 1 N m per joint, read back as its actuators
    assert back.actuators == tuple(Actuator(f"{j}_actuator", j, 1.0) for j in model.coordinates) and notes == ()
    np.testing.assert_allclose(Engine(back).inverse_dynamics(z, zd, zdd), ours, rtol=0, atol=1e-9)


def test_a_model_s_actuators_are_written_and_read_back_with_their_optimal_force(tmp_path):
    """arm2 with an actuator on the elbow: export-osim writes it alone with its optimal force; a
    second one on the elbow is left out with a note, an ActivationCoordinateActuator kept."""
    model = replace(find_model("arm2"), actuators=(Actuator("elbow_motor", "elbow", 12.5),))
    text = to_osim(model)
    assert text.count("<CoordinateActuator ") == 1
    extra = ('<CoordinateActuator name="again"><coordinate>elbow</coordinate><optimal_force>3</optimal_force>'
             '</CoordinateActuator><ActivationCoordinateActuator name="hip"><coordinate>shoulder</coordinate>'
             "<optimal_force>7</optimal_force></ActivationCoordinateActuator></objects></ForceSet>")
    path = tmp_path / "arm2.osim"
    path.write_text(text.replace("</objects></ForceSet>", extra))
    back, notes = import_osim(path)
    assert back.actuators == (Actuator("elbow_motor", "elbow", 12.5), Actuator("hip", "shoulder", 7.0))
    assert notes == ("dropped coordinate actuators: 'again' ('elbow' already has one)",)


def test_export_osim_writes_the_file_or_stdout_and_never_over_an_input(tmp_path):
    out = tmp_path / "arm2.osim"
    result = invoke("export-osim", "arm2", "-o", out, "--quiet")
    assert result.stdout == "" and result.stderr == ""
    assert out.read_text() == to_osim(find_model("arm2"))
    assert invoke("export-osim", "arm2").stdout == out.read_text()  # stdout without -o
    assert "wrote" in invoke("export-osim", "arm2", "-o", tmp_path / "again.osim").stderr
    model_file = tmp_path / "mine.toml"
    model_file.write_text(invoke("models", "show", "forearm", "--format", "toml").stdout)
    before = model_file.read_bytes()
    refused("export-osim", model_file, "-o", model_file, contains=("--output",))
    assert model_file.read_bytes() == before
    library_file = library()["arm2"]
    library_bytes = library_file.read_bytes()
    refused("export-osim", "arm2", "-o", library_file, contains=("--output",))
    assert library_file.read_bytes() == library_bytes
    refused("export-osim", "nope", "-o", tmp_path / "nope.osim", contains=("NAME|FILE", "arm2"))
    assert not (tmp_path / "nope.osim").exists()


OPENSIM_FORWARD = """
model = osim.Model(request["path"])
# each coordinate's <joint>_actuator, optimal force 1 N m: the control is the torque
actuators = [model.getActuators().get(name + "_actuator") for name in request["coordinates"]]
prescribe(model, actuators, request["torque"], request["t"], name="torques")
state = model.initSystem()
coordinates = [model.getCoordinateSet().get(name) for name in request["coordinates"]]
for coordinate, angle, rate in zip(coordinates, request["z0"], request["zd0"]):
    coordinate.setValue(state, angle, False)
    coordinate.setSpeedValue(state, rate)
state.setTime(request["t"][0])
print(json.dumps(integrate(model, state, request["accuracy"], request["t"],
                           lambda state: [coordinate.getValue(state) for coordinate in coordinates])))
"""


def opensim_forward(path: Path, coordinates, t, torque, z0, zd0, accuracy: float = 1e-10) -> np.ndarray:
    """OpenSim's forward simulation of the exported model at ``path`` from the angles z0 (rad) and
    rates zd0 (rad/s), each coordinate's ``<joint>_actuator`` driven by a PrescribedController with
    the torques (N m, shape (n, J)) at times t (s, shape (n,)) linear between them; its Manager
    (Runge-Kutta-Merson at ``accuracy``) stepped to every time; the angles (rad), shape (n, J), in
    a child process."""
    request = {"path": str(path), "coordinates": list(coordinates), "t": np.asarray(t).tolist(),
               "torque": np.asarray(torque).T.tolist(), "z0": np.asarray(z0).tolist(),
               "zd0": np.asarray(zd0).tolist(), "accuracy": accuracy}
    return np.array(run_opensim(OPENSIM_FORWARD, request, timeout=300))


FOREARM_SWING = MotionSpec("swing", "minimum-jerk", 1.0, (("theta", -0.5),), (("theta", 0.3),))


# Largest angle difference (deg) over 1 s, OpenSim (accuracy 1e-10; 1e-9 and 1e-12 change the
# figures by less than 1 %) against fdbench (RK4, dt 1e-4 s), measured:
#   forearm, -0.5 to 0.3 rad:  alpha 1e7: 2.7e-5 deg;  alpha 1e9: 6.8e-7 deg
#   arm2, reach (shoulder, elbow): alpha 1e7: 1.5e-3, 1.3e-2 deg;  alpha 1e9: 1.7e-5, 1.4e-4 deg
# Open loop, both drift from the motion alike (arm2: 0.33 deg at the elbow).
@pytest.mark.parametrize("name, spec, bound_1e7, bound_1e9", [
    ("forearm", FOREARM_SWING, 1e-4, 3e-6),
    ("arm2", None, 0.04, 5e-4),
])
def test_opensim_s_forward_simulation_of_an_exported_model_agrees_with_fdbench_s(tmp_path, name, spec, bound_1e7,
                                                                                 bound_1e9):
    """Under the same torque history (fdbench's inverse dynamics of the motion every 1 ms, linear
    between samples), OpenSim's forward simulation of the exported model and fdbench's open-loop
    simulation agree to the penalty formulation's accuracy: closer at alpha 1e9 than at 1e7 (about
    1/alpha)."""
    model = find_model(name)
    motion = MinimumJerk(spec or model.motions[0], model.coordinates)
    t = motion.samples
    desired, rates, _ = motion(t)
    torque = Engine(model).inverse_dynamics(*motion(t))
    history = lambda ts: np.stack([np.interp(ts, t, column) for column in torque.T], -1)  # noqa: E731
    path = tmp_path / f"{name}.osim"
    path.write_text(to_osim(model))
    theirs = opensim_forward(path, model.coordinates, t, torque, desired[0], rates[0])
    assert theirs.shape == desired.shape and t[-1] == 1.0
    assert np.degrees(np.abs(theirs - desired).max()) < 1.0  # OpenSim follows the torques along the motion
    differences = {}
    for alpha in (1e7, 1e9):
        ours = simulate(history, Engine(model, alpha=alpha), motion, dt=1e-4)
        assert ours.success
        differences[alpha] = np.degrees(np.abs(ours.z - theirs).max())
    assert differences[1e7] < bound_1e7 and differences[1e9] < bound_1e9, differences
    assert differences[1e9] < differences[1e7] / 20, differences


@pytest.mark.skipif(not SUBJECT01.exists(), reason="the shared data folder is not beside the source folder")
def test_the_walk_s_mot_reads_angles_in_degrees_and_the_pelvis_translations_in_metres():
    """subject01_walk_IK.mot (inDegrees=yes): its angles become radians, pelvis_tx and pelvis_ty stay
    in metres (OpenSim's convention), checked against the file's own numbers (to the smoothing of
    the derivative estimate: a wrong unit would be off by a factor of 57)."""
    from fdbench.multibody.motions import joint_motion

    model, _ = import_osim(SUBJECT01)
    path = SUBJECT01.with_name("subject01_walk_IK.mot")
    table = pd.read_csv(path, sep=r"\s+", skiprows=next(i for i, line in enumerate(path.read_text().splitlines())
                                                          if line.strip() == "endheader") + 1)
    motion = joint_motion(str(path), model)
    z, _, _ = motion(table["time"].to_numpy())
    for k, (name, kind) in enumerate(zip(model.coordinates, model.coordinate_kinds)):
        expected = table[name].to_numpy() * (1.0 if kind == "translation" else math.pi / 180)
        assert np.abs(z[:, k] - expected).max() < (0.005 if kind == "translation" else 0.03), name  # m, rad


def test_export_osim_refuses_free_and_path_joints_and_writes_nothing(tmp_path):
    model, _ = import_osim(path_knee_model(tmp_path / "knee.osim"))
    source = tmp_path / "knee.toml"
    from fdbench.multibody.model_files import to_toml

    source.write_text(to_toml(model))
    out = tmp_path / "out.osim"
    refused("export-osim", source, "-o", out, contains=("hip, knee", "free or on a path", "pin joints only"))
    assert not out.exists()
