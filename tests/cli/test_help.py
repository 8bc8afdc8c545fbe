"""What a newcomer sees first: --help with the registered names as choices (plugins included) and
no type noise on flags, output options whose names say what they hold (old names still accepted),
and an ``import fdbench`` that costs nothing until an entry point is used."""

from __future__ import annotations

import os
import re
import select
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.integrate import INTEGRATORS
from fdbench.models import named_motions, names
from fdbench.multibody.motions import KINEMATICS
from fdbench.optimizers import OPTIMIZERS
from fdbench.torques import TORQUES

from helpers.processes import GATED_OPTIMIZER, Gate, python_path, wait_until
from helpers.paths import ROOT

EXAMPLES = ROOT / "examples"
COMMANDS = ("inverse", "simulate", "control", "optimize", "report", "methods")


def help_text(*args) -> str:
    result = CliRunner().invoke(app, [*args, "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.stderr
    return result.stdout


def choice(names) -> str:
    return "[" + "|".join(names) + "]"


@pytest.mark.parametrize("command", ("optimize", "report"))
def test_method_options_show_the_registered_names(command):
    text = help_text(command)
    assert choice(TORQUES) in text and choice(OPTIMIZERS) in text
    motions = dict.fromkeys(m for model in names() for m in named_motions(model))  # the library's, in order
    assert choice([*motions, "FILE"]) in text and choice(INTEGRATORS) in text
    assert set(KINEMATICS) <= set(motions)


def test_formats_are_shown_as_choices():
    assert "[table|json|csv]" in help_text("control")
    assert "[md|csv|json]" in help_text("report")


@pytest.mark.parametrize("command", (None, *COMMANDS))
def test_no_help_shows_a_bare_type_for_flags_or_names(command):
    text = help_text(*([command] if command else []))
    assert "<bool>" not in text
    assert "<str>" not in text


def test_plugin_names_appear_among_the_choices():
    env = dict(os.environ, PYTHONPATH=python_path(EXAMPLES), FDBENCH_PLUGINS="my_methods",
               COLUMNS="200")
    exe = Path(sys.executable).with_name("fdbench")
    out = subprocess.run([str(exe), "optimize", "--help"], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert choice([*TORQUES, "linear"]) in out.stdout and choice([*OPTIMIZERS, "random"]) in out.stdout


def test_new_and_old_names_of_the_output_options_write_the_same_files(tmp_path):
    runner = CliRunner()
    base = ["optimize", "--torque", "cs", "--opt", "bfgs", "--budget", "12", "-q", "--format", "json"]
    paths = {name: tmp_path / f"{name}.csv" for name in ("traj_new", "traj_old", "conv_new", "conv_old")}
    for trajectory, convergence, a, b in (("--save-trajectory", "--save-convergence", "traj_new", "conv_new"),
                                          ("--save-history", "--history", "traj_old", "conv_old")):
        result = runner.invoke(app, [*base, trajectory, str(paths[a]), convergence, str(paths[b])])
        assert result.exit_code == 0, result.stderr
    assert paths["traj_new"].read_text() == paths["traj_old"].read_text()
    assert paths["traj_new"].read_text().splitlines()[0].startswith("t,theta,theta_desired")
    assert len(paths["traj_new"].read_text().splitlines()) == 1002
    convergence = paths["conv_new"].read_text().splitlines()
    assert convergence == paths["conv_old"].read_text().splitlines()
    assert convergence[0] == "evaluation,best_objective" and len(convergence) == 13
    text = help_text("optimize")
    assert "--save-trajectory" in text and "--save-convergence" in text


def test_import_fdbench_is_cheap_and_the_entry_points_load_on_use():
    code = ("import sys, fdbench; heavy = [m for m in ('numpy', 'numba', 'pandas', 'scipy') if m in sys.modules]; "
            "print(heavy); print(sorted(fdbench.TORQUES)); print(callable(fdbench.run), callable(fdbench.load_report))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "[]"
    assert lines[1] == str(sorted(TORQUES)) and lines[2] == "True True"
    with pytest.raises(AttributeError):
        import fdbench

        fdbench.no_such_entry_point  # noqa: B018


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pseudo-terminal")
def test_a_person_watching_sees_the_time_left_before_the_run_ends(tmp_path):
    """On a terminal the progress bar estimates the time left from the first evaluations on. The
    run holds after 3 of its 8 evaluations (tests/helpers/plugins/gate_plugin.py) until a frame shows an estimate."""
    gate = Gate(tmp_path)
    master, slave = os.openpty()
    exe = Path(sys.executable).with_name("fdbench")
    proc = subprocess.Popen([str(exe), "optimize", "--opt", GATED_OPTIMIZER, "--budget", "8", "-f", "json",
                             "-o", str(tmp_path / "run.json")], stderr=slave, stdout=subprocess.DEVNULL,
                            env=dict(gate.env, FDBENCH_GATE_AFTER="3"))
    os.close(slave)
    screen = []

    def read() -> bool:
        """Add what the terminal received to ``screen``; False once the command closed it."""
        if not select.select([master], [], [], 0.1)[0]:
            return True
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the command ended and closed it
            return False
        screen.append(chunk)
        return bool(chunk)

    def estimate_while_work_remains() -> bool:
        read()
        text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", b"".join(screen).decode(errors="replace"))
        frames = re.findall(r"(\d+)/8 best \S+ \d+:\d\d:\d\d left \d+:\d\d:\d\d", text)
        return any(int(done) < 8 for done in frames)

    try:
        wait_until(estimate_while_work_remains, "a frame showed the time left", proc)
        gate.open()
        while read():
            pass
        assert proc.wait(timeout=120) == 0
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert (tmp_path / "run.json").is_file()


FORMAT_COMMANDS = (["inverse"], ["simulate"], ["control"], ["optimize"], ["collocate"], ["report"], ["study", "noise"])


def format_choices(text: str) -> list:
    """The choices the help shows for --format ('[md|csv|json]' -> ['md', 'csv', 'json'])."""
    return re.search(r"--format\s+-f\s+\[([a-z|]+)\]", text).group(1).split("|")


@pytest.mark.parametrize("command", FORMAT_COMMANDS, ids=lambda c: c[0])
def test_every_format_help_lists_exactly_the_formats_the_command_accepts(command, tmp_path):
    shown = format_choices(help_text(*command))
    refused = CliRunner().invoke(app, [*command, "--format", "bogus", "--db", str(tmp_path / "r.sqlite")]
                                 if command[0] in ("report", "study") else [*command, "--format", "bogus"])
    assert refused.exit_code == 2
    accepted = refused.stderr.strip().split("valid: ")[1].split(", ")
    assert shown == accepted and not list(tmp_path.iterdir())


def test_study_writes_json_like_its_csv(tmp_path):
    args = ["study", "noise", "--levels", "0", "--seeds", "1", "--torque", "cs", "--opt", "bfgs", "--feedforward",
            "--budget", "5", "--jobs", "1", "-q", "--db", str(tmp_path / "s.sqlite")]
    runner = CliRunner()
    as_json, as_csv = (runner.invoke(app, [*args, "--format", fmt]) for fmt in ("json", "csv"))
    assert as_json.exit_code == 0 and as_csv.exit_code == 0, as_json.stderr + as_csv.stderr
    import io
    import json

    import pandas as pd

    study, frame = json.loads(as_json.stdout), pd.read_csv(io.StringIO(as_csv.stdout))
    assert study["settings"]["study"] == "noise" and len(study["rows"]) == len(frame) == 2
    for row, (_, expected) in zip(study["rows"], frame.iterrows()):
        assert list(row) == list(frame.columns) and row["method"] == expected["method"]
        assert row["rmse_rot_deg_median"] == pytest.approx(expected["rmse_rot_deg_median"], rel=1e-9)


def test_top_level_help_says_what_the_tool_does():
    text = " ".join(help_text().split())
    for what in ("forearm", "any planar tree of bodies", "--model arm2, leg3 or your own model file", "--format table|json|csv", "--format md|csv|json",
                 "collocation", "study"):
        assert what in text, what


def test_no_help_or_message_names_a_package_index_install():
    """fdbench is installed from its source folder: pip install '.[dask]', not 'fdbench[dask]'."""
    from fdbench.execution import DASK_INSTALL

    assert "pip install '.[dask]'" in DASK_INSTALL
    assert "fdbench[dask]" not in help_text("report") and "pip install '.[dask]'" in help_text("report")
    readme = (ROOT / "README.md").read_text()
    assert "fdbench[dask]" not in readme and "pip install '.[dask]'" in readme


BENCHMARKS = sorted((ROOT / "benchmarks").glob("bench_*.py"))


@pytest.mark.parametrize("script", BENCHMARKS, ids=[path.name for path in BENCHMARKS])
def test_every_benchmark_script_answers_help_without_running(script):
    out = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.startswith("usage:"), (script.name, out.stderr[-500:])


def test_the_top_level_help_imports_no_numerics_nor_registry():
    """``fdbench --help`` lists the commands without their choices, which need the registries."""
    code = ("import sys; from fdbench.cli import main; sys.argv = ['fdbench', '--help']\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print([m for m in ('numpy', 'fdbench.torques', 'fdbench.controllers', 'fdbench.models') if m in sys.modules],"
            " file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "Usage" in out.stdout, out.stderr
    assert out.stderr.strip().splitlines()[-1] == "[]"
