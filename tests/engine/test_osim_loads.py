"""External loads checked against OpenSim: the recorded walk's generalised forces with its ground
reactions (``fdbench inverse --model subject01.osim --loads subject01_walk_grf.xml``), the pelvis'
residuals included, against OpenSim's InverseDynamicsSolver on the same model (muscles removed)
with the same ExternalLoads file, at the same kinematics; the same data in body frames (a welded
body's, a moving body's) likewise. OpenSim runs in one child process."""

from __future__ import annotations

import importlib.util
import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from helpers.paths import ROOT
from helpers.opensim_child import run_opensim
from fdbench.cli import app

if importlib.util.find_spec("opensim") is None:
    pytest.skip("the opensim package is not installed (pip install '.[opensim]')", allow_module_level=True)

PLACES = (ROOT / "examples" / "opensim", ROOT.parent / "shared" / "data" / "opensim",
          ROOT.parent.parent / "shared" / "data" / "opensim")  # the walk's files: shipped, or beside the source
DATA = next((where for where in PLACES if (where / "subject01_walk_grf.xml").exists()), PLACES[0])
pytestmark = pytest.mark.skipif(not (DATA / "subject01_walk_grf.xml").exists(),
                                reason="the walk's files are not found")
TRANSLATIONS = ("pelvis_tx", "pelvis_ty")
runner = CliRunner()

OPENSIM_ID_WITH_LOADS = """
answers = []
for loads in request["loads"]:  # one model per case: with the ExternalLoads file, or none ('')
    model = osim.Model(request["model"])
    model.updForceSet().clearAndDestroy()
    if loads:
        model.addModelComponent(osim.ExternalLoads(loads, True))
    state = model.initSystem()
    found = [model.getCoordinateSet().get(name) for name in request["coordinates"]]
    index = []
    for coordinate in found:  # the coordinate's place among the system's speeds
        coordinate.setSpeedValue(state, 1.0)
        index.append(next(i for i in range(state.getNU()) if state.getU().get(i) == 1.0))
        coordinate.setSpeedValue(state, 0.0)
    solver = osim.InverseDynamicsSolver(model)
    out = []
    for t, angles, rates, accelerations in zip(request["t"], request["z"], request["zd"], request["zdd"]):
        state.setTime(t)
        udot = osim.Vector(state.getNU(), 0.0)
        for coordinate, k, angle, rate, acceleration in zip(found, index, angles, rates, accelerations):
            coordinate.setValue(state, angle, False)
            coordinate.setSpeedValue(state, rate)
            udot.set(k, acceleration)
        model.realizeVelocity(state)
        tau = solver.solve(state, udot)
        out.append([tau.get(k) for k in index])
    answers.append(out)
print(json.dumps(answers))
"""


def fdbench(*args) -> str:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.stderr
    return result.stdout


def walk_inverse(*extra, motion=None, loads=None) -> str:
    return fdbench("inverse", "--model", DATA / "subject01.osim", "--motion", motion or DATA / "subject01_walk_IK.mot",
                   "--loads", loads or DATA / "subject01_walk_grf.xml", "--quiet", *extra)


def coordinates_of(frame: pd.DataFrame) -> list[str]:
    return [c for c in frame.columns[1:] if not c.endswith(("_vel", "_acc", "_torque"))]


def in_si(frame: pd.DataFrame, names, suffix: str) -> np.ndarray:
    """The columns <name><suffix> (deg-based for angles, m for translations) in rad or m, shape (n, J)."""
    unit = np.array([1.0 if name in TRANSLATIONS else math.pi / 180 for name in names])
    return frame[[name + suffix for name in names]].to_numpy() * unit


def in_body_frames(folder: Path) -> Path:
    """The walk's ExternalLoads with the same data read as forces in calcn_r's axes (a body welded
    into talus_r on import) at points in talus_r's frame, for both feet: another load, the same
    file for OpenSim and fdbench."""
    text = (DATA / "subject01_walk_grf.xml").read_text()
    for tag, frame in (("force", "calcn_r"), ("point", "talus_r")):
        text = text.replace(f"<{tag}_expressed_in_body>ground<", f"<{tag}_expressed_in_body>{frame}<")
    text = text.replace("<datafile>subject01_walk_grf.mot<", f"<datafile>{DATA / 'subject01_walk_grf.mot'}<")
    (folder / "in_body_frames.xml").write_text(text)
    return folder / "in_body_frames.xml"


def opensim_forces(frame: pd.DataFrame, in_frames: Path) -> list[np.ndarray]:
    """OpenSim's generalised forces (n, J) (N m, N) at the kinematics of an inverse-dynamics CSV,
    with the walk's loads, with them in body frames and without loads, in one child process."""
    names = coordinates_of(frame)
    request = {"model": str(DATA / "subject01.osim"), "coordinates": names, "t": frame["t"].tolist(),
               "loads": [str(DATA / "subject01_walk_grf.xml"), str(in_frames), ""],
               **{key: in_si(frame, names, suffix).tolist()
                  for key, suffix in (("z", ""), ("zd", "_vel"), ("zdd", "_acc"))}}
    return [np.array(forces) for forces in run_opensim(OPENSIM_ID_WITH_LOADS, request, timeout=300)]


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """fdbench's inverse dynamics of the walk with its loads (the default derivative estimate) as a
    CSV, its record, and OpenSim's generalised forces at the CSV's kinematics (one child)."""
    folder = tmp_path_factory.mktemp("walk")
    csv = folder / "walk.csv"
    walk_inverse("--format", "csv", "--output", csv)
    frame = pd.read_csv(csv)
    record = json.loads(walk_inverse("--format", "json"))
    in_frames = in_body_frames(folder)
    with_loads, in_body, without = opensim_forces(frame, in_frames)
    return {"csv": csv, "frame": frame, "record": record, "opensim": with_loads, "opensim_bare": without,
            "in_frames": in_frames, "opensim_in_frames": in_body}


