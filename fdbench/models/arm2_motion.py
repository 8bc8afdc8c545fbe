"""Desired motions of several joints: objects that know their duration, their sample times and
the angles (rad), velocities (rad/s) and accelerations (rad/s^2) of every joint at any time t (s).

* ``Reach`` (the default ``arm2`` motion, named ``reach``): a minimum-jerk point-to-point movement
  of both joints in 1 s, sampled every 1 ms, from rest to rest:

      z(t) = z0 + (z1 - z0) (10 u^3 - 15 u^4 + 6 u^5),  u = t / T,

  shoulder from -20 deg to 15 deg, elbow from 30 deg to 55 deg, so the forearm's absolute angle
  goes from 10 deg to 70 deg. Both stay at least 20 deg away from the mixed coordinates' singular
  configurations (shoulder or shoulder + elbow at +-90 deg) and the elbow never straightens
  (elbow = 0, the arm's own singularity).
* ``PerJoint``: one single-joint motion (``fdbench.motion.Motion``) or a constant angle per joint,
  e.g. the shoulder held at 0 while the elbow follows the paper's eq. 5.
"""

from __future__ import annotations

import math

import numpy as np

from ..motion import SAMPLE_DT, Motion, as_motion


class JointMotion:
    """A desired motion of n joints over [0, duration] s."""

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
        return float(self.samples[-1])

    def describe(self) -> dict:
        return {"motion": self.name}


def _grid(duration: float, dt: float = SAMPLE_DT) -> np.ndarray:
    t = np.linspace(0.0, duration, int(round(duration / dt)) + 1)
    t.flags.writeable = False
    return t


class Reach(JointMotion):
    """Minimum-jerk movement of every joint from ``start`` to ``goal`` (rad) in ``duration`` s."""

    name = "reach"

    def __init__(self, start=(math.radians(-20.0), math.radians(30.0)), goal=(math.radians(15.0), math.radians(55.0)),
                 duration: float = 1.0, joints=("shoulder", "elbow")):
        self.start, self.goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
        if self.start.shape != self.goal.shape or self.start.shape != (len(joints),):
            raise ValueError("start and goal need one angle per joint")
        if not duration > 0:
            raise ValueError(f"the duration must be positive, got {duration}")
        self.T, self.joints = float(duration), tuple(joints)
        self._samples = _grid(self.T)

    @property
    def samples(self) -> np.ndarray:
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
    per joint; the samples are those of the first motion given (a constant has none)."""

    def __init__(self, parts, joints=("shoulder", "elbow")):
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

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        out = [np.zeros(t.shape + (len(self.parts),)) for _ in range(3)]
        for j, part in enumerate(self.parts):
            values = part(t) if isinstance(part, Motion) else (np.full(t.shape, part), 0.0, 0.0)
            for k in range(3):
                out[k][..., j] = values[k]
        return tuple(out)


MOTIONS = {"reach": Reach}


def as_joint_motion(motion) -> JointMotion:
    """A JointMotion, or the name of one ('reach')."""
    if isinstance(motion, JointMotion):
        return motion
    if motion in MOTIONS:
        return MOTIONS[motion]()
    from ..registry import unknown_name_message

    raise ValueError(unknown_name_message("arm motion", str(motion), list(MOTIONS)))


def noisy_joints(motion: JointMotion, sigma_deg: float, seed: int, capture_hz: float, **estimate) -> PerJoint:
    """``motion``'s joint angles captured with white Gaussian noise of ``sigma_deg`` degrees,
    independent per joint (seeded), and estimated like a recording (``estimate``: options of
    ``fdbench.motion.SampledMotion``). A recording keeps its own samples; an analytic motion is
    captured every 1 / capture_hz s. The result reports on ``motion``'s samples."""
    from ..motion import SampledMotion

    recorded = isinstance(motion, PerJoint) and all(isinstance(p, SampledMotion) for p in motion.parts)
    if not recorded:
        from ..memory import VALUES_PER_CAPTURED_SAMPLE, check_grid

        check_grid(motion.duration, 1 / capture_hz, "--capture-hz", len(motion.joints), VALUES_PER_CAPTURED_SAMPLE)
    t = (np.array(motion.parts[0]._t) if recorded
         else np.linspace(0.0, motion.duration, int(round(motion.duration * capture_hz)) + 1))
    angles, _, _ = motion(t)
    measured = angles + np.radians(sigma_deg) * np.random.default_rng(seed).standard_normal(angles.shape)
    check_arm_angles(measured)
    parts = [SampledMotion(t, measured[:, j], name=joint, samples=motion.samples, absolute=False, **estimate)
             for j, joint in enumerate(motion.joints)]
    out = PerJoint(parts, motion.joints)
    where = "" if recorded else f" at {capture_hz:g} Hz"
    out.name = f"{motion.name}+noise {sigma_deg:g} deg{where} (seed {seed})"
    return out


def check_arm_angles(angles: np.ndarray) -> None:
    """ValueError unless the shoulder and the forearm's absolute angle (shoulder + elbow) stay
    clear of +-90 deg, where the arm's mixed coordinates are singular; angles (rad), shape (n, 2)
    [shoulder, elbow]. The elbow alone, a relative angle, may take any value."""
    from ..motion import check_clear_of_singular

    needs = "the arm needs the shoulder and shoulder + elbow clear of it (the elbow alone may take any angle)"
    check_clear_of_singular(angles[:, 0], "the shoulder", needs)
    check_clear_of_singular(angles[:, 0] + angles[:, 1], "shoulder + elbow (the forearm's angle)", needs)


class Resampled(JointMotion):
    """A joint motion reported on another grid: every ``sample_dt`` s over its span (the end included)."""

    def __init__(self, motion: JointMotion, sample_dt: float):
        from ..motion import sample_grid

        self.base, self.sample_dt, self.name, self.joints = motion, float(sample_dt), motion.name, motion.joints
        self._samples = sample_grid(motion.duration, sample_dt)

    @property
    def samples(self) -> np.ndarray:
        return self._samples

    def __call__(self, t):
        return self.base(t)
