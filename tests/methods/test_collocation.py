"""Direct collocation of the paper's forearm: defects at the solution (recomputed here), the forward replay reproducing
the collocation's states (second order for the trapezoidal scheme), the inverse-dynamics torque
recovered, IPOPT failures as statuses, --save-torque, and bad options."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from helpers import forearm_closed_form as cf
from helpers.paths import ROOT
from fdbench.cli import app
from fdbench.collocation import collocate
from fdbench.multibody.motions import desired_motion
from fdbench.multibody import simulation as sim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion

runner = CliRunner()
MODEL = find_model("forearm")
ENGINE = Engine(MODEL)
G = cf.load_moment()  # N m, Table 1


def solve(kinematics="paper", nodes=100, scheme="hermite-simpson"):
    return collocate(MODEL, joint_motion(kinematics, MODEL), nodes, scheme)


def column(values) -> np.ndarray:
    """A node array of the one joint, shape (k,)."""
    return np.asarray(values).reshape(len(values))


def f(theta, omega, tau):
    """[theta', theta''] of I1 theta'' = tau - G cos(theta), written out from Table 1."""
    return omega, (tau - G * np.cos(theta)) / cf.I1


def defects(sol) -> np.ndarray:
    h = sol.t[1] - sol.t[0]
    th, w, u = column(sol.angles), column(sol.velocities), column(sol.torque)
    d0, a0 = f(th[:-1], w[:-1], u[:-1])
    d1, a1 = f(th[1:], w[1:], u[1:])
    if sol.torque_mid is None:
        return np.concatenate([th[1:] - th[:-1] - h / 2 * (d0 + d1), w[1:] - w[:-1] - h / 2 * (a0 + a1)])
    th_m = (th[:-1] + th[1:]) / 2 + h / 8 * (d0 - d1)
    w_m = (w[:-1] + w[1:]) / 2 + h / 8 * (a0 - a1)
    dm, am = f(th_m, w_m, column(sol.torque_mid))
    return np.concatenate([th[1:] - th[:-1] - h / 6 * (d0 + 4 * dm + d1),
                           w[1:] - w[:-1] - h / 6 * (a0 + 4 * am + a1)])


def replay_gap(sol, kinematics="paper") -> float:
    """max |theta_replay - theta_collocation| over the nodes (rad); nodes on the 1 ms samples.
    The replay is the engine's open-loop RK4 at alpha 1e9: its penalty error, O(1/alpha), stays
    below the 1e-6 rad asked of Hermite-Simpson (measured gap 4e-8 rad) and far below the
    trapezoidal gaps (3e-4 to 5e-3 rad)."""
    torque = sol.torque_function()
    replay = sim.simulate(lambda t: np.reshape(torque(t), (len(t), 1)), Engine(MODEL, 1e9),
                          joint_motion(kinematics, MODEL))
    assert replay.success
    index = np.round(sol.t * 1000).astype(int)
    assert np.allclose(index / 1000, sol.t)
    return float(np.max(np.abs(replay.z[index, 0] - column(sol.angles))))


@pytest.mark.parametrize("scheme", ["hermite-simpson", "trapezoidal"])
@pytest.mark.parametrize("nodes", [10, 100])
def test_defects_vanish_and_the_initial_state_is_the_motions(scheme, nodes):
    sol = solve("paper", nodes, scheme)
    assert sol.success, sol.message
    assert np.max(np.abs(defects(sol))) < 1e-8
    theta0, w0, _ = desired_motion(0.0, "paper")
    assert column(sol.angles)[0] == pytest.approx(theta0, abs=1e-12)
    assert column(sol.velocities)[0] == pytest.approx(w0, abs=1e-12)


def test_hermite_simpson_torque_replayed_reproduces_its_states():
    assert replay_gap(solve("paper", 100, "hermite-simpson")) < 1e-6  # rad, over a motion of pi/4 rad


def test_trapezoidal_replay_converges_at_second_order():
    gaps = [replay_gap(solve("paper", n, "trapezoidal")) for n in (25, 50, 100)]
    orders = np.log2(np.array(gaps[:-1]) / np.array(gaps[1:]))
    assert np.all((orders > 1.8) & (orders < 2.2)), (gaps, orders)


def test_on_exact_kinematics_the_torque_is_the_closed_form_elbow_torque():
    """The torque that tracks a consistent motion exactly is eq. 3's, I1 theta'' + G cos(theta);
    away from the free final state the collocation finds it."""
    sol = solve("exact", 100, "hermite-simpson")
    inside = sol.t < 0.9
    theta, _, dw = desired_motion(sol.t, "exact")
    expected = cf.elbow_torque(theta, dw)
    assert np.max(np.abs(column(sol.torque)[inside] - expected[inside])) < 1e-3  # N m, against a range of ~8 N m


def test_the_quadratic_torque_passes_through_the_node_and_midpoint_values():
    sol = solve("paper", 20, "hermite-simpson")
    h = sol.t[1] - sol.t[0]
    torque = sol.torque_function()
    np.testing.assert_allclose(column(torque(sol.t)), column(sol.torque), atol=1e-12)
    np.testing.assert_allclose(column(torque(sol.t[:-1] + h / 2)), column(sol.torque_mid), atol=1e-12)


def invoke(args):
    result = runner.invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.stderr
    return result


def test_collocate_command_reports_the_replay_and_ipopt(tmp_path):
    path = tmp_path / "torque.csv"
    result = invoke(["collocate", "-f", "json", "--save-torque", path, "--quiet"])
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["status"] == "success" and record["ipopt_status"] == "Solve_Succeeded"
    assert record["rmse_rot_deg"] < 1e-3 and record["collocation_rmse_rot_deg"] < 1e-3
    assert record["ipopt_iterations"] >= 1 and record["solve_time_s"] > 0
    # the saved torque, replayed by 'simulate --torque-file', gives the same forward simulation
    replay = json.loads(invoke(["simulate", "--torque-file", path, "-f", "json"]).stdout)
    assert replay["rmse_rot_deg"] == pytest.approx(record["rmse_rot_deg"], rel=1e-9)
    assert replay["rmse_torque_nm"] == pytest.approx(record["rmse_torque_nm"], rel=1e-9)


def test_an_iteration_limit_is_a_status_with_a_message():
    """The arm's Hermite-Simpson problem on 100 intervals needs two IPOPT iterations (its torques are
    nonlinear in the unknowns): one is not enough."""
    result = invoke(["collocate", "--model", "arm2", "--max-iter", 1, "-f", "json"])
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["ipopt_status"] == "Maximum_Iterations_Exceeded" and record["ipopt_iterations"] == 1
    assert record["status"] == "collocation_failed" and "--max-iter" in record["message"]
    assert math.isfinite(record["rmse_rot_deg"])  # the last iterate is still replayed


@pytest.mark.parametrize("args, word", [
    (["--nodes", 1], "--nodes"),
    (["--nodes", 0], "--nodes"),
    (["--nodes", -3], "--nodes"),
    (["--scheme", "euler"], "--scheme"),
    (["--regularization", -1e-3], "--regularization"),
    (["--regularization", "nan"], "--regularization"),
    (["--max-iter", 0], "--max-iter"),
    (["--max-iter", 2**31], "--max-iter"),  # beyond IPOPT's C int: it printed its option help and exited 1
    (["--max-iter", 10**20], "--max-iter"),  # wrapped to 0 iterations and exited 0
    (["--max-iter", 10**6 + 1], "[1, 1000000]"),
    (["--max-time", 0], "--max-time"),
    (["--kinematics", "approx"], "--kinematics"),
    (["--residual-force-weight", -1], "--residual-force-weight"),
    (["--residual-moment-weight", "inf"], "--residual-moment-weight"),
])
def test_bad_collocate_options_are_one_line_exit_2(args, word, tmp_path):
    out = tmp_path / "torque.csv"
    result = invoke(["collocate", *args, "--save-torque", out])
    assert result.exit_code == 2, (result.exit_code, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and word in lines[0], result.stderr
    assert result.stdout == "" and not out.exists()


def test_save_torque_into_a_missing_directory_is_refused_before_work(tmp_path):
    result = invoke(["collocate", "--save-torque", tmp_path / "missing" / "torque.csv"])
    assert result.exit_code == 2 and "--save-torque" in result.stderr
    assert len(result.stderr.splitlines()) == 1


@settings(max_examples=30)
@given(nodes=st.integers(-5, 40),
       regularization=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, 1e-6, 1e-2])),
       scheme=st.sampled_from(["hermite-simpson", "trapezoidal", "euler", ""]),
       max_iter=st.integers(-2, 50))
