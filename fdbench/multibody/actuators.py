"""Torque actuators of a model file (``[[actuators]]``): one per coordinate at most, each with its
optimal force (N m per unit control; N for a translation), as OpenSim's ``CoordinateActuator``.
Read and written with the rest of the model (``fdbench.multibody.model``).

What they mean: a model without ``[[actuators]]`` drives every coordinate by a torque (and static
optimisation gives every coordinate a reserve). With ``[[actuators]]`` and muscles, only the listed
coordinates have torques besides the muscles: ``inverse --muscles`` takes them as its reserves and
``simulate --excitation-file`` drives them by ``--torque-file``. Without muscles they change
nothing: the torque-driven methods drive every coordinate.

Checks: ``coordinate`` a coordinate of the model, named by one actuator at most; ``optimal_force``
a finite number > 0 (default 1); ``name`` (default ``<coordinate>_reserve``) distinct, ignoring
case, from every body, joint, coordinate, frame, muscle and other actuator.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..registry import unknown_name_message

DEFAULT_OPTIMAL_FORCE = 1.0  # N m per unit control, as OpenSim's arm26 reserves
ACTUATOR_KEYS = {"coordinate": True, "optimal_force": False, "name": False}
ALLOWED = {"coordinate": "a coordinate of the model (a pin's name or a free joint's coordinate)",
           "optimal_force": "a positive number (N m per unit control; N for a translation)",
           "name": "a name: a letter then letters, digits or '_'"}


@dataclass(frozen=True)
class Actuator:
    """A torque actuator on ``coordinate``: its torque is ``optimal_force`` (N m per unit control;
    N for a translation) times its control."""

    name: str
    coordinate: str
    optimal_force: float = DEFAULT_OPTIMAL_FORCE


def default_name(coordinate: str) -> str:
    return f"{coordinate}_reserve"


def read_actuators(check, entries: list, model) -> tuple[Actuator, ...]:
    """The checked actuators of the ``[[actuators]]`` tables ``entries`` of ``model`` (its bodies,
    joints, frames and muscles read); ``check`` is the model's checker (ModelError for the first problem)."""
    taken = {name.lower(): what for what, names in (
        ("a body", [b.name for b in model.bodies]), ("a coordinate", model.coordinates),
        ("a joint", [j.name for j in model.joints]), ("a frame", [f.name for f in model.frames]),
        ("a muscle", [m.name for m in model.muscles])) for name in names}
    actuators, driven = [], {}
    for i, entry in enumerate(entries):
        key = f"actuators[{i}]"
        entry = check.table(entry, key, dict.fromkeys(ACTUATOR_KEYS, False))
        if "coordinate" not in entry:
            check.fail(f"{key}.coordinate", f"missing; give {ALLOWED['coordinate']}")
        coordinate = entry["coordinate"]
        if not isinstance(coordinate, str):
            check.fail(f"{key}.coordinate", f"must be {ALLOWED['coordinate']}, got {check.kind(coordinate)}")
        if coordinate not in model.coordinates:
            check.fail(f"{key}.coordinate", unknown_name_message("coordinate", coordinate, list(model.coordinates)))
        earlier = driven.setdefault(coordinate, i)
        if earlier != i:
            check.fail(f"{key}.coordinate", f"{coordinate!r} already has actuators[{earlier}]; give a coordinate "
                                            "one actuator")
        force = DEFAULT_OPTIMAL_FORCE
        if "optimal_force" in entry:
            force = check.number(entry["optimal_force"], f"{key}.optimal_force", positive=True,
                                 what=ALLOWED["optimal_force"])
        name = check.name(entry["name"], f"{key}.name") if "name" in entry else default_name(coordinate)
        earlier_name = taken.setdefault(name.lower(), key)
        if earlier_name != key:
            check.fail(f"{key}.name", f"{name!r} is already the name of {earlier_name}; an actuator needs its own "
                                      "name (ignoring case)")
        actuators.append(Actuator(name, coordinate, force))
    return tuple(actuators)


def actuator_dict(actuator: Actuator) -> dict:
    """The actuator's keys as a file holds them, every value explicit."""
    return {"name": actuator.name, "coordinate": actuator.coordinate, "optimal_force": actuator.optimal_force}


def optimal_forces(model, override: float | None = None) -> tuple[float, ...]:
    """Per coordinate of ``model``, its actuator's optimal force (``override`` if given), 0.0 for a
    coordinate without one; a model without actuators: every coordinate ``override`` (default 1)."""
    if not model.actuators:
        return (DEFAULT_OPTIMAL_FORCE if override is None else float(override),) * model.n_joints
    own = {a.coordinate: a.optimal_force for a in model.actuators}
    return tuple((own[c] if override is None else float(override)) if c in own else 0.0 for c in model.coordinates)