def rms(values) -> np.ndarray:
    return np.sqrt(np.mean(np.asarray(values) ** 2, axis=0))


def test_the_walk_s_generalised_forces_with_its_ground_reactions_are_opensim_s(walk):
    """Every coordinate, the pelvis' three residuals included, within 1% RMS of OpenSim's (measured:
    under 1e-4 relative; what is left is the ground reactions' interpolation: their file rounds its
    times to 0.1 ms, so the motion's 60 Hz times fall between samples, where OpenSim interpolates by
    splines and fdbench linearly)."""
    frame, theirs = walk["frame"], walk["opensim"]
    names = coordinates_of(frame)
    ours = frame[[name + "_torque" for name in names]].to_numpy()
    relative = rms(ours - theirs) / rms(theirs)
    assert relative.max() < 1e-3, dict(zip(names, relative))
    assert rms(theirs)[names.index("ankle_angle_r")] > 40.0  # the loads act: the stance ankle's torques are large


def test_the_record_s_residuals_are_opensim_s_pelvis_forces(walk):
    """residual_fx/fy/mz: the pelvis' generalised forces (FX, FY in N, MZ in N m), as OpenSim's RRA
    names them; their means and RMS from the record equal those of OpenSim's forces to 0.1%."""
    names = coordinates_of(walk["frame"])
    theirs, record = walk["opensim"], walk["record"]
    fx, fy, mz = (theirs[:, names.index(name)] for name in ("pelvis_tx", "pelvis_ty", "pelvis_tilt"))
    expected = {"residual_fx_mean_n": fx.mean(), "residual_fy_mean_n": fy.mean(), "residual_mz_mean_nm": mz.mean(),
                "residual_fx_rms_n": rms(fx), "residual_fy_rms_n": rms(fy), "residual_moment_rms_nm": rms(mz),
                "residual_force_rms_n": math.sqrt(np.mean(fx**2 + fy**2))}
    for key, value in expected.items():
        assert record[key] == pytest.approx(value, rel=1e-3, abs=0.05), key


def test_a_csv_with_rates_and_accelerations_is_used_as_given_and_gives_opensim_s_forces(walk):
    """The CSV read back as the motion (its _vel and _acc columns used as given): the same
    generalised forces, so again within 1% RMS of OpenSim's at those kinematics."""
    again = pd.read_csv(io.StringIO(walk_inverse("--format", "csv", motion=walk["csv"])))
    names = coordinates_of(again)
    assert np.allclose(again["t"], walk["frame"]["t"], atol=1e-7)
    for suffix in ("", "_vel", "_acc"):  # the kinematics as given
        assert np.allclose(in_si(again, names, suffix), in_si(walk["frame"], names, suffix), rtol=1e-9, atol=1e-9)
    ours = again[[name + "_torque" for name in names]].to_numpy()
    assert (rms(ours - walk["opensim"]) / rms(walk["opensim"])).max() < 1e-3


def test_without_the_loads_the_pelvis_carries_the_body_s_weight_and_opensim_agrees(walk):
    """The same kinematics without loads: pelvis_ty's mean force is then about the body's weight (72.6
    kg), far from the run with loads, and OpenSim's without loads agrees with fdbench's."""
    names = coordinates_of(walk["frame"])
    csv = walk["csv"]
    bare = pd.read_csv(io.StringIO(fdbench("inverse", "--model", DATA / "subject01.osim", "--motion", csv, "--quiet",
                                           "--format", "csv")))
    ours = bare[[name + "_torque" for name in names]].to_numpy()
    theirs = walk["opensim_bare"]
    assert (rms(ours - theirs) / rms(theirs)).max() < 1e-6
    ty = names.index("pelvis_ty")
    assert np.mean(ours[:, ty]) == pytest.approx(72.6 * 9.80665, rel=0.05)
    assert abs(np.mean(walk["opensim"][:, ty])) < 0.1 * np.mean(ours[:, ty])


def test_loads_in_a_welded_body_s_axes_and_at_points_in_a_body_s_frame_are_opensim_s(walk):
    """The same data as forces in calcn_r's axes (welded into talus_r: a named frame) at points in
    talus_r's frame, turning with the ankle: fdbench's generalised forces within 1e-3 RMS of
    OpenSim's, which differ from the walk's (the frames matter)."""
    ours_frame = pd.read_csv(io.StringIO(walk_inverse("--format", "csv", motion=walk["csv"],
                                                      loads=walk["in_frames"])))
    names = coordinates_of(ours_frame)
    ours = ours_frame[[name + "_torque" for name in names]].to_numpy()
    theirs = walk["opensim_in_frames"]
    assert (rms(ours - theirs) / rms(theirs)).max() < 1e-3
    assert (rms(theirs - walk["opensim"]) / rms(walk["opensim"])).max() > 1.0
