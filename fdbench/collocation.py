"""Direct-collocation tracking of any model (as OpenSim Moco, bioptim and Drake transcribe it), solved by
IPOPT through CasADi, with implicit dynamics: the unknowns are the coordinates z (rad; m on a
translation), their rates z' and accelerations z'' at the transcription's points, and the generalised
forces are their inverse dynamics tau = ID(z, z', z'') - Q_loads(z, t) (``fdbench.multibody.symbolic``,
the limit of the penalty formulation; no symbolic M^-1), as Moco's implicit mode does.

The points are the N + 1 nodes t_k = k h, h = T / N, and for Hermite-Simpson the N interval midpoints
(2N + 1 points, 3J unknowns each). The defect constraints are linear in the unknowns:

- ``trapezoidal``: x_{k+1} - x_k - h/2 (f_k + f_{k+1}) = 0 for x = [z, z'], f = [z', z''];
  the torque is piecewise linear.
- ``hermite-simpson`` in separated form: x_m = (x_k + x_{k+1})/2 + h/8 (f_k - f_{k+1}),
  x_{k+1} - x_k - h/6 (f_k + 4 f_m + f_{k+1}) = 0, and z''_m = (z''_k + z''_{k+1})/2: the
  acceleration is piecewise linear, as Moco interpolates controls at the midpoints. Without that
  last constraint z'' = +A at every node and -A/2 at every midpoint leaves z, z' at all points
  unchanged, and a residual penalty would pay joint torques to zig-zag the base's forces at the
  points; with it, z is a cubic spline through the points (the forearm's replay error: 4e-5 deg
  instead of 1.5e-4). The torque is piecewise quadratic through tau_k, tau_m, tau_{k+1}.

The objective is the scheme's quadrature (Simpson or trapezoid) of sum_j tracking_j (z_j - z_dj)^2
+ effort_j tau_j^2 (``objective_weights``). Every term depends on one point's unknowns only, so the
Hessian of the Lagrangian is block diagonal (3J x 3J per point): one SX Function mapped over the
points of an MX graph. External loads enter symbolically in z, as the engine applies them
(``symbolic.MinimalDynamics.actuation``). The initial state is fixed to the desired motion's at
t = 0, the final state is free, the guess is the desired motion. A motion is anything with
``duration`` (s) and ``motion(t) -> (z, z', z'')``, each of shape t.shape + (J,).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from .casadi_loader import casadi
from .multibody.model_changes import path_pairs
from .multibody.symbolic import MinimalDynamics, load_parameters
from .registry import unknown_name_message


SCHEMES = ("hermite-simpson", "trapezoidal")
DEFAULT_NODES = 100
MIN_NODES, MAX_NODES = 2, 10_000
# The transcription's symbolic equations grow with the model's path pairs (description.path_pairs):
# `fdbench collocate --model` on a chain of forearms took 3.9 s (20 bodies, 210 pairs), 29 s and 1 GB
# (44, 990) and more than 5 min (100, 5050); on a star of 1000 (1000 pairs) 13 s and 1.5 GB.
MAX_PATH_PAIRS = 1000
DEFAULT_REGULARIZATION = 1e-6  # (deg^2) / (N^2 m^2): 1 N m of torque costs as much as 0.001 deg of error
# A floating base's residuals with external loads: 1 N (1 N m) of residual costs as much as 0.03 deg of error.
# On the recorded walk (subject01, its ground reactions, 100 intervals) the residuals' RMS at the nodes fall from
# 21 N and 13 N m (weights 1e-6, the regularization) to 8.6 N and 9.5 N m for 0.04 deg and 0.13 cm of tracking
# error (1e-2: 6.6 N, 5.8 N m for 0.13 deg, 0.37 cm, twice the solve time). Without loads the residuals carry the
# body's weight and get the regularization.
DEFAULT_RESIDUAL_FORCE_WEIGHT = 1e-3  # deg^2 / N^2 on FX and FY
DEFAULT_RESIDUAL_MOMENT_WEIGHT = 1e-3  # deg^2 / (N m)^2 on MZ
DEFAULT_MAX_ITER = 1000
MAX_ITER = 1_000_000  # IPOPT's (and Moco's) iteration limit is a C int; beyond 1e6 --max-time ends a solve first
DEFAULT_MAX_TIME = 60.0  # s of IPOPT CPU time
SOLVED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
IPOPT_HINTS = {
    "Maximum_Iterations_Exceeded": "raise --max-iter",
    "Maximum_CpuTime_Exceeded": "raise --max-time",
    "Maximum_WallTime_Exceeded": "raise --max-time",
    "Infeasible_Problem_Detected": "the defect constraints cannot be met; check the model and motion",
    "Restoration_Failed": "try another --nodes or --scheme",
}
DEG2 = (180.0 / math.pi) ** 2  # deg^2 per rad^2
CM2 = 100.0**2  # cm^2 per m^2


def check_options(nodes: int, scheme: str, regularization: float, max_iter: int = DEFAULT_MAX_ITER,
                  max_time: float = DEFAULT_MAX_TIME, residual_force_weight: float | None = None,
                  residual_moment_weight: float | None = None) -> None:
    """Raise ValueError with a one-line message naming the option for anything out of range (a
    residual weight may be None: its default)."""
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or not MIN_NODES <= nodes <= MAX_NODES:
        raise ValueError(f"--nodes must be an integer in [{MIN_NODES}, {MAX_NODES}], got {nodes}")
    if scheme not in SCHEMES:
        raise ValueError("--scheme: " + unknown_name_message("scheme", scheme, list(SCHEMES)))
    for option, value in (("--regularization", regularization), ("--residual-force-weight", residual_force_weight),
                          ("--residual-moment-weight", residual_moment_weight)):
        if value is None and option != "--regularization":
            continue
        if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
            raise ValueError(f"{option} must be a non-negative finite number, got {value}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or not 1 <= max_iter <= MAX_ITER:
        shown = str(max_iter) if len(str(max_iter)) <= 24 else str(max_iter)[:20] + "..."
        raise ValueError(f"--max-iter must be an integer in [1, {MAX_ITER}], got {shown}")
    if not (isinstance(max_time, (int, float)) and math.isfinite(max_time) and max_time > 0):
        raise ValueError(f"--max-time must be a positive finite number of seconds, got {max_time}")


def check_model(model) -> None:
    """ValueError (one line) for a model (``multibody.model.Model``) whose transcription
    would take minutes to build (``MAX_PATH_PAIRS``)."""
    pairs = path_pairs(model)
    if pairs > MAX_PATH_PAIRS:
        raise ValueError(f"collocate: model {model.name!r} is too large for direct collocation: its equations couple "
                         f"{pairs} (coordinate, body) pairs along its paths, at most {MAX_PATH_PAIRS} (a chain of 44 "
                         "bodies, a star of 1000; a chain of 100 took more than 5 min to build); use control or "
                         "optimize")


@dataclass
class CollocationResult:
    """IPOPT's solution of the transcribed problem. Node arrays have shape (N + 1, J), columns in the
    model's coordinate order (a peer's may have shape (N + 1,) for one joint); ``torque_mid`` has
    shape (N, J) for Hermite-Simpson and is None for the trapezoidal scheme. The torques are the
    inverse dynamics of the states found (external loads included): N m, N on a translation."""

    scheme: str
    t: np.ndarray  # node times, s, shape (N + 1,)
    angles: np.ndarray  # joint angles, rad
    velocities: np.ndarray  # rad/s
    torque: np.ndarray  # N m
    torque_mid: np.ndarray | None  # N m, at the interval midpoints
    objective: float  # deg^2 s (1 cm counting as 1 deg; + the torque and residual terms)
    ipopt_status: str  # IPOPT's return status, e.g. Solve_Succeeded
    iterations: int
    solve_time_s: float  # wall time of IPOPT's solve (the transcription excluded)
    build_time_s: float  # wall time of the transcription
    accelerations: np.ndarray | None = None  # rad/s^2 (m/s^2 on a translation), the nodes' z''
    residual_weights: tuple | None = None  # a floating base's (force deg^2/N^2, moment deg^2/(N m)^2)

    @property
    def success(self) -> bool:
        return self.ipopt_status in SOLVED

    @property
    def message(self) -> str:
        if self.success:
            return f"IPOPT: {self.ipopt_status} in {self.iterations} iterations"
        hint = IPOPT_HINTS.get(self.ipopt_status)
        return f"IPOPT did not solve the problem: {self.ipopt_status} after {self.iterations} iterations" + (
            f" ({hint})" if hint else "")

    def torque_function(self):
        """The torque history t (s), shape (k,) -> N m, shape (k,) (one joint) or (k, J),
        interpolated as the scheme assumes: piecewise linear (trapezoidal) or piecewise quadratic
        (Hermite-Simpson)."""
        t_nodes, u = self.t, self.torque
        h = t_nodes[1] - t_nodes[0]
        n = len(t_nodes) - 1
        if self.torque_mid is None:
            if u.ndim == 1:
                return lambda t: np.interp(t, t_nodes, u)
            return lambda t: np.stack([np.interp(t, t_nodes, u[:, j]) for j in range(u.shape[1])], axis=-1)
        um = self.torque_mid

        def quadratic(t):
            t = np.asarray(t, dtype=float)
            k = np.clip(np.floor((t - t_nodes[0]) / h).astype(int), 0, n - 1)
            s = (t - t_nodes[k]) / h  # in [0, 1] within interval k
            if u.ndim > 1:
                s = s[..., None]
            # Lagrange basis through s = 0, 1/2, 1
            return (2 * (s - 0.5) * (s - 1)) * u[k] + (-4 * s * (s - 1)) * um[k] + (2 * s * (s - 0.5)) * u[k + 1]

        return quadratic

    def torque_samples(self, t: np.ndarray) -> np.ndarray:
        return np.asarray(self.torque_function()(t), dtype=float)


def residual_weights(regularization: float, residual_force_weight: float | None, residual_moment_weight: float | None,
                     loads) -> tuple[float, float]:
    """The weights of a floating base's residual force (deg^2/N^2) and moment (deg^2/(N m)^2): those
    given, else the defaults with external loads and the ``regularization`` without them."""
    force, moment = (DEFAULT_RESIDUAL_FORCE_WEIGHT, DEFAULT_RESIDUAL_MOMENT_WEIGHT) if loads is not None else (
        regularization, regularization)
    return (force if residual_force_weight is None else float(residual_force_weight),
            moment if residual_moment_weight is None else float(residual_moment_weight))


def objective_weights(model, regularization: float, residual_force_weight: float, residual_moment_weight: float):
    """(tracking (J,), effort (J,)): the weights of each coordinate's squared error (deg^2/rad^2, or
    cm^2/m^2 on a translation: 1 cm counts as 1 deg, as eq. 18) and squared generalised force
    (``regularization``; on a floating base's MZ, FX, FY the residual moment and force weights)."""
    kinds = model.coordinate_kinds
    tracking = np.array([CM2 if kind == "translation" else DEG2 for kind in kinds])
    effort = np.full(len(kinds), float(regularization))
    base = model.floating_base
    if base is not None:
        c = model.coordinates.index(base.coordinate_names[0])  # tilt, then x, y
        effort[c], effort[c + 1:c + 3] = residual_moment_weight, residual_force_weight
    return tracking, effort


@dataclass
class Track:
    """What the transcription tracks at its m points in time order: t (s), (m,); the desired z, z',
    z'' (the guess), (m, J) each; the loads' parameters (``symbolic.load_parameters``), (m, P)."""

    t: np.ndarray
    z: np.ndarray
    zd: np.ndarray
    zdd: np.ndarray
    loads: np.ndarray


def point_times(duration: float, nodes: int, scheme: str) -> np.ndarray:
    """The transcription's points (s) over [0, duration]: the N + 1 nodes, with the N interval
    midpoints between them for Hermite-Simpson (2N + 1 points in time order)."""
    return np.linspace(0.0, duration, (2 if scheme == "hermite-simpson" else 1) * int(nodes) + 1)


def quadrature_weights(points: int, h: float, scheme: str) -> np.ndarray:
    """The weights (s) of the scheme's quadrature over its points: Simpson's h/6 (1, 4, 2, 4, ..., 4, 1)
    with the midpoints, the trapezoid's h/2 (1, 2, ..., 2, 1) on the nodes."""
    if scheme == "hermite-simpson":
        weights = np.where(np.arange(points) % 2 == 1, 4.0, 2.0)
        weights[[0, -1]] = 1.0
        return h / 6 * weights
    weights = np.full(points, 2.0)
    weights[[0, -1]] = 1.0
    return h / 2 * weights


def _point_cost(ca, actuation, tracking: np.ndarray, effort: np.ndarray):
    """The objective's integrand at one point, an SX Function (y, p, z_d) -> scalar of the point's
    unknowns y = [z, z', z''] (3J,), its load parameters p and desired z_d (J,):
    sum_j tracking_j (z_j - z_dj)^2 + effort_j tau_j^2, tau = actuation(z, z', z'', p)."""
    J = len(tracking)
    y, p, desired = ca.SX.sym("y", 3 * J), ca.SX.sym("p", actuation.size1_in(3)), ca.SX.sym("z_d", J)
    tau = actuation(y[:J], y[J:2 * J], y[2 * J:], p)
    value = ca.dot(ca.DM(tracking), (y[:J] - desired) ** 2) + ca.dot(ca.DM(effort), tau**2)
    return ca.Function("point_cost", [y, p, desired], [value])


def _defects(ca, z, w, a, h: float, scheme: str):
    """The scheme's defect constraints, linear in the points' z, z', z'' (MX (J, m) each, points in
    time order): Hermite-Simpson in separated form (the midpoint states are unknowns tied to the
    Hermite interpolant of their interval's nodes), or the trapezoid's."""
    m = z.shape[1]
    if scheme == "hermite-simpson":
        k0, mid, k1 = ca.Slice(0, m - 1, 2), ca.Slice(1, m, 2), ca.Slice(2, m, 2)
        return ca.vertcat(ca.vec(z[:, k1] - z[:, k0] - h / 6 * (w[:, k0] + 4 * w[:, mid] + w[:, k1])),
                          ca.vec(w[:, k1] - w[:, k0] - h / 6 * (a[:, k0] + 4 * a[:, mid] + a[:, k1])),
                          ca.vec(z[:, mid] - (z[:, k0] + z[:, k1]) / 2 - h / 8 * (w[:, k0] - w[:, k1])),
                          ca.vec(w[:, mid] - (w[:, k0] + w[:, k1]) / 2 - h / 8 * (a[:, k0] - a[:, k1])),
                          ca.vec(a[:, mid] - (a[:, k0] + a[:, k1]) / 2))
    k0, k1 = ca.Slice(0, m - 1), ca.Slice(1, m)
    return ca.vertcat(ca.vec(z[:, k1] - z[:, k0] - h / 2 * (w[:, k0] + w[:, k1])),
                      ca.vec(w[:, k1] - w[:, k0] - h / 2 * (a[:, k0] + a[:, k1])))


SOLVERS_KEPT = 4  # built transcriptions kept in the process (the gait model's takes minutes to build)
_SOLVERS: dict = {}


def _solver(ca, actuation, m: int, J: int, P: int, h: float, scheme: str, tracking: np.ndarray, effort: np.ndarray,
            max_iter: int, max_time: float):
    """IPOPT's solver of the transcription, built once per structure and kept (``SOLVERS_KEPT``);
    the desired z and load parameters are the NLP's parameters p = [loads, z_d] point by point."""
    key = (id(actuation), m, J, P, h, scheme, tracking.tobytes(), effort.tobytes(), max_iter, max_time)
    found = _SOLVERS.get(key)
    if found is not None and found[0] is actuation:
        return found[1]
    y, p = ca.MX.sym("y", 3 * J, m), ca.MX.sym("p", (P + J) * m)
    given = ca.reshape(p, P + J, m)  # column k: point k's load parameters, then its desired z
    cost = _point_cost(ca, actuation, tracking, effort)
    objective = ca.mtimes(cost.map(m)(y, given[:P, :], given[P:, :]), ca.DM(quadrature_weights(m, h, scheme)))
    defects = _defects(ca, y[:J, :], y[J:2 * J, :], y[2 * J:, :], h, scheme)
    options = {
        "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "verbose": False,
        "ipopt.max_iter": max_iter, "ipopt.max_cpu_time": max_time, "ipopt.tol": 1e-10,
        "error_on_fail": False,
    }
    solver = ca.nlpsol("collocation", "ipopt", {"x": ca.vec(y), "p": p, "f": objective, "g": defects}, options)
    while len(_SOLVERS) >= SOLVERS_KEPT:
        _SOLVERS.pop(next(iter(_SOLVERS)))
    _SOLVERS[key] = (actuation, solver)  # the actuation kept alive, so that its id is not another's
    return solver


def transcribe(actuation, track: Track, tracking: np.ndarray, effort: np.ndarray, scheme: str, max_iter: int,
               max_time: float, began: float | None = None) -> CollocationResult:
    """Transcribe the tracking problem at ``track``'s points and solve it with IPOPT. ``actuation``:
    the CasADi Function (z, z', z'', p) -> tau of one point (``MinimalDynamics.actuation``);
    ``began``: the perf_counter time the transcription began (default now). Never raises on a
    solver failure: IPOPT's status says what happened."""
    ca = casadi()

    began = time.perf_counter() if began is None else began
    t = track.t
    m, J = track.z.shape
    hs = scheme == "hermite-simpson"
    n = (m - 1) // 2 if hs else m - 1
    h = float(t[-1] - t[0]) / n
    solver = _solver(ca, actuation, m, J, track.loads.shape[1], h, scheme, np.asarray(tracking, dtype=float),
                     np.asarray(effort, dtype=float), int(max_iter), float(max_time))
    x0 = np.concatenate([track.z, track.zd, track.zdd], axis=1).ravel()  # point by point
    lbx, ubx = np.full(x0.size, -np.inf), np.full(x0.size, np.inf)
    lbx[:2 * J] = ubx[:2 * J] = x0[:2 * J]  # the initial state is the desired motion's
    parameters = np.concatenate([track.loads, track.z], axis=1).ravel()  # point by point: [loads, z_d]
    built = time.perf_counter()
    try:
        solution = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0, p=parameters)
        stats = solver.stats()
        values, f = np.asarray(solution["x"], dtype=float).ravel(), float(solution["f"])
        status, iterations = str(stats.get("return_status", "unknown")), int(stats.get("iter_count", 0))
    except RuntimeError as exc:  # CasADi reports an error in a callback or in IPOPT itself
        values, f = np.full(x0.size, np.nan), math.nan
        status, iterations = "CasADi error: " + " ".join(str(exc).split())[:200], 0
    solved = time.perf_counter()

    points = values.reshape(m, 3 * J)
    z, w, a = points[:, :J], points[:, J:2 * J], points[:, 2 * J:]
    torque = np.array(actuation.map(m)(z.T, w.T, a.T, track.loads.T)).T
    nodes = slice(0, m, 2 if hs else 1)
    return CollocationResult(
        scheme=scheme, t=t[nodes], angles=z[nodes], velocities=w[nodes], torque=torque[nodes],
        torque_mid=torque[1::2] if hs else None, objective=f, ipopt_status=status, iterations=iterations,
        solve_time_s=solved - built, build_time_s=built - began, accelerations=a[nodes],
    )


