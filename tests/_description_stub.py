"""A stand-in for ``fdbench.multibody.description`` (the model description's dataclasses), so that the
multibody tests can build models before that module exists: the same names, fields and helpers.
Tests import the types through ``model_types()``, which returns the real module when it is
importable and this one otherwise; nothing here is used once the real module is in place.

Planar trees of pin joints, SI units, angles in rad. A body's frame angle (from world +x,
counter-clockwise) is the sum of (coordinate + offset) over the joints on its path from ground; a
joint's point is parent origin + R(parent angle) at_parent = child origin + R(child angle) at_child.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

GROUND = "ground"


@dataclass(frozen=True)
class Body:
    name: str
    mass: float  # kg, > 0
    com: tuple[float, float]  # m, centre of mass in the body's frame
    inertia: float  # kg m^2 about the centre of mass (z axis), > 0
    end: tuple[float, float] | None = None  # m, the body's second point of natural coordinates


@dataclass(frozen=True)
class Joint:
    name: str  # the coordinate's name
    type: str  # "pin"
    parent: str  # a body name or GROUND
    child: str  # a body name
    at_parent: tuple[float, float]  # m, the joint in the parent's frame (world axes for ground)
    at_child: tuple[float, float]  # m, the joint in the child's frame
    offset: float = 0.0  # rad: child frame angle relative to the parent's when the coordinate is 0
    limits: tuple[float, float] | None = None  # rad, informative


@dataclass(frozen=True)
class Load:
    body: str
    at: tuple[float, float]  # m, in the body's frame
    force: tuple[float, float]  # N, world axes


@dataclass(frozen=True)
class Model:
    name: str
    gravity: tuple[float, float]  # m/s^2, world axes (x forward, y up)
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]  # topological order
    loads: tuple[Load, ...] = ()

    @property
    def coordinates(self) -> tuple[str, ...]:
        """The joint names in order."""
        return tuple(joint.name for joint in self.joints)

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def body(self, name: str) -> Body:
        return next(body for body in self.bodies if body.name == name)

    def parent_joint(self, body_name: str) -> Joint:
        return next(joint for joint in self.joints if joint.child == body_name)

    def path(self, body_name: str) -> tuple[int, ...]:
        """Indices of the joints from ground to the body, ground first."""
        index = {joint.child: k for k, joint in enumerate(self.joints)}
        path = []
        while body_name != GROUND:
            k = index[body_name]
            path.append(k)
            body_name = self.joints[k].parent
        return tuple(reversed(path))


def resolved_end(model: Model, body_name: str) -> tuple[float, float]:
    """The body's second point (m, body frame): its ``end``, else the at_parent of its first child
    joint, else its farthest load point (from at_child), else its com, else at_child + (1 m, 0); a
    load or com closer than 1 mm to at_child is passed over."""
    body = model.body(body_name)
    if body.end is not None:
        return body.end
    first = next((joint for joint in model.joints if joint.parent == body_name), None)
    if first is not None:
        return first.at_parent
    at_child = model.parent_joint(body_name).at_child
    loads = [load.at for load in model.loads if load.body == body_name]
    if loads and max(math.dist(at, at_child) for at in loads) >= 1e-3:
        return max(loads, key=lambda at: math.dist(at, at_child))
    if math.dist(body.com, at_child) >= 1e-3:
        return body.com
    return (at_child[0] + 1.0, at_child[1])


def model_types():
    """The module holding the description's types: ``fdbench.multibody.description`` when it can be
    imported, else this stand-in."""
    try:
        from fdbench.multibody import description
    except ImportError:
        import sys

        return sys.modules[__name__]
    return description
