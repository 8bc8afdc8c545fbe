"""External loads from data (fdbench.multibody.loads) without OpenSim:

- a free body at rest under gravity and a vertical force at a point: the floating base's three
  generalised forces (the residuals FX, FY, MZ) are the closed form's, zero when the force balances
  the weight under the centre of mass;
- OpenSim's ExternalLoads file read on a model with a welded frame at an angle: forces and points
  expressed in a body's or the frame's axes land where a hand computation puts them;
- on random models with free and path joints, the loads' generalised forces are the virtual work
  of the force at the body's material point and of the free moment, by the independent
  minimal-coordinates reference (tests/helpers/reference_dynamics.GeneralTree);
- the simulation's mixed-coordinate loads (eq. 12) agree with inverse dynamics': under tau = ID
  with loads, the simulated accelerations are the motion's (to the penalty's 1/alpha);
- the data are interpolated linearly, a time outside their span refused.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import reference_dynamics as ref
from helpers.multibody_strategies import models_with_paths_and_free_joints
from helpers.dense_checks import leading_matrix, load_forces

from fdbench.files import BadFile
from fdbench.multibody.model import GROUND, Body, Frame, Joint, Model
from fdbench.multibody.engine import Engine
from fdbench.multibody.loads import ExternalLoad, ExternalLoads, read_external_loads
from fdbench.outcomes import residual_fields

G = 9.81


def rotate(angle: float, v) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def cross(a, b) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def constant_loads(loads, force, point, moment, span=(0.0, 1.0)) -> ExternalLoads:
    """Loads constant over ``span`` (s): force, point (L, 2) and moment (L,) at both ends."""
    twice = lambda v: np.repeat(np.asarray(v, dtype=float)[None], 2, axis=0)  # noqa: E731
    return ExternalLoads(tuple(loads), list(span), twice(force), twice(point), twice(moment))


# ---------------------------------------------------------------- a known force, a known residual


def free_box(mass=2.0, com=(0.1, 0.05), at_child=(-0.2, 0.1)) -> Model:
    """One body on a free joint (its joint point at_child, in its frame) under gravity (0, -G)."""
    return Model("box", (0.0, -G), (Body("box", mass, com, 0.05),),
                 (Joint("base", "free", GROUND, "box", (0.0, 0.0), at_child, coordinates=("tilt", "x", "y")),))


def test_a_vertical_force_on_a_free_body_at_rest_is_balanced_by_the_closed_form_residuals():
    """At rest, tau = -(gravity's and the load's generalised forces): FX = 0, FY = m g - F and
    MZ = m g (c - r)_x - F (P - r)_x - M about the base's joint point r; all zero when F = m g acts
    straight under the centre of mass c with no free moment. Over random poses, forces and points."""
    model = free_box()
    rng = np.random.default_rng(7)
    for case in range(20):
        tilt, x, y = rng.uniform(-3, 3), rng.uniform(-1, 1), rng.uniform(0, 2)
        r = np.array([x, y])
        c = r + rotate(tilt, np.subtract(model.bodies[0].com, model.joints[0].at_child))
        F, M = rng.uniform(0, 40), rng.uniform(-5, 5)
        P = c + rng.uniform(-0.3, 0.3, 2) if case % 2 else np.array([c[0], rng.uniform(-1, 1)])
        if case == 0:
            F, M = 2.0 * G, 0.0  # the weight, under the centre of mass
        engine = Engine(model, loads=constant_loads([ExternalLoad("push", "box")], [[0.0, F]], [P], [M]))
        tau = engine.inverse_dynamics([tilt, x, y], [0, 0, 0], [0, 0, 0], 0.5)
        m_g = 2.0 * G
        expected = [m_g * (c - r)[0] - F * (P - r)[0] - M, 0.0, m_g - F]
        np.testing.assert_allclose(tau, expected, rtol=1e-12, atol=1e-12)
        if case == 0:
            assert np.abs(tau).max() < 1e-12
        fields = residual_fields(model, tau[None])
        assert fields["residual_fy_mean_n"] == pytest.approx(m_g - F, abs=1e-12)
        assert fields["residual_mz_mean_nm"] == pytest.approx(expected[0], abs=1e-12)
        assert fields["residual_force_rms_n"] == pytest.approx(abs(m_g - F), abs=1e-12)


def test_a_free_body_falling_freely_needs_no_residual_and_one_held_by_the_load_needs_none_either():
    """z'' = gravity with no load: zero generalised forces; the same body held (z'' = 0) by a load
    equal to its weight at its centre of mass: zero too."""
    model = free_box()
    tilt, x, y = 0.4, 0.3, 1.1
    falling = Engine(model).inverse_dynamics([tilt, x, y], [0.0, 0.2, -0.5], [0.0, 0.0, -G])
    assert np.abs(falling).max() < 1e-12
    c = np.array([x, y]) + rotate(tilt, np.subtract(model.bodies[0].com, model.joints[0].at_child))
    held = Engine(model, loads=constant_loads([ExternalLoad("hold", "box")], [[0.0, 2.0 * G]], [c], [0.0]))
    assert np.abs(held.inverse_dynamics([tilt, x, y], [0.0, 0.2, -0.5], [0.0, 0.0, 0.0], 0.1)).max() < 1e-12


# ---------------------------------------------------------------- frames, from OpenSim's file format


def leg() -> Model:
    """thigh pinned to ground at (0, 1), shank pinned at the thigh's (0, -0.4) by its own (0, 0.05),
    a frame 'foot' fixed to the shank at (0.1, -0.4), its x axis 0.3 rad from the shank's."""
    bodies = (Body("thigh", 7.0, (0.0, -0.2), 0.1), Body("shank", 3.0, (0.0, -0.2), 0.05))
    joints = (Joint("hip", "pin", GROUND, "thigh", (0.0, 1.0), (0.0, 0.0)),
              Joint("knee", "pin", "thigh", "shank", (0.0, -0.4), (0.0, 0.05)))
    return Model("leg", (0.0, -G), bodies, joints, frames=(Frame("foot", "shank", (0.1, -0.4), 0.3),))


