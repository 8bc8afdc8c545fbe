"""An independent reference for the multibody engine: planar trees of pin joints in MINIMAL
coordinates z (the joint angles), straight from the model description.

Why it is independent of the engine: the engine works in the paper's mixed coordinates (natural
coordinates of two points per body plus the angles, constraints, the penalty formulation of eq. 12).
Here there are no points, constraints or penalties: body frames are placed by rotations along each
body's path from ground, and the dynamics come from two separate constructions,
- Newton-Euler for the inverse dynamics tau(z, z', z''): the recursive Newton-Euler algorithm
  (Featherstone's RNEA, planar: a body's angular velocity is the sum of its path's joint rates),
  its forward recursion written as sums along each body's path and its backward recursion as sums
  over each joint's subtree (the same equations, vectorised over bodies and over a batch), and
- the kinetic energy T = 1/2 z'^T M(z) z' written with each body's Jacobians for the mass matrix,
so the self-checks can test them against each other, and the forward dynamics
z'' = M^{-1} (tau - h(z, z')) integrated by scipy's DOP853 at rtol = atol = 1e-12.

Conventions (the description's): body k is the child of joint k (joints in topological order); its
frame angle is the parent's plus z_k + offset_k; joint k's point is parent origin + R(parent angle)
at_parent = child origin + R(child angle) at_child; tau_k acts + on the child and - on the parent;
gravity acts at each body's com, each load's force is constant in world axes at a body point.
SI units, angles in rad. Arrays may carry leading (batch) axes: z, z', z'' of shape (..., J).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GROUND = "ground"


@dataclass(frozen=True)
class Tree:
    """The arrays of a model, indexed by joint (body k is the child of joint k).

    parent: (J,) int, the joint whose child is joint k's parent body, -1 for ground; at_parent,
    at_child, com: (J, 2) m; offset: (J,) rad; mass: (J,) kg; inertia: (J,) kg m^2 about the com;
    gravity: (2,) m/s^2; load_joint: (L,) int, the body a load acts on; load_at: (L, 2) m, body
    frame; load_force: (L, 2) N, world axes; on_path: (J, J), 1 where joint k is on the path from
    ground to body b (on_path[b, k]), else 0: a body's motion sums its path's joints' terms, a joint
    carries its subtree."""

    parent: np.ndarray
    at_parent: np.ndarray
    at_child: np.ndarray
    offset: np.ndarray
    com: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    gravity: np.ndarray
    load_joint: np.ndarray
    load_at: np.ndarray
    load_force: np.ndarray
    on_path: np.ndarray

    @property
    def n_joints(self) -> int:
        return len(self.parent)


def tree(model) -> Tree:
    """The model description's arrays, read from its fields only (none of its helpers)."""
    of_child = {joint.child: k for k, joint in enumerate(model.joints)}
    bodies = {body.name: body for body in model.bodies}
    parent = [-1 if joint.parent == GROUND else of_child[joint.parent] for joint in model.joints]
    assert all(p < k for k, p in enumerate(parent)), "joints are not in topological order"
    children = [bodies[joint.child] for joint in model.joints]
    on_path = np.zeros((len(parent), len(parent)))
    for b in range(len(parent)):
        k = b
        while k >= 0:
            on_path[b, k], k = 1.0, parent[k]

    def points(values):
        return np.array(values, dtype=float).reshape(-1, 2)

    return Tree(parent=np.array(parent, dtype=int),
                at_parent=points([joint.at_parent for joint in model.joints]),
                at_child=points([joint.at_child for joint in model.joints]),
                offset=np.array([joint.offset for joint in model.joints], dtype=float),
                com=points([body.com for body in children]),
                mass=np.array([body.mass for body in children], dtype=float),
                inertia=np.array([body.inertia for body in children], dtype=float),
                gravity=np.array(model.gravity, dtype=float),
                load_joint=np.array([of_child[load.body] for load in model.loads], dtype=int),
                load_at=points([load.at for load in model.loads]),
                load_force=points([load.force for load in model.loads]), on_path=on_path)


# ----------------------------------------------------------------------------- kinematics