def test_fuzz_collocate_is_a_result_or_one_line(nodes, regularization, scheme, max_iter):
    """Whatever the options: a result (exit 0, a JSON record) or bad input (exit 2, one line)."""
    result = invoke(["collocate", "--nodes", nodes, "--regularization", regularization, "--scheme", scheme,
                     "--max-iter", max_iter, "-f", "json"])
    assert result.exit_code in (0, 2), (result.exit_code, result.stderr)
    if result.exit_code == 2:
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("fdbench: error:") and result.stdout == ""
    else:
        record = json.loads(result.stdout)
        assert record["command"] == "collocate" and record["ipopt_status"]
        valid = 2 <= nodes and scheme in ("hermite-simpson", "trapezoidal") and max_iter >= 1
        assert valid and math.isfinite(regularization) and regularization >= 0


def test_save_torque_covers_a_recorded_motions_span(tmp_path):
    """A recorded 2.5 s motion: the torque is saved on the RK4 half-step grid of the motion's
    span, and 'simulate --torque-file' on the same motion replays what collocate replayed."""
    motion, path = ROOT / "examples" / "elbow_flexion.csv", tmp_path / "torque.csv"
    record = json.loads(invoke(["collocate", "--motion", motion, "--nodes", 50, "--save-torque", path, "-f", "json",
                                "--quiet"]).stdout)
    t, span = np.loadtxt(path, delimiter=",", skiprows=1)[:, 0], np.loadtxt(motion, delimiter=",", skiprows=1)[-1, 0]
    assert t[0] == 0 and t[-1] == pytest.approx(span) and len(t) == 2 * round(span / 1e-3) + 1 and span > 1
    replay = json.loads(invoke(["simulate", "--motion", motion, "--torque-file", path, "-f", "json"]).stdout)
    assert replay["rmse_rot_deg"] == pytest.approx(record["rmse_rot_deg"], rel=1e-9)


