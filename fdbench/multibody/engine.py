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
only as a guard, a NaN pivot as NONFINITE, and fdbench.dynamics.COS_TOL has no role here.

Mass matrix: each body's natural-coordinate mass matrix on its basic points (Garcia de Jalon and
Bayo, ch. 3) from its mass, com and inertia; Q_ext: gravity at the com and the loads mapped to the
basic points by r_P = C_P q. For the forearm this is eq. 4. The kernels take arrays only (a data
layout of indices and constants built once per Engine), so they are compiled once and cached for
every model. Strict IEEE arithmetic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..dynamics import CONSTRAINT, NONFINITE, OK, SINGULAR, VIOLATION_TOL
from ..jit import njit

from .description import Model, resolved_end

SIN_FORM_MIN_COS = 0.2  # the sin form of a body's angle constraint while |cos(phi + beta)| >= this
SAME_POINT_M = 1e-9  # m: a joint this close to a basic point of its parent sits on that point

# named indices into the kernels' arrays
ALPHA, TWO_XI_OMEGA, OMEGA2, SWITCH_COS, VIOLATION, N_PARAMS = 0, 1, 2, 3, 4, 5  # params
LENGTH, BETA = 0, 1  # body_geom columns: d (m), beta (rad)
LAMBDA, PIVOT, VELOCITY_TERM, FORM, N_AUX = 0, 1, 2, 3, 4  # aux columns per body
FIXED = -1  # pt_index of a point fixed to ground (and lin_idx padding)


@dataclass
class SimResult:
    """The outcome of ``Engine.simulate_pd``: status (fdbench.dynamics codes: 0 ok, 1 nonfinite,
    2 singular, 3 constraint), the steps done, the joint angles z (rad) and velocities zd (rad/s)
    at the steps, shape (n_steps + 1, J), NaN after ``steps_done``, the mixed-coordinate states
    (n_steps + 1, n_state) and the largest constraint violation reached (m^2 or m)."""

    status: int
    steps_done: int
    z: np.ndarray
    zd: np.ndarray
    max_violation: float
    states: np.ndarray


