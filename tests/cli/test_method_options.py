"""Method options in brackets, as benchopt passes them: ``--opt 'cmaes[sigma0=0.1,popsize=12]'``,
``--torque 'cs[knots=8]'``, ``--controller 'lqr[q_angle=1e5]'``: the same runs as the flags, any
option a method's class takes (a plugin's too, in one file), and one-line errors otherwise."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from helpers.processes import PLUGINS, python_path
from fdbench.cli import app
from fdbench.registry import parse_method

runner = CliRunner()


def as_json(*args, code=0):
    result = runner.invoke(app, [*map(str, args), "-f", "json", "-q"])
    assert result.exit_code == code, result.stderr
    return json.loads(result.stdout) if code == 0 else result.stderr


def test_bracket_options_are_the_flags():
    bracket = as_json("optimize", "--torque", "cs[knots=8]", "--opt", "cmaes[sigma0=0.1,popsize=6]", "--budget", 12)
    flags = as_json("optimize", "--torque", "cs", "--knots", 8, "--opt", "cmaes", "--sigma0", 0.1, "--popsize", 6,
                    "--budget", 12)
    assert bracket["spec_hash"] == flags["spec_hash"] and bracket["rmse_rot_deg"] == flags["rmse_rot_deg"]
    assert bracket["n_params"] == 8 and "popsize=6" in bracket["optimizer_options"]
    lqr = as_json("control", "--controller", "lqr[q_angle=1e5]")
    assert lqr["spec_hash"] == as_json("control", "--controller", "lqr", "--q-angle", "1e5")["spec_hash"]
    pd = as_json("control", "--controller", "pd[kp=100,kd=0.5]")
    assert (pd["kp"], pd["kd"]) == (100.0, 0.5)


@pytest.mark.parametrize("args, words", [
    (["optimize", "--opt", "cmaes[sigma=0.1]"], ["--opt", "takes no option 'sigma'", "sigma0"]),
    (["optimize", "--opt", "cmaes[sigma0=0.1", "--budget", "2"], ["--opt", "NAME[KEY=VALUE"]),
    (["optimize", "--opt", "cmaes[sigma0]"], ["--opt", "KEY=VALUE"]),
    (["optimize", "--opt", "cmaes[sigma0=-1]"], ["--sigma0"]),
    (["optimize", "--opt", "cmaes[sigma0=0.1]", "--sigma0", "0.2"], ["--opt", "sigma0", "both"]),
    (["optimize", "--torque", "cs[knots=3]"], ["--knots"]),
    (["control", "--controller", "lqr[q_angle=x]"], ["--q-angle", "x"]),
    (["report", "--torque", "cs[knots=8]", "--torque", "cs[knots=9]", "--no-beyond"], ["--torque", "knots"]),
])
def test_bad_bracket_options_are_one_line_exit_2(args, words, tmp_path):
    result = runner.invoke(app, [*args, "--db", str(tmp_path / "r.sqlite")] if args[0] in ("report", "optimize", "control")
                           else args)
    lines = result.stderr.splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and all(w in lines[0] for w in words), lines
    assert not (tmp_path / "r.sqlite").exists()


def test_a_report_takes_each_methods_options(tmp_path):
    report = json.loads(runner.invoke(app, [
        "report", "--torque", "cs[knots=8]", "--torque", "pf[terms=2]", "--opt", "bfgs", "--seeds", "1", "--budget", "3",
        "--no-beyond", "--no-control", "--db", str(tmp_path / "r.sqlite"), "-f", "json", "-q"]).stdout)
    labels = {cell["cell"] for cell in report["cells"]}
    assert any("CS (8 points)" in label for label in labels) and any("PF (2 terms)" in label for label in labels), labels


def test_parse_method():
    assert parse_method("cmaes[sigma0=0.1,popsize=12]", "--opt") == ("cmaes", {"sigma0": 0.1, "popsize": 12})
    assert parse_method(" ann[hidden=auto] ", "--torque") == ("ann", {"hidden": "auto"})
    assert parse_method("x[flag=true]", "--opt") == ("x", {"flag": True}) and parse_method("cs", "--t") == ("cs", {})


def test_a_plugin_optimiser_receives_its_option(tmp_path):
    """A plugin is one file; its option comes from the command line like any method's."""
    env = dict(os.environ, FDBENCH_PLUGINS="option_plugin",
               PYTHONPATH=python_path(PLUGINS))

    def optimize(opt):
        done = subprocess.run([sys.executable, "-c", "from fdbench.cli import main; main()", "optimize", "--torque", "pf", "--terms", "2",
                               "--opt", opt, "--budget", "30", "-f", "json", "-q"], env=env, capture_output=True,
                              text=True, timeout=600)
        assert done.returncode in (0, 2), done.stderr
        return done

    coarse, fine = optimize("coordinate-search[step=0.5]"), optimize("coordinate-search[step=0.01]")
    first, second = json.loads(coarse.stdout), json.loads(fine.stdout)
    assert "step=0.5" in first["optimizer_options"] and "step=0.01" in second["optimizer_options"]
    assert first["spec_hash"] != second["spec_hash"] and first["evaluations"] == 30
    bad = optimize("coordinate-search[stride=1]")
    assert bad.returncode == 2 and "takes no option 'stride'" in bad.stderr and "step" in bad.stderr