def _rotate(angle, v):
    """R(angle_k) v_k for angles (..., J) and body-frame vectors v (J, 2): shape (..., J, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=-1)


def _perp(v):
    """The vectors v (..., 2) turned by +90 degrees: e_z x v."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def _cross(a, b):
    """The z component of a x b for vectors (..., 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _sum_path(A, terms):
    """sum over the joints k on each body's path of terms[..., k, :]: shape (..., J, 2)."""
    return np.einsum("bk,...kx->...bx", A, terms)


@dataclass
class Frames:
    """Every body's motion, indexed by its joint: angle (rad), angular velocity (rad/s) and
    acceleration (rad/s^2), each (..., J); origin, its velocity and acceleration, and joint (the
    joint's point), each (..., J, 2) in m, m/s, m/s^2."""

    angle: np.ndarray
    rate: np.ndarray
    spin: np.ndarray
    origin: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    joint: np.ndarray

    def points(self, local):
        """Position, velocity and acceleration (each (..., J, 2)) of one body-fixed point per body,
        local (J, 2) (m, each in its body's frame)."""
        r = _rotate(self.angle, local)
        w, dw = self.rate[..., None], self.spin[..., None]
        return self.origin + r, self.velocity + w * _perp(r), self.acceleration + dw * _perp(r) - w**2 * r


def frames(t: Tree, z, zd, zdd) -> Frames:
    """The bodies' motion for the joint angles z, rates z' and accelerations z'' (..., J).

    A body's angle, rate and angular acceleration are sums over its path; its origin is the sum over
    its path of each joint's step u_k = R(parent angle) at_parent_k - R(angle_k) at_child_k (from
    the parent's origin to the child's), and so are the steps' derivatives."""
    z, zd, zdd = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (z, zd, zdd)))
    A = t.on_path
    angle, rate, spin = (z + t.offset) @ A.T, zd @ A.T, zdd @ A.T

    def of_parent(x):  # the parent's value per joint, 0 for ground (index -1: the zero appended)
        return np.concatenate([x, np.zeros(x.shape[:-1] + (1,))], axis=-1)[..., t.parent]

    p_angle, p_rate, p_spin = of_parent(angle), of_parent(rate)[..., None], of_parent(spin)[..., None]
    to_joint, to_origin = _rotate(p_angle, t.at_parent), -_rotate(angle, t.at_child)
    w, dw = rate[..., None], spin[..., None]
    step = to_joint + to_origin
    step_v = p_rate * _perp(to_joint) + w * _perp(to_origin)
    step_a = p_spin * _perp(to_joint) - p_rate**2 * to_joint + dw * _perp(to_origin) - w**2 * to_origin
    origin = _sum_path(A, step)
    return Frames(angle, rate, spin, origin, _sum_path(A, step_v), _sum_path(A, step_a), origin - to_origin)


# ----------------------------------------------------------------------------- dynamics


def _torques(t: Tree, f: Frames, external: bool) -> np.ndarray:
    """Newton-Euler: the torque of joint k is the moment about its point that the subtree it
    carries needs, I alpha + G x m (a_G - g) summed over the subtree's bodies, minus the loads'
    moments (the RNEA's backward recursion, f_k = own + sum of the children's, written as sums over
    subtrees). ``external`` False leaves out gravity and loads. Shape (..., J), N m."""
    com, _, com_a = f.points(t.com)
    gravity = t.gravity if external else np.zeros(2)
    force = t.mass[:, None] * (com_a - gravity)  # what the joint and the loads must supply, (..., J, 2)
    moment = t.inertia * f.spin + _cross(com, force)  # about the world's origin, (..., J)
    if external:
        for j, at, load in zip(t.load_joint, t.load_at, t.load_force):
            point = f.origin[..., j, :] + _rotate(f.angle[..., j:j + 1], at[None])[..., 0, :]
            force[..., j, :] -= load
            moment[..., j] -= _cross(point, load)
    A = t.on_path
    subtree_force, subtree_moment = np.einsum("bk,...bx->...kx", A, force), moment @ A
    return subtree_moment - _cross(f.joint, subtree_force)