def _rotate(angle, local):
    """R(angle) local for angles of shape (...,) and a local vector (2,): shape (..., 2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([local[0] * c - local[1] * s, local[0] * s + local[1] * c], axis=-1)


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

    def __init__(self, model: Model, alpha: float = 1e7, xi: float = 1.0, omega: float = 10.0):
        from ..integrate import PENALTY_RANGES

        for name, value in (("alpha", alpha), ("xi", xi), ("omega", omega)):
            low, high = PENALTY_RANGES[name]
            if not (math.isfinite(value) and low <= value <= high):
                raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {value}")
        self.model = model
        self.joints = tuple(joint.name for joint in model.joints)
        self.n_joints = len(self.joints)
        self.params = np.zeros(N_PARAMS)
        self.params[ALPHA], self.params[TWO_XI_OMEGA], self.params[OMEGA2] = alpha, 2 * xi * omega, omega**2
        self.params[SWITCH_COS], self.params[VIOLATION] = SIN_FORM_MIN_COS, VIOLATION_TOL
        self._build_points()
        self._build_matrices()
        self.n_q = self.n_p + self.n_joints
        self.n_state = 2 * self.n_q

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
            if p == FIXED:
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
    def _kernel_layout(self):
        """The arrays every kernel takes, in order."""
        return (self.pt_index, self.pt_fixed, self.body_pts, self.body_geom, self.joint_parent, self.lin_idx,
                self.lin_coef, self.lin_const, self.first, self.base, self.q_ext, self.params)

    # ------------------------------------------------------------------ kinematics (numpy)
    def _kinematics(self, z, zd, zdd):
        """Body angles phi, rates w, angular accelerations (shape (n, B)) and body origins' positions,
        velocities and accelerations (shape (n, B, 2)); the joints' world positions (n, J, 2)."""
        n, B = z.shape[0], self.n_joints
        phi, w, al = np.zeros((n, B)), np.zeros((n, B)), np.zeros((n, B))
        o, vo, ao, joint_at = (np.zeros((n, B, 2)) for _ in range(4))
        for k, joint in enumerate(self.model.joints):
            p = self.joint_parent[k]
            if p == FIXED:
                phi[:, k], w[:, k], al[:, k] = z[:, k] + joint.offset, zd[:, k], zdd[:, k]
                r, v, a = np.asarray(joint.at_parent, dtype=float), 0.0, 0.0
            else:
                phi[:, k] = phi[:, p] + z[:, k] + joint.offset
                w[:, k], al[:, k] = w[:, p] + zd[:, k], al[:, p] + zdd[:, k]
                r, v, a = self._body_point(p, joint.at_parent, phi, w, al, o, vo, ao)
            joint_at[:, k] = r
            arm = _rotate(phi[:, k], np.asarray(joint.at_child, dtype=float))
            o[:, k] = r - arm
            vo[:, k] = v - w[:, k, None] * _perp(arm)
            ao[:, k] = a - al[:, k, None] * _perp(arm) + w[:, k, None] ** 2 * arm
        return phi, w, al, o, vo, ao, joint_at

    @staticmethod
    def _body_point(b, local, phi, w, al, o, vo, ao):
        """Position, velocity and acceleration (n, 2) of a point of body b (m, body frame)."""
        arm = _rotate(phi[:, b], np.asarray(local, dtype=float))
        return (o[:, b] + arm, vo[:, b] + w[:, b, None] * _perp(arm),
                ao[:, b] + al[:, b, None] * _perp(arm) - w[:, b, None] ** 2 * arm)

    def _free_points(self, z, zd, zdd):
        """p, p', p'' (n, n_p), the body angles, rates, accelerations (n, B) and the kinematics."""
        kin = self._kinematics(z, zd, zdd)
        phi, w, al, o, vo, ao, _ = kin
        n = z.shape[0]
        p, pd, pdd = np.zeros((n, self.n_p)), np.zeros((n, self.n_p)), np.zeros((n, self.n_p))
        for pt in range(self.n_points):
            k = self.pt_index[pt]
            if k != FIXED:
                p[:, k:k + 2], pd[:, k:k + 2], pdd[:, k:k + 2] = self._body_point(
                    self.pt_owner[pt], self.pt_local[pt], phi, w, al, o, vo, ao)
        return p, pd, pdd, kin

    def _velocity_transform(self, p, kin) -> np.ndarray:
        """R_p = dp/dz, shape (n, n_p, J): dr_P/dz_k = R90 (r_P - r_joint_k) for every joint k on the
        path of P's owner."""
        joint_at = kin[-1]
        R = np.zeros((p.shape[0], self.n_p, self.n_joints))
        for pt in range(self.n_points):
            k = self.pt_index[pt]
            if k == FIXED:
                continue
            for joint in self.model.path(self.body_names[self.pt_owner[pt]]):
                R[:, k:k + 2, joint] = _perp(p[:, k:k + 2] - joint_at[:, joint])
        return R

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
        """value as a contiguous float array of shape (size,); ValueError for another shape."""
        array = np.ascontiguousarray(value, dtype=float)
        if array.shape != (size,):
            raise ValueError(f"{what} must have shape ({size},), got {array.shape}")
        return array

    # ------------------------------------------------------------------ API
    def state_from_joints(self, z, zd) -> np.ndarray:
        """y = [q, q'] on the constraint manifold for joint angles z (rad) and rates zd (rad/s), shape (J,)."""
        z, zd = self._vector(z, self.n_joints, "z"), self._vector(zd, self.n_joints, "zd")
        p, pd, _, (phi, w, *_) = self._free_points(z[None], zd[None], np.zeros((1, self.n_joints)))
        return np.concatenate([p[0], phi[0], pd[0], w[0]])

    def joints_from_state(self, y) -> tuple[np.ndarray, np.ndarray]:
        """(z, zd) (rad, rad/s), shapes (J,), from the state y (n_state,) (or (n, n_state) -> (n, J))."""
        y = np.asarray(y, dtype=float)
        if y.shape[-1:] != (self.n_state,):
            raise ValueError(f"states must have shape ({self.n_state},) or (n, {self.n_state}), got {y.shape}")
        phi, w = y[..., self.n_p:self.n_q], y[..., self.n_q + self.n_p:]
        has_parent = self.joint_parent != FIXED
        parent = np.where(has_parent, self.joint_parent, 0)
        z = phi - np.where(has_parent, phi[..., parent], 0.0) - self.joint_offset
        zd = w - np.where(has_parent, w[..., parent], 0.0)
        return z, zd

    def accelerations(self, y, tau) -> np.ndarray:
        """y' = [q', q''] of eq. 12 for the state y (n_state,) and joint torques tau (J,) N m; NaN
        where the leading matrix is singular."""
        y, tau = self._vector(y, self.n_state, "the state"), self._vector(tau, self.n_joints, "tau")
        out = np.empty(self.n_state)
        work = _workspace(self.n_p, self.n_joints)
        code = _derivative(y, tau, *self._kernel_layout, *work, out)
        if code != OK:
            out[self.n_q:] = np.nan
        return out

    def constraint_violation(self, y) -> float:
        """max |Phi_i| (m^2 and m) of the state y, the angle constraints in the form in force."""
        return float(_violation(self._vector(y, self.n_state, "the state"), *self._kernel_layout))

    def inverse_dynamics(self, z, zd, zdd) -> np.ndarray:
        """Eq. 3: tau = R^T (M q'' - Q_ext) (N m) of joint angles, rates and accelerations (rad,
        rad/s, rad/s^2) of shape (n, J) or (J,); the same shape out."""
        (z, zd, zdd), single = self._samples(z, zd, zdd)
        p, _, pdd, kin = self._free_points(z, zd, zdd)
        tau = np.einsum("npj,np->nj", self._velocity_transform(p, kin), pdd @ self.mass - self.q_ext)
        return tau[0] if single else tau

    def mass_matrix(self, z) -> np.ndarray:
        """Minimal M(z) = R^T M R, shape (J, J) (or (n, J, J) for z of shape (n, J)), kg m^2."""
        (z,), single = self._samples(z)
        p, _, _, kin = self._free_points(z, np.zeros_like(z), np.zeros_like(z))
        R = self._velocity_transform(p, kin)
        M = np.einsum("npj,pq,nqk->njk", R, self.mass, R)
        return M[0] if single else M

    def bias(self, z, zd) -> np.ndarray:
        """h(z, z') (N m) with M(z) z'' + h(z, z') = tau: R^T (M R' z' - Q_ext), shape (J,) (or (n, J))."""
        return self.inverse_dynamics(z, zd, np.zeros_like(np.asarray(zd, dtype=float)))

    def point_positions(self, z) -> dict[str, np.ndarray]:
        """World positions (m) of every body's joint point ('<body>.joint') and end ('<body>.end'),
        shape (2,) (or (n, 2) for z of shape (n, J))."""
        (z,), single = self._samples(z)
        zero = np.zeros_like(z)
        phi, w, al, o, vo, ao, joint_at = self._kinematics(z, zero, zero)
        points = {}
        for b, name in enumerate(self.body_names):
            points[f"{name}.joint"] = joint_at[:, b]
            points[f"{name}.end"] = self._body_point(b, self._local_end[b], phi, w, al, o, vo, ao)[0]
        return {key: value[0] if single else value for key, value in points.items()}

    def simulate_pd(self, z0, zd0, dt, n_steps, tau_half, ref_half, refd_half, kp, kd) -> SimResult:
        """Classical RK4 of eq. 12 over n_steps steps of dt (s) from the joint state (z0, zd0) under
        tau = tau_half + kp (ref - z) + kd (refd - zd) per joint; tau_half (N m), ref_half (rad),
        refd_half (rad/s): shape (2 n_steps + 1, J) on the half-step grid t_k = k dt / 2; kp
        (N m/rad), kd (N m s/rad): shape (J,)."""
        if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 1):
            raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt}")
        shape = (2 * n_steps + 1, self.n_joints)
        for name, array in (("tau_half", tau_half), ("ref_half", ref_half), ("refd_half", refd_half)):
            if np.shape(array) != shape:
                raise ValueError(f"{name} must have shape {shape} (the half-step grid), got {np.shape(array)}")
        tau_half, ref_half, refd_half = (np.ascontiguousarray(a, dtype=float) for a in (tau_half, ref_half, refd_half))
        kp, kd = self._vector(kp, self.n_joints, "kp"), self._vector(kd, self.n_joints, "kd")
        states = np.full((n_steps + 1, self.n_state), np.nan)
        ref_half = ref_half + self.joint_offset  # the kernel compares with phi_child - phi_parent
        code, done, max_viol = rk4_pd(self.state_from_joints(z0, zd0), float(dt), int(n_steps), tau_half, ref_half,
                                      refd_half, kp, kd, *self._kernel_layout, states)
        z, zd = self.joints_from_state(states)
        return SimResult(int(code), int(done), z, zd, float(max_viol), states)


