"""The peers with external loads (``--loads``) on a model with a floating base: OpenSim is given the
same ExternalLoads file and data as fdbench (its own reader: ``ExternalLoads`` in the model, CMCTool's
``setExternalLoadsFileName``, Moco's ``ModOpAddExternalLoads``), and the floating base's residuals
are CoordinateActuators driven like every coordinate.

A small OpenSim model (``helpers.osim_files.path_knee_model``: a free planar pelvis, a knee whose shank
follows a spline) with a recorded motion (CSV) and one load on the shank (XML + .mot, its data file
named relative to the XML, as OpenSim's examples do). Independent references: fdbench's own PD
(the same law, its own integrator), fdbench's inverse dynamics with the loads (the torques the
peers must apply), and the same runs with OpenSim given no loads (then they apply the load's
generalised force themselves: far from fdbench's reference)."""

from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from helpers.loads_files import push_files

if importlib.util.find_spec("opensim") is None:
    pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')", allow_module_level=True)

DURATION = 0.4  # s
COORDINATES = ("pelvis_tilt", "pelvis_tx", "pelvis_ty", "knee_angle")
ANGLES = ("pelvis_tilt", "knee_angle")
runner = CliRunner()


def _motion(t: np.ndarray) -> np.ndarray:
    """tilt (deg), tx, ty (m), knee (deg) at times t (s, from 0), shape (n, 4)."""
    s = np.sin(2 * np.pi * t / DURATION)
    return np.column_stack([3 * s, 0.2 * t, 1.0 + 0.01 * s, -30 - 15 * s])


def files(folder: Path, start: float = 0.0) -> list[Path]:
    """The model, its motion (recorded from ``start`` s on) and a load on the shank (its data on
    the same clock): 40 N along x and 80 N up in ground's axes at a point below the knee, and a
    free moment of 2 N m."""
    from helpers.osim_files import path_knee_model

    folder.mkdir(parents=True, exist_ok=True)
    model = path_knee_model(folder / "knee.osim")
    t = np.round(np.arange(0, DURATION + 1e-9, 0.01), 6)
    motion = folder / "motion.csv"
    with motion.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(("t",) + COORDINATES)
        writer.writerows(np.column_stack([t + start, _motion(t)]).tolist())
    loads = push_files(folder, np.arange(0, DURATION + 0.0501, 0.05) + start, (40.0, 80.0, 0.0), (0.05, 0.4, 0.0),
                       (0.0, 0.0, 2.0), datafile="data/push.mot")
    return [model, motion, loads]


def invoke(*args) -> dict:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, (result.stdout, result.stderr)
    return json.loads(result.stdout)


def common(paths, *extra) -> list:
    model, motion, loads = paths
    return ["--model", model, "--motion", motion, "--loads", loads, "-f", "json", "-q", *extra]


def trajectory(path: Path) -> dict:
    """A saved trajectory's columns (the motion file's units: deg for angles, m for translations)."""
    with path.open() as handle:
        rows = list(csv.reader(handle))
    return {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(rows[0])}


@pytest.mark.parametrize("start", [0.0, 0.5])
def test_opensim_s_pd_with_the_loads_tracks_as_fdbench_s_pd(tmp_path, start):
    """The same PD law on the pelvis's residual actuators and the knee, the load read by OpenSim
    from the same files: both reach the end and their trajectories agree within what OpenSim's
    integrator (accuracy 1e-5) and its feedforward linear between the 1 ms steps leave, as on the
    forearm (1.3e-4 deg there; measured here: 2.7e-4 deg on the knee, 2e-7 m on the pelvis): 2e-3
    deg and 1e-5 m. OpenSim's applied generalised forces are fdbench's inverse dynamics with the
    load, and the residuals on the pelvis (61 N) are fdbench's. A recording that starts at 0.5 s
    (the loads on its clock) gives the same."""
    paths = files(tmp_path, start)
    theirs = invoke("peer", "opensim", *common(paths, "--save-trajectory", tmp_path / "opensim.csv"))
    ours = invoke("control", *common(paths, "--save-trajectory", tmp_path / "fdbench.csv"))
    assert theirs["status"] == ours["status"] == "success", (theirs["message"], ours["message"])
    assert theirs["t_end"] == pytest.approx(DURATION)
    a, b = trajectory(tmp_path / "opensim.csv"), trajectory(tmp_path / "fdbench.csv")
    assert np.allclose(a["t"], b["t"])
    for name in COORDINATES:
        limit = 2e-3 if name in ANGLES else 1e-5  # deg, m
        assert np.abs(a[name] - b[name]).max() < limit, (name, np.abs(a[name] - b[name]).max())
    assert theirs["rmse_torque_nm"] < 0.05 and theirs["rmse_force_n"] < 0.05, theirs
    assert theirs["residual_force_rms_n"] == pytest.approx(ours["residual_force_rms_n"], rel=1e-3)


