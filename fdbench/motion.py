"""Desired elbow motions: objects that know their duration, their sample times and theta (rad),
theta' (rad/s), theta'' (rad/s^2) at any time t (s) of [0, duration].

* ``paper`` and ``exact``: eq. 5 over [0, 1] s, sampled every 1 ms. ``paper`` takes the velocity
  and acceleration exactly as eq. 5 prints them, derivatives with respect to the warped time t*
  (this reproduces the paper's figures); ``exact`` takes derivatives with respect to t by the chain
  rule through t*(t) = a1 t + (1 - a1) t^2 (kinematically consistent).
* A recorded joint angle (``SampledMotion``, read by ``read_motion_csv``): times and angles, its
  velocity and acceleration either given or estimated as biomechanics does, once, on the motion's
  own samples: a zero-lag Butterworth low-pass then the derivatives of an interpolating spline, or
  a smoothing spline.
* ``noisy(motion, sigma_deg, seed)``: the angle of a motion sampled on a capture grid, with white
  Gaussian noise added, then estimated like a recording: what captured data looks like.

Times of a recording are counted from its first sample.
"""

from __future__ import annotations

import hashlib
import math
from abc import ABC, abstractmethod
from functools import cached_property

import numpy as np

A1 = 0.05
AMPLITUDE = np.pi / 4  # L of eq. 5, rad
T_FINAL = 1.0  # s, the duration of eq. 5
SAMPLE_DT = 1e-3  # s, the sampling of eq. 5's reported histories
KINEMATICS = ("paper", "exact")
DEFAULT_CUTOFF_HZ = 6.0
DEFAULT_CAPTURE_HZ = 100.0
FILTER_ORDER = 2  # a 2nd-order Butterworth run forward and backward: Winter's 4th-order zero-lag filter
SMOOTHING = ("butterworth", "spline")
MIN_SAMPLES = 10


class Motion(ABC):
    """A desired joint motion over [0, duration] s."""

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


