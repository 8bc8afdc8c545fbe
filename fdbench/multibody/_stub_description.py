"""A stand-in for ``fdbench.multibody.description`` (the model description) with its exact
interface: the dataclasses and ``resolved_end``, without file parsing or validation. The engine
imports the description through ``fdbench.multibody.engine`` only, which prefers the real module."""

from __future__ import annotations

import math
from dataclasses import dataclass

GROUND = "ground"


@dataclass(frozen=True)
class Body:
    name: str
    mass: float  # kg
    com: tuple  # m, in the body's frame
    inertia: float  # kg m^2 about the centre of mass
    end: tuple | None = None  # m, the body's second point of natural coordinates


@dataclass(frozen=True)
class Joint:
    name: str
    type: str
    parent: str
    child: str
    at_parent: tuple  # m, in the parent's frame (world axes for ground)
    at_child: tuple  # m, in the child's frame
    offset: float = 0.0  # rad
    limits: tuple | None = None


@dataclass(frozen=True)
class Load:
    body: str
    at: tuple  # m, in the body's frame
    force: tuple  # N, world axes


@dataclass(frozen=True)
class Model:
    name: str
    gravity: tuple
    bodies: tuple
    joints: tuple
    loads: tuple = ()

    @property
    def coordinates(self) -> tuple:
        return tuple(joint.name for joint in self.joints)

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def body(self, name: str) -> Body:
        return next(body for body in self.bodies if body.name == name)

    def parent_joint(self, body_name: str) -> Joint:
        return next(joint for joint in self.joints if joint.child == body_name)

    def path(self, body_name: str) -> tuple:
        indices = []
        while body_name != GROUND:
            joint = self.parent_joint(body_name)
            indices.append(self.joints.index(joint))
            body_name = joint.parent
        return tuple(reversed(indices))


def resolved_end(model: Model, body_name: str) -> tuple:
    """The body's second point (m, body frame): its ``end``, else the at_parent point of its first
    child joint, else its farthest load's point, else its com (if at least 1 mm from the joint
    point), else the joint point + (1 m, 0)."""
    body = model.body(body_name)
    if body.end is not None:
        return tuple(body.end)
    for joint in model.joints:
        if joint.parent == body_name:
            return tuple(joint.at_parent)
    origin = model.parent_joint(body_name).at_child
    loads = [load.at for load in model.loads if load.body == body_name]
    if loads:
        return tuple(max(loads, key=lambda at: math.dist(at, origin)))
    if math.dist(body.com, origin) >= 1e-3:
        return tuple(body.com)
    return (origin[0] + 1.0, origin[1])
