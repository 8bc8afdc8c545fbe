"""A planar multibody model as data: bodies, joints and constant point loads, in SI units with
angles in radians and translations in m, and its checks (``model_from_dict``: the keys of a TOML
or JSON model file, read by ``fdbench.multibody.model_files``; changed by
``fdbench.multibody.model_changes``; found by name or file by ``fdbench.models.find_model``).

The model is a tree rooted at ``ground``: every body is the child of exactly one joint; a joint's
parent is ground or a body. A joint's angle is the child frame's angle relative to its parent
frame minus the joint's ``offset``, so a body's frame angle (from world +x, counter-clockwise) is
the sum of (angle + offset) over the joints on its path from ground. The joint's torque acts on
the child (+) and the parent (-): it is the generalised force of its angle. World axes: x forward,
y up. Joint types:

* ``pin`` (the default): one coordinate, the angle, named by the joint's ``name``. With a
  ``path`` table (``angles`` rad strictly increasing, ``x``, ``y`` m of the same length, 2 to
  1000 samples; ``y_angles``: y's own angles) the child's point sits at at_parent + (x(angle),
  y(angle)) in the parent's frame, on OpenSim's SimmSpline through the samples
  (``fdbench.multibody.spline``): OpenSim's knee.
* ``free`` (parent ground only): three coordinates named by ``coordinates``, [angle, x, y]: the
  child's angle as a pin's, and its point at_child at at_parent + (x, y) (m, world axes): OpenSim's
  planar pelvis. The generalised forces of x and y are forces (N) on that point.

``Model.coordinates`` lists every coordinate in joint order, ``Model.coordinate_kinds`` says
which is an angle (rad) and which a translation (m).

Choices made here (documented in the README's "Your own model"):

* Names of bodies and joints share one namespace, compared ignoring case (a joint's name is a
  column of motion and torque files, whose headers are case-insensitive, and ``NAME.key`` paths of
  ``with_changes`` must not be ambiguous). A name is a letter then letters, digits or ``_``;
  ``ground`` is reserved, a joint may not be called ``t`` (the time column) nor end in a suffix
  that trajectory files add to a joint's name (``_vel``, ``_acc``, ...).
* Misspelt keys are errors, not ignored. Every problem is a ``ModelError``: one line naming the
  file, the key path (``bodies[1].mass``) and what is allowed.
* The joints are put in topological order (a file may list them in any order); the sort is
  stable: among the joints whose parent is placed, the earliest in the file comes first, so
  siblings keep their file order.
* A body's ``end`` (its second point of natural coordinates, the first being its joint point) is
  resolved by ``resolved_end``. The at_parent point of a body's first child joint, or an explicit
  ``end``, closer than 1 mm to the body's joint point is an error (a segment of zero length: most
  likely a mistyped joint position); a load or centre of mass that close is passed over for the
  next default.
* ``[[motions]]`` (optional) names motions of the model, the first its default: ``name``,
  ``type`` ('minimum-jerk', the default: z0 + (z1 - z0)(10u^3 - 15u^4 + 6u^5), u = t /
  duration, from rest to rest, with ``duration`` (s, at least 0.01), ``start`` and ``goal``
  (tables {joint = angle}, rad, naming every joint and no other); or 'eq5-paper', 'eq5-exact':
  the paper's eq. 5 of a one-angle model, its span fixed (``fdbench.multibody.motions.eq5``).
* ``[[muscles]]`` (optional): Hill-type muscles, their constants and paths (points fixed to bodies
  or a polynomial length), read, checked and written by ``fdbench.multibody.muscles``; their
  lengths and moment arms are ``fdbench.multibody.muscle_paths``.
* ``[[actuators]]`` (optional): torque actuators, one per coordinate at most, with their optimal
  force, read, checked and written by ``fdbench.multibody.actuators`` (what they change is said there).
* ``[keys]`` (optional) maps short names (``--model KEY=VALUE``) to targets ``[-]path[@joint]``:
  a path of ``with_changes``, '-' for its negative (``F_ext = "-loads[0].force.y"``), and after
  ``<body>.inertia`` an ``@<joint>`` of the body for the inertia about the joint's point (inertia +
  mass |com - point|^2), which stays when a short key changes the body's mass or centre of mass
  (``with_short_keys``).
"""
from __future__ import annotations

import heapq
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

from ..files import quoted
from ..registry import unknown_name_message
from .actuators import Actuator, actuator_dict, read_actuators
from .muscles import Muscle, muscle_dict, read_muscles
from .spline import fit

GROUND = "ground"

MAX_MAGNITUDE = 1e6  # any number of a model file, in its unit
MAX_BODIES = 1000  # bodies, joints or loads of one model
MAX_FILE_BYTES = 2**20  # a model file
MIN_SEGMENT = 1e-3  # m: a body's end point is at least this far from its joint point
MIN_MOTION_DURATION = 0.01  # s: a named motion spans at least ten samples of its 1 ms grid
JOINT_TYPES = ("pin", "free")
ANGLE, TRANSLATION = "angle", "translation"  # the kinds of coordinates (rad, m)
MAX_PATH_SAMPLES = 1000  # samples of a joint's path
RESERVED_SUFFIXES = ("_vel", "_acc", "_torque", "_desired", "_inverse")  # columns made from a joint's name
NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}")