def _workspace(n_p, n_joints):
    """The kernels' scratch arrays: the points' matrix, right-hand side, per-body values, torques."""
    return np.zeros((n_p, n_p)), np.zeros(n_p), np.zeros((n_joints, N_AUX)), np.zeros(n_joints)


# ---------------------------------------------------------------------- compiled kernels
@njit(inline="always")
def _point(y, n_q, pt, pt_index, pt_fixed):
    """x, y, x', y' of a point (fixed points: their position and zero velocity)."""
    k = pt_index[pt]
    if k < 0:
        return pt_fixed[pt, 0], pt_fixed[pt, 1], 0.0, 0.0
    return y[k], y[k + 1], y[n_q + k], y[n_q + k + 1]


@njit(inline="always")
def _angle_form(c, switch):
    """1 for the sin form of the angle constraint (|cos| >= switch), 0 for the cos form."""
    return 1 if abs(c) >= switch else 0


@njit(inline="always")
def _violation(y, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base,
               q_ext, params):
    """max |Phi_i| (m^2 and m) of the state y: distances, angles (the form in force), linear."""
    n_b = body_pts.shape[0]
    n_q = base.shape[0] + n_b
    worst = 0.0
    for b in range(n_b):
        xi, yi, _, _ = _point(y, n_q, body_pts[b, 0], pt_index, pt_fixed)
        xj, yj, _, _ = _point(y, n_q, body_pts[b, 1], pt_index, pt_fixed)
        dx, dy, d = xj - xi, yj - yi, body_geom[b, LENGTH]
        psi = y[base.shape[0] + b] + body_geom[b, BETA]
        c = math.cos(psi)
        angle = dy - d * math.sin(psi) if _angle_form(c, params[SWITCH_COS]) == 1 else dx - d * c
        worst = max(worst, max(abs(dx * dx + dy * dy - d * d), abs(angle)))
    for r in range(lin_const.shape[0]):
        value = lin_const[r]
        for e in range(lin_idx.shape[1]):
            if lin_idx[r, e] >= 0:
                value += lin_coef[r, e] * y[lin_idx[r, e]]
        worst = max(worst, abs(value))
    return worst