# ----------------------------------------------------------------------------- a floating base, loads, residuals
HOPPER = """
name = "hopper"
gravity = [0.0, -9.80665]

[[bodies]]
name = "pelvis"
mass = 11.0
com = [-0.07, 0.0]
inertia = 0.06

[[bodies]]
name = "thigh"
mass = 9.0
com = [0.0, -0.19]
inertia = 0.18
end = [0.0, -0.19]

[[bodies]]
name = "shank"
mass = 3.6
com = [0.0, -0.18]
inertia = 0.05

[[bodies]]
name = "torso"
mass = 33.0
com = [-0.03, 0.35]
inertia = 1.6

[[joints]]
name = "base"
type = "free"
parent = "ground"
child = "pelvis"
at_parent = [0.0, 0.0]
at_child = [0.0, 0.0]
coordinates = ["pelvis_tilt", "pelvis_tx", "pelvis_ty"]

[[joints]]
name = "hip"
parent = "pelvis"
child = "thigh"
at_parent = [-0.07, -0.07]
at_child = [0.0, 0.0]

[[joints]]
name = "knee"
parent = "thigh"
child = "shank"
at_parent = [0.0, 0.0]
at_child = [0.0, 0.0]
path = { angles = [-2.0, -1.0, 0.0, 0.5], x = [-0.004, 0.005, -0.004, -0.006], y = [-0.47, -0.455, -0.452, -0.454] }

[[joints]]
name = "lumbar"
parent = "pelvis"
child = "torso"
at_parent = [-0.10, 0.08]
at_child = [0.0, 0.0]
"""


