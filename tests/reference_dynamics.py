"""An independent reference for the multibody engine: planar trees of pin joints in MINIMAL
coordinates z (the joint angles), straight from the model description.

Why it is independent of the engine: the engine works in the paper's mixed coordinates (natural
coordinates of two points per body plus the angles, constraints, the penalty formulation of eq. 12).
Here there are no points, constraints or penalties: body frames are placed by rotations along each
body's path from ground, and the dynamics come from two separate constructions,
- the recursive Newton-Euler algorithm (RNEA, Featherstone's, planar: a body's angular velocity is
  the sum of its path's joint rates) for the inverse dynamics tau(z, z', z''), and
- the kinetic energy T = 1/2 z'^T M(z) z' written with each body's Jacobians for the mass matrix,
so the self-checks can test them against each other, and the forward dynamics
z'' = M^{-1} (tau - RNEA(z, z', 0)) integrated by scipy's DOP853 at rtol = atol = 1e-12.

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
    frame; load_force: (L, 2) N, world axes."""

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
                load_force=points([load.force for load in model.loads]))


# ----------------------------------------------------------------------------- kinematics


def _rotate(angle, v):
    """R(angle) v for angles of shape (...) and a body-frame vector v (2,): shape (..., 2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]], axis=-1)


def _perp(v):
    """The vector v (..., 2) turned by +90 degrees: e_z x v."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def _cross(a, b):
    """The z component of a x b for vectors (..., 2)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@dataclass
class Frames:
    """Every body frame's motion, lists indexed by joint: angle (rad), angular velocity (rad/s) and
    acceleration (rad/s^2), each (...); origin, its velocity and acceleration, each (..., 2) m,
    m/s, m/s^2; joint (..., 2): the joint's point (m)."""

    angle: list
    rate: list
    spin: list
    origin: list
    velocity: list
    acceleration: list
    joint: list

    def point(self, k, local):
        """Position, velocity and acceleration (each (..., 2)) of the body point ``local`` (2,)
        (m, body k's frame)."""
        r = _rotate(self.angle[k], local)
        w, dw = self.rate[k][..., None], self.spin[k][..., None]
        return (self.origin[k] + r, self.velocity[k] + w * _perp(r),
                self.acceleration[k] + dw * _perp(r) - w**2 * r)


def frames(t: Tree, z, zd, zdd) -> Frames:
    """The body frames' motion for the joint angles z, rates z' and accelerations z'' (..., J),
    joint by joint from ground (the forward pass of the RNEA)."""
    z, zd, zdd = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (z, zd, zdd)))
    zero, zero2 = np.zeros(z.shape[:-1]), np.zeros(z.shape[:-1] + (2,))
    f = Frames([], [], [], [], [], [], [])
    for k in range(t.n_joints):
        p = t.parent[k]
        if p < 0:
            base = (zero, zero, zero, zero2, zero2, zero2)
        else:
            base = (f.angle[p], f.rate[p], f.spin[p], f.origin[p], f.velocity[p], f.acceleration[p])
        angle, rate, spin = base[0] + z[..., k] + t.offset[k], base[1] + zd[..., k], base[2] + zdd[..., k]
        if p < 0:
            joint, joint_v, joint_a = zero2 + t.at_parent[k], zero2, zero2
        else:
            joint, joint_v, joint_a = f.point(p, t.at_parent[k])
        arm = -_rotate(angle, t.at_child[k])  # from the joint to the child's origin
        f.angle.append(angle)
        f.rate.append(rate)
        f.spin.append(spin)
        f.joint.append(joint)
        f.origin.append(joint + arm)
        f.velocity.append(joint_v + rate[..., None] * _perp(arm))
        f.acceleration.append(joint_a + spin[..., None] * _perp(arm) - rate[..., None] ** 2 * arm)
    return f


# ----------------------------------------------------------------------------- dynamics


def inverse_dynamics(t: Tree, z, zd, zdd, external: bool = True) -> np.ndarray:
    """The joint torques tau (..., J) (N m) of the motion z, z', z'' (..., J) by the planar RNEA:
    the force and moment (about the joint's point) each joint passes to its child, from the leaves
    to ground; tau_k is the moment of joint k. ``external`` False leaves out gravity and loads."""
    f = frames(t, z, zd, zdd)
    J = t.n_joints
    force = [None] * J  # from the parent onto body k, N
    moment = [None] * J  # from the parent onto body k about its joint's point, N m
    for k in range(J):
        com, _, com_a = f.point(k, t.com[k])
        weight = t.mass[k] * t.gravity if external else np.zeros(2)
        inertial = t.mass[k] * com_a - weight  # what the joint and the loads must supply
        force[k] = inertial
        moment[k] = t.inertia[k] * f.spin[k] + _cross(com - f.joint[k], inertial)
    if external:
        for j, at, load in zip(t.load_joint, t.load_at, t.load_force):
            point, _, _ = f.point(j, at)
            force[j] = force[j] - load
            moment[j] = moment[j] - _cross(point - f.joint[j], np.broadcast_to(load, point.shape))
    for k in reversed(range(J)):
        p = t.parent[k]
        if p >= 0:  # the child's joint pushes back on its parent
            force[p] = force[p] + force[k]
            moment[p] = moment[p] + moment[k] + _cross(f.joint[k] - f.joint[p], force[k])
    return np.stack(moment, axis=-1)


