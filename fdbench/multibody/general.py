"""Eq. 12 for models with free joints and joint paths, by numpy: the engine's mixed coordinates
(``fdbench.multibody.engine``) with two more kinds of joint, assembled and solved densely.

What the two joints add to the engine's formulation:

* A free joint's body has its joint point i among the free points with no constraint to ground;
  its coordinates are the body's angle (minus the offset) and point i's x and y (minus
  ``at_parent``), and the generalised forces of x and y (N) act on point i's coordinates.
* A joint with a path makes the child's point i a free point tied to its parent by two
  constraints, r_i - r_pi - G(theta) e_p = 0 with e_p = r_pj - r_pi (the parent's basic points),
  G = c1 I + c2 R90 and (c1, c2) the parent-frame point at_parent + path(theta) in the parent's
  basic-point frame (``engine._point_map``); on ground, r_i - at_parent - path(theta) = 0. theta =
  phi_child - phi_parent - offset, so these constraints hold the angles too: their Jacobian has
  -G' e_p on the child's angle and +G' e_p on the parent's, and their velocity term is
  -2 G' theta' e_p' - G'' theta'^2 e_p. The joint's torque acts on the angles as a pin's does.

Everything else is the engine's: the distance and angle constraints of every body (the angle's
sin or cos form chosen from the state, SIN_FORM_MIN_COS), the extra points' linear constraints,
the points' mass matrix and Q_ext. Eq. 12, (M + alpha J^T J) q'' = Q - alpha J^T (J' q' + 2 xi
omega Phi' + omega^2 Phi), is solved by a Cholesky factorisation of the whole (points and angles)
leading matrix, which is positive definite for positive masses and inertias (every angle has its
angle constraint). The RK4 driver is the compiled kernel's (``kernels._drive``), step for step:
the same half-step grid, feedback laws, violation check and status codes; it is slower (numpy per
stage: about 0.3 ms for the 10-coordinate gait model) and has no sensitivities or population.
"""

from __future__ import annotations

import math

import numpy as np

from .kernels import CONSTRAINT, NONFINITE, OK, SINGULAR
from .kernels import ALPHA, COMPUTED, FIXED, GAINS, OMEGA2, SWITCH_COS, TWO_XI_OMEGA, VIOLATION


def _perp(v):
    return np.array([-v[1], v[0]])


