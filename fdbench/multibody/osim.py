"""OpenSim models and motions in: an ``.osim`` model as fdbench's planar description (what comes in,
what is dropped or refused: README, "OpenSim models"), OpenSim's storage files (``.mot``, ``.sto``)
as the columns of a motion; and ``to_osim``, a description as an ``.osim`` (XML, no OpenSim needed).

OpenSim (``pip install 'fdbench[opensim]'``, imported in a child process) builds the model and gives
its frames' transforms at the default pose. The plane is ground's x-y plane, its normal ground's z.
A one-coordinate joint whose child turns about a fixed axis through a fixed point becomes a pin
named after its coordinate. The axis is found numerically: the child offset frame M's rotation in
the parent offset frame F, at two values of the coordinate, turns by exactly the coordinate's change
about one axis, and M's origin does not move in F. With h the kept body (or ground) the parent is
welded to:

    at_parent = xy of X_hF * p_FM        (the joint point in the parent's frame)
    at_child  = xy of p_CM               (M's origin in the child's frame)
    offset    = planar angle of R_hF R_FM(q0) R_CM^T  -  q0

so that the child frame's angle relative to the parent's is coordinate + offset. Offsets along the
normal are dropped; an axis (or child frame's z, or gravity) within ``max_tilt_deg`` of the normal
is projected onto it. Welded and locked joints merge their child into the parent (parallel axes); a
CustomJoint whose translations are splines of its coordinate becomes a pin on a path (checked
against OpenSim's placement); a three-coordinate planar joint on ground becomes a ``free`` joint.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import __version__
from ..files import BadFile, quoted, read_input_bytes, read_input_text, shown
from ..isolation import python_command
from .model import GROUND, MIN_SEGMENT, ModelError, model_from_dict, to_dict
from .model_files import to_toml
from .osim_muscles import MAX_PATH_ERROR, imported_muscles
from .osim_muscles_out import check_muscles, osim_muscle
from .osim_muscles_out import frame_path as _frame_path
from .osim_muscles_out import numbers as _numbers
from .spline import fit

INSTALL_HINT = "pip install 'fdbench[opensim]'"
MAX_OSIM_BYTES = 64 * 2**20
STORAGE_SUFFIXES = (".mot", ".sto")
MOTION_NAME = "mid_range"
MOTION_DURATION = 1.0  # s
PROBE_STEP = 0.5  # rad: the change of a coordinate that reveals its joint's axis
SAME_POINT = 1e-9  # m: a joint's point that moves less than this is fixed
SAME_ANGLE = 1e-9  # rad
CHILD_TIMEOUT_S = 300  # s: OpenSim's import of one model (its start-up included)
ONE_THREAD = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}  # the fits' lstsq


def _fail(source: str, problem: str):
    raise ModelError(source, "", problem)


# ---------------------------------------------------------------------------------------- the model


def import_osim(path, max_tilt_deg: float = 5.0, option: str = "--model", max_path_error: float = MAX_PATH_ERROR):
    """(Model, notes): the planar description of the OpenSim model file ``path`` and the import's
    notes (one line each); ``max_path_error``: the largest error (m) of a muscle's path against
    OpenSim's lengths (``osim_muscles``). ModelError or files.BadFile (one line) when it cannot be
    imported."""
    source = str(path)
    content = read_input_bytes(path, option, MAX_OSIM_BYTES)
    return import_osim_content(content, source, max_tilt_deg, max_path_error)


def import_osim_content(content: bytes, source: str, max_tilt_deg: float = 5.0, max_path_error: float = MAX_PATH_ERROR):
    """``import_osim`` of a file's bytes (``source`` names it), in a child process: OpenSim's own
    CasADi cannot share a process with the casadi package."""
    import base64
    import json
    import os
    import subprocess
    import tempfile

    _model_element(content, source)  # a file that is not an OpenSim model is refused before a process starts
    import importlib.util

    if importlib.util.find_spec("opensim") is None:
        _fail(source, f"reading an OpenSim model needs the opensim package: {INSTALL_HINT}")
    request = json.dumps({"content": base64.b64encode(content).decode(), "source": source,
                          "max_tilt_deg": max_tilt_deg, "max_path_error": max_path_error})
    with tempfile.TemporaryDirectory(prefix="fdbench-osim-") as folder:  # a private working directory
        done = subprocess.run(python_command("from fdbench.multibody.osim import _child; _child()"),
                              input=request, capture_output=True, text=True, timeout=CHILD_TIMEOUT_S, cwd=folder,
                              env=os.environ | ONE_THREAD)
    try:
        answer = json.loads(done.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        _fail(source, f"OpenSim's import process failed (exit {done.returncode}): {shown(last, 300)}")
    if "error" in answer:
        raise ModelError(*answer["error"])
    return model_from_dict(answer["model"], source, default_name=Path(source).stem), tuple(answer["notes"])


def _child() -> None:
    """The child process of ``import_osim_content``: a request (JSON on stdin) in, the model's
    description and the notes, or the ModelError's parts, as one JSON line on stdout."""
    import base64
    import io
    import json
    import sys

    request = json.loads(sys.stdin.read())
    content, source = base64.b64decode(request["content"]), request["source"]
    real_stdout, sys.stdout = sys.stdout, io.StringIO()  # nothing but the answer on the pipe
    try:
        osim = _opensim(source)
        model, state = _built(osim, content, source)
        found, notes = _describe(osim, model, state, source, _model_element(content, source),
                                 request["max_tilt_deg"], request["max_path_error"])
        answer = {"model": to_dict(found), "notes": list(notes)}
    except ModelError as exc:
        answer = {"error": [exc.source, exc.key, exc.problem]}
    finally:
        sys.stdout = real_stdout
    print(json.dumps(answer))