def inverse_dynamics(t: Tree, z, zd, zdd, external: bool = True) -> np.ndarray:
    """The joint torques tau (..., J) (N m) of the motion z, z', z'' (..., J)."""
    return _torques(t, frames(t, z, zd, zdd), external)


def _mass_matrix(t: Tree, f: Frames) -> np.ndarray:
    A = t.on_path
    com = f.points(t.com)[0]  # (..., B, 2)
    lever = _perp(com[..., :, None, :] - f.joint[..., None, :, :]) * A[..., None]  # (..., B, J, 2)
    return np.einsum("b,...bjx,...bkx->...jk", t.mass, lever, lever) + np.einsum("b,bj,bk->jk", t.inertia, A, A)


def mass_matrix(t: Tree, z) -> np.ndarray:
    """M(z) (..., J, J) (kg m^2) from the kinetic energy T = 1/2 z'^T M z' =
    sum_b 1/2 (m_b |v_G|^2 + I_b w_b^2), with v_G = sum_k e_z x (G_b - P_k) z'_k and w_b = sum_k z'_k
    over the joints k on body b's path (P_k the joint's point, G_b the body's com)."""
    z = np.asarray(z, dtype=float)
    return _mass_matrix(t, frames(t, z, np.zeros_like(z), np.zeros_like(z)))


def bias(t: Tree, z, zd) -> np.ndarray:
    """h(z, z') (..., J) (N m) of M z'' + h = tau: velocity, gravity and load terms."""
    return inverse_dynamics(t, z, zd, np.zeros_like(np.asarray(zd, dtype=float)))


def forward_dynamics(t: Tree, z, zd, tau) -> np.ndarray:
    """z'' (J,) (rad/s^2) = M^{-1} (tau - h) for one state z, z' (J,) under the torques tau (J,) N m."""
    f = frames(t, z, zd, np.zeros_like(np.asarray(zd, dtype=float)))
    return np.linalg.solve(_mass_matrix(t, f), np.asarray(tau, dtype=float) - _torques(t, f, True))


def kinetic_energy(t: Tree, z, zd) -> np.ndarray:
    """T (...) (joules) from the bodies' com velocities and angular velocities."""
    f = frames(t, z, zd, np.zeros_like(np.asarray(zd, dtype=float)))
    v = f.points(t.com)[1]
    return 0.5 * (np.sum(v**2, axis=-1) @ t.mass + f.rate**2 @ t.inertia)


def potential_energy(t: Tree, z) -> np.ndarray:
    """V (...) (joules) of gravity and the constant loads: -sum m g . G - sum F . (load point)."""
    z = np.asarray(z, dtype=float)
    f = frames(t, z, np.zeros_like(z), np.zeros_like(z))
    total = -(f.points(t.com)[0] @ t.gravity) @ t.mass
    for j, at, load in zip(t.load_joint, t.load_at, t.load_force):
        total = total - (f.origin[..., j, :] + _rotate(f.angle[..., j:j + 1], at[None])[..., 0, :]) @ load
    return total


# ----------------------------------------------------------------------------- simulation


def simulate(t: Tree, z0, zd0, t_end, torque, t_eval, tolerance: float = 1e-12):
    """DOP853 (rtol = atol = ``tolerance``) of the forward dynamics from z0, z'0 (J,) over [0, t_end] s
    under torque(time, z, z') -> tau (J,) N m (a Tree, or a GeneralTree). Returns (z, z') at t_eval,
    each (len(t_eval), J)."""
    from scipy.integrate import solve_ivp

    J = t.n_joints

    def rhs(time, y):
        z, zd = y[:J], y[J:]
        accelerations = (t.forward_dynamics(z, zd, torque(time, z, zd)) if isinstance(t, GeneralTree)
                         else forward_dynamics(t, z, zd, torque(time, z, zd)))
        return np.concatenate([zd, accelerations])

    sol = solve_ivp(rhs, (0.0, t_end), np.concatenate([z0, zd0]), method="DOP853", rtol=tolerance, atol=tolerance,
                    t_eval=t_eval)
    assert sol.success, sol.message
    return sol.y[:J].T, sol.y[J:].T