class ModelError(ValueError):
    """A model description that cannot be used: ``source: key: problem``, one line."""

    def __init__(self, source: str, key: str, problem: str):
        self.source, self.key, self.problem = source, key, problem
        super().__init__(f"{source}: {key}: {problem}" if key else f"{source}: {problem}")


@dataclass(frozen=True)
class Body:
    """A rigid body: mass (kg), centre of mass in its frame (m), inertia about the centre of mass
    (kg m^2) and optionally its second point of natural coordinates (m, in its frame)."""

    name: str
    mass: float
    com: tuple[float, float]
    inertia: float
    end: tuple[float, float] | None = None


@dataclass(frozen=True)
class JointPath:
    """The path of a joint's point in its parent's frame: at the coordinate ``angles[i]`` (rad,
    strictly increasing) the child's point sits at at_parent + (x[i], y[i]) (m), in between on
    OpenSim's SimmSpline through the samples (``fdbench.multibody.spline``), beyond them on its end
    slopes. ``y_angles``: y's own angles where they differ from x's (OpenSim's knee)."""

    angles: tuple[float, ...]
    x: tuple[float, ...]
    y: tuple[float, ...]
    y_angles: tuple[float, ...] | None = None

    @property
    def angles_of_y(self) -> tuple[float, ...]:
        return self.angles if self.y_angles is None else self.y_angles

    def splines(self):
        """The splines (x(angle), y(angle)), fitted once per path."""
        return _path_splines(self)


@dataclass(frozen=True)
class Joint:
    """A joint: the point ``at_parent`` of the parent's frame (world axes for ground) coincides with
    ``at_child`` of the child's frame (m); ``offset`` (rad) is the child frame's angle relative to the
    parent's when the angle is 0; ``limits`` (rad) are informative.

    type 'pin': one coordinate, the angle, named ``name``; with a ``path`` the child's point moves
    along it with the angle (at_parent + path(angle)). type 'free' (parent ground only): three
    coordinates named by ``coordinates``, (angle, x, y): the angle as a pin's, and the child's point
    at at_parent + (x, y) (m, world axes)."""

    name: str
    type: str
    parent: str
    child: str
    at_parent: tuple[float, float]
    at_child: tuple[float, float]
    offset: float = 0.0
    limits: tuple[float, float] | None = None
    path: JointPath | None = None
    coordinates: tuple[str, str, str] | None = None

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        """The joint's coordinates: (name,) for a pin, its three for a free joint."""
        return self.coordinates if self.type == "free" else (self.name,)


@dataclass(frozen=True)
class Load:
    """A constant point force (N, world axes) at ``at`` (m) in the frame of ``body``."""

    body: str
    at: tuple[float, float]
    force: tuple[float, float]


@dataclass(frozen=True)
class Frame:
    """A named frame fixed to ``body``: its origin ``at`` (m) and its x axis at ``angle`` (rad) in
    the body's frame (e.g. an OpenSim body welded to ``body`` on import), for loads given in it."""

    name: str
    body: str
    at: tuple[float, float]
    angle: float = 0.0


