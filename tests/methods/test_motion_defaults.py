"""Defaults that follow the motion: the spline's knots, one every 0.1 s of the motion (the paper's
11 over eq. 5's 1 s), so that a longer recording gets as fine a torque history; runs on the paper's
motion keep their identity."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.spec import RunSpec, optimize_spec
from fdbench.torques.cs import knots_for

runner = CliRunner()


def optimize(*args) -> dict:
    result = runner.invoke(app, ["optimize", "--torque", "cs", "--budget", "4", "-f", "json", "-q", *map(str, args)])
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)


@pytest.fixture(scope="module")
def flexion(tmp_path_factory):
    """A 2.5 s recorded flexion (deg), sampled at 200 Hz."""
    t = np.linspace(0.0, 2.5, 501)
    u = t / 2.5
    theta = -45 + 45 * (10 * u**3 - 15 * u**4 + 6 * u**5) + 5 * np.sin(2 * np.pi * u)
    path = tmp_path_factory.mktemp("motion") / "flexion.csv"
    path.write_text("t,theta\n" + "".join(f"{a:.6f},{b:.9f}\n" for a, b in zip(t, theta)))
    return path


@pytest.mark.parametrize("duration, knots", [(1.0, 11), (2.5, 26), (0.25, 4), (0.05, 4), (0.33, 4), (0.36, 5),
                                             (200.0, 1000)])
def test_one_knot_every_tenth_of_a_second(duration, knots):
    assert knots_for(duration) == knots


def test_a_longer_recording_gets_more_knots_and_its_own_runs(flexion):
    default, eleven = optimize("--motion", flexion), optimize("--motion", flexion, "--knots", 11)
    assert default["torque_options"] == "knots=26" and default["n_params"] == 26
    assert eleven["torque_options"] == "knots=11" and default["spec_hash"] != eleven["spec_hash"]
    assert default["t_end"] == pytest.approx(2.5)


def test_the_paper_motion_keeps_its_11_knots_and_its_hash():
    """The command line always wrote --knots 11 into the spec; the Python API left it out: both
    keep the hashes their stored runs have."""
    given, default = optimize("--knots", 11), optimize()
    assert default["torque_options"] == "knots=11" and default["spec_hash"] == given["spec_hash"]
    api = optimize_spec("cs", "bfgs", budget=4)
    assert "knots" not in dict(api.torque_options)
    assert api.hash() == RunSpec(command="optimize", torque="cs", optimizer="bfgs", seed=0, budget=4).hash()
    assert dict(optimize_spec("cs", "bfgs", budget=4, torque_options={"knots": None}).torque_options)["knots"] == 11
