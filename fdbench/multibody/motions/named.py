"""A model's named motions (``Model.motions``: 'minimum-jerk', z0 + (z1 - z0)(10 u^3 - 15 u^4 + 6 u^5)
with u = t / duration, or eq. 5's 'eq5-paper', 'eq5-exact') and the dispatch of ``--motion``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...memory import check_grid
from ...registry import unknown_name_message
from .base import SAMPLE_DT, JointMotion, PerJoint, grid
from .eq5 import Eq5
from .recorded import read_joint_motion_csv

EQ5_TYPES = {"eq5-paper": "paper", "eq5-exact": "exact"}  # a motion type -> eq. 5's variant


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
            check_grid(self.T, SAMPLE_DT, "--sample-dt", len(self.joints))  # before the allocation
            self._samples = grid(self.T)
        return self._samples

    def __call__(self, t):
        u = np.clip(np.asarray(t, dtype=float) / self.T, 0.0, 1.0)[..., None]
        span = self.goal - self.start
        shape = 10 * u**3 - 15 * u**4 + 6 * u**5
        rate = (30 * u**2 - 60 * u**3 + 30 * u**4) / self.T
        curvature = (60 * u - 180 * u**2 + 120 * u**3) / self.T**2
        return self.start + span * shape, span * rate, span * curvature


def named_motion(spec, joints) -> JointMotion:
    """The motion of a model's ``MotionSpec`` over ``joints`` (the model's coordinates)."""
    if spec.type in EQ5_TYPES:
        return PerJoint([Eq5(EQ5_TYPES[spec.type], spec.name)], joints)
    return MinimumJerk(spec, joints)


def joint_motion(name_or_path, model, radians: bool = False, **estimate) -> JointMotion:
    """A named motion of ``model`` (a ``Model``: its ``[[motions]]``) or a motion file of its joints
    (``read_joint_motion_csv``). ValueError listing the model's motions for a name that is neither;
    files.BadFile for a file that cannot be used."""
    text = str(name_or_path)
    for spec in model.motions:
        if spec.name == text:
            return named_motion(spec, model.coordinates)
    if not (Path(text).exists() or "/" in text or Path(text).suffix):
        valid = [spec.name for spec in model.motions]
        if not valid:
            raise ValueError(f"--motion: model {model.name!r} declares no motion named {text!r} (it has none); give a "
                             f"CSV file with columns t, {', '.join(model.coordinates)}")
        raise ValueError("--motion: " + unknown_name_message(f"{model.name} motion", text, valid) + " or a CSV file")
    return read_joint_motion_csv(text, model.coordinates, "--motion", radians, model.coordinate_kinds, **estimate)
