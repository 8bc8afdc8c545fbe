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


DECLARING_PLUGIN = '''
import math
from fdbench.method_options import MethodOption
from fdbench.optimizers import OPTIMIZERS, Optimizer

@OPTIMIZERS.register("stepper")
class Stepper(Optimizer):
    summary = "one step per parameter and direction, then stop (a plugin declaring its option)"
    command_line = {"stride": MethodOption("step of each trial, in scaled parameter units.", default=0.25)}

    def __init__(self, stride=0.25):
        if not (math.isfinite(stride) and stride > 0):
            raise ValueError(f"--stride must be a positive finite number, got {stride}")
        self.stride = stride

    def run(self, f, x0, seed):
        for i in range(len(x0)):
            for sign in (1.0, -1.0):
                trial = x0.copy()
                trial[i] += sign * self.stride
                f(trial)
        return "done"
'''


def test_a_method_declaring_an_option_gets_a_flag_of_its_own(tmp_path):
    """A registered method that declares an option in ``command_line`` is given a flag by the
    commands of its kind, with no change to the command line: the flag and the bracket make the
    same run, the help lists it under the method's name, and its own check refuses a bad value."""
    (tmp_path / "stepper_plugin.py").write_text(DECLARING_PLUGIN)
    env = dict(os.environ, FDBENCH_PLUGINS="stepper_plugin", COLUMNS="200",
               PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))

    def fdbench(*args):
        return subprocess.run([sys.executable, "-c", "from fdbench.cli import main; main()", *args], env=env,
                              capture_output=True, text=True, timeout=600)

    base = ["optimize", "--torque", "pf", "--terms", "2", "--opt", "stepper", "--budget", "50", "-f", "json", "-q"]
    flag, bracket = fdbench(*base, "--stride", "0.5"), fdbench(*[a if a != "stepper" else "stepper[stride=0.5]" for a in base])
    assert flag.returncode == 0 and bracket.returncode == 0, flag.stderr + bracket.stderr
    first, second = json.loads(flag.stdout), json.loads(bracket.stdout)
    assert first["spec_hash"] == second["spec_hash"] and "stride=0.5" in first["optimizer_options"]
    assert first["evaluations"] == 2 * 6  # two trials per parameter (2 terms, 3 parameters each)
    shown = " ".join(fdbench("optimize", "--help").stdout.split())
    assert "--stride" in shown and "stepper: step of each trial" in shown
    assert "--stride" not in " ".join(fdbench("control", "--help").stdout.split())
    bad = fdbench(*base, "--stride", "-1")
    assert bad.returncode == 2 and bad.stderr.splitlines() == ["fdbench: error: --stride must be a positive finite "
                                                               "number, got -1.0"]
    wrong = fdbench(*[a if a != "stepper" else "bfgs" for a in base], "--stride", "0.5")
    assert wrong.returncode == 2 and "--stride does not apply to --opt bfgs" in wrong.stderr


def test_the_method_flags_are_those_the_registered_methods_declare():
    """Each method flag of a command is one the registry's methods declare, with its default."""
    import typer

    from fdbench.controllers import CONTROLLERS
    from fdbench.method_options import command_line_options
    from fdbench.optimizers import OPTIMIZERS
    from fdbench.torques import TORQUES

    root = typer.main.get_command(app)
    ctx = root.make_context("fdbench", ["optimize"], resilient_parsing=True)

    def flags(name, *registries, only=None):
        command = root.commands[name]
        declared = {}
        for registry in registries:
            declared.update(command_line_options(registry, only))
        params = {p.name: p for p in command.get_params(ctx)}
        assert set(declared) <= set(params), (name, set(declared) - set(params))
        for option, (method_option, _) in declared.items():
            default = params[option].default
            assert default == method_option.default, (name, option, default)
        return set(declared)

    assert flags("control", CONTROLLERS) == {"kp", "kd", "bandwidth", "damping", "q_angle", "q_rate", "r_torque",
                                            "window", "reserve_optimal_force", "tendons"}
    assert flags("optimize", TORQUES, OPTIMIZERS) >= {"hidden", "knots", "terms", "sigma0", "popsize"}
    for command in ("report", "study"):
        assert flags(command, TORQUES, OPTIMIZERS) >= {"hidden", "knots", "terms", "sigma0", "popsize"}
        assert flags(command, CONTROLLERS, only=["pd"]) == {"kp", "kd"}
        names = {p.name for p in root.commands[command].get_params(ctx)}
        assert not names & {"bandwidth", "q_angle"}, command  # the report's control is the paper's PD
    # the report's computed muscle control (on a model with muscles) takes its options; a study runs none
    assert flags("report", CONTROLLERS, only=["cmc"]) == {"window", "reserve_optimal_force", "tendons"}
    assert not {p.name for p in root.commands["study"].get_params(ctx)} & {"window", "tendons"}
