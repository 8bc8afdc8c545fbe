"""The peers (``fdbench peer``, ``fdbench report --peers``): OpenSim's forward simulation under
fdbench's PD law, checked against fdbench's PD (the same law and motion, one integrate in
OpenSim; the difference is OpenSim's accuracy and the feedforward it interpolates linearly between
the step times), OpenSim's CMCTool, checked against fdbench's inverse dynamics, and Moco's
MocoTrack, checked by replaying its torque through fdbench (the replay follows Moco's own
states) and against fdbench's inverse dynamics."""

from __future__ import annotations

import importlib.util
import io
import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from helpers.cli_checks import assert_one_line_error
from helpers.paths import ROOT

from fdbench.cli import app
from fdbench.api import run
from fdbench.spec import RunSpec, control_spec, peer_spec

ARM26 = ROOT / "examples" / "opensim" / "arm26.osim"

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


def test_opensim_runs_the_pd_law_in_one_integrate_and_tracks_the_forearm_as_fdbench_pd(monkeypatch):
    """The same law (Kp 80, Kd 0.3, feedforward from the inverse dynamics) on the same motion, the
    law inside OpenSim's model and one integrate over the motion: the integrator takes its own
    steps (fewer than the 1000 of --dt: it is not restarted at each), the indicators agree to
    0.2 % and the trajectories to 5e-4 deg at OpenSim's default accuracy. At accuracy 1e-9 what is
    left is the time discretisation: OpenSim's feedforward is linear between the step times, so
    the difference falls about fourfold when --dt halves (measured: 6.6e-5 deg at 1 ms, 1.7e-5 at
    0.5 ms)."""
    from fdbench.peers import opensim_pd

    theirs, ours = run(peer_spec("opensim")), run(control_spec())
    record = theirs.record
    assert record["status"] == "success" and record["peer"] == "opensim" and (record["kp"], record["kd"]) == (80, 0.3)
    assert record["opensim_version"].startswith("4.") and record["runtime_s"] > 0
    assert 1 <= record["opensim_steps"] < 1000 and record["opensim_accuracy"] == 1e-5
    assert record["rmse_rot_deg"] == pytest.approx(ours.record["rmse_rot_deg"], rel=2e-3)
    assert record["rmse_torque_nm"] == pytest.approx(ours.record["rmse_torque_nm"], rel=2e-3)
    assert np.abs(angles(theirs) - angles(ours)).max() < 5e-4
    monkeypatch.setattr(opensim_pd, "ACCURACY", 1e-9)
    differences = [np.abs(angles(run(peer_spec("opensim", dt=dt))) - angles(run(control_spec(dt=dt)))).max()
                   for dt in (1e-3, 5e-4)]
    assert differences[0] < 1e-4 and 3 < differences[0] / differences[1] < 5, differences


def test_cmc_tracks_arm2_with_the_inverse_dynamics_torques_and_leaves_nothing_behind(tmp_path, monkeypatch):
    """OpenSim's CMCTool on arm2 made torque-driven: it follows the motion (its tasks' PD on the
    computed accelerations) to within 0.01 deg, up to one time window (0.01 s) before the end,
    where it stops, and its actuators' torques are fdbench's inverse dynamics of the motion to
    0.1 % of their peak (measured: 0.0016 deg, 3e-4 N m). Its result files stay in its own
    temporary folder."""
    monkeypatch.chdir(tmp_path)
    outcome = run(peer_spec("opensim-cmc", model_name="arm2"))
    record = outcome.record
    assert record["status"] == "success" and record["peer"] == "opensim-cmc", record["message"]
    assert record["t_end"] == pytest.approx(0.99) and record["runtime_s"] > 0
    assert record["rmse_rot_deg"] < 0.01
    peak = np.abs(RunSpec(model_name="arm2").reference().torque).max()
    assert record["rmse_torque_nm"] < 1e-3 * peak, (record["rmse_torque_nm"], peak)
    assert list(tmp_path.iterdir()) == []


