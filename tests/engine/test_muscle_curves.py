"""The De Groote–Fregly 2016 muscle (fdbench.multibody.muscle) against OpenSim's own
DeGrooteFregly2016Muscle: its curves at 200 random points with random properties, and muscles
in small models (a block on a slider pulled by one muscle along the slider) at 200 random states
with a rigid and with a compliant tendon; plus checks of its own: derivatives against finite
differences, f_V and its inverse composing to the identity, the curves' defining points, closed
forms of the isometric force and of a tendon holding its length."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers.opensim_child import run_opensim
from fdbench.multibody import muscle as mu

RNG_SEED = 20161001
CURVES = ("active_force_length", "active_force_length_derivative", "force_velocity", "force_velocity_inverse",
          "passive_force_length", "passive_force_length_derivative", "tendon_force_length",
          "tendon_force_length_derivative", "tendon_force_length_inverse")

# OpenSim runs in a child process only: its bundled CasADi cannot share a process with the casadi
# package the rest of the suite imports (see fdbench.multibody.osim.import_osim_content).
OPENSIM_MUSCLE = """
M = osim.DeGrooteFregly2016Muscle
curves = []
for s in request["curves"]:
    m = M()
    m.set_passive_fiber_strain_at_one_norm_force(s["e0"])
    m.set_tendon_strain_at_one_norm_force(s["eT"])
    m.set_active_force_width_scale(s["width"])
    curves.append({
        "active_force_length": m.calcActiveForceLengthMultiplier(s["l"]),
        "active_force_length_derivative": m.calcActiveForceLengthMultiplierDerivative(s["l"]),
        "force_velocity": M.calcForceVelocityMultiplier(s["v"]),
        "force_velocity_inverse": M.calcForceVelocityInverseCurve(s["fv"]),
        "passive_force_length": m.calcPassiveForceMultiplier(s["l"]),
        "passive_force_length_derivative": m.calcPassiveForceMultiplierDerivative(s["l"]),
        "tendon_force_length": m.calcTendonForceMultiplier(s["lT"]),
        "tendon_force_length_derivative": m.calcTendonForceMultiplierDerivative(s["lT"]),
        "tendon_force_length_inverse": m.calcTendonForceLengthInverseCurve(s["fT"])})
muscles = []
for spec in request["muscles"]:
    model = osim.Model()
    block = osim.Body("block", 1.0, osim.Vec3(0), osim.Inertia(1))
    model.addBody(block)
    slider = osim.SliderJoint("slider", model.getGround(), block)  # along ground's x
    model.addJoint(slider)
    muscle = M()
    muscle.setName("muscle")
    for name, value in spec["properties"].items():
        getattr(muscle, "set_" + name)(value)
    muscle.set_ignore_tendon_compliance(spec["rigid"])
    muscle.addNewPathPoint("origin", model.getGround(), osim.Vec3(-spec["anchor"], 0, 0))
    muscle.addNewPathPoint("insertion", block, osim.Vec3(0))  # length anchor + q, lengthening speed q'
    model.addForce(muscle)
    state = model.initSystem()
    coordinate = slider.getCoordinate()
    out = []
    for length, lengthening, activation, tendon_force, excitation in spec["states"]:
        coordinate.setValue(state, length - spec["anchor"], False)
        coordinate.setSpeedValue(state, lengthening)
        muscle.setActivation(state, activation)
        if not spec["rigid"]:
            muscle.setNormalizedTendonForce(state, tendon_force)
        model.realizeVelocity(state)
        controls = model.updControls(state)
        muscle.setControls(osim.Vector(1, excitation), controls)
        model.setControls(state, controls)
        model.realizeAcceleration(state)
        out.append([muscle.getLength(state), muscle.getLengtheningSpeed(state), muscle.getFiberLength(state),
                    muscle.getCosPennationAngle(state), muscle.getTendonForce(state),
                    muscle.getNormalizedTendonForceDerivative(state),
                    muscle.getStateVariableDerivativeValue(state, "activation")])
    muscles.append(out)
print(json.dumps({"curves": curves, "muscles": muscles}))
"""


def opensim(request: dict) -> dict:
    """OpenSim's answers to ``request`` (see OPENSIM_MUSCLE), in a child process."""
    return run_opensim(OPENSIM_MUSCLE, request, timeout=600)


def random_curve_points(rng, n: int = 200) -> list[dict]:
    """Curve inputs over their domains, each with random curve properties."""
    return [{"e0": rng.uniform(0.3, 0.9), "eT": rng.uniform(0.02, 0.08), "width": rng.uniform(1.0, 2.0),
             "l": rng.uniform(0.2, 1.8), "v": rng.uniform(-1.0, 1.0), "fv": rng.uniform(0.0, 1.79),
             "lT": rng.uniform(0.98, 1.08), "fT": rng.uniform(0.0, 3.0)} for _ in range(n)]


