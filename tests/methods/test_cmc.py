"""Computed muscle control (``fdbench control --controller cmc``, ``fdbench.multibody.cmc``) on the
forearm's pin with a flexor and an extensor (rigid tendons, point paths) following a smooth swing:
its compiled parts against independent computations (static optimisation's capacities, scipy's
integration of the activation dynamics), the tracking and reserves of a run, its record and
trajectory, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.models import find_model
from fdbench.multibody import muscle
from fdbench.multibody.cmc import _bounded_controls, _start, computed_muscle_control, reserve_strengths
from fdbench.multibody.cmc_muscles import excitations_for, force_after, forces_after, muscle_gains
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.model_files import to_toml
from fdbench.multibody.motions.named import MinimumJerk
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.multibody.simulation import half_steps, muscle_forces
from fdbench.multibody.static_optimization import muscle_capacity

from helpers.models import forearm_with_muscles_data, hopper_loads, hopper_model

runner = CliRunner()


@pytest.fixture(scope="module")
def pin():
    return Engine(model_from_dict(forearm_with_muscles_data(), "pin.toml"))


@pytest.fixture(scope="module")
def pin_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("cmc") / "pin.toml"
    path.write_text(to_toml(model_from_dict(forearm_with_muscles_data(), "pin.toml")))
    return path


@pytest.fixture(scope="module")
def swing(pin):
    return MinimumJerk(pin.model.motions[0], pin.joints)


@pytest.fixture(scope="module")
def run(pin, swing):
    """CMC with reserves of 0.01 N m per unit control: a reserve costs as much as 0.01 N m of torque."""
    return computed_muscle_control(pin, swing, reserve_optimal_force=0.01, dt=1e-3)


def test_a_rigid_tendon_s_gains_are_static_optimisation_s_capacities(pin):
    rng = np.random.default_rng(3)
    for _ in range(5):
        lengths = 0.3 + rng.uniform(-0.02, 0.02, 2)
        speed = rng.uniform(-0.3, 0.3, 2)
        gain, passive = muscle_gains(np.array([0.4, 0.4]), lengths, speed, pin.muscle_params, pin.tendon_row)
        active, at_rest = muscle_capacity(pin.muscle_params, lengths[None], speed[None])
        np.testing.assert_allclose(gain, active[0], rtol=1e-13)
        np.testing.assert_allclose(passive, at_rest[0], rtol=1e-13, atol=1e-12)


def test_the_force_after_a_window_follows_the_activation_dynamics_as_scipy_integrates_them(pin):
    from scipy.integrate import solve_ivp

    p = pin.muscle_params[0]
    for excitation, start in ((0.8, 0.1), (0.05, 0.7)):
        rate = lambda t, a: [muscle.activation_derivative(excitation, a[0], p[muscle.TAU_ACT],  # noqa: E731
                                                          p[muscle.TAU_DEACT], p[muscle.SMOOTHING])]
        end = solve_ivp(rate, (0.0, 0.01), [start], rtol=1e-12, atol=1e-14).y[0, -1]
        expected = muscle.rigid_tendon_force(end, 0.3, 0.0, p)
        assert force_after(excitation, start, 0.0, 0.3, 0.0, 0.0, 1e-4, 100, p, False) == pytest.approx(expected,
                                                                                                     rel=1e-8)
        # the path moving at 0.05 m/s, accelerating at 2 m/s^2: after 0.01 s it is 0.3006 m long, at 0.07 m/s
        moving = muscle.rigid_tendon_force(end, 0.3 + 0.05 * 0.01 + 0.5 * 2.0 * 0.01**2, 0.05 + 2.0 * 0.01, p)
        assert force_after(excitation, start, 0.0, 0.3, 0.05, 2.0, 1e-4, 100, p, False) == pytest.approx(moving,
                                                                                                      rel=1e-8)


def test_the_excitations_reach_the_forces_asked_for_and_stop_at_their_bounds(pin):
    p, rows, states = pin.muscle_params, pin.tendon_row, np.array([0.3, 0.2])
    lengths, speed = np.array([0.3, 0.31]), np.array([0.1, -0.1])
    wanted = np.array([0.62, 0.17])
    speeding = np.array([1.0, -2.0])
    target = np.array([force_after(u, a, 0.0, l, v, s, 1e-3, 10, q, False)
                       for u, a, l, v, s, q in zip(wanted, states, lengths, speed, speeding, p)])
    found = excitations_for(target, np.array([0.5, 0.5]), states, lengths, speed, speeding, 1e-3, 10, p, rows)
    np.testing.assert_allclose(found, wanted, atol=1e-6)
    out_of_reach = excitations_for(np.array([1e4, -1.0]), np.array([0.5, 0.5]), states, lengths, speed, speeding,
                                   1e-3, 10, p, rows)
    assert out_of_reach.tolist() == [1.0, 0.0]
    for bound in (0.0, 1.0):  # the forces a window can reach: those under the excitations' bounds
        reach = forces_after(bound, states, lengths, speed, speeding, 1e-3, 10, p, rows)
        np.testing.assert_allclose(reach, [force_after(bound, a, 0.0, l, v, s, 1e-3, 10, q, False)
                                           for a, l, v, s, q in zip(states, lengths, speed, speeding, p)], rtol=1e-14)


def test_static_optimisation_within_the_reachable_controls_is_scipy_s_bounded_minimum():
    from scipy.optimize import minimize

    rng = np.random.default_rng(5)
    for _ in range(3):
        gain = rng.normal(0.0, 20.0, (2, 4))  # N m per unit control
        need, reserve_force = rng.normal(0.0, 10.0, 2), np.array([1.0, 2.0])
        low = rng.uniform(0.0, 0.4, 4)
        high = np.minimum(low + rng.uniform(0.0, 0.5, 4), 1.0)
        high[0] = low[0]  # a muscle whose window leaves it no range
        found = _bounded_controls(gain, need, reserve_force, low, high, np.full(4, 0.5))
        cost = lambda c: np.sum(c**2) + np.sum(((need - gain @ c) / reserve_force) ** 2)  # noqa: E731
        best = minimize(cost, (low + high) / 2, method="L-BFGS-B", bounds=list(zip(low, high)),
                        options={"ftol": 1e-15, "gtol": 1e-12}).x
        assert np.all((found >= low) & (found <= high)) and found[0] == low[0]
        assert cost(found) <= cost(best) + 1e-9
        np.testing.assert_allclose(found, best, atol=1e-5)


def test_cmc_tracks_a_swing_the_muscles_can_make_with_negligible_reserves(run, swing):
    result = run.simulation
    assert result.success and run.windows_done == 50
    error = np.degrees(result.z[:, 0] - swing(swing.samples)[0][:, 0])
    # the task's error dynamics e'' + 20 e' + 100 e = 0 (a double pole at 10 rad/s) driven by the
    # muscles' forces, which reach their targets only at each window's end: the product's goal for
    # CMC, within 0.5 deg RMS (measured 0.008 deg RMS, 0.013 deg at most, on 28.6 deg in 0.5 s)
    assert np.sqrt(np.mean(error**2)) < 0.5 and np.abs(error).max() < 1.0
    assert np.all((result.activation >= 0.0) & (result.activation <= 1.0))
    assert np.all((run.excitation >= 0.0) & (run.excitation <= 1.0))
    assert run.reserve_rms()[0] < 1e-3  # N m, beside gravity's 1.5 to 3 N m
    assert result.activation[:, 0].max() > 0.05  # the flexor holds the forearm up


def test_the_applied_torques_are_the_reserves_plus_the_muscles_forces_times_their_moment_arms(run, pin):
    result = run.simulation
    _, arms = muscle_geometry(pin.model, result.z, pin.muscle_paths)
    lengthening = -np.einsum("nmj,nj->nm", arms, result.zd)
    lengths, _ = muscle_geometry(pin.model, result.z, pin.muscle_paths)
    forces = np.array([[muscle.rigid_tendon_force(a, l, v, pin.muscle_params[m])
                        for m, (a, l, v) in enumerate(zip(*row))]
                       for row in zip(result.activation, lengths, lengthening)])
    np.testing.assert_allclose(forces, result.muscle_force, rtol=1e-12)
    # the reserves linear within each window; a sample on a window's boundary left out, as the torque there
    # is the last window's
    on_boundary = np.isclose(np.mod(result.t + 1e-9, run.window), 1e-9)
    rows = ~on_boundary
    rows[[0, -1]] = False
    expected = run.reserve_on_samples + np.einsum("nmj,nm->nj", arms, forces)
    np.testing.assert_allclose(result.torque[rows], expected[rows], rtol=1e-10, atol=1e-10)


def test_fdbench_control_cmc_records_the_reserves_effort_and_each_muscle(pin_file, tmp_path):
    trajectory = tmp_path / "run.csv"
    done = runner.invoke(app, ["control", "--model", str(pin_file), "--motion", "swing", "--controller", "cmc",
                               "--reserve-optimal-force", "0.01", "--kp", "100", "--kd", "20", "--window", "0.01",
                               "--save-trajectory", str(trajectory), "-f", "json", "--quiet"])
    assert done.exit_code == 0, done.output
    record = json.loads(done.stdout)
    assert record["controller"] == "cmc" and record["status"] == "success"
    assert record["rmse_rot_deg"] < 0.5 and record["reserve_rms_nm"] < 1e-3
    rows = np.loadtxt(trajectory, delimiter=",", skiprows=1)
    header = trajectory.read_text().splitlines()[0].split(",")
    assert header[-7:] == [f"{m}_{s}" for m in ("flexor", "extensor") for s in ("activation", "excitation", "force")] \
        + ["theta_reserve"]
    activations = rows[:, [header.index("flexor_activation"), header.index("extensor_activation")]]
    assert record["effort"] == pytest.approx(np.mean(np.sum(activations**2, axis=1)), rel=1e-6)
    assert record["flexor_activation_mean"] == pytest.approx(activations[:, 0].mean(), rel=1e-6)
    assert record["cmc_window_s"] == pytest.approx(0.01) and record["cmc_kp"] == 100.0


def test_pd_on_a_model_with_muscles_says_it_leaves_them_out(pin_file):
    done = runner.invoke(app, ["control", "--model", str(pin_file), "--motion", "swing", "-f", "json", "--quiet"])
    assert done.exit_code == 0, done.output
    assert "2 muscles left out" in json.loads(done.stdout)["message"]


def bad_input(args, *words):
    done = runner.invoke(app, [str(a) for a in args])
    assert done.exit_code == 2, (done.exit_code, done.output)
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:"), done.stderr
    for word in words:
        assert word in lines[0]


@pytest.mark.parametrize("extra, words", [(["--window", "0"], ["--window"]), (["--window", "2"], ["--window", "longer"]),
                                          (["--reserve-optimal-force", "-1"], ["--reserve-optimal-force"])])
def test_bad_cmc_settings_are_one_line_exit_2(pin_file, extra, words):
    bad_input(["control", "--model", pin_file, "--motion", "swing", "--controller", "cmc", *extra], *words)


def test_a_model_without_muscles_refuses_cmc():
    bad_input(["control", "--controller", "cmc"], "cmc", "no muscles")


def rigid_arm26(actuators) -> dict:
    """The library's arm26 with rigid tendons (RK4 at 1 ms) and the given ``[[actuators]]``."""
    data = to_dict(find_model("arm26"))
    for entry in data["muscles"]:
        entry["tendon"] = "rigid"
        entry.pop("tendon_strain", None)
    data["actuators"] = actuators
    return data