@njit(error_model="numpy", inline="always")
def _derivative(y, tau, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first,
                base, q_ext, params, K, rhs, aux, q_phi, out):
    """y' = [q', q''] of eq. 12 into out for the state y and joint torques tau (N m). K, rhs, aux,
    q_phi: scratch (``_workspace``). Returns OK, or SINGULAR where a pivot of the points' matrix is
    not positive (then out[n_q:] is left unfinished)."""
    n_p, n_b = base.shape[0], body_pts.shape[0]
    n_q = n_p + n_b
    alpha, txo, om2 = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2]
    for k in range(n_q):
        out[k] = y[n_q + k]
    for k in range(n_b):  # joint torques -> generalised forces of the absolute angles
        q_phi[k] = tau[k]
    for k in range(n_b):
        if joint_parent[k] >= 0:
            q_phi[joint_parent[k]] -= tau[k]
    for r in range(n_p):
        rhs[r] = q_ext[r]
        for c in range(first[r], r + 1):
            K[r, c] = base[r, c]
    for r in range(lin_const.shape[0]):  # linear constraints: their J^T J is in base
        phi, rate = lin_const[r], 0.0
        for e in range(lin_idx.shape[1]):
            k = lin_idx[r, e]
            if k >= 0:
                phi += lin_coef[r, e] * y[k]
                rate += lin_coef[r, e] * y[n_q + k]
        cc = alpha * (txo * rate + om2 * phi)
        for e in range(lin_idx.shape[1]):
            k = lin_idx[r, e]
            if k >= 0:
                rhs[k] -= lin_coef[r, e] * cc
    for b in range(n_b):
        ki, kj = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        xi, yi, vxi, vyi = _point(y, n_q, body_pts[b, 0], pt_index, pt_fixed)
        xj, yj, vxj, vyj = y[kj], y[kj + 1], y[n_q + kj], y[n_q + kj + 1]
        dx, dy, dvx, dvy = xj - xi, yj - yi, vxj - vxi, vyj - vyi
        d = body_geom[b, LENGTH]
        psi = y[n_p + b] + body_geom[b, BETA]
        w = y[n_q + n_p + b]
        s, c = math.sin(psi), math.cos(psi)
        # distance: Phi = |dr|^2 - d^2, J = 2 dr on j, -2 dr on i
        cd = 2 * (dvx * dvx + dvy * dvy) + txo * 2 * (dx * dvx + dy * dvy) + om2 * (dx * dx + dy * dy - d * d)
        p4 = 4 * alpha
        K[kj, kj] += p4 * dx * dx
        K[kj + 1, kj] += p4 * dx * dy
        K[kj + 1, kj + 1] += p4 * dy * dy
        rhs[kj] -= 2 * alpha * dx * cd
        rhs[kj + 1] -= 2 * alpha * dy * cd
        if ki >= 0:
            K[ki, ki] += p4 * dx * dx
            K[ki + 1, ki] += p4 * dx * dy
            K[ki + 1, ki + 1] += p4 * dy * dy
            K[kj, ki] -= p4 * dx * dx
            K[kj, ki + 1] -= p4 * dx * dy
            K[kj + 1, ki] -= p4 * dx * dy
            K[kj + 1, ki + 1] -= p4 * dy * dy
            rhs[ki] += 2 * alpha * dx * cd
            rhs[ki + 1] += 2 * alpha * dy * cd
        # angle: its row gives the multiplier lambda = Q_phi / (dPhi/dphi)
        form = _angle_form(c, params[SWITCH_COS])
        if form == 1:  # (y_j - y_i) - d sin(psi)
            pivot = -d * c
            ca = d * s * w * w + txo * (dvy - d * c * w) + om2 * (dy - d * s)
            axis = 1
        else:  # (x_j - x_i) - d cos(psi)
            pivot = d * s
            ca = d * c * w * w + txo * (dvx + d * s * w) + om2 * (dx - d * c)
            axis = 0
        lam = q_phi[b] / pivot
        rhs[kj + axis] -= lam
        if ki >= 0:
            rhs[ki + axis] += lam
        aux[b, LAMBDA], aux[b, PIVOT], aux[b, VELOCITY_TERM], aux[b, FORM] = lam, pivot, ca, axis
    code = _solve_envelope(K, first, rhs)
    if code != OK:
        return code
    for r in range(n_p):
        out[n_q + r] = rhs[r]
    for b in range(n_b):
        ki, kj = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        axis = int(aux[b, FORM])
        rel = rhs[kj + axis] - (rhs[ki + axis] if ki >= 0 else 0.0)
        out[n_q + n_p + b] = (aux[b, LAMBDA] / alpha - aux[b, VELOCITY_TERM] - rel) / aux[b, PIVOT]
    return OK


