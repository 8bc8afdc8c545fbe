"""Muscles of a model file (``[[muscles]]``): a muscle's constants in SI units and its path, as data,
with their checks and their keys as a file holds them. Read and written with the rest of the model
(``fdbench.multibody.model``); their lengths and moment arms are ``fdbench.multibody.muscle_paths``.

A path is one of two forms:

* ``points``: straight segments through points fixed to bodies, frames or ground (``PointPath``),
  OpenSim's PathPointSet of a GeometryPath, exact planar geometry;
* ``length``: the muscle-tendon length (m) as a polynomial in some of the model's coordinates
  (``PolynomialPath``: a sum of terms coefficient * prod(q_k ** power_k)), OpenSim's
  FunctionBasedPath with a MultivariatePolynomialFunction.

The defaults are those of OpenSim's DeGrooteFregly2016Muscle where it has one (tendon strain
0.049 at one normalised force, passive fibre strain 0.6 at one normalised force, a maximum
contraction velocity of 10 optimal fibre lengths per s) and activation and deactivation time
constants of 15 and 60 ms.

Checks: every number finite and at most 1e6 in magnitude (the model's own checks); forces, lengths,
times, strains and velocities positive; a pennation angle in [0, pi/2); a fibre damping >= 0; a path
of 2 to 100 points of which no two in a row are the same point of the same body; a polynomial in 1
to 6 distinct coordinates of the model, 1 to 1000 terms of distinct integer powers 0 to 20. A muscle's
name is distinct (ignoring case) from every other muscle, body, joint, coordinate and frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from ..registry import unknown_name_message

GROUND = "ground"  # the fixed world (as in fdbench.multibody.model, which imports this module)
TENDONS = ("rigid", "compliant")
MAX_PATH_POINTS = 100
MAX_COORDINATES = 6  # of a polynomial path, as OpenSim's MultivariatePolynomialFunction
MAX_TERMS = 1000
MAX_POWER = 20


@dataclass(frozen=True)
class PathPoint:
    """A point of a muscle's path: ``at`` (m) in the frame of ``body`` (a body, a named frame fixed to
    a body, or 'ground': world axes)."""

    body: str
    at: tuple[float, float]


@dataclass(frozen=True)
class PointPath:
    """Straight segments through ``points`` (2 or more), in order."""

    points: tuple[PathPoint, ...]


@dataclass(frozen=True)
class Term:
    """coefficient (m) * prod(q_k ** powers[k]) over the path's coordinates q_k (rad or m)."""

    coefficient: float
    powers: tuple[int, ...]


@dataclass(frozen=True)
class PolynomialPath:
    """The muscle-tendon length (m) as the sum of ``terms`` in ``coordinates`` (names of the model's)."""

    coordinates: tuple[str, ...]
    terms: tuple[Term, ...]


@dataclass(frozen=True)
class Muscle:
    """A Hill-type muscle: maximum isometric force (N), optimal fibre length (m), tendon slack length
    (m), its path, pennation angle at the optimal fibre length (rad), maximum contraction velocity
    (optimal fibre lengths per s), activation and deactivation time constants (s), tendon 'rigid' or
    'compliant' with its strain at one normalised force, the passive fibre strain at one normalised
    force and the fibre damping (normalised)."""

    name: str
    max_isometric_force: float
    optimal_fiber_length: float
    tendon_slack_length: float
    path: PointPath | PolynomialPath
    pennation_angle: float = 0.0
    max_contraction_velocity: float = 10.0
    activation_time: float = 0.015
    deactivation_time: float = 0.060
    tendon: str = "rigid"
    tendon_strain: float = 0.049
    passive_strain: float = 0.6
    fiber_damping: float = 0.0


# the keys of a [[muscles]] table (True: required) and what each allows
MUSCLE_KEYS = {"name": True, "max_isometric_force": True, "optimal_fiber_length": True, "tendon_slack_length": True,
               "pennation_angle": False, "max_contraction_velocity": False, "activation_time": False,
               "deactivation_time": False, "tendon": False, "tendon_strain": False, "passive_strain": False,
               "fiber_damping": False, "path": True}
