"""Muscle-driven direct collocation of OpenSim's arm26 (its compliant tendons taken as rigid) along its named motion:
IPOPT's solution checked against the compiled engine, the compiled muscle paths and curves (an independent path
from the transcription's symbolic equations), and replayed by the forward simulation with muscles; the symbolic
muscles against the compiled ones; `fdbench collocate --actuation muscles`, its record against its trajectory."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.cli_checks import assert_one_line_error
from helpers.models import LEG

from fdbench.casadi_loader import casadi
from fdbench.cli import app
from fdbench.collocation import collocate_muscles
from fdbench.multibody.model_changes import rigid_tendons
from fdbench.models import find_model
from fdbench.multibody import simulation as sim
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.multibody.model import model_from_dict
from fdbench.multibody.muscle import (SMOOTHING, TAU_ACT, TAU_DEACT, activation_derivative, compliant_tendon,
                                      rigid_tendon_force)
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.multibody.symbolic_muscles import muscle_functions, symbolic

runner = CliRunner()
ARM26 = find_model("arm26")
RIGID = rigid_tendons(ARM26)
NODES = 20


@pytest.fixture(scope="module")
def solved():
    engine = Engine(RIGID)
    motion = joint_motion(RIGID.motions[0].name, RIGID)
    return engine, motion, collocate_muscles(ARM26, motion, engine.muscle_params, NODES)


def test_the_collocation_converges_tracks_the_motion_and_keeps_its_controls_in_bounds(solved):
    """IPOPT converges; the angles at the nodes follow the motion (RMS 0.25 deg with 20 intervals,
    the worst at the free final state); activations and excitations lie in [0, 1] (IPOPT's bound
    tolerance 1e-8); each activation starts at its excitation, as the replay starts it; the compliant
    tendons are named as taken rigid; the reserves are arm26's own (no actuators: 1 N m per coordinate)."""
    _, motion, sol = solved
    assert sol.success, sol.message
    error = np.degrees(sol.angles - motion(sol.t)[0])
    assert np.sqrt(np.mean(error**2)) < 0.5 and np.abs(error).max() < 3.0
    for values in (sol.activation, sol.excitation):
        assert values.shape == (NODES + 1, 6) and values.min() > -1e-7 and values.max() < 1 + 1e-7
    np.testing.assert_allclose(sol.activation[0], sol.excitation[0], atol=1e-8)
    assert sol.rigid_tendons == tuple(m.name for m in ARM26.muscles)
    np.testing.assert_array_equal(sol.reserve_forces, [1.0, 1.0])


def test_the_generalised_forces_balance_at_the_nodes_by_the_compiled_engine_and_muscles(solved):
    """At every node the compiled engine's inverse dynamics of the solution's z, z', z'' equals the
    muscles' generalised forces, each force from the compiled rigid-tendon curve at the length and
    lengthening speed of the compiled path kernel, plus the reserves (to 1e-6 N m); the solution's own
    muscle forces are those (1e-6 N)."""
    engine, _, sol = solved
    tau = engine.inverse_dynamics(sol.angles, sol.velocities, sol.accelerations)
    lengths, arms = muscle_geometry(RIGID, sol.angles)
    lengthening = -np.einsum("nmj,nj->nm", arms, sol.velocities)
    force = np.array([[rigid_tendon_force(sol.activation[k, m], lengths[k, m], lengthening[k, m],
                                          engine.muscle_params[m]) for m in range(6)] for k in range(NODES + 1)])
    np.testing.assert_allclose(sol.muscle_force, force, atol=1e-6)
    np.testing.assert_allclose(tau, np.einsum("nmj,nm->nj", arms, force) + sol.torque, atol=1e-6)
    rms = np.sqrt(np.mean(tau**2, axis=0))  # the muscles, not the reserves, carry the elbow
    assert np.sqrt(np.mean(sol.torque[:, 1] ** 2)) < 0.1 * rms[1]


def test_the_replay_of_the_excitations_and_reserves_reaches_the_end_near_the_collocation(solved):
    """The forward simulation with muscles (rigid tendons), driven by the excitations (linear between
    the nodes) and reserves found, reaches the end; its angles follow the collocation's nodes
    within 1 deg and its activations the collocation's within 0.05."""
    engine, motion, sol = solved
    result = sim.simulate(sol.torque_function(), engine, motion, excitation=sol.excitation_function())
    assert result.success and result.t_end == pytest.approx(motion.duration)
    at = np.abs(result.t[:, None] - sol.t).argmin(axis=0)  # the samples at the nodes
    np.testing.assert_allclose(result.t[at], sol.t, atol=1e-9)
    assert np.degrees(np.abs(result.angles[at] - sol.angles)).max() < 1.0
    assert np.abs(result.activation[at] - sol.activation).max() < 0.05


def test_a_model_without_muscles_or_a_bad_weight_is_refused_in_one_line():
    forearm = find_model("forearm")
    motion = joint_motion("paper", forearm)
    for model, weight, words in ((forearm, 1.0, "has no muscles"), (RIGID, -1.0, "--effort-weight")):
        with pytest.raises(ValueError, match=words) as caught:
            collocate_muscles(model, motion, np.zeros((0, 12)), 5, effort_weight=weight)
        assert "\n" not in str(caught.value)


# ---------------------------------------------------------------- the symbolic muscles against the compiled ones
LEG_MUSCLES = [{"name": name, "max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.3,
                "pennation_angle": 0.2, "fiber_damping": 0.01,
                "path": {"points": [{"body": b, "at": [x, y]} for b, x, y in points]}}
               for name, points in (("long", [("ground", 0.05, 0.1), ("thigh", 0.04, -0.1), ("shank", 0.02, -0.05),
                                              ("heel", 0.12, 0.03)]),
                                    ("soleus", [("shank", -0.03, -0.1), ("foot", -0.04, 0.02)]))]


