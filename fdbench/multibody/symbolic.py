"""The minimal-coordinate equations of motion of any model description, written once as CasADi
expressions: M(z) z'' + h(z, z') = tau for the joint angles z (rad), J of them.

How they are built (one definition, from the description only):

* Kinematics by the tree's recursion, as symbolic functions of z: a body's frame angle is its
  parent's plus (coordinate + offset); its joint point is its parent's origin plus the parent's
  rotation of ``at_parent`` (ground: ``at_parent`` itself), plus the joint's path at its angle
  (OpenSim's spline, piecewise by ``if_else``) for a joint with a path, plus (x, y) for a free
  joint's translations; its origin is the joint point minus its own rotation of ``at_child``; the
  centres of mass and the loads' points follow from the origin.
* Velocities and accelerations by CasADi's forward derivatives (``jtimes``): v = (dr/dz) z',
  a = (dv/dz) z' + (dv/dz') z''; a body's angular velocity and acceleration are sums over its path.
* Inverse dynamics by the principle of virtual work (Kane's equations): tau = sum_b J_b^T m_b (a_b - g)
  + I_b alpha_b (over the joints on b's path) - sum_loads J_L^T F_L, J = dr/dz by CasADi's
  ``jacobian``. Then M = d tau / d z'' (exact) and h = tau(z, z', 0).
* Forward dynamics z'' = M^-1 (tau - h) by a symbolic L D L^T solve (no explicit inverse; M is
  symmetric positive definite for positive masses and inertias, so no pivoting is needed; CasADi's
  own ``solve`` on SX forms the inverse by minors up to 3 x 3).
* The linearisation of x = [z, z'], x' = [z', z''(z, z', tau)] by the implicit-function theorem on
  the inverse dynamics: ID(z, z', f(z, z', tau)) = tau gives df/d(z, z') = -M^-1 dID/d(z, z') at
  z'' = f, and df/dtau = M^-1; the derivatives of ID by CasADi's ``jacobian`` (exact, and cheaper
  than differentiating through the solve). About a desired motion (the LQR) z'' is the motion's and
  the forward solve is not needed.

The expressions are SX (scalar graphs, fast to evaluate for small J), their common subexpressions
eliminated (``casadi.cse``), and wrapped in CasADi Functions built once per model
(``functools.lru_cache`` on the frozen ``Model``). Numeric calls
take numpy arrays of shape (J,) or (k, J) (one state or k of them, by ``Function.map``) and return
numpy arrays of the matching shape. The collocation's transcription works on SX matrices of shape
(k, J), one node per row: ``forward_rows`` maps the forward Function over the rows (the map of an
SX Function called on SX arguments is expanded into the transcription's graph, as hand-written
expressions would be). ``casadi`` is imported only when a function here is called.
"""

from __future__ import annotations

import functools

import numpy as np

from .description import GROUND, Model


def _rotate(ca, angle, local):
    """R(angle) local (m) as an SX column (2, 1); local: (2,) numbers or an SX column."""
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(local[0] * c - local[1] * s, local[0] * s + local[1] * c)


def _inverse_expression(ca, model: Model, z, zd, zdd):
    """tau (N m), an SX column (J, 1), of the motion z, z', z'' (rad, rad/s, rad/s^2; SX columns (J, 1))."""
    J, B = model.n_joints, len(model.joints)
    body_of = {joint.child: k for k, joint in enumerate(model.joints)}  # body k is the child of joint k
    angle, rate, spin, origin = [None] * B, [None] * B, [None] * B, [None] * B
    c = 0  # the column of joint k's angle (a free joint's x, y follow it)
    for k, joint in enumerate(model.joints):
        at_parent = ca.DM(list(joint.at_parent))
        if joint.path is not None:  # the child's point on its path in the parent's frame
            from .spline import casadi_value

            at_parent = at_parent + ca.vertcat(*(casadi_value(ca, spline, z[c]) for spline in joint.path.splines()))
        if joint.parent == GROUND:
            angle[k], rate[k], spin[k] = z[c] + joint.offset, zd[c], zdd[c]
            at_joint = at_parent
            if joint.type == "free":
                at_joint = at_joint + ca.vertcat(z[c + 1], z[c + 2])
        else:
            p = body_of[joint.parent]
            angle[k], rate[k], spin[k] = angle[p] + z[c] + joint.offset, rate[p] + zd[c], spin[p] + zdd[c]
            at_joint = origin[p] + _rotate(ca, angle[p], at_parent)
        origin[k] = at_joint - _rotate(ca, angle[k], joint.at_child)
        c += len(joint.coordinate_names)

    def point(k, local):
        return origin[k] + _rotate(ca, angle[k], local)

    def acceleration(r):
        v = ca.jtimes(r, z, zd)
        return ca.jtimes(v, z, zd) + ca.jtimes(v, zd, zdd)

    gravity = ca.DM(list(model.gravity))
    tau = ca.SX.zeros(J, 1)
    for k, joint in enumerate(model.joints):
        body = model.body(joint.child)
        com = point(k, body.com)
        tau += ca.jacobian(com, z).T @ (body.mass * (acceleration(com) - gravity))
        tau += ca.jacobian(angle[k], z).T * (body.inertia * spin[k])
    for load in model.loads:
        at = point(body_of[load.body], load.at)
        tau -= ca.jacobian(at, z).T @ ca.DM(list(load.force))
    return tau


