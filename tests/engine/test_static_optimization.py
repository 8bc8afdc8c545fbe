"""Static optimisation (``fdbench inverse --muscles``): closed forms of one and two muscles across a
pin with a reserve, the KKT conditions over random problems, and arm26 against OpenSim's own
StaticOptimization (AnalyzeTool, in a child process) on the same motion, its muscles replaced by
De Groote muscles as fdbench's import maps them, the same reserves and a lower bound of 0."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from typer.testing import CliRunner

from helpers.paths import ROOT
from helpers.opensim_child import run_opensim
from fdbench.cli import app
from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.motions.named import MinimumJerk
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.multibody.static_optimization import box_qp, solve_sample, static_optimization

ARM26 = ROOT / "examples" / "opensim" / "arm26.osim"
runner = CliRunner()


# ---------------------------------------------------------------- closed forms and KKT


@pytest.mark.parametrize("arm, tau, reserve", [(0.03, 5.0, 1.0), (-0.02, -3.0, 0.5), (0.04, 8.0, 1e-4)])
def test_one_muscle_across_one_pin_takes_the_closed_form_share(arm, tau, reserve):
    """min a^2 + ((tau - k a) / rho)^2 with k = arm F: a = k tau / (rho^2 + k^2), inside (0, 1)."""
    active = 400.0
    k = arm * active
    a = solve_sample(np.array([[k]]), np.array([tau]), np.array([reserve]))
    assert a[0] == pytest.approx(k * tau / (reserve**2 + k * k), rel=1e-12)
    if reserve < 1e-3:  # no reserve to speak of: the activation solves arm * a F = tau
        assert a[0] == pytest.approx(tau / k, rel=1e-6)


def test_two_identical_muscles_share_equally():
    k, tau, rho = 12.0, 6.0, 1.0
    a = solve_sample(np.array([[k, k]]), np.array([tau]), np.array([rho]))
    np.testing.assert_allclose(a, k * tau / (rho**2 + 2 * k * k), rtol=1e-12)


def test_a_torque_beyond_the_muscle_saturates_it_and_the_reserve_takes_the_rest():
    a = solve_sample(np.array([[10.0]]), np.array([50.0]), np.array([1.0]))
    assert a[0] == 1.0


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 3), st.integers(1, 8), st.integers(0, 10**6), st.sampled_from([2.0, 3.0]))
def test_the_solution_meets_the_kkt_conditions(joints, muscles, seed, exponent):
    """The reduced objective's slope vanishes where 0 < a < 1, is >= 0 at 0 and <= 0 at 1."""
    rng = np.random.default_rng(seed)
    gain = rng.normal(0, 20.0, (joints, muscles))
    need, rho = rng.normal(0, 10.0, joints), rng.uniform(0.5, 2.0, joints)
    a = solve_sample(gain, need, rho, exponent)
    reserve = (need - gain @ a) / rho
    slope = exponent * (a ** (exponent - 1) - (gain / rho[:, None]).T @ (np.sign(reserve) * np.abs(reserve) ** (exponent - 1)))
    scale = 1e-7 * (1 + np.abs(gain).sum() * (1 + np.abs(reserve).max() ** (exponent - 1)))
    assert np.all((a >= 0) & (a <= 1))
    inside = (a > 1e-9) & (a < 1 - 1e-9)
    assert np.all(np.abs(slope[inside]) <= scale)
    assert np.all(slope[a <= 1e-9] >= -scale) and np.all(slope[a >= 1 - 1e-9] <= scale)


@settings(max_examples=20, deadline=None)
@given(st.integers(1, 8), st.integers(0, 10**6))
def test_the_active_set_method_equals_scipy_s_bounded_least_squares(muscles, seed):
    from scipy.optimize import lsq_linear

    rng = np.random.default_rng(seed)
    factor = rng.normal(0, 3.0, (muscles + 2, muscles))
    target = rng.normal(0, 3.0, muscles + 2)
    ours = box_qp(factor.T @ factor + 1e-3 * np.eye(muscles), factor.T @ target, rng.uniform(0, 1, muscles))
    theirs = lsq_linear(np.vstack([factor, np.sqrt(1e-3) * np.eye(muscles)]), np.concatenate([target, np.zeros(muscles)]),
                        bounds=(0, 1), method="bvls", tol=1e-14).x
    np.testing.assert_allclose(ours, theirs, atol=1e-8)


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize("args, words", [
    (["--muscles"], "has no muscles"),
    (["--model", "arm26", "--muscles", "--activation-exponent", "0"], "--activation-exponent must be > 0"),
    (["--model", "arm26", "--muscles", "--reserve-optimal-force", "-1"], "--reserve-optimal-force must be > 0"),
    (["--model", "arm26", "--activation-exponent", "3"], "--activation-exponent needs --muscles"),
])
def test_bad_static_optimization_input_is_one_line_and_exit_2(args, words):
    result = runner.invoke(app, ["inverse", *args])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and words in lines[0]


