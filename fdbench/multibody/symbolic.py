"""The minimal-coordinate equations of motion of any model description, written once as CasADi
expressions: M(z) z'' + h(z, z') = tau for the coordinates z (rad; m on a translation), J of them.

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
* External loads from data (``loads.ExternalLoads``): their generalised force
  Q = J_o^T F + J_phi^T ((P - o) x F + M) on a body of origin o and angle phi, with the force F,
  point P and free moment M of each load as parameters (in the load's frames, turned into ground's
  symbolically), so that ``actuation`` tau = ID(z, z', z'') - Q(z, p) is the collocation's
  implicit dynamics.
* Forward dynamics z'' = M^-1 (tau - h) by a symbolic L D L^T solve (no explicit inverse; M is
  symmetric positive definite for positive masses and inertias, so no pivoting is needed; CasADi's
  own ``solve`` on SX forms the inverse by minors up to 3 x 3).
* The linearisation of x = [z, z'], x' = [z', z''(z, z', tau)] by the implicit-function theorem on
  the inverse dynamics: ID(z, z', f(z, z', tau)) = tau gives df/d(z, z') = -M^-1 dID/d(z, z') at
  z'' = f, and df/dtau = M^-1; the derivatives of ID by CasADi's ``jacobian`` (exact, and cheaper
  than differentiating through the solve). About a desired motion (the LQR) z'' is the motion's and
  the forward solve is not needed.

The expressions are SX (scalar graphs, fast to evaluate for small J), their common subexpressions
eliminated (``casadi.cse``), and wrapped in CasADi Functions, each built on its first use and then
kept (``functools.lru_cache`` on the frozen ``Model``): a caller pays only for what it needs (the
collocation needs the inverse dynamics alone; the symbolic solve of M behind ``forward`` and the
linearisation costs most for many coordinates). ``MinimalDynamics.build`` builds some ahead of a
timing. Numeric calls take numpy arrays of shape (J,) or (k, J) (one state or k of them, by
``Function.map``) and return numpy arrays of the matching shape. ``casadi`` is imported only when a
function here is called.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np

from .model import GROUND, Model


def _rotate(ca, angle, local):
    """R(angle) local (m) as an SX column (2, 1); local: (2,) numbers or an SX column."""
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(local[0] * c - local[1] * s, local[0] * s + local[1] * c)


def _poses(ca, model: Model, z):
    """Each body's frame angle (rad, SX scalar) and origin (m, SX column (2, 1)) as functions of the
    coordinates z (SX column (J, 1)); body k is the child of joint k."""
    B = len(model.joints)
    body_of = {joint.child: k for k, joint in enumerate(model.joints)}
    angle, origin = [None] * B, [None] * B
    c = 0  # the column of joint k's angle (a free joint's x, y follow it)
    for k, joint in enumerate(model.joints):
        at_parent = ca.DM(list(joint.at_parent))
        if joint.path is not None:  # the child's point on its path in the parent's frame
            from .spline import casadi_value

            at_parent = at_parent + ca.vertcat(*(casadi_value(ca, spline, z[c]) for spline in joint.path.splines()))
        if joint.parent == GROUND:
            angle[k] = z[c] + joint.offset
            at_joint = at_parent
            if joint.type == "free":
                at_joint = at_joint + ca.vertcat(z[c + 1], z[c + 2])
        else:
            p = body_of[joint.parent]
            angle[k] = angle[p] + z[c] + joint.offset
            at_joint = origin[p] + _rotate(ca, angle[p], at_parent)
        origin[k] = at_joint - _rotate(ca, angle[k], joint.at_child)
        c += len(joint.coordinate_names)
    return angle, origin


def _inverse_expression(ca, model: Model, z, zd, zdd):
    """tau (N m; N on a translation), an SX column (J, 1), of the motion z, z', z'' (rad, rad/s,
    rad/s^2; SX columns (J, 1)), the model's own constant loads included."""
    J = model.n_joints
    body_of = {joint.child: k for k, joint in enumerate(model.joints)}
    angle, origin = _poses(ca, model, z)

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
        tau += ca.jacobian(angle[k], z).T * (body.inertia * ca.jtimes(angle[k], z, zdd))  # the angle is linear in z
    for load in model.loads:
        at = point(body_of[load.body], load.at)
        tau -= ca.jacobian(at, z).T @ ca.DM(list(load.force))
    return tau


