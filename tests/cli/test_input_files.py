"""Input files as a hostile or careless user writes them: numbers with no sense (1e300 deg, a
1e300 N load, times in the wrong unit), duplicate and short columns, control characters and
endless names in what a message quotes; each refused in one line (exit 2, nothing written). And
the derivative estimate at a recording's ends against eq. 5's closed form. (OpenSim models' names:
tests/engine/test_osim.py, which imports opensim.)"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers import forearm_closed_form as forearm
from helpers.cli_checks import assert_one_line_error
from fdbench.cli import app
from fdbench.files import quoted, shown
from fdbench.multibody.motions import A1, butterworth_design_hz, eq5, read_motion_csv

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def refused(tmp_path: Path, *args, words=()) -> str:
    """The command refused in one line naming ``words``, with no output file left."""
    out = tmp_path / "out.json"
    line = assert_one_line_error(invoke(*args, "-f", "json", "-o", out), *words)
    assert not out.exists()
    assert "\x1b" not in line
    return line


def motion_csv(path: Path, t, theta_deg, header: str = "t,theta") -> Path:
    np.savetxt(path, np.column_stack([t, theta_deg]), delimiter=",", header=header, comments="", fmt="%.17g")
    return path


def storage(path: Path, labels, rows, in_degrees: bool = True) -> Path:
    """An OpenSim .mot: 4 header lines, 'endheader' on line 5, the labels on line 6, rows from line 7."""
    text = [path.stem, "version=1", f"nRows={len(rows)}", f"inDegrees={'yes' if in_degrees else 'no'}", "endheader",
            "\t".join(labels)] + ["\t".join(repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(text) + "\n")
    return path


T = np.linspace(0.0, 1.0, 101)
REACH = np.column_stack([T, -20 + 35 * T, 30 + 25 * T])  # arm2's shoulder and elbow (deg)


# ---------------------------------------------------------------- numbers with no sense


def test_an_angle_of_1e300_deg_is_refused_in_a_csv_and_in_a_mot(tmp_path):
    theta = np.full(T.shape, -30.0)
    theta[50] = 1e300
    refused(tmp_path, "inverse", "--motion", motion_csv(tmp_path / "huge.csv", T, theta),
            words=("huge.csv", "the angle is 1.745e+298 rad", "t = 0.5 s", "at most 1e+06"))
    rows = REACH.copy()
    rows[3, 2] = -1e300
    refused(tmp_path, "inverse", "--model", "arm2", "--motion", storage(tmp_path / "huge.mot", ["time", "shoulder", "elbow"], rows),
            words=("huge.mot", "elbow", "-1.745e+298 rad", "t = 0.03 s"))


def test_given_rates_of_1e300_and_overflowing_times_are_refused(tmp_path):
    path = tmp_path / "rates.csv"
    np.savetxt(path, np.column_stack([T, np.full(T.shape, -30.0), np.zeros_like(T), np.full(T.shape, 1e300)]),
               delimiter=",", header="t,theta,theta_vel,theta_acc", comments="", fmt="%.17g")
    refused(tmp_path, "inverse", "--motion", path, words=("the acceleration is", "rad/s^2", "at most 1e+06"))
    far = (np.arange(11.0) - 5) * 3e307  # each step finite, the span 3e308 is not
    refused(tmp_path, "inverse", "--motion", motion_csv(tmp_path / "far.csv", far, np.full(far.shape, -30.0)),
            words=("far.csv", "times must be finite numbers apart"))


def test_times_in_the_wrong_unit_are_refused_naming_the_interval(tmp_path):
    """eq. 5 recorded with its times scaled by 1e-7 (samples 1e-10 s apart) was filtered at an
    absurd rate and reported -50.9 deg for a -45 deg start."""
    t = np.linspace(0.0, 1.0, 1001)
    theta = np.degrees(eq5(t, "exact")[0])
    refused(tmp_path, "inverse", "--motion", motion_csv(tmp_path / "scaled.csv", t * 1e-7, theta),
            words=("scaled.csv", "1e-10 s apart", "at least 1e-05 s apart", "seconds"))


def test_the_fastest_capture_allowed_is_not_refused_for_its_clock_s_rounding():
    """--capture-hz 100000 samples every 1e-5 s, the smallest interval a recording may have; the
    rounding of linspace's steps (1e-5 - 1e-21 s) must not refuse it, and it is still eq. 5 within
    what the filter removes (``filter_bound``)."""
    from fdbench.multibody.motions import as_motion, noisy

    captured = noisy(as_motion("exact"), 0.0, 1, capture_hz=100_000.0)
    t = np.linspace(0.1, 0.9, 9)
    np.testing.assert_allclose(captured(t)[0], eq5(t, "exact")[0], atol=2 * filter_bound(100_000.0) * math.pi / 4)


def test_a_load_of_1e300_n_is_refused_naming_the_load_and_time(tmp_path):
    from helpers.loads_files import storage as loads_storage, write

    loads = write(tmp_path, data=loads_storage(value="1e300"))
    refused(tmp_path, "inverse", "--model", "leg3", "--loads", loads,
            words=("push.mot", "the force of load 'push' is 1e+300 N", "t = 0 s", "at most 1e+06"))


def test_a_datafile_name_keeps_its_inner_spaces(tmp_path):
    from helpers.loads_files import loads_xml, storage as loads_storage

    (tmp_path / "my  grf.mot").write_text(loads_storage())
    (tmp_path / "push.xml").write_text(loads_xml(datafile="  my  grf.mot "))  # outer spaces are not the name's
    result = invoke("inverse", "--model", "leg3", "--loads", tmp_path / "push.xml", "-f", "json", "-q")
    assert result.exit_code == 0, result.stderr
    (tmp_path / "push.xml").write_text(loads_xml(datafile="my\tgrf.mot"))
    refused(tmp_path, "inverse", "--model", "leg3", "--loads", tmp_path / "push.xml",
            words=("<datafile> 'my\\tgrf.mot' is not a file name",))


# ---------------------------------------------------------------- motion files


def test_duplicate_labels_of_a_mot_are_refused_naming_both_and_the_line(tmp_path):
    rows = np.column_stack([REACH, REACH[:, 2]])
    path = storage(tmp_path / "twice.mot", ["time", "shoulder", "elbow", "ELBOW"], rows)
    refused(tmp_path, "inverse", "--model", "arm2", "--motion", path,
            words=("twice.mot line 6", "'elbow' and 'ELBOW'", "ignoring case"))
    # a state's path names the same coordinate
    path = storage(tmp_path / "paths.mot", ["time", "shoulder", "elbow", "/jointset/j2/elbow/value"], rows)
    refused(tmp_path, "inverse", "--model", "arm2", "--motion", path, words=("'elbow' and '/jointset/j2/elbow/value'",))
    csv = tmp_path / "twice.csv"
    csv.write_text("\n\nt,theta,THETA\n" + "".join(f"{t},-30,-30\n" for t in T))
    refused(tmp_path, "inverse", "--motion", csv, words=("twice.csv line 3", "'theta' and 'THETA'"))


def test_a_short_row_or_a_word_is_named_by_its_line(tmp_path):
    text = storage(tmp_path / "short.mot", ["time", "shoulder", "elbow"], REACH).read_text().splitlines()
    text[10] = text[10].rsplit("\t", 1)[0]  # line 11 lacks its elbow
    (tmp_path / "short.mot").write_text("\n".join(text) + "\n")
    refused(tmp_path, "inverse", "--model", "arm2", "--motion", tmp_path / "short.mot",
            words=("short.mot line 11", "2 values", "no value for 'elbow'"))
    text[10] = text[10] + "\tbad"
    (tmp_path / "short.mot").write_text("\n".join(text) + "\n")
    refused(tmp_path, "inverse", "--model", "arm2", "--motion", tmp_path / "short.mot",
            words=("short.mot line 11", "column 'elbow' holds 'bad'"))
    csv = tmp_path / "short.csv"
    csv.write_text("t,theta\n\n" + "".join(f"{t},-30\n" for t in T[:5]) + "0.05\n" + "".join(f"{t},-30\n" for t in T[6:]))
    refused(tmp_path, "inverse", "--motion", csv, words=("short.csv line 8", "no value for 'theta'"))


def test_control_characters_of_labels_are_escaped_in_errors_and_warnings(tmp_path):
    evil = "\x1b]0;owned\x07\x1b[31mred"
    csv = tmp_path / "evil.csv"
    csv.write_text(f"{evil},theta\n" + "".join(f"{t},-30\n" for t in T))
    line = refused(tmp_path, "inverse", "--motion", csv, words=("found \\x1b]0;owned\\x07\\x1b[31mred, theta",))
    assert "\x07" not in line
    rows = np.column_stack([REACH, REACH[:, 2]])
    path = storage(tmp_path / "extra.mot", ["time", "shoulder", "elbow", evil], rows)
    result = invoke("inverse", "--model", "arm2", "--motion", path, "-f", "json", "-o", tmp_path / "out.json")
    assert result.exit_code == 0, result.stderr
    assert "\x1b" not in result.stderr and "\x07" not in result.stderr
    assert "ignored: \\x1b]0;owned\\x07\\x1b[31mred" in result.stderr


def test_shown_and_quoted_make_one_short_line_of_any_text():
    assert shown("a\tb\n\nc") == "a b c"
    assert quoted("a\tb") == "'a\\tb'" and quoted("\x1b[2J\u202e") == "'\\x1b[2J\\u202e'"
    words = " ".join(["word"] * 40)
    cut = shown(words, 80)
    assert cut.endswith("...") and cut[:-3] == " ".join(["word"] * 16) and len(cut) <= 83  # on a word's end
    assert shown("b" * 100000) == "b" * 80 + "..."
    assert quoted("x" * 78 + "\x1b") == "'" + "x" * 78 + "...'"  # an escape is not cut in two


# ---------------------------------------------------------------- a recording's ends


def filter_bound(rate_hz: float = 1000.0, cutoff_hz: float = 6.0) -> float:
    """The fraction of a component at eq. 5's highest frequency that the zero-lag filter removes:
    each pass has |H|^2 = 1 / (1 + (f / f_design)^4), two passes 1 / (1 + (f / f_design)^4), so
    1 - |H| = r / (1 + r), r = (f / f_design)^4. Eq. 5 (exact) is a sine of t* whose frequency is
    dt*/dt <= a1 + 2 (1 - a1) = 1.95 Hz."""
    r = ((A1 + 2 * (1 - A1)) / butterworth_design_hz(cutoff_hz, rate_hz)) ** 4
    return r / (1 + r)


def test_the_ends_of_a_recording_without_rates_match_eq5(tmp_path):
    """eq. 5 (exact) sampled every 1 ms into a CSV without rates, read back: at both ends (at rest)
    the estimated rate, acceleration and inverse-dynamics torque agree with the closed form within
    twice what the filter removes anywhere (its gain at 1.95 Hz times the largest rate or
    acceleration: once for the filter, once for the reflected end it needs). Before, the filter's
    padding (90 samples, a third of its settling) left a transient: 2.7 deg/s and 22 deg/s^2 at
    t = 1 s."""
    t = np.round(np.arange(0.0, 1.0 + 5e-4, 1e-3), 10)
    theta, vel, acc = eq5(t, "exact")
    path = motion_csv(tmp_path / "eq5.csv", t, np.degrees(theta))
    tight = 2 * filter_bound()
    vel_tol, acc_tol = tight * np.max(np.abs(vel)), tight * np.max(np.abs(acc))  # rad/s, rad/s^2
    _, est_vel, est_acc = read_motion_csv(path)(t)
    ends = [0, -1]
    assert np.all(np.abs(est_vel[ends] - vel[ends]) < vel_tol), (np.degrees(est_vel[ends] - vel[ends]), np.degrees(vel_tol))
    assert np.all(np.abs(est_acc[ends] - acc[ends]) < acc_tol), (np.degrees(est_acc[ends] - acc[ends]), np.degrees(acc_tol))
    # through the command line: the torque at the ends is I1 theta'' + cos(theta) (F L12 + m g L1G)
    result = invoke("inverse", "--motion", path, "-f", "csv", "-q")
    assert result.exit_code == 0, result.stderr
    table = np.loadtxt(io.StringIO(result.stdout), delimiter=",", skiprows=1)
    exact_torque = forearm.elbow_torque(theta, acc)
    theta_tol = tight * (math.pi / 4)  # the angle's own content is eq. 5's amplitude L
    torque_tol = forearm.I1 * acc_tol + forearm.GRAVITY_TORQUE * theta_tol
    assert np.all(np.abs(table[ends, 4] - exact_torque[ends]) < torque_tol), (table[ends, 4], exact_torque[ends])
    assert np.all(np.abs(np.radians(table[ends, 2]) - vel[ends]) < vel_tol)
    assert np.all(np.abs(np.radians(table[ends, 3]) - acc[ends]) < acc_tol)


def test_the_ends_of_a_noisy_recording_are_no_noisier_than_its_middle():
    """eq. 5 captured at 1 kHz with 0.1 deg of noise (10 seeds): the RMS error of the estimated
    acceleration at each end is at most the RMS error over the middle 80 % (the filter's own noise);
    an end estimate from a local fit of the noisy samples would be tens of times noisier."""
    from fdbench.multibody.motions import SampledMotion

    t = np.linspace(0.0, 1.0, 1001)
    theta, _, acc = eq5(t, "exact")
    errors = []
    for seed in range(10):
        noisy = theta + np.radians(0.1) * np.random.default_rng(seed).standard_normal(len(t))
        errors.append(SampledMotion(t, noisy)(t)[2] - acc)
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    middle = np.sqrt(np.mean(rms[100:-100] ** 2))
    assert rms[0] <= middle and rms[-1] <= middle, (np.degrees(rms[[0, -1]]), np.degrees(middle))