def _model_element(content: bytes, source: str):
    """The <Model> element of the file's XML (checked before OpenSim reads it)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(content)
    except ET.ParseError as exc:
        _fail(source, f"not an OpenSim model file: not valid XML ({exc})")
    element = root if root.tag == "Model" else root.find("Model")
    if element is None:
        _fail(source, f"not an OpenSim model file: its root element is <{root.tag}>, expected <OpenSimDocument> "
                      "holding a <Model>")
    return element


def _opensim(source: str):
    """The ``opensim`` module, its log silenced (it writes to standard output)."""
    try:
        import opensim
    except ImportError:
        _fail(source, f"reading an OpenSim model needs the opensim package: {INSTALL_HINT}")
    opensim.Logger.setLevelString("Off")
    return opensim


def _built(osim, content: bytes, source: str):
    """(opensim.Model, its default state) of the file's bytes, read from a private copy."""
    import os
    import tempfile

    with tempfile.TemporaryDirectory(prefix="fdbench-osim-") as folder:
        copy = os.path.join(folder, "model.osim")
        with open(copy, "wb") as handle:
            handle.write(content)
        try:
            model = osim.Model(copy)
            state = model.initSystem()
        except Exception as exc:  # noqa: BLE001 - OpenSim's errors are RuntimeErrors of many kinds
            _fail(source, f"OpenSim cannot build this model: {shown(str(exc).replace(copy, Path(source).name), 300)}")
    return model, state


def _describe(osim, model, state, source: str, element, max_tilt_deg: float, max_path_error: float = MAX_PATH_ERROR):
    _refuse_constraints(model, source)
    joints = _joints_by_child(model, source)
    kept, welded, tilts, refused = [], [], [], []
    hosts = {GROUND: (GROUND, np.eye(3), np.zeros(3))}
    for joint in _tree_order(joints, source):
        parent, child = _body_name(joint.getParentFrame()), _body_name(joint.getChildFrame())
        free = [joint.get_coordinates(i) for i in range(joint.numCoordinates())
                if not joint.get_coordinates(i).getDefaultLocked()]
        if not free:
            hosts[child] = _welded_host(hosts[parent], joint, state)
            welded.append(f"{shown(child)} ({_weld_reason(joint)}) into {shown(hosts[parent][0])}")
            continue
        hosts[child] = (child, np.eye(3), np.zeros(3))
        try:
            if len(free) == 3 and hosts[parent][0] == GROUND:
                pin, tilt = _free_joint(model, state, joint, free, hosts[parent], max_tilt_deg)
            else:
                pin, tilt = _pin(osim, model, state, joint, free, hosts[parent], max_tilt_deg)
        except _Refused as exc:
            refused.append(f"joint {quoted(joint.getName())} ({joint.getConcreteClassName()}) {exc}")
            continue
        kept.append(pin)
        tilts += tilt
    if refused:
        more = f"; and {len(refused) - 3} more joints" if len(refused) > 3 else ""
        _fail(source, f"cannot be imported: {'; '.join(refused[:3])}{more}; fdbench imports planar trees of pin joints (one "
                      f"coordinate, the axis within --max-tilt {max_tilt_deg:g} deg of the plane's normal z, the "
                      "joint's point fixed or on a path of the coordinate) and one free planar joint on ground")
    gravity, gravity_tilt = _gravity(model, source, max_tilt_deg)
    bodies = _merged_bodies(model, hosts, [pin["child"] for pin in kept])
    loads = _constant_loads(osim, model, hosts, {pin["child"] for pin in kept})
    data = {"name": _text(model.getName(), 100) or Path(source).stem,
            "description": _description(model, source, element), "gravity": gravity,
            "bodies": _with_ends(bodies, kept), "joints": kept, "loads": list(loads.values()),
            "motions": [_mid_range(kept)], "frames": _welded_frames(hosts, {pin["child"] for pin in kept})}
    description = model_from_dict(data, source, default_name=Path(source).stem)
    data["muscles"], muscle_notes = imported_muscles(osim, model, state, description, hosts, source, max_path_error)
    if data["muscles"]:
        description = model_from_dict(data, source, default_name=Path(source).stem)
    actuators, actuator_names, actuator_note = _coordinate_actuators(osim, model, description)
    if actuators:
        data["actuators"] = actuators
        description = model_from_dict(data, source, default_name=Path(source).stem)
    kept_forces = set(loads) | {muscle["name"] for muscle in data["muscles"]} | actuator_names
    notes = [note for note in (_dropped_note(osim, model, kept_forces), actuator_note, _welded_note(welded),
                               _tilt_note(tilts + gravity_tilt), *muscle_notes) if note]
    return description, tuple(notes)


def _body_name(frame) -> str:
    return frame.findBaseFrame().getName()


def _refuse_constraints(model, source: str) -> None:
    for constraint in model.getConstraintSet():
        if constraint.get_isEnforced():
            _fail(source, f"constraint {quoted(constraint.getName())} ({constraint.getConcreteClassName()}): fdbench imports "
                          "trees without constraints (no closed loops or coupled coordinates)")


def _joints_by_child(model, source: str) -> dict:
    """{child body: joint}; a body with two parent joints (a closed loop) is refused."""
    joints = {}
    for joint in model.getJointSet():
        child = _body_name(joint.getChildFrame())
        if child in joints:
            _fail(source, f"joint {quoted(joint.getName())}: body {quoted(child)} is already the child of joint "
                          f"{quoted(joints[child].getName())} (a closed loop); fdbench imports trees")
        joints[child] = joint
    for body in model.getBodySet():
        if body.getName() not in joints:
            _fail(source, f"body {quoted(body.getName())} is attached by no joint; every body must hang from ground")
    return joints