FORCES = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="30000"><ExternalLoads name="loads"><objects>
<ExternalForce name="in_foot"><applied_to_body>foot</applied_to_body>
<force_expressed_in_body>foot</force_expressed_in_body><point_expressed_in_body>foot</point_expressed_in_body>
<force_identifier>a_v</force_identifier><point_identifier>a_p</point_identifier>
<torque_identifier>a_t</torque_identifier></ExternalForce>
<ExternalForce name="mixed"><applied_to_body>shank</applied_to_body>
<force_expressed_in_body>ground</force_expressed_in_body><point_expressed_in_body>thigh</point_expressed_in_body>
<force_identifier>b_v</force_identifier><point_identifier>b_p</point_identifier></ExternalForce>
</objects><datafile>forces.mot</datafile></ExternalLoads></OpenSimDocument>
"""
COLUMNS = ("a_vx", "a_vy", "a_vz", "a_px", "a_py", "a_pz", "a_tx", "a_ty", "a_tz", "b_vx", "b_vy", "b_vz", "b_px",
           "b_py", "b_pz")
ROWS = {0.0: (10.0, 20.0, 99.0, 0.05, -0.02, 9.0, 7.0, 7.0, 1.5, -30.0, 5.0, 0.0, 0.02, -0.3, 0.0),
        2.0: (30.0, -20.0, 99.0, 0.15, 0.06, 9.0, 7.0, 7.0, -0.5, 10.0, 45.0, 0.0, -0.06, -0.1, 0.0)}


def write_loads(folder, xml: str = FORCES, columns=COLUMNS, rows=ROWS, datafile: str = "forces.mot"):
    """An ExternalLoads file and its storage file in ``folder``; the XML's path."""
    lines = ["forces", "version=1", f"nRows={len(rows)}", f"nColumns={len(columns) + 1}", "inDegrees=no", "endheader",
             "\t".join(("time",) + tuple(columns))]
    lines += ["\t".join(map(repr, (t,) + tuple(values))) for t, values in rows.items()]
    (folder / datafile).write_text("\n".join(lines) + "\n")
    (folder / "loads.xml").write_text(xml)
    return folder / "loads.xml"


