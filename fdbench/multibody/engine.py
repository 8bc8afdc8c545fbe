"""The paper's mixed-coordinate penalty formulation (eqs. 3, 4, 9-12) assembled from a model
description, for any planar tree of bodies joined by pins.

Coordinates. The mixed coordinates q are the natural coordinates (x, y) of the free points and one
ABSOLUTE angle per body (phi_b, from world +x: the sum of (coordinate + offset) of the joints on
its path from ground). Each body has two basic points: i, its joint point (shared with the
parent's point when the joint sits at one of the parent's basic points, a constant when the
parent is ground) and j, its resolved end. A joint at another point of its parent adds that point
as a massless free point tied to the parent's basic points by two linear constraints. Points are
numbered body by body (i before j), so a chain's leading matrix is banded. The joint angles z
(relative) appear only at the API: phi = S z + offsets with S constant and invertible, so eq. 12
in (points, phi) has the same solution as in (points, z) (its matrices are T^T A T and T^T b,
T = diag(I, S)), and the joint torques map to the angle rows as Q_phi_child += tau,
Q_phi_parent -= tau. With absolute angles each angle constraint holds one angle only.

Constraints per body (eq. 9 once per body): the rigid distance |r_j - r_i|^2 - d^2 = 0 and the
angle constraint, in one of two forms:

    sin form   (y_j - y_i) - d sin(phi_b + beta_b) = 0     while |cos(phi_b + beta_b)| >= SIN_FORM_MIN_COS
    cos form   (x_j - x_i) - d cos(phi_b + beta_b) = 0     otherwise

(d: the end's distance from the joint point, beta_b: the direction of end - joint point in the
body's frame). The sin form is the paper's and is singular where cos(phi_b + beta_b) = 0 (a leg
hanging at -90 deg); there |sin| >= 0.98 and the cos form is regular. The form is chosen at every
evaluation from the state alone (no memory in the integrator), so ``accelerations`` is a function
of (y, tau). On the constraint manifold both forms hold, so a switch changes only the penalty
terms, by amounts of the size of the constraint violation. The threshold 0.2 (78.5 deg from the
horizontal) keeps the paper's form everywhere the forearm (theta in [-45, 0] deg) and the arm's
reach (absolute angles in [-20, 70] deg) go: their numbers do not move.

Eq. 12, (M + alpha Phi_q^T Phi_q) q'' = Q - alpha Phi_q^T (Phi_q' q' + 2 xi omega Phi' + omega^2 Phi),
is solved as the forearm and arm kernels do: the angle rows hold no mass and each holds one angle
constraint, so they give that constraint's multiplier lambda_b = Q_phi_b / (dPhi_b/dphi_b); the
point accelerations then solve the points' symmetric positive definite system (the mass matrix
plus the penalty of the distance and linear constraints) by an L D L^T factorisation restricted to
the matrix's envelope (a band for a chain: the cost grows linearly with the number of bodies), and
the angle accelerations follow from the angle constraints' rows. The points' matrix is positive definite for positive masses and
inertias, and the angle rows' pivots are at least 0.2 d in magnitude, so the formulation has no
singular configuration: a pivot that is not positive (rank lost) stops a simulation as SINGULAR
only as a guard, a NaN pivot as NONFINITE.

Mass matrix: each body's natural-coordinate mass matrix on its basic points (Garcia de Jalon and
Bayo, ch. 3) from its mass, com and inertia; Q_ext: gravity at the com and the loads mapped to the
basic points by r_P = C_P q. For the forearm this is eq. 4. The kernels (fdbench.multibody.kernels)
take one data layout (``Engine.layout``, named tuples of arrays of fdbench.multibody.layout, built
once per Engine), so they are compiled once and cached for every model of a kind. Strict IEEE
arithmetic.

Free and path joints (``fdbench.multibody.model``). A free joint's body has its joint point
among the free points, unconstrained, its x and y the point's coordinates minus at_parent; a
joint with a path gives its child a joint point of its own, held on the path by two constraints
that involve both bodies' angles. M(z) (numpy) takes both through the joints' velocity transform.
The kernels take paths, free joints and external loads from data (``fdbench.multibody.loads``) as
optional arguments (``Engine.paths``, ``free``, ``loads_at``; None when absent): a model of pin
joints only without loads takes the banded solve above (``banded``), any other model a Cholesky
factorisation of the whole leading matrix, with the same driver, feedback laws, status codes and
sensitivities.

Feedback laws. One compiled RK4 driver (``Engine.simulate``) serves PD, computed torque and gain
matrices; computed torque evaluates eq. 3 (the believed model's inverse dynamics) from the joint
angles alone by recursive kinematics of the body points, so a nominal model other than the plant
is just another layout of arrays.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable

import numpy as np


from .model import Model, resolved_end
from .model_changes import rigid_tendons
from . import kernels
from .muscle import PARAMETERS as MUSCLE_PARAMETERS, parameters as muscle_parameters
from .muscle_paths import muscle_layout
from .layout import (ALPHA, AT_CHILD_X, AT_CHILD_Y, AT_PARENT_X, AT_PARENT_Y, BASE_1, BASE_2, BETA_F as BETA, COLUMN,
                     COMPUTED, FIXED, FIXED_X, FIXED_Y, FREE, GAINS, KI, KJ, L_11, L_12, L_21, L_22, LENGTH, N_BODY_FLOAT,
                     N_BODY_INT, N_LOAD, N_LOAD_INT, N_PARAMS, N_PATH_FLOAT, OFFSET, OMEGA2, PARENT, PATH, PD, SWITCH_COS,
                     TWO_XI_OMEGA, VIOLATION, VIOLATION_TOL, D, Law, Loads, Muscles, Paths)
from .layout import Model as Layout

SIN_FORM_MIN_COS = 0.2  # the sin form of a body's angle constraint while |cos(phi + beta)| >= this
SAME_POINT_M = 1e-9  # m: a joint this close to a basic point of its parent sits on that point
MODES = (PD, COMPUTED, GAINS)  # the feedback laws of ``Engine.simulate``
FIRST_CHUNK_VALUES = 100_000  # state values (steps x state size) of a compiled RK4's first call: a few ms
CHUNK_S = 0.1  # s: the calls after it, by the time the first took


@dataclass
class SimResult:
    """The outcome of ``Engine.simulate``: status (the kernels' codes: 0 ok, 1 nonfinite,
    2 singular, 3 constraint), the steps done, the largest constraint violation reached (m^2 or m),
    the mixed-coordinate states and their derivatives ``rates`` (n_steps + 1, n_state) and the total
    applied joint torques ``applied`` (n_steps + 1, J) (N m); NaN after ``steps_done``. The joint
    angles z (rad) and velocities zd (rad/s) at the steps, shape (n_steps + 1, J), are computed from
    the states when first read (``joints``: the engine's ``joints_from_state``)."""

    status: int
    steps_done: int
    max_violation: float
    states: np.ndarray
    rates: np.ndarray
    applied: np.ndarray
    joints: Callable = field(repr=False)

    @cached_property
    def _coordinates(self) -> tuple[np.ndarray, np.ndarray]:
        return self.joints(self.states)

    @property
    def z(self) -> np.ndarray:
        return self._coordinates[0]

    @property
    def zd(self) -> np.ndarray:
        return self._coordinates[1]


def _rotate(angle, local):
    """R(angle) local for angles of shape (...,) and a local vector (2,): shape (..., 2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([local[0] * c - local[1] * s, local[0] * s + local[1] * c], axis=-1)


def _rotate_each(angle, local):
    """R(angle_i) local_i for angles (n,) and vectors local (n, 2): shape (n, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([local[:, 0] * c - local[:, 1] * s, local[:, 0] * s + local[:, 1] * c], axis=-1)


def _perp(v):
    """R90 v, the vector turned by +90 deg, for v of shape (..., 2)."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def _point_map(rel, u):
    """(c1, c2) with rel = c1 u + c2 R90 u: a body point (rel from the joint point, m) in the
    frame of its basic points (u = end - joint point, m)."""
    d2 = u[0] * u[0] + u[1] * u[1]
    return (rel[0] * u[0] + rel[1] * u[1]) / d2, (u[0] * rel[1] - u[1] * rel[0]) / d2


def _point_blocks(c1, c2):
    """C_i, C_j (2x2 each) with r_P = C_i r_i + C_j r_j for the point (c1, c2) of ``_point_map``."""
    return np.array([[1 - c1, c2], [-c2, 1 - c1]]), np.array([[c1, -c2], [c2, c1]])


class Engine:
    """The mixed-coordinate penalty formulation of ``model`` with the penalty factor alpha, the
    damping ratio xi and the natural frequency omega (rad/s) of eq. 12."""

    def __init__(self, model: Model, alpha: float = 1e7, xi: float = 1.0, omega: float = 10.0, loads=None):
        from ..integrate import PENALTY_RANGES

        for name, value in (("alpha", alpha), ("xi", xi), ("omega", omega)):
            low, high = PENALTY_RANGES[name]
            if not (math.isfinite(value) and low <= value <= high):
                raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {value}")
        self.model = model
        self.penalty = (alpha, xi, omega)
        self.joints = tuple(model.coordinates)  # the coordinates (a free joint has three)
        self.n_joints = len(self.joints)
        self.n_bodies = len(model.joints)
        # per joint: the column of its angle among the coordinates (a free joint's x, y follow it)
        self.joint_column = np.cumsum([0] + [len(j.coordinate_names) for j in model.joints][:-1]).astype(np.int64)
        self.loads = loads  # external loads from data (``fdbench.multibody.loads.ExternalLoads``) or None
        if loads is not None:
            for load in loads.loads:
                for name in {load.body, load.force_frame, load.point_frame} - {"ground"}:
                    model.body(name)  # KeyError for a body the model lacks
        self.params = np.zeros(N_PARAMS)
        self.params[ALPHA], self.params[TWO_XI_OMEGA], self.params[OMEGA2] = alpha, 2 * xi * omega, omega**2
        self.params[SWITCH_COS], self.params[VIOLATION] = SIN_FORM_MIN_COS, VIOLATION_TOL
        self._build_points()
        self._build_matrices()
        self.n_q = self.n_p + self.n_bodies  # the points and one angle per body
        self.n_state = 2 * self.n_q
        self._build_layout()
        self._build_muscles()
        self._last_start = None  # (z and zd as bytes, the state) of the last ``state_from_joints``

    def with_rigid_tendons(self) -> "Engine":
        """This engine with every compliant tendon rigid (``model_changes.rigid_tendons``, Moco's
        ModOpIgnoreTendonCompliance), its penalty and loads kept; itself without compliant tendons."""
        if not (self.tendon_row >= 0).any():
            return self
        return Engine(rigid_tendons(self.model), *self.penalty, self.loads)

    # ------------------------------------------------------------------ layout
    def _build_points(self):
        """Points (owner body, local position), the bodies' basic points, the linear constraints."""
        model = self.model
        body_index = {joint.child: k for k, joint in enumerate(model.joints)}  # body b is the child of joint b
        self.body_names = tuple(joint.child for joint in model.joints)
        owners, locals_, fixed = [], [], []  # per point: owner body (-1 ground), local (m), world if fixed
        basic, geom, extra = [], [], {}
        self.joint_parent = np.array([body_index.get(j.parent, FIXED) for j in model.joints], dtype=np.int64)
        self.joint_offset = np.array([j.offset for j in model.joints], dtype=float)
        self.joint_at_parent = np.array([j.at_parent for j in model.joints], dtype=float).reshape(-1, 2)
        self.joint_at_child = np.array([j.at_child for j in model.joints], dtype=float).reshape(-1, 2)
        self._local_end = []
        lin_rows = []  # (point, parent body) of the extra points

        def new_point(owner, local, world=None):
            owners.append(owner)
            locals_.append(np.asarray(local, dtype=float))
            fixed.append(world)
            return len(owners) - 1

        for b, joint in enumerate(model.joints):
            p = self.joint_parent[b]
            at_parent = np.asarray(joint.at_parent, dtype=float)
            if joint.type == "free" or joint.path is not None:  # a point of the child that moves on its parent
                i = new_point(b, joint.at_child)
            elif p == FIXED:
                i = new_point(FIXED, at_parent, at_parent)
            else:
                pi, pj = basic[p]
                i = next((pt for pt, local in ((pi, model.joints[p].at_child), (pj, self._local_end[p]))
                          if np.hypot(*(at_parent - np.asarray(local))) <= SAME_POINT_M), None)
                if i is None:
                    key = (p, round(at_parent[0] / SAME_POINT_M), round(at_parent[1] / SAME_POINT_M))
                    if key not in extra:
                        extra[key] = new_point(p, at_parent)
                        lin_rows.append((extra[key], p))
                    i = extra[key]
            end = np.asarray(resolved_end(model, joint.child), dtype=float)
            self._local_end.append(end)
            j = new_point(b, end)
            basic.append((i, j))
            u = end - np.asarray(joint.at_child, dtype=float)
            if not math.hypot(u[0], u[1]) >= 1e-3:
                raise ValueError(f"body {joint.child!r}: its end must be at least 1 mm from its joint point")
            geom.append((math.hypot(u[0], u[1]), math.atan2(u[1], u[0])))
        self.n_points = len(owners)
        self.pt_owner = np.array(owners, dtype=np.int64)
        self.pt_local = np.array(locals_)
        self.pt_index = np.full(self.n_points, FIXED, dtype=np.int64)
        self.pt_fixed = np.zeros((self.n_points, 2))
        free = 0
        for pt in range(self.n_points):
            if fixed[pt] is None:
                self.pt_index[pt], free = 2 * free, free + 1
            else:
                self.pt_fixed[pt] = fixed[pt]
        self.n_p = 2 * free
        self.body_pts = np.array(basic, dtype=np.int64).reshape(-1, 2)
        self.body_geom = np.array(geom, dtype=float).reshape(-1, 2)
        self._lin_rows = lin_rows

    def _basic_map(self, b, local):
        """(c1, c2) of a point of body b given in the body's frame (m)."""
        at_child = np.asarray(self.model.joints[b].at_child, dtype=float)
        return _point_map(np.asarray(local, dtype=float) - at_child, self._local_end[b] - at_child)

    def _coords(self, pt):
        """The scalar coordinate indices (x, y) of a point, or None for a fixed one."""
        k = self.pt_index[pt]
        return None if k == FIXED else (k, k + 1)

    def _build_matrices(self):
        """The points' mass matrix M_p, Q_ext, the linear constraints and the envelope."""
        model, n = self.model, self.n_p
        mass, q_ext = np.zeros((n, n)), np.zeros(n)
        gravity = np.asarray(model.gravity, dtype=float)
        for b, name in enumerate(self.body_names):
            body = model.body(name)
            at_child = np.asarray(model.joints[b].at_child, dtype=float)
            d = self.body_geom[b, LENGTH]
            c1, c2 = self._basic_map(b, body.com)
            inertia_i = body.inertia + body.mass * float(np.sum((np.asarray(body.com) - at_child) ** 2))
            r90 = np.array([[0.0, -1.0], [1.0, 0.0]])
            blocks = {(0, 0): (body.mass - 2 * body.mass * c1 + inertia_i / d**2) * np.eye(2),
                      (0, 1): (body.mass * c1 - inertia_i / d**2) * np.eye(2) + body.mass * c2 * r90,
                      (1, 1): inertia_i / d**2 * np.eye(2)}
            blocks[(1, 0)] = blocks[(0, 1)].T
            self._add_blocks(mass, blocks, b)
            self._add_force(q_ext, b, body.com, body.mass * gravity)
        for load in model.loads:
            self._add_force(q_ext, self.body_names.index(load.body), load.at, np.asarray(load.force, dtype=float))
        self.mass = mass
        self.q_ext = q_ext
        self._build_linear()
        alpha = self.params[ALPHA]
        self.base = mass.copy()
        for row in range(len(self.lin_const)):
            for a, ka in zip(self.lin_idx[row], self.lin_coef[row]):
                for c, kc in zip(self.lin_idx[row], self.lin_coef[row]):
                    if a != FIXED and c != FIXED:
                        self.base[a, c] += alpha * ka * kc
        self.first = self._envelope()

    def _add_blocks(self, matrix, blocks, b):
        for (r, c), block in blocks.items():
            rows, cols = self._coords(self.body_pts[b, r]), self._coords(self.body_pts[b, c])
            if rows is not None and cols is not None:
                matrix[np.ix_(rows, cols)] += block

    def _add_force(self, q_ext, b, local, force):
        """Q_ext += C_P^T force for a force (N, world) at a point of body b (m, body frame)."""
        blocks = _point_blocks(*self._basic_map(b, local))
        for r in range(2):
            coords = self._coords(self.body_pts[b, r])
            if coords is not None:
                q_ext[list(coords)] += blocks[r].T @ force

    def _build_linear(self):
        """Two rows per extra point P of parent p: r_P - C_i r_i - C_j r_j = 0, as (coordinate
        index, coefficient) pairs (index FIXED: none) and a constant for fixed points."""
        idx, coef, const = [], [], []
        for pt, p in self._lin_rows:
            c_i, c_j = _point_blocks(*self._basic_map(p, self.pt_local[pt]))
            pi, pj = self.body_pts[p]
            for axis in range(2):
                row_idx, row_coef, k = [self.pt_index[pt] + axis], [1.0], 0.0
                for point, block in ((pi, c_i), (pj, c_j)):
                    coords = self._coords(point)
                    for other in range(2):
                        if coords is None:
                            k -= block[axis, other] * self.pt_fixed[point, other]
                            row_idx.append(FIXED)
                            row_coef.append(0.0)
                        else:
                            row_idx.append(coords[other])
                            row_coef.append(-block[axis, other])
                idx.append(row_idx)
                coef.append(row_coef)
                const.append(k)
        self.lin_idx = np.array(idx, dtype=np.int64).reshape(-1, 5)
        self.lin_coef = np.array(coef, dtype=float).reshape(-1, 5)
        self.lin_const = np.array(const, dtype=float)

    def _envelope(self) -> np.ndarray:
        """first[r]: the first column of row r inside the points' matrix's envelope."""
        coupled = self.base != 0.0
        for b in range(len(self.body_names)):
            coords = [c for pt in self.body_pts[b] for c in (self._coords(pt) or ())]
            coupled[np.ix_(coords, coords)] = True
        first = np.arange(self.n_p, dtype=np.int64)
        for r in range(self.n_p):
            first[r] = int(np.flatnonzero(coupled[r, : r + 1])[0])
        return first

    @property
    def banded(self) -> bool:
        """Whether the kernels take the banded, angle-eliminated solve: pin joints only and no
        external loads (``kernels``' module docstring); any other model takes the dense one."""
        return self.paths is None and self.free is None and self.loads is None

    def load_values(self, times) -> np.ndarray:
        """The external loads' values at the times (s, shape (n,)) as the kernels take them
        (``layout.Loads.values``): shape (n, L, N_LOAD), force (N) and point (m) in their frames,
        free moment (N m); L = 0 without loads."""
        times = np.asarray(times, dtype=float)
        if self.loads is None:
            return np.zeros((len(times), 0, N_LOAD))
        force, point, moment = self.loads.at(times)
        return np.ascontiguousarray(np.concatenate([force, point, moment[..., None]], axis=2))

    def loads_at(self, times) -> "Loads | None":
        """The kernels' ``loads`` argument at the times (s) of a grid: None without loads."""
        if self.loads is None:
            return None
        return Loads(self.load_frames, self.load_values(times))

    def kernel_args(self) -> tuple:
        """(model, paths, free): the kernels' layout arguments of this model (``layout``)."""
        return self.layout, self.paths, self.free

    def _build_muscles(self) -> None:
        """The muscles' part of the kernels' layout (``layout.Muscles`` less its excitations):
        ``muscle_paths`` (None without muscles), ``muscle_params`` (M, len(muscle.PARAMETERS)),
        ``tendon_row`` (M,) and ``n_muscle_states``: M activations, then one normalised force per
        compliant tendon."""
        muscles = self.model.muscles
        self.n_muscles = len(muscles)
        self.muscle_paths = muscle_layout(self.model) if muscles else None
        self.muscle_params = np.array([muscle_parameters(
            m.max_isometric_force, m.optimal_fiber_length, m.tendon_slack_length,
            pennation_angle_at_optimal=m.pennation_angle, max_contraction_velocity=m.max_contraction_velocity,
            passive_fiber_strain_at_one_norm_force=m.passive_strain, tendon_strain_at_one_norm_force=m.tendon_strain,
            fiber_damping=m.fiber_damping, activation_time_constant=m.activation_time,
            deactivation_time_constant=m.deactivation_time) for m in muscles]).reshape(-1, len(MUSCLE_PARAMETERS))
        compliant = np.array([m.tendon == "compliant" for m in muscles], dtype=bool)
        self.tendon_row = np.full(self.n_muscles, -1, dtype=np.int64)
        self.tendon_row[compliant] = self.n_muscles + np.arange(compliant.sum())
        self.n_muscle_states = self.n_muscles + int(compliant.sum())

    def muscles_at(self, excitation_half) -> Muscles:
        """The kernels' ``muscles`` argument (``layout.Muscles``) with the excitations (in [0, 1],
        shape (rows, M), on the half-step grid). ValueError for a model without muscles or another
        shape."""
        if not self.n_muscles:
            raise ValueError(f"the model {self.model.name!r} has no muscles to excite")
        excitation = _writeable(excitation_half)
        if excitation.ndim != 2 or excitation.shape[1] != self.n_muscles:
            raise ValueError(f"excitations must have shape (rows, {self.n_muscles}), got {excitation.shape}")
        return Muscles(self.muscle_paths, self.muscle_params, self.tendon_row, excitation)

    def _build_layout(self) -> None:
        """The kernels' layout (``fdbench.multibody.layout``), built once: ``layout`` (a ``Model``),
        ``paths`` (a ``Paths`` or None), ``free`` (the free joints' bodies or None) and the loads'
        frames: per body its points, parent, coordinate, kind and geometry; per path its point map
        and splines' pieces; per external load its body and frames."""
        B = self.n_bodies
        body_int, body_float = np.full((B, N_BODY_INT), FIXED, dtype=np.int64), np.zeros((B, N_BODY_FLOAT))
        path_body, path_float, pieces, spline_start = [], [], [], [0]
        for b, joint in enumerate(self.model.joints):
            p = self.joint_parent[b]
            body_int[b, [KI, KJ]] = self.pt_index[self.body_pts[b]]
            body_int[b, PARENT], body_int[b, COLUMN] = p, self.joint_column[b]
            body_int[b, FREE] = joint.type == "free"
            body_float[b, [D, BETA]] = self.body_geom[b]
            body_float[b, [FIXED_X, FIXED_Y]] = self.pt_fixed[self.body_pts[b, 0]]
            body_float[b, OFFSET] = joint.offset
            body_float[b, [AT_PARENT_X, AT_PARENT_Y]] = joint.at_parent
            body_float[b, [AT_CHILD_X, AT_CHILD_Y]] = joint.at_child
            if joint.path is None:
                continue
            body_int[b, PATH] = len(path_body)
            path_body.append(b)
            maps = np.zeros(N_PATH_FLOAT)
            if p != FIXED:  # (c1, c2) = base + L s: the point map is linear in the path's offset s
                at_child_p = np.asarray(self.model.joints[p].at_child, dtype=float)
                u = self._local_end[p] - at_child_p
                maps[[BASE_1, BASE_2]] = _point_map(np.asarray(joint.at_parent, dtype=float) - at_child_p, u)
                (maps[L_11], maps[L_21]), (maps[L_12], maps[L_22]) = (_point_map((1.0, 0.0), u),
                                                                      _point_map((0.0, 1.0), u))
            path_float.append(maps)
            for spline in joint.path.splines():
                pieces.append(np.column_stack([spline.x, spline.y, spline.b, spline.c, spline.d]))
                spline_start.append(spline_start[-1] + len(spline.x))
        index = {name: b for b, name in enumerate(self.body_names)}
        self.load_frames = np.array([[index.get(name, FIXED) for name in (load.body, load.force_frame, load.point_frame)]
                                     for load in (self.loads.loads if self.loads is not None else ())],
                                    dtype=np.int64).reshape(-1, N_LOAD_INT)
        path_body = np.array(path_body, dtype=np.int64)
        self.paths = None if not len(path_body) else Paths(
            path_body, np.array(path_float, dtype=float).reshape(-1, N_PATH_FLOAT), np.concatenate(pieces),
            np.array(spline_start, dtype=np.int64))
        free = np.flatnonzero(body_int[:, FREE]).astype(np.int64)
        self.free = free if len(free) else None
        self.layout = Layout(
            pt_index=self.pt_index, pt_fixed=self.pt_fixed, body_pts=self.body_pts, body_geom=self.body_geom,
            joint_parent=self.joint_parent, offset=self.joint_offset, at_parent=self.joint_at_parent,
            at_child=self.joint_at_child, lin_idx=self.lin_idx, lin_coef=self.lin_coef, lin_const=self.lin_const,
            first=self.first, base=self.base, mass=self.mass, q_ext=self.q_ext, params=self.params,
            pt_owner=self.pt_owner, pt_local=self.pt_local, body_int=body_int, body_float=body_float,
            dense_first=self._dense_envelope(body_int, path_body))

    def _dense_envelope(self, body_int, path_body) -> np.ndarray:
        """first[r]: the first column of row r inside the envelope of eq. 12's dense leading matrix
        (n_q, n_q): the entries of the points' mass matrix and, for every constraint row, those of
        its columns (both of a point's coordinates, whichever angle form is in force)."""
        n_p = self.n_p
        coupled = np.eye(self.n_q, dtype=bool)
        coupled[:n_p, :n_p] |= self.mass != 0.0

        def points(*indices):
            return [k + axis for k in indices if k != FIXED for axis in range(2)]

        rows = [points(ki, kj) + [n_p + b] for b, (ki, kj) in enumerate(body_int[:, [KI, KJ]])]
        rows += [[k for k in row if k != FIXED] for row in self.lin_idx]
        for k in path_body:
            p = body_int[k, PARENT]
            rows.append(points(body_int[k, KI]) + [n_p + k] + ([] if p == FIXED else (
                points(body_int[p, KI], body_int[p, KJ]) + [n_p + p])))
        for row in rows:
            coupled[np.ix_(row, row)] = True
        return np.array([np.flatnonzero(coupled[r, :r + 1])[0] for r in range(self.n_q)], dtype=np.int64)

    def check_nominal(self, nominal: "Engine | None") -> None:
        """ValueError (one line) unless ``nominal`` (None: this engine) can be the model computed-torque
        control believes: the same coordinates."""
        if nominal is not None and nominal.joints != self.joints:
            raise ValueError(f"the nominal model's joints {nominal.joints} are not the plant's {self.joints}")

    def believed_args(self, nominal: "Engine | None", times) -> tuple:
        """(loads, believed, believed_paths, believed_loads): the kernels' plant loads and the model
        computed-torque control believes (``nominal``; None: this one) on the grid of the times (s;
        or a function that makes them, called only where there are loads), the loads interpolated
        once when both carry the same."""
        self.check_nominal(nominal)
        believed = self if nominal is None else nominal
        if callable(times):
            times = times() if self.loads is not None or believed.loads is not None else None
        own = self.loads_at(times)
        theirs = own if believed.loads is self.loads else believed.loads_at(times)
        return own, believed.layout, believed.paths, theirs

    # ------------------------------------------------------------------ kinematics (numpy)
    def _kinematics(self, z, zd):
        """Body angles phi and rates w (shape (n, B)), body origins' positions and velocities, the
        joints' world positions and, for a joint with a path, the world direction of its point's
        motion per radian (m/rad; 0 without a path) (shape (n, B, 2)) of the coordinates z and rates
        zd (n, J)."""
        n, B = z.shape[0], self.n_bodies
        phi, w = np.zeros((n, B)), np.zeros((n, B))
        o, vo, joint_at, path_dir = (np.zeros((n, B, 2)) for _ in range(4))
        for k, joint in enumerate(self.model.joints):
            p, c = self.joint_parent[k], self.joint_column[k]
            at_parent = np.asarray(joint.at_parent, dtype=float)
            if p == FIXED:
                phi[:, k], w[:, k] = z[:, c] + joint.offset, zd[:, c]
                r, v = np.broadcast_to(at_parent, (n, 2)), np.zeros((n, 2))
                if joint.type == "free":
                    r, v = r + z[:, c + 1:c + 3], zd[:, c + 1:c + 3]
                parent_phi, parent_w = np.zeros(n), np.zeros(n)
            else:
                phi[:, k] = phi[:, p] + z[:, c] + joint.offset
                w[:, k] = w[:, p] + zd[:, c]
                r, v = self._body_point(p, at_parent, phi, w, o, vo)
                parent_phi, parent_w = phi[:, p], w[:, p]
            if joint.path is not None:  # the point moves along the path in the parent's frame
                theta, rate = z[:, c], zd[:, c]
                splines = joint.path.splines()
                s0, s1 = (np.stack([sp.evaluate(theta, order) for sp in splines], axis=-1) for order in range(2))
                arm, d1 = (_rotate_each(parent_phi, u) for u in (s0, s1))
                r = r + arm
                v = v + parent_w[:, None] * _perp(arm) + d1 * rate[:, None]
                path_dir[:, k] = d1
            joint_at[:, k] = r
            arm = _rotate(phi[:, k], np.asarray(joint.at_child, dtype=float))
            o[:, k] = r - arm
            vo[:, k] = v - w[:, k, None] * _perp(arm)
        return phi, w, o, vo, joint_at, path_dir

    @staticmethod
    def _body_point(b, local, phi, w, o, vo):
        """Position and velocity (n, 2) of a point of body b (m, body frame)."""
        arm = _rotate(phi[:, b], np.asarray(local, dtype=float))
        return o[:, b] + arm, vo[:, b] + w[:, b, None] * _perp(arm)

    def _free_points(self, z, zd):
        """p, p' (n, n_p) and the body angles and rates (n, B)."""
        phi, w, o, vo, _, _ = self._kinematics(z, zd)
        n = z.shape[0]
        p, pd = np.zeros((n, self.n_p)), np.zeros((n, self.n_p))
        for pt in range(self.n_points):
            k = self.pt_index[pt]
            if k != FIXED:
                p[:, k:k + 2], pd[:, k:k + 2] = self._body_point(self.pt_owner[pt], self.pt_local[pt], phi, w, o, vo)
        return p, pd, phi, w

    def _samples(self, *arrays):
        """Arrays of shape (J,) or (n, J), all alike, as (n, J), and whether the input was one
        sample. ValueError for another shape."""
        arrays = [np.asarray(a, dtype=float) for a in arrays]
        shape = arrays[0].shape
        if not (shape[-1:] == (self.n_joints,) and len(shape) <= 2) or any(a.shape != shape for a in arrays):
            raise ValueError(f"joint values must have shape ({self.n_joints},) or (n, {self.n_joints}), got "
                             f"{', '.join(str(a.shape) for a in arrays)}")
        return [np.atleast_2d(a) for a in arrays], len(shape) == 1

    @staticmethod
    def _vector(value, size: int, what: str) -> np.ndarray:
        """value as a contiguous, writeable float array of shape (size,) (``_writeable``); ValueError
        for another shape."""
        array = _writeable(value)
        if array.shape != (size,):
            raise ValueError(f"{what} must have shape ({size},), got {array.shape}")
        return array

    # ------------------------------------------------------------------ API
    def state_from_joints(self, z, zd) -> np.ndarray:
        """y = [q, q'] on the constraint manifold for joint angles z (rad) and rates zd (rad/s), shape (J,)."""
        z, zd = self._vector(z, self.n_joints, "z"), self._vector(zd, self.n_joints, "zd")
        key = z.tobytes() + zd.tobytes()
        if self._last_start is None or self._last_start[0] != key:  # a run's start, kept for its repeats
            p, pd, phi, w = self._free_points(z[None], zd[None])
            self._last_start = key, np.concatenate([p[0], phi[0], pd[0], w[0]])
        return self._last_start[1].copy()

    def joints_from_state(self, y) -> tuple[np.ndarray, np.ndarray]:
        """(z, zd) (rad, rad/s), shapes (J,), from the state y (n_state,) (or (n, n_state) -> (n, J))."""
        y = np.asarray(y, dtype=float)
        if y.shape[-1:] != (self.n_state,):
            raise ValueError(f"states must have shape ({self.n_state},) or (n, {self.n_state}), got {y.shape}")
        phi, w = y[..., self.n_p:self.n_q], y[..., self.n_q + self.n_p:]
        if not self.banded:
            return self._coordinates_from_state(y, phi, w)
        z, zd = np.empty(phi.shape), np.empty(w.shape)
        for k, parent in enumerate(self.joint_parent):  # column by column: no gathered copies
            if parent == FIXED:
                np.subtract(phi[..., k], 0.0, out=z[..., k])
                np.subtract(w[..., k], 0.0, out=zd[..., k])
            else:
                np.subtract(phi[..., k], phi[..., parent], out=z[..., k])
                np.subtract(w[..., k], w[..., parent], out=zd[..., k])
        z -= self.joint_offset
        return z, zd

    def _coordinates_from_state(self, y, phi, w):
        """(z, zd) of every coordinate (a free joint's x, y from its child's point) from the state y."""
        z, zd = np.empty(y.shape[:-1] + (self.n_joints,)), np.empty(y.shape[:-1] + (self.n_joints,))
        for k, (parent, joint) in enumerate(zip(self.joint_parent, self.model.joints)):
            c = self.joint_column[k]
            z[..., c] = phi[..., k] - (phi[..., parent] if parent != FIXED else 0.0) - joint.offset
            zd[..., c] = w[..., k] - (w[..., parent] if parent != FIXED else 0.0)
            if joint.type == "free":
                i = self.pt_index[self.body_pts[k, 0]]
                z[..., c + 1:c + 3] = y[..., i:i + 2] - np.asarray(joint.at_parent, dtype=float)
                zd[..., c + 1:c + 3] = y[..., self.n_q + i:self.n_q + i + 2]
        return z, zd

    def accelerations(self, y, tau) -> np.ndarray:
        """y' = [q', q''] of eq. 12 for the state y (n_state,) and joint torques tau (J,) N m; NaN
        where the leading matrix is singular."""
        y, tau = self._vector(y, self.n_state, "the state"), self._vector(tau, self.n_joints, "tau")
        zero = np.zeros((1, self.n_joints))
        return self.rates(y[None], tau[None], zero, zero, zero, 0.0, 0.0)[0][0]

    def constraint_violation(self, y) -> float:
        """max |Phi_i| (m^2 and m) of the state y, the angle constraints in the form in force."""
        return float(kernels.constraint_violation(self._vector(y, self.n_state, "the state"), *self.kernel_args(),
                                                  self.loads_at(np.zeros(1)), None))

    def inverse_dynamics(self, z, zd, zdd, t=None) -> np.ndarray:
        """Eq. 3: tau = R^T (M q'' - Q_ext) (N m; N for a free joint's x and y) of joint angles,
        rates and accelerations (rad, rad/s, rad/s^2; m for a free joint's x and y) of shape (n, J)
        or (J,), by the compiled kernel (``inverse.inverse_torques``); the same shape out. With
        external loads, the times t (s, shape (n,) or a number) they are taken at, and their
        generalised forces subtracted."""
        (z, zd, zdd), single = self._samples(z, zd, zdd)
        if self.loads is not None and t is None:
            raise ValueError("a model with external loads needs the times of its inverse dynamics")
        times = np.broadcast_to(np.asarray(0.0 if t is None else t, dtype=float), (len(z),))
        tau = self._eq3(z, zd, zdd, self.layout, self.loads_at(times))
        return tau[0] if single else tau

    def _eq3(self, z, zd, zdd, layout, loads) -> np.ndarray:
        """The compiled eq. 3 (n, J) of the samples z, zd, zdd (n, J) over ``layout`` under ``loads``."""
        tau = np.empty(z.shape)
        kernels.inverse_torques(*(np.ascontiguousarray(a) for a in (z, zd, zdd)), layout, self.paths, loads, tau)
        return tau

    def mass_matrix(self, z) -> np.ndarray:
        """Minimal M(z) = R^T M R, shape (J, J) (or (n, J, J) for z of shape (n, J)), kg m^2, by
        composite bodies (Featherstone's CRBA, planar): the points' mass matrix is each body's rigid
        inertia, so M_cd = S_c^T I_d S_d for coordinate c on the path of d's body, S the coordinates'
        twists (rad/s and the velocity of the body point at the world origin, m/s, per unit rate) and
        I_d the composite inertia of the subtree d moves, about the origin. Cost O(J^2), no R."""
        (z,), single = self._samples(z)
        phi, w, o, vo, joint_at, path_dir = self._kinematics(z, np.zeros_like(z))
        com = np.stack([self._body_point(b, self.model.body(name).com, phi, w, o, vo)[0]
                        for b, name in enumerate(self.body_names)], axis=1)  # (n, B, 2) m
        mass, inertia = self._body_inertias
        # per subtree: mass (kg), first moment about the origin (kg m), inertia about the origin (kg m^2)
        m_sub = np.broadcast_to(mass, z.shape[:1] + mass.shape).copy()
        h_sub = mass[:, None] * com
        j_sub = inertia + mass * np.sum(com**2, axis=-1)
        self._to_subtrees(m_sub, h_sub, j_sub)
        S = np.zeros(z.shape + (3,))  # per coordinate (omega, v0x, v0y)
        F = np.zeros(z.shape + (3,))  # I_sub S
        for b, joint in enumerate(self.model.joints):
            c = self.joint_column[b]
            S[:, c, 0] = 1.0
            S[:, c, 1:] = _perp(-joint_at[:, b]) + path_dir[:, b]
            if joint.type == "free":
                S[:, c + 1, 1], S[:, c + 2, 2] = 1.0, 1.0
            h = _perp(h_sub[:, b])  # the subtree's m perp(com), kg m
            for k in range(c, c + len(joint.coordinate_names)):
                F[:, k, 0] = j_sub[:, b] * S[:, k, 0] + np.sum(h * S[:, k, 1:], axis=-1)
                F[:, k, 1:] = h * S[:, k, 0, None] + m_sub[:, b, None] * S[:, k, 1:]
        M = S @ np.swapaxes(F, 1, 2)  # S_c^T I_d S_d for every pair: kept where c moves d's body
        upper = self._on_path  # c <= d (an ancestor's columns come first), mirrored: M exactly symmetric
        M = np.where(upper, M, np.where(upper.T, np.swapaxes(M, 1, 2), 0.0))
        return M[0] if single else M

    @property
    def _body_inertias(self) -> tuple[np.ndarray, np.ndarray]:
        """Per body its mass (kg) and inertia about its centre of mass (kg m^2), shape (B,) each."""
        bodies = [self.model.body(name) for name in self.body_names]
        return np.array([b.mass for b in bodies], dtype=float), np.array([b.inertia for b in bodies], dtype=float)

    @property
    def _on_path(self) -> np.ndarray:
        """(J, J) bool: coordinate c's joint is on the path from ground to coordinate d's body, and
        c <= d (the upper triangle: joints are in topological order)."""
        if getattr(self, "_on_path_cache", None) is None:
            B = self.n_bodies
            above = np.zeros((B, B), dtype=bool)  # above[a, b]: joint a on body b's path (b's own included)
            for b, parent in enumerate(self.joint_parent):  # topological order: the parent's column is done
                if parent != FIXED:
                    above[:, b] = above[:, parent]
                above[b, b] = True
            body = np.repeat(np.arange(B), [len(j.coordinate_names) for j in self.model.joints])
            self._on_path_cache = np.triu(above[np.ix_(body, body)])
        return self._on_path_cache

    def _to_subtrees(self, *arrays) -> None:
        """Each array (n, B, ...) of values per body, in place, summed over each body's subtree."""
        for b in range(self.n_bodies - 1, -1, -1):  # children come after their parent
            parent = self.joint_parent[b]
            if parent != FIXED:
                for array in arrays:
                    array[:, parent] += array[:, b]

    def bias(self, z, zd) -> np.ndarray:
        """h(z, z') (N m) with M(z) z'' + h(z, z') = tau: R^T (M R' z' - Q_ext), shape (J,) (or (n, J))."""
        return self.inverse_dynamics(z, zd, np.zeros_like(np.asarray(zd, dtype=float)))

    def point_positions(self, z) -> dict[str, np.ndarray]:
        """World positions (m) of every body's joint point ('<body>.joint') and end ('<body>.end'),
        shape (2,) (or (n, 2) for z of shape (n, J))."""
        (z,), single = self._samples(z)
        phi, w, o, vo, joint_at, _ = self._kinematics(z, np.zeros_like(z))
        points = {}
        for b, name in enumerate(self.body_names):
            points[f"{name}.joint"] = joint_at[:, b]
            points[f"{name}.end"] = self._body_point(b, self._local_end[b], phi, w, o, vo)[0]
        return {key: value[0] if single else value for key, value in points.items()}

    def inverse_torques(self, z, zd, zdd, t=None) -> np.ndarray:
        """``inverse_dynamics`` of one minimal motion (z, zd, zdd) (rad, rad/s, rad/s^2; m for a free
        joint's x and y), shape (J,) each, at the time t (s): shape (J,)."""
        z, zd, zdd = (self._vector(a, self.n_joints, name) for a, name in ((z, "z"), (zd, "zd"), (zdd, "zdd")))
        return self.inverse_dynamics(z, zd, zdd, None if t is None else float(t))

    def simulate(self, y0, dt, n_steps, tau_half, ref_half, refd_half, refdd_half, kp, kd, mode=PD, gains=None,
                 nominal: "Engine | None" = None, excitation_half=None, t0: float = 0.0) -> SimResult:
        """Classical RK4 of eq. 12 (compiled, ``kernels.rk4``) over n_steps steps of dt (s) from the
        state y0 (n_state,) under a feedback law: ``mode`` PD, tau + kp (ref - z) + kd (refd - z')
        (kp N m/rad, kd N m s/rad); COMPUTED, the inverse dynamics of ``nominal`` (an Engine of the
        same joints; None: this one) at (z, z') for the accelerations refdd + kp e + kd e' (kp 1/s^2,
        kd 1/s), plus tau; GAINS, tau + K_k [ref - z, refd - z'] with ``gains`` K of shape
        (2 n_steps + 1, J, 2J) (N m/rad, N m s/rad). tau_half (N m), ref_half (rad), refd_half
        (rad/s), refdd_half (rad/s^2): shape (2 n_steps + 1, J) on the half-step grid t_k = k dt / 2;
        kp, kd: shape (J,) or one number. ``excitation_half``: the muscles' excitations (2 n_steps + 1,
        M) on the grid (``kernels.rk4_muscles``): y0, states and rates then have n_state +
        n_muscle_states columns (activations, compliant tendons' forces) and ``applied`` adds the
        muscles' generalised forces; None: the muscles (if any) left out. ``t0``: the time (s) of y0,
        the grid's first row, at which the external loads (if any) are taken along."""
        if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 1):
            raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt}")
        muscles = None if excitation_half is None else self.muscles_at(excitation_half)
        if muscles is not None and muscles.excitation.shape[0] != 2 * n_steps + 1:
            raise ValueError(f"excitation_half must have {2 * n_steps + 1} rows (the half-step grid), "
                             f"got {muscles.excitation.shape[0]}")
        width = self.n_state + (0 if muscles is None else self.n_muscle_states)
        y0 = self._vector(y0, width, "the initial state")
        tau, ref, refd, refdd = self._half_step_arrays(2 * n_steps + 1, tau_half=tau_half,
                                                       ref_half=ref_half, refd_half=refd_half, refdd_half=refdd_half)
        kp, kd, mode, gains = self._law(kp, kd, mode, gains, 2 * n_steps + 1)
        states, rates = np.empty((n_steps + 1, width)), np.empty((n_steps + 1, width))
        applied = np.empty((n_steps + 1, self.n_joints))
        law = Law(tau, ref, refd, refdd, kp, kd, mode, gains)
        loads, *believed = self.believed_args(nominal, lambda: t0 + np.arange(2 * n_steps + 1) * (0.5 * dt))

        def run(y, n, rows, out):
            if muscles is not None:
                return kernels.rk4_muscles(y, float(dt), n, rows.start, law, self.layout, self.paths, self.free, loads,
                                           *believed, muscles, *out)
            return kernels.rk4(y, float(dt), n, rows.start, law, self.layout, self.paths, self.free, loads, *believed,
                               *out)
        code, done, max_viol = self._in_chunks(run, y0, int(n_steps), (states, rates, applied))
        for array in (states, rates, applied):  # the kernel filled the rows up to step ``done``
            array[done + 1:] = np.nan
        return SimResult(int(code), int(done), float(max_viol), states, rates, applied,
                         lambda y: self.joints_from_state(y[:, :self.n_state]))

    def _in_chunks(self, run, y0, n_steps: int, out: tuple) -> tuple[int, int, float]:
        """``run(y, n, rows, out)`` (a compiled RK4 of n steps from y on the half-step rows ``rows``,
        filling the rows of ``out``) over n_steps steps in chunks of about CHUNK_S seconds each (the
        first of FIRST_CHUNK_VALUES state values), so that Ctrl-C (acted on between two calls, never
        inside compiled code) ends a long simulation within a fraction of a second. Each chunk starts
        from the last state of the one before, at the same grid row, so the numbers are those of one
        call. (status, steps done, largest violation)."""
        chunk = max(1, FIRST_CHUNK_VALUES // self.n_state)
        start, worst = 0, 0.0
        while True:
            n = min(chunk, n_steps - start)
            rows = slice(2 * start, 2 * (start + n) + 1)
            began = time.perf_counter()
            code, done, viol = run(out[0][start].copy() if start else y0, n, rows,
                                   tuple(array[start:start + n + 1] for array in out))
            worst, start = max(worst, viol), start + int(done)
            if code != 0 or start == n_steps:
                return int(code), start, worst
            chunk = max(1, int(CHUNK_S * n / max(time.perf_counter() - began, 1e-9)))

    def simulate_pd(self, z0, zd0, dt, n_steps, tau_half, ref_half, refd_half, kp, kd) -> SimResult:
        """``simulate`` under PD from the joint state (z0, zd0) (rad, rad/s), shapes (J,)."""
        zero = np.zeros((2 * n_steps + 1, self.n_joints)) if isinstance(n_steps, (int, np.integer)) else None
        return self.simulate(self.state_from_joints(z0, zd0), dt, n_steps, tau_half, ref_half, refd_half, zero, kp, kd)

    def rates(self, states, tau, ref, refd, refdd, kp, kd, mode=PD, gains=None,
              nominal: "Engine | None" = None, t=None) -> tuple[np.ndarray, np.ndarray]:
        """The state derivatives (k, n_state) and applied joint torques (k, J) (N m) of k states
        (k, n_state) under ``simulate``'s feedback law, row i with row i of tau, ref, refd, refdd
        (each (k, J)) and of gains ((k, J, 2J)): the adaptive integrators' right-hand side. The
        accelerations are NaN where the points' matrix is singular. t: the states' times (s, (k,)),
        needed with external loads."""
        states = np.ascontiguousarray(states, dtype=float)
        if states.ndim != 2 or states.shape[1] != self.n_state:
            raise ValueError(f"states must have shape (k, {self.n_state}), got {states.shape}")
        k = states.shape[0]
        tau, ref, refd, refdd = self._half_step_arrays(k, tau=tau, ref=ref, refd=refd, refdd=refdd)
        kp, kd, mode, gains = self._law(kp, kd, mode, gains, k)
        out, applied = np.empty((k, self.n_state)), np.empty((k, self.n_joints))
        if (self.loads is not None or (nominal is not None and nominal.loads is not None)) and t is None:
            raise ValueError("a model with external loads needs the times of its states")
        times = np.zeros(k) if t is None else np.asarray(t, dtype=float).reshape(k)
        loads, *believed = self.believed_args(nominal, times)
        kernels.derivatives(states, Law(tau, ref, refd, refdd, kp, kd, mode, gains), self.layout, self.paths,
                            self.free, loads, *believed, out, applied)
        return out, applied

    def population_args(self, y0, dt, n_steps, tau, ref_half, refd_half, every, angles_ref, penalty_weight,
                        excitation=None) -> tuple:
        """The arguments of ``fdbench.tracking.rk4_candidates`` before its work buffers, for
        ``fdbench.population.Population(rk4_candidates, n_steps, engine.population_widths)(lam, args)``:
        the start y0 (n_state,), the step dt (s), the candidates' torques tau (N m, shape (lam,
        2 n_steps + 1, J)), the half-step references ref_half (rad), refd_half (rad/s) (2 n_steps + 1,
        J), eq. 18's samples every ``every``-th step with the desired coordinates angles_ref (rad,
        shape (n_steps // every + 1, J)) and its penalty weight (deg), then the kernels' layout, the
        loads on the grid and the muscles: None, or with ``excitation`` (the candidates' excitations
        in [0, 1], shape (lam, 2 n_steps + 1, M)) their ``layout.Muscles`` (y0 then has n_state +
        n_muscle_states entries and the work buffers ``population_widths_with(True)``)."""
        if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 1):
            raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
        if not (isinstance(every, (int, np.integer)) and 1 <= every <= n_steps):
            raise ValueError(f"every must be an integer in [1, {n_steps}], got {every!r}")
        rows = 2 * n_steps + 1
        if np.ndim(tau) != 3 or np.shape(tau)[1:] != (rows, self.n_joints):
            raise ValueError(f"tau must have shape (candidates, {rows}, {self.n_joints}), got {np.shape(tau)}")
        ref, refd = self._half_step_arrays(rows, ref_half=ref_half, refd_half=refd_half)
        samples = (n_steps // every + 1, self.n_joints)
        if np.shape(angles_ref) != samples:
            raise ValueError(f"angles_ref must have shape {samples}, got {np.shape(angles_ref)}")
        muscles = None
        if excitation is not None:
            shape = (np.shape(tau)[0], rows, self.n_muscles)
            if not self.n_muscles or np.shape(excitation) != shape:
                raise ValueError(f"excitations must have shape {shape} (candidates, the half-step grid, muscles), "
                                 f"got {np.shape(excitation)}")
            muscles = Muscles(self.muscle_paths, self.muscle_params, self.tendon_row,
                              _writeable(excitation))
        width = self.n_state + (0 if muscles is None else self.n_muscle_states)
        return (self._vector(y0, width, "the initial state"), float(dt), int(n_steps),
                _writeable(tau), ref, refd, int(every), np.array(angles_ref, dtype=float),
                float(penalty_weight), *self.kernel_args(), self.loads_at(np.arange(rows) * (0.5 * float(dt))),
                muscles)

    @property
    def population_widths(self) -> tuple:
        """The trailing shapes of ``rk4_candidates``' work buffers: states, rates, applied."""
        return self.population_widths_with(False)

    def population_widths_with(self, muscles: bool) -> tuple:
        """``population_widths`` of candidates without or with (``muscles``) the muscle states."""
        width = self.n_state + (self.n_muscle_states if muscles else 0)
        return (width,), (width,), (self.n_joints,)

    def _half_step_arrays(self, rows: int, **arrays) -> list[np.ndarray]:
        """Each array as a new contiguous float array of shape (rows, J): writeable whatever the
        caller's flags, so that every entry of the RK4 driver passes the same types and numba
        compiles the driver once per kind of model, not once more per combination of writeable and
        read-only arguments; ValueError naming another shape."""
        shape = (rows, self.n_joints)
        for name, array in arrays.items():
            if np.shape(array) != shape:
                raise ValueError(f"{name} must have shape {shape} (the half-step grid), got {np.shape(array)}")
        return [np.array(array, dtype=float) for array in arrays.values()]

    def _law(self, kp, kd, mode, gains, rows: int):
        """kp, kd (J,), the mode and the gain matrices as the kernels take them."""
        if mode not in MODES:
            raise ValueError(f"mode must be one of PD={PD}, COMPUTED={COMPUTED}, GAINS={GAINS}, got {mode!r}")
        kp, kd = (np.full(self.n_joints, float(g)) if np.ndim(g) == 0
                  else self._vector(g, self.n_joints, name) for g, name in ((kp, "kp"), (kd, "kd")))
        shape = (rows, self.n_joints, 2 * self.n_joints)
        if mode == GAINS:
            if np.shape(gains) != shape:
                raise ValueError(f"gains must have shape {shape}, got {np.shape(gains)}")
            gains = np.array(gains, dtype=float)
        else:
            gains = np.zeros((1, *shape[1:]))
        return kp, kd, int(mode), gains


def _writeable(array) -> np.ndarray:
    """array as a contiguous, writeable float array (a copy only where it is not one already): the
    kernels compile once for writeable arguments, not once more for read-only ones."""
    if (type(array) is np.ndarray and array.dtype == np.float64 and array.flags.c_contiguous
            and array.flags.writeable):  # the common case, without np.require's cost (microseconds)
        return array
    return np.require(array, dtype=float, requirements=["C", "W"])
