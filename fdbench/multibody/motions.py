"""Desired motions of a model's joints: objects that know their duration, their sample times and
the angles (rad), velocities (rad/s) and accelerations (rad/s^2) of every joint at any time t (s).

* ``MinimumJerk``: a named motion of a model file (``[[motions]]``, type 'minimum-jerk'): every
  joint from rest at its start angle to rest at its goal angle in ``duration`` s, sampled every
  1 ms, z(t) = z0 + (z1 - z0)(10 u^3 - 15 u^4 + 6 u^5), u = t / duration.
* ``PerJoint``: one single-joint motion (``fdbench.motion.Motion``) or a constant angle per joint;
  a recorded motion (``read_joint_motion_csv``) is one ``SampledMotion`` per joint.
* ``noisy_joints``: a motion captured with Gaussian noise and estimated like a recording.
* ``Resampled``: a motion reported on another grid.

The engine's angle constraints stay regular at any angle, so no angle is refused here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..motion import SAMPLE_DT, Motion, as_motion


class JointMotion:
    """A desired motion of the joints ``joints`` over [0, duration] s."""

    name: str = ""
    joints: tuple[str, ...] = ()

    @property
    def samples(self) -> np.ndarray:
        """The reporting grid, times (s) from 0 to the duration, shape (n,)."""
        raise NotImplementedError

    def __call__(self, t):
        """Angles (rad), velocities (rad/s), accelerations (rad/s^2) at times t (s), each of shape
        t.shape + (n_joints,)."""
        raise NotImplementedError

    @property
    def duration(self) -> float:
        """s."""
        return float(self.samples[-1])

    def describe(self) -> dict:
        """Fields that say which motion a result used."""
        return {"motion": self.name}


def _grid(duration: float, dt: float = SAMPLE_DT) -> np.ndarray:
    t = np.linspace(0.0, duration, int(round(duration / dt)) + 1)
    t.flags.writeable = False
    return t


class MinimumJerk(JointMotion):
    """A model's named minimum-jerk motion (``MotionSpec``) of ``joints`` (their order in the
    result), sampled every 1 ms."""

    def __init__(self, spec, joints):
        start, goal = dict(spec.start), dict(spec.goal)
        self.joints, self.name, self.T = tuple(joints), spec.name, float(spec.duration)
        self.start = np.array([start[joint] for joint in self.joints], dtype=float)
        self.goal = np.array([goal[joint] for joint in self.joints], dtype=float)
        if not self.T > 0:
            raise ValueError(f"the duration must be positive, got {self.T}")
        self._samples = None  # the 1 ms grid, made when asked for (a --sample-dt grid replaces it)

    @property
    def duration(self) -> float:
        return self.T

    @property
    def samples(self) -> np.ndarray:
        if self._samples is None:
            from ..memory import check_grid

            check_grid(self.T, SAMPLE_DT, "--sample-dt", len(self.joints))  # before the allocation
            self._samples = _grid(self.T)
        return self._samples

    def __call__(self, t):
        u = np.clip(np.asarray(t, dtype=float) / self.T, 0.0, 1.0)[..., None]
        span = self.goal - self.start
        shape = 10 * u**3 - 15 * u**4 + 6 * u**5
        rate = (30 * u**2 - 60 * u**3 + 30 * u**4) / self.T
        curvature = (60 * u - 180 * u**2 + 120 * u**3) / self.T**2
        return self.start + span * shape, span * rate, span * curvature


class PerJoint(JointMotion):
    """One single-joint motion (a ``Motion`` or a name such as 'paper') or a constant angle (rad)
    per joint of ``joints``; the samples are those of the first motion given (a constant has none:
    1 s every 1 ms)."""

    def __init__(self, parts, joints):
        if len(parts) != len(joints):
            raise ValueError("one motion or angle per joint is needed")
        self.parts = [float(p) if isinstance(p, (int, float)) else as_motion(p) for p in parts]
        motions = [p for p in self.parts if isinstance(p, Motion)]
        self._samples = motions[0].samples if motions else _grid(1.0)
        self.joints = tuple(joints)
        self.name = "+".join(p.name if isinstance(p, Motion) else f"{math.degrees(p):g}deg" for p in self.parts)

    @property
    def samples(self) -> np.ndarray:
        return self._samples

    @property
    def start_s(self) -> float:
        """The recording's own time (s) of the motion's time 0 (0 for an analytic motion)."""
        return next((p.start_s for p in self.parts if hasattr(p, "start_s")), 0.0)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        out = [np.zeros(t.shape + (len(self.parts),)) for _ in range(3)]
        for j, part in enumerate(self.parts):
            values = part(t) if isinstance(part, Motion) else (np.full(t.shape, part), 0.0, 0.0)
            for k in range(3):
                out[k][..., j] = values[k]
        return tuple(out)

    def describe(self) -> dict:
        """The motion's name, and how a recording's derivatives were obtained."""
        described = [p.describe() for p in self.parts if isinstance(p, Motion)]
        derivatives = described[0].get("derivatives") if described else None
        return {"motion": self.name} | ({"derivatives": derivatives} if derivatives else {})


class Resampled(JointMotion):
    """A joint motion reported on another grid: every ``sample_dt`` s over its span (the end included)."""

    def __init__(self, motion: JointMotion, sample_dt: float):
        from ..motion import sample_grid

        self.base, self.sample_dt, self.name, self.joints = motion, float(sample_dt), motion.name, motion.joints
        self._samples = sample_grid(motion.duration, sample_dt)

    @property
    def start_s(self) -> float:
        return self.base.start_s

    @property
    def samples(self) -> np.ndarray:
        return self._samples

    def __call__(self, t):
        return self.base(t)


def noisy_joints(motion: JointMotion, sigma_deg: float, seed: int, capture_hz: float, kinds=None,
                 **estimate) -> PerJoint:
    """``motion``'s joint angles captured with white Gaussian noise of ``sigma_deg`` degrees,
    independent per joint (seeded), and estimated like a recording (``estimate``: options of
    ``fdbench.motion.SampledMotion``). ``kinds``: per joint 'angle' or 'translation'
    (``Model.coordinate_kinds``; default all angles): translations are captured without noise (the
    angles draw the same numbers as without them). A recording keeps its own samples; an analytic
    motion is captured every 1 / capture_hz s. The result reports on ``motion``'s samples."""
    from ..motion import SampledMotion

    recorded = isinstance(motion, PerJoint) and all(isinstance(p, SampledMotion) for p in motion.parts)
    if not recorded:
        from ..memory import VALUES_PER_CAPTURED_SAMPLE, check_grid

        check_grid(motion.duration, 1 / capture_hz, "--capture-hz", len(motion.joints), VALUES_PER_CAPTURED_SAMPLE)
    t = (np.array(motion.parts[0]._t) if recorded
         else np.linspace(0.0, motion.duration, int(round(motion.duration * capture_hz)) + 1))
    angles, _, _ = motion(t)
    noise = np.random.default_rng(seed).standard_normal(angles.shape)
    if kinds is not None:
        noise[:, [kind == "translation" for kind in kinds]] = 0.0
    measured = angles + np.radians(sigma_deg) * noise
    parts = [SampledMotion(t, measured[:, j], name=joint, samples=motion.samples, absolute=False, **estimate)
             for j, joint in enumerate(motion.joints)]
    out = PerJoint(parts, motion.joints)
    where = "" if recorded else f" at {capture_hz:g} Hz"
    out.name = f"{motion.name}+noise {sigma_deg:g} deg{where} (seed {seed})"
    return out


