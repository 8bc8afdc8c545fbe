"""Direct-collocation tracking of any model (as OpenSim Moco, bioptim and Drake transcribe it), solved by
IPOPT through CasADi, on the model's minimal equations z'' = M(z)^-1 (tau - h(z, z'))
(``fdbench.multibody.symbolic``, the limit of the penalty formulation).

The unknowns are the joint angles z (rad), their rates z' (rad/s) and the joint torques tau (N m) at
the N + 1 nodes t_k = k h, h = T / N (Hermite-Simpson adds the torques at the N interval midpoints),
2J states and J torques per node. The defect constraints discretise the equation of motion:

- ``trapezoidal``: x_{k+1} - x_k - h/2 (f_k + f_{k+1}) = 0; the torque is piecewise linear.
- ``hermite-simpson`` (separated midpoint states written out in compressed form):
  x_m = (x_k + x_{k+1})/2 + h/8 (f_k - f_{k+1}),  x_{k+1} - x_k - h/6 (f_k + 4 f_m + f_{k+1}) = 0;
  the torque is piecewise quadratic through tau_k, tau_m, tau_{k+1}.

The objective is the integral over the motion's span of the squared joint-angle errors in degrees^2,
summed over the joints, plus ``regularization`` times the integral of |tau|^2 (N^2 m^2 s), by the
scheme's own quadrature (trapezoid or Simpson). The initial state is fixed to the desired motion's at
t = 0; the final state is free; the initial guess is the desired motion and the model's
inverse-dynamics torques. A motion is anything with ``duration`` (s) and ``motion(t) -> (z, z', z'')``
(rad, rad/s, rad/s^2), each of shape t.shape + (J,). ``casadi`` is imported only when the
transcription is built.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np


SCHEMES = ("hermite-simpson", "trapezoidal")
DEFAULT_NODES = 100
MIN_NODES, MAX_NODES = 2, 10_000
DEFAULT_REGULARIZATION = 1e-6  # (deg^2) / (N^2 m^2): 1 N m of torque costs as much as 0.001 deg of error
DEFAULT_MAX_ITER = 1000
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


def check_options(nodes: int, scheme: str, regularization: float, max_iter: int = DEFAULT_MAX_ITER,
                  max_time: float = DEFAULT_MAX_TIME) -> None:
    """Raise ValueError with a one-line message naming the option for anything out of range."""
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or not MIN_NODES <= nodes <= MAX_NODES:
        raise ValueError(f"--nodes must be an integer in [{MIN_NODES}, {MAX_NODES}], got {nodes}")
    if scheme not in SCHEMES:
        from .registry import unknown_name_message

        raise ValueError("--scheme: " + unknown_name_message("scheme", scheme, list(SCHEMES)))
    if not (isinstance(regularization, (int, float)) and math.isfinite(regularization) and regularization >= 0):
        raise ValueError(f"--regularization must be a non-negative finite number, got {regularization}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"--max-iter must be an integer >= 1, got {max_iter}")
    if not (isinstance(max_time, (int, float)) and math.isfinite(max_time) and max_time > 0):
        raise ValueError(f"--max-time must be a positive finite number of seconds, got {max_time}")


@dataclass
class CollocationResult:
    """IPOPT's solution of the transcribed problem. Node arrays have shape (N + 1,) for one joint
    (the forearm) or (N + 1, J) for J joints (columns in the model's joint order); ``torque_mid``
    has shape (N,) or (N, J) for Hermite-Simpson and is None for the trapezoidal scheme."""

    scheme: str
    t: np.ndarray  # node times, s, shape (N + 1,)
    angles: np.ndarray  # joint angles, rad
    velocities: np.ndarray  # rad/s
    torque: np.ndarray  # N m
    torque_mid: np.ndarray | None  # N m, at the interval midpoints
    objective: float  # deg^2 s (+ regularisation)
    ipopt_status: str  # IPOPT's return status, e.g. Solve_Succeeded
    iterations: int
    solve_time_s: float  # wall time of IPOPT's solve (the transcription excluded)
    build_time_s: float  # wall time of the transcription

    @property
    def theta(self) -> np.ndarray:
        """The forearm's name of ``angles``: theta (rad) at the nodes."""
        return self.angles

    @property
    def theta_dot(self) -> np.ndarray:
        """The forearm's name of ``velocities``: theta' (rad/s) at the nodes."""
        return self.velocities

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


def _joint_sum(terms):
    """The sum over the columns (joints) of an SX matrix of shape (k, J): shape (k, 1)."""
    total = terms[:, 0]
    for j in range(1, terms.shape[1]):
        total = total + terms[:, j]
    return total


def transcribe(acceleration, t: np.ndarray, angles_d: np.ndarray, velocities_d: np.ndarray,
               angles_mid_d: np.ndarray | None, torque_guess: np.ndarray, torque_mid_guess: np.ndarray | None,
               scheme: str, regularization: float, max_iter: int, max_time: float,
               began: float | None = None) -> CollocationResult:
    """Transcribe the tracking problem of a model with J joints on the N + 1 equally spaced nodes
    ``t`` (s) and solve it with IPOPT.

    acceleration(z, w, u): the model's joint accelerations (rad/s^2) as CasADi SX of shape (k, J)
    from its angles z (rad), velocities w (rad/s) and torques u (N m), each SX of shape (k, J).
    angles_d (rad), velocities_d (rad/s), torque_guess (N m): the desired motion and the torque
    of the initial guess at the nodes, shape (N + 1,) for one joint or (N + 1, J); angles_mid_d,
    torque_mid_guess: the same at the interval midpoints, shape (N,) or (N, J) (Hermite-Simpson;
    None for trapezoidal). The initial state is fixed to angles_d[0], velocities_d[0]; the guess
    of the states is the desired motion. The objective is the integral of the squared angle
    errors in deg^2 summed over the joints plus ``regularization`` times that of |tau|^2.
    ``began``: the perf_counter time the transcription began (default now).

    Never raises on a solver failure: IPOPT's status says what happened."""
    import casadi as ca

    began = time.perf_counter() if began is None else began
    one = np.ndim(angles_d) == 1
    n, joints = len(t) - 1, 1 if one else np.shape(angles_d)[1]
    h = float(t[1] - t[0])
    hs = scheme == "hermite-simpson"

    th, w, u = (ca.SX.sym(name, n + 1, joints) for name in ("angle", "velocity", "tau"))
    um = ca.SX.sym("tau_mid", n, joints) if hs else None
    acc = acceleration(th, w, u)
    lagrange = _joint_sum(DEG2 * (th - angles_d) ** 2) + _joint_sum(regularization * u**2)  # at the nodes
    k0, k1 = slice(0, n), slice(1, n + 1)
    if hs:
        th_m = (th[k0, :] + th[k1, :]) / 2 + h / 8 * (w[k0, :] - w[k1, :])
        w_m = (w[k0, :] + w[k1, :]) / 2 + h / 8 * (acc[k0, :] - acc[k1, :])
        acc_m = acceleration(th_m, w_m, um)
        defects = ca.vertcat(ca.vec(th[k1, :] - th[k0, :] - h / 6 * (w[k0, :] + 4 * w_m + w[k1, :])),
                             ca.vec(w[k1, :] - w[k0, :] - h / 6 * (acc[k0, :] + 4 * acc_m + acc[k1, :])))
        lagrange_m = _joint_sum(DEG2 * (th_m - angles_mid_d) ** 2) + _joint_sum(regularization * um**2)
        objective = h / 6 * (ca.sum1(lagrange[k0]) + 4 * ca.sum1(lagrange_m) + ca.sum1(lagrange[k1]))
        x = ca.vertcat(ca.vec(th), ca.vec(w), ca.vec(u), ca.vec(um))
        guess = [angles_d, velocities_d, torque_guess, torque_mid_guess]
    else:
        defects = ca.vertcat(ca.vec(th[k1, :] - th[k0, :] - h / 2 * (w[k0, :] + w[k1, :])),
                             ca.vec(w[k1, :] - w[k0, :] - h / 2 * (acc[k0, :] + acc[k1, :])))
        objective = h / 2 * (ca.sum1(lagrange[k0]) + ca.sum1(lagrange[k1]))
        x = ca.vertcat(ca.vec(th), ca.vec(w), ca.vec(u))
        guess = [angles_d, velocities_d, torque_guess]

    x0 = np.concatenate([np.asarray(g, dtype=float).ravel(order="F") for g in guess])  # ca.vec is column-major
    lbx, ubx = np.full(x0.size, -np.inf), np.full(x0.size, np.inf)
    size = (n + 1) * joints  # one block of node values
    z0, w0 = (np.atleast_1d(np.asarray(d, dtype=float)[0]) for d in (angles_d, velocities_d))
    for j in range(joints):  # the initial state is the desired motion's
        lbx[j * (n + 1)] = ubx[j * (n + 1)] = z0[j]
        lbx[size + j * (n + 1)] = ubx[size + j * (n + 1)] = w0[j]
    options = {
        "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "verbose": False,
        "ipopt.max_iter": int(max_iter), "ipopt.max_cpu_time": float(max_time), "ipopt.tol": 1e-10,
        "error_on_fail": False,
    }
    solver = ca.nlpsol("collocation", "ipopt", {"x": x, "f": objective, "g": defects}, options)
    built = time.perf_counter()
    try:
        solution = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
        stats = solver.stats()
        z, f = np.asarray(solution["x"], dtype=float).ravel(), float(solution["f"])
        status, iterations = str(stats.get("return_status", "unknown")), int(stats.get("iter_count", 0))
    except RuntimeError as exc:  # CasADi reports an error in a callback or in IPOPT itself
        z, f = np.full(x0.size, np.nan), math.nan
        status, iterations = "CasADi error: " + " ".join(str(exc).split())[:200], 0
    solved = time.perf_counter()

    def block(k: int, rows: int = n + 1) -> np.ndarray:
        values = z[k * size : k * size + rows * joints]
        return values if one else values.reshape(joints, rows).T

    return CollocationResult(
        scheme=scheme, t=t, angles=block(0), velocities=block(1), torque=block(2),
        torque_mid=block(3, n) if hs else None, objective=f, ipopt_status=status, iterations=iterations,
        solve_time_s=solved - built, build_time_s=built - began,
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
              max_time: float = DEFAULT_MAX_TIME) -> CollocationResult:
    """Transcribe and solve the tracking problem of ``motion`` with ``model`` on ``nodes`` intervals
    over the motion's span: node arrays of shape (N + 1, J) in the model's joint order. ValueError
    (one line) for options out of range or a motion of other joints; never raises on a solver
    failure: IPOPT's status says what happened."""
    from .multibody.symbolic import MinimalDynamics

    check_options(nodes, scheme, regularization, max_iter, max_time)
    began = time.perf_counter()
    dynamics = MinimalDynamics(model)
    n = int(nodes)
    t = np.linspace(0.0, motion.duration, n + 1)
    z_d, w_d, a_d = desired_samples(model, motion, t)
    z_md = um_guess = None
    if scheme == "hermite-simpson":
        z_md, w_md, a_md = desired_samples(model, motion, t[:-1] + motion.duration / n / 2)
        um_guess = dynamics.inverse(z_md, w_md, a_md)
    return transcribe(dynamics.forward_rows, t, z_d, w_d, z_md, dynamics.inverse(z_d, w_d, a_d), um_guess, scheme,
                      regularization, max_iter, max_time, began)


def record_fields(solution: CollocationResult, options: dict, own_rmse_deg: float, replay_message: str) -> dict:
    """The fields a collocate run adds to the record of its replay: the options, the collocation's
    own RMSE_rot at its nodes (deg), IPOPT's status, iterations and solve time (s); status
    'collocation_failed' when IPOPT did not solve the problem."""
    fields = dict(torque="collocation", evaluations=1, nodes=options["nodes"], scheme=options["scheme"],
                  regularization=options["regularization"], collocation_rmse_rot_deg=own_rmse_deg,
                  ipopt_status=solution.ipopt_status, ipopt_iterations=solution.iterations,
                  solve_time_s=solution.solve_time_s)
    if not solution.success:
        fields.update(status="collocation_failed",
                      message=f"{solution.message}; the replay of its last iterate: {replay_message}")
    return fields