class Sway:
    """Each of the hopper's six coordinates z0 + amplitude sin(2 pi f t + phase) for ``duration`` s
    (rad; m for pelvis_tx, pelvis_ty), with its exact derivatives."""

    z0 = np.array([0.05, 0.0, 0.95, 0.3, -0.6, 0.1])
    amplitude = np.array([0.05, 0.2, 0.02, 0.4, 0.5, 0.1])
    frequency = np.array([1.0, 0.5, 2.0, 1.0, 1.0, 1.5])  # Hz
    phase = np.array([0.0, 0.0, 1.0, 0.5, 2.0, 0.3])

    def __init__(self, duration=0.5):
        self.duration = duration

    def __call__(self, t):
        w = 2 * math.pi * self.frequency
        arg = w * np.asarray(t, dtype=float)[..., None] + self.phase
        return (self.z0 + self.amplitude * np.sin(arg), self.amplitude * w * np.cos(arg),
                -self.amplitude * w**2 * np.sin(arg))


@pytest.fixture(scope="module")
def hopper(tmp_path_factory):
    from fdbench.models import description

    path = tmp_path_factory.mktemp("hopper") / "hopper.toml"
    path.write_text(HOPPER)
    return description(str(path))


def hopper_loads(model, duration=0.5, support=0.9):
    """Two loads on the hopper over [0, duration] s: a ground reaction under the shank (ground's
    axes, at a point moving forward on the ground) that carries ``support`` of the body's weight, and a
    push on the torso given in the torso's own frame with a free moment."""
    from fdbench.multibody.loads import ExternalLoad, ExternalLoads

    t = np.linspace(0.0, duration, 51)
    weight = support * model.total_mass * 9.80665
    force = np.stack([np.stack([20 * np.sin(3 * t), weight + 30 * np.cos(5 * t)], axis=1),
                      np.stack([5 + 0 * t, -8 * t], axis=1)], axis=1)
    point = np.stack([np.stack([0.1 * t - 0.05, 0 * t], axis=1),
                      np.stack([0.02 + 0 * t, 0.3 + 0 * t], axis=1)], axis=1)
    moment = np.stack([2 * np.sin(4 * t), 1 + 0 * t], axis=1)
    loads = (ExternalLoad("grf", "shank"), ExternalLoad("push", "torso", force_frame="torso", point_frame="torso"))
    return ExternalLoads(loads, t, force, point, moment, source="test")


def test_a_floating_base_models_collocation_obeys_the_independent_reference(hopper):
    """A six-coordinate model with a free base and a knee on a path (the walk's kinds of joint) is
    transcribed and solved in seconds; its torques at the nodes are the independent minimal-coordinate
    reference's inverse dynamics of its states; its states are the exact integrals of a piecewise
    linear acceleration (what Hermite-Simpson with the midpoint acceleration the nodes' mean
    imposes); it tracks the motion (angles in deg and translations in cm apart) to the price of
    the regularization (1e-6 on the base's forces too without loads)."""
    from helpers import reference_dynamics as ref

    from fdbench.collocation import own_fields

    motion = Sway()
    sol = collocate(hopper, motion, nodes=20)
    assert sol.success, sol.message
    assert sol.angles.shape == sol.accelerations.shape == sol.torque.shape == (21, 6)
    tree = ref.GeneralTree(hopper)
    expected = tree.inverse_dynamics(sol.angles, sol.velocities, sol.accelerations)
    scale = np.sqrt(np.mean(expected**2))
    assert np.max(np.abs(sol.torque - expected)) < 1e-9 * scale
    h, z, w, a = sol.t[1] - sol.t[0], sol.angles, sol.velocities, sol.accelerations
    np.testing.assert_allclose(w[1:] - w[:-1], h / 2 * (a[:-1] + a[1:]), atol=1e-9)
    np.testing.assert_allclose(z[1:] - z[:-1], h * w[:-1] + h**2 / 6 * (2 * a[:-1] + a[1:]), atol=1e-10)
    fields = own_fields(hopper, sol, motion)
    assert fields["collocation_rmse_rot_deg"] < 0.02 and fields["collocation_rmse_trans_cm"] < 0.2
    assert sol.residual_weights == (1e-6, 1e-6)  # without loads: the regularization