def compiled_muscles(model, params, z, zd, a):
    """Lengths, moment arms, lengthening speeds and rigid-tendon forces by the compiled kernels."""
    lengths, arms = muscle_geometry(model, z)
    lengthening = -arms @ zd
    force = np.array([rigid_tendon_force(a[m], lengths[m], lengthening[m], params[m]) for m in range(len(a))])
    return lengths, arms, lengthening, force


@pytest.mark.parametrize("name", ["arm26", "leg"])
def test_the_symbolic_muscles_are_the_compiled_ones_at_random_states(name):
    """At random coordinates, rates and activations: lengths, moment arms (-dl/dz by CasADi's jacobian
    against the kernel's closed forms), lengthening speeds, rigid-tendon forces, the muscles'
    generalised forces and De Groote's activation rate agree with the compiled functions to 1e-10
    (relative to each quantity's scale): arm26's polynomial paths, and paths of points on a free base, a
    knee on a path spline, an offset ankle and a frame."""
    model = RIGID if name == "arm26" else model_from_dict(LEG | {"muscles": LEG_MUSCLES}, "leg")
    params = Engine(model).muscle_params
    geometry, forces, rate = muscle_functions(model, params)
    J, M = model.n_joints, len(model.muscles)
    rng = np.random.default_rng(7)
    for _ in range(5):
        z = rng.uniform(0.1, 1.2, J) if name == "arm26" else rng.uniform(-0.5, 0.5, J)
        zd, a, e = rng.normal(0.0, 2.0, J), rng.uniform(0.0, 1.0, M), rng.uniform(0.0, 1.0, M)
        lengths, arms, lengthening, force = compiled_muscles(model, params, z, zd, a)
        found = [np.array(v) for v in (*geometry(z, zd), *forces(z, zd, a))]
        for mine, theirs in zip(found, (lengths, arms, lengthening, force, arms.T @ force)):
            np.testing.assert_allclose(mine.reshape(theirs.shape), theirs, rtol=0, atol=1e-10 * np.abs(theirs).max())
        expected = [activation_derivative(e[m], a[m], params[m, TAU_ACT], params[m, TAU_DEACT], params[m, SMOOTHING])
                    for m in range(M)]
        np.testing.assert_allclose(np.array(rate(e, a)).ravel(), expected, rtol=1e-12, atol=1e-12)


def test_a_compiled_function_that_branches_on_data_raises_on_a_symbol():
    """The compliant tendon's max(a, MIN_ACTIVATION) cannot be written on a symbol: it raises, never a silent branch."""
    ca = casadi()
    a = ca.SX.sym("a")
    with pytest.raises(Exception):
        symbolic(compliant_tendon)(a, 0.5, 0.3, 0.0, Engine(RIGID).muscle_params[0])


# ---------------------------------------------------------------- the command line
def test_collocate_actuation_muscles_records_the_muscle_fields_of_its_replay(tmp_path):
    """`fdbench collocate --model arm26 --actuation muscles` (20 intervals): the replay tracks within 0.5 deg
    RMS; the record's effort, activation means and reserves are those of the saved trajectory; each applied
    generalised force is the muscles' (their saved forces times the compiled moment arms) plus the reserve."""
    trajectory = tmp_path / "run.csv"
    result = runner.invoke(app, ["collocate", "--model", "arm26", "--actuation", "muscles", "--nodes", "20", "-f",
                                 "json", "-q", "--save-trajectory", str(trajectory)])
    assert result.exit_code == 0, result.stderr
    record = json.loads(result.stdout)
    with open(trajectory, newline="") as handle:
        rows = list(csv.DictReader(handle))
    column = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    assert record["status"] == "success" and record["actuation"] == "muscles" and record["rmse_rot_deg"] < 0.5
    assert record["ipopt_status"] == "Solve_Succeeded" and "compliant taken as rigid" in record["tendons"]
    names, joints = [m.name for m in ARM26.muscles], ARM26.coordinates
    activation = np.stack([column[f"{m}_activation"] for m in names], axis=1)
    assert record["effort"] == pytest.approx(np.mean(np.sum(activation**2, axis=1)), rel=1e-9)
    for i, m in enumerate(names):
        assert record[f"{m}_activation_mean"] == pytest.approx(np.mean(activation[:, i]), rel=1e-9, abs=1e-12)
    reserve = np.stack([column[f"{j}_reserve"] for j in joints], axis=1)
    assert record["reserve_rms_nm"] == pytest.approx(np.sqrt(np.mean(reserve**2)), rel=1e-9)
    z = np.radians(np.stack([column[j] for j in joints], axis=1))
    _, arms = muscle_geometry(ARM26, z)
    force = np.stack([column[f"{m}_force"] for m in names], axis=1)
    applied = np.stack([column[f"{j}_torque"] for j in joints], axis=1)
    np.testing.assert_allclose(applied, np.einsum("nmj,nm->nj", arms, force) + reserve, atol=1e-6)


@pytest.mark.parametrize("args, words", [
    (["--actuation", "muscles"], ["model 'forearm' has no muscles"]),
    (["--model", "arm26", "--actuation", "muscles", "--regularization", "1"], ["--regularization", "torques only"]),
    (["--model", "arm26", "--effort-weight", "1"], ["--effort-weight", "muscles only"]),
    (["--model", "arm26", "--actuation", "muscles", "--save-torque", "t.csv"], ["--save-torque"]),
    (["--model", "arm26", "--actuation", "muscle"], ["--actuation", "did you mean 'muscles'"]),
])
def test_collocate_s_bad_actuation_input_is_one_line_and_exit_2(args, words):
    assert_one_line_error(runner.invoke(app, ["collocate", *args]), *words)