# ---------------------------------------------------------------- arm26 against OpenSim

OPENSIM_SO = """
model = osim.Model(request["model"])
osim.DeGrooteFregly2016Muscle.replaceMuscles(model)
for i in range(model.getMuscles().getSize()):
    model.updMuscles().get(i).setMinControl(0.0)  # arm26's Thelen muscles carry 0.01
for name in request["coordinates"]:
    reserve = osim.CoordinateActuator(name)
    reserve.setName(name + "_reserve")
    reserve.setOptimalForce(request["reserve"])
    reserve.setMinControl(-math.inf)
    reserve.setMaxControl(math.inf)
    model.addForce(reserve)
analysis = osim.StaticOptimization()
analysis.setStartTime(0.0)
analysis.setEndTime(request["end"])
analysis.setUseModelForceSet(True)
analysis.setUseMusclePhysiology(True)
analysis.setActivationExponent(2.0)
analysis.setConvergenceCriterion(1e-10)
analysis.setMaxIterations(1000)
model.addAnalysis(analysis)
model.finalizeConnections()
state = model.initSystem()
tool = osim.AnalyzeTool(model)
tool.setName("so")
tool.setModel(model)
tool.setCoordinatesFileName(request["motion"])
tool.setLowpassCutoffFrequency(-1)
tool.setInitialTime(0.0)
tool.setFinalTime(request["end"])
tool.setResultsDir(request["out"])
tool.setStatesFromMotion(state, osim.Storage(request["motion"]), True)
tool.run()
state = model.initSystem()  # OpenSim's paths at the motion's states, for the same problem on fdbench's side
coordinates = [model.getCoordinateSet().get(name) for name in request["coordinates"]]
muscles = [model.getMuscles().get(i) for i in range(model.getMuscles().getSize())]
lengths, arms, speeds = [], [], []
for q, u in zip(request["q"], request["u"]):
    for coordinate, value, speed in zip(coordinates, q, u):
        coordinate.setValue(state, value, False)
        coordinate.setSpeedValue(state, speed)
    model.realizeVelocity(state)
    lengths.append([m.getLength(state) for m in muscles])
    speeds.append([m.getLengtheningSpeed(state) for m in muscles])
    arms.append([[m.computeMomentArm(state, c) for c in coordinates] for m in muscles])
print(json.dumps({"lengths": lengths, "arms": arms, "speeds": speeds}))
"""


def _storage(path) -> tuple[list, np.ndarray]:
    lines = path.read_text().splitlines()
    start = lines.index("endheader")
    return lines[start + 1].split(), np.array([[float(x) for x in line.split()] for line in lines[start + 2:]])


@pytest.fixture(scope="module")
def opensim_so(tmp_path_factory):
    """arm26's motion mid_range written at 201 rows, OpenSim's static optimisation of it:
    (times (n,), activations (n, 6) and reserve controls (n, 2), OpenSim's column names)."""
    if importlib.util.find_spec("opensim") is None:
        pytest.skip("the opensim package is not installed (pip install 'fdbench[opensim]')")
    folder = tmp_path_factory.mktemp("so")
    model = find_model("arm26")
    motion = MinimumJerk(model.motions[0], model.coordinates)
    t = np.linspace(0.0, motion.duration, 201)
    z = np.degrees(motion(t)[0])
    rows = "\n".join("\t".join(f"{v:.12f}" for v in (ti, *zi)) for ti, zi in zip(t, z))
    (folder / "motion.mot").write_text(f"motion\nversion=1\nnRows={len(t)}\nnColumns=3\ninDegrees=yes\nendheader\n"
                                       f"time\t{chr(9).join(model.coordinates)}\n{rows}\n")
    q, u, _ = motion(t)
    request = {"model": str(ARM26), "coordinates": list(model.coordinates), "reserve": 1.0, "end": motion.duration,
               "motion": str(folder / "motion.mot"), "out": str(folder), "q": q.tolist(), "u": u.tolist()}
    paths = run_opensim(OPENSIM_SO, request, timeout=300, cwd=folder)
    names, table = _storage(folder / "so_StaticOptimization_activation.sto")
    _, forces = _storage(folder / "so_StaticOptimization_force.sto")
    np.testing.assert_allclose(table[:, 0], t, atol=1e-9)  # one row per row of the motion
    geometry = tuple(np.array(paths[key]) for key in ("lengths", "arms", "speeds"))
    # OpenSim's own inverse dynamics: its constraint, moment arms times its forces plus the reserves
    torque = np.einsum("nmj,nm->nj", geometry[1], forces[:, 1:7]) + forces[:, 7:9]
    return t, table[:, 1:7], table[:, 7:9], names[1:], geometry, torque


