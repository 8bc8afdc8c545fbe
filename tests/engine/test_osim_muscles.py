"""OpenSim's muscles in (``fdbench.multibody.osim_muscles``): their parameters against the .osim
file read independently (xml.etree), their paths against OpenSim's own getLength and
computeMomentArm (in a child process: OpenSim's bundled CasADi cannot share a process with the
casadi package the suite imports), a planar path of points against its closed form, and the
library's arm26 without OpenSim."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.osim_files import body, joint, osim_file
from helpers.paths import ROOT
from helpers.opensim_child import run_opensim
from fdbench.cli import app
from fdbench.models import find_model
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.multibody.muscles import PointPath, PolynomialPath
from fdbench.multibody.osim import import_osim

if importlib.util.find_spec("opensim") is None:
    pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')", allow_module_level=True)

ARM26 = ROOT / "examples" / "opensim" / "arm26.osim"
SMOOTH = ("TRIlat", "TRImed", "BICshort", "BRA")  # arm26's muscles whose OpenSim paths are smooth
runner = CliRunner()

OPENSIM_PATHS = """
model = osim.Model(request["path"])
state = model.initSystem()
coordinates = [model.getCoordinateSet().get(name) for name in request["coordinates"]]
muscles = [model.getMuscles().get(i) for i in range(model.getMuscles().getSize())]
lengths, arms = [], []
for row in request["q"]:
    for coordinate, value in zip(coordinates, row):
        coordinate.setValue(state, value, False)
    model.realizePosition(state)
    lengths.append([m.getLength(state) for m in muscles])
    arms.append([[m.computeMomentArm(state, c) for c in coordinates] for m in muscles])
print(json.dumps({"names": [m.getName() for m in muscles], "lengths": lengths, "arms": arms}))
"""


def opensim_paths(path: Path, coordinates, q) -> tuple[list, np.ndarray, np.ndarray]:
    """(muscle names, lengths (n, M) m, moment arms (n, M, J) m) by OpenSim at the states q (n, J)."""
    request = {"path": str(path), "coordinates": list(coordinates), "q": np.asarray(q).tolist()}
    answer = run_opensim(OPENSIM_PATHS, request, timeout=300)
    return answer["names"], np.array(answer["lengths"]), np.array(answer["arms"])


@pytest.fixture(scope="module")
def arm26():
    return import_osim(ARM26)


def test_arm26_muscles_are_de_groote_muscles_with_the_file_s_parameters(arm26):
    model, _ = arm26
    xml = ET.parse(ARM26).getroot().find("Model")
    found = {m.get("name"): m for m in xml.iter("Thelen2003Muscle")}
    assert [m.name for m in model.muscles] == list(found)
    number = lambda element, key: float(element.findtext(key))  # noqa: E731
    for muscle in model.muscles:
        element = found[muscle.name]
        assert (muscle.max_isometric_force, muscle.optimal_fiber_length, muscle.tendon_slack_length,
                muscle.pennation_angle, muscle.max_contraction_velocity) == tuple(
            number(element, key) for key in ("max_isometric_force", "optimal_fiber_length", "tendon_slack_length",
                                             "pennation_angle_at_optimal", "max_contraction_velocity"))
        # replaceMuscles: Thelen's time constants, FmaxTendonStrain and FmaxMuscleStrain, no damping;
        # ignore_tendon_compliance absent (false): a compliant tendon
        assert (muscle.activation_time, muscle.deactivation_time, muscle.tendon_strain, muscle.passive_strain) == (
            number(element, "activation_time_constant"), number(element, "deactivation_time_constant"),
            number(element, "FmaxTendonStrain"), number(element, "FmaxMuscleStrain"))
        assert muscle.fiber_damping == 0 and muscle.tendon == "compliant"
        assert isinstance(muscle.path, PolynomialPath)  # every arm26 path wraps


def test_the_library_s_arm26_is_the_import_of_the_example_file(arm26):
    """The library's arm26 is the import of examples/opensim/arm26.osim: the same muscles, their
    paths' polynomials in the same coordinates and powers, whose least-squares coefficients a
    machine's rounding may move (the high powers' are ill-conditioned) while the paths' lengths and
    moment arms stay within 1e-9 m (1e-8 m) over the coordinates' ranges."""
    model, notes = arm26
    library = find_model("arm26")
    assert [dataclasses.replace(m, path=None) for m in library.muscles] == \
        [dataclasses.replace(m, path=None) for m in model.muscles]
    for ours, imported in zip(library.muscles, model.muscles):
        assert ours.path.coordinates == imported.path.coordinates
        assert [t.powers for t in ours.path.terms] == [t.powers for t in imported.path.terms]
    assert tuple(library.coordinates) == ("r_shoulder_elev", "r_elbow_flex")
    q = np.random.default_rng(0).uniform([-1.5708, 0.0], [3.14159, 2.26893], (200, 2))  # arm26.osim's ranges (rad)
    (ours, our_arms), (imported, imported_arms) = (muscle_geometry(m, q) for m in (library, model))
    np.testing.assert_allclose(ours, imported, rtol=0, atol=1e-9)
    np.testing.assert_allclose(our_arms, imported_arms, rtol=0, atol=1e-8)
    text = (ROOT / "fdbench" / "models" / "library" / "arm26.toml").read_text()
    assert all(f"# note: {note}" in text for note in notes)  # the errors of the fits travel with it


