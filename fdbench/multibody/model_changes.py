"""Changes of a model's constants: ``with_changes`` (``--model``/``--plant PATH=VALUE``, a path
of ``change_paths``) and ``with_short_keys`` (the short keys of a model file's ``[keys]``, e.g.
the forearm's ``I1``), each checked as a file is; ``path_value`` and ``short_key_values`` read
them."""

from __future__ import annotations

import math
import re
from dataclasses import replace

from ..registry import unknown_name_message
from .model import (GROUND, Model, ModelError, change_paths, distance, model_from_dict, parse_target, resolved_end,
                    to_dict)


def with_changes(model: Model, pairs) -> Model:
    """``model`` with scalar values changed by (path, value) pairs, checked as a file is. Paths:

    * ``<body>.mass``, ``<body>.inertia``, ``<body>.com.x|y``, ``<body>.end.x|y`` (an end not
      given starts from its resolved default);
    * ``<joint>.offset``, ``<joint>.at_parent.x|y``, ``<joint>.at_child.x|y``;
    * ``loads[<i>].force.x|y``, ``loads[<i>].at.x|y`` (i from 0 in file order), and
      ``<body>.force.x|y`` for the one load of a body that carries exactly one;
    * ``gravity.x|y``.

    Values are numbers or their text. ModelError naming ``path=value`` otherwise."""
    data = to_dict(model)
    for path, value in pairs:
        label = f"{path}={value}"
        if path not in change_paths(model):
            raise ModelError(label, "", unknown_name_message(f"path into model {model.name!r}", path, change_paths(model)))
        key = _set(data, model, path, _float(value, label))
        try:
            model = model_from_dict(data, label, default_name=model.name)
        except ModelError as exc:
            raise ModelError(label, "" if exc.key == key else exc.key, exc.problem) from None
    return model


def rigid_tendons(model: Model) -> Model:
    """``model`` with every compliant tendon rigid (Moco's ModOpIgnoreTendonCompliance)."""
    return replace(model, muscles=tuple(replace(m, tendon="rigid") for m in model.muscles))


def _float(value, label: str) -> float:
    if isinstance(value, bool):
        raise ModelError(label, "", "must be a number")
    try:
        return float(value)
    except OverflowError:  # an integer beyond the range of floats: refused as not finite
        return math.inf if value > 0 else -math.inf
    except (TypeError, ValueError):
        raise ModelError(label, "", f"must be a number, got {value!r}") from None


def _set(data: dict, model: Model, path: str, value: float) -> str:
    """Write ``value`` at ``path`` into the description ``data``; the key path of the file it changed."""
    axis = {"x": 0, "y": 1}
    if path.startswith("gravity."):
        data["gravity"][axis[path[-1]]] = value
        return f"gravity[{axis[path[-1]]}]"
    match = re.fullmatch(r"loads\[(\d+)\]\.(.+)", path)
    if match:
        index, rest = int(match.group(1)), match.group(2)
    else:
        name, rest = path.split(".", 1)
        names = [b.name for b in model.bodies]
        if name in names and rest.startswith("force."):
            index = next(i for i, load in enumerate(model.loads) if load.body == name)
        elif name in names:
            entry, key = data["bodies"][names.index(name)], f"bodies[{names.index(name)}]"
            return key + _set_field(entry, rest, value, lambda: list(resolved_end(model, name)))
        else:
            k = [j.name for j in model.joints].index(name)
            return f"joints[{k}]" + _set_field(data["joints"][k], rest, value, None)
    return f"loads[{index}]" + _set_field(data["loads"][index], rest, value, None)


def _set_field(entry: dict, rest: str, value: float, default_end) -> str:
    if "." not in rest:
        entry[rest] = value
        return f".{rest}"
    field, component = rest.split(".")
    if field == "end" and "end" not in entry:
        entry["end"] = default_end()
    i = {"x": 0, "y": 1}[component]
    entry[field][i] = value
    return f".{field}[{i}]"


# ---------------------------------------------------------------- short keys


def short_key_values(model: Model) -> dict[str, float]:
    """{short key: the value it reads in ``model``} (SI units; an @<joint> inertia about the joint)."""
    return {name: _target_value(model, target) for name, target in model.keys}


def _target_value(model: Model, target: str) -> float:
    negated, path, joint = parse_target(target)
    if joint is not None:
        value = inertia_about(model, path.rsplit(".", 1)[0], joint)
    else:
        value = path_value(model, path)
    return -value if negated else value


def path_pairs(model: Model) -> int:
    """The pairs (coordinate, body) with the coordinate on the body's path from ground: the entries
    of M(z) on and above its diagonal that are not zero, the size of the symbolic equations (a star
    of B pin joints has B, a chain B (B + 1) / 2)."""
    index, depth = {joint.child: k for k, joint in enumerate(model.joints)}, []
    for joint in model.joints:  # topological order: the parent's depth is known
        above = depth[index[joint.parent]] if joint.parent != GROUND else 0
        depth.append(above + len(joint.coordinate_names))
    return sum(depth)