def _tree_order(joints: dict, source: str) -> list:
    """The joints, each after the joint of its parent body (file order among those ready)."""
    order, placed = [], {GROUND}
    pending = list(joints.values())
    while pending:
        ready = [joint for joint in pending if _body_name(joint.getParentFrame()) in placed]
        if not ready:
            _fail(source, f"joint {quoted(pending[0].getName())}: its parent has no path to ground; fdbench imports trees")
        for joint in ready:
            order.append(joint)
            placed.add(_body_name(joint.getChildFrame()))
            pending.remove(joint)
    return order


def _weld_reason(joint) -> str:
    if joint.numCoordinates() == 0:
        return f"{joint.getConcreteClassName()} {quoted(joint.getName())}"
    names = shown(", ".join(joint.get_coordinates(i).getName() for i in range(joint.numCoordinates())))
    return f"joint {quoted(joint.getName())}, coordinate {names} locked"


# ---------------------------------------------------------------------------------------- frames


def _transform(transform) -> tuple[np.ndarray, np.ndarray]:
    """(R, p) of a SimTK Transform."""
    R, p = transform.R(), transform.p()
    return (np.array([[R.get(i, j) for j in range(3)] for i in range(3)]), np.array([p.get(i) for i in range(3)]))


def _compose(first, second):
    """X_AC from X_AB and X_BC, each (R, p)."""
    return first[0] @ second[0], first[0] @ second[1] + first[1]


def _inverse(transform):
    R, p = transform
    return R.T, -R.T @ p


def _in_base(frame):
    """X_BF: the offset frame F in its body B."""
    return _transform(frame.findTransformInBaseFrame())


def _between(state, joint):
    """X_FM: the child offset frame M in the parent offset frame F at ``state``."""
    return _transform(joint.getChildFrame().findTransformBetween(state, joint.getParentFrame()))


def _welded_host(parent_host, joint, state):
    """(host, R, p) of a welded child: the parent's host and the child's frame in it."""
    host, R, p = parent_host
    X_PC = _compose(_compose(_in_base(joint.getParentFrame()), _between(state, joint)),
                    _inverse(_in_base(joint.getChildFrame())))
    R_hC, p_hC = _compose((R, p), X_PC)
    return host, R_hC, p_hC


def _welded_frames(hosts: dict, kept: set) -> list[dict]:
    """A description's frame for each body welded into a kept one (its name, host, origin and
    angle in the host's frame), so that loads given on or in the welded body find it."""
    return [{"name": name, "body": host, "at": _xy(p), "angle": math.atan2(R[1, 0], R[0, 0])}
            for name, (host, R, p) in hosts.items() if host in kept and host != name]


def _angle_axis(R: np.ndarray) -> tuple[float, np.ndarray]:
    """(angle in [0, pi], unit axis) of a rotation matrix."""
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    angle = math.atan2(np.linalg.norm(w) / 2, (np.trace(R) - 1) / 2)
    norm = np.linalg.norm(w)
    return angle, (w / norm if norm > 0 else np.array([0.0, 0.0, 1.0]))


def _off_normal(vector: np.ndarray) -> float:
    """deg: the angle of ``vector`` from +z."""
    return math.degrees(math.acos(max(-1.0, min(1.0, vector[2] / np.linalg.norm(vector)))))


# ---------------------------------------------------------------------------------------- pins


class _Refused(Exception):
    """Why a joint cannot be imported (completed by the joint's name)."""


def _pin(osim, model, state, joint, free: list, parent_host, max_tilt_deg: float):
    """(the description's joint, [(tilt deg, what)]) of a one-coordinate joint about a fixed axis,
    its point fixed or on a path of the coordinate."""
    if len(free) > 1:
        raise _Refused(f"has {len(free)} free coordinates ({shown(', '.join(c.getName() for c in free))}): a 3D joint, or "
                       "a free planar base not on ground")
    coordinate, name = free[0], joint.getName()
    q0 = coordinate.getValue(state)
    samples = []
    for q in (q0 + PROBE_STEP, q0 - PROBE_STEP, q0):
        coordinate.setValue(state, q, False)
        model.realizePosition(state)
        samples.append((coordinate.getValue(state), _between(state, joint)))
    (q1, X1), (q2, X2), (q0, X0) = samples
    moves = max(np.linalg.norm(X1[1] - X0[1]), np.linalg.norm(X2[1] - X0[1])) > SAME_POINT
    axis = _rotation_axis(X0[0], X1[0], q1 - q0, coordinate)
    if not np.allclose(_axis_rotation(axis, q2 - q0) @ X0[0], X2[0], atol=SAME_ANGLE):
        raise _Refused(f"turns its child about more than one axis with coordinate {quoted(coordinate.getName())}")
    host, R_hP, p_hP = parent_host
    X_hF = _compose((R_hP, p_hP), _in_base(joint.getParentFrame()))
    X_CM = _in_base(joint.getChildFrame())
    R_hC = X_hF[0] @ X0[0] @ X_CM[0].T
    tilts = [(_off_normal(X_hF[0] @ axis), f"{shown(name)}'s axis"), (_off_normal(R_hC[:, 2]), f"{shown(name)}'s child frame")]
    for (tilt, _), what in zip(tilts, ("axis", "child frame")):
        if tilt > 90:
            raise _Refused(f"has its {what} along -z ({tilt:.3g} deg from +z): fdbench's coordinates turn "
                           "counter-clockwise about +z")
        if tilt > max_tilt_deg:
            raise _Refused(f"has its {what} {tilt:.3g} deg off the plane's normal z")
    offset = math.atan2(R_hC[1, 0], R_hC[0, 0]) - q0
    pin = {"name": coordinate.getName(), "type": "pin", "parent": host, "child": _body_name(joint.getChildFrame()),
           "at_parent": _xy(X_hF[0] @ X0[1] + X_hF[1]), "at_child": _xy(X_CM[1]),
           "offset": math.remainder(offset, 2 * math.pi)}
    if moves:
        pin["at_parent"], pin["path"] = _path(osim, model, state, joint, coordinate, X_hF)
    low, high = coordinate.getRangeMin(), coordinate.getRangeMax()
    if math.isfinite(low) and math.isfinite(high) and low < high:
        pin["limits"] = [low, high]
    pin["_coordinates"] = [(coordinate.getName(), q0, pin.get("limits"))]
    return pin, tilts


