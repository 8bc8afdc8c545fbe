"""Methods registered by plugin modules ($FDBENCH_PLUGINS) reach the command line."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from helpers.processes import python_path

PLUGIN = textwrap.dedent('''
    import numpy as np
    from fdbench.optimizers import OPTIMIZERS, Optimizer
    from fdbench.torques import TORQUES, TorqueParameterisation

    @TORQUES.register("linear-plugin")
    class LinearTorque(TorqueParameterisation):
        summary = "straight line a + b t (a plugin)"
        def __init__(self):
            self.n_params = 2
        def prepare(self, t, target, feedforward):
            return np.zeros(2) if feedforward else np.polyfit(t, target, 1)[::-1]
        def evaluate(self, p, t):
            return p[0] + p[1] * np.asarray(t)

    @OPTIMIZERS.register("coordinate-plugin")
    class CoordinateSearch(Optimizer):
        summary = "coordinate search (a plugin)"
        def run(self, f, x0, seed):
            x, fx, step = x0.copy(), f(x0), 0.1
            while True:
                for i in range(len(x)):
                    for sign in (1, -1):
                        trial = x.copy()
                        trial[i] += sign * step
                        ft = f(trial)
                        if ft < fx:
                            x, fx = trial, ft
                step /= 2
''')


def fdbench(args, tmp_path, plugins):
    env = dict(os.environ, FDBENCH_PLUGINS=plugins, PYTHONPATH=python_path(tmp_path))
    exe = Path(sys.executable).with_name("fdbench")
    return subprocess.run([str(exe), *args], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)


def test_plugin_methods_are_listed_and_run(tmp_path):
    (tmp_path / "fdbench_test_plugin.py").write_text(PLUGIN)
    listed = fdbench(["methods"], tmp_path, "fdbench_test_plugin")
    assert listed.returncode == 0, listed.stderr
    assert "linear-plugin" in listed.stdout and "coordinate-plugin" in listed.stdout
    out = fdbench(["optimize", "--torque", "linear-plugin", "--opt", "coordinate-plugin", "--budget", "25",
                   "--format", "json", "--quiet"], tmp_path, "fdbench_test_plugin")
    assert out.returncode == 0, out.stderr
    record = json.loads(out.stdout)
    assert record["torque"] == "linear-plugin" and record["n_params"] == 2
    assert record["evaluations"] == 25
    # the coordinate search starts at the least-squares line and only accepts improvements
    assert record["best_objective"] <= record["initial_objective"]


def test_a_plugin_that_cannot_be_imported_is_bad_input(tmp_path):
    out = fdbench(["methods"], tmp_path, "no_such_fdbench_plugin")
    assert out.returncode == 2
    assert out.stderr.splitlines() == [out.stderr.strip()] and "no_such_fdbench_plugin" in out.stderr
    assert "Traceback" not in out.stderr