def _ancestry(t: Tree) -> np.ndarray:
    """on_path[b, k]: joint k is on the path from ground to body b, shape (J, J) bool."""
    J = t.n_joints
    on_path = np.zeros((J, J), dtype=bool)
    for b in range(J):
        k = b
        while k >= 0:
            on_path[b, k] = True
            k = t.parent[k]
    return on_path


def mass_matrix(t: Tree, z) -> np.ndarray:
    """M(z) (..., J, J) (kg m^2) from the kinetic energy T = 1/2 z'^T M z' =
    sum_b 1/2 (m_b |v_G|^2 + I_b w_b^2), with v_G = sum_k e_z x (G_b - P_k) z'_k and w_b = sum_k z'_k
    over the joints k on body b's path (P_k the joint's point, G_b the body's com)."""
    z = np.asarray(z, dtype=float)
    f = frames(t, z, np.zeros_like(z), np.zeros_like(z))
    on_path = _ancestry(t).astype(float)  # (B, J)
    com = np.stack([f.point(b, t.com[b])[0] for b in range(t.n_joints)], axis=-2)  # (..., B, 2)
    joint = np.stack(f.joint, axis=-2)  # (..., J, 2)
    lever = _perp(com[..., :, None, :] - joint[..., None, :, :]) * on_path[..., None]  # (..., B, J, 2)
    translation = np.einsum("b,...bjx,...bkx->...jk", t.mass, lever, lever)
    rotation = np.einsum("b,bj,bk->jk", t.inertia, on_path, on_path)
    return translation + rotation


def bias(t: Tree, z, zd) -> np.ndarray:
    """h(z, z') (..., J) (N m) of M z'' + h = tau: velocity, gravity and load terms."""
    return inverse_dynamics(t, z, zd, np.zeros_like(np.asarray(zd, dtype=float)))


def forward_dynamics(t: Tree, z, zd, tau) -> np.ndarray:
    """z'' (J,) (rad/s^2) = M^{-1} (tau - h) for one state z, z' (J,) under the torques tau (J,) N m."""
    return np.linalg.solve(mass_matrix(t, z), np.asarray(tau, dtype=float) - bias(t, z, zd))


def kinetic_energy(t: Tree, z, zd) -> np.ndarray:
    """T (...) (joules) from the bodies' com velocities and angular velocities."""
    f = frames(t, z, zd, np.zeros_like(np.asarray(zd, dtype=float)))
    total = 0.0
    for k in range(t.n_joints):
        _, v, _ = f.point(k, t.com[k])
        total = total + 0.5 * t.mass[k] * np.sum(v**2, axis=-1) + 0.5 * t.inertia[k] * f.rate[k] ** 2
    return total


def potential_energy(t: Tree, z) -> np.ndarray:
    """V (...) (joules) of gravity and the constant loads: -sum m g . G - sum F . (load point)."""
    z = np.asarray(z, dtype=float)
    f = frames(t, z, np.zeros_like(z), np.zeros_like(z))
    total = 0.0
    for k in range(t.n_joints):
        total = total - t.mass[k] * f.point(k, t.com[k])[0] @ t.gravity
    for j, at, load in zip(t.load_joint, t.load_at, t.load_force):
        total = total - f.point(j, at)[0] @ load
    return total


# ----------------------------------------------------------------------------- simulation


def simulate(t: Tree, z0, zd0, t_end, torque, t_eval, extra=None):
    """DOP853 (rtol = atol = 1e-12) of the forward dynamics from z0, z'0 (J,) over [0, t_end] s
    under torque(time, z, z') -> tau (J,) N m. Returns (z, z') at t_eval, each (len(t_eval), J).
    ``extra(time, z, z', tau)``, if given, adds quantities to integrate along (returned third)."""
    from scipy.integrate import solve_ivp

    J = t.n_joints
    n_extra = 0 if extra is None else len(extra(0.0, z0, zd0, torque(0.0, z0, zd0)))

    def rhs(time, y):
        z, zd = y[:J], y[J:2 * J]
        tau = torque(time, z, zd)
        parts = [zd, forward_dynamics(t, z, zd, tau)]
        return np.concatenate(parts + ([np.atleast_1d(extra(time, z, zd, tau))] if n_extra else []))

    y0 = np.concatenate([z0, zd0, np.zeros(n_extra)])
    sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", rtol=1e-12, atol=1e-12, t_eval=t_eval)
    assert sol.success, sol.message
    out = sol.y.T
    return (out[:, :J], out[:, J:2 * J]) + ((out[:, 2 * J:],) if n_extra else ())


def simulate_pd(t: Tree, z0, zd0, t_end, feedforward, reference, kp, kd, t_eval):
    """The engine's PD law tau = feedforward(t) + kp (ref - z) + kd (ref' - z') per joint, with
    reference(t) -> (ref, ref') (rad, rad/s) and kp (N m/rad), kd (N m s/rad) of shape (J,),
    integrated as ``simulate``. Returns (z, z') at t_eval."""
    kp, kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)

    def torque(time, z, zd):
        ref, refd = reference(time)
        return feedforward(time) + kp * (ref - z) + kd * (refd - zd)

    return simulate(t, z0, zd0, t_end, torque, t_eval)