def _arm26_short(folder) -> str:
    """The path of the library's arm26 as a model file in ``folder``, with one motion of its own
    (0.2 s of minimum jerk, shoulder 20 to 35 deg, elbow 30 to 60 deg)."""
    from fdbench.models import find_model
    from fdbench.multibody.model import model_from_dict, to_dict
    from fdbench.multibody.model_files import to_toml

    data = to_dict(find_model("arm26"))
    data["motions"] = [{"name": "short", "type": "minimum-jerk", "duration": 0.2,
                        "start": {"r_shoulder_elev": 0.35, "r_elbow_flex": 0.52},
                        "goal": {"r_shoulder_elev": 0.61, "r_elbow_flex": 1.05}}]
    path = folder / "arm26_short.toml"
    path.write_text(to_toml(model_from_dict(data, "arm26_short")))
    return str(path)


def test_cmc_drives_arm26_s_muscles_with_reserves_and_its_torque_is_the_inverse_dynamics(tmp_path):
    """OpenSim's CMCTool on the library's arm26 (its six De Groote muscles written by to_osim, one
    reserve of 1 N m per coordinate as the model has no actuators) along a short motion of its own
    (0.2 s, shoulder 20 to 35 deg, elbow 30 to 60 deg): muscle-driven, it runs from 0.03 s (its
    muscles' states settled before) to one window before the end and tracks within 1 deg; its
    activations stay in [0, 1] and its torque (reserves plus OpenSim's moment arms times the
    muscles' forces, composed by the peer) is fdbench's inverse dynamics within 2 % of the peak
    (measured: 0.13 deg, 0.12 N m of 31 N m, CMC's run 7 s)."""
    from fdbench.models import find_model

    outcome = run(peer_spec("opensim-cmc", model_name=_arm26_short(tmp_path)))
    record = outcome.record
    assert record["status"] == "success" and record["t_end"] == pytest.approx(0.19), record["message"]
    assert record["message"].startswith("muscle-driven: 6 muscles (DeGrooteFregly2016Muscle), reserves "
                                        "r_shoulder_elev_actuator (1 N m), r_elbow_flex_actuator (1 N m) (the model "
                                        "has no actuators"), record["message"]
    assert "CMC starts at t = 0.03 s" in record["message"] and outcome.trajectory()[1][0, 0] == pytest.approx(0.03)
    assert record["rmse_rot_deg"] < 1.0, record
    peak = np.abs(outcome.inverse.torque).max()  # N m
    assert record["rmse_torque_nm"] < 0.02 * peak, (record["rmse_torque_nm"], peak)
    means = [record[f"{m.name}_activation_mean"] for m in find_model("arm26").muscles]
    assert all(0.0 <= a <= 1.0 for a in means) and max(means) > 0.05, means
    assert 0 < record["effort"] <= 6 and sum(a * a for a in means) <= record["effort"] + 1e-12  # Jensen
    reserves = record["reserve_rms_nm_r_shoulder_elev"], record["reserve_rms_nm_r_elbow_flex"]
    assert record["reserve_rms_nm"] == pytest.approx(np.sqrt(np.mean(np.square(reserves))))
    assert "cmc_optimal_force_nm" not in record


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


