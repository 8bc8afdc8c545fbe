"""Muscle-driven direct collocation of OpenSim's arm26 (its compliant tendons taken as rigid) along its named motion:
IPOPT's solution checked against the compiled engine, the compiled muscle paths and curves (an independent path
from the transcription's symbolic equations), and replayed by the forward simulation with muscles."""

from __future__ import annotations

import numpy as np
import pytest

from fdbench.collocation import collocate_muscles, rigid_tendons
from fdbench.models import find_model
from fdbench.multibody import simulation as sim
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions import joint_motion
from fdbench.multibody.muscle import rigid_tendon_force
from fdbench.multibody.muscle_paths import muscle_geometry

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