@dataclass(frozen=True)
class MotionSpec:
    """A named motion of a model: every joint from ``start`` to ``goal`` (rad, (joint, angle) pairs
    in the model's coordinate order) in ``duration`` s, from rest to rest, along ``type``
    ('minimum-jerk': z0 + (z1 - z0)(10u^3 - 15u^4 + 6u^5), u = t / duration; 'eq5-paper',
    'eq5-exact': the paper's eq. 5, -45 deg to 0 in 1 s)."""

    name: str
    type: str
    duration: float
    start: tuple[tuple[str, float], ...]
    goal: tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class Model:
    """A planar tree of bodies hanging from ground through pin joints (in topological order),
    gravity (m/s^2, world axes), constant loads, named motions (the first the default), short
    keys ((name, target) pairs: see ``with_short_keys``), frames, muscles (``fdbench.multibody.muscles``)
    and torque actuators (``fdbench.multibody.actuators``)."""

    name: str
    gravity: tuple[float, float]
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    loads: tuple[Load, ...] = ()
    description: str = ""
    motions: tuple[MotionSpec, ...] = ()
    keys: tuple[tuple[str, str], ...] = ()
    frames: tuple[Frame, ...] = ()
    muscles: tuple[Muscle, ...] = ()
    actuators: tuple[Actuator, ...] = ()

    def frame(self, name: str) -> tuple[str, tuple[float, float], float]:
        """(body, origin (m), angle (rad)) of a body's own frame or of a named frame fixed to a body;
        KeyError for another name."""
        for body in self.bodies:
            if body.name == name:
                return body.name, (0.0, 0.0), 0.0
        for frame in self.frames:
            if frame.name == name:
                return frame.body, frame.at, frame.angle
        raise KeyError(f"no body or frame {name!r} in model {self.name!r}")

    @property
    def coordinates(self) -> tuple[str, ...]:
        """The model's coordinates in order: a pin joint's name, a free joint's three (angle, x, y)."""
        return tuple(name for joint in self.joints for name in joint.coordinate_names)

    @property
    def coordinate_kinds(self) -> tuple[str, ...]:
        """Per coordinate, ANGLE ('angle', rad) or TRANSLATION ('translation', m)."""
        return tuple(kind for joint in self.joints
                     for kind in ((ANGLE, TRANSLATION, TRANSLATION) if joint.type == "free" else (ANGLE,)))

    @property
    def n_joints(self) -> int:
        """The number of coordinates (a free joint has three)."""
        return len(self.coordinates)

    @property
    def floating_base(self) -> "Joint | None":
        """The free joint between ground and a body (the model's floating base), or None."""
        return next((joint for joint in self.joints if joint.type == "free" and joint.parent == GROUND), None)

    def joint_named(self, name: str) -> Joint:
        """The joint called ``name`` (a joint's name, not a free joint's coordinate)."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(f"no joint {name!r} in model {self.name!r}")

    @property
    def total_mass(self) -> float:
        """kg."""
        return math.fsum(body.mass for body in self.bodies)

    def body(self, name: str) -> Body:
        for body in self.bodies:
            if body.name == name:
                return body
        raise KeyError(f"no body {name!r} in model {self.name!r}")

    def parent_joint(self, body_name: str) -> Joint:
        """The joint whose child is body ``body_name``."""
        return self.joints[self._parent_index(body_name)]

    def children(self, body_name: str) -> tuple[int, ...]:
        """Indices of the joints whose parent is ``body_name`` (a body or GROUND), in order."""
        return tuple(k for k, joint in enumerate(self.joints) if joint.parent == body_name)

    def path(self, body_name: str) -> tuple[int, ...]:
        """Indices of the joints from ground to body ``body_name``, ground's joint first."""
        indices = []
        while body_name != GROUND:
            k = self._parent_index(body_name)
            indices.append(k)
            body_name = self.joints[k].parent
            if len(indices) > len(self.joints):
                raise ValueError(f"model {self.name!r}: the joints form a cycle")
        return tuple(reversed(indices))

    def _parent_index(self, body_name: str) -> int:
        for k, joint in enumerate(self.joints):
            if joint.child == body_name:
                return k
        raise KeyError(f"no joint has body {body_name!r} as its child in model {self.name!r}")


# ---------------------------------------------------------------- the end point of natural coordinates


def resolved_end(model: Model, body_name: str) -> tuple[float, float]:
    """The body's second point of natural coordinates (m, in its frame): its ``end`` if given; else
    the at_parent point of its first child joint; else its farthest load's point; else its centre of
    mass; else its joint point + (1 m, 0). A load or centre of mass closer than 1 mm to the joint
    point is passed over."""
    return end_of(model, body_name)[0]


def end_of(model: Model, body_name: str) -> tuple[tuple[float, float], str]:
    """resolved_end and what gave it: 'end', 'joint <k>', 'load <i>', 'com' or 'default'."""
    body = model.body(body_name)
    if body.end is not None:
        return body.end, "end"
    children = model.children(body_name)
    if children:
        return model.joints[children[0]].at_parent, f"joint {children[0]}"
    origin = model.parent_joint(body_name).at_child
    loads = [(i, load) for i, load in enumerate(model.loads) if load.body == body_name]
    if loads:
        i, load = max(loads, key=lambda pair: distance(pair[1].at, origin))
        if distance(load.at, origin) >= MIN_SEGMENT:
            return load.at, f"load {i}"
    if distance(body.com, origin) >= MIN_SEGMENT:
        return body.com, "com"
    return (origin[0] + 1.0, origin[1]), "default"


def distance(a, b) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])

# ---------------------------------------------------------------- checking values

TOP_KEYS = {"name": False, "description": False, "gravity": False, "bodies": True, "joints": True, "loads": False,
            "motions": False, "keys": False, "frames": False, "muscles": False,
            "actuators": False}
BODY_KEYS = {"name": True, "mass": True, "com": True, "inertia": True, "end": False}
JOINT_KEYS = {"name": True, "type": False, "parent": True, "child": True, "at_parent": True, "at_child": False,
              "offset": False, "limits": False, "path": False, "coordinates": False}
PATH_KEYS = {"angles": True, "x": True, "y": True, "y_angles": False}
LOAD_KEYS = {"body": True, "at": True, "force": True}
FRAME_KEYS = {"name": True, "body": True, "at": True, "angle": False}
MOTION_KEYS = {"name": True, "type": False, "duration": False, "start": False, "goal": False}
MOTION_TYPES = ("minimum-jerk", "eq5-paper", "eq5-exact")
EQ5 = {"duration": 1.0, "start": -math.pi / 4, "goal": 0.0}  # eq. 5's span (s) and angles (rad), fixed