def desired_samples(model, motion, t: np.ndarray):
    """The motion's (z, z', z'') at times t (s), each (len(t), J); ValueError (one line) when the
    motion does not give one column per joint of the model."""
    values = tuple(np.asarray(v, dtype=float) for v in motion(t))
    shape = (len(t), model.n_joints)
    if any(v.shape != shape for v in values):
        raise ValueError(f"the motion gives joint values of shape {values[0].shape}; model {model.name!r} needs "
                         f"{shape} (one column per joint: {', '.join(model.coordinates)})")
    return values


def collocate(model, motion, nodes: int = DEFAULT_NODES, scheme: str = "hermite-simpson",
              regularization: float = DEFAULT_REGULARIZATION, max_iter: int = DEFAULT_MAX_ITER,
              max_time: float = DEFAULT_MAX_TIME, residual_force_weight: float | None = None,
              residual_moment_weight: float | None = None, loads=None) -> CollocationResult:
    """Transcribe and solve the tracking of ``motion`` by ``model`` on ``nodes`` intervals (``loads``:
    ``ExternalLoads`` or None). ValueError (one line) for bad options or a motion of other joints."""
    check_options(nodes, scheme, regularization, max_iter, max_time, residual_force_weight, residual_moment_weight)
    began = time.perf_counter()
    t = point_times(motion.duration, nodes, scheme)
    track = Track(t, *desired_samples(model, motion, t), loads=load_parameters(loads, t))
    actuation = MinimalDynamics(model).actuation(() if loads is None else loads.loads)
    weights = residual_weights(regularization, residual_force_weight, residual_moment_weight, loads)
    tracking, effort = objective_weights(model, regularization, *weights)
    solution = transcribe(actuation, track, tracking, effort, scheme, max_iter, max_time, began)
    solution.residual_weights = weights if model.floating_base is not None else None
    return solution


