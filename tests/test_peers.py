"""The peers (``fdbench peer``, ``fdbench report --peers``): OpenSim's forward simulation under
fdbench's PD law, checked against fdbench's PD (the same law and motion; the difference is the
feedback OpenSim holds over each step, first order in --dt), and Moco's MocoTrack, checked by
replaying its torque through fdbench (the replay follows Moco's own states) and against
fdbench's inverse dynamics."""

from __future__ import annotations

import importlib.util
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli_checks import assert_one_line_error

from fdbench.cli import app
from fdbench.experiment import RunSpec, control_spec, run
from fdbench.peers import peer_spec

ARM26 = Path(__file__).resolve().parent.parent / "examples" / "opensim" / "arm26.osim"

# OpenSim runs in child processes only (see fdbench.peers.child).
if importlib.util.find_spec("opensim") is None:
    pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')", allow_module_level=True)

runner = CliRunner()
HINT = "pip install 'fdbench[opensim]'"


def invoke(*args, code=0):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == code, (result.stdout, result.stderr)
    return result


def refused(*args, contains=()):
    """The command exits 2 with one line on stderr holding every text of ``contains``."""
    return assert_one_line_error(invoke(*args, code=2), *contains)


def angles(outcome) -> np.ndarray:
    """The simulated angles (deg) of a run's trajectory, on the motion's samples, shape (n,)."""
    header, rows = outcome.trajectory()
    return rows[:, header.index("theta")]


def test_opensim_pd_tracks_the_forearm_as_fdbench_pd_and_the_difference_is_the_held_feedback():
    """The same law (Kp 80, Kd 0.3, feedforward from the inverse dynamics) on the same motion: the
    indicators agree to 0.2 %; the trajectories differ by the feedback OpenSim holds over each
    step (fdbench's PD acts continuously), so the difference halves with --dt (first order),
    leaving far less than the minimal-against-penalty coordinates or OpenSim's integrator would
    explain (measured: 0.0026 deg at dt 1 ms, 0.0013 deg at 0.5 ms)."""
    differences = []
    for dt in (1e-3, 5e-4):
        theirs, ours = run(peer_spec("opensim", dt=dt)), run(control_spec(dt=dt))
        record = theirs.record
        assert record["status"] == "success" and record["peer"] == "opensim" and (record["kp"], record["kd"]) == (80, 0.3)
        assert record["opensim_version"].startswith("4.") and record["runtime_s"] > 0
        assert record["rmse_rot_deg"] == pytest.approx(ours.record["rmse_rot_deg"], rel=2e-3)
        assert record["rmse_torque_nm"] == pytest.approx(ours.record["rmse_torque_nm"], rel=2e-3)
        differences.append(np.abs(angles(theirs) - angles(ours)).max())
    assert differences[0] < 0.005
    assert 1.8 < differences[0] / differences[1] < 2.2, differences


def test_opensim_simulates_the_user_s_own_osim_whose_tilted_axes_explain_its_torque_difference(tmp_path):
    """--model FILE.osim: OpenSim simulates the file itself (arm26, its axes 3.4 deg off the
    normal, its muscles removed), fdbench's reference is the import (the axes projected). Both
    track closely; OpenSim's torques differ from fdbench's inverse dynamics by the projection, as
    the same file with its axes set along z shows (measured: 0.015 N m, then 6e-6 N m)."""
    text = ARM26.read_text()
    for tilted in ("-0.058898020000000002 0.0023 0.99826135999999999",
                   "0.049400010000000001 0.036600010000000002 0.99810825000000003"):
        assert tilted in text
        text = text.replace(tilted, "0 0 1")
    exact = tmp_path / "arm26_exact.osim"
    exact.write_text(text.replace("0.99826135999999999 -0 0.058898020000000002", "1 0 0")
                     .replace("0.99810825000000003 0 -0.049400010000000001", "1 0 0"))
    found = {}
    for path in (ARM26, exact):
        record = json.loads(invoke("peer", "opensim", "--model", path, "-f", "json", "-q").stdout)
        assert record["status"] == "success" and record["rmse_rot_deg"] < 1e-4, record
        found[path] = record["rmse_torque_nm"]
    assert 0.005 < found[ARM26] < 0.05 and found[exact] < found[ARM26] / 10, found