def simulate_pd(t: Tree, z0, zd0, t_end, feedforward, reference, kp, kd, t_eval, tolerance: float = 1e-12):
    """The engine's PD law tau = feedforward(t) + kp (ref - z) + kd (ref' - z') per joint, with
    reference(t) -> (ref, ref') (rad, rad/s) and kp (N m/rad), kd (N m s/rad) of shape (J,),
    integrated as ``simulate``. Returns (z, z') at t_eval."""
    kp, kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)

    def torque(time, z, zd):
        ref, refd = reference(time)
        return feedforward(time) + kp * (ref - z) + kd * (refd - zd)

    return simulate(t, z0, zd0, t_end, torque, t_eval, tolerance)


# ============================================================================= free bases and joint paths
# Trees with free planar joints (three coordinates: angle, x, y of the child's joint point from
# at_parent, world axes) and pin joints whose point moves along a path in the parent's frame
# (at_parent + (x(angle), y(angle)), the cubic spline OpenSim's SimmSpline evaluates). Minimal
# coordinates again, by a construction of its own: every body's angle and centre of mass as
# functions of the coordinates, evaluated on truncated Taylor series ("jets") along q(s) = q + s u
# + s^2 w / 2, which give exact first and second derivatives: the Jacobians (u a unit vector, w 0)
# and the accelerations (u = z', w = z''). The inverse dynamics is d'Alembert's principle in these
# Jacobians, sum_b J_Gb^T m_b (a_G - g) + J_phi^T I_b alpha_b - sum_loads J_L^T F; M = sum m J_G^T
# J_G + I J_phi^T J_phi. The spline's second derivatives solve their own linear system (continuity
# of the first derivative, and at each end the third derivative of the cubic through the four
# samples nearest it: 6 times their third divided difference).


class Jet:
    """a0 + a1 s + a2 s^2 (s the jet's parameter): numbers or arrays (2,) alike."""

    def __init__(self, a0, a1=0.0, a2=0.0):
        self.a = (a0, a1, a2)

    @staticmethod
    def of(value):
        return value if isinstance(value, Jet) else Jet(value)

    def __add__(self, other):
        o = Jet.of(other).a
        return Jet(*(x + y for x, y in zip(self.a, o)))

    __radd__ = __add__

    def __neg__(self):
        return Jet(*(-x for x in self.a))

    def __sub__(self, other):
        return self + (-Jet.of(other))

    def __rsub__(self, other):
        return Jet.of(other) - self

    def __mul__(self, other):
        (a0, a1, a2), (b0, b1, b2) = self.a, Jet.of(other).a
        return Jet(a0 * b0, a0 * b1 + a1 * b0, a0 * b2 + a1 * b1 + a2 * b0)

    __rmul__ = __mul__

    def apply(self, f0, f1, f2):
        """f(jet) for f with value f0, f' f1 and f'' f2 at a0 (a scalar jet)."""
        a0, a1, a2 = self.a
        return Jet(f0, f1 * a1, f1 * a2 + 0.5 * f2 * a1 * a1)


def jet_sin(x: Jet) -> Jet:
    return x.apply(np.sin(x.a[0]), np.cos(x.a[0]), -np.sin(x.a[0]))


def jet_cos(x: Jet) -> Jet:
    return x.apply(np.cos(x.a[0]), -np.sin(x.a[0]), -np.cos(x.a[0]))


def jet_rotate(angle: Jet, local) -> tuple[Jet, Jet]:
    """R(angle) local for a body-frame vector local (two jets or numbers): (x, y) jets."""
    c, s = jet_cos(angle), jet_sin(angle)
    lx, ly = local
    return c * lx - s * ly, s * lx + c * ly