def test_the_load_is_applied_by_opensim_not_only_by_fdbench(tmp_path, monkeypatch):
    """OpenSim's runs given no loads apply the load's generalised force themselves (their own
    inverse dynamics then lacks it): their torques stand off fdbench's reference (with the load) by
    about the load's size, while with the load they agree (PD, CMC)."""
    from fdbench.peers import common as peer_common

    paths = files(tmp_path)
    loaded = {name: invoke("peer", name, *common(paths)) for name in ("opensim", "opensim-cmc")}
    monkeypatch.setattr(peer_common, "loads_request", lambda spec: None)
    bare = {name: invoke("peer", name, *common(paths)) for name in ("opensim", "opensim-cmc")}
    for name in loaded:
        assert loaded[name]["status"] == bare[name]["status"] == "success", (loaded[name], bare[name])
        assert loaded[name]["rmse_force_n"] < 1.0 and bare[name]["rmse_force_n"] > 20.0, (loaded[name], bare[name])
        assert bare[name]["rmse_torque_nm"] > 10 * loaded[name]["rmse_torque_nm"] + 1.0, (loaded[name], bare[name])


def test_cmc_and_moco_track_with_the_loads_and_apply_fdbench_s_inverse_dynamics(tmp_path, monkeypatch):
    """CMCTool given the loads file follows the motion to one window before its end with fdbench's
    inverse-dynamics generalised forces (within 1 N m and 1 N, the load 40 N, 80 N). MocoTrack
    with the loads (20 mesh intervals): its torque, replayed by fdbench with the same loads,
    reaches the end near the motion (measured: 0.37 deg, 1.2 cm); Moco's torque made without the
    loads, replayed with them, does not (the load's 80 N upward push is then nobody's)."""
    from fdbench.peers import common as peer_common

    paths = files(tmp_path)
    cmc = invoke("peer", "opensim-cmc", *common(paths))
    assert cmc["status"] == "success" and cmc["t_end"] == pytest.approx(DURATION - 0.01), cmc["message"]
    assert cmc["rmse_rot_deg"] < 0.5 and cmc["rmse_torque_nm"] < 1.0 and cmc["rmse_force_n"] < 1.0, cmc
    # a step that does not divide CMC's window (as the walk report's 1/1020 s): its last step time before
    # the window is reached, which is the end
    steps = invoke("peer", "opensim-cmc", *common(paths, "--dt", "0.0007"))
    grid = np.linspace(0, DURATION, round(DURATION / 0.0007) + 1)  # the steps of the motion's span
    assert steps["status"] == "success", steps["message"]
    assert steps["t_end"] == pytest.approx(grid[grid <= DURATION - 0.01][-1]) and steps["t_end"] < DURATION - 0.01
    moco = invoke("peer", "moco", *common(paths, "--nodes", "20"))
    assert moco["ipopt_status"] == "Solve_Succeeded" and moco["status"] == "success", moco["message"]
    assert moco["rmse_rot_deg"] < 2.0 and moco["rmse_trans_cm"] < 5.0, moco
    monkeypatch.setattr(peer_common, "loads_request", lambda spec: None)
    bare = invoke("peer", "moco", *common(paths, "--nodes", "20"))
    assert bare["rmse_rot_deg"] > 10 * 2.0 and bare["rmse_trans_cm"] > 5.0, bare  # measured: 74 deg, 11 cm


def test_the_walk_report_has_the_peers_beside_its_methods(tmp_path):
    """``report --peers`` on a model with a floating base: the walk's report gets the section
    "Peers", each peer beside the method it stands for (PD beside OpenSim's simulation, computed
    torque beside CMC), in Markdown, CSV and JSON."""
    paths = files(tmp_path)
    base = ["report", "--model", paths[0], "--motion", paths[1], "--loads", paths[2], "--db", tmp_path / "runs.sqlite",
            "--budget", "2", "--popsize", "2", "--no-beyond", "--jobs", "1", "--peers", "opensim,opensim-cmc", "-q"]
    result = runner.invoke(app, [str(a) for a in base + ["-f", "json"]])
    assert result.exit_code == 0, (result.stdout, result.stderr)
    report = json.loads(result.stdout)
    peers = {entry["peer"]: entry for entry in report["peers"]}
    assert set(peers) == {"opensim", "opensim-cmc"}
    pd = next(e["record"] for e in report["walk"] if e["key"] == "pd")
    pair = peers["opensim"]["vs_fdbench"]
    assert pair["rmse_rot_deg_fdbench"] == pd["rmse_rot_deg"]
    assert pair["rmse_rot_deg_peer"] == peers["opensim"]["record"]["rmse_rot_deg"]
    assert pair["time_ratio"] == pytest.approx(pair["runtime_s_peer"] / pair["runtime_s_fdbench"])
    assert peers["opensim-cmc"]["vs_fdbench"]["fdbench"].startswith("Computed torque")
    text = runner.invoke(app, [str(a) for a in base + ["-f", "md"]]).stdout
    assert "## Peers" in text and text.count("; the goal is ") == 2
    assert text.index("## Peers") < text.index("## When and where the runs were made")
    rows = list(csv.DictReader(runner.invoke(app, [str(a) for a in base + ["-f", "csv"]]).stdout.splitlines()))
    assert [r["key"] for r in rows if r["command"] == "peer"] == ["opensim", "opensim-cmc"]
