"""Models of the library through the command line, on the multibody engine: --model arm2 on every
command against the arm's closed form (tests/helpers/arm2_closed_form.py), motion and torque files by joint
name, per-joint indicators, and bad input as one line with exit 2."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.model_changes import with_short_keys
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion

from helpers.arm2_closed_form import joint_torques, reach

runner = CliRunner()
ARM = Engine(find_model("arm2"))
REACH = joint_motion("reach", find_model("arm2"))
SAMPLES = np.linspace(0.0, 1.0, 1001)


def arm(**changes) -> Engine:
    return Engine(with_short_keys(find_model("arm2"), tuple(changes.items())))


def invoke(*args, code=0):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == code, result.stderr
    return result


def as_json(*args):
    return json.loads(invoke(*args, "--format", "json").stdout)


def test_inverse_history_is_the_models_joint_torques():
    table = pd.read_csv(io.StringIO(invoke("inverse", "--model", "arm2", "--format", "csv").stdout))
    assert len(table) == 1001 and {"shoulder", "elbow", "shoulder_torque", "elbow_torque"} <= set(table.columns)
    z = np.radians(table[["shoulder", "elbow"]].to_numpy())  # degrees, like a motion file
    w = np.radians(table[["shoulder_vel", "elbow_vel"]].to_numpy())
    dw = np.radians(table[["shoulder_acc", "elbow_acc"]].to_numpy())
    expected = joint_torques(z, w, dw, m0=2.5)
    changed = pd.read_csv(io.StringIO(invoke("inverse", "--model", "arm2", "--model", "m0=2.5", "--format", "csv").stdout))
    np.testing.assert_allclose(changed[["shoulder_torque", "elbow_torque"]].to_numpy(), expected, rtol=1e-8)
    np.testing.assert_allclose(changed.elbow_torque, table.elbow_torque, rtol=1e-8)  # m0 acts on the shoulder only


def test_control_reports_overall_and_per_joint_indicators(tmp_path):
    history = tmp_path / "h.csv"
    record = as_json("control", "--model", "arm2", "--kp", "80", "--kd", "0.3", "--save-trajectory", history)
    assert record["model"] == "arm2" and record["status"] == "success" and record["t_end"] == pytest.approx(1.0)
    per = np.array([record["rmse_rot_deg_shoulder"], record["rmse_rot_deg_elbow"]])
    assert record["rmse_rot_deg"] == pytest.approx(math.sqrt(np.mean(per**2)), rel=1e-12)
    assert record["rmse_rot_deg"] < 1e-5  # the reach is kinematically consistent: PD + feedforward tracks it
    table = pd.read_csv(history)
    error = table[["shoulder", "elbow"]].to_numpy() - table[["shoulder_desired", "elbow_desired"]].to_numpy()  # deg
    assert record["rmse_rot_deg"] == pytest.approx(math.sqrt(np.mean(error**2)), rel=1e-6)


def test_computed_torque_on_the_arm():
    record = as_json("control", "--model", "arm2", "--controller", "computed-torque", "--bandwidth", "15")
    assert record["controller"] == "computed-torque" and "bandwidth=15.0" in record["controller_options"]
    assert record["status"] == "success" and record["rmse_rot_deg"] < 1e-5 and record["kp"] is None


def test_plant_mismatch_on_the_arm():
    """--plant changes the simulated body only: the feedforward (and computed torque) keep the
    nominal model, so tracking degrades; --model changes both and tracking stays exact."""
    both = as_json("control", "--model", "arm2", "--model", "m0=2.5", "--kp", "80", "--kd", "0.3")
    plant = as_json("control", "--model", "arm2", "--plant", "m0=2.5", "--kp", "80", "--kd", "0.3")
    ct = as_json("control", "--model", "arm2", "--plant", "m0=2.5", "--controller", "computed-torque")
    assert both["rmse_rot_deg"] < 1e-5 and both["model_options"] == "m0=2.5" and both["plant"] is None
    assert plant["plant"] == "m0=2.5" and plant["rmse_rot_deg"] > 0.1 and ct["rmse_rot_deg"] > 0.1
    direct = sim.simulate(sim.feedforward(ARM, REACH), arm(m0=2.5), REACH, 80.0, 0.3)
    rot, _ = sim.rmse_deg(direct, reach(SAMPLES)[0])
    assert plant["rmse_rot_deg"] == pytest.approx(rot, rel=1e-12)


def test_pd_gains_follow_each_joints_inertia_unless_given():
    """Without --kp and --kd each joint gets the paper's 80 and 0.3 scaled by its inertia M_jj at the
    motion's start over the forearm's 0.04 kg m^2 (the closed form's M11 for the shoulder; the elbow
    is the forearm itself); given gains are the same on every joint, the runs stored before."""
    record = as_json("control", "--model", "arm2")
    z0 = reach(np.zeros(1))[0][0]
    m11 = 0.06 + 0.04 + 1.0 * 0.30**2 + 2 * 1.0 * 0.30 * 0.11 * math.cos(z0[1])
    assert record["kp"] is None and record["kp_shoulder"] == pytest.approx(80 * m11 / 0.04, rel=1e-12)
    assert record["kd_shoulder"] == pytest.approx(0.3 * m11 / 0.04, rel=1e-12)
    assert (record["kp_elbow"], record["kd_elbow"]) == (pytest.approx(80.0, rel=1e-12), pytest.approx(0.3, rel=1e-12))
    given = as_json("control", "--model", "arm2", "--kp", "80", "--kd", "0.3")
    assert given["kp_shoulder"] == given["kp_elbow"] == 80.0 and given["spec_hash"] != record["spec_hash"]
    assert as_json("control")["kp"] == 80.0  # the forearm keeps the paper's


def test_lqr_on_the_arm():
    record = as_json("control", "--model", "arm2", "--controller", "lqr", "--q-angle", "1e5")
    assert record["controller"] == "lqr" and "q_angle=100000.0" in record["controller_options"]
    assert record["status"] == "success" and record["rmse_rot_deg"] < 1e-5 and record["kp"] is None
    heavy = as_json("control", "--model", "arm2", "--controller", "lqr", "--plant", "m0=2.5")
    pd_heavy = as_json("control", "--model", "arm2", "--plant", "m0=2.5", "--kp", "80", "--kd", "0.3")
    assert 0 < heavy["rmse_rot_deg"] < pd_heavy["rmse_rot_deg"]  # stiffer than PD 80 / 0.3


def test_simulate_reads_one_torque_column_per_joint(tmp_path):
    t = np.linspace(0.0, 1.0, 2001)
    torque = joint_torques(*reach(t)) + np.array([0.05, -0.02])
    path = tmp_path / "torque.csv"
    pd.DataFrame({"t": t, "shoulder": torque[:, 0], "elbow": torque[:, 1]}).to_csv(path, index=False)
    record = as_json("simulate", "--model", "arm2", "--torque-file", path)
    expected = sim.simulate(lambda s: np.stack([np.interp(s, t, torque[:, j]) for j in range(2)], -1), ARM, REACH)
    rot, _ = sim.rmse_deg(expected, reach(SAMPLES)[0])
    assert record["torque"] == f"file:{path}" and record["rmse_rot_deg"] == pytest.approx(rot, rel=1e-9)
    assert record["rmse_rot_deg"] > 0.1  # the offsets drive the arm off the reach


def test_a_motion_file_in_degrees_gives_the_reach(tmp_path):
    z, w, dw = reach(SAMPLES)
    frame = {"t": SAMPLES}
    for j, joint in enumerate(("shoulder", "elbow")):
        frame.update({joint: np.degrees(z[:, j]), f"{joint}_vel": np.degrees(w[:, j]), f"{joint}_acc": np.degrees(dw[:, j])})
    path = tmp_path / "reach.csv"
    pd.DataFrame(frame).to_csv(path, index=False, float_format="%.12g")
    from_file = as_json("control", "--model", "arm2", "--motion", path)
    named = as_json("control", "--model", "arm2")
    assert from_file["motion"] == "file:reach.csv" and from_file["status"] == "success"
    assert from_file["rmse_rot_deg"] < 1e-4 and named["rmse_rot_deg"] < 1e-4


def test_arm_inverse_csv_and_trajectory_read_back_as_motions(tmp_path):
    """The arm's inverse --format csv is a motion file (degrees, <joint>_vel, <joint>_acc), and a
    saved trajectory's angles are read back in degrees."""
    z, w, dw = reach(SAMPLES)
    path = tmp_path / "m.csv"
    path.write_text(invoke("inverse", "--model", "arm2", "--format", "csv").stdout)
    again = pd.read_csv(io.StringIO(invoke("inverse", "--model", "arm2", "--motion", path, "--format", "csv").stdout))
    np.testing.assert_allclose(again[["shoulder", "elbow"]], np.degrees(z), rtol=0, atol=1e-9)
    np.testing.assert_allclose(again[["shoulder_acc", "elbow_acc"]], np.degrees(dw), rtol=1e-12, atol=1e-9)
    assert as_json("control", "--model", "arm2", "--motion", path)["derivatives"] == "given"
    trajectory = tmp_path / "tr.csv"
    as_json("control", "--model", "arm2", "--plant", "m=1.3", "--save-trajectory", trajectory)
    saved = pd.read_csv(trajectory)
    from_trajectory = as_json("inverse", "--model", "arm2", "--motion", trajectory)
    assert from_trajectory["motion"] == "file:tr.csv" and saved.shoulder[0] == pytest.approx(-20.0)