class ReferenceSpline:
    """The interpolating cubic through (x, y) with OpenSim's SimmSpline end conditions, continued by
    its end slopes beyond x; value, first and second derivative by ``at``."""

    def __init__(self, x, y):
        self.x, self.y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        n, h = len(self.x), np.diff(self.x)
        self.m = np.zeros(n)  # second derivatives at the knots
        if n >= 3:
            A, b = np.zeros((n, n)), np.zeros(n)
            for i in range(1, n - 1):  # the first derivative is continuous at knot i
                A[i, i - 1:i + 2] = h[i - 1] / 6, (h[i - 1] + h[i]) / 3, h[i] / 6
                b[i] = (self.y[i + 1] - self.y[i]) / h[i] - (self.y[i] - self.y[i - 1]) / h[i - 1]
            A[0, :2], A[-1, -2:] = (-1 / h[0], 1 / h[0]), (-1 / h[-1], 1 / h[-1])  # the end third derivatives
            if n > 3:
                b[0] = 6 * self._third_difference(slice(0, 4))
                b[-1] = 6 * self._third_difference(slice(n - 4, n))
            self.m = np.linalg.solve(A, b)

    def _third_difference(self, part):
        x, y = self.x[part], self.y[part]
        table = list(y)
        for order in range(1, 4):
            table = [(table[i + 1] - table[i]) / (x[i + order] - x[i]) for i in range(len(table) - 1)]
        return table[0]

    def at(self, t: float):
        """(value, first, second derivative) at the number t."""
        x, y, m = self.x, self.y, self.m
        if t < x[0] or t > x[-1]:
            end = 0 if t < x[0] else -1
            slope = self.at(x[end])[1]
            return y[end] + (t - x[end]) * slope, slope, 0.0
        k = min(max(int(np.searchsorted(x, t, side="right")) - 1, 0), len(x) - 2)
        h, a, b = x[k + 1] - x[k], x[k + 1] - t, t - x[k]
        left, right = y[k] / h - m[k] * h / 6, y[k + 1] / h - m[k + 1] * h / 6
        value = (m[k] * a**3 + m[k + 1] * b**3) / (6 * h) + left * a + right * b
        first = (-m[k] * a**2 + m[k + 1] * b**2) / (2 * h) - left + right
        second = (m[k] * a + m[k + 1] * b) / h
        return value, first, second