PATH_FORMS = {"points": False, "length": False}
POINT_KEYS = {"body": True, "at": True}
LENGTH_KEYS = {"coordinates": True, "terms": True}
TERM_KEYS = {"coefficient": True, "powers": True}
ALLOWED = {
    "name": "a name: a letter then letters, digits or '_'",
    "max_isometric_force": "a positive number (N)", "optimal_fiber_length": "a positive number (m)",
    "tendon_slack_length": "a positive number (m)",
    "pennation_angle": "an angle in [0, pi/2) (rad, at the optimal fibre length)",
    "max_contraction_velocity": "a positive number (optimal fibre lengths per s)",
    "activation_time": "a positive number (s)", "deactivation_time": "a positive number (s)",
    "tendon": "rigid or compliant", "tendon_strain": "a positive number (the tendon's strain at one normalised force)",
    "passive_strain": "a positive number (the fibre's passive strain at one normalised force)",
    "fiber_damping": "a number >= 0 (normalised)",
    "path": "a table with points = [{ body = ..., at = [x, y] }, ...] or length = { coordinates = [...], terms = [...] }",
    "points": f"a list of 2 to {MAX_PATH_POINTS} tables {{ body = ..., at = [x, y] }}",
    "body": "a body's or frame's name or 'ground'", "at": "[x, y] (m, in the body's frame)",
    "length": "a table { coordinates = [...], terms = [{ coefficient = ..., powers = [...] }, ...] }",
    "coordinates": f"a list of 1 to {MAX_COORDINATES} distinct coordinates of the model",
    "terms": f"a list of 1 to {MAX_TERMS} tables {{ coefficient = ..., powers = [...] }}",
    "coefficient": "a number (m)", "powers": f"a list of integers 0 to {MAX_POWER}, one per coordinate",
}


def read_muscles(check, entries: list, model) -> tuple[Muscle, ...]:
    """The checked muscles of the ``[[muscles]]`` tables ``entries`` of ``model`` (its bodies, joints
    and frames read); ``check`` is the model's checker (ModelError for the first problem)."""
    taken = {name.lower(): what for what, names in (
        ("a body", [b.name for b in model.bodies]), ("a coordinate", model.coordinates),
        ("a joint", [j.name for j in model.joints]), ("a frame", [f.name for f in model.frames])) for name in names}
    muscles = []
    for i, entry in enumerate(entries):
        muscle = _muscle(check, entry, f"muscles[{i}]", model)
        earlier = taken.setdefault(muscle.name.lower(), f"muscles[{i}]")
        if earlier != f"muscles[{i}]":
            check.fail(f"muscles[{i}].name", f"{muscle.name!r} is already the name of {earlier}; a muscle needs "
                                             "its own name (ignoring case)")
        muscles.append(muscle)
    return tuple(muscles)


def muscle_dict(muscle: Muscle) -> dict:
    """The muscle's keys as a file holds them, every value explicit, the path last."""
    entry = {f.name: getattr(muscle, f.name) for f in fields(muscle) if f.name != "path"}
    path = muscle.path
    if isinstance(path, PointPath):
        entry["path"] = {"points": [{"body": p.body, "at": list(p.at)} for p in path.points]}
    else:
        entry["path"] = {"length": {"coordinates": list(path.coordinates), "terms": [
            {"coefficient": t.coefficient, "powers": list(t.powers)} for t in path.terms]}}
    return entry


def _table(check, value, key: str, keys: dict) -> dict:
    """``value`` as a table of ``keys`` only, the required ones present (said with this module's texts)."""
    check.table(value, key, dict.fromkeys(keys, False))
    for name, required in keys.items():
        if required and name not in value:
            check.fail(f"{key}.{name}", f"missing; give {ALLOWED[name]}")
    return value


def _list(check, value, key: str, low: int, high: int) -> list:
    if not isinstance(value, list) or not low <= len(value) <= high:
        check.fail(key, f"must be {ALLOWED[key.rsplit('.', 1)[-1]]}, got {check.kind(value)}")
    return value