def test_the_model_s_actuators_are_cmc_s_reserves_and_a_coordinate_without_one_has_none(tmp_path):
    """With a shoulder actuator only, the elbow is driven by its muscles alone: its reserve is 0 in
    every window, the torque applied there is the muscles' moment arms times forces, and what they
    miss is reported unmet; --reserve-optimal-force overrides the actuator's optimal force only."""
    shoulder_only = model_from_dict(rigid_arm26([{"coordinate": "r_shoulder_elev", "optimal_force": 2.0}]),
                                    "arm.toml")
    assert list(reserve_strengths(shoulder_only)) == [2.0, 0.0]
    assert list(reserve_strengths(shoulder_only, 5.0)) == [5.0, 0.0]
    assert list(reserve_strengths(model_from_dict(rigid_arm26([]), "arm.toml"))) == [1.0, 1.0]
    plant = Engine(shoulder_only)
    motion = MinimumJerk(plant.model.motions[0], plant.joints)
    run = computed_muscle_control(plant, motion, dt=1e-3)
    assert run.simulation.success
    elbow = plant.joints.index("r_elbow_flex")
    assert np.all(run.reserve[:, elbow] == 0.0) and np.all(run.unmet[:, 1 - elbow] == 0.0)
    result = run.simulation
    lengths, arms = muscle_geometry(plant.model, result.z, plant.muscle_paths)
    on_boundary = np.isclose(np.mod(result.t + 1e-9, run.window), 1e-9)
    rows = ~on_boundary
    rows[[0, -1]] = False
    np.testing.assert_allclose(result.torque[rows, elbow],
                               np.einsum("nm,nm->n", arms[rows, :, elbow], result.muscle_force[rows]), rtol=1e-10,
                               atol=1e-10)
    path = tmp_path / "arm.toml"
    path.write_text(to_toml(shoulder_only))
    done = runner.invoke(app, ["control", "--model", str(path), "--controller", "cmc", "-f", "json", "--quiet"])
    assert done.exit_code == 0, done.output
    record = json.loads(done.stdout)
    assert record["reserve_rms_nm_r_elbow_flex"] == 0.0
    assert record["reserve_optimal_force"] == "per actuator (see reserves)"
    assert record["unmet_rms_nm_r_elbow_flex"] == pytest.approx(run.unmet_rms()[elbow], rel=1e-9)
    assert record["unmet_rms_nm_r_shoulder_elev"] == 0.0