def inertia_about(model: Model, body_name: str, joint_name: str) -> float:
    """kg m^2: the body's inertia about the point of joint ``joint_name`` (one of the body's joints):
    inertia + mass |com - point|^2."""
    body = model.body(body_name)
    return body.inertia + body.mass * distance(body.com, _joint_point(model, body_name, joint_name)) ** 2


def _joint_point(model: Model, body_name: str, joint_name: str) -> tuple[float, float]:
    """The joint's point in the body's frame (m): at_child if the body is its child, else at_parent."""
    joint = model.joint_named(joint_name)
    return joint.at_child if joint.child == body_name else joint.at_parent


def path_value(model: Model, path: str) -> float:
    """The value at one of ``change_paths(model)`` (an end not given reads its resolved default)."""
    head, _, component = path.rpartition(".")
    axis = {"x": 0, "y": 1}.get(component)
    if axis is None:  # <body>.mass, <body>.inertia, <joint>.offset
        name, field = path.split(".")
        return getattr(model.body(name) if field != "offset" else model.joint_named(name), field)
    if head == "gravity":
        return model.gravity[axis]
    owner, _, field = head.rpartition(".")
    if owner.startswith("loads["):
        return getattr(model.loads[int(owner[6:-1])], field)[axis]
    if field == "force":
        return next(load for load in model.loads if load.body == owner).force[axis]
    if owner in [joint.name for joint in model.joints]:
        return getattr(model.joint_named(owner), field)[axis]
    return (resolved_end(model, owner) if field == "end" else model.body(owner).com)[axis]


def with_short_keys(model: Model, pairs) -> Model:
    """``model`` with values changed by (name, value) pairs, each name a short key of the model's
    [keys] table or a path of ``with_changes``. A short key's target '[-]path[@joint]' sets the
    path to the value (negated with '-'); '<body>.inertia@<joint>' sets the body's inertia about
    the joint's point (kg m^2). When short keys change a body's mass, centre of mass or joint
    point, its inertia about the joint of its @ key is what stays (as the built-in arm's I0 and I1
    do); paths keep the description's meaning (the inertia about the centre of mass stays).
    ModelError naming ``name=value`` for an unknown name (listing the short keys and paths) or a
    bad value."""
    short, paths = dict(model.keys), change_paths(model)
    about = {target: (_target_value(model, target), None) for target in short.values() if parse_target(target)[2]}
    inertia_paths = set()  # set by a path: kept as given
    for name, value in pairs:
        label = f"{name}={value}"
        if name not in short and name not in paths:
            listed = [f"{key} ({target})" for key, target in short.items()] + paths
            raise ModelError(label, "", unknown_name_message(f"key of model {model.name!r}", name, listed))
        negated, path, joint = parse_target(short[name]) if name in short else (False, name, None)
        number = -_float(value, label) if negated else _float(value, label)
        if joint is not None:
            about[short[name]] = (number, label)
            continue
        before, model = model, _changed(model, path, number, label)
        if name not in short:
            inertia_paths |= {path} if path.endswith(".inertia") else set()
            continue
        for target, (held, held_label) in about.items():  # what this short key moved keeps its inertia
            if held_label is None and _moved(before, model, *parse_target(target)[1:]):
                about[target] = (held, label)
    for target, (value, label) in about.items():
        _, path, joint = parse_target(target)
        if label is not None and path not in inertia_paths:
            model = _inertia_about(model, path.rsplit(".", 1)[0], joint, value, label)
    return model


def _inertia_about(model: Model, body: str, joint: str, value: float, label: str) -> Model:
    """``model`` with the body's inertia (kg m^2) about the joint's point set to ``value``."""
    inertia = value - (inertia_about(model, body, joint) - model.body(body).inertia)
    if not inertia > 0:
        raise ModelError(label, f"{body}.inertia@{joint}",
                         f"the inertia about {joint}, {value:g} kg m^2, must be more than mass * distance^2 of the "
                         f"centre of mass from the joint ({value - inertia:g} kg m^2): the inertia about the centre "
                         "of mass must be positive")
    return _changed(model, f"{body}.inertia", inertia, label)


def _moved(before: Model, after: Model, path: str, joint: str) -> bool:
    """The mass, centre of mass of the body of ``path`` ('<body>.inertia') or the joint's point
    differ between the two models."""
    body = path.rsplit(".", 1)[0]
    old, new = before.body(body), after.body(body)
    return ((old.mass, old.com) != (new.mass, new.com)
            or _joint_point(before, body, joint) != _joint_point(after, body, joint))


def _changed(model: Model, path: str, value: float, label: str) -> Model:
    """with_changes of one path, its ModelError naming ``label`` and the path."""
    try:
        return with_changes(model, [(path, value)])
    except ModelError as exc:
        raise ModelError(label, exc.key or path, exc.problem) from None