def _solve_spd(ca, M, b):
    """M^-1 b for a symmetric positive definite SX matrix M (J, J) and b (J, c), by L D L^T without
    pivoting (M's pivots are positive) and forward and back substitution, written out symbolically."""
    n = M.shape[0]
    L, D = [[None] * n for _ in range(n)], [None] * n
    for j in range(n):
        D[j] = M[j, j] - sum((L[j][k] ** 2 * D[k] for k in range(j)), 0)
        for i in range(j + 1, n):
            L[i][j] = (M[i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)), 0)) / D[j]
    y = [None] * n
    for i in range(n):
        y[i] = b[i, :] - sum((L[i][k] * y[k] for k in range(i)), 0)
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = y[i] / D[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), 0)
    return ca.vertcat(*x)


@functools.lru_cache(maxsize=64)
def _functions(model: Model) -> dict:
    """The model's CasADi Functions (see the module docstring), built once per model."""
    import casadi as ca

    J = model.n_joints
    z, zd, zdd, tau = (ca.SX.sym(name, J) for name in ("z", "zd", "zdd", "tau"))
    inverse = ca.cse(_inverse_expression(ca, model, z, zd, zdd))
    M = ca.cse(ca.jacobian(inverse, zdd))
    h = ca.cse(ca.substitute(inverse, zdd, ca.SX.zeros(J)))
    forward = ca.cse(_solve_spd(ca, M, tau - h))
    # the implicit-function linearisation at (z, z', z'') (see the module docstring)
    lower = -_solve_spd(ca, M, ca.jacobian(inverse, ca.vertcat(z, zd)))
    A = ca.cse(ca.vertcat(ca.horzcat(ca.SX.zeros(J, J), ca.SX.eye(J)), lower))
    B = ca.cse(ca.vertcat(ca.SX.zeros(J, J), _solve_spd(ca, M, ca.SX.eye(J))))
    about_motion = ca.Function("linearisation_about_motion", [z, zd, zdd], [A, B])
    functions = {
        "mass_matrix": ca.Function("mass_matrix", [z], [M]),
        "bias": ca.Function("bias", [z, zd], [h]),
        "inverse": ca.Function("inverse", [z, zd, zdd], [inverse]),
        "forward": ca.Function("forward", [z, zd, tau], [forward]),
        "linearisation": ca.Function("linearisation", [z, zd, tau], list(about_motion(z, zd, forward))),
    }
    functions["riccati_rate"] = _riccati_function(ca, J, about_motion)
    return functions


def _riccati_function(ca, J: int, about_motion):
    """P' = -(A^T P + P A - P B R^-1 B^T P + Q) (symmetrised) about the desired z, z', z''
    (rad, rad/s, rad/s^2; A, B at the inverse dynamics' torques) for P (2J x 2J) flattened row-wise,
    Q = diag(q), q (2J,), and R^-1 = diag(r_inv), r_inv (J,) (N m)^2, all in ONE input vector
    [z, z', z'', P, q, r_inv] (a Function's call from Python costs about 10 us per argument): a
    Riccati evaluation is one call."""
    x = ca.SX.sym("x", riccati_input_size(J))
    z, zd, zdd, p, q, r_inv = ca.vertsplit(x, list(np.cumsum([0, J, J, J, 4 * J * J, 2 * J, J])))
    A, B = about_motion(z, zd, zdd)
    P = ca.reshape(p, 2 * J, 2 * J).T  # row-wise
    PB = P @ B
    dP = A.T @ P + P @ A - PB @ ca.diag(r_inv) @ PB.T + ca.diag(q)
    rate = -0.5 * (dP + dP.T)
    return ca.Function("riccati_rate", [x], [ca.cse(ca.reshape(rate.T, 4 * J * J, 1))])


