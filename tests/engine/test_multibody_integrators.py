"""The adaptive integrators (scipy's solve_ivp methods) on the engine's two-segment arm: agreement
with the compiled RK4 at a small step, convergence as the tolerance tightens, the same stopping
event (constraint violation) as RK4, no singular configuration, every feedback law, and the command
line.

The bounds are measured (the figures in the comments, on the machine these tests were written
on) and given a margin; the reference is RK4 at dt = 0.1 ms, whose own error is below 1e-10 deg
(it moves by 2e-11 deg when the step is halved)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import fdbench
from fdbench.cli import app
from fdbench.integrate import SCIPY_METHODS, Status
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.lqr import lqr_gains
from fdbench.multibody.motions import joint_motion

ARM = Engine(find_model("arm2"))
REACH = joint_motion("reach", find_model("arm2"))
ADAPTIVE = tuple(SCIPY_METHODS)
KP, KD = 80.0, 0.3  # N m/rad, N m s/rad: the README's PD gains
runner = CliRunner()


def wobbly(t):
    """The reach's inverse-dynamics torques plus sinusoids (N m), shape (k,) -> (k, 2): under PD
    the arm leaves the reach by up to 7.3 deg, so agreement is not both integrators tracking it."""
    t = np.asarray(t, dtype=float)
    return FEEDFORWARD(t) + np.stack([2.0 * np.sin(6 * np.pi * t), np.cos(4 * np.pi * t)], axis=-1)


FEEDFORWARD = sim.feedforward(ARM, REACH)


def adaptive(integrator, rtol, torque=wobbly, **options):
    return sim.simulate(torque, ARM, REACH, KP, KD, integrator=integrator, rtol=rtol, atol=rtol * 1e-3, **options)


def max_angle_error_deg(result, reference) -> float:
    return float(np.degrees(np.abs(result.angles - reference.angles)).max())


@pytest.fixture(scope="module")
def fine_rk4():
    """The PD run of ``wobbly`` by RK4 at dt = 0.1 ms."""
    result = sim.simulate(wobbly, ARM, REACH, KP, KD, dt=1e-4)
    assert result.success
    desired = sim.inverse_dynamics(None, ARM, REACH).angles
    assert np.degrees(np.abs(result.angles - desired)).max() > 5.0  # far from the reach: a real test
    return result


@pytest.mark.parametrize("integrator", ["rk45", "dop853", "lsoda"])
def test_tight_tolerance_agrees_with_rk4_at_a_small_step(integrator, fine_rk4):
    # measured at rtol 1e-9: rk45 6.4e-9, dop853 1.0e-7, lsoda 6.9e-8 deg; torques 8.8e-9 to 1.6e-7 N m
    result = adaptive(integrator, 1e-9)
    assert result.success and result.integrator == integrator and result.t_end == pytest.approx(1.0)
    assert result.rhs_evaluations > 0 and np.all(result.reached)
    assert max_angle_error_deg(result, fine_rk4) < 1e-6
    assert np.abs(result.torque - fine_rk4.torque).max() < 1e-6
    assert result.max_violation < 1e-6


@pytest.mark.parametrize("integrator", ADAPTIVE)
def test_every_adaptive_integrator_agrees_with_rk4(integrator, fine_rk4):
    # measured at rtol 1e-7: rk45 5.2e-7, dop853 2.4e-6, lsoda 7.7e-7, radau 8.6e-8, bdf 3.7e-6 deg
    result = adaptive(integrator, 1e-7)
    assert result.success
    assert max_angle_error_deg(result, fine_rk4) < 2e-5


@pytest.mark.parametrize("integrator", ADAPTIVE)
def test_the_error_decreases_as_the_tolerance_tightens(integrator, fine_rk4):
    """rtol 1e-3, 1e-5, 1e-7 (atol 1000 times smaller): every hundredfold tightening cuts the error
    against RK4 at least tenfold (measured: 24 to 150 fold; rk45 1.3e-2, 6.5e-5, 5.2e-7 deg)."""
    errors = [max_angle_error_deg(adaptive(integrator, rtol), fine_rk4) for rtol in (1e-3, 1e-5, 1e-7)]
    assert errors[0] > 0
    assert errors[1] < errors[0] / 10 and errors[2] < errors[1] / 10, errors


@pytest.mark.parametrize("integrator", ["rk45", "dop853"])
def test_the_arm_falls_through_the_papers_singular_configuration(integrator):
    """Zero torque from the reach's start: gravity and the load drop the arm, and the forearm's
    absolute angle passes -90 deg (where the paper's angle constraint alone is singular) at about
    0.18 s without stopping; RK4 and the adaptive integrators agree while it falls."""
    rk4 = sim.simulate(None, ARM, REACH, dt=1e-4)
    result = sim.simulate(None, ARM, REACH, integrator=integrator, rtol=1e-9, atol=1e-12)
    early = result.t <= 0.3
    forearm = np.degrees(rk4.angles[early].sum(axis=1))
    assert forearm.min() < -100.0 and np.all(rk4.reached[early]) and np.all(result.reached[early])
    assert np.degrees(np.abs(result.angles[early] - rk4.angles[early])).max() < 1e-4


@pytest.mark.parametrize("integrator", ["rk45", "radau"])
def test_a_constraint_violation_stops_as_rk4_does(integrator):
    """A soft penalty (alpha = 100) lets the constraints drift beyond their tolerance under PD
    control: both integrators stop with CONSTRAINT at about 0.108 s, within one RK4 step."""
    soft, dt = Engine(find_model("arm2"), alpha=100.0), 1e-3
    rk4 = sim.simulate(FEEDFORWARD, soft, REACH, KP, KD, dt=dt)
    result = sim.simulate(FEEDFORWARD, soft, REACH, KP, KD, integrator=integrator, rtol=1e-8, atol=1e-11)
    assert rk4.status is Status.CONSTRAINT and result.status is Status.CONSTRAINT
    assert abs(result.t_end - rk4.t_end) <= dt
    assert 0 < result.max_violation <= 1e-3  # measured on the samples reached, all before the stop


@pytest.mark.parametrize("law", ["computed-torque", "lqr"])
def test_computed_torque_and_lqr_agree_with_rk4(law):
    """From 2 deg and -3 deg off the reach's start, the feedback laws evaluated along the adaptive
    integration agree with the compiled ones of RK4 (measured at rtol 1e-8, dop853: 1e-8 deg,
    4e-8 deg for LQR)."""
    z, w, _ = REACH(np.zeros(1))
    options = dict(start=ARM.state_from_joints(z[0] + np.radians([2.0, -3.0]), w[0]))
    if law == "lqr":
        options.update(torque=FEEDFORWARD, gains=lqr_gains(find_model("arm2"), REACH))
    else:
        options.update(torque=None, kp=400.0, kd=40.0, computed=True)
    rk4 = sim.simulate(engine=ARM, motion=REACH, dt=1e-4, **options)
    result = sim.simulate(engine=ARM, motion=REACH, integrator="dop853", rtol=1e-8, atol=1e-11, **options)
    assert rk4.success and result.success
    assert max_angle_error_deg(result, rk4) < 1e-6
    assert np.abs(result.torque - rk4.torque).max() < 1e-4


def test_rk4_stays_the_default():
    assert sim.simulate(FEEDFORWARD, ARM, REACH, KP, KD).integrator == "rk4"


def test_bad_integrator_or_tolerance_raises():
    with pytest.raises(ValueError, match="integrator"):
        sim.simulate(None, ARM, REACH, integrator="euler")
    with pytest.raises(ValueError, match="rtol"):
        sim.simulate(None, ARM, REACH, integrator="rk45", rtol=0.0)
    with pytest.raises(ValueError, match="atol"):
        sim.simulate(None, ARM, REACH, integrator="rk45", atol=float("nan"))


def test_the_spec_tolerances_reach_the_simulation():
    """A control run with --integrator lsoda --rtol 1e-8 is the direct simulation with those settings."""
    record = fdbench.run(fdbench.control_spec(KP, KD, model_name="arm2", integrator="lsoda", rtol=1e-8, atol=1e-11)).record
    direct = sim.simulate(FEEDFORWARD, ARM, REACH, KP, KD, integrator="lsoda", rtol=1e-8, atol=1e-11)
    expected, _ = sim.rmse_deg(direct, sim.inverse_dynamics(None, ARM, REACH).angles)
    assert record["integrator"] == "lsoda" and record["status"] == "success"
    assert record["rmse_rot_deg"] == pytest.approx(expected, rel=1e-12)


# ----------------------------------------------------------------------------- the command line


def as_json(*args):
    result = runner.invoke(app, [str(a) for a in args] + ["-f", "json"])
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)


def test_control_with_dop853_on_the_command_line():
    record = as_json("control", "--model", "arm2", "--integrator", "dop853")
    rk4 = as_json("control", "--model", "arm2")
    assert record["integrator"] == "dop853" and record["status"] == "success" and record["t_end"] == pytest.approx(1.0)
    assert record["rmse_rot_deg"] < 1e-5 and rk4["rmse_rot_deg"] < 1e-5  # both track the reach
    assert record["spec_hash"] != rk4["spec_hash"]


def test_optimize_simulate_and_collocate_with_an_adaptive_integrator():
    optimized = as_json("optimize", "--model", "arm2", "--torque", "pf", "--terms", "2", "--feedforward", "--opt", "bfgs",
                        "--budget", "6", "--integrator", "rk45")
    assert optimized["integrator"] == "rk45" and optimized["evaluations"] == 6 and optimized["status"] == "success"
    assert optimized["best_objective"] <= optimized["initial_objective"]
    assert optimized["best_objective"] == pytest.approx(optimized["rmse_rot_deg"], rel=1e-12)
    simulated = as_json("simulate", "--model", "arm2", "--integrator", "bdf")
    assert simulated["integrator"] == "bdf" and simulated["status"] == "success"
    # the arm's open loop amplifies any difference a millionfold over 1 s: tight tolerances
    replay = as_json("collocate", "--model", "arm2", "--integrator", "dop853", "--rtol", "1e-10", "--atol", "1e-13")
    rk4 = as_json("collocate", "--model", "arm2")
    assert replay["integrator"] == "dop853" and replay["status"] == "success"
    assert replay["rmse_rot_deg"] == pytest.approx(rk4["rmse_rot_deg"], rel=0.05)  # the same replay, 2 integrators


@pytest.mark.parametrize("command, args, word", [
    ("control", ["--integrator", "dop853", "--rtol", "0"], "--rtol"),
    ("control", ["--integrator", "dop853", "--rtol", "nan"], "--rtol"),
    ("control", ["--integrator", "rk45", "--rtol", "1"], "--rtol"),
    ("simulate", ["--integrator", "radau", "--atol", "2"], "--atol"),
    ("control", ["--integrator", "euler"], "--integrator"),
    ("optimize", ["--integrator", "dop853", "--opt", "bfgs", "--torque", "cs", "--gradient", "exact"], "--gradient"),
])
def test_bad_input_exits_2_with_one_line(command, args, word):
    result = runner.invoke(app, [command, "--model", "arm2", *args])
    lines = result.stderr.splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("fdbench: error:") and word in lines[0], lines


def test_an_adaptive_optimisation_objective_is_the_adaptive_simulations():
    """With an adaptive integrator the arm's objective comes from that integrator's simulation,
    not from the RK4 population kernel."""
    from fdbench.problem import TrackingProblem

    problem = TrackingProblem("cs", ARM, REACH, True, integrator="rk45", rtol=1e-6, atol=1e-9)
    rk4 = TrackingProblem("cs", ARM, REACH, True)
    assert not problem.batched and rk4.batched
    p = problem.p0 + 0.05 * problem.scale
    adaptive = sim.simulate(problem.torque_function(p), ARM, REACH, integrator="rk45", rtol=1e-6, atol=1e-9)
    assert problem.objective(p) == problem.objective_of(adaptive)
    assert problem.objective(p) != rk4.objective(p)
