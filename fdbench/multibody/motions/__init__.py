"""Desired motions of a model's joints: ``base`` (``Motion``, ``JointMotion``, ``PerJoint``,
``Resampled``), ``eq5`` (the paper's eq. 5), ``recorded`` (recordings, their derivatives' estimate,
noisy captures) and ``named`` (a model's named motions, the dispatch of ``--motion``).
"""

from __future__ import annotations

from .base import SAMPLE_DT, JointMotion, Motion, PerJoint, Resampled, sample_grid
from .eq5 import A1, KINEMATICS, Eq5, as_motion, desired_motion, eq5, sample_times, warped_time
from .named import EQ5_TYPES, MinimumJerk, joint_motion, named_motion
from .recorded import (DEFAULT_CAPTURE_HZ, DEFAULT_CUTOFF_HZ, SMOOTHING, SampledMotion, butterworth_design_hz,
                       check_estimate, check_source, noisy, noisy_joints, read_joint_motion_csv, read_motion_csv,
                       zero_lag_lowpass)

__all__ = [
    "A1", "DEFAULT_CAPTURE_HZ", "DEFAULT_CUTOFF_HZ", "EQ5_TYPES", "KINEMATICS", "SAMPLE_DT", "SMOOTHING", "Eq5",
    "JointMotion", "MinimumJerk", "Motion", "PerJoint", "Resampled", "SampledMotion", "as_motion",
    "butterworth_design_hz", "check_estimate", "check_source", "desired_motion", "eq5", "joint_motion",
    "named_motion", "noisy", "noisy_joints", "read_joint_motion_csv", "read_motion_csv", "sample_grid",
    "sample_times", "warped_time", "zero_lag_lowpass",
]