def read_joint_motion_csv(path, joints, option: str = "--motion", radians: bool = False, kinds=None,
                          **estimate) -> PerJoint:
    """A recorded motion of ``joints`` from a CSV file with a header: ``t`` (s) and one angle column
    per joint (deg, or rad with ``radians``), names case-insensitive, any order, other columns
    ignored; optional ``<joint>_vel`` and ``<joint>_acc`` (deg/s, deg/s^2, or rad units), the
    derivatives otherwise estimated (``estimate``: options of ``fdbench.motion.SampledMotion``).
    An OpenSim storage file (.mot, .sto: ``fdbench.multibody.osim.read_storage``) gives its own
    unit by its header's ``inDegrees`` (``radians`` is not used). ``kinds``: per joint 'angle' or
    'translation' (``Model.coordinate_kinds``; default all angles): a translation's column is in m
    (m/s, m/s^2) whatever the angles' unit, as OpenSim writes it.
    Raises files.BadFile naming the file (and the joint) in one line."""
    from ..files import BadFile, quoted, read_columns, shown
    from ..motion import SampledMotion, given_rates, rate_column_names
    from .osim import is_storage, read_storage

    path, names = Path(path), [joint.lower() for joint in joints]
    optional = tuple(names) + tuple(rate for name in names for rate in rate_column_names(name))
    if is_storage(path):
        columns, in_degrees, _ = read_storage(path, option, joints)
        radians = not in_degrees
    else:
        columns = read_columns(path, option, required=("t",), optional=optional)
    for joint, name in zip(joints, names):
        if name not in columns:
            needed = "a time column and" if is_storage(path) else "columns t,"
            raise BadFile(f"{option}: {path} has no column for joint {quoted(joint)}; a motion file needs {needed} "
                          f"{shown(', '.join(joints), 200)} (angles in {'rad' if radians else 'deg'})")
    angle_unit = 1.0 if radians else math.pi / 180
    parts = []
    for joint, name, kind in zip(joints, names, kinds or ("angle",) * len(joints)):
        unit = 1.0 if kind == "translation" else angle_unit
        vel, acc = given_rates(columns, name, path, option, radians)
        try:
            parts.append(SampledMotion(columns["t"], columns[name] * unit, None if vel is None else vel * unit,
                                       None if acc is None else acc * unit, name=joint, absolute=False, **estimate))
        except ValueError as exc:
            raise BadFile(f"{option}: {path}: {shown(joint)}: {exc}") from None
    motion = PerJoint(parts, joints)
    motion.name = f"file:{path.name}"
    return motion


def joint_motion(name_or_path, model, radians: bool = False, **estimate) -> JointMotion:
    """A named motion of ``model`` (a ``Model``: its ``[[motions]]``) or a motion file of its joints
    (``read_joint_motion_csv``). ValueError listing the model's motions for a name that is neither;
    files.BadFile for a file that cannot be used."""
    text = str(name_or_path)
    for spec in model.motions:
        if spec.name == text:
            return MinimumJerk(spec, model.coordinates)
    from ..motion import KINEMATICS

    if text in KINEMATICS and len(model.coordinates) == 1:  # eq. 5's motions serve any one-joint model
        return PerJoint([text], model.coordinates)
    if text in KINEMATICS or not (Path(text).exists() or "/" in text or Path(text).suffix):
        from ..registry import unknown_name_message

        valid = [spec.name for spec in model.motions]
        if not valid:
            raise ValueError(f"--motion: model {model.name!r} declares no motion named {text!r} (it has none); give a "
                             f"CSV file with columns t, {', '.join(model.coordinates)}")
        raise ValueError("--motion: " + unknown_name_message(f"{model.name} motion", text, valid) + " or a CSV file")
    return read_joint_motion_csv(text, model.coordinates, "--motion", radians, model.coordinate_kinds, **estimate)