LOAD_PARAMETERS = 5  # per external load: force x, y (N), point x, y (m), free moment (N m)


def _external_loads_expression(ca, model: Model, loads: tuple, z, p):
    """The generalised forces Q (SX column (J, 1); N m on angles, N on translations) of external
    loads (``loads.ExternalLoad``: the body, the frames of force and point) given, per load, by
    the parameters p[5 l : 5 l + 5] = force (N), point (m), each in the load's frame, and free
    moment (N m): Q = J_o^T F + J_phi^T ((P - o) x F + M) for the body's origin o and angle phi,
    i.e. J_P(z)^T F + J_phi^T M with P the body's material point at P (``loads``' module docstring)."""
    from .loads import GROUND as LOADS_GROUND

    body_of = {joint.child: k for k, joint in enumerate(model.joints)}
    angle, origin = _poses(ca, model, z)
    Q = ca.SX.zeros(model.n_joints, 1)
    for l, load in enumerate(loads):
        force, point, moment = p[5 * l:5 * l + 2], p[5 * l + 2:5 * l + 4], p[5 * l + 4]
        if load.force_frame != LOADS_GROUND:
            force = _rotate(ca, angle[body_of[load.force_frame]], force)
        if load.point_frame != LOADS_GROUND:
            b = body_of[load.point_frame]
            point = origin[b] + _rotate(ca, angle[b], point)
        b = body_of[load.body]
        arm = point - origin[b]
        Q += ca.jacobian(origin[b], z).T @ force
        Q += ca.jacobian(angle[b], z).T * (arm[0] * force[1] - arm[1] * force[0] + moment)
    return Q


