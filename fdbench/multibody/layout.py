"""The data layout of the engine's compiled kernels (``fdbench.multibody.kernels``): named tuples of
arrays built once per ``Engine`` (``Engine.layout``), their columns and constants by named index.

* ``Model``: one model's arrays, every kernel's first argument after the run's own: its points,
  bodies, joints, linear constraints, mass matrix, Q_ext and penalty parameters (``params``).
* ``Paths``: the joint paths' point maps and splines, or None for a model without paths.
* ``Loads``: the external loads' bodies and frames and their values on the half-step grid, or None.
* ``Law``: a run's feedback law on the half-step grid.
* ``Muscles``: the muscles' paths, constants and excitations on the half-step grid, or None (a
  model without muscles, or run without excitations: the kernels then hold none of their code).

A model's free joints are passed as ``free`` (the indices of their bodies) or None. numba compiles
one variant of each kernel per pattern of None: a model of pin joints only (paths, free and loads
None) takes the banded, angle-eliminated solve, any other the dense one.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# a simulation's status codes (``simulation.STATUS_OF_CODE`` names them)
OK, NONFINITE, SINGULAR, CONSTRAINT = 0, 1, 2, 3
VIOLATION_TOL = 1e-3  # m (or m^2): a constraint violation beyond this stops a simulation
PD, COMPUTED, GAINS = 0, 1, 2  # feedback laws (``Law.mode``)
FIXED = -1  # pt_index of a point fixed to ground (and lin_idx padding)

# params: the penalty formulation's constants
ALPHA, TWO_XI_OMEGA, OMEGA2, SWITCH_COS, VIOLATION, N_PARAMS = range(6)
LENGTH, BETA = 0, 1  # body_geom columns: d (m), beta (rad)
# body_int columns: the coordinate indices of the body's points i (-1: fixed) and j, its parent
# body (-1: ground), its joint's first coordinate, 1 for a free joint, its path (-1: none)
KI, KJ, PARENT, COLUMN, FREE, PATH, N_BODY_INT = range(7)
# body_float columns: d (m), beta (rad), point i where fixed (m), the joint's offset (rad),
# at_parent (m), at_child (m)
D, BETA_F, FIXED_X, FIXED_Y, OFFSET, AT_PARENT_X, AT_PARENT_Y, AT_CHILD_X, AT_CHILD_Y, N_BODY_FLOAT = range(10)
# Paths.maps columns: (c1, c2) = base + L s of the path's point in its parent's basic-point frame
BASE_1, BASE_2, L_11, L_12, L_21, L_22, N_PATH_FLOAT = range(7)
LOAD_BODY, FORCE_FRAME, POINT_FRAME, N_LOAD_INT = range(4)  # Loads.frames columns (frames: -1 ground)
FX, FY, PX, PY, MOMENT, N_LOAD = range(6)  # a load's values: force (N), point (m), free moment (N m)


class Model(NamedTuple):
    """One model's arrays (``Engine._build_layout``). The banded solve's: pt_index (n_points,) the
    coordinate index of each point (FIXED on ground), pt_fixed (n_points, 2), body_pts (B, 2) the
    body's points i and j, body_geom (B, 2) d and beta, joint_parent (B,), offset (B,) the joints'
    offsets (rad), at_parent, at_child (B, 2) (m), lin_idx, lin_coef (n_lin, 5), lin_const (n_lin,),
    first (n_p,) the points' matrix's envelope, base (n_p, n_p) its constant part (mass and the
    linear rows' alpha J^T J); the inverse dynamics': pt_owner, pt_local; the dense solve's:
    body_int (B, N_BODY_INT), body_float (B, N_BODY_FLOAT), dense_first (n_q,); and mass (n_p, n_p),
    q_ext (n_p,), params (N_PARAMS,)."""
    pt_index: np.ndarray
    pt_fixed: np.ndarray
    body_pts: np.ndarray
    body_geom: np.ndarray
    joint_parent: np.ndarray
    offset: np.ndarray
    at_parent: np.ndarray
    at_child: np.ndarray
    lin_idx: np.ndarray
    lin_coef: np.ndarray
    lin_const: np.ndarray
    first: np.ndarray
    base: np.ndarray
    mass: np.ndarray
    q_ext: np.ndarray
    params: np.ndarray
    pt_owner: np.ndarray
    pt_local: np.ndarray
    body_int: np.ndarray
    body_float: np.ndarray
    dense_first: np.ndarray


class Paths(NamedTuple):
    """The joint paths: body (n_paths,) the child body of each, maps (n_paths, N_PATH_FLOAT), knots
    (n_knots, 5) and start (2 n_paths + 1,): path m's x spline is spline 2 m, its y spline 2 m + 1,
    rows start[s] to start[s + 1] of knots, each (x, y, b, c, d) of a piece y + b u + c u^2 + d u^3."""
    body: np.ndarray
    maps: np.ndarray
    knots: np.ndarray
    start: np.ndarray


class Loads(NamedTuple):
    """External loads: frames (L, N_LOAD_INT) their body and the frames of force and point, values
    (rows, L, N_LOAD) on the half-step grid."""
    frames: np.ndarray
    values: np.ndarray


class Law(NamedTuple):
    """A feedback law on the half-step grid t_k = k dt / 2: tau, ref, refd, refdd (rows, J) the
    feedforward (N m; N for a free joint's x and y), the reference coordinates (rad, m; without the
    joint offsets), rates and accelerations; kp, kd (J,); mode PD, COMPUTED or GAINS; gains
    (rows, J, 2J) for GAINS (any (m, J, 2J) otherwise)."""
    tau: np.ndarray
    ref: np.ndarray
    refd: np.ndarray
    refdd: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    mode: int
    gains: np.ndarray


class Muscles(NamedTuple):
    """A model's muscles (``kernels.rk4_muscles``): paths (``muscle_paths.MusclePaths``), params
    (M, len(muscle.PARAMETERS)) each muscle's constants, tendon_row (M,) the index among the muscle
    states (after the M activations) of a compliant tendon's normalised force (-1: a rigid tendon),
    excitation (rows, M) in [0, 1] on the half-step grid."""
    paths: tuple
    params: np.ndarray
    tendon_row: np.ndarray
    excitation: np.ndarray