class DensePenalty:
    """Eq. 12 of ``engine`` (an Engine of a model with free or path joints), by numpy."""

    def __init__(self, engine):
        from .engine import _point_map

        self.engine = engine
        e = engine
        self.n_p, self.n_b, self.n_q = e.n_p, e.n_bodies, e.n_q
        self.alpha, self.txo, self.om2 = e.params[ALPHA], e.params[TWO_XI_OMEGA], e.params[OMEGA2]
        self.switch = e.params[SWITCH_COS]
        self.mass = np.zeros((self.n_q, self.n_q))
        self.mass[:self.n_p, :self.n_p] = e.mass
        self.q_ext = np.concatenate([e.q_ext, np.zeros(self.n_b)])
        self.ends = [(e.pt_index[i], e.pt_index[j], e.pt_fixed[i].copy()) for i, j in e.body_pts]
        self.paths, self.frees = [], []
        for k, joint in enumerate(e.model.joints):
            c, p = e.joint_column[k], e.joint_parent[k]
            if joint.type == "free":
                self.frees.append((c, k, e.pt_index[e.body_pts[k, 0]]))
            if joint.path is not None:
                splines = joint.path.splines()
                at_parent = np.asarray(joint.at_parent, dtype=float)
                if p == FIXED:
                    maps = None
                else:  # (c1, c2) = base + L s: the point map is linear in the path's offset s
                    at_child_p = np.asarray(e.model.joints[p].at_child, dtype=float)
                    u = e._local_end[p] - at_child_p
                    base = np.array(_point_map(at_parent - at_child_p, u))
                    L = np.array([_point_map((1.0, 0.0), u), _point_map((0.0, 1.0), u)]).T  # (c1, c2) per unit s
                    maps = (base, L)
                self.paths.append((k, p, e.pt_index[e.body_pts[k, 0]], at_parent, splines, maps, joint.offset))
        self.n_rows = 2 * self.n_b + len(e.lin_const) + 2 * len(self.paths)

    # ------------------------------------------------------------------ constraints
    def _point(self, q, v, k, fixed=None):
        """Position and velocity (2,) of the point whose coordinates start at k (FIXED: ``fixed``, at rest)."""
        if k == FIXED:
            return fixed, np.zeros(2)
        return q[k:k + 2], v[k:k + 2]

    def _prepare_rows(self):
        """Index arrays of the bodies' rows (built once): their points' coordinates in the state
        extended by the fixed points (at the end), the linear rows as a dense matrix."""
        e, B = self.engine, self.n_b
        fixed = [k for k, (ki, _, _) in enumerate(self.ends) if ki == FIXED]
        self._fixed_at = np.array([self.ends[k][2] for k in fixed]).reshape(-1)  # appended positions
        slot = {k: self.n_q + 2 * n for n, k in enumerate(fixed)}
        self._i = np.array([slot.get(k, ki) for k, (ki, _, _) in enumerate(self.ends)], dtype=np.int64)
        self._j = np.array([kj for _, kj, _ in self.ends], dtype=np.int64)
        self._i_free = np.array([ki != FIXED for ki, _, _ in self.ends])
        self._d, self._beta = e.body_geom[:, 0].copy(), e.body_geom[:, 1].copy()
        self._angles = self.n_p + np.arange(B)
        self._lin = np.zeros((len(e.lin_const), self.n_q))
        for r in range(len(e.lin_const)):
            for index, coef in zip(e.lin_idx[r], e.lin_coef[r]):
                if index != FIXED:
                    self._lin[r, index] += coef

    def constraints(self, q, v):
        """(Phi (m,), J (m, n_q), J' q' (m,)) at q, q': the bodies' distance rows, their angle rows
        (the form in force), the linear rows, then two rows per path."""
        if not hasattr(self, "_i"):
            self._prepare_rows()
        B, n_p = self.n_b, self.n_p
        m = self.n_rows
        Phi, J, Jdv = np.zeros(m), np.zeros((m, self.n_q)), np.zeros(m)
        qx = np.concatenate([q, self._fixed_at])
        vx = np.concatenate([v, np.zeros(len(self._fixed_at))])
        both = np.array([0, 1])
        ci, cj = self._i[:, None] + both, self._j[:, None] + both  # (B, 2) coordinate indices
        e_, ed = qx[cj] - qx[ci], vx[cj] - vx[ci]
        d = self._d
        dist = np.arange(B)
        Phi[dist] = np.sum(e_ * e_, axis=1) - d * d
        J[dist[:, None], cj] = 2 * e_
        free = self._i_free
        J[dist[free][:, None], ci[free]] = -2 * e_[free]
        Jdv[dist] = 2 * np.sum(ed * ed, axis=1)
        psi, w = q[self._angles] + self._beta, v[self._angles]
        s, c = np.sin(psi), np.cos(psi)
        on_y = np.abs(c) >= self.switch  # the sin form
        axis = on_y.astype(np.int64)
        rows = B + dist
        Phi[rows] = np.where(on_y, e_[dist, 1] - d * s, e_[dist, 0] - d * c)
        J[rows, self._j + axis] = 1.0
        J[rows[free], self._i[free] + axis[free]] = -1.0
        J[rows, self._angles] = np.where(on_y, -d * c, d * s)
        Jdv[rows] = np.where(on_y, d * s, d * c) * w * w
        row = 2 * B
        n_lin = len(self._lin)
        if n_lin:
            Phi[row:row + n_lin] = self._lin @ q + self.engine.lin_const
            J[row:row + n_lin] = self._lin
        row += n_lin
        for k, p, ki, at_parent, splines, maps, offset in self.paths:
            theta = q[n_p + k] - (q[n_p + p] if p != FIXED else 0.0) - offset
            rate = v[n_p + k] - (v[n_p + p] if p != FIXED else 0.0)
            (x0, x1, x2), (y0, y1, y2) = (spline.at(theta) for spline in splines)
            s0, s1, s2 = np.array([x0, y0]), np.array([x1, y1]), np.array([x2, y2])
            ri = q[ki:ki + 2]
            rows2 = slice(row, row + 2)
            J[rows2, ki:ki + 2] = np.eye(2)
            if maps is None:  # on ground: r_i - at_parent - s(theta)
                Phi[rows2] = ri - at_parent - s0
                J[rows2, n_p + k] = -s1
                Jdv[rows2] = -s2 * rate * rate
            else:
                base, L = maps
                pi, pj, _ = self.ends[p]
                (rpi, vpi), (rpj, vpj) = self._point(q, v, pi, self.ends[p][2]), self._point(q, v, pj)
                ep, epd = rpj - rpi, vpj - vpi
                c0, c1, c2 = base + L @ s0, L @ s1, L @ s2  # (c1, c2) and its first and second derivatives

                def G(cc, x):
                    return cc[0] * x + cc[1] * _perp(x)

                Phi[rows2] = ri - rpi - G(c0, ep)
                Gm = np.array([[c0[0], -c0[1]], [c0[1], c0[0]]])
                J[rows2, pj:pj + 2] = -Gm
                if pi != FIXED:
                    J[rows2, pi:pi + 2] = -np.eye(2) + Gm
                dtheta = -G(c1, ep)
                J[rows2, n_p + k] = dtheta
                J[rows2, n_p + p] = -dtheta
                Jdv[rows2] = -2 * G(c1, epd) * rate - G(c2, ep) * rate * rate
            row += 2
        return Phi, J, Jdv

    def violation(self, y) -> float:
        """max |Phi_i| (m^2 and m) of the state y."""
        q = y[:self.n_q]
        return float(np.max(np.abs(self.constraints(q, y[self.n_q:])[0]), initial=0.0))

    # ------------------------------------------------------------------ eq. 12
    def derivative(self, y, torque, loads=None):
        """(status, y') of eq. 12 at the state y (n_state,) under the coordinates' generalised forces
        torque (J,) (N m; N for a free joint's x and y) and the engine's external loads (one row of
        ``ExternalLoads.at``: force, point (L, 2), moment (L,); None without them)."""
        n_q, n_p = self.n_q, self.n_p
        q, v = y[:n_q], y[n_q:]
        Phi, J, Jdv = self.constraints(q, v)
        Q = self.q_ext.copy()
        e = self.engine
        for k, parent in enumerate(e.joint_parent):
            tau = torque[e.joint_column[k]]
            Q[n_p + k] += tau
            if parent != FIXED:
                Q[n_p + parent] -= tau
        for c, k, ki in self.frees:
            Q[ki:ki + 2] += torque[c + 1:c + 3]
        if loads is not None:
            from .loads import mixed_forces

            Q += mixed_forces(e, q, *loads)
        A = self.mass + self.alpha * J.T @ J
        rhs = Q - self.alpha * J.T @ (Jdv + self.txo * (J @ v) + self.om2 * Phi)
        if not np.all(np.isfinite(A)):
            return NONFINITE, None
        try:
            factor = np.linalg.cholesky(A)
        except np.linalg.LinAlgError:
            return SINGULAR, None
        acc = np.linalg.solve(factor.T, np.linalg.solve(factor, rhs))
        return OK, np.concatenate([v, acc])


