"""A model's muscles along a motion (``fdbench.multibody.muscle_analysis``): on one pin with one
muscle from (0, h) on ground to (d, 0) on the forearm, the rigid tendon's fibre by the closed forms
of the constant-thickness pennation model and the paper's curves at their defining points, its
moment arm against finite differences of the closed-form length; a compliant tendon's fibre in
static equilibrium and its velocity the rate of that equilibrium; and against OpenSim's
DeGrooteFregly2016Muscle on the same pin (rigid tendon at speed, compliant tendon equilibrated)."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from helpers.opensim_child import run_opensim
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.muscle_analysis import muscle_analysis

D, H = 0.05, 0.3  # m: the insertion on the forearm (d, 0), the origin on ground (0, h)
F0, L_OPT, ALPHA, V_MAX, DAMPING = 1000.0, 0.1, 0.3, 10.0, 0.05
THETA0 = 0.2  # rad: where the rigid tendon leaves the fibre at its optimal length


def path_length(theta):
    return np.sqrt(D * D + H * H - 2 * D * H * np.sin(theta))


L_SLACK = float(path_length(THETA0)) - L_OPT * math.cos(ALPHA)
MUSCLE = {"max_isometric_force": F0, "optimal_fiber_length": L_OPT, "tendon_slack_length": L_SLACK,
          "pennation_angle": ALPHA, "max_contraction_velocity": V_MAX, "fiber_damping": DAMPING,
          "path": {"points": [{"body": "ground", "at": [0.0, H]}, {"body": "forearm", "at": [D, 0.0]}]}}


@pytest.fixture(scope="module")
def pin():
    """The forearm with the muscle twice: a rigid tendon ('rigid') and a compliant one ('springy')."""
    data = to_dict(find_model("forearm")) | {"muscles": [MUSCLE | {"name": "rigid"},
                                                         MUSCLE | {"name": "springy", "tendon": "compliant"}]}
    return Engine(model_from_dict(data, "forearm"))


def passive_multiplier(norm_length, strain=0.6, shape=4.0, minimum=0.2):
    """De Groote et al. 2016's passive curve, zero at the minimum fibre length as OpenSim's."""
    offset = math.exp(shape * (minimum - 1) / strain)
    return (math.exp(shape * (norm_length - 1) / strain) - offset) / (math.exp(shape) - offset)


def test_a_rigid_tendon_s_fibre_is_the_constant_thickness_closed_form(pin):
    theta = np.linspace(-0.5, 0.9, 15)
    rate = np.linspace(-3.0, 2.0, 15)
    got = muscle_analysis(pin, theta[:, None], rate[:, None])
    length = path_length(theta)
    height = L_OPT * math.sin(ALPHA)
    fiber = np.sqrt((length - L_SLACK) ** 2 + height ** 2)
    np.testing.assert_allclose(got.length[:, 0], length, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got.fiber_length[:, 0], fiber, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got.pennation_angle[:, 0], np.arctan2(height, length - L_SLACK), rtol=0, atol=1e-12)
    step = 1e-6
    slope = (path_length(theta + step) - path_length(theta - step)) / (2 * step)
    np.testing.assert_allclose(got.moment_arm[:, 0, 0], -slope, rtol=0, atol=1e-9)
    # d(fibre)/dt = (l - l_s) / fibre * dl/dt, in optimal lengths per s over v_max
    np.testing.assert_allclose(got.fiber_velocity[:, 0], (length - L_SLACK) / fiber * slope * rate / (V_MAX * L_OPT),
                               rtol=1e-8, atol=0)
    passive = np.array([passive_multiplier(x) for x in fiber / L_OPT])
    np.testing.assert_allclose(got.passive_fiber_force[:, 0], F0 * (passive + DAMPING * got.fiber_velocity[:, 0]),
                               rtol=1e-12, atol=0)


def test_at_the_optimal_length_the_isometric_force_is_f0_along_the_pennation(pin):
    """f_L(1) = 1, f_V(0) = 1, f_V(-1) = 0: F0 cos(alpha_opt) along the path at rest, none at the
    fastest shortening; the passive force is the paper's f_PE(1) = (1 - e^(-16/3)) / (e^4 - e^(-16/3))."""
    slope = -D * H * math.cos(THETA0) / float(path_length(THETA0))  # dl/dtheta
    fastest = -V_MAX * L_OPT / (math.cos(ALPHA) * slope)  # rad/s: v = -1
    got = muscle_analysis(pin, [[THETA0], [THETA0]], [[0.0], [fastest]])
    np.testing.assert_allclose(got.fiber_length[:, 0], L_OPT, rtol=1e-14)
    np.testing.assert_allclose(got.pennation_angle[:, 0], ALPHA, rtol=1e-12)
    assert got.active_fiber_force[0, 0] * math.cos(got.pennation_angle[0, 0]) == pytest.approx(F0 * math.cos(ALPHA),
                                                                                                 rel=1e-12)
    assert got.passive_fiber_force[0, 0] == pytest.approx(
        F0 * (1 - math.exp(-16 / 3)) / (math.exp(4) - math.exp(-16 / 3)), rel=1e-12)
    assert got.fiber_velocity[1, 0] == pytest.approx(-1.0, rel=1e-12)
    assert abs(got.active_fiber_force[1, 0]) < 1e-9 * F0