def riccati_input_size(J: int) -> int:
    """The length of the Riccati Function's input [z, z', z'', P, q, r_inv] for J joints."""
    return 3 * J + 4 * J * J + 2 * J + J


def _is_symbolic(values) -> bool:
    import casadi as ca

    return any(isinstance(v, (ca.SX, ca.MX)) for v in values)


def _unstack(side_by_side: np.ndarray, k: int) -> np.ndarray:
    """k matrices (r, c) placed side by side, shape (r, k c), as (k, r, c)."""
    return side_by_side.reshape(side_by_side.shape[0], k, -1).transpose(1, 0, 2)


class MinimalDynamics:
    """M(z), h(z, z'), the inverse and forward dynamics and the linearisation of ``model`` in its
    joint angles z (rad), from CasADi Functions built once per model.

    Numeric arguments: numpy arrays of shape (J,) (one state) or (k, J) (k states); the results
    have the matching leading shape. CasADi SX/MX arguments (columns (J, 1)): the Functions'
    symbolic results."""

    def __init__(self, model: Model):
        self.model = model
        self.n_joints = model.n_joints
        self.functions = _functions(model)

    def _call(self, name: str, *args):
        """The Function ``name`` on one state (J,) or on k states (k, J) (by ``map``)."""
        function = self.functions[name]
        if _is_symbolic(args):
            return function(*args)
        arrays = [np.asarray(a, dtype=float) for a in args]
        J = self.n_joints
        shape = arrays[0].shape
        if not (shape[-1:] == (J,) and len(shape) <= 2) or any(a.shape != shape for a in arrays):
            raise ValueError(f"joint values must have shape ({J},) or (k, {J}), got "
                             f"{', '.join(str(a.shape) for a in arrays)}")
        if len(shape) == 1:
            out = function(*arrays)
            return tuple(np.array(o) for o in out) if isinstance(out, tuple) else np.array(out)
        k = shape[0]
        out = function.map(k)(*(a.T for a in arrays))  # the k results side by side
        stacked = tuple(_unstack(np.array(o), k) for o in (out if isinstance(out, tuple) else (out,)))
        return stacked if isinstance(out, tuple) else stacked[0]

    def mass_matrix(self, z):
        """M(z) (kg m^2): (J, J), or (k, J, J) for z of shape (k, J)."""
        return self._call("mass_matrix", z)

    def bias(self, z, zd):
        """h(z, z') (N m): Coriolis, centrifugal, gravity and load terms, shape (J,) or (k, J)."""
        return self._vector(self._call("bias", z, zd), z)

    def inverse(self, z, zd, zdd):
        """tau = M(z) z'' + h(z, z') (N m), shape (J,) or (k, J)."""
        return self._vector(self._call("inverse", z, zd, zdd), z)

    def forward(self, z, zd, tau):
        """z'' = M(z)^-1 (tau - h(z, z')) (rad/s^2), shape (J,) or (k, J)."""
        return self._vector(self._call("forward", z, zd, tau), z)

    def linearisation(self, z, zd, tau):
        """(A, B) of x = [z, z'], x' = [z', z''(z, z', tau)]: A (2J, 2J) (1/s^2 and 1/s entries),
        B (2J, J) (1/(kg m^2)); with a leading axis k for inputs of shape (k, J)."""
        return self._call("linearisation", z, zd, tau)

    def forward_rows(self, z, zd, tau):
        """z'' as CasADi SX of shape (k, J) from SX z, z', tau of shape (k, J), one state per row
        (the form ``fdbench.collocation.transcribe`` takes)."""
        k = z.shape[0]
        return self.functions["forward"].map(k)(z.T, zd.T, tau.T).T

    def riccati_rate(self, z, zd, zdd, p, q, r_inv) -> np.ndarray:
        """The Riccati right-hand side P' flattened row-wise (4 J^2,) about the desired z, z', z''
        (J,) each, for P flattened row-wise p (4 J^2,), q (2J,) the diagonal of Q and r_inv (J,)
        that of R^-1 ((N m)^2)."""
        packed = np.concatenate([z, zd, zdd, p, q, r_inv])
        return np.asarray(self.functions["riccati_rate"](packed), dtype=float).ravel()

    def _vector(self, value, like):
        """Numeric columns (J, 1) or (k, J, 1) as (J,) or (k, J); symbolic results unchanged."""
        if _is_symbolic([value, like]):
            return value
        return value.reshape(np.shape(like))
