"""What every desired motion is: its duration, sample times and the angles (rad), velocities
(rad/s) and accelerations (rad/s^2) of its joints at any time t (s) of [0, duration]: ``Motion``
for one coordinate (shaped like t), ``JointMotion`` for a model's joints (t.shape + (J,)).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from functools import cached_property

import numpy as np

SAMPLE_DT = 1e-3  # s, the sampling of a named motion's reported histories
MIN_SAMPLE_DT = 1e-4  # s


def read_only(array) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.flags.writeable = False
    return array


def grid(duration: float, dt: float = SAMPLE_DT) -> np.ndarray:
    """Times every ``dt`` s over [0, duration] (read-only), ``dt`` dividing the duration."""
    return read_only(np.linspace(0.0, duration, int(round(duration / dt)) + 1))


class Motion(ABC):
    """A desired motion of one coordinate over [0, duration] s."""

    name: str = ""

    @property
    @abstractmethod
    def samples(self) -> np.ndarray:
        """The reporting grid, times (s) from 0 to the duration, read-only, shape (n,)."""

    @abstractmethod
    def __call__(self, t):
        """theta (rad), theta' (rad/s), theta'' (rad/s^2) at times t (s), each shaped like t."""

    @property
    def duration(self) -> float:
        return float(self.samples[-1])

    @cached_property
    def uniform(self) -> bool:
        """True if the samples are equally spaced over [0, duration]."""
        ts = self.samples
        return bool(np.allclose(ts, np.linspace(0.0, ts[-1], len(ts)), rtol=0, atol=1e-12 * max(1.0, ts[-1])))

    @property
    def key(self) -> str:
        """What identifies the motion (its name, and a digest of its data where it has any)."""
        return self.name

    def describe(self) -> dict:
        """Fields that say which motion a result used."""
        return {"motion": self.name}

    def __eq__(self, other):
        return isinstance(other, Motion) and self.key == other.key

    def __hash__(self):
        return hash(self.key)

    def __repr__(self):
        return f"{type(self).__name__}({self.key!r})"


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


class PerJoint(JointMotion):
    """One single-coordinate ``Motion`` or a constant angle (rad) per joint of ``joints``; the
    samples are those of the first motion given (a constant has none: 1 s every 1 ms)."""

    def __init__(self, parts, joints):
        if len(parts) != len(joints):
            raise ValueError("one motion or angle per joint is needed")
        self.parts = [float(p) if isinstance(p, (int, float)) else p for p in parts]
        motions = [p for p in self.parts if isinstance(p, Motion)]
        self._samples = motions[0].samples if motions else grid(1.0)
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


def sample_grid(duration: float, sample_dt: float) -> np.ndarray:
    """Times every ``sample_dt`` s over [0, duration], the end included (read-only); ValueError for
    a step outside [MIN_SAMPLE_DT, duration]."""
    if not (math.isfinite(sample_dt) and MIN_SAMPLE_DT <= sample_dt <= duration):
        raise ValueError(f"--sample-dt must be in [{MIN_SAMPLE_DT:g}, {duration:g}] s, got {sample_dt}")
    from ...memory import check_grid

    check_grid(duration, sample_dt, "--sample-dt")
    times = np.arange(0.0, duration, sample_dt)
    if duration - times[-1] > 1e-9 * sample_dt:
        times = np.append(times, duration)
    else:
        times[-1] = duration
    return read_only(times)