@njit(error_model="numpy", inline="always")
def _solve_envelope(K, first, rhs):
    """Solve K x = rhs in place (x into rhs) for K symmetric positive definite, its lower triangle
    given inside the envelope first[r] <= c <= r, by L D L^T (L into K's strict lower triangle, D on
    its diagonal). Returns OK, NONFINITE for a pivot that is NaN, or SINGULAR for one that is not
    positive (rank lost; rhs is then unfinished)."""
    n = rhs.shape[0]
    for r in range(n):
        fr = first[r]
        for c in range(fr, r):
            total = K[r, c]
            for k in range(max(fr, first[c]), c):
                total -= K[r, k] * K[c, k]  # K[r, k] holds L[r, k] D[k] until row r is done
            K[r, c] = total
        diag = K[r, r]
        for c in range(fr, r):
            lrc = K[r, c] / K[c, c]
            diag -= lrc * K[r, c]
            K[r, c] = lrc
        if math.isnan(diag):
            return NONFINITE
        if not diag > 0.0:
            return SINGULAR
        K[r, r] = diag
    for r in range(n):  # L z = rhs
        total = rhs[r]
        for k in range(first[r], r):
            total -= K[r, k] * rhs[k]
        rhs[r] = total
    for r in range(n):
        rhs[r] /= K[r, r]
    for r in range(n - 1, -1, -1):  # L^T x = z, column by column
        x = rhs[r]
        for k in range(first[r], r):
            rhs[k] -= K[r, k] * x
    return OK