# ---------------------------------------------------------------------------------------- paths and free joints

PATH_CHECKS = 41  # values of the coordinate at which an imported path is checked against OpenSim's
PATH_TOLERANCE = 1e-9  # m


def _path(osim, model, state, joint, coordinate, X_hF):
    """(at_parent, path) of a CustomJoint whose translations are functions of its coordinate q: the
    child's point in the host's frame is at_parent + path(q), checked against OpenSim's."""
    custom = osim.CustomJoint.safeDownCast(joint)
    name = coordinate.getName()
    if custom is None:
        raise _Refused(f"moves its child with coordinate {quoted(name)} and is not a CustomJoint")
    transform = custom.getSpatialTransform()
    constant, varying = np.zeros(3), []  # the translation in F: constant + sum of axis * f(q)
    for i in range(3, 6):
        axis_of = transform.getTransformAxis(i)
        names = axis_of.getCoordinateNamesInArray()
        axis = np.array([axis_of.getAxis().get(k) for k in range(3)])
        samples = _function_samples(osim, axis_of.getFunction(), f"{shown(axis_of.getName())} of {quoted(name)}")
        if names.getSize() == 0 or samples[1] is None:
            constant += axis * (samples[0] if samples[1] is None else _constant_of(osim, axis_of.getFunction()))
            continue
        if names.getSize() != 1 or names.get(0) != name:
            raise _Refused(f"translates its child by a function of coordinates other than {quoted(name)}")
        varying.append((X_hF[0] @ axis, samples))
    at_parent = _xy(X_hF[0] @ constant + X_hF[1])
    path = _planar_path(varying, name)
    _check_path(model, state, joint, coordinate, X_hF, at_parent, path)
    return at_parent, path


def _function_samples(osim, function, what: str):
    """(knots, values) of a function of one coordinate as OpenSim's SimmSpline through them, or
    (value, None) for a constant."""
    multiplier = osim.MultiplierFunction.safeDownCast(function)
    scale = 1.0
    while multiplier is not None:
        scale *= multiplier.getScale()
        function = multiplier.getFunction()
        multiplier = osim.MultiplierFunction.safeDownCast(function)
    constant = osim.Constant.safeDownCast(function)
    if constant is not None:
        return scale * constant.getValue(), None
    spline = osim.SimmSpline.safeDownCast(function)
    if spline is not None:
        knots = [spline.getX(i) for i in range(spline.getSize())]
        return knots, [scale * spline.getY(i) for i in range(spline.getSize())]
    linear = osim.LinearFunction.safeDownCast(function)
    if linear is not None:  # a line is the spline through two of its points
        slope, intercept = linear.getSlope(), linear.getIntercept()
        return [-1.0, 1.0], [scale * (intercept - slope), scale * (intercept + slope)]
    raise _Refused(f"has a {function.getConcreteClassName()} as {what}: fdbench imports paths of SimmSpline, "
                   "Constant and LinearFunction (in MultiplierFunction)")


def _constant_of(osim, function) -> float:
    """The value of a function that names no coordinate (OpenSim evaluates it at 0)."""
    return float(function.calcValue(osim.Vector(1, 0.0)))


def _planar_path(varying: list, name: str) -> dict:
    """The description's path {angles, x, y[, y_angles]} (host frame) of the varying translations:
    (host-frame axis (3,), (knots, values)) each. Two that share their knots add; otherwise each must
    lie along the host's x or its y."""
    if not varying:
        return {"angles": [-1.0, 1.0], "x": [0.0, 0.0], "y": [0.0, 0.0]}
    by_knots = {}
    for axis, (knots, values) in varying:
        total = by_knots.setdefault(tuple(knots), np.zeros((2, len(knots))))
        total += np.outer(axis[:2], values)
    if len(by_knots) == 1:
        (knots, xy), = by_knots.items()
        return {"angles": list(knots), "x": xy[0].tolist(), "y": xy[1].tolist()}
    along = {}  # 0: x, 1: y -> (knots, values)
    for knots, xy in by_knots.items():
        moving = [k for k in (0, 1) if np.any(xy[k] != 0.0)]
        if len(moving) != 1 or moving[0] in along:
            raise _Refused(f"translates its child along a path of {quoted(name)} whose two components have different "
                           "knots and do not lie along the parent's x and y axes")
        along[moving[0]] = (list(knots), xy[moving[0]].tolist())
    x_knots, x_values = along.get(0, (along[1][0], [0.0] * len(along[1][0])))
    y_knots, y_values = along.get(1, (x_knots, [0.0] * len(x_knots)))
    path = {"angles": x_knots, "x": x_values, "y": y_values}
    return path | ({"y_angles": y_knots} if y_knots != x_knots else {})