def _read_only(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.flags.writeable = False
    return array


class PaperMotion(Motion):
    """Eq. 5 over [0, 1] s in one of the two kinematics variants, sampled every 1 ms."""

    def __init__(self, kinematics: str = "paper"):
        self.name = check_kinematics(kinematics)

    @property
    def samples(self) -> np.ndarray:
        return _SAMPLES

    def __call__(self, t):
        return eq5(t, self.name)


_SAMPLES = _read_only(np.linspace(0.0, T_FINAL, int(round(T_FINAL / SAMPLE_DT)) + 1))


def eq5(t, kinematics: str = "paper"):
    """theta (rad), theta' (rad/s), theta'' (rad/s^2) of eq. 5 at times t (s)."""
    ts, dts = warped_time(t)
    phase = 2 * np.pi * ts
    theta = AMPLITUDE * (ts - np.sin(phase) / (2 * np.pi) - 1)
    dtheta = AMPLITUDE * (1 - np.cos(phase))  # d theta / d t*
    ddtheta = 2 * np.pi * AMPLITUDE * np.sin(phase)  # d^2 theta / d t*^2
    if kinematics == "paper":
        return theta, dtheta, ddtheta
    return theta, dtheta * dts, ddtheta * dts**2 + dtheta * 2 * (1 - A1)


class SampledMotion(Motion):
    """A motion known at sample times: angles, and velocities and accelerations given or
    estimated. Between samples (and for the integrator's stages) it is a smooth function of t.

    t: times (s), increasing, shape (n,), n >= 10; theta: angles (rad), shape (n,); theta_vel,
    theta_acc: rad/s and rad/s^2 (None: estimated). ``cutoff_hz``: the -3 dB frequency of the whole
    zero-lag Butterworth filter; ``smoothing``: 'butterworth' or 'spline' (a smoothing spline whose
    factor ``spline_lambda`` is chosen by generalised cross-validation when None). ``samples``:
    the reporting grid (default: t). ``absolute``: theta is measured from the horizontal, so
    +-90 deg is singular (the forearm's theta); False for a relative angle (the arm's elbow)."""

    def __init__(self, t, theta, theta_vel=None, theta_acc=None, *, name: str = "sampled",
                 cutoff_hz: float = DEFAULT_CUTOFF_HZ, smoothing: str = "butterworth", spline_lambda=None,
                 samples=None, absolute: bool = True):
        t, theta = np.asarray(t, dtype=float), np.asarray(theta, dtype=float)
        check_samples(t, theta)
        if absolute:
            check_clear_of_singular(theta)
        self.name = name
        self.start_s = float(t[0])  # the recording's own time of its first sample (s): external loads' clock
        self._t = _read_only(t - t[0])
        self.recorded = _read_only(theta.copy())  # the raw angles (rad) at times self._t, for figures
        self._samples = self._t if samples is None else _read_only(samples)
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
        from scipy.interpolate import CubicHermiteSpline, make_interp_spline

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
    """Winter's zero-lag 4th-order Butterworth low-pass: a 2nd-order filter forward then backward
    (scipy's butter + filtfilt), its design cutoff corrected so that the -3 dB point of the whole
    is ``cutoff_hz``. values: shape (n,) sampled at ``rate_hz``. Each end is extended by its point
    reflection (value and slope continuous; repeated as far as needed, as OpenSim's Signal::Pad
    once) for as long as the filter takes to forget its start (``settling_samples``): the ends
    carry no start-up transient. The reflection reverses the curvature, so at an end that is not at
    rest the acceleration is drawn towards 0 over about 1 / (2 cutoff_hz) s."""
    from scipy.signal import butter, filtfilt

    if not 0 < cutoff_hz < rate_hz / 2:
        raise ValueError(f"the cutoff {cutoff_hz:g} Hz must be below half the sampling rate ({rate_hz / 2:.4g} Hz)")
    b, a = butter(FILTER_ORDER, butterworth_design_hz(cutoff_hz, rate_hz), fs=rate_hz)
    values = np.asarray(values, dtype=float)
    pad = min(settling_samples(a), PAD_RECORDINGS * len(values))
    out = filtfilt(b, a, np.pad(values, pad, mode="reflect", reflect_type="odd"), padtype=None)
    return out[pad:pad + len(values)]


SETTLED = 1e-6  # the filter's start transient is forgotten when it has decayed to this fraction
PAD_RECORDINGS = 20  # at most this many times the recording's length of padding at each end


def settling_samples(a) -> int:
    """Samples in which the transients of the filter of denominator ``a`` decay to SETTLED."""
    radius = float(np.max(np.abs(np.roots(a))))
    return int(math.ceil(math.log(SETTLED) / math.log(radius)))


MIN_RECORDING_DT = 1e-5  # s: samples closer than this (faster than 100 kHz) are not a motion capture's


def check_samples(t: np.ndarray, theta: np.ndarray) -> None:
    """Times and angles a motion can be built from; ValueError with a one-line message. Values are
    bounded as a model file's numbers are (``description.MAX_MAGNITUDE`` in SI units)."""
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
    a model file's bound on any number (``description.MAX_MAGNITUDE``), in ``unit``."""
    from .multibody.description import MAX_MAGNITUDE

    bad = ~(np.abs(values) <= MAX_MAGNITUDE)  # NaN included
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ValueError(f"{what} is {values[k]:.4g} {unit} at t = {t[k]:.10g} s; a motion's values must be finite "
                         f"and at most {MAX_MAGNITUDE:g} in magnitude")


SINGULAR_COS = 1e-2  # |cos| below this (within 0.57 deg of +-90 deg): a singular mixed coordinate


def check_clear_of_singular(theta: np.ndarray, what: str = "the angle",
                            needs: str = "the forearm model needs angles clear of it") -> None:
    """ValueError unless every absolute angle (rad, from the horizontal) stays clear of +-90 deg,
    where the mixed coordinates are singular."""
    if np.any(np.abs(np.cos(theta)) < SINGULAR_COS):
        worst = float(np.degrees(theta[np.argmin(np.abs(np.cos(theta)))]))
        raise ValueError(f"{what} reaches {worst:.4g} deg, where the mixed coordinates are singular "
                         f"(+-90 deg); {needs}")


def noisy(motion: Motion, sigma_deg: float, seed: int, capture_hz: float = DEFAULT_CAPTURE_HZ,
          cutoff_hz: float = DEFAULT_CUTOFF_HZ, smoothing: str = "butterworth", spline_lambda=None) -> SampledMotion:
    """``motion``'s angle captured with white Gaussian noise of ``sigma_deg`` degrees (seeded) and
    estimated like a recording. A recording keeps its own samples; an analytic motion is captured
    every 1 / capture_hz s. The result reports on ``motion``'s samples."""
    if isinstance(motion, SampledMotion):
        t = np.array(motion._t)
    else:
        from .memory import VALUES_PER_CAPTURED_SAMPLE, check_grid

        check_grid(motion.duration, 1 / capture_hz, "--capture-hz", values=VALUES_PER_CAPTURED_SAMPLE)
        t = np.linspace(0.0, motion.duration, int(round(motion.duration * capture_hz)) + 1)
    theta, _, _ = motion(t)
    rng = np.random.default_rng(seed)
    measured = theta + np.radians(sigma_deg) * rng.standard_normal(len(t))
    where = "" if isinstance(motion, SampledMotion) else f" at {capture_hz:g} Hz"
    return SampledMotion(t, measured, name=f"{motion.name}+noise {sigma_deg:g} deg{where} (seed {seed})",
                         cutoff_hz=cutoff_hz, smoothing=smoothing, spline_lambda=spline_lambda,
                         samples=motion.samples)


def rate_column_names(joint: str) -> tuple:
    """The columns a motion file may give for ``joint``'s rates: ``<joint>_vel``, ``<joint>_acc``
    and older fdbench's radian names ``<joint>_dot``, ``<joint>_ddot``."""
    return tuple(f"{joint}_{suffix}" for suffix in ("vel", "acc", "dot", "ddot"))


def given_rates(columns: dict, joint: str, path, option: str, radians: bool) -> tuple:
    """(velocity, acceleration) of ``joint`` as a motion file gives them (in the file's units), or
    (None, None). ``<joint>_dot``/``<joint>_ddot`` were written in radians by older fdbench: they
    are refused unless ``radians``, where they name the rates. Raises files.BadFile."""
    from .files import BadFile

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
    """A recorded joint angle from a CSV file: columns ``t`` (s) and ``theta`` (degrees, or
    radians with ``radians``), optionally ``theta_vel`` and ``theta_acc`` (deg/s, deg/s^2, or rad
    units), any order, any sampling: the columns ``fdbench inverse --format csv`` and
    ``--save-trajectory`` write; or an OpenSim storage file (.mot, .sto) with a theta column.
    ``estimate``: options of ``SampledMotion``. Raises files.BadFile with a one-line message."""
    from pathlib import Path

    from .files import BadFile, read_columns
    from .multibody.osim import is_storage, read_storage

    path = Path(path)
    if is_storage(path):  # OpenSim's .mot or .sto: the header's inDegrees gives the unit
        columns, in_degrees, _ = read_storage(path, option, ("theta",))
        radians = not in_degrees
        if "theta" not in columns:
            raise BadFile(f"{option}: {path} has no column for joint 'theta'; a motion file needs a time column and theta")
    else:
        columns = read_columns(path, option, required=("t", "theta"), optional=rate_column_names("theta"))
    unit = 1.0 if radians else math.pi / 180
    vel, acc = given_rates(columns, "theta", path, option, radians)
    try:
        return SampledMotion(columns["t"], columns["theta"] * unit, None if vel is None else vel * unit,
                             None if acc is None else acc * unit, name=f"file:{path.name}", **estimate)
    except ValueError as exc:
        raise BadFile(f"{option}: {path}: {exc}") from None


def check_kinematics(kinematics: str) -> str:
    if kinematics not in KINEMATICS:
        from .registry import unknown_name_message

        raise ValueError(unknown_name_message("kinematics", kinematics, list(KINEMATICS)))
    return kinematics


def as_motion(motion) -> Motion:
    """A Motion from a Motion or the name of one of eq. 5's variants ('paper', 'exact')."""
    if isinstance(motion, Motion):
        return motion
    return _named(check_kinematics(motion))


_NAMED = {}


def _named(name: str) -> Motion:
    if name not in _NAMED:
        _NAMED[name] = PaperMotion(name)
    return _NAMED[name]


# ---- the functions of eq. 5 that earlier code calls -------------------------------------------


def sample_times() -> np.ndarray:
    """The 1001 sample instants 0, 1 ms, ..., 1 s of eq. 5 (a read-only array)."""
    return _SAMPLES


def warped_time(t):
    """t*(t) and dt*/dt, dimensionless."""
    t = np.asarray(t, dtype=float)
    return A1 * t + (1 - A1) * t**2, A1 + 2 * (1 - A1) * t


def desired_motion(t, kinematics="paper"):
    """theta (rad), theta' (rad/s), theta'' (rad/s^2) at times t (s) of a motion or of the named
    variant of eq. 5, each shaped like t."""
    return as_motion(kinematics)(t)


class Resampled(Motion):
    """A motion reported on another grid: every ``sample_dt`` s over its span (the end included)."""

    def __init__(self, motion: Motion, sample_dt: float):
        self.base, self.sample_dt, self.name = motion, float(sample_dt), motion.name
        self._samples = sample_grid(motion.duration, sample_dt)

    @property
    def samples(self) -> np.ndarray:
        return self._samples

    @property
    def key(self) -> str:
        return f"{self.base.key}@{self.sample_dt!r}"

    def describe(self) -> dict:
        return {**self.base.describe(), "sample_dt": self.sample_dt}

    def __call__(self, t):
        return self.base(t)


MIN_SAMPLE_DT = 1e-4  # s


def sample_grid(duration: float, sample_dt: float) -> np.ndarray:
    """Times every ``sample_dt`` s over [0, duration], the end included (read-only); ValueError for
    a step outside [MIN_SAMPLE_DT, duration]."""
    if not (math.isfinite(sample_dt) and MIN_SAMPLE_DT <= sample_dt <= duration):
        raise ValueError(f"--sample-dt must be in [{MIN_SAMPLE_DT:g}, {duration:g}] s, got {sample_dt}")
    from .memory import check_grid

    check_grid(duration, sample_dt, "--sample-dt")
    grid = np.arange(0.0, duration, sample_dt)
    if duration - grid[-1] > 1e-9 * sample_dt:
        grid = np.append(grid, duration)
    else:
        grid[-1] = duration
    return _read_only(grid)


def load_motion(source: str, radians: bool = False, cutoff_hz: float = DEFAULT_CUTOFF_HZ,
                smoothing: str = "butterworth", spline_lambda=None, sample_dt=None, option: str = "--motion") -> Motion:
    """The motion named ``source`` ('paper', 'exact') or recorded in the CSV file ``source``,
    reported every ``sample_dt`` s if given. Files raise files.BadFile; options ValueError."""
    check_estimate(cutoff_hz, smoothing, spline_lambda)
    check_source(source)
    if source in KINEMATICS:
        motion = as_motion(source)
    else:
        motion = read_motion_csv(source, option, radians=radians, cutoff_hz=cutoff_hz, smoothing=smoothing,
                                 spline_lambda=spline_lambda)
    return motion if sample_dt is None else Resampled(motion, sample_dt)


def check_estimate(cutoff_hz: float, smoothing: str, spline_lambda) -> None:
    """Options of the derivative estimate; ValueError with a one-line message."""
    if not (math.isfinite(cutoff_hz) and cutoff_hz > 0):
        raise ValueError(f"--cutoff must be a positive frequency in Hz, got {cutoff_hz}")
    if smoothing not in SMOOTHING:
        from .registry import unknown_name_message

        raise ValueError("--smoothing: " + unknown_name_message("smoothing", smoothing, list(SMOOTHING)))
    if spline_lambda is not None and not (math.isfinite(spline_lambda) and spline_lambda > 0):
        raise ValueError(f"--spline-lambda must be a positive number, got {spline_lambda}")


def check_source(source: str, option: str = "--motion (--kinematics)") -> None:
    """A motion's name or an existing file; files.BadFile naming the valid names otherwise."""
    import os

    if source not in KINEMATICS and not os.path.exists(source):
        from .files import BadFile
        from .registry import unknown_name_message

        raise BadFile(f"{option}: {unknown_name_message('motion', source, list(KINEMATICS))}, and no file "
                      f"{source} exists (a recorded motion is a CSV file with columns t, theta)")