def test_the_arm_inverse_history_is_a_torque_file(tmp_path):
    """Its <joint>_torque columns drive the simulation, not its angle columns named by joint."""
    path = tmp_path / "tau.csv"
    path.write_text(invoke("inverse", "--model", "arm2", "--format", "csv").stdout)
    from_file, default = as_json("simulate", "--model", "arm2", "--torque-file", path), as_json("simulate", "--model", "arm2")
    assert from_file["torque"] == f"file:{path}" and from_file["rmse_torque_nm"] < 1e-9
    # open loop: linear interpolation between the 1 ms samples drifts a little more than the exact torque
    assert default["rmse_rot_deg"] < from_file["rmse_rot_deg"] < 0.1


def test_an_arm_file_in_radians_from_an_older_fdbench_needs_radians(tmp_path):
    z, w, dw = reach(SAMPLES)
    old = tmp_path / "old.csv"
    pd.DataFrame({"t": SAMPLES, "shoulder": z[:, 0], "elbow": z[:, 1], "shoulder_dot": w[:, 0],
                  "elbow_dot": w[:, 1], "shoulder_ddot": dw[:, 0], "elbow_ddot": dw[:, 1]}).to_csv(old, index=False)
    lines = invoke("control", "--model", "arm2", "--motion", old, code=2).stderr.splitlines()
    assert len(lines) == 1 and "shoulder_dot" in lines[0] and "older fdbench" in lines[0] and "--radians" in lines[0]
    read = pd.read_csv(io.StringIO(invoke("inverse", "--model", "arm2", "--motion", old, "--radians",
                                          "--format", "csv").stdout))
    np.testing.assert_allclose(read[["shoulder", "elbow"]], np.degrees(z), rtol=0, atol=1e-9)


