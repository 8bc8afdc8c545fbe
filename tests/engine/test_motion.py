"""Desired motions as inputs: recorded files, the derivative estimate (zero-lag Butterworth or
smoothing spline), noisy captures, model mismatch, and every command following the motion's
duration instead of [0, 1] s."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from helpers import forearm_closed_form as forearm
from helpers.paths import ROOT
from fdbench.cli import app
from fdbench.spec import control_spec, optimize_spec, with_motion_file
from fdbench.multibody.motions import as_motion, butterworth_design_hz, eq5, noisy, read_motion_csv, zero_lag_lowpass

runner = CliRunner()
EXAMPLE = ROOT / "examples" / "elbow_flexion.csv"


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def run_json(*args) -> dict:
    result = invoke(*args, "-f", "json", "-q")
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)


def csv_table(*args) -> np.ndarray:
    result = invoke(*args, "-f", "csv", "-q")
    assert result.exit_code == 0, result.stderr
    return np.loadtxt(io.StringIO(result.stdout), delimiter=",", skiprows=1)


def write_motion(path: Path, t, theta_deg, vel=None, acc=None) -> Path:
    columns, header = [t, theta_deg], "t,theta"
    if vel is not None:
        columns += [vel, acc]
        header += ",theta_vel,theta_acc"
    np.savetxt(path, np.column_stack(columns), delimiter=",", header=header, comments="", fmt="%.17g")
    return path


# ---- the zero-lag filter -----------------------------------------------------------------------


def test_filter_attenuates_a_sine_at_the_cutoff_by_3_db():
    """The -3 dB point of the whole forward-backward filter is the cutoff (Winter's correction of
    the design frequency): a long sine at the cutoff keeps 1/sqrt(2) of its amplitude."""
    rate, cutoff = 200.0, 6.0
    t = np.arange(0, 20, 1 / rate)
    for frequency, expected in ((cutoff, 1 / math.sqrt(2)), (cutoff / 4, None), (4 * cutoff, None)):
        out = zero_lag_lowpass(np.sin(2 * np.pi * frequency * t), rate, cutoff)
        middle = slice(len(t) // 4, 3 * len(t) // 4)
        gain = np.sqrt(2 * np.mean(out[middle] ** 2))
        if expected is not None:
            assert gain == pytest.approx(expected, rel=2e-3)
        elif frequency < cutoff:
            assert gain > 0.99
        else:
            assert gain < 0.01
    # the design frequency sits above the cutoff: one pass alone would be -3 dB there
    assert butterworth_design_hz(cutoff, rate) > cutoff


def test_filter_has_zero_lag():
    rate = 200.0
    t = np.arange(0, 10, 1 / rate)
    signal = np.sin(2 * np.pi * 2.0 * t)
    out = zero_lag_lowpass(signal, rate, 6.0)
    middle = slice(200, -200)
    gain = np.dot(out[middle], signal[middle]) / np.dot(signal[middle], signal[middle])
    assert np.max(np.abs(out[middle] - gain * signal[middle])) < 1e-6  # a pure gain: no phase shift


@pytest.mark.parametrize("smoothing", ["butterworth", "spline"])
def test_derivative_estimates_converge_as_noise_falls(smoothing):
    exact = as_motion("exact")
    t = np.linspace(0.1, 0.9, 201)
    _, w_true, a_true = eq5(t, "exact")

    def errors(sigma):
        out = []
        for seed in range(3):
            _, w, a = noisy(exact, sigma, seed, capture_hz=200.0, smoothing=smoothing)(t)
            out.append((np.sqrt(np.mean((w - w_true) ** 2)), np.sqrt(np.mean((a - a_true) ** 2))))
        return np.mean(out, axis=0)

    levels = [1.0, 0.3, 0.1, 0.03]
    found = [errors(sigma) for sigma in levels]
    assert all(np.all(a > b) for a, b in zip(found, found[1:]))  # falling with the noise
    noise_free = errors(0.0)
    assert found[-1][1] < 0.2 * found[0][1] and noise_free[1] < found[-1][1]


def test_same_seed_same_noisy_motion_and_other_seeds_differ():
    exact = as_motion("exact")
    t = np.linspace(0, 1, 57)
    a, b, c = (noisy(exact, 0.5, seed)(t)[0] for seed in (3, 3, 4))
    assert np.array_equal(a, b) and not np.allclose(a, c)
    first = run_json("control", "--noise-deg", 0.5, "--seed", 3)
    again = run_json("control", "--noise-deg", 0.5, "--seed", 3)
    other = run_json("control", "--noise-deg", 0.5, "--seed", 4)
    assert first["rmse_rot_deg"] == again["rmse_rot_deg"] != other["rmse_rot_deg"]
    assert first["spec_hash"] == again["spec_hash"] != other["spec_hash"]


# ---- recorded motions --------------------------------------------------------------------------


def test_paper_motion_at_200_hz_with_its_derivatives_gives_the_paper_torque(tmp_path):
    t = np.arange(201) / 200
    theta, vel, acc = eq5(t, "paper")
    path = write_motion(tmp_path / "paper200.csv", t, np.degrees(theta), np.degrees(vel), np.degrees(acc))
    from_file = csv_table("inverse", "--motion", path)
    reference = csv_table("inverse", "--motion", "paper", "--sample-dt", 0.005)
    assert from_file.shape == reference.shape == (201, 5)
    assert np.max(np.abs(from_file[:, 4] - reference[:, 4])) < 1e-6


def test_exact_angle_at_200_hz_gives_the_exact_torque_within_2_percent(tmp_path):
    t = np.arange(201) / 200
    theta, _, _ = eq5(t, "exact")
    path = write_motion(tmp_path / "exact200.csv", t, np.degrees(theta))
    estimated = csv_table("inverse", "--motion", path)
    exact = csv_table("inverse", "--motion", "exact", "--sample-dt", 0.005)
    inside = (estimated[:, 0] >= 0.05) & (estimated[:, 0] <= 0.95)
    error = estimated[inside, 4] - exact[inside, 4]
    assert np.sqrt(np.mean(error**2)) < 0.02 * np.sqrt(np.mean(exact[inside, 4] ** 2))  # the target
    assert np.sqrt(np.mean(error**2)) < 0.001 * np.sqrt(np.mean(exact[inside, 4] ** 2))  # the README's figure
    assert np.max(np.abs(estimated[:, 4] - exact[:, 4])) < 0.02  # ends included, as the README says


def test_irregular_sampling_is_accepted(tmp_path):
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.004, 0.006, 300))
    t -= t[0]
    theta, _, _ = eq5(t / t[-1], "exact")
    motion = read_motion_csv(write_motion(tmp_path / "jitter.csv", t, np.degrees(theta)))
    assert motion.duration == pytest.approx(t[-1]) and not motion.uniform
    th, _, _ = motion(motion.samples)
    assert np.max(np.abs(np.degrees(th - theta))) < 0.2


def test_radians_option_reads_radians(tmp_path):
    t = np.linspace(0, 1, 101)
    theta, _, _ = eq5(t, "exact")
    in_degrees = csv_table("inverse", "--motion", write_motion(tmp_path / "deg.csv", t, np.degrees(theta)))
    in_radians = csv_table("inverse", "--motion", write_motion(tmp_path / "rad.csv", t, theta), "--radians")
    assert np.allclose(in_degrees, in_radians, atol=1e-9)


# ---- fdbench's own files read back as motions ---------------------------------------------------


def csv_frame(*args):
    import pandas as pd

    result = invoke(*args, "-f", "csv", "-q")
    assert result.exit_code == 0, result.stderr
    return pd.read_csv(io.StringIO(result.stdout))


@pytest.mark.parametrize("kinematics", ["paper", "exact"])
def test_inverse_csv_read_back_as_motion_is_the_same_motion(tmp_path, kinematics):
    """inverse --format csv writes a motion file: read back as --motion, it gives the named
    motion's angle (deg), rates and torque at the samples."""
    path = tmp_path / "m.csv"
    path.write_text(invoke("inverse", "--motion", kinematics, "-f", "csv").stdout)
    named, ts = csv_frame("inverse", "--motion", kinematics), np.linspace(0, 1, 1001)
    theta, vel, acc = eq5(ts, kinematics)
    np.testing.assert_allclose(named.theta, np.degrees(theta), rtol=0, atol=1e-9)
    again = csv_frame("inverse", "--motion", path)
    np.testing.assert_allclose(again.theta, np.degrees(theta), rtol=0, atol=1e-9)
    np.testing.assert_allclose(again[["theta_vel", "theta_acc"]], np.degrees([vel, acc]).T, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(named.theta_torque, forearm.torque_along(theta, vel, acc), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(again.theta_torque, named.theta_torque, rtol=1e-12)
    from_file, direct = run_json("control", "--motion", path), run_json("control", "--motion", kinematics)
    assert from_file["derivatives"] == "given"
    # RK4's half steps fall between the file's samples: Hermite interpolation there, hence 1e-3
    assert from_file["rmse_rot_deg"] == pytest.approx(direct["rmse_rot_deg"], rel=1e-3)


def test_saved_trajectory_read_back_as_motion_is_the_simulated_angle(tmp_path):
    trajectory = tmp_path / "tr.csv"
    run_json("control", "--plant", "m=1.3", "--save-trajectory", trajectory)
    import pandas as pd

    saved = pd.read_csv(trajectory)
    assert saved.theta[0] == pytest.approx(-45.0) and np.max(np.abs(saved.theta - saved.theta_desired)) > 0.01
    again = csv_frame("inverse", "--motion", trajectory)
    np.testing.assert_allclose(again.theta, saved.theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(again[["theta_vel", "theta_acc"]], saved[["theta_vel", "theta_acc"]], rtol=0, atol=1e-9)
    # the simulated acceleration is the simulated velocity's rate
    np.testing.assert_allclose(np.gradient(saved.theta_vel, saved.t)[1:-1], saved.theta_acc[1:-1], rtol=0, atol=0.5)


def test_saved_trajectory_is_a_torque_file_of_the_applied_torque(tmp_path):
    """Its theta_torque column drives an open-loop simulation: the PD run's applied torque, simulated
    alone on the same plant, tracks about as the PD run did (its RK4 half steps interpolate the 1 ms
    samples, hence not to the bit)."""
    trajectory = tmp_path / "tr.csv"
    pd_run = run_json("control", "--plant", "m=1.3", "--save-trajectory", trajectory)
    replay = run_json("simulate", "--plant", "m=1.3", "--torque-file", trajectory)
    assert replay["torque"].startswith("file:") and replay["status"] == "success"
    assert replay["rmse_rot_deg"] == pytest.approx(pd_run["rmse_rot_deg"], rel=1e-3)  # open loop alone: 8.3 deg


def test_a_file_in_radians_from_an_older_fdbench_needs_radians(tmp_path):
    ts = np.linspace(0, 1, 1001)
    theta, vel, acc = eq5(ts, "exact")
    old = tmp_path / "old.csv"
    np.savetxt(old, np.column_stack([ts, theta, vel, acc, 0 * ts]), delimiter=",", fmt="%.17g", comments="",
               header="t,theta,theta_dot,theta_ddot,torque")
    result = invoke("control", "--motion", old)
    lines = result.stderr.splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and "theta_dot" in lines[0], lines
    assert "radians by an older fdbench" in lines[0] and "--radians" in lines[0]
    assert not list(tmp_path.glob("*.fdbench-*"))
    read = csv_frame("inverse", "--motion", old, "--radians")
    np.testing.assert_allclose(read.theta, np.degrees(theta), rtol=0, atol=1e-9)
    np.testing.assert_allclose(read.theta_acc, np.degrees(acc), rtol=1e-12, atol=1e-9)  # theta_ddot given
    assert run_json("control", "--motion", old, "--radians")["derivatives"] == "given"


BAD_MOTIONS = {
    "few.csv": ("t,theta\n" + "".join(f"{i / 10},{-40 + i}\n" for i in range(9)), "at least 10"),
    "backwards.csv": ("t,theta\n" + "".join(f"{t},{-40}\n" for t in [0, 0.1, 0.2, 0.2, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1]),
                      "increasing"),
    "nan.csv": ("t,theta\n" + "".join(f"{i / 10},{'nan' if i == 4 else -40}\n" for i in range(12)), "finite"),
    "singular.csv": ("t,theta\n" + "".join(f"{i / 10},{-40 + 13 * i}\n" for i in range(12)), "singular"),
    "columns.csv": ("time,angle\n" + "".join(f"{i / 10},{-40}\n" for i in range(12)), "columns"),
    "half.csv": ("t,theta,theta_vel\n" + "".join(f"{i / 10},-40,0\n" for i in range(12)), "both"),
    "empty.csv": ("", "empty"),
    "text.csv": ("t,theta\n" + "".join(f"{i / 10},abc\n" for i in range(12)), "numbers"),
}


@pytest.mark.parametrize("name", sorted(BAD_MOTIONS))
def test_bad_motion_file_is_one_line_exit_2(tmp_path, name):
    text, word = BAD_MOTIONS[name]
    (tmp_path / name).write_text(text)
    for command in ("inverse", "control"):
        result = invoke(command, "--motion", tmp_path / name)
        assert result.exit_code == 2, result.stderr
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("fdbench: error: --motion") and word in lines[0], lines


@pytest.mark.parametrize("cutoff", [1e-300, 1e-10, 0.01])
def test_a_cutoff_too_low_to_settle_is_refused_with_the_lowest_that_does(cutoff):
    """A cutoff whose filter would not forget its start within the padding (or is not even stable
    in double precision) is refused, not filtered into nonsense; the lowest cutoff it names works
    and keeps a ramp a ramp (the odd reflection and a unit DC gain preserve a straight line)."""
    rate, n = 100.0, 12
    ramp = np.linspace(-1.0, 1.0, n)
    with pytest.raises(ValueError, match="too low") as refused:
        zero_lag_lowpass(ramp, rate, cutoff)
    lowest = float(str(refused.value).rsplit("at least ", 1)[1].split()[0])
    assert cutoff < lowest < rate / 2
    assert np.allclose(zero_lag_lowpass(ramp, rate, lowest), ramp, atol=1e-6)


def test_unknown_motion_name_lists_the_valid_ones():
    result = invoke("control", "--motion", "papr")
    assert result.exit_code == 2 and "paper" in result.stderr and "did you mean" in result.stderr


def test_bad_condition_options_are_one_line_exit_2(tmp_path):
    for args, word in ((["--noise-deg", "-1"], "--noise-deg"), (["--noise-deg", "100"], "--noise-deg"),
                       (["--cutoff", "0"], "--cutoff"), (["--smoothing", "lowess"], "smoothing"),
                       (["--spline-lambda", "-1", "--smoothing", "spline"], "--spline-lambda"),
                       (["--plant", "I1"], "KEY=VALUE"), (["--plant", "mass=2"], "mass"),
                       (["--model", "I1=-1"], "I1"), (["--model", "L1G=0.5"], "L1G"),
                       (["--sample-dt", "5"], "--sample-dt must be in"), (["--capture-hz", "0", "--noise-deg", "1"], "--capture-hz"),
                       (["--noise-deg", "1", "--cutoff", "80"], "cutoff"),
                       (["--noise-deg", "1", "--cutoff", "1e-20"], "too low")):
        result = invoke("control", *args)
        assert result.exit_code == 2, (args, result.stderr)
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and word in lines[0], (args, lines)


# ---- model mismatch ----------------------------------------------------------------------------


def test_plant_leaves_the_feedforward_unchanged_and_model_changes_it():
    nominal = csv_table("inverse")
    plant = csv_table("inverse", "--plant", "I1=0.05")
    model = csv_table("inverse", "--model", "I1=0.05")
    assert np.array_equal(plant, nominal)
    # the closed form: the torque changes by (I1' - I1) theta''
    assert np.allclose(model[:, 4] - nominal[:, 4], (0.05 - forearm.I1) * np.radians(nominal[:, 3]), atol=1e-10)


def test_plant_mismatch_makes_open_loop_worse_and_is_measured_against_the_nominal_torque():
    exact = run_json("simulate", "--motion", "exact")
    heavier = run_json("simulate", "--motion", "exact", "--plant", "m=1.2")
    assert exact["rmse_rot_deg"] < 1e-4 < heavier["rmse_rot_deg"]
    assert heavier["plant"] == "m=1.2" and heavier["rmse_torque_nm"] == pytest.approx(0, abs=1e-9)
    pd = run_json("control", "--motion", "exact", "--plant", "m=1.2")
    assert pd["rmse_rot_deg"] < heavier["rmse_rot_deg"]
    # PD's extra torque against the nominal model's inverse dynamics makes up the missing weight
    assert pd["rmse_torque_nm"] > 0.1


def test_model_file_sets_the_nominal_model(tmp_path):
    (tmp_path / "arm.toml").write_text("[forearm]\nI1 = 0.05\nm = 1.1\n")
    (tmp_path / "arm.json").write_text('{"I1": 0.05, "m": 1.1}')
    by_options = csv_table("inverse", "--model", "I1=0.05", "--model", "m=1.1")
    for name in ("arm.toml", "arm.json"):
        assert np.array_equal(csv_table("inverse", "--model-file", tmp_path / name), by_options)
    (tmp_path / "bad.toml").write_text("I1 = 'heavy'\n")
    result = invoke("inverse", "--model-file", tmp_path / "bad.toml")
    assert result.exit_code == 2 and len(result.stderr.splitlines()) == 1


@settings(max_examples=15)
@given(scale=st.floats(0.5, 2.0))
def test_nominal_model_scales_the_feedforward(scale):
    """Inverse dynamics is linear in (I1, F_ext, m): scaling all three scales the torque."""
    from fdbench.models import with_changes
    from fdbench.multibody.engine import Engine
    from fdbench.multibody.motions import joint_motion
    from fdbench.multibody.simulation import inverse_dynamics

    changes = (("I1", forearm.I1 * scale), ("F_ext", forearm.F_EXT * scale), ("m", forearm.M * scale))
    base, scaled = with_changes("forearm"), with_changes("forearm", changes)
    motion = joint_motion("exact", base)
    a = inverse_dynamics(None, Engine(base), motion).torque
    b = inverse_dynamics(None, Engine(scaled), motion).torque
    assert np.allclose(b, scale * a, rtol=1e-12, atol=1e-12)


# ---- a recorded motion of another length, through every command ------------------------------


def test_recorded_motion_of_2_5_s_runs_through_every_command(tmp_path):
    assert EXAMPLE.is_file()
    inverse = run_json("inverse", "--motion", EXAMPLE)
    assert inverse["duration_s"] == pytest.approx(2.5) and inverse["samples"] == 301
    control = run_json("control", "--motion", EXAMPLE)
    assert control["status"] == "success" and control["t_end"] == pytest.approx(2.5)
    optimized = run_json("optimize", "--motion", EXAMPLE, "--torque", "cs", "--knots", 26, "--opt", "bfgs",
                         "--budget", 30, "--feedforward")
    assert optimized["evaluations"] == 30 and optimized["t_end"] == pytest.approx(2.5)
    assert invoke("control", "--motion", EXAMPLE, "--save-trajectory", tmp_path / "traj.csv", "-q").exit_code == 0
    trajectory = np.loadtxt(tmp_path / "traj.csv", delimiter=",", skiprows=1)
    assert trajectory.shape[0] == 301 and trajectory[-1, 0] == pytest.approx(2.5)
    study = invoke("study", "noise", "--motion", EXAMPLE, "--levels", "0,0.5", "--seeds", 2, "--torque", "cs",
                   "--opt", "bfgs", "--feedforward", "--budget", 10, "--jobs", 1, "--db", tmp_path / "s.sqlite",
                   "-f", "csv", "-q")
    assert study.exit_code == 0, study.stderr
    rows = [line.split(",") for line in study.stdout.splitlines()[1:]]
    assert len(rows) == 4 and {r[2] for r in rows} == {"PD + feedforward", "CS + bfgs + ff"}


def test_torque_parameterisations_spread_over_the_motion():
    from fdbench.models import find_model
    from fdbench.multibody.engine import Engine
    from fdbench.multibody.motions import joint_motion
    from fdbench.problem import TrackingProblem
    from fdbench.torques import make_torque

    model = find_model("forearm")
    joints = joint_motion(str(EXAMPLE), model)
    for name in ("cs", "pf", "ann"):
        problem = TrackingProblem(name, Engine(model), joints, feedforward=False)
        fitted = problem.parts[0].evaluate(problem.p0, problem.inverse.t)
        target = problem.inverse.torque[:, 0]
        rms = np.sqrt(np.mean((fitted - target) ** 2))
        assert rms < 0.2 * np.ptp(target), name  # the fit covers all 2.5 s
    motion = read_motion_csv(EXAMPLE)
    assert make_torque("cs").n_params == 11
    cs = make_torque("cs")
    cs.prepare(motion.samples, np.ones_like(motion.samples), False)
    assert cs.t_knots[-1] == pytest.approx(2.5)


def test_sample_dt_sets_the_reporting_grid():
    coarse = csv_table("inverse", "--sample-dt", 0.01)
    assert coarse.shape[0] == 101 and coarse[-1, 0] == pytest.approx(1.0)
    pd = run_json("control", "--sample-dt", 0.01)
    assert pd["rmse_rot_deg"] == pytest.approx(run_json("control")["rmse_rot_deg"], rel=0.05)


def test_motion_file_enters_the_hash_by_content(tmp_path):
    text = EXAMPLE.read_text()
    (tmp_path / "a.csv").write_text(text)
    (tmp_path / "b.csv").write_text(text)
    (tmp_path / "c.csv").write_text(text.replace("-49.9996", "-49.9990", 1))
    a, b, c = (with_motion_file(control_spec(80.0, 0.3, kinematics=str(tmp_path / f"{n}.csv"))).hash() for n in "abc")
    assert a == b != c
    spec = with_motion_file(optimize_spec("cs", "bfgs", kinematics=str(tmp_path / "a.csv")))
    (tmp_path / "a.csv").write_text(text.replace("-49.9996", "-49.0", 1))
    with pytest.raises(ValueError, match="changed"):
        spec.validate()


def test_noise_is_measured_against_the_true_motion():
    noisy_run = run_json("control", "--motion", "exact", "--noise-deg", 1.0, "--seed", 2)
    clean = run_json("control", "--motion", "exact")
    assert clean["rmse_rot_deg"] < 1e-6 < noisy_run["rmse_rot_deg"] < 2.0
    assert noisy_run["noise_deg"] == 1.0 and "noise" in noisy_run["motion"]


def test_report_on_a_recorded_motion_sets_no_paper_figure_beside_ours(tmp_path):
    result = invoke("report", "--motion", EXAMPLE, "--torque", "cs", "--opt", "bfgs", "--feedforward", "--seeds", 1,
                    "--budget", 5, "--no-beyond", "--jobs", 1, "--db", tmp_path / "r.sqlite", "-f", "csv", "-q")
    assert result.exit_code == 0, result.stderr
    import pandas as pd

    frame = pd.read_csv(io.StringIO(result.stdout))
    assert frame["paper_rmse_rot_deg"].isna().all() and len(frame) == 2