def test_moco_drives_arm26_s_muscles_and_fdbench_s_replay_of_its_excitations_follows_its_states(tmp_path,
                                                                                                 monkeypatch):
    """MocoTrack muscle-driven on arm26's short motion (20 mesh intervals; its six De Groote muscles,
    tendons rigid, reserves of 1 N m): fdbench's own muscles and simulation, given Moco's
    excitations and reserve torques, follow Moco's states (its angles within 0.1 deg, its
    activations within 0.02, at the mesh points); each activation starts at its excitation; the
    record's effort and reserves are those of the replay's trajectory."""
    monkeypatch.chdir(tmp_path)
    model = _arm26_short(tmp_path)
    outcome = run(peer_spec("moco", dict(nodes=20), model_name=model))
    record, solution = outcome.record, outcome.extra["collocation"]
    assert record["status"] == "success" and record["ipopt_status"] == "Solve_Succeeded", record["message"]
    assert record["actuation"] == "muscles" and "muscle-driven: 6 muscles" in record["message"]
    assert record["tendons"].startswith("rigid") and record["effort_weight"] > 0
    header, rows = outcome.trajectory()
    at_nodes = lambda column: np.interp(solution.t, rows[:, 0], rows[:, header.index(column)])  # noqa: E731
    for j, name in enumerate(("r_shoulder_elev", "r_elbow_flex")):
        assert np.abs(at_nodes(name) - np.degrees(solution.angles[:, j])).max() < 0.1, name
    for m, name in enumerate(solution.muscles):
        assert np.abs(at_nodes(f"{name}_activation") - solution.activation[:, m]).max() < 0.02, name
    assert np.abs(solution.activation[0] - solution.excitation[0]).max() < 1e-4
    activation = rows[:, [header.index(f"{name}_activation") for name in solution.muscles]]
    assert record["effort"] == pytest.approx(np.mean(np.sum(activation ** 2, axis=1)), rel=1e-9)
    reserves = rows[:, [header.index(f"{j}_reserve") for j in ("r_shoulder_elev", "r_elbow_flex")]]
    assert record["reserve_rms_nm"] == pytest.approx(np.sqrt(np.mean(reserves ** 2)), rel=1e-9)
    assert record["rmse_rot_deg"] < 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["arm26_short.toml"]


def test_the_report_with_peers_has_their_rows_in_markdown_csv_and_json(tmp_path):
    db, spec_hashes = tmp_path / "peers.sqlite", {}
    common = ["report", "--db", db, "--torque", "cs", "--opt", "bfgs", "--feedforward", "--seeds", 1, "--budget", 2,
              "--no-beyond", "--jobs", 1, "--peers", "opensim,opensim-cmc,moco", "-q"]
    text = invoke(*common).stdout
    assert "## Peers" in text and "| OpenSim forward simulation, PD + feedforward |" in text
    assert "| MocoTrack (Hermite-Simpson) + forward replay |" in text
    assert "| PD control + feedforward | OpenSim forward simulation, PD + feedforward |" in text  # side by side
    # without the computed-torque row (--no-beyond) CMC stands beside PD; each pair says whether the goal is met
    assert "| PD control + feedforward | OpenSim CMCTool (Computed Muscle Control) |" in text
    assert text.count("; the goal is ") == 2
    frame = pd.read_csv(io.StringIO(invoke(*common, "-f", "csv").stdout))
    rows = frame[frame["table"] == "peers"]
    assert list(rows["torque"]) == ["opensim", "opensim-cmc", "moco"] and rows["runs"].tolist() == [1, 1, 1]
    control = frame[frame["table"] == "control"].iloc[0]
    opensim = rows.iloc[0]
    assert opensim["rmse_rot_deg_median"] == pytest.approx(control["rmse_rot_deg_median"], rel=5e-3)
    cells = json.loads(invoke(*common, "-f", "json").stdout)["cells"]
    peers = [cell for cell in cells if cell["table"] == "peers"]
    assert [cell["torque"] for cell in peers] == ["opensim", "opensim-cmc", "moco"]
    assert ["vs_fdbench" in cell for cell in peers] == [True, True, False]  # no collocation row (--no-beyond)
    for cell in peers[:2]:  # the goal: at least 10x faster at an RMSE_rot at most 1 % above the peer's
        pair = cell["vs_fdbench"]
        assert pair["time_ratio"] == pytest.approx(pair["runtime_s_peer"] / pair["runtime_s_fdbench"])
        assert pair["goal_met"] == (pair["time_ratio"] >= 10
                                    and pair["rmse_rot_deg_fdbench"] <= 1.01 * pair["rmse_rot_deg_peer"])
    moco = peers[2]
    assert moco["moco_run_s"] >= moco["solve_time_s"] > 0  # the whole run holds the solve
    assert moco["runtime_s_median"] >= moco["moco_run_s"]  # and the runtime the replay too
    spec_hashes = {cell["torque"]: cell["spec_hashes"][0] for cell in peers}
    # the peer command alone is the same run: the same hash, stored once
    alone = json.loads(invoke("peer", "opensim", "-f", "json", "--db", db, "-q").stdout)
    assert alone["spec_hash"] == spec_hashes["opensim"]
    assert alone["rmse_rot_deg"] == pytest.approx(opensim["rmse_rot_deg_median"], rel=1e-6)
    listed = pd.read_csv(io.StringIO(invoke("runs", "list", "--db", db, "--command", "peer", "-f", "csv").stdout))
    assert sorted(listed["method"]) == ["moco", "opensim", "opensim-cmc"]