def own_fields(model, solution: CollocationResult, truth) -> dict:
    """The collocation's own indicators at its nodes against ``truth`` (``truth(t)`` -> (z, ...)): RMS
    error of angles (deg) and translations (cm), a floating base's residual force (N) and moment (N m)."""
    error = solution.angles - np.asarray(truth(solution.t)[0], dtype=float).reshape(solution.angles.shape)
    translation = np.array([kind == "translation" for kind in model.coordinate_kinds])
    fields = {"collocation_rmse_rot_deg": float(np.degrees(np.sqrt(np.mean(error[:, ~translation] ** 2))))
              if (~translation).any() else math.nan}
    if translation.any():
        fields["collocation_rmse_trans_cm"] = float(100 * np.sqrt(np.mean(error[:, translation] ** 2)))
    base = model.floating_base
    if base is not None:
        c = model.coordinates.index(base.coordinate_names[0])
        moment, fx, fy = solution.torque[:, c:c + 3].T
        fields.update(collocation_residual_force_rms_n=float(np.sqrt(np.mean(fx**2 + fy**2))),
                      collocation_residual_moment_rms_nm=float(np.sqrt(np.mean(moment**2))))
    return fields


def record_fields(solution: CollocationResult, options: dict, own: dict, replay_message: str) -> dict:
    """The fields a collocate run adds to its replay's record: options, ``own`` indicators, IPOPT's
    status and iterations, build and solve times (s); status 'collocation_failed' if unsolved."""
    fields = dict(torque="collocation", evaluations=1, nodes=options["nodes"], scheme=options["scheme"],
                  regularization=options["regularization"], **own, ipopt_status=solution.ipopt_status,
                  ipopt_iterations=solution.iterations, build_time_s=solution.build_time_s,
                  solve_time_s=solution.solve_time_s)
    if solution.residual_weights is not None:
        fields.update(residual_force_weight=solution.residual_weights[0],
                      residual_moment_weight=solution.residual_weights[1])
    if not solution.success:
        fields.update(status="collocation_failed",
                      message=f"{solution.message}; the replay of its last iterate: {replay_message}")
    return fields