# what each key allows, said when it is missing or wrong
ALLOWED = {
    "name": "a name: a letter then letters, digits or '_'", "description": "a text (one line)",
    "gravity": "[x, y] (m/s^2, world axes)", "bodies": "a list of tables ([[bodies]] in TOML)",
    "joints": "a list of tables ([[joints]] in TOML)", "loads": "a list of tables ([[loads]] in TOML)",
    "mass": "a positive number (kg)", "com": "[x, y] (m, in the body's frame)",
    "inertia": "a positive number (kg m^2, about the centre of mass)",
    "end": "[x, y] (m, in the body's frame)", "type": "pin or free", "parent": "a body's name or 'ground'",
    "child": "a body's name", "at_parent": "[x, y] (m, in the parent's frame)",
    "at_child": "[x, y] (m, in the child's frame)", "offset": "a number (rad)",
    "limits": "[lower, upper] (rad, lower < upper)", "body": "a body's name", "at": "[x, y] (m, in the body's frame)",
    "force": "[x, y] (N, world axes)", "frames": "a list of tables ([[frames]] in TOML)",
    "angle": "a number (rad, the frame's x axis in the body's frame)", "motions": "a list of tables ([[motions]] in TOML)",
    "keys": "a table of short names, each a path of with_changes ([keys] in TOML)",
    "duration": "a positive number (s)", "start": "a table {joint = angle} (rad), every joint",
    "goal": "a table {joint = angle} (rad), every joint",
    "path": "a table with angles (rad, strictly increasing), x and y (m), lists of the same length (2 to 1000)",
    "coordinates": "three names [angle, x, y] of a free joint's coordinates",
    "angles": "a list of angles (rad), strictly increasing", "x": "a list of x values (m)",
    "y": "a list of y values (m)", "y_angles": "a list of angles (rad), strictly increasing: y's own",
    "muscles": "a list of tables ([[muscles]] in TOML)", "actuators": "a list of tables ([[actuators]] in TOML)",
}