def _check_path(model, state, joint, coordinate, X_hF, at_parent, path) -> None:
    """The child's point from at_parent + path against OpenSim's at PATH_CHECKS values."""
    try:
        x_of, y_of = fit(path["angles"], path["x"]), fit(path.get("y_angles", path["angles"]), path["y"])
    except ValueError:
        knots = path["angles"] if np.any(np.diff(path["angles"]) <= 0) else path.get("y_angles", path["angles"])
        raise _Refused(f"moves its child along a path of coordinate {quoted(coordinate.getName())} whose spline knots "
                       f"({shown(' '.join(f'{k:g}' for k in knots), 60)}) are not strictly increasing") from None
    low, high = coordinate.getRangeMin(), coordinate.getRangeMax()
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        low, high = -math.pi, math.pi
    q0 = coordinate.getValue(state)
    worst = 0.0
    for q in np.linspace(low, high, PATH_CHECKS):
        coordinate.setValue(state, float(q), False)
        model.realizePosition(state)
        X = _between(state, joint)
        where = X_hF[0] @ X[1] + X_hF[1]
        worst = max(worst, abs(where[0] - at_parent[0] - float(x_of.evaluate(q))),
                    abs(where[1] - at_parent[1] - float(y_of.evaluate(q))))
    coordinate.setValue(state, q0, False)
    model.realizePosition(state)
    if worst > PATH_TOLERANCE:
        raise _Refused(f"moves its child along a path of {quoted(coordinate.getName())} that fdbench's spline does not "
                       f"reproduce (off by {worst:.3g} m)")


def _free_joint(model, state, joint, free: list, parent_host, max_tilt_deg: float):
    """(the description's free joint, [(tilt deg, what)]) of a joint on ground with three coordinates:
    one turning the child about z, two translating it along the host's x and y by their values."""
    host, R_hP, p_hP = parent_host
    X_hF = _compose((R_hP, p_hP), _in_base(joint.getParentFrame()))
    X_CM = _in_base(joint.getChildFrame())
    name, defaults = joint.getName(), [c.getValue(state) for c in free]
    X0 = _between(state, joint)
    roles = {}
    for coordinate, q0 in zip(free, defaults):
        coordinate.setValue(state, q0 + PROBE_STEP, False)
        model.realizePosition(state)
        X1 = _between(state, joint)
        coordinate.setValue(state, q0, False)
        model.realizePosition(state)
        turn, moved = _angle_axis(X1[0] @ X0[0].T)[0], X_hF[0] @ (X1[1] - X0[1]) / PROBE_STEP
        if turn > SAME_ANGLE and np.linalg.norm(X1[1] - X0[1]) <= SAME_POINT:
            roles.setdefault("angle", []).append((coordinate, q0, X1))
        elif turn <= SAME_ANGLE and np.allclose(moved, [1.0, 0.0, 0.0], atol=1e-9):
            roles.setdefault("x", []).append((coordinate, q0, X1))
        elif turn <= SAME_ANGLE and np.allclose(moved, [0.0, 1.0, 0.0], atol=1e-9):
            roles.setdefault("y", []).append((coordinate, q0, X1))
        else:
            raise _Refused(f"has coordinate {quoted(coordinate.getName())} that neither turns its child about a fixed point "
                           "nor moves it along the ground's x or y by its value: not a free planar joint")
    if any(len(roles.get(role, ())) != 1 for role in ("angle", "x", "y")):
        raise _Refused("has three coordinates that are not one angle and the translations along x and y")
    (angle, q_angle, X1), = roles["angle"]
    axis = _rotation_axis(X0[0], X1[0], PROBE_STEP, angle)
    R_hC = X_hF[0] @ X0[0] @ X_CM[0].T
    tilts = [(_off_normal(X_hF[0] @ axis), f"{shown(name)}'s axis"), (_off_normal(R_hC[:, 2]), f"{shown(name)}'s child frame")]
    for (tilt, _), what in zip(tilts, ("axis", "child frame")):
        if tilt > 90 or tilt > max_tilt_deg:
            raise _Refused(f"has its {what} {tilt:.3g} deg off the plane's normal z")
    (x, q_x, _), = roles["x"]
    (y, q_y, _), = roles["y"]
    origin = X_hF[0] @ X0[1] + X_hF[1] - np.array([q_x, q_y, 0.0])  # the child's point at x = y = 0
    entry = {"name": name, "type": "free", "coordinates": [angle.getName(), x.getName(), y.getName()],
             "parent": host, "child": _body_name(joint.getChildFrame()), "at_parent": _xy(origin),
             "at_child": _xy(X_CM[1]),
             "offset": math.remainder(math.atan2(R_hC[1, 0], R_hC[0, 0]) - q_angle, 2 * math.pi)}
    low, high = angle.getRangeMin(), angle.getRangeMax()
    if math.isfinite(low) and math.isfinite(high) and low < high:
        entry["limits"] = [low, high]
    entry["_coordinates"] = [(angle.getName(), q_angle, entry.get("limits")), (x.getName(), q_x, None),
                             (y.getName(), q_y, None)]
    return entry, tilts


def _rotation_axis(R0, R1, step: float, coordinate) -> np.ndarray:
    """The unit axis (in F) about which the child turns by +step from R0 to R1."""
    angle, axis = _angle_axis(R1 @ R0.T)
    if abs(angle - abs(step)) > SAME_ANGLE:
        raise _Refused(f"turns its child by {math.degrees(angle):.4g} deg when coordinate {quoted(coordinate.getName())} "
                       f"changes by {math.degrees(abs(step)):.4g} deg: its angle is not the coordinate")
    return axis if step > 0 else -axis


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation by ``angle`` (rad) about the unit ``axis``."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _xy(vector) -> list[float]:
    return [float(vector[0]), float(vector[1])]


def _gravity(model, source: str, max_tilt_deg: float):
    """([gx, gy] m/s^2, [(tilt deg, 'gravity')] or [])."""
    g = model.getGravity()
    g = np.array([g.get(i) for i in range(3)])
    norm = np.linalg.norm(g)
    if norm == 0:
        return [0.0, 0.0], []
    tilt = math.degrees(math.asin(min(1.0, abs(g[2]) / norm)))
    if tilt > max_tilt_deg:
        _fail(source, f"gravity {g.tolist()} is {tilt:.3g} deg off the model's plane (x-y), more than the tolerance "
                      f"{max_tilt_deg:g} deg (--max-tilt)")
    return _xy(g), [(tilt, "gravity")] if tilt > 0 else []


# ---------------------------------------------------------------------------------------- bodies