def ours(name: str, s: dict) -> float:
    f = getattr(mu, name)
    return {"active_force_length": lambda: f(s["l"], s["width"]),
            "active_force_length_derivative": lambda: f(s["l"], s["width"]),
            "force_velocity": lambda: f(s["v"]), "force_velocity_inverse": lambda: f(s["fv"]),
            "passive_force_length": lambda: f(s["l"], s["e0"]),
            "passive_force_length_derivative": lambda: f(s["l"], s["e0"]),
            "tendon_force_length": lambda: f(s["lT"], s["eT"]),
            "tendon_force_length_derivative": lambda: f(s["lT"], s["eT"]),
            "tendon_force_length_inverse": lambda: f(s["fT"], s["eT"])}[name]()


def random_muscle(rng) -> dict:
    """OpenSim's properties of a random muscle, activation's time constants and smoothing at their
    defaults (OpenSim 4.6 keeps those of the first muscle of a process for all its muscles)."""
    return {"max_isometric_force": rng.uniform(200.0, 3000.0), "optimal_fiber_length": rng.uniform(0.04, 0.2),
            "tendon_slack_length": rng.uniform(0.05, 0.4), "pennation_angle_at_optimal": rng.uniform(0.0, 0.5),
            "max_contraction_velocity": rng.uniform(5.0, 15.0),
            "passive_fiber_strain_at_one_norm_force": rng.uniform(0.4, 0.8),
            "tendon_strain_at_one_norm_force": rng.uniform(0.03, 0.07), "fiber_damping": rng.uniform(0.0, 0.1),
            "active_force_width_scale": rng.uniform(1.0, 1.5)}


def random_states(rng, p: np.ndarray, rigid: bool, n: int) -> list[list[float]]:
    """States (muscle-tendon length m, lengthening m/s, activation, normalised tendon force,
    excitation) with normalised fibre lengths in [0.5, 1.5] and, compliant, f_V in [0.05, 1.7]."""
    states = []
    height = p[mu.L_OPT] * math.sin(p[mu.ALPHA_OPT])
    for _ in range(n):
        activation, excitation = rng.uniform(0.02, 1.0), rng.uniform(0.0, 1.0)
        fiber = rng.uniform(0.5, 1.5) * p[mu.L_OPT]
        along = math.sqrt(fiber ** 2 - height ** 2)
        if rigid:
            tendon_force, tendon = 0.0, p[mu.L_SLACK]
            lengthening = rng.uniform(-0.8, 0.8) * p[mu.V_MAX] * p[mu.L_OPT] * fiber / along
        else:  # the tendon force of a fibre velocity in f_V's range (the inputs only; OpenSim gives the outputs)
            norm = fiber / p[mu.L_OPT]
            tendon_force = along / fiber * (activation * mu.active_force_length(norm, p[mu.WIDTH])
                                            * rng.uniform(0.05, 1.7)
                                            + mu.passive_force_length(norm, p[mu.PASSIVE_STRAIN]))
            tendon = p[mu.L_SLACK] * mu.tendon_force_length_inverse(tendon_force, p[mu.TENDON_STRAIN])
            lengthening = rng.uniform(-0.5, 0.5) * p[mu.V_MAX] * p[mu.L_OPT]
        states.append([tendon + along, lengthening, activation, tendon_force, excitation])
    return states


@pytest.fixture(scope="module")
def against_opensim():
    """200 curve points and 10 muscles x 2 tendons x 10 states, ours and OpenSim's."""
    if importlib.util.find_spec("opensim") is None:
        pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')")
    rng = np.random.default_rng(RNG_SEED)
    points = random_curve_points(rng)
    muscles = []
    for _ in range(10):
        properties = random_muscle(rng)
        p = mu.parameters(**properties)
        for rigid in (True, False):
            muscles.append({"properties": properties, "rigid": rigid, "anchor": p[mu.L_SLACK] + p[mu.L_OPT],
                            "states": random_states(rng, p, rigid, 10), "p": p})
    theirs = opensim({"curves": points,
                      "muscles": [{k: v for k, v in m.items() if k != "p"} for m in muscles]})
    return points, muscles, theirs


def test_the_curves_are_opensims_at_200_random_points(against_opensim):
    points, _, theirs = against_opensim
    for name in CURVES:
        mine = np.array([ours(name, s) for s in points])
        expected = np.array([c[name] for c in theirs["curves"]])
        np.testing.assert_allclose(mine, expected, rtol=1e-6, atol=1e-12, err_msg=name)
    assert np.ptp([c["active_force_length"] for c in theirs["curves"]]) > 0.5  # the points span the curves