def test_loads_enter_as_the_engines_inverse_dynamics_with_loads(hopper):
    """The collocation's actuation under loads (a force and point in ground's axes, another in the
    torso's frame, free moments) against the engine's inverse dynamics with the same loads (mixed
    coordinates, numpy): at random states and times, and on the collocation's own nodes."""
    from fdbench.multibody.symbolic import MinimalDynamics, load_parameters

    loads = hopper_loads(hopper)
    engine = Engine(hopper, loads=loads)
    rng = np.random.default_rng(5)
    z = Sway()(rng.uniform(0, 0.5, 8))[0] + rng.uniform(-0.2, 0.2, (8, 6))
    zd, zdd, t = rng.uniform(-3, 3, (8, 6)), rng.uniform(-30, 30, (8, 6)), rng.uniform(0, 0.5, 8)
    actuation = MinimalDynamics(hopper).actuation(loads.loads).map(8)
    tau = np.array(actuation(z.T, zd.T, zdd.T, load_parameters(loads, t).T)).T
    expected = engine.inverse_dynamics(z, zd, zdd, t)
    assert np.max(np.abs(tau - expected)) < 1e-9 * np.sqrt(np.mean(expected**2))
    free = engine.inverse_dynamics(z, zd, zdd, t) - Engine(hopper).inverse_dynamics(z, zd, zdd)
    assert np.max(np.abs(free)) > 10  # N, N m: the loads matter here

    sol = collocate(hopper, Sway(), nodes=20, loads=loads)
    assert sol.success, sol.message
    on_nodes = engine.inverse_dynamics(sol.angles, sol.velocities, sol.accelerations, sol.t)
    assert np.max(np.abs(sol.torque - on_nodes)) < 1e-9 * np.sqrt(np.mean(on_nodes**2))


def residual_integrals(model, sol) -> tuple[float, float]:
    """The integrals of FX^2 + FY^2 (N^2 s) and MZ^2 (N^2 m^2 s) by Simpson's rule over the nodes
    and midpoints (the objective's own quadrature)."""
    base = model.coordinates.index(model.floating_base.coordinate_names[0])
    h = sol.t[1] - sol.t[0]

    def integral(columns):
        node = np.sum(sol.torque[:, columns] ** 2, axis=1)
        mid = np.sum(sol.torque_mid[:, columns] ** 2, axis=1)
        return float(h / 6 * (node[:-1].sum() + 4 * mid.sum() + node[1:].sum()))

    return integral([base + 1, base + 2]), integral([base])


def test_a_larger_residual_weight_never_raises_the_residuals(hopper):
    """The loads carry 90% of the hopper's weight: the residuals cannot vanish without tracking error.
    Raising the residual weights lowers the residuals' integrals and raises the tracking error (the
    optimum of a weighted sum moves monotonically along the trade-off)."""
    from fdbench.collocation import own_fields

    loads, motion = hopper_loads(hopper), Sway()
    found = []
    for weight in (1e-6, 1e-3, 1e-1):
        sol = collocate(hopper, motion, nodes=20, loads=loads, residual_force_weight=weight,
                        residual_moment_weight=weight)
        assert sol.success and sol.residual_weights == (weight, weight), sol.message
        error = own_fields(hopper, sol, motion)
        found.append((*residual_integrals(hopper, sol), error["collocation_rmse_rot_deg"]
                      + error["collocation_rmse_trans_cm"]))
    forces, moments, errors = np.array(found).T
    assert np.all(np.diff(forces) < 0) and np.all(np.diff(moments) <= 1e-9 * moments[0])
    assert np.all(np.diff(errors) > 0)
    assert forces[-1] < 0.5 * forces[0]  # the weight matters