def _kind(value) -> str:
    """How a value of the wrong type is named in a message."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f"the text {value!r}" if len(value) <= 40 else "a text"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if value is None:
        return "null"
    if isinstance(value, (int, float)):
        return repr(value)
    return f"a {type(value).__name__}"


class _Checker:
    """Reads the values of one description, raising ModelError naming ``source`` and the key."""

    kind = staticmethod(_kind)  # how a value of the wrong type is named

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, problem: str):
        raise ModelError(self.source, key, problem)

    def table(self, value, key: str, keys: dict) -> dict:
        """``value`` as a table with every required key of ``keys`` and no other."""
        if not isinstance(value, dict):
            self.fail(key, f"must be a table of keys, got {_kind(value)}")
        for name in value:
            if name not in keys:
                where = f"{key}." if key else ""
                self.fail(f"{where}{name}", unknown_name_message("key", name, list(keys)))
        for name, required in keys.items():
            if required and name not in value:
                self.fail(f"{key}.{name}" if key else name, f"missing; give {ALLOWED[name]}")
        return value

    def number(self, value, key: str, positive: bool = False, what: str = "") -> float:
        what = what or ALLOWED[key.rsplit(".", 1)[-1].split("[")[0]]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, f"must be {what}, got {_kind(value)}")
        try:
            value = float(value)
        except OverflowError:  # an integer beyond the range of floats
            value = math.inf if value > 0 else -math.inf
        if not math.isfinite(value):
            self.fail(key, f"must be finite: {what}, got {value}")
        if abs(value) > MAX_MAGNITUDE:
            self.fail(key, f"must be at most 1e6 in magnitude: {what}, got {value:g}")
        if positive and value <= 0:
            self.fail(key, f"must be {what}, got {value:g}")
        return value

    def pair(self, value, key: str) -> tuple[float, float]:
        what = ALLOWED[key.rsplit(".", 1)[-1].split("[")[0]]
        if not isinstance(value, list) or len(value) != 2:
            self.fail(key, f"must be {what}, got {_kind(value)}")
        return tuple(self.number(v, f"{key}[{i}]", what="a number") for i, v in enumerate(value))

    def text(self, value, key: str, limit: int) -> str:
        if not isinstance(value, str):
            self.fail(key, f"must be a text, got {_kind(value)}")
        if len(value) > limit or any(ord(c) < 32 or ord(c) == 127 for c in value) or not value.strip():
            self.fail(key, f"must be a non-empty line of at most {limit} characters")
        return value

    def name(self, value, key: str) -> str:
        if not isinstance(value, str):
            self.fail(key, f"must be {ALLOWED['name']}, got {_kind(value)}")
        if not NAME_PATTERN.fullmatch(value):
            self.fail(key, f"{quoted(value)} is not a name fdbench accepts: a letter then letters, digits or '_', "
                           "at most 64 characters")
        if value.lower() == GROUND:
            self.fail(key, "'ground' is reserved for the fixed world; choose another name")
        return value

    def entries(self, data: dict, key: str) -> list:
        value = data.get(key, [])
        if not isinstance(value, list):
            self.fail(key, f"must be {ALLOWED[key]}, got {_kind(value)}")
        if len(value) > MAX_BODIES:
            self.fail(key, f"at most {MAX_BODIES} entries, got {len(value)}")
        return value


def model_from_dict(data, source: str, default_name: str | None = None) -> Model:
    """The checked Model of a description's keys (as a TOML or JSON file gives them); ``source``
    names it in errors, ``default_name`` (else the stem of ``source``) is its name if it has none.
    ModelError for the first problem found."""
    check = _Checker(source)
    data = check.table(data, "", TOP_KEYS)
    name = check.text(data["name"], "name", 100) if "name" in data else (default_name or Path(source).stem or "model")
    description = check.text(data["description"], "description", 500) if "description" in data else ""
    gravity = check.pair(data["gravity"], "gravity") if "gravity" in data else (0.0, -9.81)
    bodies = [_body(check, entry, f"bodies[{i}]") for i, entry in enumerate(check.entries(data, "bodies"))]
    joints = [_joint(check, entry, f"joints[{k}]") for k, entry in enumerate(check.entries(data, "joints"))]
    loads = [_load(check, entry, f"loads[{i}]") for i, entry in enumerate(check.entries(data, "loads"))]
    if not bodies:
        check.fail("bodies", "a model needs at least one body ([[bodies]] with name, mass, com, inertia)")
    _check_names(check, bodies, joints)
    _check_references(check, bodies, joints, loads)
    order = _topological_order(check, bodies, joints)
    model = Model(name, gravity, tuple(bodies), tuple(joints[k] for k in order), tuple(loads), description)
    _check_ends(check, model, bodies, order)
    motions = tuple(_motion(check, entry, f"motions[{i}]", model.coordinates, model.coordinate_kinds)
                    for i, entry in enumerate(check.entries(data, "motions")))
    _check_motion_names(check, motions)
    named = set()
    frames = tuple(_frame(check, entry, f"frames[{i}]", model, named)
                   for i, entry in enumerate(check.entries(data, "frames")))
    model = replace(model, motions=motions, keys=_short_keys(check, data.get("keys", {}), model), frames=frames)
    model = replace(model, muscles=read_muscles(check, check.entries(data, "muscles"), model))
    return replace(model, actuators=read_actuators(check, check.entries(data, "actuators"), model))


def _body(check: _Checker, entry, key: str) -> Body:
    entry = check.table(entry, key, BODY_KEYS)
    return Body(
        name=check.name(entry["name"], f"{key}.name"),
        mass=check.number(entry["mass"], f"{key}.mass", positive=True),
        com=check.pair(entry["com"], f"{key}.com"),
        inertia=check.number(entry["inertia"], f"{key}.inertia", positive=True),
        end=check.pair(entry["end"], f"{key}.end") if "end" in entry else None,
    )


def _joint(check: _Checker, entry, key: str) -> Joint:
    entry = check.table(entry, key, JOINT_KEYS)
    name = check.name(entry["name"], f"{key}.name")
    if name.lower() == "t" or name.lower().endswith(RESERVED_SUFFIXES):
        check.fail(f"{key}.name", f"{name!r} would clash with the columns of motion and torque files (t, <joint>"
                                  f"{', <joint>'.join(RESERVED_SUFFIXES)}); choose another name")
    kind = entry.get("type", "pin")
    if kind not in JOINT_TYPES:
        check.fail(f"{key}.type", f"{_kind(kind)} is not a joint type fdbench knows; valid: {', '.join(JOINT_TYPES)}")
    limits = check.pair(entry["limits"], f"{key}.limits") if "limits" in entry else None
    if limits is not None and not limits[0] < limits[1]:
        check.fail(f"{key}.limits", f"must be [lower, upper] with lower < upper (rad), got {list(limits)}")
    path = _path(check, entry["path"], f"{key}.path") if "path" in entry else None
    coordinates = None
    if kind == "free":
        if path is not None:
            check.fail(f"{key}.path", "a free joint has no path (its x and y are coordinates); remove path")
        if "coordinates" not in entry:
            check.fail(f"{key}.coordinates", f"missing; give {ALLOWED['coordinates']}")
        coordinates = _free_coordinates(check, entry["coordinates"], f"{key}.coordinates")
        if entry["parent"] != GROUND:
            check.fail(f"{key}.parent", f"a free joint's parent must be 'ground', got {_kind(entry['parent'])}")
    elif "coordinates" in entry:
        check.fail(f"{key}.coordinates", "only a free joint names coordinates (a pin's coordinate is its name); "
                                         "remove coordinates or give type = \"free\"")
    return Joint(
        name=name, type=kind,
        parent=_reference(check, entry["parent"], f"{key}.parent"),
        child=_reference(check, entry["child"], f"{key}.child"),
        at_parent=check.pair(entry["at_parent"], f"{key}.at_parent"),
        at_child=check.pair(entry.get("at_child", [0.0, 0.0]), f"{key}.at_child"),
        offset=check.number(entry.get("offset", 0.0), f"{key}.offset"),
        limits=limits, path=path, coordinates=coordinates,
    )


def _path(check: _Checker, entry, key: str) -> JointPath:
    """A joint's path table: angles strictly increasing, x and y of the same length."""
    entry = check.table(entry, key, PATH_KEYS)
    lists = {}
    for name in (name for name in PATH_KEYS if name in entry):
        value = entry[name]
        if not isinstance(value, list) or not 2 <= len(value) <= MAX_PATH_SAMPLES:
            check.fail(f"{key}.{name}",
                       f"must be {ALLOWED[name]} of 2 to {MAX_PATH_SAMPLES} numbers, got {_kind(value)}")
        lists[name] = tuple(check.number(v, f"{key}.{name}[{i}]", what="a number") for i, v in enumerate(value))
    for name, knots in (("x", "angles"), ("y", "y_angles" if "y_angles" in lists else "angles")):
        if len(lists[name]) != len(lists[knots]):
            check.fail(f"{key}.{name}", f"has {len(lists[name])} values but {knots} has {len(lists[knots])}; "
                                        f"give one value per angle")
    for knots in ("angles", "y_angles"):
        values = lists.get(knots, ())
        for i in range(1, len(values)):
            if not values[i] > values[i - 1]:
                check.fail(f"{key}.{knots}[{i}]", f"must be more than {knots}[{i - 1}] ({values[i - 1]:g}): "
                                                  f"{ALLOWED['angles']}, got {values[i]:g}")
    return JointPath(lists["angles"], lists["x"], lists["y"], lists.get("y_angles"))