def test_muscles_in_a_model_are_opensims_with_rigid_and_compliant_tendons(against_opensim):
    """Fibre length and pennation, the force along the path, d(tendon force)/dt and da/dt at 200
    states of 10 random muscles (each with a rigid and with a compliant tendon)."""
    _, muscles, theirs = against_opensim
    checked = 0
    for muscle, answers in zip(muscles, theirs["muscles"]):
        p = muscle["p"]
        for (length, lengthening, activation, tendon_force, excitation), answer in zip(muscle["states"], answers):
            path_length, speed, fiber, cos_alpha, force, force_rate, activation_rate = answer
            assert (path_length, speed) == pytest.approx((length, lengthening), rel=1e-12, abs=1e-12)
            tendon = p[mu.L_SLACK] * (1.0 if muscle["rigid"] else
                                      mu.tendon_force_length_inverse(tendon_force, p[mu.TENDON_STRAIN]))
            assert mu.fiber_length(length - tendon, p[mu.L_OPT], p[mu.ALPHA_OPT]) == pytest.approx(
                (fiber, cos_alpha), rel=1e-9)
            if muscle["rigid"]:
                assert mu.rigid_tendon_force(activation, length, lengthening, p) == pytest.approx(force, rel=1e-6)
                assert force_rate == 0.0
            else:
                assert mu.compliant_tendon(activation, tendon_force, length, lengthening, p) == pytest.approx(
                    (force, force_rate), rel=1e-6, abs=1e-9)
            assert mu.activation_derivative(excitation, activation, p[mu.TAU_ACT], p[mu.TAU_DEACT],
                                            p[mu.SMOOTHING]) == pytest.approx(activation_rate, rel=1e-6, abs=1e-12)
            checked += 1
    assert checked == 200


def test_activation_dynamics_with_other_time_constants_and_smoothing_are_opensims():
    """A muscle with its own activation_time_constant, deactivation_time_constant and
    activation_dynamics_smoothing, alone in its process: OpenSim 4.6 keeps these three of the first
    muscle it computes in static variables, shared by every muscle of the process after it."""
    if importlib.util.find_spec("opensim") is None:
        pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')")
    rng = np.random.default_rng(RNG_SEED + 1)
    properties = {**random_muscle(rng), "activation_time_constant": 0.01, "deactivation_time_constant": 0.04,
                  "activation_dynamics_smoothing": 10.0}
    p = mu.parameters(**properties)
    states = random_states(rng, p, True, 20)
    theirs = opensim({"curves": [], "muscles": [{"properties": properties, "rigid": True,
                                                 "anchor": p[mu.L_SLACK] + p[mu.L_OPT], "states": states}]})
    rates = [answer[-1] for answer in theirs["muscles"][0]]
    mine = [mu.activation_derivative(e, a, 0.01, 0.04, 10.0) for _, _, a, _, e in states]
    np.testing.assert_allclose(mine, rates, rtol=1e-6, atol=1e-12)
    defaults = [mu.activation_derivative(e, a, 0.015, 0.06, 0.1) for _, _, a, _, e in states]
    assert np.abs(np.subtract(defaults, rates)).max() > 1.0  # the constants did matter (1/s)


# ---------------------------------------------------------------------- checks of its own


def central_difference(f, x, h=1e-6):
    return (f(x + h) - f(x - h)) / (2 * h)


@pytest.mark.parametrize("e0,eT,width", [(0.6, 0.049, 1.0), (0.4, 0.03, 1.7)])
def test_derivatives_are_the_curves_slopes(e0, eT, width):
    for x in np.linspace(0.3, 1.8, 31):
        assert mu.active_force_length_derivative(x, width) == pytest.approx(
            central_difference(lambda y: mu.active_force_length(y, width), x), rel=1e-6, abs=1e-8)
        assert mu.passive_force_length_derivative(x, e0) == pytest.approx(
            central_difference(lambda y: mu.passive_force_length(y, e0), x), rel=1e-6, abs=1e-8)
    for v in np.linspace(-1.0, 1.0, 21):
        assert mu.force_velocity_derivative(v) == pytest.approx(central_difference(mu.force_velocity, v), rel=1e-6)
    for lt in np.linspace(0.98, 1.08, 21):
        assert mu.tendon_force_length_derivative(lt, eT) == pytest.approx(
            central_difference(lambda y: mu.tendon_force_length(y, eT), lt), rel=1e-6)


