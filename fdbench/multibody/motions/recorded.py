"""Recorded motions: joint angles at sample times, their rates given or estimated once on the
samples (a zero-lag Butterworth low-pass then an interpolating spline's derivatives, or a smoothing
spline): ``SampledMotion``, read from CSV or OpenSim storage files (``read_joint_motion_csv``), and
``noisy_joints``, a motion captured with white noise. A recording's times count from its first sample.
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

import numpy as np

from ...files import BadFile, quoted, read_columns, shown
from ...memory import VALUES_PER_CAPTURED_SAMPLE, check_grid
from ...models import PAPER, named_motions
from ...registry import unknown_name_message
from ..model import MAX_MAGNITUDE
from ..osim import is_storage, read_storage
from .base import JointMotion, Motion, PerJoint, read_only

DEFAULT_CUTOFF_HZ = 6.0
DEFAULT_CAPTURE_HZ = 100.0
FILTER_ORDER = 2  # a 2nd-order Butterworth run forward and backward: Winter's 4th-order zero-lag filter
SMOOTHING = ("butterworth", "spline")
MIN_SAMPLES = 10


class SampledMotion(Motion):
    """A motion known at times t (s, increasing, (n,), n >= 10): angles theta (rad, (n,)), rates
    theta_vel, theta_acc (rad/s, rad/s^2) given or None (estimated: ``smoothing`` 'butterworth',
    -3 dB at ``cutoff_hz``, or 'spline', ``spline_lambda`` None by cross-validation); smooth
    between samples. ``samples``: the reporting grid (default: t)."""

    def __init__(self, t, theta, theta_vel=None, theta_acc=None, *, name: str = "sampled",
                 cutoff_hz: float = DEFAULT_CUTOFF_HZ, smoothing: str = "butterworth", spline_lambda=None,
                 samples=None):
        t, theta = np.asarray(t, dtype=float), np.asarray(theta, dtype=float)
        check_samples(t, theta)
        self.name = name
        self.start_s = float(t[0])  # the recording's own time of its first sample (s): external loads' clock
        self._t = read_only(t - t[0])
        self.recorded = read_only(theta.copy())  # the raw angles (rad) at times self._t, for figures
        self._samples = self._t if samples is None else read_only(samples)
        self.cutoff_hz, self.smoothing, self.spline_lambda = cutoff_hz, smoothing, spline_lambda
        self.given_derivatives = theta_vel is not None and theta_acc is not None
        if self.given_derivatives:
            self._theta, self._vel, self._acc = self._interpolants_given(theta, np.asarray(theta_vel, float),
                                                                         np.asarray(theta_acc, float))
        else:
            self._theta, self._vel, self._acc = self._interpolants_estimated(theta)
        digest = hashlib.sha256(np.concatenate([t, theta]).tobytes())
        for extra in (theta_vel, theta_acc):
            if extra is not None:
                digest.update(np.asarray(extra, dtype=float).tobytes())
        self._digest = digest.hexdigest()[:16]

    @property
    def samples(self) -> np.ndarray:
        return self._samples

    @property
    def key(self) -> str:
        if self.given_derivatives:
            how = "given"
        elif self.smoothing == "spline":
            how = f"spline:{self.spline_lambda}"
        else:
            how = f"butterworth:{self.cutoff_hz!r}"
        return f"{self.name}#{self._digest}#{how}"

    def describe(self) -> dict:
        if self.given_derivatives:
            derivatives = "given"
        elif self.smoothing == "spline":
            derivatives = "smoothing spline" + ("" if self.spline_lambda is None else f" (lambda {self.spline_lambda:g})")
        else:
            derivatives = f"Butterworth {self.cutoff_hz:g} Hz zero-lag + spline"
        return {"motion": self.name, "derivatives": derivatives}

    def __call__(self, t):
        t = np.clip(np.asarray(t, dtype=float), 0.0, self._t[-1])
        return self._theta(t), self._vel(t), self._acc(t)

    def _interpolants_given(self, theta, vel, acc):
        from scipy.interpolate import CubicHermiteSpline, make_interp_spline  # scipy: start-up time

        for values, what, unit in ((vel, "the velocity", "rad/s (or m/s)"), (acc, "the acceleration", "rad/s^2 (or m/s^2)")):
            if values.shape != theta.shape:
                raise ValueError(f"{what} must have one value per sample")
            check_bounded(values, self._t + self.start_s, what, unit)
        # theta and theta' are each Hermite-interpolated with their own derivative: at the samples
        # the motion is exactly as given
        position = CubicHermiteSpline(self._t, theta, vel)
        velocity = CubicHermiteSpline(self._t, vel, acc)
        acceleration = make_interp_spline(self._t, acc, k=min(3, len(acc) - 1))
        return position, velocity, acceleration

    def _interpolants_estimated(self, theta):
        from scipy.interpolate import make_interp_spline, make_smoothing_spline

        if self.smoothing == "spline":
            spline = make_smoothing_spline(self._t, theta, lam=self.spline_lambda)
        else:
            uniform_t, uniform_theta = _uniform(self._t, theta)
            filtered = zero_lag_lowpass(uniform_theta, 1.0 / (uniform_t[1] - uniform_t[0]), self.cutoff_hz)
            spline = make_interp_spline(uniform_t, filtered, k=5)  # quintic: a smooth acceleration
        velocity, acceleration = spline.derivative(1), spline.derivative(2)
        for values, what, unit in ((velocity(self._t), "the estimated velocity", "rad/s (or m/s)"),
                                   (acceleration(self._t), "the estimated acceleration", "rad/s^2 (or m/s^2)")):
            check_bounded(values, self._t + self.start_s, what, unit)
        return spline, velocity, acceleration


def _uniform(t, theta):
    """The samples on a uniform grid of the same count (a recording with an irregular clock is
    interpolated by a cubic spline first), as the filter needs."""
    steps = np.diff(t)
    if np.ptp(steps) <= 1e-9 * np.mean(steps):
        return t, theta
    from scipy.interpolate import CubicSpline

    uniform = np.linspace(t[0], t[-1], len(t))
    return uniform, CubicSpline(t, theta)(uniform)


def butterworth_design_hz(cutoff_hz: float, rate_hz: float, passes: int = 2, order: int = FILTER_ORDER) -> float:
    """The design cutoff (Hz) of a digital Butterworth filter of ``order`` run ``passes`` times so
    that the whole has its -3 dB point at ``cutoff_hz`` (Winter's correction, exact for the
    bilinear transform): |H|^(2 passes) = 1/2 at the cutoff."""
    correction = (2 ** (1 / passes) - 1) ** (1 / (2 * order))
    return rate_hz / math.pi * math.atan(math.tan(math.pi * cutoff_hz / rate_hz) / correction)


def zero_lag_lowpass(values: np.ndarray, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    """Winter's zero-lag 4th-order Butterworth low-pass of ``values`` ((n,) at ``rate_hz``), -3 dB at
    ``cutoff_hz``; each end padded by its point reflection (as OpenSim's Signal::Pad) for as long
    as the filter takes to forget its start (``settling_samples``)."""
    from scipy.signal import butter, filtfilt

    if not 0 < cutoff_hz < rate_hz / 2:
        raise ValueError(f"the cutoff {cutoff_hz:g} Hz must be below half the sampling rate ({rate_hz / 2:.4g} Hz)")
    values = np.asarray(values, dtype=float)
    b, a = butter(FILTER_ORDER, butterworth_design_hz(cutoff_hz, rate_hz), fs=rate_hz)
    if not _settles(a, len(values)):
        lowest = _lowest_settling_cutoff(rate_hz, len(values), cutoff_hz)
        raise ValueError(f"the cutoff {cutoff_hz:g} Hz is too low for {len(values)} samples at {rate_hz:.4g} Hz: the "
                         f"filter would not forget its start within the recording; choose at least {lowest:.3g} Hz")
    pad = min(settling_samples(a), PAD_RECORDINGS * len(values))
    out = filtfilt(b, a, np.pad(values, pad, mode="reflect", reflect_type="odd"), padtype=None)
    return out[pad:pad + len(values)]


SETTLED = 1e-6  # the filter's start transient is forgotten when it has decayed to this fraction
PAD_RECORDINGS = 20  # at most this many times the recording's length of padding at each end


def _settles(a, count: int) -> bool:
    """True if the filter of denominator ``a`` is stable in double precision and forgets its start
    (``settling_samples``) within the padding of a recording of ``count`` samples."""
    return float(np.max(np.abs(np.roots(a)))) < 1.0 and settling_samples(a) <= PAD_RECORDINGS * count


def _lowest_settling_cutoff(rate_hz: float, count: int, below: float) -> float:
    """The lowest cutoff (Hz, above ``below``, rounded up to 3 digits) whose filter settles for a
    recording of ``count`` samples at ``rate_hz`` (``_settles``), by bisection on its logarithm."""
    from scipy.signal import butter

    low, high = math.log(below), math.log(0.49 * rate_hz)
    for _ in range(40):
        middle = 0.5 * (low + high)
        _, a = butter(FILTER_ORDER, butterworth_design_hz(math.exp(middle), rate_hz), fs=rate_hz)
        low, high = (low, middle) if _settles(a, count) else (middle, high)
    unit = 10.0 ** (math.floor(math.log10(math.exp(high))) - 2)
    return math.ceil(math.exp(high) / unit) * unit  # rounded up: the value shown settles


def settling_samples(a) -> int:
    """Samples in which the transients of the filter of denominator ``a`` decay to SETTLED."""
    radius = float(np.max(np.abs(np.roots(a))))
    return int(math.ceil(math.log(SETTLED) / math.log(radius)))


MIN_RECORDING_DT = 1e-5  # s: samples closer than this (faster than 100 kHz) are not a motion capture's


def check_samples(t: np.ndarray, theta: np.ndarray) -> None:
    """Times and angles a motion can be built from; ValueError with a one-line message. Values are
    bounded as a model file's numbers are (``model.MAX_MAGNITUDE`` in SI units)."""
    if t.ndim != 1 or t.shape != theta.shape:
        raise ValueError("times and angles must be two columns of the same length")
    if len(t) < MIN_SAMPLES:
        raise ValueError(f"a motion needs at least {MIN_SAMPLES} samples, found {len(t)}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(theta))):
        raise ValueError("times and angles must be finite numbers (no NaN or empty cells)")
    check_bounded(theta, t, "the angle", "rad (or m)")
    steps = np.diff(t)
    if not (np.all(np.isfinite(steps)) and math.isfinite(t[-1] - t[0])):
        raise ValueError(f"times must be finite numbers apart, got {t[0]:g} to {t[-1]:g} s")
    if np.any(steps <= 0):
        raise ValueError("times must be strictly increasing")
    if steps.min() < MIN_RECORDING_DT * (1 - 1e-9):  # a 100 kHz clock's rounding is not refused
        k = int(np.argmin(steps))
        raise ValueError(f"samples at {t[k]:.10g} and {t[k + 1]:.10g} s are {steps[k]:.3g} s apart; a recording's "
                         f"samples must be at least {MIN_RECORDING_DT:g} s apart (at most {1 / MIN_RECORDING_DT:g} Hz): "
                         "are the times in seconds?")


def check_bounded(values: np.ndarray, t: np.ndarray, what: str, unit: str) -> None:
    """ValueError naming the first sample (its time t, s) where ``values`` are not finite or exceed
    a model file's bound on any number (``model.MAX_MAGNITUDE``), in ``unit``."""
    bad = ~(np.abs(values) <= MAX_MAGNITUDE)  # NaN included
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ValueError(f"{what} is {values[k]:.4g} {unit} at t = {t[k]:.10g} s; a motion's values must be finite "
                         f"and at most {MAX_MAGNITUDE:g} in magnitude")


def noisy(motion: Motion, sigma_deg: float, seed: int, capture_hz: float = DEFAULT_CAPTURE_HZ,
          **estimate) -> SampledMotion:
    """One coordinate's ``motion`` captured with noise and estimated like a recording: the one part
    of ``noisy_joints``, named like its result."""
    captured = noisy_joints(PerJoint([motion], ("theta",)), sigma_deg, seed, capture_hz, **estimate)
    part = captured.parts[0]
    part.name = captured.name
    return part


def rate_column_names(joint: str) -> tuple:
    """The columns a motion file may give for ``joint``'s rates: ``<joint>_vel``, ``<joint>_acc``
    and older fdbench's radian names ``<joint>_dot``, ``<joint>_ddot``."""
    return tuple(f"{joint}_{suffix}" for suffix in ("vel", "acc", "dot", "ddot"))


def given_rates(columns: dict, joint: str, path, option: str, radians: bool) -> tuple:
    """(velocity, acceleration) of ``joint`` as a motion file gives them (in the file's units), or
    (None, None). ``<joint>_dot``/``<joint>_ddot`` were written in radians by older fdbench: they
    are refused unless ``radians``, where they name the rates. Raises files.BadFile."""
    vel_name, acc_name, dot_name, ddot_name = rate_column_names(joint)
    if (dot_name in columns or ddot_name in columns) and not radians:
        raise BadFile(f"{option}: {path} has a column {dot_name if dot_name in columns else ddot_name}: it looks "
                      "like a file written in radians by an older fdbench; add --radians to read it")
    if radians and vel_name not in columns and acc_name not in columns:
        vel_name, acc_name = dot_name, ddot_name
    vel, acc = columns.get(vel_name), columns.get(acc_name)
    if (vel is None) != (acc is None):
        raise BadFile(f"{option}: {path} gives only one of {vel_name} and {acc_name}; give both or neither")
    return vel, acc


def read_motion_csv(path, option: str = "--motion", radians: bool = False, **estimate) -> SampledMotion:
    """The recorded angle ``theta`` (the forearm's joint) of a motion file: the one part of
    ``read_joint_motion_csv``, named like its result."""
    motion = read_joint_motion_csv(path, ("theta",), option, radians, **estimate)
    part = motion.parts[0]
    part.name = motion.name
    return part


def noisy_joints(motion: JointMotion, sigma_deg: float, seed: int, capture_hz: float, kinds=None,
                 **estimate) -> PerJoint:
    """``motion`` captured (a recording on its samples, else every 1 / capture_hz s) with seeded white
    Gaussian noise of ``sigma_deg`` deg per joint (none on the translations of ``kinds``) and
    estimated like a recording (``estimate``: options of ``SampledMotion``)."""
    recorded = isinstance(motion, PerJoint) and all(isinstance(p, SampledMotion) for p in motion.parts)
    if not recorded:
        check_grid(motion.duration, 1 / capture_hz, "--capture-hz", len(motion.joints), VALUES_PER_CAPTURED_SAMPLE)
    t = (np.array(motion.parts[0]._t) if recorded
         else np.linspace(0.0, motion.duration, int(round(motion.duration * capture_hz)) + 1))
    angles, _, _ = motion(t)
    noise = np.random.default_rng(seed).standard_normal(angles.shape)
    if kinds is not None:
        noise[:, [kind == "translation" for kind in kinds]] = 0.0
    measured = angles + np.radians(sigma_deg) * noise
    parts = [SampledMotion(t, measured[:, j], name=joint, samples=motion.samples, **estimate)
             for j, joint in enumerate(motion.joints)]
    out = PerJoint(parts, motion.joints)
    where = "" if recorded else f" at {capture_hz:g} Hz"
    out.name = f"{motion.name}+noise {sigma_deg:g} deg{where} (seed {seed})"
    return out


def read_joint_motion_csv(path, joints, option: str = "--motion", radians: bool = False, kinds=None,
                          **estimate) -> PerJoint:
    """A recorded motion of ``joints`` from a CSV file (``t`` s, an angle column per joint in deg,
    or rad with ``radians``, optional ``<joint>_vel``, ``<joint>_acc``) or an OpenSim storage file
    (its unit by ``inDegrees``); translations (``kinds``) in m. BadFile in one line."""
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
                                       None if acc is None else acc * unit, name=joint, **estimate))
        except ValueError as exc:
            raise BadFile(f"{option}: {path}: {shown(joint)}: {exc}") from None
    motion = PerJoint(parts, joints)
    motion.name = f"file:{path.name}"
    return motion


def check_estimate(cutoff_hz: float, smoothing: str, spline_lambda) -> None:
    """Options of the derivative estimate; ValueError with a one-line message."""
    if not (math.isfinite(cutoff_hz) and cutoff_hz > 0):
        raise ValueError(f"--cutoff must be a positive frequency in Hz, got {cutoff_hz}")
    if smoothing not in SMOOTHING:
        raise ValueError("--smoothing: " + unknown_name_message("smoothing", smoothing, list(SMOOTHING)))
    if spline_lambda is not None and not (math.isfinite(spline_lambda) and spline_lambda > 0):
        raise ValueError(f"--spline-lambda must be a positive number, got {spline_lambda}")


def check_source(source: str, option: str = "--motion (--kinematics)") -> None:
    """A motion of the forearm (the default model: ``fdbench.models.named_motions``) or an existing
    file; files.BadFile naming the valid names otherwise."""
    names = named_motions(PAPER)
    if source not in names and not os.path.exists(source):
        raise BadFile(f"{option}: {unknown_name_message('motion', source, list(names))}, and no file "
                      f"{source} exists (a recorded motion is a CSV file with columns t, theta)")