def test_arm26_activations_agree_with_opensim_s_static_optimization(opensim_so):
    t, theirs, their_reserves, names, _, _ = opensim_so
    model = find_model("arm26")
    body = Engine(model)
    motion = MinimumJerk(model.motions[0], model.coordinates)
    z, zd, zdd = motion(t)
    ours = static_optimization(model, body.muscle_params, t, z, zd, body.inverse_dynamics(z, zd, zdd, t),
                               along_tendon=False)  # OpenSim's DeGroote muscle's force (the next test)
    assert list(ours.muscles) == names[:6] and names[6:] == [f"{j}_reserve" for j in model.coordinates]
    worst = np.abs(ours.activation - theirs)
    # OpenSim's optimiser stops once off its optimum (t = 0.585 s: BRA 0.2, a 4.8 N m reserve); left out
    failed = np.abs(their_reserves[:, 0]) > 1.0
    assert failed.sum() <= 2
    per_muscle = worst[~failed].max(axis=0)
    # BIClong and TRIlong: fdbench's polynomial paths are within 15 mm of OpenSim's moment arms where it wraps
    # and its projection of the axes moves the torques by up to 0.08 N m: 0.029, 0.027, 0.037, 0.011 measured
    limits = {"TRIlong": 0.02, "TRIlat": 0.04, "TRImed": 0.04, "BIClong": 0.05, "BICshort": 0.02, "BRA": 0.02}
    assert all(per_muscle[i] < limits[m] for i, m in enumerate(ours.muscles)), dict(zip(ours.muscles, per_muscle))
    assert np.median(worst[~failed]) < 0.01
    np.testing.assert_allclose(ours.reserve[~failed], their_reserves[~failed], atol=0.05)


def test_on_opensim_s_paths_and_torques_the_activations_are_opensim_s(opensim_so):
    """The same problem as OpenSim's (its lengths, moment arms, lengthening speeds and inverse
    dynamics): what remains is the optimisers' tolerance and the curves (fdbench's equal OpenSim's)."""
    t, theirs, their_reserves, _, geometry, torque = opensim_so
    model = find_model("arm26")
    z, zd, _ = MinimumJerk(model.motions[0], model.coordinates)(t)
    params = Engine(model).muscle_params
    ours = static_optimization(model, params, t, z, zd, torque, geometry=geometry, along_tendon=False)
    failed = np.abs(their_reserves[:, 0]) > 1.0
    assert np.abs(ours.activation - theirs)[~failed].max() < 1e-4  # 5e-10 median
    np.testing.assert_allclose(ours.reserve[~failed], their_reserves[~failed], atol=1e-4)
    # OpenSim's DeGrooteFregly2016Muscle hands StaticOptimization its fibre's force, not times cos(alpha):
    # fdbench's force along the tendon asks more of the pennated triceps (pennation 0.157 rad)
    projected = static_optimization(model, params, t, z, zd, torque, geometry=geometry)
    pennated = (params[:, 3] > 0.1) & (theirs.max(axis=0) > 0.05)  # TRIlat and TRImed (TRIlong rests)
    assert pennated.sum() == 2 and np.mean((projected.activation - theirs)[~failed][:, pennated]) > 0.005


def test_the_csv_s_forces_and_reserves_meet_the_inverse_dynamics_torques(tmp_path):
    """``inverse --muscles -f csv`` on arm26 (every 50th ms): its muscle forces times the moment arms
    plus its reserves are the torques of plain ``inverse -f csv``; activations in [0, 1]."""
    import csv

    def table(*args):
        result = runner.invoke(app, ["inverse", "--model", "arm26", "--sample-dt", "0.05", "-f", "csv", *args])
        assert result.exit_code == 0, result.output
        rows = list(csv.reader(result.output.strip().splitlines()))
        return rows[0], np.array(rows[1:], dtype=float)

    header, so = table("--muscles")
    plain_header, plain = table()
    model = find_model("arm26")
    muscles, joints = [m.name for m in model.muscles], list(model.coordinates)
    assert header == ["t", *(f"{m}_{k}" for m in muscles for k in ("activation", "force")),
                      *(f"{j}_reserve" for j in joints)]
    np.testing.assert_array_equal(so[:, 0], plain[:, 0])
    angles = np.radians(plain[:, [plain_header.index(j) for j in joints]])
    torque = plain[:, [plain_header.index(f"{j}_torque") for j in joints]]
    _, arms = muscle_geometry(model, angles)
    force = so[:, [header.index(f"{m}_force") for m in muscles]]
    reserve = so[:, [header.index(f"{j}_reserve") for j in joints]]
    np.testing.assert_allclose(np.einsum("nmj,nm->nj", arms, force) + reserve, torque, atol=1e-9)
    activation = so[:, [header.index(f"{m}_activation") for m in muscles]]
    assert np.all((activation >= 0) & (activation <= 1)) and activation.max() > 0.5