def test_the_forearm_is_the_default_model():
    assert as_json("control", "--model", "forearm")["rmse_rot_deg"] == as_json("control")["rmse_rot_deg"]


@pytest.mark.parametrize("args, word", [
    (["--model", "arm3"], "valid: forearm, arm2, arm26, leg3"), (["--model", "arm2", "--model", "forearm"], "one model"),
    (["--model", "arm2", "--model", "L0G=0.5"], "L0G"), (["--model", "arm2", "--model", "mass=1"], "unknown key of model 'arm2' 'mass'"),
    (["--model", "arm2", "--motion", "exact"], "reach"), (["--model", "arm2", "--integrator", "rk45", "--rtol", "0"], "--rtol"),
    (["--model", "arm2", "--controller", "mpc"], "unknown controller 'mpc'"),
    (["--model", "arm2", "--controller", "computed-torque", "--bandwidth", "-1"], "--bandwidth"), (["--model", "arm2", "--sample-dt", "5"], "--sample-dt"),
    (["--model", "arm2", "--dt", "5"], "--dt"), (["--model", "arm2", "--kp", "-1"], "--kp"),
    (["--model", "arm2", "--motion", "missing.csv"], "missing.csv"),
])
def test_bad_arm_input_is_one_line_exit_2(args, word):
    result = invoke("control", *args, code=2)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and word in lines[0], lines