@pytest.mark.parametrize("args, contains", [
    (("peer", "nope"), ("unknown peer 'nope'", "opensim, opensim-cmc, moco")),
    (("peer", "opensim-cmc", "--kp", "3"), ("--kp does not apply to peer opensim-cmc",)),
    (("report", "--peers", "opensim,mocco"), ("--peers", "unknown peer 'mocco'", "did you mean 'moco'")),
    (("peer", "opensim", "--nodes", "5"), ("--nodes does not apply to peer opensim",)),
    (("peer", "moco", "--kp", "3"), ("--kp does not apply to peer moco",)),
    (("peer", "moco", "--nodes", "1"), ("--nodes",)),
    (("peer", "moco", "--tolerance", "2"), ("--tolerance",)),
    (("peer", "moco", "--max-iter", str(2**31)), ("--max-iter", "[1, 1000000]")),  # was OpenSim's "Wrong number..."
    (("peer", "moco", "--max-iter", "0"), ("--max-iter",)),
    (("peer", "moco", "--model", "arm26", "--regularization", "1e-3"), ("--regularization", "on a model with muscles")),
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


@pytest.mark.parametrize("ratio, ours, theirs, met, says", [
    (19.2, 4.2e-5, 0.353, True, "fdbench 19.2× faster (RMSE_rot 4.2e-05 against 0.353 deg); the goal is met."),
    (1.78, 0.1134, 0.1133, False, "fdbench 1.78× faster (RMSE_rot 0.113 against 0.113 deg); the goal is not met: "
                                  "1.78× is below 10×."),
    (0.5, 1e-7, 1e-5, False, "fdbench 2× slower (RMSE_rot 1e-07 against 1e-05 deg); the goal is not met: 0.5× is "
                             "below 10×."),
    (949.0, 1.64, 0.00119, False, "fdbench 949× faster (RMSE_rot 1.64 against 0.00119 deg); the goal is not met: its "
                                  "RMSE_rot 1.64 deg is above the peer's 0.00119 deg."),
    (12.0, 0.102, 0.1, False, "the goal is not met: its RMSE_rot 0.102 deg is above the peer's 0.1 deg."),
])
def test_the_goal_is_ten_times_faster_at_equal_or_better_accuracy_and_each_pair_says_so(ratio, ours, theirs, met,
                                                                                          says):
    from fdbench.report.peers import goal_met, goal_sentence

    pair = {"fdbench": "ours", "peer": "theirs", "model": "arm2", "rmse_rot_deg_fdbench": ours,
            "rmse_rot_deg_peer": theirs, "runtime_s_fdbench": 1.0, "runtime_s_peer": ratio, "time_ratio": ratio}
    pair["goal_met"] = goal_met(pair)
    assert pair["goal_met"] is met
    sentence = goal_sentence(pair)
    assert sentence.startswith("- ours against theirs on arm2: ") and sentence.endswith(says), sentence


def test_the_integrator_s_steps_are_read_at_the_samples_exactly_for_a_cubic():
    """OpenSim's states come at its own steps (one recorded twice here); cubic Hermite
    interpolation of angle and rate is exact for a cubic, its rate too."""
    from fdbench.peers.opensim_pd import hermite

    times = np.array([0.0, 0.3, 0.3, 0.45, 1.0])
    angle = lambda t: np.stack([t**3 - t, 2 - t**2], axis=-1)  # noqa: E731
    rate = lambda t: np.stack([3 * t**2 - 1, -2 * t], axis=-1)  # noqa: E731
    at = np.linspace(0.0, 1.0, 11)
    found, found_rate = hermite(times, angle(times), rate(times), at)
    np.testing.assert_allclose(found, angle(at), atol=1e-12)
    np.testing.assert_allclose(found_rate, rate(at), atol=1e-12)