def test_with_compliant_tendons_the_run_starts_with_the_muscles_giving_static_optimisation_s_torque():
    """arm26's compliant tendons settled at the start: the muscles' forces there (the engine's own,
    from the start's tendon states) times their moment arms, plus the reserves, are the inverse
    dynamics of the motion at t = 0, and the activations stay in [0.01, 1]."""
    plant = Engine(find_model("arm26"))
    assert (plant.tendon_row >= 0).all()
    motion = MinimumJerk(plant.model.motions[0], plant.joints)
    grid = half_steps(motion, 5e-5)
    rho = reserve_strengths(plant.model)
    floor = np.full(plant.n_muscles, muscle.MIN_ACTIVATION)
    y, control, reserve = _start(plant, plant, grid, rho, floor)
    S, M = plant.n_state, plant.n_muscles
    z, zd = plant.joints_from_state(y[:S])
    np.testing.assert_allclose(z, grid.ref[0], atol=1e-12)
    forces = muscle_forces(plant, z[None], zd[None], y[S:][None])[0]
    _, arms = muscle_geometry(plant.model, z, plant.muscle_paths)
    tau = plant.inverse_torques(grid.ref[0], grid.refd[0], grid.refdd[0], 0.0)
    np.testing.assert_allclose(arms.T @ forces + reserve, tau, atol=1e-6)
    np.testing.assert_allclose(y[S:S + M], floor + (1 - floor) * control, atol=1e-12)