def test_a_motion_file_without_a_joint_column_is_refused(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("t,shoulder\n0,1\n1,2\n")
    result = invoke("inverse", "--model", "arm2", "--motion", path, code=2)
    assert "elbow" in result.stderr and len(result.stderr.splitlines()) == 1


def test_optimize_on_the_arm(tmp_path):
    convergence = tmp_path / "c.csv"
    record = as_json("optimize", "--model", "arm2", "--torque", "pf", "--terms", "3", "--feedforward", "--opt", "bfgs",
                     "--budget", "40", "--save-convergence", convergence)
    assert record["model"] == "arm2" and record["n_params"] == 18 and record["evaluations"] == 40
    assert record["best_objective"] <= record["initial_objective"] and record["status"] == "success"
    assert record["best_objective"] == pytest.approx(record["rmse_rot_deg"], rel=1e-12)
    assert {"rmse_rot_deg_shoulder", "rmse_rot_deg_elbow"} <= set(record)
    best = pd.read_csv(convergence).best_objective
    assert len(best) == 40 and best.iloc[-1] == pytest.approx(record["best_objective"]) and best.is_monotonic_decreasing


def test_optimize_on_the_arm_refuses_what_it_lacks():
    for args, word in ((["--hidden", "0", "--torque", "ann"], "--hidden"), (["--budget", "0"], "--budget"),
                       (["--torque", "xx"], "--torque"), (["--integrator", "euler"], "--integrator"),
                       (["--gradient", "exact", "--opt", "cmaes"], "--gradient"), (["--plant", "m0=-2"], "m0")):
        result = invoke("optimize", "--model", "arm2", *args, code=2)
        assert len(result.stderr.splitlines()) == 1 and word in result.stderr, result.stderr


def test_methods_lists_the_models():
    text = invoke("methods").stdout
    assert "models (--model" in text and "  arm2 " in text and "  forearm " in text and "  leg3 " in text


def test_arm_runs_are_stored_and_found_again(tmp_path):
    db = tmp_path / "r.sqlite"
    first = as_json("control", "--model", "arm2", "--db", db)
    again = as_json("control", "--model", "arm2", "--db", db)
    forearm = as_json("control", "--db", db)
    assert first["spec_hash"] == again["spec_hash"] != forearm["spec_hash"]
    from fdbench.store import open_store

    with open_store(db) as store:
        stored = {r["spec_hash"]: r for r in store.records()}
    assert stored[first["spec_hash"]]["model"] == "arm2" and stored[forearm["spec_hash"]]["model"] == "forearm"


def test_the_report_on_the_arm_gives_each_joint_and_their_root_mean_square(tmp_path):
    args = ["report", "--model", "arm2", "--torque", "cs", "--opt", "bfgs", "--opt", "cmaes", "--seeds", "2",
            "--budget", "12", "--no-beyond", "--jobs", "1", "--db", tmp_path / "r.sqlite", "-q"]
    report = json.loads(invoke(*args, "-f", "json").stdout)
    assert report["settings"]["model"].startswith("arm2") and len(report["cells"]) == 5  # PD and four cells
    for cell in report["cells"]:
        assert cell["model"] == "arm2" and cell["paper_rmse_rot_deg"] is None
        assert {"rmse_rot_deg_shoulder_median", "rmse_rot_deg_elbow_median"} <= set(cell)
    from fdbench.store import open_store

    with open_store(tmp_path / "r.sqlite") as store:
        records = store.records()
    assert len(records) == 9
    for r in records:  # both joints have every sample: the overall RMSE is the root mean square of the joints'
        if r["t_end"] == 1.0:
            joints = np.array([r["rmse_rot_deg_shoulder"], r["rmse_rot_deg_elbow"]])
            assert r["rmse_rot_deg"] == pytest.approx(np.sqrt(np.mean(joints**2)), rel=1e-12)
    markdown = invoke(*args, "--figures", tmp_path / "figs").stdout
    assert "| method | RMSE_rot (deg) | shoulder (deg) | elbow (deg) |" in markdown and "two-segment arm" in markdown
    from fdbench.figures import FIGURE_FILES

    for name in FIGURE_FILES:  # every figure of the forearm's report, a column per joint
        assert (tmp_path / "figs" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"figs/{name}" in markdown


def test_a_noisy_reach_is_seeded_and_measured_against_the_true_one():
    clean = as_json("control", "--model", "arm2")
    noisy = [as_json("control", "--model", "arm2", "--noise-deg", "0.5", "--seed", str(s)) for s in (1, 1, 2)]
    assert noisy[0]["rmse_rot_deg"] == noisy[1]["rmse_rot_deg"] != noisy[2]["rmse_rot_deg"]
    assert all(n["rmse_rot_deg"] > 100 * clean["rmse_rot_deg"] for n in noisy)
    assert "noise 0.5 deg" in noisy[0]["motion"] and noisy[0]["derivatives"]


def test_a_mismatch_study_of_the_arm_at_level_zero_is_the_plain_run(tmp_path):
    csv = invoke("study", "mismatch", "--model", "arm2", "--param", "m0", "--levels", "0,20", "--no-feedforward",
                 "--torque", "cs", "--opt", "bfgs", "--seeds", "1", "--budget", "8", "--jobs", "1",
                 "--db", tmp_path / "s.sqlite", "-f", "csv", "-q").stdout
    table = pd.read_csv(io.StringIO(csv))
    pd_rows = table[table.method.str.startswith("PD")].set_index("level")
    assert pd_rows.loc[0, "rmse_rot_deg_median"] == pytest.approx(as_json("control", "--model", "arm2")["rmse_rot_deg"],
                                                                  rel=1e-12)
    heavier = as_json("control", "--model", "arm2", "--plant", "m0=2.4")
    assert pd_rows.loc[20, "rmse_rot_deg_median"] == pytest.approx(heavier["rmse_rot_deg"], rel=1e-12)


def test_saved_arm_parameters_replay_the_optimised_run(tmp_path):
    params = tmp_path / "p.json"
    optimised = as_json("optimize", "--model", "arm2", "--torque", "cs", "--feedforward", "--budget", "30",
                        "--save-params", params)
    replayed = as_json("simulate", "--model", "arm2", "--params", params)
    assert replayed["rmse_rot_deg"] == pytest.approx(optimised["rmse_rot_deg"], rel=1e-6)
    assert replayed["rmse_rot_deg"] < as_json("simulate", "--model", "arm2")["rmse_rot_deg"]
    assert json.loads(params.read_text())["model"] == "arm2"
    forearm = invoke("simulate", "--params", params, code=2).stderr
    assert "--model arm2" in forearm and len(forearm.splitlines()) == 1


def test_a_coarser_reporting_grid_samples_the_same_arm_simulation(tmp_path):
    """--sample-dt changes where the indicators are read, not the simulation: on a 10 ms grid that
    falls on the 1 ms samples, each joint's history equals the 1 ms history at those times."""
    tables = []
    for name, extra in (("fine", []), ("coarse", ["--sample-dt", "0.01"])):
        path = tmp_path / f"{name}.csv"
        as_json("control", "--model", "arm2", "--plant", "m0=2.2", "--save-trajectory", path, *extra)
        tables.append(pd.read_csv(path))
    fine, coarse = tables
    assert len(fine) == 1001 and len(coarse) == 101
    picked = fine.iloc[::10].reset_index(drop=True)
    for column in ("shoulder", "elbow", "shoulder_torque", "elbow_torque"):
        assert np.allclose(coarse[column], picked[column], rtol=0, atol=1e-9), column


def test_hidden_auto_on_the_arm_is_the_smallest_count_fitting_every_joint():
    from fdbench.torques.ann import AUTO_TOLERANCE, AnnTorque

    record = as_json("optimize", "--model", "arm2", "--torque", "ann", "--hidden", "auto", "--budget", "3")
    chosen = int(record["torque_options"].split("=")[1])
    assert record["n_params"] == 2 * (3 * chosen + 1)
    inv = sim.inverse_dynamics(None, ARM, REACH)

    def fits(n):
        errors = []
        for j in range(2):
            ann = AnnTorque(hidden=n)
            ann.prepare(inv.t, inv.torque[:, j], feedforward=False)
            errors.append(ann.fit_rmse / 2)
        return max(errors) <= AUTO_TOLERANCE

    assert fits(chosen) and (chosen == 1 or not fits(chosen - 1))


# ---------------------------------------------------------------------- any model: the leg and files
LEG = ["--model", "leg3"]


def test_the_leg_swings_through_the_hanging_pose_under_every_controller():
    """The thigh passes -90 deg, where the paper's angle constraint is singular: every controller
    tracks the leg's default motion to the end."""
    for args in ([], ["--controller", "computed-torque"], ["--controller", "lqr"]):
        record = as_json("control", *LEG, *args)
        duration = find_model("leg3").motions[0].duration
        assert record["status"] == "success" and record["t_end"] == pytest.approx(duration)
        assert record["rmse_rot_deg"] < 0.05, (args, record["rmse_rot_deg"])
        assert {"rmse_rot_deg_hip", "rmse_rot_deg_knee", "rmse_rot_deg_ankle"} <= set(record)


def test_the_legs_inverse_history_drives_its_simulation(tmp_path):
    path = tmp_path / "leg.csv"
    path.write_text(invoke("inverse", *LEG, "--format", "csv").stdout)
    table = pd.read_csv(path)
    assert {"t", "hip", "knee", "ankle", "hip_torque", "knee_torque", "ankle_torque"} <= set(table.columns)
    record = as_json("simulate", *LEG, "--torque-file", path)
    assert record["rmse_torque_nm"] < 1e-9 and record["status"] == "success"


def test_optimize_and_collocate_on_the_leg():
    optimised = as_json("optimize", *LEG, "--torque", "cs", "--feedforward", "--opt", "bfgs", "--budget", "10")
    assert optimised["n_params"] == 3 * 11 and optimised["best_objective"] <= optimised["initial_objective"]
    collocated = as_json("collocate", *LEG, "--nodes", "40")
    assert collocated["status"] == "success" and collocated["rmse_rot_deg"] < 0.5


def test_a_model_file_counts_by_its_content(tmp_path):
    """The same file under two names is the same model (one spec hash); a changed mass is another;
    the file is an input that no output may overwrite."""
    from fdbench.models import library

    text = library()["leg3"].read_text()
    first, second = tmp_path / "a.toml", tmp_path / "b.toml"
    first.write_text(text)
    second.write_text(text)
    a, b = as_json("control", "--model", first), as_json("control", "--model", second)
    assert a["spec_hash"] == b["spec_hash"] and a["rmse_rot_deg"] == b["rmse_rot_deg"]
    second.write_text(text.replace("mass = 7.5 ", "mass = 7.6 "))
    assert as_json("control", "--model", second)["spec_hash"] != a["spec_hash"]
    before = first.read_bytes()
    result = invoke("control", "--model", first, "--save-trajectory", first, code=2)
    assert len(result.stderr.splitlines()) == 1 and first.read_bytes() == before


@pytest.mark.parametrize("content, words", [
    ("[[bodies]]\nname = 'a'\nmass = -1\ncom = [0.1, 0]\ninertia = 0.1\n[[joints]]\nname = 'j'\nparent = 'ground'\n"
     "child = 'a'\nat_parent = [0, 0]\n", ["bodies[0].mass"]),
    ("[[bodies]]\nname = 'a'\nmass = 1\ncom = [0.1, 0]\ninertia = 0.1\n[[joints]]\nname = 'j'\ntype = 'pin'\n"
     "parent = 'nowhere'\nchild = 'a'\nat_parent = [0, 0]\nat_child = [0, 0]\n", ["joints[0].parent", "nowhere"]),
    ("this is not toml", ["not valid TOML"]),
])
def test_a_bad_model_file_is_one_line_exit_2_naming_file_and_key(tmp_path, content, words):
    path = tmp_path / "bad.toml"
    path.write_text(content)
    lines = invoke("control", "--model", path, code=2).stderr.splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and all(w in lines[0] for w in words), lines


# ---------------------------------------------------------------------- collocation on the arm
def test_collocate_on_the_arm_saves_a_torque_that_simulate_replays(tmp_path):
    path = tmp_path / "torque.csv"
    record = json.loads(invoke("collocate", "--model", "arm2", "--nodes", 50, "-f", "json", "--save-torque", path,
                               "--quiet").stdout)
    assert record["model"] == "arm2" and record["command"] == "collocate" and record["nodes"] == 50
    assert record["status"] == "success" and {"rmse_rot_deg_shoulder", "rmse_torque_nm_elbow"} <= set(record)
    table = pd.read_csv(path)
    assert list(table.columns) == ["t", "shoulder", "elbow"] and len(table) == 2001
    replay = json.loads(invoke("simulate", "--model", "arm2", "--torque-file", path, "-f", "json").stdout)
    for key in ("rmse_rot_deg", "rmse_torque_nm", "rmse_rot_deg_shoulder", "rmse_rot_deg_elbow"):
        assert replay[key] == pytest.approx(record[key], rel=1e-9), key


def test_an_iteration_limit_on_the_arm_is_a_status_with_a_message():
    record = json.loads(invoke("collocate", "--model", "arm2", "--max-iter", 1, "-f", "json").stdout)
    assert record["ipopt_status"] == "Maximum_Iterations_Exceeded" and record["status"] == "collocation_failed"
    assert "--max-iter" in record["message"] and np.isfinite(record["rmse_rot_deg"])


@pytest.mark.parametrize("args, word", [
    (["--nodes", 1], "--nodes"), (["--scheme", "euler"], "--scheme"), (["--regularization", -1], "--regularization"),
    (["--max-iter", 0], "--max-iter"), (["--max-time", 0], "--max-time"), (["--integrator", "dop853", "--atol", 2], "--atol"),
    (["--motion", "paper"], "--motion"), (["--model", "m0=-1"], "m0"),
])
def test_bad_collocate_options_on_the_arm_are_one_line_exit_2(args, word, tmp_path):
    out = tmp_path / "torque.csv"
    result = invoke("collocate", "--model", "arm2", *args, "--save-torque", out, code=2)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and word in lines[0], result.stderr
    assert result.stdout == "" and not out.exists()


def test_the_arms_beyond_the_paper_table_has_direct_collocation():
    from fdbench.report.methods import beyond_methods

    specs = [m.spec for m in beyond_methods(kinematics="reach", model_name="arm2")[0]]
    assert [s.command for s in specs] == ["control", "control", "collocate"]
    assert all(s.model_name == "arm2" for s in specs)


def test_a_missing_model_file_and_one_without_motions_are_one_line_exit_2(tmp_path):
    missing = invoke("control", "--model", tmp_path / "none.toml", code=2).stderr.splitlines()
    assert len(missing) == 1 and missing[0].count("--model") == 1 and "does not exist" in missing[0]
    from fdbench.models import library

    text = library()["leg3"].read_text()
    path = tmp_path / "still.toml"
    path.write_text(text[:text.index("[[motions]]")])
    lines = invoke("control", "--model", path, code=2).stderr.splitlines()
    assert len(lines) == 1 and "--motion" in lines[0] and "t,hip,knee,ankle" in lines[0]
    motion = tmp_path / "m.csv"
    motion.write_text(invoke("inverse", *LEG, "--format", "csv").stdout)
    assert as_json("control", "--model", path, "--motion", motion)["status"] == "success"


def test_a_mismatch_study_and_a_report_of_the_leg_by_path(tmp_path):
    """study mismatch takes a path into the model as --param: level 0 is the plain run, +10 % of
    the thigh's mass is a heavier plant; a report of the leg has a column per joint."""
    csv = invoke("study", "mismatch", *LEG, "--param", "thigh.mass", "--levels", "0,10", "--no-feedforward",
                 "--torque", "cs", "--opt", "bfgs", "--seeds", "1", "--budget", "4", "--jobs", "1",
                 "--db", tmp_path / "s.sqlite", "-f", "csv", "-q").stdout
    rows = pd.read_csv(io.StringIO(csv))
    pd_rows = rows[rows.method.str.startswith("PD")].set_index("level")
    assert pd_rows.loc[0, "rmse_rot_deg_median"] == pytest.approx(as_json("control", *LEG)["rmse_rot_deg"], rel=1e-12)
    heavier = as_json("control", *LEG, "--plant", "thigh.mass=8.25")
    assert pd_rows.loc[10, "rmse_rot_deg_median"] == pytest.approx(heavier["rmse_rot_deg"], rel=1e-12)
    markdown = invoke("report", *LEG, "--torque", "cs", "--opt", "bfgs", "--feedforward", "--seeds", "1",
                      "--budget", "3", "--no-beyond", "--jobs", "1", "--db", tmp_path / "r.sqlite", "-q").stdout
    assert "| method | RMSE_rot (deg) | hip (deg) | knee (deg) | ankle (deg) |" in markdown
    assert "Kp and Kd per joint" in markdown
