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

Muscle-driven (``collocate_muscles``, as Moco's MocoTrack with De Groote muscles): per point also the
activations a and excitations e (M each, bounds [0, 1]) and a reserve torque r_j per coordinate (static
optimisation's reserves: the model's actuators with their optimal forces, 0 (none) on a coordinate without
one, one of 1 N m per coordinate on a model without actuators). The states are [z, z', a] with rates
[z', z'', a'(e, a)] (De Groote's activation dynamics) in the same defects, e linear over an interval
with Hermite-Simpson as z''; at every point ID - Q_loads = sum_m arm_m F_m(a_m, l_m, v_m) + r, each muscle's
force along its path with a rigid tendon (a compliant tendon is taken as rigid, as Moco's
ModOpIgnoreTendonCompliance; ``MuscleCollocationResult.rigid_tendons`` names them); a(0) = e(0) (free
otherwise), as the forward simulation starts a muscle. The objective adds ``effort_weight`` times the
quadrature of sum e^2 + sum (r / F_opt)^2 (MocoControlGoal's controls). The muscles' equations are
``fdbench.multibody.symbolic_muscles``; the guess is static optimisation's activations and reserves.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from .casadi_loader import casadi
from .multibody.actuators import optimal_forces
from .multibody.model_changes import path_pairs, rigid_tendons
from .multibody.static_optimization import static_optimization
from .multibody.symbolic import MinimalDynamics, load_parameters
from .multibody.symbolic_muscles import muscle_functions
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
# The muscle-driven transcription's weight on the controls' squares (sum e^2 + sum (r / F_opt)^2, as Moco's
# MocoControlGoal): deg^2 per excitation^2, the tracking term's deg^2 (excitation_problem's DEFAULT_EFFORT_WEIGHT
# weighs an RMSE in deg, not deg^2). Small, because the motion's torque must be made whatever the weight: the
# term only keeps the muscles from co-contracting. On arm26's mid_range, 0.01 tracks within 0.05 deg at the
# nodes with an effort (mean sum a^2) of 1.05; 0.1 gives up 0.17 deg of tracking for an effort of 1.04.
DEFAULT_EXCITATION_WEIGHT = 0.01
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


def check_options(nodes: int, scheme: str, regularization: float = 0.0, max_iter: int = DEFAULT_MAX_ITER,
                  max_time: float = DEFAULT_MAX_TIME, residual_force_weight: float | None = None,
                  residual_moment_weight: float | None = None, effort_weight: float | None = None) -> None:
    """Raise ValueError with a one-line message naming the option for anything out of range (a
    residual or effort weight may be None: its default)."""
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or not MIN_NODES <= nodes <= MAX_NODES:
        raise ValueError(f"--nodes must be an integer in [{MIN_NODES}, {MAX_NODES}], got {nodes}")
    if scheme not in SCHEMES:
        raise ValueError("--scheme: " + unknown_name_message("scheme", scheme, list(SCHEMES)))
    for option, value in (("--regularization", regularization), ("--residual-force-weight", residual_force_weight),
                          ("--residual-moment-weight", residual_moment_weight), ("--effort-weight", effort_weight)):
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


def _defects(ca, x, f, linear, h: float, scheme: str):
    """The scheme's defect constraints of the states x with rates f (MX (n, m) each, points in time
    order; the torque-driven transcription's x = [z, z'], f = [z', z'']): Hermite-Simpson in
    separated form (the midpoint states are unknowns tied to the Hermite interpolant of their
    interval's nodes, and ``linear`` (MX (k, m): z'', the excitations) is linear over each interval),
    or the trapezoid's (``linear`` unused)."""
    m = x.shape[1]
    if scheme == "hermite-simpson":
        k0, mid, k1 = ca.Slice(0, m - 1, 2), ca.Slice(1, m, 2), ca.Slice(2, m, 2)
        return ca.vertcat(ca.vec(x[:, k1] - x[:, k0] - h / 6 * (f[:, k0] + 4 * f[:, mid] + f[:, k1])),
                          ca.vec(x[:, mid] - (x[:, k0] + x[:, k1]) / 2 - h / 8 * (f[:, k0] - f[:, k1])),
                          ca.vec(linear[:, mid] - (linear[:, k0] + linear[:, k1]) / 2))
    k0, k1 = ca.Slice(0, m - 1), ca.Slice(1, m)
    return ca.vec(x[:, k1] - x[:, k0] - h / 2 * (f[:, k0] + f[:, k1]))


SOLVERS_KEPT = 4  # built transcriptions kept in the process (the gait model's takes minutes to build)
_SOLVERS: dict = {}


def _kept(key: tuple, owners: tuple, build):
    """The solver kept under ``key`` for ``owners`` (the Functions it was built of, their ids in the
    key), else ``build()``'s, kept (``SOLVERS_KEPT``) with its owners alive, so that their ids are
    not others'."""
    found = _SOLVERS.get(key)
    if found is not None and all(a is b for a, b in zip(found[0], owners)):
        return found[1]
    solver = build()
    while len(_SOLVERS) >= SOLVERS_KEPT:
        _SOLVERS.pop(next(iter(_SOLVERS)))
    _SOLVERS[key] = (owners, solver)
    return solver


def _ipopt(ca, y, p, objective, constraints, max_iter: int, max_time: float):
    """IPOPT through CasADi on the unknowns y (MX, flattened point by point) with parameters p."""
    options = {
        "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "verbose": False,
        "ipopt.max_iter": max_iter, "ipopt.max_cpu_time": max_time, "ipopt.tol": 1e-10,
        "error_on_fail": False,
        "show_eval_warnings": False,  # a NaN or Inf met on the way is IPOPT's status in the record, not stderr noise
    }
    return ca.nlpsol("collocation", "ipopt", {"x": ca.vec(y), "p": p, "f": objective, "g": constraints}, options)


def _solver(ca, actuation, m: int, J: int, P: int, h: float, scheme: str, tracking: np.ndarray, effort: np.ndarray,
            max_iter: int, max_time: float):
    """IPOPT's solver of the transcription, built once per structure and kept (``SOLVERS_KEPT``);
    the desired z and load parameters are the NLP's parameters p = [loads, z_d] point by point."""
    def build():
        y, p = ca.MX.sym("y", 3 * J, m), ca.MX.sym("p", (P + J) * m)
        given = ca.reshape(p, P + J, m)  # column k: point k's load parameters, then its desired z
        cost = _point_cost(ca, actuation, tracking, effort)
        objective = ca.mtimes(cost.map(m)(y, given[:P, :], given[P:, :]), ca.DM(quadrature_weights(m, h, scheme)))
        defects = _defects(ca, y[:2 * J, :], y[J:, :], y[2 * J:, :], h, scheme)
        return _ipopt(ca, y, p, objective, defects, max_iter, max_time)

    key = (id(actuation), m, J, P, h, scheme, tracking.tobytes(), effort.tobytes(), max_iter, max_time)
    return _kept(key, (actuation,), build)


def _run(solver, x0: np.ndarray, lbx: np.ndarray, ubx: np.ndarray, parameters: np.ndarray):
    """(unknowns found, objective, IPOPT's status, iterations) of a solve with every constraint an
    equality; never raises: a CasADi error is a status, its unknowns NaN."""
    try:
        solution = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0, p=parameters)
        stats = solver.stats()
        return (np.asarray(solution["x"], dtype=float).ravel(), float(solution["f"]),
                str(stats.get("return_status", "unknown")), int(stats.get("iter_count", 0)))
    except RuntimeError as exc:  # CasADi reports an error in a callback or in IPOPT itself
        return np.full(x0.size, np.nan), math.nan, "CasADi error: " + " ".join(str(exc).split())[:200], 0


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
    values, f, status, iterations = _run(solver, x0, lbx, ubx, parameters)
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


# ---------------------------------------------------------------------- muscle-driven
@dataclass
class MuscleCollocationResult(CollocationResult):
    """The muscle-driven transcription's solution (``collocate_muscles``): ``torque`` and
    ``torque_mid`` are the reserve torques (N m; N on a translation; 0 on a coordinate without a
    reserve), which the replay applies beside the muscles. Node arrays: activations and excitations
    (N + 1, M) in [0, 1], the muscles' forces along their paths (N), their generalised forces
    arms^T F (N + 1, J) (N m) and the inverse dynamics ID - Q_loads (N + 1, J) (N m)."""

    muscles: tuple = ()
    activation: np.ndarray | None = None
    excitation: np.ndarray | None = None
    muscle_force: np.ndarray | None = None
    muscle_torque: np.ndarray | None = None
    inverse: np.ndarray | None = None
    reserve_forces: np.ndarray | None = None  # (J,) each reserve's optimal force (N m per unit control), 0: none
    effort_weight: float = math.nan  # deg^2 per excitation^2
    rigid_tendons: tuple = ()  # the muscles whose compliant tendon the transcription took as rigid

    def excitation_function(self):
        """The excitations t (s), (k,) -> (k, M): linear between the nodes (as the scheme has them),
        clipped into [0, 1] (IPOPT may leave a bound by its tolerance)."""
        t_nodes, e = self.t, np.clip(self.excitation, 0.0, 1.0)
        return lambda t: np.stack([np.interp(t, t_nodes, e[:, m]) for m in range(e.shape[1])], axis=-1)


def _muscle_solver(ca, actuation, functions, m: int, J: int, M: int, P: int, h: float, scheme: str,
                   tracking: np.ndarray, controls: np.ndarray, max_iter: int, max_time: float):
    """IPOPT's solver of the muscle-driven transcription (kept as ``_solver``'s): per point the
    unknowns y = [z, z', z'', a, e, r] (4J + 2M), the parameters [loads, z_d]; constraints: the
    defects of x = [z, z', a] with rates [z', z'', a'(e, a)] (z'' and e linear over an interval with
    Hermite-Simpson), ID - Q_loads - arms^T F(a, l, v) - r = 0 at every point, a = e at t = 0."""
    _, forces, rate = functions
    n = 4 * J + 2 * M
    cuts = [0, J, 2 * J, 3 * J, 3 * J + M, 3 * J + 2 * M, n]

    def build():
        y, p = ca.MX.sym("y", n, m), ca.MX.sym("p", (P + J) * m)
        given = ca.reshape(p, P + J, m)
        one, loads, desired = ca.SX.sym("y", n), ca.SX.sym("p", P), ca.SX.sym("z_d", J)
        z, w, acc, a, e, r = ca.vertsplit(one, cuts)
        cost = ca.Function("point_cost", [one, desired], [ca.dot(ca.DM(tracking), (z - desired) ** 2)
                                                          + ca.dot(ca.DM(controls), ca.vertcat(e, r) ** 2)])
        residual = actuation(z, w, acc, loads) - forces(z, w, a)[1] - r
        point = ca.Function("point", [one, loads], [ca.vertcat(residual, rate(e, a))])
        objective = ca.mtimes(cost.map(m)(y, given[P:, :]), ca.DM(quadrature_weights(m, h, scheme)))
        out = point.map(m)(y, given[:P, :])
        rows = [y[cuts[i]:cuts[i + 1], :] for i in range(6)]  # z, z', z'', a, e, r
        defects = _defects(ca, ca.vertcat(rows[0], rows[1], rows[3]), ca.vertcat(rows[1], rows[2], out[J:, :]),
                           ca.vertcat(rows[2], rows[4]), h, scheme)
        start = rows[3][:, 0] - rows[4][:, 0]
        return _ipopt(ca, y, p, objective, ca.vertcat(defects, ca.vec(out[:J, :]), start), max_iter, max_time)

    key = ("muscles", id(actuation), id(forces), m, J, M, P, h, scheme, tracking.tobytes(), controls.tobytes(),
           max_iter, max_time)
    return _kept(key, (actuation, forces, rate), build)


def collocate_muscles(model, motion, params: np.ndarray, nodes: int = DEFAULT_NODES, scheme: str = "hermite-simpson",
                      effort_weight: float = DEFAULT_EXCITATION_WEIGHT, max_iter: int = DEFAULT_MAX_ITER,
                      max_time: float = DEFAULT_MAX_TIME, loads=None) -> MuscleCollocationResult:
    """Transcribe and solve the muscle-driven tracking of ``motion`` by ``model`` (its muscles of
    ``params`` (M, len(muscle.PARAMETERS)), the engine's ``muscle_params``; ``loads``:
    ``ExternalLoads`` or None) on ``nodes`` intervals: the objective is the quadrature of
    sum_j tracking_j (z_j - z_dj)^2 + ``effort_weight`` (sum_m e_m^2 + sum_j (r_j / F_j)^2), the
    reserves r_j those of static optimisation (the model's actuators of optimal force F_j; without
    actuators one of 1 N m per coordinate). Tendons rigid (a compliant one taken as rigid, said by
    ``rigid_tendons``). The guess: the motion, and static optimisation's activations and reserves
    at the points. ValueError (one line) for bad options, a model without muscles or a motion of
    other joints."""
    check_options(nodes, scheme, max_iter=max_iter, max_time=max_time, effort_weight=effort_weight)
    if not model.muscles:
        raise ValueError(f"collocate: model {model.name!r} has no muscles ([[muscles]] in its file); collocate it "
                         "torque-driven")
    ca = casadi()
    began = time.perf_counter()
    compliant = tuple(muscle.name for muscle in model.muscles if muscle.tendon == "compliant")
    model = rigid_tendons(model)
    J, M = model.n_joints, len(model.muscles)
    t = point_times(motion.duration, nodes, scheme)
    z, zd, zdd = desired_samples(model, motion, t)
    p_loads = load_parameters(loads, t)
    actuation = MinimalDynamics(model).actuation(() if loads is None else loads.loads)
    functions = muscle_functions(model, params)
    reserve = np.array(optimal_forces(model), dtype=float)
    tracking, _ = objective_weights(model, 0.0, 0.0, 0.0)
    controls = float(effort_weight) * np.concatenate([np.ones(M), np.divide(1.0, reserve ** 2, out=np.zeros(J),
                                                                            where=reserve > 0)])
    m = len(t)
    h = float(motion.duration) / int(nodes)
    solver = _muscle_solver(ca, actuation, functions, m, J, M, p_loads.shape[1], h, scheme, tracking, controls,
                            int(max_iter), float(max_time))
    inverse = np.array(actuation.map(m)(z.T, zd.T, zdd.T, p_loads.T)).T
    so = static_optimization(model, params, t, z, zd, inverse, reserve_forces=reserve)
    guess = np.clip(so.activation, 0.0, 1.0)
    x0 = np.concatenate([z, zd, zdd, guess, guess, so.reserve], axis=1).ravel()  # point by point
    lower, upper = np.full((m, 4 * J + 2 * M), -np.inf), np.full((m, 4 * J + 2 * M), np.inf)
    lower[:, 3 * J:3 * J + 2 * M], upper[:, 3 * J:3 * J + 2 * M] = 0.0, 1.0  # a, e in [0, 1]
    lower[:, 3 * J + 2 * M:][:, reserve == 0] = upper[:, 3 * J + 2 * M:][:, reserve == 0] = 0.0
    lower[0, :2 * J] = upper[0, :2 * J] = np.concatenate([z[0], zd[0]])  # the initial state is the motion's
    built = time.perf_counter()
    values, f, status, iterations = _run(solver, x0, lower.ravel(), upper.ravel(),
                                         np.concatenate([p_loads, z], axis=1).ravel())
    solved = time.perf_counter()

    y = values.reshape(m, -1)
    zs, ws, accs, a, e, r = np.split(y, [J, 2 * J, 3 * J, 3 * J + M, 3 * J + 2 * M], axis=1)
    force, muscle_torque = (np.array(v).T for v in functions[1].map(m)(zs.T, ws.T, a.T))
    hs = scheme == "hermite-simpson"
    nodes_ = slice(0, m, 2 if hs else 1)
    return MuscleCollocationResult(
        scheme=scheme, t=t[nodes_], angles=zs[nodes_], velocities=ws[nodes_], torque=r[nodes_],
        torque_mid=r[1::2] if hs else None, objective=f, ipopt_status=status, iterations=iterations,
        solve_time_s=solved - built, build_time_s=built - began, accelerations=accs[nodes_],
        muscles=tuple(muscle.name for muscle in model.muscles), activation=a[nodes_], excitation=e[nodes_],
        muscle_force=force[nodes_], muscle_torque=muscle_torque[nodes_],
        inverse=np.array(actuation.map(m)(zs.T, ws.T, accs.T, p_loads.T)).T[nodes_], reserve_forces=reserve,
        effort_weight=float(effort_weight),
        rigid_tendons=compliant)


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
    weight = {key: options[key] for key in ("regularization", "effort_weight") if key in options}
    fields = dict(torque="collocation", evaluations=1, nodes=options["nodes"], scheme=options["scheme"],
                  **weight, **own, ipopt_status=solution.ipopt_status,
                  ipopt_iterations=solution.iterations, build_time_s=solution.build_time_s,
                  solve_time_s=solution.solve_time_s)
    if solution.residual_weights is not None:
        fields.update(residual_force_weight=solution.residual_weights[0],
                      residual_moment_weight=solution.residual_weights[1])
    if not solution.success:
        fields.update(status="collocation_failed",
                      message=f"{solution.message}; the replay of its last iterate: {replay_message}")
    return fields