def _merged_bodies(model, hosts: dict, kept: list) -> list[dict]:
    """The kept bodies (in ``kept``'s order), each with the bodies welded to it."""
    parts = {name: [] for name in kept}
    for body in model.getBodySet():
        host, R, p = hosts[body.getName()]
        if host in parts:
            com = np.array([body.getMassCenter().get(i) for i in range(3)])
            I = _inertia_matrix(body.get_inertia())
            parts[host].append((body.getMass(), R @ com + p, R @ I @ R.T))
    return [_body(name, parts[name]) for name in kept]


def _inertia_matrix(vec6) -> np.ndarray:
    """3x3 inertia about the centre of mass from OpenSim's [Ixx Iyy Izz Ixy Ixz Iyz]."""
    xx, yy, zz, xy, xz, yz = (vec6.get(i) for i in range(6))
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def _body(name: str, parts: list) -> dict:
    """A description's body from (mass kg, com m, inertia kg m^2 about the com) parts in its frame."""
    mass = math.fsum(m for m, _, _ in parts)
    if len(parts) == 1 or mass == 0:
        com = parts[0][1]
    else:
        com = sum(m * c for m, c, _ in parts) / mass
    inertia = math.fsum(I[2, 2] + m * ((c[0] - com[0]) ** 2 + (c[1] - com[1]) ** 2) for m, c, I in parts)
    return {"name": name, "mass": mass, "com": _xy(com), "inertia": inertia}


def _with_ends(bodies: list, joints: list) -> list:
    """The bodies, with an explicit ``end`` where the default one (the first child joint's point)
    would be within 1 mm of the body's joint point: then the centre of mass, or 0.1 m along x."""
    for body in bodies:
        own = next(j for j in joints if j["child"] == body["name"])
        first = next((j for j in joints if j["parent"] == body["name"]), None)
        if first is None or math.dist(first["at_parent"], own["at_child"]) >= MIN_SEGMENT:
            continue
        far = math.dist(body["com"], own["at_child"]) >= MIN_SEGMENT
        body["end"] = body["com"] if far else [own["at_child"][0] + 0.1, own["at_child"][1]]
    return bodies


def _constant_loads(osim, model, hosts: dict, kept: set) -> dict:
    """{force name: the description's load} of each PrescribedForce that is a constant point force
    in ground's axes at a fixed point of a kept body (or of a body welded to one)."""
    loads = {}
    for force in model.getForceSet():
        prescribed = osim.PrescribedForce.safeDownCast(force)
        if prescribed is None or not prescribed.get_appliesForce():
            continue
        if not prescribed.getForceIsInGlobalFrame() or prescribed.getPointIsInGlobalFrame():
            continue
        vector = _constants(osim, prescribed.getForceFunctions())
        point = _constants(osim, prescribed.getPointFunctions(), empty=(0.0, 0.0, 0.0))
        torque = _constants(osim, prescribed.getTorqueFunctions(), empty=(0.0, 0.0, 0.0))
        frame = prescribed.getFrame()
        host, R, p = hosts.get(_body_name(frame), (None, None, None))
        if vector is None or point is None or torque is None or any(torque) or host not in kept:
            continue
        R_hF, p_hF = _compose((R, p), _in_base(frame))
        loads[force.getName()] = {"body": host, "at": _xy(R_hF @ np.array(point) + p_hF), "force": _xy(vector)}
    return loads


def _coordinate_actuators(osim, model, description) -> tuple[list[dict], set, str]:
    """([[actuators]] tables, the names of every CoordinateActuator and ActivationCoordinateActuator
    of the OpenSim model, a note naming those left out and why): one actuator per kept coordinate
    (the first), its optimal force kept (its control bounds and activation dynamics are not);
    named as in OpenSim where that name is free, else ``<coordinate>_reserve``."""
    from .actuators import default_name
    from .model import NAME_PATTERN

    taken = {name.lower() for name in [b.name for b in description.bodies] + [j.name for j in description.joints]
             + list(description.coordinates) + [f.name for f in description.frames]
             + [m.name for m in description.muscles]}
    entries, seen, dropped, driven = [], set(), [], set()
    for force in model.getForceSet():
        actuator = osim.CoordinateActuator.safeDownCast(force)
        if actuator is None:
            continue
        name = force.getName()
        seen.add(name)
        coordinate, optimal = actuator.get_coordinate(), actuator.getOptimalForce()
        reason = ("it applies no force" if not force.get_appliesForce() else
                  f"its coordinate {quoted(coordinate)} is not one of the model's" if coordinate not in
                  description.coordinates else
                  f"its optimal force {optimal:g} is not > 0" if not (math.isfinite(optimal) and optimal > 0) else
                  f"{quoted(coordinate)} already has one" if coordinate in driven else "")
        if reason:
            dropped.append(f"{quoted(name)} ({reason})")
            continue
        own = name if NAME_PATTERN.fullmatch(name) and name.lower() not in taken else default_name(coordinate)
        if own.lower() in taken:
            dropped.append(f"{quoted(name)} (its name and {quoted(own)} are taken)")
            continue
        taken.add(own.lower())
        driven.add(coordinate)
        entries.append({"name": own, "coordinate": coordinate, "optimal_force": optimal})
    note = f"dropped coordinate actuators: {shown('; '.join(dropped), 300)}" if dropped else ""
    return entries, seen, note


def _constants(osim, functions, empty=None):
    """The three values of a FunctionSet of Constant functions, ``empty`` for an empty set, or None."""
    if functions.getSize() == 0:
        return empty
    values = [osim.Constant.safeDownCast(functions.get(i)) for i in range(functions.getSize())]
    if len(values) != 3 or any(value is None for value in values):
        return None
    return tuple(value.getValue() for value in values)


# ---------------------------------------------------------------------------------------- the rest


