"""External loads from data (a walk's ground reactions): on one body each, a force (N) at a point
(m) and a free moment (N m) about z, force and point in ground's axes or a body's frame, sampled at
the data's times and linear between them. The file is OpenSim's ExternalLoads (``--loads FILE.xml``)
and the storage file its ``datafile`` names; a force without a point acts at the body's origin; a
body welded into another on import is found as the host's named frame (``Model.frames``).

A load's generalised force on z is Q = sum over the joints m from ground to the body of
[(P - r_m) x F + d_m . F + M] on m's angle (d_m: a path joint's point direction per radian) and F
on a free joint's x and y: J_P(z)^T F, P the body's material point at that instant. In eq. 12's
mixed coordinates it is F on the body's joint point i and (P - r_i) x F + M on its angle.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..files import BadFile, quoted, read_input_bytes, shown
from ..registry import unknown_name_message
from .model import MAX_MAGNITUDE
from .osim import read_storage

GROUND = "ground"
MAX_LOADS = 100
MAX_PATH_CHARACTERS = 4096  # a <datafile> name (Linux's PATH_MAX)


@dataclass(frozen=True)
class ExternalLoad:
    """One load: its name, the model body it acts on, and the frames of its force and point
    ('ground' or a model body)."""

    name: str
    body: str
    force_frame: str = GROUND
    point_frame: str = GROUND


class ExternalLoads:
    """Loads sampled at times t (s, increasing, shape (n,)): force (N) and point (m) in each load's
    frames, shape (n, L, 2), free moment (N m), shape (n, L). ``source`` names the file."""

    def __init__(self, loads: tuple, t, force, point, moment, source: str = "loads"):
        self.loads, self.source = tuple(loads), source
        self.t = np.asarray(t, dtype=float)
        self.force, self.point = np.asarray(force, dtype=float), np.asarray(point, dtype=float)
        self.moment = np.asarray(moment, dtype=float)
        L, n = len(self.loads), len(self.t)
        if self.force.shape != (n, L, 2) or self.point.shape != (n, L, 2) or self.moment.shape != (n, L):
            raise ValueError(f"loads: force and point must have shape ({n}, {L}, 2) and moment ({n}, {L})")
        if n < 2 or not np.all(np.diff(self.t) > 0):
            raise ValueError(f"{source}: the loads' times must be at least two and increasing")

        for name, unit, values in (("force", "N", self.force), ("point", "m", self.point), ("moment", "N m", self.moment)):
            bad = ~(np.abs(values) <= MAX_MAGNITUDE)  # NaN included
            if np.any(bad):
                where = tuple(np.argwhere(bad)[0])
                raise ValueError(f"{source}: the {name} of load {quoted(self.loads[where[1]].name)} is {values[where]:.4g} "
                                 f"{unit} at t = {self.t[where[0]]:g} s; a load's values must be finite and at most "
                                 f"{MAX_MAGNITUDE:g} in magnitude")

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(force (k, L, 2), point (k, L, 2), moment (k, L)) at times t (s, shape (k,)), linear
        between samples; ValueError for a time outside the data's span."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if t.size:
            self.check_span(float(t.min()), float(t.max()))
        flat = np.concatenate([self.force.reshape(len(self.t), -1), self.point.reshape(len(self.t), -1),
                               self.moment], axis=1)
        values = np.stack([np.interp(t, self.t, column) for column in flat.T], axis=1)
        L = len(self.loads)
        return (values[:, :2 * L].reshape(-1, L, 2), values[:, 2 * L:4 * L].reshape(-1, L, 2),
                values[:, 4 * L:])

    def check_span(self, start: float, end: float) -> None:
        """ValueError (one line) unless the data cover [start, end] (s)."""
        slack = 1e-9 * max(1.0, abs(end))
        if start < self.t[0] - slack or end > self.t[-1] + slack:
            raise ValueError(f"{self.source}: the loads cover {self.t[0]:g} to {self.t[-1]:g} s of the motion's time, "
                             f"not all of {start:g} to {end:g} s")

    def shifted(self, t0: float) -> "ExternalLoads":
        """The loads on a clock starting at t0 (s): the motion's time 0 is the file's t0."""
        return ExternalLoads(self.loads, self.t - t0, self.force, self.point, self.moment, self.source)


# ---------------------------------------------------------------------- reading OpenSim's ExternalLoads
def _fail(option: str, path, problem: str):
    raise BadFile(f"{option}: {path}: {problem}")


def _text(element, tag: str, default: str = "", collapse: bool = True) -> str:
    """An element's text, stripped, its inner whitespace runs made one space unless not ``collapse``
    (a file name is kept as written)."""
    found = element.find(tag)
    if found is None or found.text is None:
        return default
    return " ".join(found.text.split()) if collapse else found.text.strip()


def _root_and_datafile(path: Path, option: str):
    """(the <ExternalLoads> element, the path of its data file)."""
    try:
        root = ElementTree.fromstring(read_input_bytes(path, option))
    except ElementTree.ParseError as exc:
        _fail(option, path, f"is not an XML file ({exc})")
    element = root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")
    if element is None:
        _fail(option, path, "has no <ExternalLoads> element (OpenSim's external loads file)")
    datafile = _text(element, "datafile", collapse=False)
    if not datafile:
        _fail(option, path, "names no <datafile> (the storage file of the forces)")
    if not datafile.isprintable() or len(datafile) > MAX_PATH_CHARACTERS:
        _fail(option, path, f"its <datafile> {quoted(datafile)} is not a file name (control characters, or more "
                            f"than {MAX_PATH_CHARACTERS} characters)")
    return element, Path(datafile) if Path(datafile).is_absolute() else path.parent / datafile


def _data_option(option: str, path: Path) -> str:
    """How messages about the data file name it: the option and the file that names it."""
    return f"{option} (the <datafile> of {path.name})"


def loads_digest(path, option: str = "--loads") -> str:
    """SHA-256 of an external loads file's content and of its data file's (a run's identity)."""
    import hashlib

    path = Path(path)
    _, data_path = _root_and_datafile(path, option)
    digest = hashlib.sha256(read_input_bytes(path, option))
    digest.update(b"\0" + read_input_bytes(data_path, _data_option(option, path)))
    return digest.hexdigest()


def data_file(path, option: str = "--loads") -> Path:
    """The data file an external loads file names (an input the outputs must not overwrite)."""
    return _root_and_datafile(Path(path), option)[1]


def read_external_loads(path, model, option: str = "--loads") -> ExternalLoads:
    """The loads of an OpenSim ExternalLoads file (XML) and the storage file it names, on ``model``
    (a ``Model``: bodies and welded frames resolved to its bodies). files.BadFile in one line."""
    path = Path(path)
    element, data_path = _root_and_datafile(path, option)
    forces = [f for f in element.iter("ExternalForce") if _text(f, "isDisabled", "false").lower() != "true"]
    if not forces:
        _fail(option, path, "has no enabled <ExternalForce>")
    if len(forces) > MAX_LOADS:
        _fail(option, path, f"has {len(forces)} forces; at most {MAX_LOADS}")
    loads, columns = [], []
    for force in forces:
        load, wanted = _external_force(force, model, option, path)
        loads.append(load)
        columns.append(wanted)
    names = [name for wanted in columns for group in wanted.values() for name in group]
    table, _, _ = read_storage(data_path, _data_option(option, path), names)
    for name in names:
        if name.lower() not in table:
            _fail(option, data_path, f"has no column {quoted(name)} (named by {path.name})")
    t = table["t"]
    n, L = len(t), len(loads)
    force, point, moment = np.zeros((n, L, 2)), np.zeros((n, L, 2)), np.zeros((n, L))
    for k, wanted in enumerate(columns):
        force[:, k] = np.stack([table[c.lower()] for c in wanted["force"]], axis=1)
        if wanted["point"]:
            point[:, k] = np.stack([table[c.lower()] for c in wanted["point"]], axis=1)
        if wanted["torque"]:
            moment[:, k] = table[wanted["torque"][0].lower()]
    force, point, loads = _in_model_frames(model, loads, force, point)
    try:
        return ExternalLoads(tuple(loads), t, force, point, moment, source=f"{option}: {path}")
    except ValueError as exc:
        _fail(option, data_path, str(exc).split(": ", 2)[-1])


def _external_force(force, model, option: str, path) -> tuple[ExternalLoad, dict]:
    """The load of one <ExternalForce> (frames as the file names them) and its columns."""
    name = force.get("name") or "force"
    body = _text(force, "applied_to_body")
    frames = {key: _text(force, f"{key}_expressed_in_body", GROUND) or GROUND for key in ("force", "point")}
    for what, frame in [("applied_to_body", body)] + [(f"{k}_expressed_in_body", v) for k, v in frames.items()]:
        if what == "applied_to_body" or frame.lower() != GROUND:
            try:
                model.frame(frame)
            except KeyError:
                known = [b.name for b in model.bodies] + [f.name for f in model.frames]
                _fail(option, path, f"ExternalForce {quoted(name)}: {what}: "
                                    + unknown_name_message("body", shown(frame), known + ([GROUND] if what != "applied_to_body" else [])))
    force_id, point_id, torque_id = (_text(force, f"{key}_identifier") for key in ("force", "point", "torque"))
    if not force_id:
        _fail(option, path, f"ExternalForce {quoted(name)} has no <force_identifier>")
    if not point_id:  # as OpenSim: a force without a point acts at the origin of the body it is applied to
        frames["point"] = body
    wanted = {"force": [force_id + "x", force_id + "y"], "point": [point_id + "x", point_id + "y"] if point_id else [],
              "torque": [torque_id + "z"] if torque_id else []}
    load = ExternalLoad(name, body, *(GROUND if frames[key].lower() == GROUND else frames[key]
                                      for key in ("force", "point")))
    return load, wanted


def _in_model_frames(model, loads: list, force, point):
    """Loads whose bodies and frames are the model's bodies: a named frame's values turned into its
    body's frame (force rotated, point moved), the applied body its host."""
    out = []
    for k, load in enumerate(loads):
        frames = []
        for key, values in (("force", force), ("point", point)):
            frame = getattr(load, f"{key}_frame")
            if frame == GROUND:
                frames.append(GROUND)
                continue
            host, at, angle = model.frame(frame)
            c, s = math.cos(angle), math.sin(angle)
            v = values[:, k].copy()
            values[:, k, 0], values[:, k, 1] = c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]
            if key == "point":
                values[:, k] += np.asarray(at)
            frames.append(host)
        out.append(ExternalLoad(load.name, model.frame(load.body)[0], *frames))
    return force, point, out