@njit(error_model="numpy", inline="always")
def _pd_derivative(y, half, tau_half, ref_half, refd_half, kp, kd, pt_index, pt_fixed, body_pts, body_geom,
                   joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, K, rhs, aux, q_phi, torque,
                   out):
    """The state derivative at grid index ``half`` under per-joint PD feedback plus feedforward."""
    n_p, n_b = base.shape[0], body_pts.shape[0]
    n_q = n_p + n_b
    for k in range(n_b):
        p = joint_parent[k]
        z = y[n_p + k] - (y[n_p + p] if p >= 0 else 0.0)
        zd = y[n_q + n_p + k] - (y[n_q + n_p + p] if p >= 0 else 0.0)
        torque[k] = tau_half[half, k] + kp[k] * (ref_half[half, k] - z) + kd[k] * (refd_half[half, k] - zd)
    return _derivative(y, torque, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const,
                       first, base, q_ext, params, K, rhs, aux, q_phi, out)


@njit(error_model="numpy")
def rk4_pd(y0, dt, n_steps, tau_half, ref_half, refd_half, kp, kd, pt_index, pt_fixed, body_pts, body_geom,
           joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, states):
    """Classical RK4 of eq. 12 over n_steps steps of dt (s) under per-joint PD plus feedforward (see
    ``Engine.simulate_pd``; ref_half holds the reference joint angles plus the joint offsets, as the
    kernel's z is the difference of the body angles). Fills
    states (n_steps + 1, n_state) up to the last step reached. Returns (status, steps_done, max
    constraint violation)."""
    n_p, n_b = base.shape[0], body_pts.shape[0]
    n = y0.shape[0]
    K, rhs, aux, q_phi = np.zeros((n_p, n_p)), np.zeros(n_p), np.zeros((n_b, N_AUX)), np.zeros(n_b)
    torque = np.zeros(n_b)
    y = y0.copy()
    k1, k2, k3, k4, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    max_viol = _violation(y, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const,
                          first, base, q_ext, params)
    for i in range(n_steps + 1):
        j = 2 * i
        code = _pd_derivative(y, j, tau_half, ref_half, refd_half, kp, kd, pt_index, pt_fixed, body_pts, body_geom,
                              joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, K, rhs, aux,
                              q_phi, torque, k1)
        for m in range(n):
            states[i, m] = y[m]
        if code != OK:
            return code, i, max_viol
        if i == n_steps:
            break
        for m in range(n):
            tmp[m] = y[m] + 0.5 * dt * k1[m]
        code = _pd_derivative(tmp, j + 1, tau_half, ref_half, refd_half, kp, kd, pt_index, pt_fixed, body_pts,
                              body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, K,
                              rhs, aux, q_phi, torque, k2)
        if code == OK:
            for m in range(n):
                tmp[m] = y[m] + 0.5 * dt * k2[m]
            code = _pd_derivative(tmp, j + 1, tau_half, ref_half, refd_half, kp, kd, pt_index, pt_fixed, body_pts,
                                  body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params,
                                  K, rhs, aux, q_phi, torque, k3)
        if code == OK:
            for m in range(n):
                tmp[m] = y[m] + dt * k3[m]
            code = _pd_derivative(tmp, j + 2, tau_half, ref_half, refd_half, kp, kd, pt_index, pt_fixed, body_pts,
                                  body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params,
                                  K, rhs, aux, q_phi, torque, k4)
        if code != OK:
            return code, i, max_viol
        finite = True
        for m in range(n):
            tmp[m] = y[m] + dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            finite = finite and math.isfinite(tmp[m])
        if not finite:
            return NONFINITE, i, max_viol
        viol = _violation(tmp, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const,
                          first, base, q_ext, params)
        if viol > params[VIOLATION]:
            return CONSTRAINT, i, max(max_viol, viol)
        max_viol = max(max_viol, viol)
        y[:] = tmp
    return OK, n_steps, max_viol