@given(st.floats(-1.0, 1.0))
def test_force_velocity_inverse_undoes_force_velocity(v):
    assert mu.force_velocity_inverse(mu.force_velocity(v)) == pytest.approx(v, abs=1e-12)


@given(st.floats(0.0, 1.79))
def test_force_velocity_undoes_its_inverse(multiplier):
    assert mu.force_velocity(mu.force_velocity_inverse(multiplier)) == pytest.approx(multiplier, abs=1e-12)


@given(st.floats(0.0, 5.0), st.floats(0.01, 0.1))
def test_tendon_inverse_undoes_the_tendon_curve(force, strain):
    length = mu.tendon_force_length_inverse(force, strain)
    assert mu.tendon_force_length(length, strain) == pytest.approx(force, abs=1e-12)
    assert length >= 1.0 - 1e-15


def test_the_curves_defining_points():
    # active: 1 at the optimal length; the sum of the three terms peaks 0.1 % higher, 1.3 % longer
    assert mu.active_force_length(1.0, 1.0) == pytest.approx(1.0, abs=1e-15)
    grid = np.linspace(0.2, 1.8, 16001)
    active = np.array([mu.active_force_length(x, 1.0) for x in grid])
    assert 1.0 < active.max() < 1.0011 and 1.0 < grid[active.argmax()] < 1.014
    assert active.min() > 0 and mu.active_force_length(0.4, 1.0) < 0.1
    for width in (1.3, 2.0):  # the width scale stretches the curve about 1
        for x in (0.5, 0.8, 1.2, 1.6):
            assert mu.active_force_length(1.0 + width * (x - 1.0), width) == pytest.approx(
                mu.active_force_length(x, 1.0), rel=1e-14)
    # force-velocity: 0 at the fastest shortening, 1 isometric, 1.794 at the fastest lengthening
    assert mu.force_velocity(-1.0) == pytest.approx(0.0, abs=1e-14)
    assert mu.force_velocity(0.0) == pytest.approx(1.0, abs=1e-14)
    assert mu.force_velocity(1.0) == pytest.approx(1.794, abs=5e-4)
    # passive: 0 at the shortest fibre (0.2), negative below, 1 at 1 + strain, increasing
    for e0 in (0.4, 0.6, 0.9):
        assert mu.passive_force_length(mu.MIN_FIBER_LENGTH, e0) == pytest.approx(0.0, abs=1e-15)
        assert mu.passive_force_length(0.15, e0) < 0 < mu.passive_force_length(0.25, e0)
        assert mu.passive_force_length(1.0 + e0, e0) == pytest.approx(1.0, abs=1e-14)
        assert all(np.diff([mu.passive_force_length(x, e0) for x in grid]) > 0)
    # tendon: 0 at the slack length, 1 at 1 + strain, kT = ln(6) / strain
    for eT in (0.03, 0.049, 0.07):
        assert mu.tendon_force_length(1.0, eT) == pytest.approx(0.0, abs=1e-15)
        assert mu.tendon_force_length(1.0 + eT, eT) == pytest.approx(1.0, abs=1e-13)
        assert mu.tendon_stiffness(eT) == pytest.approx(math.log(6.0) / eT, rel=1e-14)
        assert mu.tendon_force_length(0.9, eT) > -0.2  # its asymptote, -c3


def test_activation_dynamics_time_constants():
    """At rest nothing moves; with a steep smoothing (b = 1000) it is first order with
    tau_act (0.5 + 1.5 a) rising and tau_deact / (0.5 + 1.5 a) falling; OpenSim's b = 0.1 blends."""
    for a in (0.05, 0.5, 0.9):
        assert mu.activation_derivative(a, a, 0.015, 0.06, 0.1) == 0.0
        assert mu.activation_derivative(1.0, a, 0.015, 0.06, 1000.0) == pytest.approx(
            (1.0 - a) / (0.015 * (0.5 + 1.5 * a)), rel=1e-12)
        assert mu.activation_derivative(0.0, a, 0.015, 0.06, 1000.0) == pytest.approx(
            -a * (0.5 + 1.5 * a) / 0.06, rel=1e-12)
        rise, fall = (0.5 * (1 + math.tanh(0.1 * (1 - a))), 0.5 * (1 - math.tanh(0.1 * (1 - a))))
        assert mu.activation_derivative(1.0, a, 0.015, 0.06, 0.1) == pytest.approx(
            (1 - a) * (rise / (0.015 * (0.5 + 1.5 * a)) + fall * (0.5 + 1.5 * a) / 0.06), rel=1e-12)