def applied_torque(engine, state, half, tau, ref, refd, refdd, kp, kd, mode, gains, nominal, times):
    """The applied generalised forces (J,) of ``simulate``'s feedback laws at the state (row ``half``
    of the half-step arrays, at times[half] s; ref without the joint offsets)."""
    z, zd = engine.joints_from_state(state)
    if mode == GAINS:
        return tau[half] + gains[half] @ np.concatenate([ref[half] - z, refd[half] - zd])
    if mode == COMPUTED:
        v = refdd[half] + kp * (ref[half] - z) + kd * (refd[half] - zd)
        return (nominal or engine).inverse_dynamics(z, zd, v, times[half]) + tau[half]
    return tau[half] + kp * (ref[half] - z) + kd * (refd[half] - zd)


def rk4(engine, y0, dt, n_steps, tau, ref, refd, refdd, kp, kd, mode, gains, nominal, states, rates, applied, times):
    """The compiled ``kernels.rk4`` for a model with free or path joints or external loads: classical
    RK4 over n_steps steps of dt from y0, the half-step grid at ``times`` (s), filling states, rates
    and applied up to the last step reached. Returns (status, steps_done, max constraint violation)."""
    dense = engine.dense_penalty
    loads = engine.loads.at(times) if engine.loads is not None else None
    limit = engine.params[VIOLATION]
    y = np.array(y0, dtype=float)
    max_viol = dense.violation(y)
    ks = np.empty((4, len(y)))
    code = OK
    for i in range(n_steps + 1):
        j = 2 * i
        for stage in range(4):
            h = 0.0 if stage == 0 else (dt if stage == 3 else 0.5 * dt)
            state = y if stage == 0 else y + h * ks[stage - 1]
            row = j + (stage + 1) // 2
            torque = applied_torque(engine, state, row, tau, ref, refd, refdd, kp, kd, mode, gains, nominal, times)
            code, rate = dense.derivative(state, torque, None if loads is None else [a[row] for a in loads])
            if code == OK:
                ks[stage] = rate
            if stage == 0:
                states[i], applied[i] = y, torque
                rates[i] = rate if code == OK else np.concatenate([y[dense.n_q:], np.full(dense.n_q, np.nan)])
            if code != OK or i == n_steps:
                break
        if code != OK:
            return code, i, max_viol
        if i == n_steps:
            break
        new = y + dt / 6.0 * (ks[0] + 2.0 * ks[1] + 2.0 * ks[2] + ks[3])
        if not np.all(np.isfinite(new)):
            return NONFINITE, i, max_viol
        viol = dense.violation(new)
        if viol > limit:
            return CONSTRAINT, i, max(max_viol, viol)
        max_viol = max(max_viol, viol)
        y = new
    return OK, n_steps, max_viol
