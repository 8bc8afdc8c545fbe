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

from fdbench import files
from fdbench.cli import app

runner = CliRunner()


def invoke(args):
    return runner.invoke(app, [str(a) for a in args])


def assert_one_line_error(result, *words):
    """Exit 2, nothing on stdout, one 'fdbench: error:' line on stderr naming ``words``."""
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.stdout)
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:"), result.stderr
    for word in words:
        assert word in lines[0], lines[0]


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


@pytest.mark.parametrize("shoulder, elbow, words", [(-95.0, 5.0, ("the shoulder",)),
                                                    (20.0, 70.0, ("shoulder + elbow",))])
def test_the_arm_s_singular_configurations_are_refused_before_any_work(tmp_path, shoulder, elbow, words):
    """shoulder -95 + 10 sin(3t) deg passes -90 deg; shoulder + elbow = 90 deg at t = 0."""
    path = arm_csv(tmp_path, shoulder, elbow)
    assert_one_line_error(invoke(["simulate", "--model", "arm2", "--motion", path, "-q"]), "--motion", *words)