class GeneralTree:
    """A model description with pin, path and free joints, in minimal coordinates (the model's
    coordinates in order: a free joint's angle, x, y), read from its fields only."""

    def __init__(self, model):
        self.model = model
        self.of_child = {joint.child: k for k, joint in enumerate(model.joints)}
        self.bodies = [next(b for b in model.bodies if b.name == joint.child) for joint in model.joints]
        sizes = [3 if joint.type == "free" else 1 for joint in model.joints]
        self.column = list(np.cumsum([0] + sizes[:-1]))
        self.n_joints = sum(sizes)
        self.paths = [None if joint.path is None else (ReferenceSpline(joint.path.angles, joint.path.x),
                                                       ReferenceSpline(joint.path.y_angles or joint.path.angles,
                                                                       joint.path.y))
                      for joint in model.joints]

    def _frames(self, q):
        """Per body: (angle jet, origin (x, y) jets) for coordinates q, a list of jets."""
        angle, origin = [], []
        for k, joint in enumerate(self.model.joints):
            c = self.column[k]
            if joint.parent == GROUND:
                p_angle, p_origin = Jet(0.0), (Jet(0.0), Jet(0.0))
            else:
                p = self.of_child[joint.parent]
                p_angle, p_origin = angle[p], origin[p]
            local = [Jet(joint.at_parent[0]), Jet(joint.at_parent[1])]
            if self.paths[k] is not None:
                for axis, spline in enumerate(self.paths[k]):
                    local[axis] = local[axis] + q[c].apply(*spline.at(q[c].a[0]))
            step = jet_rotate(p_angle, local)
            point = [p_origin[0] + step[0], p_origin[1] + step[1]]
            if joint.type == "free":
                point = [point[0] + q[c + 1], point[1] + q[c + 2]]
            body_angle = p_angle + q[c] + joint.offset
            arm = jet_rotate(body_angle, joint.at_child)
            angle.append(body_angle)
            origin.append((point[0] - arm[0], point[1] - arm[1]))
        return angle, origin

    def _points(self, q):
        """Per body its angle jet and com (x, y) jets; per load its point's (x, y) jets."""
        angle, origin = self._frames(q)
        coms = []
        for k, body in enumerate(self.bodies):
            arm = jet_rotate(angle[k], body.com)
            coms.append((origin[k][0] + arm[0], origin[k][1] + arm[1]))
        loads = []
        for load in self.model.loads:
            k = self.of_child[load.body]
            arm = jet_rotate(angle[k], load.at)
            loads.append((origin[k][0] + arm[0], origin[k][1] + arm[1]))
        return angle, coms, loads

    def _jacobians(self, z):
        """d(angle)/dq (B, J), d(com)/dq (B, 2, J) and d(load point)/dq (L, 2, J) at z."""
        J = self.n_joints
        dphi, dcom, dload = np.zeros((len(self.bodies), J)), np.zeros((len(self.bodies), 2, J)), np.zeros(
            (len(self.model.loads), 2, J))
        for j in range(J):
            angle, coms, loads = self._points([Jet(z[i], float(i == j)) for i in range(J)])
            for b in range(len(self.bodies)):
                dphi[b, j] = angle[b].a[1]
                dcom[b, :, j] = coms[b][0].a[1], coms[b][1].a[1]
            for i, point in enumerate(loads):
                dload[i, :, j] = point[0].a[1], point[1].a[1]
        return dphi, dcom, dload

    def inverse_dynamics_one(self, z, zd, zdd, external=True, jacobians=None):
        """tau (J,) (N m, N for translations) of one state z, z', z'' (J,) (``jacobians``: those of
        ``_jacobians(z)`` if known)."""
        angle, coms, _ = self._points([Jet(z[i], zd[i], 0.5 * zdd[i]) for i in range(self.n_joints)])
        dphi, dcom, dload = jacobians or self._jacobians(z)
        gravity = np.asarray(self.model.gravity, dtype=float) if external else np.zeros(2)
        tau = np.zeros(self.n_joints)
        for b, body in enumerate(self.bodies):
            acc = np.array([2 * coms[b][0].a[2], 2 * coms[b][1].a[2]])
            tau += dcom[b].T @ (body.mass * (acc - gravity)) + dphi[b] * body.inertia * 2 * angle[b].a[2]
        if external:
            for i, load in enumerate(self.model.loads):
                tau -= dload[i].T @ np.asarray(load.force, dtype=float)
        return tau

    def inverse_dynamics(self, z, zd, zdd):
        """tau (..., J) of z, z', z'' (..., J) (one or a batch of rows)."""
        z, zd, zdd = (np.asarray(v, dtype=float) for v in (z, zd, zdd))
        rows = [self.inverse_dynamics_one(a, b, c) for a, b, c in zip(*(v.reshape(-1, self.n_joints)
                                                                         for v in (z, zd, zdd)))]
        return np.array(rows).reshape(z.shape)

    def mass_matrix(self, z):
        """M(z) (J, J) (or (n, J, J)) from the Jacobians of the angles and centres of mass."""
        z = np.asarray(z, dtype=float)
        out = []
        for row in z.reshape(-1, self.n_joints):
            dphi, dcom, _ = self._jacobians(row)
            out.append(sum(body.mass * dcom[b].T @ dcom[b] + body.inertia * np.outer(dphi[b], dphi[b])
                           for b, body in enumerate(self.bodies)))
        return np.array(out).reshape(z.shape + (self.n_joints,))

    def bias(self, z, zd):
        return self.inverse_dynamics(z, zd, np.zeros_like(np.asarray(zd, dtype=float)))

    def forward_dynamics(self, z, zd, tau):
        """z'' (J,) = M^-1 (tau - h) of one state."""
        jacobians = self._jacobians(z)
        dphi, dcom, _ = jacobians
        M = sum(body.mass * dcom[b].T @ dcom[b] + body.inertia * np.outer(dphi[b], dphi[b])
                for b, body in enumerate(self.bodies))
        h = self.inverse_dynamics_one(z, zd, np.zeros(self.n_joints), jacobians=jacobians)
        return np.linalg.solve(M, np.asarray(tau, dtype=float) - h)