def test_collocate_records_a_floating_bases_units_apart_and_its_residual_weights(hopper, tmp_path):
    """A model file with a free base and a motion file on the command line: the collocation's own
    RMSE of angles (deg) and translations (cm) apart, its residuals' RMS, and the residual weights
    used (the regularization without loads; the option when given)."""
    model, motion = tmp_path / "hopper.toml", tmp_path / "sway.csv"
    model.write_text(HOPPER)
    t = np.linspace(0.0, 0.5, 51)
    z = Sway()(t)[0]
    columns = np.column_stack([t, np.degrees(z[:, 0]), z[:, 1], z[:, 2], np.degrees(z[:, 3:])])
    np.savetxt(motion, columns, delimiter=",", header="t," + ",".join(hopper.coordinates), comments="")
    base = ["collocate", "--model", model, "--motion", motion, "--nodes", 20, "-f", "json", "--quiet"]
    record = json.loads(invoke(base).stdout)
    assert record["ipopt_status"] == "Solve_Succeeded"
    assert record["collocation_rmse_rot_deg"] < 0.1 and record["collocation_rmse_trans_cm"] < 0.5
    assert record["residual_force_weight"] == record["residual_moment_weight"] == record["regularization"] == 1e-6
    assert record["collocation_residual_force_rms_n"] > 0.9 * hopper.total_mass * 9.80665  # the base carries the body
    weighted = json.loads(invoke(base + ["--residual-force-weight", 0.01]).stdout)
    assert weighted["residual_force_weight"] == 0.01 and weighted["residual_moment_weight"] == 1e-6
    assert weighted["spec_hash"] != record["spec_hash"]


class Shifted:
    """A motion ``base`` with every angle raised by ``offset`` (rad)."""

    def __init__(self, base, offset: float):
        self.base, self.offset, self.duration = base, offset, base.duration

    def __call__(self, t):
        z, zd, zdd = self.base(t)
        return np.asarray(z) + self.offset, zd, zdd


def test_a_repeated_collocation_reuses_its_transcription_and_solves_each_motion_as_a_fresh_one():
    """The built solver is kept per structure (model, mesh, scheme, options): another motion of
    the same structure (the exact motion raised by 0.1 rad) reuses it (no new solver is built),
    gets exactly the solution a freshly built transcription gives it, and follows its own
    angles, 0.1 rad above the first motion's solution; another mesh builds another."""
    from fdbench import collocation

    collocation._SOLVERS.clear()
    first = collocate(MODEL, joint_motion("exact", MODEL), 20)
    assert len(collocation._SOLVERS) == 1
    kept = next(iter(collocation._SOLVERS.values()))[1]
    raised = Shifted(joint_motion("exact", MODEL), 0.1)
    reused = collocate(MODEL, raised, 20)
    assert len(collocation._SOLVERS) == 1 and next(iter(collocation._SOLVERS.values()))[1] is kept
    collocation._SOLVERS.clear()
    fresh = collocate(MODEL, raised, 20)
    assert fresh.ipopt_status == reused.ipopt_status == "Solve_Succeeded"
    np.testing.assert_array_equal(reused.angles, fresh.angles)
    np.testing.assert_array_equal(reused.torque, fresh.torque)
    np.testing.assert_allclose(reused.angles, first.angles + 0.1, atol=1e-4)  # rad: each tracks its own motion
    collocate(MODEL, raised, 21)
    assert len(collocation._SOLVERS) == 2


