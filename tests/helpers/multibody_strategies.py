"""Model descriptions for the multibody tests: the built-in forearm and arm written in the
description (``forearm_model``, ``arm2_model``), and hypothesis strategies for random valid models
(planar chains and trees of 1 to 6 bodies on pin joints) and random joint states and motions.

Each body is a segment of length 0.05 to 1 m, in any direction in its own frame, starting at its
joint point (at_child, anywhere near the frame's origin); its centre of mass anywhere on or off the
segment; masses 0.1 to 20 kg, inertias 1e-4 to 2 kg m^2 about the centre of mass, joint offsets in
(-pi, pi). A child's joint sits at the parent's far end, or elsewhere on the parent; several bodies
may share a parent, ground included. Loads are constant world-axis forces up to 50 N at body points.
Gravity (0, -9.81). Away from singular geometry: every body's two natural-coordinate points (its
joint point and its end, given or resolved by default) are at least MIN_END = 5 cm apart, as a
segment's length is (a body's end is its tip where its default would fall nearer).

Shrinking leads to the simplest failing model: fewer bodies, a chain (each parent the previous
body), joints at the parent's far end, no offsets, no loads, segments along the frame's x axis.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st

from fdbench.multibody import model as d

ANGLE = st.floats(-math.pi, math.pi)


MIN_END = 0.05  # m: every body's natural-coordinate points at least this far apart


def _along(at_child, length, direction, u, v, least=0.0):
    """The body-frame point at_child + length R(direction) (u, v) (m): u along the segment, v across;
    moved out along the same line to at least ``least`` (m) from at_child."""
    reach = length * math.hypot(u, v)
    if reach < least:
        u, v = u * least / reach, v * least / reach
    c, s = math.cos(direction), math.sin(direction)
    return (at_child[0] + length * (c * u - s * v), at_child[1] + length * (s * u + c * v))


def _pair(low, high):
    return st.tuples(st.floats(low, high), st.floats(low, high))


def forearm_model():
    """The forearm as a model description (Table 1, F_ext 15 N at the hand)."""
    return d.Model(name="forearm", gravity=(0.0, -9.81),
                   bodies=(d.Body("forearm", mass=1.0, com=(0.11, 0.0), inertia=0.04 - 1.0 * 0.11**2),),
                   joints=(d.Joint("theta", "pin", d.GROUND, "forearm", (0.0, 0.0), (0.0, 0.0)),),
                   loads=(d.Load("forearm", at=(0.33, 0.0), force=(0.0, -15.0)),))


def arm2_model(**changes):
    """The description of the two-segment arm of tests/arm2_closed_form.py with some of its
    constants changed (its inertias I0, I1 are about the joints)."""
    from types import SimpleNamespace

    from helpers.arm2_closed_form import ARM2

    arm = SimpleNamespace(**{**ARM2, **changes})
    upper = d.Body("upper_arm", mass=arm.m0, com=(arm.L0G, 0.0), inertia=arm.I0 - arm.m0 * arm.L0G**2)
    fore = d.Body("forearm", mass=arm.m, com=(arm.L1G, 0.0), inertia=arm.I1 - arm.m * arm.L1G**2)
    return d.Model(name="arm2", gravity=(0.0, -arm.g), bodies=(upper, fore),
                   joints=(d.Joint("shoulder", "pin", d.GROUND, "upper_arm", (0.0, 0.0), (0.0, 0.0)),
                           d.Joint("elbow", "pin", "upper_arm", "forearm", (arm.L01, 0.0), (0.0, 0.0))),
                   loads=(d.Load("forearm", at=(arm.L12, 0.0), force=(0.0, -arm.F_ext)),))


@st.composite
def models(draw, min_bodies: int = 1, max_bodies: int = 6, chain: bool = False):
    """A valid Model: a tree (each body the child of ground or of any earlier body), or a chain
    (each body the child of the previous one)."""
    n = draw(st.integers(min_bodies, max_bodies))
    bodies, joints, segments = [], [], []
    for i in range(n):
        back = 0 if chain or i == 0 else draw(st.integers(0, i))  # 0: the previous body
        parent = i - 1 - back  # -1: ground
        length = draw(st.floats(0.05, 1.0))
        direction = draw(ANGLE)  # of the segment in the body's frame
        at_child = draw(_pair(-0.2, 0.2))
        com = _along(at_child, length, direction, draw(st.floats(-0.5, 1.5)), draw(st.floats(-0.5, 0.5)))
        tip = _along(at_child, length, direction, 1.0, 0.0)
        end = tip if draw(st.booleans()) else None
        bodies.append(d.Body(name=f"b{i}", mass=draw(st.floats(0.1, 20.0)), com=com,
                                 inertia=draw(st.floats(1e-4, 2.0)), end=end))
        if parent < 0:
            at_parent = draw(_pair(-0.5, 0.5))
        elif draw(st.booleans()):  # elsewhere on the parent
            p_child, p_length, p_direction, _ = segments[parent]
            at_parent = _along(p_child, p_length, p_direction, draw(st.floats(0.1, 1.0)), draw(st.floats(-0.3, 0.3)),
                               MIN_END)
        else:
            at_parent = segments[parent][3]
        joints.append(d.Joint(name=f"q{i}", type="pin", parent="ground" if parent < 0 else f"b{parent}",
                                  child=f"b{i}", at_parent=at_parent, at_child=at_child, offset=draw(ANGLE)))
        segments.append((at_child, length, direction, tip))
    loads = []
    for _ in range(draw(st.integers(0, 2))):
        k = draw(st.integers(0, n - 1))
        at_child, length, direction, _ = segments[k]
        at = _along(at_child, length, direction, draw(st.floats(0.1, 1.2)), draw(st.floats(-0.3, 0.3)), MIN_END)
        loads.append(d.Load(body=f"b{k}", at=at, force=draw(_pair(-50.0, 50.0))))
    model = d.Model(name="random", gravity=(0.0, -9.81), bodies=tuple(bodies), joints=tuple(joints),
                    loads=tuple(loads))
    return _with_distinct_ends(model, [segment[3] for segment in segments])


def _with_distinct_ends(model, tips):
    """The model with end = tip for the bodies whose default end (their centre of mass, for a leaf
    without loads) would lie closer than MIN_END to their joint point."""
    import dataclasses

    bodies = list(model.bodies)
    for k, joint in enumerate(model.joints):
        end = d.resolved_end(model, joint.child)
        if math.dist(end, joint.at_child) < MIN_END:
            bodies[k] = dataclasses.replace(bodies[k], end=tips[k])
    return dataclasses.replace(model, bodies=tuple(bodies))


def vectors(n: int, bound: float):
    """Arrays (n,) of floats in [-bound, bound]."""
    return st.lists(st.floats(-bound, bound), min_size=n, max_size=n).map(np.array)


def joint_states(n: int, max_rate: float = 5.0, max_acceleration: float = 50.0):
    """(z, z', z'') for n joints: angles anywhere in (-pi, pi) rad, rates up to max_rate rad/s,
    accelerations up to max_acceleration rad/s^2. In minimal coordinates a tree of pin joints has no
    singular configuration (M(z) is positive definite everywhere), and the models' natural-coordinate
    points are at least MIN_END apart, so every angle is a fair test."""
    return st.tuples(vectors(n, math.pi), vectors(n, max_rate), vectors(n, max_acceleration))


@st.composite
def models_and_states(draw, max_bodies: int = 6):
    """(model, (z, z', z'')) for a random tree or chain."""
    model = draw(models(max_bodies=max_bodies))
    return model, draw(joint_states(len(model.joints)))


@st.composite
def models_and_motions(draw, max_bodies: int = 6):
    """(model, (c, a, f, p)) for a random tree or chain and a sinusoidal motion of its joints."""
    model = draw(models(max_bodies=max_bodies))
    return model, draw(sinusoids(len(model.joints)))


@st.composite
def sinusoids(draw, n: int):
    """A smooth reference motion per joint, ref_j(t) = c_j + a_j sin(2 pi f_j t + p_j): returns the
    arrays (c, a, f, p) of shape (n,) (rad, rad, Hz, rad), amplitudes up to 0.5 rad, 0.5 to 2 Hz."""
    centre = draw(vectors(n, math.pi))
    amplitude = draw(st.lists(st.floats(0.0, 0.5), min_size=n, max_size=n).map(np.array))
    frequency = draw(st.lists(st.floats(0.5, 2.0), min_size=n, max_size=n).map(np.array))
    phase = draw(vectors(n, math.pi))
    return centre, amplitude, frequency, phase


@st.composite
def joint_paths(draw):
    """A joint's path: 2 to 8 samples, angles strictly increasing in [-3, 3] rad (at least 0.05 rad
    apart), x and y within 5 cm."""
    def knots(n):
        gaps = draw(st.lists(st.floats(0.05, 1.0), min_size=n - 1, max_size=n - 1))
        return tuple(float(a) for a in np.cumsum([draw(st.floats(-3.0, -1.0))] + gaps))

    n, m = draw(st.integers(2, 8)), draw(st.integers(2, 8))
    coordinate = st.floats(-0.05, 0.05)
    y_angles = knots(m) if draw(st.booleans()) else None  # y's own angles (OpenSim's knee)
    return d.JointPath(knots(n), tuple(draw(coordinate) for _ in range(n)),
                       tuple(draw(coordinate) for _ in range(n if y_angles is None else m)), y_angles)


@st.composite
def models_with_paths_and_free_joints(draw, max_bodies: int = 5):
    """A random model of ``models`` whose joints on ground are free (with some chance, the first
    always) and whose other joints have paths (with some chance, at least one when there is one)."""
    import dataclasses

    model = draw(models(min_bodies=2, max_bodies=max_bodies))
    joints = list(model.joints)
    for k, joint in enumerate(joints):
        if joint.parent == d.GROUND and (k == 0 or draw(st.booleans())):
            joints[k] = dataclasses.replace(joint, type="free", coordinates=(f"a{k}", f"x{k}", f"y{k}"))
        elif joint.parent != d.GROUND and draw(st.booleans()) or k == len(joints) - 1:
            joints[k] = dataclasses.replace(joint, path=draw(joint_paths()))
    return dataclasses.replace(model, joints=tuple(joints))
