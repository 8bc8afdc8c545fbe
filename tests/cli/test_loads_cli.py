"""``--loads FILE.xml`` on the command line: bad input refused before any work in one line (exit
2, nothing written) on inverse, control and simulate; the loads file and its data file are inputs no
output may overwrite; a run's identity holds the files' content, not their names, and a run whose
loads changed since it was specified is refused."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.cli_checks import assert_one_line_error
from helpers.loads_files import COLUMNS, loads_xml, storage, write
from helpers.paths import ROOT

from fdbench.cli import app
from fdbench.files import BadFile
from fdbench.models import find_model
from fdbench.multibody.model import Frame
from fdbench.multibody.model_files import to_toml

WALK = next((where for where in (ROOT / "examples" / "opensim", ROOT.parent / "shared" / "data" / "opensim",
                                  ROOT.parent.parent / "shared" / "data" / "opensim")
             if (where / "subject01_walk_grf.xml").exists()), None)  # the walk's files: shipped, or beside the source
COMMANDS = ("inverse", "control", "simulate")
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


BAD = {  # case: (how the folder is set up -> the --loads argument, words of the message)
    "missing file": (lambda f: f / "nothing.xml", ("--loads", "nothing.xml", "does not exist")),
    "a directory": (lambda f: (f / "folder.xml").mkdir() or f / "folder.xml", ("--loads", "is a directory")),
    "not XML": (lambda f: write(f, xml="loads, but no XML <<"), ("--loads", "is not an XML file")),
    "no ExternalLoads": (lambda f: write(f, xml="<OpenSimDocument><Model/></OpenSimDocument>"),
                         ("--loads", "no <ExternalLoads>")),
    "no ExternalForce": (lambda f: write(f, xml="<ExternalLoads><objects/><datafile>push.mot</datafile>"
                                              "</ExternalLoads>"), ("--loads", "no enabled <ExternalForce>")),
    "no datafile": (lambda f: write(f, xml=loads_xml(datafile=None)), ("--loads", "names no <datafile>")),
    "datafile missing": (lambda f: write(f, xml=loads_xml(datafile="gone.mot")),
                         ("--loads", "<datafile> of push.xml", "gone.mot does not exist")),
    "datafile not a storage": (lambda f: write(f, data="t,f_vx\n0,1\n"), ("<datafile> of push.xml", "endheader")),
    "unknown body": (lambda f: write(f, xml=loads_xml(body="calf")),
                     ("ExternalForce 'push'", "applied_to_body", "'calf'", "thigh, shank, foot")),
    "unknown frame": (lambda f: write(f, xml=loads_xml(point_frame="heel")),
                      ("point_expressed_in_body", "'heel'", "thigh, shank, foot, ground")),
    "missing column": (lambda f: write(f, data=storage(columns=COLUMNS[:3] + COLUMNS[4:])),
                       ("push.mot", "no column 'f_px'", "push.xml")),
    "not a number": (lambda f: write(f, data=storage(value="nan")), ("push.mot", "the force of load 'push' is nan N", "must be finite")),
    "data short of the motion": (lambda f: write(f, data=storage(0.0, 0.5)),
                                 ("push.xml", "the loads cover 0 to 0.5 s", "not all of 0 to 1 s")),
    "data after the motion's start": (lambda f: write(f, data=storage(0.2, 1.5)), ("the loads cover 0.2 to 1.5 s",)),
}


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("case", list(BAD))
def test_bad_loads_are_refused_in_one_line_before_any_work_and_nothing_is_written(tmp_path, case, command):
    setup, words = BAD[case]
    loads = setup(tmp_path)
    out, history = tmp_path / "out.json", tmp_path / "history.csv"
    extra = ("--save-history", history) if command == "simulate" else ()
    result = invoke(command, "--model", "leg3", "--loads", loads, "-f", "json", "-o", out, *extra)
    assert_one_line_error(result, *words)
    assert not out.exists() and not history.exists()


def test_an_unknown_body_is_named_with_the_model_s_bodies_and_frames(tmp_path):
    model = replace(find_model("leg3"), frames=(Frame("heel", "foot", (-0.05, -0.04), 0.2),))
    (tmp_path / "leg.toml").write_text(to_toml(model))
    loads = write(tmp_path, xml=loads_xml(body="toe"))
    line = assert_one_line_error(invoke("inverse", "--model", tmp_path / "leg.toml", "--loads", loads))
    assert "unknown body 'toe'" in line and "thigh, shank, foot, heel" in line
    # on its frame the load is accepted
    assert invoke("inverse", "--model", tmp_path / "leg.toml", "--loads", write(tmp_path, xml=loads_xml(body="heel")),
                  "-q").exit_code == 0


@pytest.mark.skipif(WALK is None, reason="the walk's files are not found")
@pytest.mark.parametrize("command", COMMANDS)
def test_the_walk_s_ground_reactions_on_a_model_without_feet_are_refused(tmp_path, command):
    out = tmp_path / "out.json"
    result = invoke(command, "--model", "leg3", "--loads", WALK / "subject01_walk_grf.xml", "-o", out)
    assert_one_line_error(result, "subject01_walk_grf.xml", "'calcn_r'", "thigh, shank, foot")
    assert not out.exists()


@pytest.mark.parametrize("target", ["push.xml", "push.mot"])
def test_no_output_writes_over_the_loads_file_or_its_data_file(tmp_path, target):
    loads = write(tmp_path)
    before = (tmp_path / target).read_bytes()
    result = invoke("inverse", "--model", "leg3", "--loads", loads, "-f", "csv", "-o", tmp_path / target)
    assert_one_line_error(result, "--output", target, "--loads")
    assert (tmp_path / target).read_bytes() == before


# ---------------------------------------------------------------- identity


@pytest.fixture(scope="module")
def short_motion(tmp_path_factory) -> Path:
    """leg3's swing over its first 0.2 s, rates and accelerations given (a quick run)."""
    folder = tmp_path_factory.mktemp("motion")
    result = invoke("inverse", "--model", "leg3", "--format", "csv")
    assert result.exit_code == 0, result.stderr
    path = folder / "swing.csv"
    path.write_text("\n".join(result.stdout.splitlines()[:202]) + "\n")
    return path