@pytest.mark.parametrize("alpha", [0.0, 0.3])
def test_isometric_force_at_the_optimal_length_is_f0_along_the_pennation(alpha):
    """A rigid tendon at l_MT = l_s + l_opt cos(alpha_opt): the fibre is at l_opt, so fully active
    and still it pulls F0 (1 + f_PE(1)) cos(alpha_opt), f_PE(1) = (1 - e^(-3.2/e0)) / (e^4 - e^(-3.2/e0))
    (-0.8 KPE / e0 = -3.2 / e0); at zero activation, the passive part alone."""
    p = mu.parameters(1500.0, 0.09, 0.25, pennation_angle_at_optimal=alpha, passive_fiber_strain_at_one_norm_force=0.5)
    length = 0.25 + 0.09 * math.cos(alpha)
    passive = (1 - math.exp(-6.4)) / (math.exp(4.0) - math.exp(-6.4))
    assert mu.fiber_length(0.09 * math.cos(alpha), 0.09, alpha) == pytest.approx((0.09, math.cos(alpha)), rel=1e-14)
    assert mu.rigid_tendon_force(1.0, length, 0.0, p) == pytest.approx(1500.0 * (1 + passive) * math.cos(alpha),
                                                                       rel=1e-13)
    assert mu.rigid_tendon_force(0.0, length, 0.0, p) == pytest.approx(1500.0 * passive * math.cos(alpha), rel=1e-13)
    # the fastest shortening leaves passive force and damping: -F0 d cos(alpha) more
    damped = mu.parameters(1500.0, 0.09, 0.25, pennation_angle_at_optimal=alpha,
                           passive_fiber_strain_at_one_norm_force=0.5, fiber_damping=0.05)
    fastest = -10.0 * 0.09 / math.cos(alpha)  # fibre at -v_max l_opt
    assert mu.rigid_tendon_force(1.0, length, fastest, damped) == pytest.approx(
        1500.0 * (passive - 0.05) * math.cos(alpha), rel=1e-12)


@pytest.mark.parametrize("velocity", [-0.6, 0.0, 0.4])
def test_a_tendon_holding_its_length_has_a_steady_force(velocity):
    """Compliant: with the tendon force of a fibre at normalised velocity ``velocity`` and the path
    lengthening exactly as the fibre does (v_M / cos(alpha)), the tendon's length, and so its
    force, stays: d(tendon force)/dt = 0; 0.01 m/s faster stretches the tendon at 0.01 m/s."""
    p = mu.parameters(800.0, 0.1, 0.2, pennation_angle_at_optimal=0.25)
    a, l_norm = 0.7, 1.1
    height = 0.1 * math.sin(0.25)
    along = math.sqrt((0.1 * l_norm) ** 2 - height ** 2)
    cos_alpha = along / (0.1 * l_norm)
    force = cos_alpha * (a * mu.active_force_length(l_norm, 1.0) * mu.force_velocity(velocity)
                         + mu.passive_force_length(l_norm, 0.6))
    length = 0.2 * mu.tendon_force_length_inverse(force, 0.049) + along
    lengthening = velocity * 10.0 * 0.1 / cos_alpha
    pulled, rate = mu.compliant_tendon(a, force, length, lengthening, p)
    assert pulled == pytest.approx(800.0 * force, rel=1e-15)
    assert rate == pytest.approx(0.0, abs=1e-9)
    stiffness = mu.tendon_force_length_derivative(mu.tendon_force_length_inverse(force, 0.049), 0.049)
    assert mu.compliant_tendon(a, force, length, lengthening + 0.01, p)[1] == pytest.approx(
        0.01 / 0.2 * stiffness, rel=1e-9)


def test_parameters_have_opensims_defaults_and_bounds():
    p = mu.parameters(1000.0, 0.1, 0.2)
    assert dict(zip(mu.PARAMETERS, p)) == {"max_isometric_force": 1000.0, "optimal_fiber_length": 0.1,
                                           "tendon_slack_length": 0.2, **mu.DEFAULTS}
    for bad, says in (({"fiber_damping": -0.1}, "fiber_damping"), ({"pennation_angle_at_optimal": 1.6}, "pi/2"),
                      ({"active_force_width_scale": 0.9}, "active_force_width_scale"),
                      ({"activation_time_constant": 0.0}, "activation_time_constant"),
                      ({"tendon_strain": 0.05}, "unknown muscle parameter")):
        with pytest.raises(ValueError, match=says) as raised:
            mu.parameters(1000.0, 0.1, 0.2, **bad)
        assert "\n" not in str(raised.value)
    with pytest.raises(ValueError, match="optimal_fiber_length"):
        mu.parameters(1000.0, float("nan"), 0.2)