def test_loads_in_a_welded_frame_at_an_angle_and_in_another_body_s_frame_are_where_a_hand_computation_puts_them(
        tmp_path):
    """At t = 0.5 s (a quarter of the way between the samples, linear): the first force and point in
    the foot frame's axes (angle phi_shank + 0.3, origin on the shank), its torque about z only; the
    second force in ground's axes at a point of the thigh's frame, applied to the shank. The hip's
    and knee's generalised forces are (P - r) x F + M summed over the loads, r each joint's point."""
    model = leg()
    loads = read_external_loads(write_loads(tmp_path), model)
    assert [(x.body, x.force_frame, x.point_frame) for x in loads.loads] == [("shank", "shank", "shank"),
                                                                            ("shank", GROUND, "thigh")]
    engine = Engine(model, loads=loads)
    mix = lambda k: 0.75 * np.array(ROWS[0.0])[k] + 0.25 * np.array(ROWS[2.0])[k]  # noqa: E731
    rng = np.random.default_rng(3)
    for _ in range(10):
        q1, q2 = rng.uniform(-2, 2, 2)
        thigh, shank = q1, q1 + q2
        hip = np.array([0.0, 1.0])
        knee = hip + rotate(thigh, (0.0, -0.4))
        shank_origin = knee - rotate(shank, (0.0, 0.05))
        foot_origin, foot_angle = shank_origin + rotate(shank, (0.1, -0.4)), shank + 0.3
        F1 = rotate(foot_angle, mix([0, 1]))
        P1 = foot_origin + rotate(foot_angle, mix([3, 4]))
        M1 = mix(8)
        F2, P2 = mix([9, 10]), hip + rotate(thigh, mix([12, 13]))
        expected = [cross(P1 - hip, F1) + M1 + cross(P2 - hip, F2), cross(P1 - knee, F1) + M1 + cross(P2 - knee, F2)]
        np.testing.assert_allclose(load_forces(engine, [q1, q2], 0.5), expected,
                                   rtol=1e-12, atol=1e-12)


def test_a_force_without_a_point_acts_at_the_origin_of_the_body_or_frame_it_is_applied_to(tmp_path):
    """As OpenSim's ExternalForce: no <point_identifier>, the force acts at the origin of the body
    it is applied to, here the welded frame 'foot' (its origin on the shank)."""
    xml = FORCES.replace("<point_identifier>a_p</point_identifier>", "")
    model = leg()
    loads = read_external_loads(write_loads(tmp_path, xml=xml), model)
    assert (loads.loads[0].point_frame, tuple(loads.point[0, 0])) == ("shank", (0.1, -0.4))
    engine = Engine(model, loads=loads)
    q1, q2 = 0.7, -1.1
    hip = np.array([0.0, 1.0])
    knee = hip + rotate(q1, (0.0, -0.4))
    foot_origin = knee - rotate(q1 + q2, (0.0, 0.05)) + rotate(q1 + q2, (0.1, -0.4))
    F1, M1 = rotate(q1 + q2 + 0.3, ROWS[0.0][:2]), ROWS[0.0][8]
    F2, P2 = np.array(ROWS[0.0][9:11]), hip + rotate(q1, ROWS[0.0][12:14])
    expected = [cross(foot_origin - hip, F1) + M1 + cross(P2 - hip, F2),
                cross(foot_origin - knee, F1) + M1 + cross(P2 - knee, F2)]
    np.testing.assert_allclose(load_forces(engine, [q1, q2], 0.0), expected, rtol=1e-12)


# ---------------------------------------------------------------- random models against the reference