def _mid_range(joints: list) -> dict:
    """The model's named motion: minimum jerk from the default values to the middle of the angles'
    ranges (a free joint's translations held at their defaults)."""
    start, goal = {}, {}
    for joint in joints:
        for name, default, limits in joint.pop("_coordinates"):
            low, high = limits or (default, default)
            start[name] = min(max(default, low), high)
            goal[name] = (low + high) / 2
    return {"name": MOTION_NAME, "type": "minimum-jerk", "duration": MOTION_DURATION, "start": start, "goal": goal}


def _text(value: str, limit: int) -> str:
    """One line of at most ``limit`` characters (whitespace collapsed, control characters dropped)."""
    line = " ".join("".join(c if c.isprintable() else " " for c in str(value)).split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _description(model, source: str, element) -> str:
    credits = element.findtext("credits") or ""
    text = f"OpenSim model {model.getName()} imported from {Path(source).name}"
    return _text(text + (f"; credits: {credits}" if credits.strip() else ""), 500)


def _dropped_note(osim, model, kept: set) -> str:
    """One line: what the import left out (empty if nothing); ``kept``: the forces made loads or muscles."""
    muscles, forces = {}, {}
    for force in model.getForceSet():
        if force.getName() in kept:
            continue
        kind = muscles if osim.Muscle.safeDownCast(force) is not None else forces
        name = force.getConcreteClassName()
        kind[name] = kind.get(name, 0) + 1
    wraps = sum(body.getWrapObjectSet().getSize() for body in model.getBodySet())
    wraps += model.getGround().getWrapObjectSet().getSize()
    imported = any(muscle.getName() in kept for muscle in model.getMuscles())  # wraps live on in their paths
    wraps = 0 if imported else wraps
    counts = [(sum(muscles.values()), "muscle", muscles), (sum(forces.values()), "other force", forces),
              (model.getMarkerSet().getSize(), "marker", {}), (wraps, "wrap object", {}),
              (model.getContactGeometrySet().getSize(), "contact geometry", {}),
              (model.getControllerSet().getSize(), "controller", {}), (model.getProbeSet().getSize(), "probe", {})]
    parts = [f"{n} {what}{'s' if n > 1 and what != 'contact geometry' else ''}"
             + (f" ({', '.join(kinds)})" if kinds else "") for n, what, kinds in counts if n]
    tail = "" if imported else ": the imported model is driven by joint torques"
    return f"dropped {', '.join(parts)}{tail}" if parts else ""


def _welded_note(welded: list) -> str:
    return f"welded into their parent: {'; '.join(welded)}" if welded else ""


def _tilt_note(tilts: list) -> str:
    if not tilts or max(tilts)[0] == 0:
        return ""
    angle, what = max(tilts)
    return f"projected onto the plane's normal (z): the largest angle off it is {angle:.2f} deg ({what})"


# ---------------------------------------------------------------------------------------- motions


def is_storage(path) -> bool:
    """True for an OpenSim storage file's name (.mot, .sto)."""
    return Path(str(path)).suffix.lower() in STORAGE_SUFFIXES


def read_storage(path, option: str, joints) -> tuple[dict, bool, list]:
    """({'t' and each of ``joints`` (lower case) present: arrays}, in_degrees, unused labels) of an
    OpenSim storage file (columns by coordinate or state path); files.BadFile in one line."""
    path = Path(path)
    lines = read_input_text(path, option).splitlines()
    end = next((i for i, line in enumerate(lines) if line.strip().lower() == "endheader"), None)
    if end is None:
        raise BadFile(f"{option}: {path} is not an OpenSim storage file: no 'endheader' line")
    settings = dict(line.strip().lower().split("=", 1) for line in lines[:end] if "=" in line)
    in_degrees = settings.get("indegrees", "no").strip() == "yes"
    rows = [(number, line.split()) for number, line in enumerate(lines[end + 1:], start=end + 2) if line.strip()]
    if not rows:
        raise BadFile(f"{option}: {path} has no column labels after 'endheader'")
    header_line, labels = rows[0]
    header = [_column_name(label) for label in labels]
    if "time" not in header:
        raise BadFile(f"{option}: {path} has no 'time' column after 'endheader'")
    wanted = {"time": "t"} | {joint.lower(): joint.lower() for joint in joints}
    for k, label in enumerate(header):
        first = header.index(label)
        if label in wanted and first != k:
            raise BadFile(f"{option}: {path} line {header_line}: columns {quoted(labels[first])} and "
                          f"{quoted(labels[k])} both name {quoted(label)} (labels are matched ignoring case); keep one")
    columns = {}
    for k, label in enumerate(header):
        if label in wanted:
            values = []
            for number, row in rows[1:]:
                try:
                    values.append(float(row[k]))
                except IndexError:
                    raise BadFile(f"{option}: {path} line {number}: {len(row)} value{'s' if len(row) != 1 else ''}, fewer than the {len(labels)} "
                                  f"column labels (no value for {quoted(labels[k])})") from None
                except ValueError:
                    raise BadFile(f"{option}: {path} line {number}: column {quoted(labels[k])} holds "
                                  f"{quoted(row[k], 20)} where numbers are expected") from None
            columns[wanted[label]] = np.array(values)
    unused = [label for label, name in zip(labels, header) if name not in wanted]
    return columns, in_degrees, unused


def _column_name(label: str) -> str:
    """A storage column's name, lower case; a state's value '/jointset/<joint>/<coordinate>/value' -> its coordinate."""
    parts = label.strip().lower().split("/")
    return parts[-2] if len(parts) > 2 and parts[-1] == "value" else label.strip().lower()


def storage_note(path, joints) -> str:
    """One line naming the columns of an OpenSim storage file that are not the model's coordinates
    (ignored), or '' (also for a file that cannot be read: its error comes when it is used)."""
    if not is_storage(path):
        return ""
    try:
        _, _, unused = read_storage(path, "--motion", joints)
    except BadFile:
        return ""
    return f"{path}: columns the model lacks were ignored: {shown(', '.join(unused), 200)}" if unused else ""


def toml_text(model, notes, source) -> str:
    """The imported model as a model file: a header of comments (the source, the notes) and the TOML."""
    header = [f"# Imported from the OpenSim model {Path(str(source)).name} by fdbench {__version__} import-osim.",
              "# SI units, angles in radians; world axes x forward, y up; joints named by OpenSim's coordinates."]
    header += [f"# note: {note}" for note in notes]
    return "\n".join(header) + "\n" + to_toml(model)


# ---------------------------------------------------------------------------------------- the model out

OSIM_VERSION = "40000"
DEFAULT_RANGE = (-math.pi, math.pi)  # rad: a coordinate's range in the file when its joint has no limits


def check_exportable(model) -> None:
    """ModelError (one line) for a model ``to_osim`` cannot write yet: one with free or path joints,
    or a polynomial muscle path too large for OpenSim's form (``osim_muscles_out.check_muscles``)."""
    odd = [j.name for j in model.joints if j.type == "free" or j.path is not None]
    if odd:
        raise ModelError(model.name, "", f"joints {', '.join(odd)} are free or on a path: export-osim writes pin "
                                         "joints only in this version")
    check_muscles(model)


def to_osim(model) -> str:
    """The description ``model`` (pin joints only) as an OpenSim model file (XML text): a ``Body``
    per body, a ``PinJoint`` about z, a ``CoordinateActuator`` per actuator of the model's
    ``[[actuators]]`` with its optimal force (a model without: one of 1 N m per joint), a constant
    ``PrescribedForce`` per load, a ``DeGrooteFregly2016Muscle`` per muscle (``osim_muscles_out``)."""
    check_exportable(model)

    credits = _text(f"written by fdbench {__version__} export-osim from the model {model.name}"
                    + (f": {model.description}" if model.description else ""), 500)
    parts = ['<?xml version="1.0" encoding="UTF-8" ?>', f'<OpenSimDocument Version="{OSIM_VERSION}">',
             f'<Model name="{_xml(model.name)}">', f"<credits>{_xml(credits)}</credits>",
             f"<gravity>{_numbers(*model.gravity, 0.0)}</gravity>",
             '<BodySet name="bodyset"><objects>', *map(_osim_body, model.bodies), "</objects></BodySet>",
             '<JointSet name="jointset"><objects>', *map(_osim_joint, model.joints), "</objects></JointSet>",
             '<ForceSet name="forceset"><objects>', *(_osim_load(k, load) for k, load in enumerate(model.loads)),
             *(_osim_actuator(a.coordinate, a.name, a.optimal_force) for a in model.actuators),
             *(_osim_actuator(joint.name) for joint in model.joints if not model.actuators),
             *(osim_muscle(muscle, model) for muscle in model.muscles), "</objects></ForceSet>",
             "</Model>", "</OpenSimDocument>"]
    return "\n".join(parts) + "\n"


def _xml(text: str) -> str:
    from xml.sax.saxutils import escape

    return escape(str(text), {'"': "&quot;"})


def _osim_body(body) -> str:
    inertia = float(body.inertia)
    return (f'<Body name="{body.name}"><mass>{_numbers(body.mass)}</mass>'
            f"<mass_center>{_numbers(*body.com, 0.0)}</mass_center>"
            f"<inertia>{_numbers(inertia, inertia, inertia, 0.0, 0.0, 0.0)}</inertia></Body>")


def _osim_frame(name: str, body: str, at, angle: float) -> str:
    return (f'<PhysicalOffsetFrame name="{name}"><socket_parent>{_frame_path(body)}</socket_parent>'
            f"<translation>{_numbers(*at, 0.0)}</translation>"
            f"<orientation>{_numbers(0.0, 0.0, angle)}</orientation></PhysicalOffsetFrame>")


def _osim_joint(joint) -> str:
    name = f"{joint.name}_joint"
    low, high = joint.limits if joint.limits is not None else DEFAULT_RANGE
    return (f'<PinJoint name="{name}"><socket_parent_frame>{name}_parent</socket_parent_frame>'
            f"<socket_child_frame>{name}_child</socket_child_frame>"
            f'<coordinates><Coordinate name="{joint.name}"><default_value>0</default_value>'
            f"<range>{_numbers(low, high)}</range></Coordinate></coordinates>"
            f"<frames>{_osim_frame(name + '_parent', joint.parent, joint.at_parent, joint.offset)}"
            f"{_osim_frame(name + '_child', joint.child, joint.at_child, 0.0)}</frames></PinJoint>")


def _constant_set(name: str, values) -> str:
    constants = "".join(f"<Constant><value>{_numbers(value)}</value></Constant>" for value in values)
    return f'<FunctionSet name="{name}"><objects>{constants}</objects></FunctionSet>'


def _osim_load(k: int, load) -> str:
    return (f'<PrescribedForce name="load{k}"><socket_frame>{_frame_path(load.body)}</socket_frame>'
            "<pointIsGlobal>false</pointIsGlobal><forceIsGlobal>true</forceIsGlobal>"
            f"{_constant_set('forceFunctions', (*load.force, 0.0))}"
            f"{_constant_set('pointFunctions', (*load.at, 0.0))}</PrescribedForce>")


def _osim_actuator(coordinate: str, name: str | None = None, optimal_force: float | None = None) -> str:
    name = f"{coordinate}_actuator" if name is None else name
    force = "1" if optimal_force is None else _numbers(optimal_force)
    return (f'<CoordinateActuator name="{name}"><coordinate>{coordinate}</coordinate>'
            f"<optimal_force>{force}</optimal_force></CoordinateActuator>")