def test_a_compliant_tendon_holds_the_fibre_in_equilibrium_and_moves_with_it(pin):
    """The tendon's length l - l_M cos(alpha) gives the force c1 exp(kT (l_T / l_s - 1)) - c3
    (kT from the strain at one normalised force, 0.049) that the fibre bears at full activation and
    rest, cos(alpha) (f_L + f_PE); the fibre keeps its height; its velocity is the rate of its
    length along the motion theta(t) = theta + rate t (central differences in t)."""
    theta = np.linspace(-0.5, 0.9, 8)
    rate = np.linspace(-3.0, 2.0, 8)
    at_rest = muscle_analysis(pin, theta[:, None], np.zeros((8, 1)))
    fiber, alpha = at_rest.fiber_length[:, 1], at_rest.pennation_angle[:, 1]
    tendon = at_rest.length[:, 1] - fiber * np.cos(alpha)
    c1, c3, strain = 0.2, 0.2, 0.049
    stiffness = math.log((1 + c3) / c1) / strain
    tendon_force = c1 * np.exp(stiffness * (tendon / L_SLACK - 1)) - c3
    fiber_force = np.cos(alpha) * (at_rest.active_fiber_force[:, 1] + at_rest.passive_fiber_force[:, 1]) / F0
    np.testing.assert_allclose(tendon_force, fiber_force, rtol=1e-9, atol=1e-12)
    assert np.all(tendon > L_SLACK)  # stretched by the fibre's pull
    np.testing.assert_allclose(fiber * np.sin(alpha), L_OPT * math.sin(ALPHA), rtol=1e-12)
    assert np.all(at_rest.fiber_velocity[:, 1] == 0.0)
    moving = muscle_analysis(pin, theta[:, None], rate[:, None])
    dt = 1e-6
    ahead, behind = (muscle_analysis(pin, (theta + s * rate * dt)[:, None], rate[:, None]) for s in (1, -1))
    rates = (ahead.fiber_length[:, 1] - behind.fiber_length[:, 1]) / (2 * dt) / (V_MAX * L_OPT)
    np.testing.assert_allclose(moving.fiber_velocity[:, 1], rates, rtol=1e-5, atol=1e-9)


OPENSIM_PIN = """
model = osim.Model()
arm = osim.Body("arm", 1.0, osim.Vec3(0), osim.Inertia(1))
model.addBody(arm)
pin = osim.PinJoint("pin", model.getGround(), osim.Vec3(0), osim.Vec3(0), arm, osim.Vec3(0), osim.Vec3(0))
model.addJoint(pin)
muscles = []
for name, rigid in (("rigid", True), ("springy", False)):
    muscle = osim.DeGrooteFregly2016Muscle()
    muscle.setName(name)
    for key, value in request["properties"].items():
        getattr(muscle, "set_" + key)(value)
    muscle.set_ignore_tendon_compliance(rigid)
    muscle.addNewPathPoint("origin", model.getGround(), osim.Vec3(0, request["h"], 0))
    muscle.addNewPathPoint("insertion", arm, osim.Vec3(request["d"], 0, 0))
    model.addForce(muscle)
    muscles.append(muscle)
state = model.initSystem()
coordinate = pin.getCoordinate()
out = []
for theta, rate in request["states"]:
    coordinate.setValue(state, theta, False)
    coordinate.setSpeedValue(state, rate)
    for muscle in muscles:
        muscle.setActivation(state, 1.0)
    model.equilibrateMuscles(state)
    model.realizeDynamics(state)
    out.append([[m.getLength(state), m.computeMomentArm(state, coordinate), m.getFiberLength(state),
                 m.getPennationAngle(state), m.getNormalizedFiberVelocity(state), m.getActiveFiberForce(state),
                 m.getPassiveFiberForce(state)] for m in muscles])
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def opensim_pin():
    """OpenSim's answers at 6 states of the pin, in one child process (its bundled CasADi cannot
    share a process with the casadi package): moving (the rigid tendon's) and at rest (both)."""
    if importlib.util.find_spec("opensim") is None:
        pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')")
    states = [[-0.4, 1.5], [0.3, -2.0], [0.8, 0.7], [-0.4, 0.0], [0.3, 0.0], [0.8, 0.0]]
    request = {"d": D, "h": H, "states": states, "properties": {
        "max_isometric_force": F0, "optimal_fiber_length": L_OPT, "tendon_slack_length": L_SLACK,
        "pennation_angle_at_optimal": ALPHA, "max_contraction_velocity": V_MAX, "fiber_damping": DAMPING}}
    return np.array(states), np.array(run_opensim(OPENSIM_PIN, request, timeout=300))


def test_the_fibres_are_opensims(pin, opensim_pin):
    """Length, moment arm, fibre length, pennation, normalised fibre velocity, active fibre force at
    activation 1 and passive fibre force: the rigid tendon at every state, the compliant one at rest
    (OpenSim's equilibrateMuscles)."""
    states, theirs = opensim_pin
    got = muscle_analysis(pin, states[:, :1], states[:, 1:])
    ours = np.stack([got.length, got.moment_arm[:, :, 0], got.fiber_length, got.pennation_angle, got.fiber_velocity,
                     got.active_fiber_force, got.passive_fiber_force], axis=-1)  # (n, M, 7) as theirs
    scale = np.array([1.0, 1.0, 1.0, 1.0, 1.0, F0, F0])
    np.testing.assert_allclose(ours[:, 0] / scale, theirs[:, 0] / scale, rtol=0, atol=1e-9)
    at_rest = states[:, 1] == 0.0
    np.testing.assert_allclose(ours[at_rest, 1] / scale, theirs[at_rest, 1] / scale, rtol=0, atol=1e-6)