def frames_of(tree: ref.GeneralTree, z) -> tuple[list, list]:
    """Per joint (the order of the engine's bodies): the body's angle (rad) and origin (2,) at z."""
    angle, origin = tree._frames([ref.Jet(value) for value in z])
    return [a.a[0] for a in angle], [np.array([o[0].a[0], o[1].a[0]]) for o in origin]


def virtual_work(tree: ref.GeneralTree, z, body: int, P, F, M) -> np.ndarray:
    """The generalised forces (J,) of a force F at the world point P (taken as a material point of
    ``body``) and a moment M: F . dP/dz + M dphi/dz, the derivatives by the reference's jets."""
    angle, origin = frames_of(tree, z)
    local = rotate(-angle[body], np.asarray(P) - origin[body])
    out = np.zeros(len(z))
    for j in range(len(z)):
        jets_angle, jets_origin = tree._frames([ref.Jet(value, float(i == j)) for i, value in enumerate(z)])
        arm = ref.jet_rotate(jets_angle[body], local)
        dP = np.array([(jets_origin[body][0] + arm[0]).a[1], (jets_origin[body][1] + arm[1]).a[1]])
        out[j] = F @ dP + M * jets_angle[body].a[1]
    return out


@settings(max_examples=25, deadline=None)
@given(model=models_with_paths_and_free_joints(max_bodies=4), seed=st.integers(0, 2**16))
def test_the_loads_generalised_forces_are_their_virtual_work_on_random_models(model, seed):
    """Two loads on random bodies, their forces and points in ground's or random bodies' axes:
    the compiled eq. 3's loads (at rest, without gravity) are the reference's virtual work, frames
    resolved by hand."""
    rng = np.random.default_rng(seed)
    names = [joint.child for joint in model.joints]
    frame = lambda: GROUND if rng.random() < 0.3 else str(rng.choice(names))  # noqa: E731
    loads = [ExternalLoad(f"l{k}", str(rng.choice(names)), frame(), frame()) for k in range(2)]
    force, point, moment = rng.uniform(-50, 50, (2, 2)), rng.uniform(-0.5, 0.5, (2, 2)), rng.uniform(-5, 5, 2)
    data = constant_loads(loads, force, point, moment)
    engine = Engine(model, loads=data)
    tree = ref.GeneralTree(model)
    z = rng.uniform(-1.0, 0.15, engine.n_joints)
    angle, origin = frames_of(tree, z)
    expected = np.zeros(engine.n_joints)
    for k, load in enumerate(loads):
        F, P = force[k], point[k]
        if load.force_frame != GROUND:
            F = rotate(angle[names.index(load.force_frame)], F)
        if load.point_frame != GROUND:
            b = names.index(load.point_frame)
            P = origin[b] + rotate(angle[b], P)
        expected += virtual_work(tree, z, names.index(load.body), P, F, moment[k])
    ours = load_forces(engine, z, 0.3)
    np.testing.assert_allclose(ours, expected, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(expected).max()))