def _free_coordinates(check: _Checker, value, key: str) -> tuple[str, str, str]:
    if not isinstance(value, list) or len(value) != 3:
        check.fail(key, f"must be {ALLOWED['coordinates']}, got {_kind(value)}")
    names = tuple(check.name(v, f"{key}[{i}]") for i, v in enumerate(value))
    for i, name in enumerate(names):
        if name.lower() == "t" or name.lower().endswith(RESERVED_SUFFIXES):
            check.fail(f"{key}[{i}]", f"{name!r} would clash with the columns of motion and torque files; "
                                      "choose another name")
    return names


_SPLINES: dict = {}


def _path_splines(path: JointPath):
    if path not in _SPLINES:
        _SPLINES[path] = (fit(path.angles, path.x), fit(path.angles_of_y, path.y))
    return _SPLINES[path]


def _load(check: _Checker, entry, key: str) -> Load:
    entry = check.table(entry, key, LOAD_KEYS)
    return Load(body=_reference(check, entry["body"], f"{key}.body"), at=check.pair(entry["at"], f"{key}.at"),
                force=check.pair(entry["force"], f"{key}.force"))


def _frame(check: _Checker, entry, key: str, model: Model, earlier: set) -> Frame:
    entry = check.table(entry, key, FRAME_KEYS)
    name = check.name(entry["name"], f"{key}.name")
    taken = {n.lower() for n in [b.name for b in model.bodies] + [j.name for j in model.joints]}
    if name.lower() in taken or name.lower() in earlier:
        check.fail(f"{key}.name", f"{name!r} is already the name of a body, joint or frame; a frame needs its own name")
    body = _reference(check, entry["body"], f"{key}.body")
    if body not in [b.name for b in model.bodies]:
        check.fail(f"{key}.body", unknown_name_message("body", body, [b.name for b in model.bodies]))
    angle = check.number(entry["angle"], f"{key}.angle") if "angle" in entry else 0.0
    earlier.add(name.lower())
    return Frame(name, body, check.pair(entry["at"], f"{key}.at"), angle)


def _reference(check: _Checker, value, key: str) -> str:
    if not isinstance(value, str):
        check.fail(key, f"must be {ALLOWED[key.rsplit('.', 1)[-1]]}, got {_kind(value)}")
    return value


def _motion(check: _Checker, entry, key: str, joints: tuple, kinds: tuple = ()) -> MotionSpec:
    entry = check.table(entry, key, MOTION_KEYS)
    kind = entry.get("type", MOTION_TYPES[0])
    if kind not in MOTION_TYPES:
        check.fail(f"{key}.type", f"{_kind(kind)} is not a motion type fdbench knows; valid: {', '.join(MOTION_TYPES)}")
    name = check.name(entry["name"], f"{key}.name")
    if kind != "minimum-jerk":  # eq. 5: one angle from -45 deg to 0 in 1 s
        for fixed in ("duration", "start", "goal"):
            if fixed in entry:
                check.fail(f"{key}.{fixed}", f"eq. 5 fixes it ({EQ5['duration']:g} s, from -45 deg to 0); remove it")
        if len(joints) != 1 or (kinds and kinds[0] == TRANSLATION):
            check.fail(f"{key}.type", f"{kind} moves the one angle of a one-joint model; this model has "
                                      f"{len(joints)} coordinates")
        return MotionSpec(name=name, type=kind, duration=EQ5["duration"], start=((joints[0], EQ5["start"]),),
                          goal=((joints[0], EQ5["goal"]),))
    for required in ("duration", "start", "goal"):
        if required not in entry:
            check.fail(f"{key}.{required}", f"missing; give {ALLOWED[required]}")
    duration = check.number(entry["duration"], f"{key}.duration", positive=True)
    if duration < MIN_MOTION_DURATION:
        check.fail(f"{key}.duration", f"must be at least {MIN_MOTION_DURATION:g} s (ten samples of the motion's "
                                      f"1 ms grid), got {duration:g}")
    return MotionSpec(name=name, type=kind, duration=duration,
                      start=_joint_angles(check, entry["start"], f"{key}.start", joints, kinds),
                      goal=_joint_angles(check, entry["goal"], f"{key}.goal", joints, kinds))