def test_casadi_works_with_opensim_s_library_folder_first_on_ld_library_path(tmp_path):
    """Importing opensim (or OpenSim's Linux install instructions) puts its library folder, which
    holds an older libcasadi, on LD_LIBRARY_PATH. A plain 'import casadi' then fails (checked
    here, so that the test shows the environment is the hostile one); LQR control and collocation
    still run and give the same indicators as without it."""
    import importlib.util
    import os
    import subprocess
    import sys

    found = importlib.util.find_spec("opensim")
    if found is None:
        pytest.skip("the opensim package is not installed")
    env = dict(os.environ, LD_LIBRARY_PATH=list(found.submodule_search_locations)[0])
    plain = subprocess.run([sys.executable, "-c", "import casadi"], capture_output=True, text=True, env=env,
                           timeout=120)
    if plain.returncode == 0:
        pytest.skip("this opensim package's libraries do not clash with casadi's")
    assert "undefined symbol" in plain.stderr
    for args in (["control", "--controller", "lqr", "--model", "arm2"],
                 ["collocate", "--model", "arm2", "--nodes", "10"]):
        done = subprocess.run([sys.executable, "-m", "fdbench.cli", *args, "-f", "json", "-q"], capture_output=True,
                              text=True, env=env, cwd=tmp_path, timeout=600)
        assert done.returncode == 0, done.stderr
        clean = invoke([*args, "-f", "json", "-q"])
        assert clean.exit_code == 0, clean.stderr
        theirs, ours = json.loads(done.stdout), json.loads(clean.stdout)
        assert theirs["status"] == "success" and theirs["rmse_rot_deg"] == pytest.approx(ours["rmse_rot_deg"],
                                                                                          rel=1e-9), (theirs, ours)


def test_where_casadi_s_own_library_cannot_be_loaded_first_the_clash_is_one_line_naming_ld_library_path(tmp_path):
    """Should loading casadi's own libcasadi first not help (here: not done), collocate and LQR
    control stop before any work with one line naming LD_LIBRARY_PATH and the folder at fault."""
    import importlib.util
    import os
    import subprocess
    import sys

    found = importlib.util.find_spec("opensim")
    if found is None:
        pytest.skip("the opensim package is not installed")
    folder = list(found.submodule_search_locations)[0]
    env = dict(os.environ, LD_LIBRARY_PATH=folder)
    entry = ("import sys; import fdbench.casadi_loader as loader; loader._preload = lambda: None; "
             "from fdbench.cli import main; sys.argv[0] = 'fdbench'; main()")
    for args in (["collocate", "--model", "arm2", "--nodes", "5"], ["control", "--controller", "lqr"]):
        done = subprocess.run([sys.executable, "-c", entry, *args, "--db", tmp_path / "runs.sqlite"],
                              capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
        if done.returncode == 0:
            pytest.skip("this opensim package's libraries do not clash with casadi's")
        lines = done.stderr.splitlines()
        assert done.returncode == 2 and len(lines) == 1 and "LD_LIBRARY_PATH" in lines[0], done.stderr
        assert folder[:60] in lines[0] and done.stdout == ""
        assert list(tmp_path.iterdir()) == []


def test_a_solve_that_meets_infinities_is_quiet_on_stderr(tmp_path):
    """CasADi writes its evaluation warnings (NaN or Inf met on the way) to the process's own stderr,
    past Python: under -q nothing reaches it; the record says how IPOPT ended."""
    import os
    import subprocess
    import sys

    from helpers.processes import python_path

    done = subprocess.run([sys.executable, "-m", "fdbench.cli", "collocate", "--nodes", "20", "--regularization",
                           "1e308", "--format", "json", "-q"], capture_output=True, text=True, cwd=tmp_path,
                          env=dict(os.environ, PYTHONPATH=python_path(ROOT)), timeout=600)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert json.loads(done.stdout)["status"]