def test_arm26_fitted_paths_against_opensim_at_200_random_states(arm26, capsys):
    """Per muscle the worst length and moment-arm errors of the library's arm26 against OpenSim at
    200 random states within the ranges. The four smooth paths: lengths within 1 mm and moment arms
    within 2 mm. TRIlong and BIClong: OpenSim's own lengths jump (by 8 mm) and their moment arms
    turn abruptly where their wrapping switches (TRIlong's above 40 deg of shoulder elevation); the
    fitted path is smooth and follows the largest part of the range between jumps: its length within
    1 mm at half the states, its moment arms within 2 mm at most and within 20 mm at all."""
    model = find_model("arm26")
    ranges = np.array([joint.limits for joint in model.joints])
    q = ranges[:, 0] + np.random.default_rng(7).random((200, 2)) * np.diff(ranges, axis=1)[:, 0]
    names, lengths, arms = opensim_paths(ARM26, model.coordinates, q)
    ours, our_arms = muscle_geometry(model, q)
    assert names == [m.name for m in model.muscles]
    length_error = np.abs(ours - lengths)
    arm_error = np.abs(our_arms - arms).max(axis=2)
    with capsys.disabled():
        print("\nmuscle     worst length (mm)  worst moment arm (mm)  states within 1 mm, 2 mm")
        for m, name in enumerate(names):
            print(f"{name:<10} {length_error[:, m].max() * 1e3:17.3f}  {arm_error[:, m].max() * 1e3:21.3f}  "
                  f"{np.mean(length_error[:, m] <= 1e-3):6.0%} {np.mean(arm_error[:, m] <= 2e-3):6.0%}")
    for m, name in enumerate(names):
        if name in SMOOTH:
            assert length_error[:, m].max() <= 1e-3 and arm_error[:, m].max() <= 2e-3, name
        else:
            assert np.mean(length_error[:, m] <= 1e-3) >= 0.5 and np.mean(arm_error[:, m] <= 2e-3) >= 0.6, name
            assert arm_error[:, m].max() <= 0.02, name