def spec_hash(motion: Path, loads: Path) -> str:
    result = invoke("control", "--model", "leg3", "--motion", motion, "--loads", loads, "-f", "json", "-q")
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["status"] == "success"
    return record["spec_hash"]


def test_the_loads_count_by_their_content_not_their_names(tmp_path, short_motion):
    """The same XML and data under other folder and XML names: the same run. One number changed in
    the data file: another run. No loads: another run again."""
    first = write(tmp_path)
    (tmp_path / "copy").mkdir()
    renamed = write(tmp_path / "copy", name="same_loads.xml")
    changed_folder = tmp_path / "changed"
    changed_folder.mkdir()
    changed = write(changed_folder, data=storage().replace("2.0", "2.5", 1))
    hashes = [spec_hash(short_motion, path) for path in (first, renamed, changed)]
    assert hashes[0] == hashes[1] != hashes[2]
    bare = invoke("control", "--model", "leg3", "--motion", short_motion, "-f", "json", "-q")
    assert json.loads(bare.stdout)["spec_hash"] not in hashes


def test_a_run_whose_loads_changed_since_it_was_specified_is_refused(tmp_path, short_motion):
    """A spec made with the files' digests (as the command line makes it), then the data file
    changed: running it is refused naming the loads file; restored, it runs."""
    from fdbench.spec import RunSpec, motion_digest
    from fdbench import run_inputs as runs
    from fdbench.multibody.loads import loads_digest

    loads = write(tmp_path)
    inputs = tuple(sorted((("--loads", loads_digest(loads)), ("--motion", motion_digest(str(short_motion))))))
    spec = RunSpec(command="control", kinematics=str(short_motion), model_name="leg3", loads=str(loads), inputs=inputs)
    original = (tmp_path / "push.mot").read_text()
    (tmp_path / "push.mot").write_text(storage(value="3.25"))
    with pytest.raises(BadFile, match=r"--loads: .*push.xml \(or its data file\) has changed since this run was"):
        runs.check(spec)
    (tmp_path / "push.mot").write_text(original)
    runs.check(spec)  # the files as specified again


def test_the_walk_s_benchmark_skips_cleanly_without_opensim(tmp_path):
    """benchmarks/bench_walk_inverse.py where OpenSim cannot be imported: one line saying so, exit 0."""
    import os
    import subprocess
    import sys

    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "opensim.py").write_text("raise ImportError('No module named opensim')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(hidden), os.environ.get("PYTHONPATH", ""), str(ROOT)]))
    args = [sys.executable, str(ROOT / "benchmarks" / "bench_walk_inverse.py")]
    if WALK is not None:
        args += ["--data", str(WALK)]
    done = subprocess.run(args, capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("skipped: ") and len(done.stdout.strip().splitlines()) == 1, done.stdout
    assert WALK is None or "pip install '.[opensim]'" in done.stdout


def test_the_loads_are_read_on_the_recording_s_clock(tmp_path, short_motion):
    """A motion file whose times start at 0.1 s takes the loads of 0.1 s on: its generalised forces
    equal those of the whole recording at the same times (loads ramping in time, so a shifted clock
    would show); before 0.1 s the data may be missing."""
    import io

    import pandas as pd

    ramp = ["push", "endheader", "\t".join(("time",) + COLUMNS)]
    ramp += ["\t".join(repr(float(v)) for v in [t, 40 * t, -100 + 300 * t, 0.0, 0.1, 0.5 - t, 0.0, 0.0, 0.0, 5 * t])
             for t in np.linspace(0.1, 0.2, 11)]
    whole_ramp = ramp[:3] + ["\t".join(map(repr, [0.0, 0.0, -100.0, 0.0, 0.1, 0.5, 0.0, 0.0, 0.0, 0.0]))] + ramp[3:]
    late = tmp_path / "late"
    late.mkdir()
    late_loads = write(late, data="\n".join(ramp) + "\n")
    whole_loads = write(tmp_path, data="\n".join(whole_ramp) + "\n")
    lines = short_motion.read_text().splitlines()
    (tmp_path / "late.csv").write_text("\n".join(lines[:1] + lines[101:]) + "\n")  # t from 0.1 s
    runs = {}
    for key, motion, loads in (("whole", short_motion, whole_loads), ("late", tmp_path / "late.csv", late_loads)):
        result = invoke("inverse", "--model", "leg3", "--motion", motion, "--loads", loads, "-f", "csv")
        assert result.exit_code == 0, result.stderr
        runs[key] = pd.read_csv(io.StringIO(result.stdout))
    whole = runs["whole"][runs["whole"]["t"] >= 0.1 - 1e-9].reset_index(drop=True)
    late_run = runs["late"]
    assert len(late_run) == len(whole) == 101
    torques = [c for c in whole.columns if c.endswith("_torque")]
    np.testing.assert_allclose(late_run[torques].to_numpy(), whole[torques].to_numpy(), rtol=1e-9, atol=1e-9)
    result = invoke("inverse", "--model", "leg3", "--motion", short_motion, "--loads", late_loads)
    assert_one_line_error(result, "the loads cover 0.1 to 0.2 s", "not all of 0 to 0.2 s")