@settings(max_examples=10, deadline=None)
@given(model=models_with_paths_and_free_joints(max_bodies=3), seed=st.integers(0, 2**16))
def test_under_inverse_dynamics_torques_with_loads_the_simulation_keeps_the_motion(model, seed):
    """tau = ID(z, z', z'', t) with loads, then eq. 12 (its loads in mixed coordinates) at the state
    of (z, z') and time t: the accelerations are z'' up to the penalty's error, which shrinks as
    1/alpha; without the loads in eq. 12 they are not."""
    rng = np.random.default_rng(seed)
    names = [joint.child for joint in model.joints]
    loads = [ExternalLoad(f"l{k}", str(rng.choice(names)), str(rng.choice(names + [GROUND])),
                          str(rng.choice(names + [GROUND]))) for k in range(2)]
    t = np.array([0.0, 0.4, 1.0])
    force, point = rng.uniform(-40, 40, (3, 2, 2)), rng.uniform(-0.4, 0.4, (3, 2, 2))
    moment = rng.uniform(-4, 4, (3, 2))
    data = ExternalLoads(tuple(loads), t, force, point, moment)
    J = Engine(model).n_joints
    z, zd, zdd = rng.uniform(-1.0, 0.15, J), rng.uniform(-2, 2, J), rng.uniform(-10, 10, J)
    when = rng.uniform(0.0, 1.0)
    errors = []
    for alpha in (1e5, 1e7):
        engine = Engine(model, alpha=alpha, loads=data)
        tau = engine.inverse_dynamics(z, zd, zdd, when)
        y = engine.state_from_joints(z, zd)
        zero = np.zeros((1, J))
        rate, _ = engine.rates(y[None], tau[None], zero, zero, zero, 0.0, 0.0, t=[when])
        errors.append(np.abs(engine.joints_from_state(rate[0])[1] - zdd).max() / max(1.0, np.abs(zdd).max()))
        rounding = 1e-14 * np.linalg.cond(leading_matrix(engine, y))
    # loads of up to 40 N on bodies of 1 kg: the penalty's error at 1e7 reaches several percent, and
    # falls as 1/alpha (a factor 100 here, 30 asked for)
    assert errors[1] < errors[0] / 30 or errors[1] < rounding, (errors, rounding)
    bare = Engine(model, alpha=1e7)  # the same torques without the loads in eq. 12
    y = bare.state_from_joints(z, zd)
    tau = Engine(model, alpha=1e7, loads=data).inverse_dynamics(z, zd, zdd, when)
    zero = np.zeros((1, J))
    rate, _ = bare.rates(y[None], tau[None], zero, zero, zero, 0.0, 0.0)
    loads_q = load_forces(Engine(model, loads=data), z, when)
    if np.abs(loads_q).max() > 1e-3 * max(1.0, np.abs(tau).max()):
        assert np.abs(bare.joints_from_state(rate[0])[1] - zdd).max() > 10 * errors[1] * max(1.0, np.abs(zdd).max())


# ---------------------------------------------------------------- interpolation


def test_the_data_are_interpolated_linearly_and_a_time_outside_them_is_refused():
    t = np.array([1.0, 1.5, 3.0])
    force = np.array([[[0.0, 10.0]], [[5.0, 20.0]], [[-1.0, 0.0]]])
    point, moment = force * 0.01, force[:, :, 0] * 2
    data = ExternalLoads((ExternalLoad("f", "b"),), t, force, point, moment)
    f, p, m = data.at([1.0, 1.25, 1.5, 2.0, 3.0])
    np.testing.assert_allclose(f[:, 0], [[0, 10], [2.5, 15], [5, 20], [3, 40 / 3], [-1, 0]], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(p, f * 0.01, rtol=1e-14)
    np.testing.assert_allclose(m, f[:, :, 0] * 2, rtol=1e-14)
    for outside in ([0.99], [1.2, 3.01]):
        with pytest.raises(ValueError, match="cover 1 to 3 s"):
            data.at(outside)
    shifted = data.shifted(1.0)  # the motion's time 0 is the file's 1 s
    np.testing.assert_allclose(shifted.at([0.25])[0], data.at([1.25])[0], rtol=1e-15)


@pytest.mark.parametrize("t, problem", [([0.0, 0.0], "increasing"), ([0.0], "at least two")])
def test_loads_need_increasing_times(t, problem):
    n = len(t)
    with pytest.raises(ValueError, match=problem):
        ExternalLoads((ExternalLoad("f", "b"),), t, np.zeros((n, 1, 2)), np.zeros((n, 1, 2)), np.zeros((n, 1)))


def test_a_missing_column_and_an_unknown_body_are_refused_in_one_line(tmp_path):
    model = leg()
    with pytest.raises(BadFile, match=r"no column 'b_py'"):
        read_external_loads(write_loads(tmp_path, columns=COLUMNS[:13] + ("b_pz", "extra")), model)
    with pytest.raises(BadFile, match=r"applied_to_body.*'calf'.*(shank|thigh|foot)"):
        xml = FORCES.replace("<applied_to_body>shank", "<applied_to_body>calf")
        read_external_loads(write_loads(tmp_path, xml=xml), model)