def test_moco_s_torque_replayed_follows_its_states_and_nears_the_inverse_dynamics_as_it_converges(tmp_path,
                                                                                                    monkeypatch):
    """MocoTrack of the forearm's exact motion (20 mesh intervals): fdbench's replay of its
    torque follows Moco's own states (the same model, simulated independently), and a tighter
    IPOPT tolerance brings the tracking and the torque closer to fdbench's inverse dynamics.
    Nothing is written where the command runs (MocoTrack writes its tracked states file in its
    own working directory)."""
    monkeypatch.chdir(tmp_path)
    spec = RunSpec(kinematics="exact")
    inverse = spec.reference()
    found = {}
    for tolerance in (1e-4, 1e-6):
        outcome = run(peer_spec("moco", dict(nodes=20, tolerance=tolerance), kinematics="exact"))
        record, solution = outcome.record, outcome.extra["collocation"]
        assert record["status"] == "success" and record["ipopt_status"] == "Solve_Succeeded", record["message"]
        assert solution.scheme == "hermite-simpson" and len(solution.t) == 21 and record["solve_time_s"] > 0
        header, rows = outcome.trajectory()
        replayed = np.interp(solution.t, rows[:, 0], rows[:, header.index("theta")])
        assert np.abs(replayed - np.degrees(solution.angles[:, 0])).max() < 0.01  # deg: the replay is Moco's trajectory
        torque_error = np.sqrt(np.mean((solution.torque[:, 0] - np.interp(solution.t, inverse.t, inverse.torque[:, 0]))
                                       ** 2))
        found[tolerance] = record["rmse_rot_deg"], record["rmse_torque_nm"], torque_error
    (rot_loose, torque_loose, error_loose), (rot_tight, torque_tight, error_tight) = found[1e-4], found[1e-6]
    peak = np.abs(inverse.torque).max()  # 6 N m
    assert rot_tight < 0.1 and rot_tight < rot_loose / 2 and rot_loose < 1.0, found
    assert torque_tight < 0.1 * peak and torque_tight < torque_loose and error_tight < error_loose, found
    assert list(tmp_path.iterdir()) == []


def test_the_report_with_peers_has_their_rows_in_markdown_csv_and_json(tmp_path):
    db, spec_hashes = tmp_path / "peers.sqlite", {}
    common = ["report", "--db", db, "--torque", "cs", "--opt", "bfgs", "--feedforward", "--seeds", 1, "--budget", 2,
              "--no-beyond", "--jobs", 1, "--peers", "opensim,moco", "-q"]
    text = invoke(*common).stdout
    assert "## Peers" in text and "| OpenSim forward simulation, PD + feedforward |" in text
    assert "| MocoTrack (Hermite-Simpson) + forward replay |" in text
    assert "| PD control + feedforward | OpenSim forward simulation, PD + feedforward |" in text  # side by side
    frame = pd.read_csv(io.StringIO(invoke(*common, "-f", "csv").stdout))
    rows = frame[frame["table"] == "peers"]
    assert list(rows["torque"]) == ["opensim", "moco"] and rows["runs"].tolist() == [1, 1]
    control = frame[frame["table"] == "control"].iloc[0]
    opensim = rows.iloc[0]
    assert opensim["rmse_rot_deg_median"] == pytest.approx(control["rmse_rot_deg_median"], rel=5e-3)
    cells = json.loads(invoke(*common, "-f", "json").stdout)["cells"]
    peers = [cell for cell in cells if cell["table"] == "peers"]
    assert [cell["torque"] for cell in peers] == ["opensim", "moco"]
    spec_hashes = {cell["torque"]: cell["spec_hashes"][0] for cell in peers}
    # the peer command alone is the same run: the same hash, stored once
    alone = json.loads(invoke("peer", "opensim", "-f", "json", "--db", db, "-q").stdout)
    assert alone["spec_hash"] == spec_hashes["opensim"]
    assert alone["rmse_rot_deg"] == pytest.approx(opensim["rmse_rot_deg_median"], rel=1e-6)
    listed = pd.read_csv(io.StringIO(invoke("runs", "list", "--db", db, "--command", "peer", "-f", "csv").stdout))
    assert sorted(listed["method"]) == ["moco", "opensim"]


@pytest.mark.parametrize("args, contains", [
    (("peer", "nope"), ("unknown peer 'nope'", "opensim, moco")),
    (("report", "--peers", "opensim,mocco"), ("--peers", "unknown peer 'mocco'", "did you mean 'moco'")),
    (("peer", "opensim", "--nodes", "5"), ("--nodes does not apply to peer opensim",)),
    (("peer", "moco", "--kp", "3"), ("--kp does not apply to peer moco",)),
    (("peer", "moco", "--nodes", "1"), ("--nodes",)),
    (("peer", "moco", "--tolerance", "2"), ("--tolerance",)),
    (("peer", "opensim", "--kd", "-1"), ("--kd",)),
])
def test_bad_peer_inputs_are_refused_in_one_line_and_nothing_is_written(tmp_path, args, contains):
    out, db = tmp_path / "out.json", tmp_path / "runs.sqlite"
    refused(*args, "-o", out, "--db", db, contains=contains)
    assert not out.exists() and not db.exists()


def test_without_opensim_the_peers_name_the_extra_to_install(tmp_path, monkeypatch):
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "opensim.py").write_text("raise ImportError('No module named opensim')\n")  # the child's opensim
    monkeypatch.syspath_prepend(str(hidden))  # the children import what this process would
    out, db = tmp_path / "out.md", tmp_path / "runs.sqlite"
    refused("peer", "moco", "--model", "arm2", "-o", out, contains=(HINT,))
    refused("report", "--peers", "opensim", "--db", db, "-o", out, contains=(HINT,))
    assert not out.exists() and not db.exists()