def _joint_angles(check: _Checker, value, key: str, joints: tuple, kinds: tuple = ()) -> tuple[tuple[str, float], ...]:
    """{joint = angle} (rad) naming every joint once: (joint, angle) pairs in the model's order."""
    if not isinstance(value, dict):
        check.fail(key, f"must be {ALLOWED[key.rsplit('.', 1)[-1]]}, got {_kind(value)}")
    for name in value:
        if name not in joints:
            check.fail(f"{key}.{name}", unknown_name_message("joint", name, list(joints)))
    for joint in joints:
        if joint not in value:
            check.fail(f"{key}.{joint}", f"missing; give the value (rad; m for a translation) of every joint: "
                                         f"{', '.join(joints)}")
    what = dict(zip(joints, kinds or ())) if kinds else {}
    return tuple((joint, check.number(value[joint], f"{key}.{joint}", what="a translation (m)" if what.get(joint) ==
                                      TRANSLATION else "an angle (rad)")) for joint in joints)


def _check_motion_names(check: _Checker, motions: tuple) -> None:
    seen = {}
    for i, motion in enumerate(motions):
        earlier = seen.setdefault(motion.name.lower(), i)
        if earlier != i:
            check.fail(f"motions[{i}].name", f"{motion.name!r} is already the name of motions[{earlier}]; "
                                             "motions need distinct names (ignoring case)")


def _short_keys(check: _Checker, value, model: Model) -> tuple[tuple[str, str], ...]:
    """The [keys] table: short name -> '[-]path[@joint]', each path one of ``change_paths``."""
    if not isinstance(value, dict):
        check.fail("keys", f"must be {ALLOWED['keys']}, got {_kind(value)}")
    if len(value) > MAX_BODIES:
        check.fail("keys", f"at most {MAX_BODIES} entries, got {len(value)}")
    for name, target in value.items():
        key = f"keys.{name}"
        if not NAME_PATTERN.fullmatch(name):
            check.fail(key, f"{quoted(name)} is not a short key fdbench accepts: a letter then letters, digits or '_'")
        if not isinstance(target, str):
            check.fail(key, f"must be a path of the model as a text ('[-]path[@joint]'), got {_kind(target)}")
        problem = _target_problem(model, target)
        if problem:
            check.fail(key, problem)
    return tuple(value.items())


def parse_target(target: str) -> tuple[bool, str, str | None]:
    """(negated, path, joint) of a short key's target '[-]path[@joint]'."""
    negated = target.startswith("-")
    path, _, joint = target[negated:].partition("@")
    return negated, path, joint or None


def _target_problem(model: Model, target: str) -> str:
    """Why ``target`` cannot be a short key's target of ``model`` ('' if it can)."""
    _, path, joint = parse_target(target)
    paths = change_paths(model)
    if path not in paths:
        return (unknown_name_message("path", path, paths)
                + " (with '-' before it for its negative, @<joint> after an inertia for the inertia about that joint)")
    if joint is None:
        return ""
    body = path.rsplit(".", 1)[0]
    if not path.endswith(".inertia") or body not in [b.name for b in model.bodies]:
        return f"@{joint} goes after a body's inertia (<body>.inertia@<joint>), not after {path!r}"
    near = [j.name for j in model.joints if body in (j.parent, j.child)]
    if joint not in near:
        return unknown_name_message(f"joint of body {body!r}", joint, near)
    return ""


def _check_names(check: _Checker, bodies: list, joints: list) -> None:
    """Names of bodies and joints are distinct, ignoring case."""
    seen = {}
    named = [(f"bodies[{i}]", b.name) for i, b in enumerate(bodies)] + [(f"joints[{k}]", j.name) for k, j in enumerate(joints)]
    named += [(f"joints[{k}].coordinates[{i}]", name) for k, j in enumerate(joints) if j.type == "free"
              for i, name in enumerate(j.coordinates) if name != j.name]
    for key, name in named:
        earlier = seen.setdefault(name.lower(), key)
        if earlier != key:
            check.fail(f"{key}.name", f"{name!r} is already the name of {earlier}; names of bodies and joints must "
                                      "be distinct (ignoring case)")


def _check_references(check: _Checker, bodies: list, joints: list, loads: list) -> None:
    """Parents, children and loaded bodies exist; every body is the child of exactly one joint."""
    names = [body.name for body in bodies]
    parent_of = {}
    for k, joint in enumerate(joints):
        if joint.parent != GROUND and joint.parent not in names:
            check.fail(f"joints[{k}].parent", unknown_name_message("body", joint.parent, [GROUND, *names]))
        if joint.child not in names:
            check.fail(f"joints[{k}].child", unknown_name_message("body", joint.child, names))
        if joint.child == joint.parent:
            check.fail(f"joints[{k}].child", f"{joint.child!r} is also the joint's parent; a body cannot hang from itself")
        if joint.child in parent_of:
            check.fail(f"joints[{k}].child", f"body {joint.child!r} is already the child of joints[{parent_of[joint.child]}]; "
                                             "a body hangs from exactly one joint (the model is a tree)")
        parent_of[joint.child] = k
    for i, body in enumerate(bodies):
        if body.name not in parent_of:
            check.fail(f"bodies[{i}]", f"body {body.name!r} is the child of no joint; every body hangs from ground "
                                       "through joints (add a [[joints]] with child = " + repr(body.name) + ")")
    for i, load in enumerate(loads):
        if load.body not in names:
            check.fail(f"loads[{i}].body", unknown_name_message("body", load.body, names))