def test_a_window_simulated_from_its_own_start_time_takes_the_loads_of_that_time():
    """CMC simulates window by window from each window's start t0 (``Engine.simulate``'s t0): under
    time-varying external loads, 40 steps from step 40's state at t0 = 40 dt are the last 40 steps of
    one 80-step run from 0; from t0 = 0 (the loads of the first window again) they are not."""
    engine = Engine(hopper_model(), loads=hopper_loads(3))
    dt, n = 1e-3, 40
    y0 = engine.state_from_joints(np.array([0.1, 0.0, 0.0, 0.2, 0.3]), np.zeros(5))

    def run(y, steps, t0):
        zeros = np.zeros((2 * steps + 1, engine.n_joints))
        return engine.simulate(y, dt, steps, zeros, zeros, zeros, zeros, 0.0, 0.0, t0=t0)
    whole = run(y0, 2 * n, 0.0)
    tail = run(whole.states[n], n, n * dt)
    restarted = run(whole.states[n], n, 0.0)
    assert whole.status == tail.status == 0
    np.testing.assert_allclose(tail.states, whole.states[n:], rtol=0, atol=1e-9)
    assert np.abs(restarted.states[-1] - whole.states[-1]).max() > 1e-6


def test_cmc_with_rigid_tendons_is_cmc_on_the_model_with_its_tendons_rigid(tmp_path):
    """``--tendons rigid`` on arm26 (compliant tendons) runs as CMC on arm26's file with every tendon
    rigid: the same record to the bit, stepped at --dt (1 ms), and it says which tendons it took
    as rigid; a bad value is one line, exit 2."""
    compliant, rigid = tmp_path / "arm.toml", tmp_path / "rigid.toml"
    compliant.write_text(to_toml(find_model("arm26")))
    rigid.write_text(to_toml(model_from_dict(rigid_arm26([]), "arm.toml")))
    common = ["control", "--controller", "cmc", "--motion", "mid_range", "-f", "json", "--quiet", "--db"]
    taken = runner.invoke(app, [*common, str(tmp_path / "a.sqlite"), "--model", str(compliant), "--tendons", "rigid"])
    made = runner.invoke(app, [*common, str(tmp_path / "b.sqlite"), "--model", str(rigid)])
    assert taken.exit_code == 0 and made.exit_code == 0, taken.output + made.output
    taken, made = json.loads(taken.stdout), json.loads(made.stdout)
    assert taken["status"] == "success" and taken["cmc_step_s"] == 1e-3
    assert taken["tendons"] == "rigid (compliant taken as rigid: " + ", ".join(
        m.name for m in find_model("arm26").muscles) + ")"
    assert made["tendons"] == "model"
    for name in ("rmse_rot_deg", "rmse_torque_nm", "reserve_rms_nm", "effort", "BIClong_activation_mean"):
        assert taken[name] == made[name]
    bad_input(["control", "--model", compliant, "--controller", "cmc", "--tendons", "elastic"], "--tendons", "rigid")