def planar_muscles_model(path: Path) -> Path:
    """Two bodies on pins about z and a third welded to the second (moved by (0.1, 0.2) and turned
    90 deg about z); muscle 'flexor' on points of ground, the first body and the welded one, all at
    z = 0.05; muscle 'skew' with one point off that plane (z = 0.45): fitted."""
    points = lambda name, items: "".join(  # noqa: E731
        f'<PathPoint name="{name}{i}"><socket_parent_frame>{frame}</socket_parent_frame>'
        f"<location>{' '.join(map(repr, map(float, at)))}</location></PathPoint>" for i, (frame, at) in enumerate(items))
    muscle = lambda name, items: (  # noqa: E731
        f'<Thelen2003Muscle name="{name}"><GeometryPath name="path"><PathPointSet><objects>{points(name, items)}'
        "</objects></PathPointSet></GeometryPath><max_isometric_force>300</max_isometric_force>"
        "<optimal_fiber_length>0.1</optimal_fiber_length><tendon_slack_length>0.2</tendon_slack_length>"
        "<pennation_angle_at_optimal>0.1</pennation_angle_at_optimal></Thelen2003Muscle>")
    forces = ('<ForceSet name="forceset"><objects>'
              + muscle("flexor", [("/ground", (0.05, 0.3, 0.05)), ("/bodyset/upper", (0.25, -0.02, 0.05)),
                                  ("/bodyset/hand", (0.03, 0.01, 0.05))])
              + muscle("skew", [("/ground", (0.05, 0.3, 0.45)), ("/bodyset/upper", (0.25, -0.02, 0.05))])
              + "</objects></ForceSet>")
    inertia = (0.01, 0.01, 0.01, 0, 0, 0)
    return osim_file(path, [body("upper", 2.0, (0.15, 0, 0), inertia), body("lower", 1.0, (0.1, 0, 0), inertia),
                            body("hand", 0.5, (0.05, 0, 0), inertia)],
                     [joint("PinJoint", "shoulder", "ground", "upper", [("q1", 0.0, False)]),
                      joint("PinJoint", "elbow", "upper", "lower", [("q2", 0.0, False)], parent_at=(0.3, 0, 0)),
                      joint("WeldJoint", "wrist", "lower", "hand", parent_at=(0.1, 0.2, 0),
                            parent_rotation=(0, 0, math.pi / 2))], extra=forces)


def test_a_planar_path_of_points_comes_out_exactly_and_another_is_fitted(tmp_path):
    model, notes = import_osim(planar_muscles_model(tmp_path / "planar.osim"))
    flexor, skew = model.muscles
    # the welded hand's point in the lower body's frame: (0.1, 0.2) + R(90 deg) (0.03, 0.01)
    assert isinstance(flexor.path, PointPath)
    assert [p.body for p in flexor.path.points] == ["ground", "upper", "lower"]
    expected = [(0.05, 0.3), (0.25, -0.02), (0.1 - 0.01, 0.2 + 0.03)]
    for point, at in zip(flexor.path.points, expected):
        assert point.at == pytest.approx(at, abs=1e-15)
    assert (flexor.max_isometric_force, flexor.optimal_fiber_length, flexor.tendon_slack_length,
            flexor.pennation_angle) == (300, 0.1, 0.2, 0.1)
    assert isinstance(skew.path, PolynomialPath) and skew.path.coordinates == ("q1",)
    # the skew path's closed form: from (0.05, 0.3, 0.45) in ground to the upper body's point at z = 0.05
    q = np.linspace(-3, 3, 13)
    point = np.stack([0.25 * np.cos(q) + 0.02 * np.sin(q), 0.25 * np.sin(q) - 0.02 * np.cos(q)], axis=1)
    closed = np.sqrt(((point - [0.05, 0.3]) ** 2).sum(axis=1) + 0.4**2)
    lengths, _ = muscle_geometry(model, np.stack([q, np.zeros_like(q)], axis=1))
    assert np.max(np.abs(lengths[:, 1] - closed)) < 1e-4  # FIT_TARGET
    assert any("flexor (Thelen2003Muscle, points)" in note for note in notes)


def test_max_path_error_refuses_a_fit_beyond_it_naming_the_muscle(tmp_path):
    path = planar_muscles_model(tmp_path / "planar.osim")
    result = runner.invoke(app, ["import-osim", str(path), "--max-path-error", "1e-9"])
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "muscle 'skew'" in lines[0] and "--max-path-error" in lines[0]
    result = runner.invoke(app, ["import-osim", str(path), "--max-path-error", "0"])
    assert result.exit_code == 2 and "--max-path-error" in result.stderr


def test_the_library_s_arm26_loads_without_opensim(tmp_path):
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "opensim.py").write_text("raise ImportError('No module named opensim')\n")
    code = ("import sys; sys.path.insert(0, sys.argv[1]); from fdbench.models import find_model; "
            "m = find_model('arm26'); print(len(m.muscles), m.coordinates)")
    done = subprocess.run([sys.executable, "-c", code, str(hidden)], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[0] == "6"