def _topological_order(check: _Checker, bodies: list, joints: list) -> list[int]:
    """Joint indices, each after the joint of its parent body; among those ready, file order.
    ModelError naming a cycle when some bodies have no path to ground."""
    by_parent = {}
    for k, joint in enumerate(joints):
        by_parent.setdefault(joint.parent, []).append(k)
    ready = list(by_parent.get(GROUND, []))
    heapq.heapify(ready)
    order = []
    while ready:
        k = heapq.heappop(ready)
        order.append(k)
        for child in by_parent.get(joints[k].child, []):
            heapq.heappush(ready, child)
    if len(order) < len(joints):
        _fail_cycle(check, joints, set(order))
    return order


def _fail_cycle(check: _Checker, joints: list, placed: set) -> None:
    parent_joint = {joint.child: k for k, joint in enumerate(joints)}
    start = min(k for k in range(len(joints)) if k not in placed)
    chain, k = [], start
    while k not in chain:
        chain.append(k)
        k = parent_joint[joints[k].parent]
    cycle = chain[chain.index(k):]
    bodies = " -> ".join([joints[j].child for j in cycle] + [joints[cycle[0]].child])
    check.fail(f"joints[{min(cycle)}].parent", f"the joints form a cycle ({bodies}), so these bodies have no path "
                                               "to ground; the model must be a tree hanging from ground")


def _check_ends(check: _Checker, model: Model, bodies: list, order: list) -> None:
    """Each body's end point is at least 1 mm from its joint point (a segment has a length)."""
    for i, body in enumerate(bodies):
        joint = model.parent_joint(body.name)
        end, given_by = end_of(model, body.name)
        if distance(end, joint.at_child) >= MIN_SEGMENT:
            continue
        here = f"the joint point {list(joint.at_child)} of {body.name!r} (joints[{order[model.joints.index(joint)]}].at_child)"
        if given_by == "end":
            check.fail(f"bodies[{i}].end", f"is within 1 mm of {here}: a segment of zero length; the end point "
                                           "must be at least 1 mm away")
        k = order[int(given_by.split()[1])]
        check.fail(f"joints[{k}].at_parent", f"is within 1 mm of {here}: a segment of zero length; move the joint "
                                             f"or give bodies[{i}].end, the body's second point")

# ---------------------------------------------------------------- as plain data


def to_dict(model: Model, explicit_ends: bool = False) -> dict:
    """The description's keys (as a file holds them); with ``explicit_ends`` every body's resolved end."""
    def body(b: Body) -> dict:
        entry = {"name": b.name, "mass": b.mass, "com": list(b.com), "inertia": b.inertia}
        end = resolved_end(model, b.name) if explicit_ends else b.end
        return entry | ({"end": list(end)} if end is not None else {})

    def joint(j: Joint) -> dict:
        entry = {"name": j.name, "type": j.type, "parent": j.parent, "child": j.child, "at_parent": list(j.at_parent),
                 "at_child": list(j.at_child), "offset": j.offset}
        entry |= {"coordinates": list(j.coordinates)} if j.coordinates is not None else {}
        if j.path is not None:
            entry["path"] = {"angles": list(j.path.angles), "x": list(j.path.x), "y": list(j.path.y)}
            entry["path"] |= {"y_angles": list(j.path.y_angles)} if j.path.y_angles is not None else {}
        return entry | ({"limits": list(j.limits)} if j.limits is not None else {})

    data = {"name": model.name} | ({"description": model.description} if model.description else {})
    data |= {"gravity": list(model.gravity), "bodies": [body(b) for b in model.bodies],
             "joints": [joint(j) for j in model.joints]}
    if model.loads:
        data["loads"] = [{"body": load.body, "at": list(load.at), "force": list(load.force)} for load in model.loads]
    if model.motions:
        data["motions"] = [{"name": m.name, "type": m.type} | ({} if m.type != "minimum-jerk" else {
            "duration": m.duration, "start": dict(m.start), "goal": dict(m.goal)}) for m in model.motions]
    if model.keys:
        data["keys"] = dict(model.keys)
    if model.frames:
        data["frames"] = [{"name": f.name, "body": f.body, "at": list(f.at), "angle": f.angle} for f in model.frames]
    if model.muscles:
        data["muscles"] = [muscle_dict(m) for m in model.muscles]
    if model.actuators:
        data["actuators"] = [actuator_dict(a) for a in model.actuators]
    return data


def change_paths(model: Model) -> list[str]:
    """Every path ``with_changes`` accepts for ``model``."""
    paths = []
    for body in model.bodies:
        paths += [f"{body.name}.{key}" for key in ("mass", "inertia", "com.x", "com.y", "end.x", "end.y")]
        if sum(load.body == body.name for load in model.loads) == 1:
            paths += [f"{body.name}.force.x", f"{body.name}.force.y"]
    for joint in model.joints:
        paths += [f"{joint.name}.{key}" for key in ("offset", "at_parent.x", "at_parent.y", "at_child.x", "at_child.y")]
    for i in range(len(model.loads)):
        paths += [f"loads[{i}].{key}" for key in ("force.x", "force.y", "at.x", "at.y")]
    return paths + ["gravity.x", "gravity.y"]
