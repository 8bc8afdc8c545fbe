"""Bad input is exit 2 and one line, always: files fdbench reads (CSV, JSON, TOML, pipes and
FIFOs), options that do not apply, work too large for the machine's memory, singular motions of
the arm and implausible constants."""

from __future__ import annotations

import json
import math
import os
import threading

import pytest
from typer.testing import CliRunner

import fdbench
from fdbench import files
from fdbench.cli import app

from helpers.cli_checks import assert_one_line_error

runner = CliRunner()


def invoke(args):
    return runner.invoke(app, [str(a) for a in args])


def motion_rows(n=101, rate=100.0):
    """(t s, theta deg) of a smooth recorded forearm motion."""
    return [(i / rate, 30 * math.sin(3 * i / rate)) for i in range(n)]


def motion_csv(tmp_path, name="motion.csv", newline="\n", rows=None):
    path = tmp_path / name
    lines = ["t,theta"] + [f"{t},{theta}" for t, theta in rows or motion_rows()]
    path.write_bytes(newline.join(lines).encode() + newline.encode())
    return path


def inverse_json(motion, *extra):
    result = invoke(["inverse", "--motion", motion, "-f", "json", "-q", *extra])
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)


# ---- CSV ---------------------------------------------------------------------------------------


def test_a_cell_over_the_csv_field_limit_is_one_line(tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text("t,theta\n0," + "1" * 200_000 + "\n" + "".join(f"{t},{a}\n" for t, a in motion_rows()[1:]))
    assert_one_line_error(invoke(["inverse", "--motion", path, "-q"]), "--motion", "line 2")


def test_old_mac_line_endings_read_as_any_other(tmp_path):
    unix = inverse_json(motion_csv(tmp_path, "unix.csv"))
    mac = inverse_json(motion_csv(tmp_path, "mac.csv", newline="\r"))
    assert mac["torque_rms_nm"] == unix["torque_rms_nm"]
    assert mac["samples"] == unix["samples"] == 101


def test_a_column_named_twice_is_refused(tmp_path):
    path = tmp_path / "twice.csv"
    path.write_text("t,theta,theta\n" + "".join(f"{t},{a},{-a}\n" for t, a in motion_rows()))
    assert_one_line_error(invoke(["inverse", "--motion", path, "-q"]), "--motion", "'theta'")


# ---- JSON and TOML -----------------------------------------------------------------------------

HUGE = "1" + "0" * 400  # an integer no float can hold
ENORMOUS = "1" + "0" * 5000  # beyond Python's digit limit for int()


@pytest.mark.parametrize("number", [HUGE, ENORMOUS])
def test_a_parameter_file_with_an_integer_too_large_for_a_float(tmp_path, number):
    path = tmp_path / "params.json"
    path.write_text('{"torque": "cs", "torque_options": {"knots": 11}, "feedforward": false, '
                    f'"kinematics": "paper", "params": [{", ".join(["0"] * 10)}, {number}]}}')
    assert_one_line_error(invoke(["simulate", "--params", path, "-q"]), "--params", "finite")


@pytest.mark.parametrize("name, text", [("model.json", '{"I1": %s}' % HUGE), ("model.json", '{"I1": %s}' % ENORMOUS),
                                        ("model.toml", "I1 = %s\n" % HUGE)])
def test_a_model_file_with_an_integer_too_large_for_a_float(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    assert_one_line_error(invoke(["inverse", "--model-file", path, "-q"]), "I1")


# ---- pipes and FIFOs: read once, in bounded time -----------------------------------------------


def test_a_fifo_with_no_writer_is_refused_in_bounded_time(tmp_path, monkeypatch):
    monkeypatch.setattr(files, "INPUT_TIMEOUT_S", 0.2)
    fifo = tmp_path / "motion.fifo"
    os.mkfifo(fifo)
    assert_one_line_error(invoke(["inverse", "--motion", fifo, "-q"]), "--motion", "no writer")
    model_fifo = tmp_path / "model.fifo"
    os.mkfifo(model_fifo)
    assert_one_line_error(invoke(["inverse", "--model-file", model_fifo, "-q"]), "--model-file", "no writer")


def test_a_motion_from_a_pipe_is_read_once_and_gives_the_file_s_result(tmp_path):
    path = motion_csv(tmp_path)
    expected = inverse_json(path)
    read, write = os.pipe()
    writer = threading.Thread(target=lambda: (os.write(write, path.read_bytes()), os.close(write)))
    writer.start()
    try:
        piped = inverse_json(f"/proc/self/fd/{read}")
    finally:
        writer.join()
        os.close(read)
    assert piped["torque_rms_nm"] == expected["torque_rms_nm"]


def test_a_fifo_written_once_serves_the_digest_and_the_parse(tmp_path):
    path = motion_csv(tmp_path)
    fifo = tmp_path / "motion.fifo"
    os.mkfifo(fifo)

    def write_once():
        with open(fifo, "wb") as handle:  # blocks until fdbench opens it for reading
            handle.write(path.read_bytes())

    writer = threading.Thread(target=write_once)
    writer.start()
    try:
        result = invoke(["simulate", "--motion", fifo, "-f", "json", "-q"])
    finally:
        writer.join()
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["status"] == "success"


# ---- the arm's singular configurations ---------------------------------------------------------


def arm_csv(tmp_path, shoulder, elbow):
    path = tmp_path / "arm.csv"
    path.write_text("t,shoulder,elbow\n" + "".join(f"{t},{shoulder + a / 3},{elbow}\n" for t, a in motion_rows()))
    return path


def test_the_arm_s_elbow_at_90_degrees_is_not_singular(tmp_path):
    result = invoke(["inverse", "--model", "arm2", "--motion", arm_csv(tmp_path, 10.0, 90.0), "-f", "json", "-q"])
    assert result.exit_code == 0, result.stderr


@pytest.mark.parametrize("shoulder, elbow", [(-95.0, 5.0), (20.0, 70.0)])
def test_the_paper_s_singular_configurations_are_tracked_by_the_arm(tmp_path, shoulder, elbow):
    """shoulder -95 + 10 sin(3t) deg passes -90 deg; shoulder + elbow = 90 deg at t = 0: where the
    paper's angle constraint alone is singular, the engine's switches form, so the arm follows."""
    path = arm_csv(tmp_path, shoulder, elbow)
    result = invoke(["control", "--model", "arm2", "--motion", path, "-f", "json", "-q"])
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["status"] == "success" and record["rmse_rot_deg"] < 0.01


# ---- options that do not apply are errors, not ignored -----------------------------------------


def saved_params(tmp_path, options):
    path = tmp_path / "params.json"
    path.write_text(json.dumps({"torque": "cs", "torque_options": options, "feedforward": False,
                                "kinematics": "paper", "params": [0.0] * 11}))
    return path


@pytest.mark.parametrize("options, key", [({"knots": 11, "wings": 3}, "'wings'"), ({"knots": 11, "terms": -5}, "'terms'")])
def test_a_parameter_file_s_unknown_torque_option_is_refused(tmp_path, options, key):
    assert_one_line_error(invoke(["simulate", "--params", saved_params(tmp_path, options), "-q"]),
                          "--params", key, "knots")


@pytest.mark.parametrize("make, words", [
    (lambda: fdbench.control_spec(controller="lqr", controller_options={"q_angl": 1}), ("'q_angl'", "q_angle")),
    (lambda: fdbench.control_spec(controller_options={"q_angle": 1}), ("'q_angle'", "kp, kd")),
    (lambda: fdbench.optimize_spec("cs", "bfgs", torque_options={"knot": 5}), ("'knot'", "knots")),
    (lambda: fdbench.optimize_spec("cs", "bfgs", optimizer_options={"popsize": 5}), ("'popsize'", "bfgs")),
    (lambda: fdbench.run(fdbench.RunSpec(command="optimize", torque="pf", optimizer="bfgs", seed=0, budget=2,
                                         torque_options=(("term", 3),))), ("'term'", "terms")),
])
def test_a_misspelt_option_from_python_is_a_value_error_naming_it(make, words):
    with pytest.raises(ValueError) as error:
        make()
    for word in words:
        assert word in str(error.value)


def test_a_sweep_s_shared_options_go_to_the_methods_that_take_them():
    shared = fdbench.optimize_spec("pf", "bfgs", torque_options={"knots": 11, "hidden": 4, "terms": 3},
                                   optimizer_options={"popsize": 8}, shared_options=True)
    assert shared == fdbench.optimize_spec("pf", "bfgs", torque_options={"terms": 3})


@pytest.mark.parametrize("args, words", [
    (["control", "--controller", "lqr", "--kp", "50"], ("--kp", "--controller lqr", "--q-angle")),
    (["control", "--controller", "pd", "--bandwidth", "5"], ("--bandwidth", "--controller pd")),
    (["optimize", "--torque", "ann", "--knots", "5"], ("--knots", "--torque ann", "--hidden")),
    (["optimize", "--opt", "bfgs", "--popsize", "5"], ("--popsize", "--opt bfgs")),
])
def test_an_option_given_for_another_method_is_refused(args, words):
    assert_one_line_error(invoke([*args, "-q"]), *words)


def test_defaults_of_other_methods_do_not_count_as_given():
    result = invoke(["control", "--controller", "lqr", "-f", "json", "-q"])
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["controller_options"] == "q_angle=10000.0 q_rate=1.0 r_torque=1.0"


# ---- memory: the work is bounded before it starts ----------------------------------------------


@pytest.fixture
def four_gib(monkeypatch):
    """The budget of a machine with 16 GiB, whatever this one has."""
    from fdbench import memory

    monkeypatch.setattr(memory, "budget_bytes", lambda: 4 * 2**30)


def long_motion(tmp_path):
    """10 rows spanning 900,000 s."""
    path = tmp_path / "long.csv"
    path.write_text("t,theta\n" + "".join(f"{i * 100_000},{10 + i}\n" for i in range(10)))
    return path


@pytest.mark.parametrize("extra, option", [([], "--dt"), (["--dt", "0.1", "--sample-dt", "1e-4"], "--sample-dt"),
                                           (["--integrator", "rk45", "--sample-dt", "1e-4"], "--sample-dt")])
def test_a_long_motion_is_refused_before_any_allocation(tmp_path, four_gib, extra, option):
    args = ["simulate", "--motion", long_motion(tmp_path), "--cutoff", "1e-6", *extra, "-q"]
    assert_one_line_error(invoke(args), "memory", option)


def test_a_tiny_step_on_a_long_motion_is_refused(tmp_path, four_gib):
    rows = [(t / 100, 30 * math.sin(t / 100)) for t in range(10_001)]  # 100 s at 100 Hz
    args = ["control", "--motion", motion_csv(tmp_path, rows=rows), "--dt", "1e-6", "-q"]
    assert_one_line_error(invoke(args), "memory", "--dt")


def test_a_capture_too_dense_for_memory_is_refused(tmp_path, four_gib):
    args = ["inverse", "--motion", long_motion(tmp_path), "--cutoff", "1e-6", "--sample-dt", "1000",
            "--noise-deg", "1", "--capture-hz", "1000", "-q"]
    assert_one_line_error(invoke(args), "memory", "--capture-hz")


def test_a_population_within_every_option_s_bounds_but_too_large_together(four_gib):
    args = ["optimize", "--model", "arm2", "--popsize", "10000", "--budget", "10000", "--torque", "ann", "--hidden",
            "50", "--opt", "cmaes", "-q"]
    assert_one_line_error(invoke(args), "memory", "--popsize", "--hidden")


# ---- implausible constants: a warning, and the likely cause of a failure -----------------------


def test_centimetres_typed_for_metres_are_warned_about_and_named_as_the_cause():
    result = invoke(["simulate", "--plant", "L12=30", "-f", "json"])
    assert result.exit_code == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if line.startswith("fdbench: warning: --plant")]
    assert len(warnings) == 1 and "L12 = 30 m" in warnings[0], result.stderr
    record = json.loads(result.stdout)
    assert record["status"] != "success"
    assert "likely cause: L12 = 30 m" in record["message"] and "--alpha" not in record["message"]


@pytest.mark.parametrize("change, words", [("m=0.01", "m = 0.01 kg"), ("I1=40", "I1 = 40 kg m^2")])
def test_implausible_masses_and_inertias_are_warned_about(change, words):
    result = invoke(["inverse", "--plant", change, "-f", "json"])
    assert result.exit_code == 0, result.stderr
    assert words in result.stderr


def test_a_mass_the_inertia_about_the_elbow_cannot_hold_is_refused():
    """I1 is the inertia about the elbow: 1000 kg at L1G = 0.11 m alone has 12.1 kg m^2 about it,
    more than I1's 0.04, so no body has these constants (its inertia about the centre of mass would
    be negative)."""
    result = invoke(["inverse", "--plant", "m=1000", "-f", "json"])
    assert result.exit_code == 2 and result.stdout == ""
    assert "--plant m=1000" in result.stderr and "inertia" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_plausible_constants_and_quiet_runs_have_no_warning():
    assert "warning" not in invoke(["inverse", "--plant", "L12=0.3", "-f", "json"]).stderr
    assert invoke(["inverse", "--plant", "L12=30", "-f", "json", "-q"]).stderr == ""


# ---- options within their bounds that the method cannot be carried out with -------------------------


@pytest.mark.parametrize("args, words", [
    (["--controller", "computed-torque", "--bandwidth", "1e308"], ("--controller computed-torque", "bandwidth")),
    (["--controller", "lqr", "--q-rate", "1e300"], ("--controller lqr", "q_rate")),
    (["--model", "arm26", "--controller", "cmc", "--reserve-optimal-force", "1e-300"],
     ("--controller cmc", "reserve_optimal_force")),
])
def test_a_design_that_fails_on_extreme_options_is_bad_input_naming_them(args, words):
    """Finite, positive options whose design has no finite solution (an overflowing gain, a Riccati
    equation without one, a static optimisation that cannot converge) are one line and exit 2."""
    assert_one_line_error(invoke(["control", *args, "-q"]), *words, "choose less extreme values")


def test_static_optimisation_that_fails_on_extreme_options_is_bad_input():
    assert_one_line_error(invoke(["inverse", "--model", "arm26", "--muscles", "--activation-exponent", "1e308"]),
                          "--muscles", "activation_exponent")


def test_a_mismatch_study_refuses_a_plant_change_of_its_own_constant(tmp_path):
    """The study sets the swept constant itself: the same key in --plant would be dropped silently."""
    line = assert_one_line_error(invoke(["study", "mismatch", "--param", "I1", "--levels", "0", "--plant", "I1=0.05",
                                         "--seeds", "1", "--db", tmp_path / "r.sqlite"]), "--plant", "I1")
    assert not (tmp_path / "r.sqlite").exists(), line


def test_the_rtol_bound_said_is_the_bound_kept():
    from fdbench.integrate import MIN_RTOL, check_tolerances

    shown = assert_one_line_error(invoke(["control", "--integrator", "radau", "--rtol", "2.2e-14"]), "--rtol")
    said = float(shown.split("= [", 1)[1].split(",", 1)[0])
    assert said == MIN_RTOL
    check_tolerances(said, 1e-9)  # accepted


@pytest.mark.parametrize("option", ["--residual-force-weight", "--residual-moment-weight"])
def test_collocation_s_residual_weights_need_a_floating_base(option):
    """Without a floating base there are no residuals to weigh: the option is refused, not dropped."""
    assert_one_line_error(invoke(["collocate", "--nodes", "20", option, "1", "-q"]), option, "floating base")