def _muscle(check, entry, key: str, model) -> Muscle:
    entry = _table(check, entry, key, MUSCLE_KEYS)
    defaults = {f.name: f.default for f in fields(Muscle) if f.name in MUSCLE_KEYS and not MUSCLE_KEYS[f.name]}
    values = {}
    for name in MUSCLE_KEYS:
        if name in ("name", "path", "tendon"):
            continue
        value = check.number(entry[name], f"{key}.{name}", what=ALLOWED[name]) if name in entry else defaults[name]
        if not (value >= 0 if name in ("pennation_angle", "fiber_damping") else value > 0) or (
                name == "pennation_angle" and not value < math.pi / 2):
            check.fail(f"{key}.{name}", f"must be {ALLOWED[name]}, got {value:g}")
        values[name] = value
    tendon = entry.get("tendon", "rigid")
    if tendon not in TENDONS:
        check.fail(f"{key}.tendon", f"{check.kind(tendon)} is not a tendon fdbench knows; valid: {', '.join(TENDONS)}")
    return Muscle(name=check.name(entry["name"], f"{key}.name"), path=_path(check, entry["path"], f"{key}.path", model),
                  tendon=tendon, **values)


def _path(check, entry, key: str, model) -> PointPath | PolynomialPath:
    entry = _table(check, entry, key, PATH_FORMS)
    if len(entry) != 1:
        check.fail(key, f"give one of points (straight segments through points of bodies) or length (a polynomial "
                        f"in coordinates), got {' and '.join(entry) if entry else 'neither'}")
    if "points" in entry:
        return _points(check, entry["points"], f"{key}.points", model)
    return _polynomial(check, entry["length"], f"{key}.length", model)


def _points(check, value, key: str, model) -> PointPath:
    frames = [GROUND] + [b.name for b in model.bodies] + [f.name for f in model.frames]
    points = []
    for i, entry in enumerate(_list(check, value, key, 2, MAX_PATH_POINTS)):
        where = f"{key}[{i}]"
        entry = _table(check, entry, where, POINT_KEYS)
        body = entry["body"]
        if not isinstance(body, str):
            check.fail(f"{where}.body", f"must be {ALLOWED['body']}, got {check.kind(body)}")
        if body not in frames:
            check.fail(f"{where}.body", unknown_name_message("body", body, frames))
        point = PathPoint(body, check.pair(entry["at"], f"{where}.at"))
        if points and point == points[-1]:
            check.fail(where, f"is {key}[{i - 1}] again (the same point of {body!r}): a segment of zero length; "
                              "remove one")
        points.append(point)
    return PointPath(tuple(points))


def _polynomial(check, entry, key: str, model) -> PolynomialPath:
    entry = _table(check, entry, key, LENGTH_KEYS)
    names = _list(check, entry["coordinates"], f"{key}.coordinates", 1, MAX_COORDINATES)
    for k, name in enumerate(names):
        if not isinstance(name, str):
            check.fail(f"{key}.coordinates[{k}]", f"must be a coordinate's name, got {check.kind(name)}")
        if name not in model.coordinates:
            check.fail(f"{key}.coordinates[{k}]", unknown_name_message("coordinate", name, list(model.coordinates)))
        if name in names[:k]:
            check.fail(f"{key}.coordinates[{k}]", f"{name!r} is already coordinates[{names.index(name)}]; "
                                                  "name each coordinate once")
    terms, seen = [], {}
    for t, term in enumerate(_list(check, entry["terms"], f"{key}.terms", 1, MAX_TERMS)):
        where = f"{key}.terms[{t}]"
        term = _table(check, term, where, TERM_KEYS)
        coefficient = check.number(term["coefficient"], f"{where}.coefficient", what=ALLOWED["coefficient"])
        powers = term["powers"]
        if not isinstance(powers, list) or len(powers) != len(names):
            check.fail(f"{where}.powers", f"must be {ALLOWED['powers']} ({len(names)}), got {check.kind(powers)}")
        for k, power in enumerate(powers):
            if isinstance(power, bool) or not isinstance(power, (int, float)) or not 0 <= power <= MAX_POWER or (
                    power != int(power)):
                check.fail(f"{where}.powers[{k}]", f"must be an integer 0 to {MAX_POWER}, got {check.kind(power)}")
        powers = tuple(int(p) for p in powers)
        earlier = seen.setdefault(powers, t)
        if earlier != t:
            check.fail(f"{where}.powers", f"{list(powers)} are already the powers of terms[{earlier}]; give each "
                                          "product of powers once")
        terms.append(Term(coefficient, powers))
    return PolynomialPath(tuple(names), tuple(terms))