def load_parameters(loads, t) -> np.ndarray:
    """The parameters of ``_external_loads_expression`` at times t (s, shape (k,)): shape (k, 5 L),
    per load force x, y (N), point x, y (m) in its frames and free moment (N m), interpolated
    from ``loads`` (``loads.ExternalLoads``); shape (k, 0) when ``loads`` is None."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if loads is None:
        return np.zeros((len(t), 0))
    force, point, moment = loads.at(t)
    return np.concatenate([force, point, moment[..., None]], axis=2).reshape(len(t), -1)


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
def _equations(model: Model):
    """The symbols z, z', z'', tau (SX columns (J, 1)) and the inverse dynamics, M and h as SX
    expressions of them, their common subexpressions eliminated; built once per model."""
    from ..casadi_loader import casadi

    ca = casadi()

    J = model.n_joints
    z, zd, zdd, tau = (ca.SX.sym(name, J) for name in ("z", "zd", "zdd", "tau"))
    inverse = ca.cse(_inverse_expression(ca, model, z, zd, zdd))
    return z, zd, zdd, tau, inverse


@functools.lru_cache(maxsize=64)
def _mass_matrix_and_bias(model: Model):
    """M = d tau / d z'' (exact) and h = tau(z, z', 0), SX expressions of ``_equations``' symbols."""
    from ..casadi_loader import casadi

    ca = casadi()

    z, zd, zdd, _, inverse = _equations(model)
    return ca.cse(ca.jacobian(inverse, zdd)), ca.cse(ca.substitute(inverse, zdd, ca.SX.zeros(model.n_joints)))


def _build_inverse(ca, model):
    z, zd, zdd, _, inverse = _equations(model)
    return ca.Function("inverse", [z, zd, zdd], [inverse])


def _build_mass_matrix(ca, model):
    return ca.Function("mass_matrix", [_equations(model)[0]], [_mass_matrix_and_bias(model)[0]])


def _build_bias(ca, model):
    z, zd, *_ = _equations(model)
    return ca.Function("bias", [z, zd], [_mass_matrix_and_bias(model)[1]])


@functools.lru_cache(maxsize=64)
def _forward_expression(ca, model):
    """z'' = M^-1 (tau - h), an SX expression of ``_equations``' symbols (z, z', tau)."""
    z, zd, zdd, tau, _ = _equations(model)
    M, h = _mass_matrix_and_bias(model)
    return ca.cse(_solve_spd(ca, M, tau - h))


def _build_forward(ca, model):
    z, zd, _, tau, _ = _equations(model)
    return ca.Function("forward", [z, zd, tau], [_forward_expression(ca, model)])


def _build_about_motion(ca, model):
    """(A, B) at (z, z', z'') by the implicit-function theorem (see the module docstring)."""
    J = model.n_joints
    z, zd, zdd, _, inverse = _equations(model)
    M, _ = _mass_matrix_and_bias(model)
    lower = -_solve_spd(ca, M, ca.jacobian(inverse, ca.vertcat(z, zd)))
    A = ca.cse(ca.vertcat(ca.horzcat(ca.SX.zeros(J, J), ca.SX.eye(J)), lower))
    B = ca.cse(ca.vertcat(ca.SX.zeros(J, J), _solve_spd(ca, M, ca.SX.eye(J))))
    return ca.Function("linearisation_about_motion", [z, zd, zdd], [A, B])


def _build_linearisation(ca, model):
    z, zd, _, tau, _ = _equations(model)
    about_motion = _function(model, "linearisation_about_motion")
    return ca.Function("linearisation", [z, zd, tau], list(about_motion(z, zd, _forward_expression(ca, model))))


def _build_riccati_rate(ca, model):
    return _riccati_function(ca, model.n_joints, _function(model, "linearisation_about_motion"))


_BUILDERS = {
    "inverse": _build_inverse, "mass_matrix": _build_mass_matrix, "bias": _build_bias, "forward": _build_forward,
    "linearisation_about_motion": _build_about_motion, "linearisation": _build_linearisation,
    "riccati_rate": _build_riccati_rate,
}


@functools.lru_cache(maxsize=256)
def _function(model: Model, name: str):
    """The model's CasADi Function ``name`` (a key of ``_BUILDERS``), built on first use."""
    from ..casadi_loader import casadi

    ca = casadi()

    return _BUILDERS[name](ca, model)


@functools.lru_cache(maxsize=64)
def _actuation(model: Model, loads: tuple):
    """tau = ID(z, z', z'') - Q(z, p): the generalised forces (N m; N on translations) that move the
    model along z, z', z'' under the external ``loads`` of parameters p (``load_parameters``)."""
    from ..casadi_loader import casadi

    ca = casadi()

    z, zd, zdd, _, inverse = _equations(model)
    p = ca.SX.sym("p", LOAD_PARAMETERS * len(loads))
    if loads:
        inverse = inverse - ca.cse(_external_loads_expression(ca, model, loads, z, p))
    return ca.Function("actuation", [z, zd, zdd, p], [inverse])


class _Functions(Mapping):
    """The model's Functions by name, each built on its first look-up."""

    def __init__(self, model: Model):
        self.model = model

    def __getitem__(self, name: str):
        if name not in _BUILDERS:
            raise KeyError(name)
        return _function(self.model, name)

    def __iter__(self):
        return iter(_BUILDERS)

    def __len__(self) -> int:
        return len(_BUILDERS)


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
    from ..casadi_loader import casadi

    ca = casadi()

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
        self.functions = _Functions(model)

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

    def build(self, *names: str) -> None:
        """Build the Functions ``names`` now (keys of ``functions``), so that later timings exclude it."""
        for name in names:
            self.functions[name]

    def actuation(self, loads: tuple = ()):
        """The CasADi Function (z, z', z'', p) -> tau (columns (J, 1); p (5 L, 1)): the generalised
        forces that move the model along z, z', z'' under the external loads ``loads``
        (``loads.ExternalLoad`` of ``ExternalLoads.loads``) of parameters p (``load_parameters``),
        tau = ID(z, z', z'') - J_P(z)^T F - J_phi(z)^T M, as ``Engine.inverse_dynamics`` with loads."""
        return _actuation(self.model, tuple(loads))

    def _vector(self, value, like):
        """Numeric columns (J, 1) or (k, J, 1) as (J,) or (k, J); symbolic results unchanged."""
        if _is_symbolic([value, like]):
            return value
        return value.reshape(np.shape(like))
