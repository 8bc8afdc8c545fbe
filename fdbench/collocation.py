"""Direct-collocation tracking (as OpenSim Moco, bioptim and Drake transcribe it), solved by IPOPT
through CasADi.

The unknowns are theta (rad), theta' (rad/s) and the elbow torque tau (N m) at the N + 1 nodes
t_k = k h, h = 1 s / N (Hermite-Simpson adds the torque at the N interval midpoints). The
defect constraints discretise the minimal-coordinate equation of motion
I1 theta'' = tau - G cos(theta) (``fdbench.minimal``, the limit of the penalty formulation):

- ``trapezoidal``: x_{k+1} - x_k - h/2 (f_k + f_{k+1}) = 0; the torque is piecewise linear.
- ``hermite-simpson`` (separated midpoint states written out in compressed form):
  x_m = (x_k + x_{k+1})/2 + h/8 (f_k - f_{k+1}),  x_{k+1} - x_k - h/6 (f_k + 4 f_m + f_{k+1}) = 0;
  the torque is piecewise quadratic through tau_k, tau_m, tau_{k+1}.

The objective is the integral over the motion's span of the squared rotation error in degrees^2 plus
``regularization`` times the integral of tau^2 (N^2 m^2 s), by the scheme's own quadrature
(trapezoid or Simpson). The initial state is fixed to the desired motion's at t = 0; the final
state is free. ``casadi`` is imported here only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .integrate import Settings
from .minimal import gravity_moment
from .motion import desired_motion

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
    """IPOPT's solution of the transcribed problem. Node arrays have shape (N + 1,); ``torque_mid``
    has shape (N,) for Hermite-Simpson and is None for the trapezoidal scheme."""

    scheme: str
    t: np.ndarray  # node times, s
    theta: np.ndarray  # rad
    theta_dot: np.ndarray  # rad/s
    torque: np.ndarray  # N m
    torque_mid: np.ndarray | None  # N m, at the interval midpoints
    objective: float  # deg^2 s (+ regularisation)
    ipopt_status: str  # IPOPT's return status, e.g. Solve_Succeeded
    iterations: int
    solve_time_s: float  # wall time of IPOPT's solve (the transcription excluded)
    build_time_s: float  # wall time of the transcription

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
        """The torque history t (s), shape (n,) -> N m, shape (n,), interpolated as the scheme
        assumes: piecewise linear (trapezoidal) or piecewise quadratic (Hermite-Simpson)."""
        t_nodes, u = self.t, self.torque
        h = t_nodes[1] - t_nodes[0]
        n = len(t_nodes) - 1
        if self.torque_mid is None:
            return lambda t: np.interp(t, t_nodes, u)
        um = self.torque_mid

        def quadratic(t):
            t = np.asarray(t, dtype=float)
            k = np.clip(np.floor((t - t_nodes[0]) / h).astype(int), 0, n - 1)
            s = (t - t_nodes[k]) / h  # in [0, 1] within interval k
            # Lagrange basis through s = 0, 1/2, 1
            return (2 * (s - 0.5) * (s - 1)) * u[k] + (-4 * s * (s - 1)) * um[k] + (2 * s * (s - 0.5)) * u[k + 1]

        return quadratic

    def torque_samples(self, t: np.ndarray) -> np.ndarray:
        return np.asarray(self.torque_function()(t), dtype=float)


def collocate(settings: Settings = Settings(), nodes: int = DEFAULT_NODES, scheme: str = "hermite-simpson",
              regularization: float = DEFAULT_REGULARIZATION, max_iter: int = DEFAULT_MAX_ITER,
              max_time: float = DEFAULT_MAX_TIME) -> CollocationResult:
    """Transcribe and solve the tracking problem of ``settings``' model and kinematics.

    Never raises on a solver failure: IPOPT's status says what happened (``success``, ``message``)."""
    check_options(nodes, scheme, regularization, max_iter, max_time)
    import casadi as ca

    began = time.perf_counter()
    model, kinematics = settings.nominal_model, settings.kinematics
    G, inertia = gravity_moment(model), model.I1
    duration = settings.motion.duration
    n, h = int(nodes), duration / nodes
    t = np.linspace(0.0, duration, n + 1)
    th_d, w_d, _ = desired_motion(t, kinematics)
    hs = scheme == "hermite-simpson"

    th, w, u = ca.SX.sym("theta", n + 1), ca.SX.sym("omega", n + 1), ca.SX.sym("tau", n + 1)
    um = ca.SX.sym("tau_mid", n) if hs else None
    acc = (u - G * ca.cos(th)) / inertia
    deg2 = (180.0 / math.pi) ** 2
    lagrange = deg2 * (th - th_d) ** 2 + regularization * u**2  # integrand at the nodes
    k0, k1 = slice(0, n), slice(1, n + 1)
    if hs:
        th_m = (th[k0] + th[k1]) / 2 + h / 8 * (w[k0] - w[k1])
        w_m = (w[k0] + w[k1]) / 2 + h / 8 * (acc[k0] - acc[k1])
        acc_m = (um - G * ca.cos(th_m)) / inertia
        th_md = desired_motion(t[:-1] + h / 2, kinematics)[0]
        defects = ca.vertcat(th[k1] - th[k0] - h / 6 * (w[k0] + 4 * w_m + w[k1]),
                             w[k1] - w[k0] - h / 6 * (acc[k0] + 4 * acc_m + acc[k1]))
        lagrange_m = deg2 * (th_m - th_md) ** 2 + regularization * um**2
        objective = h / 6 * (ca.sum1(lagrange[k0]) + 4 * ca.sum1(lagrange_m) + ca.sum1(lagrange[k1]))
        x = ca.vertcat(th, w, u, um)
    else:
        defects = ca.vertcat(th[k1] - th[k0] - h / 2 * (w[k0] + w[k1]),
                             w[k1] - w[k0] - h / 2 * (acc[k0] + acc[k1]))
        objective = h / 2 * (ca.sum1(lagrange[k0]) + ca.sum1(lagrange[k1]))
        x = ca.vertcat(th, w, u)

    # initial guess: the desired motion and the minimal model's inverse-dynamics torque
    u_guess = inertia * desired_motion(t, kinematics)[2] + G * np.cos(th_d)
    guess = [th_d, w_d, u_guess]
    if hs:
        tm = t[:-1] + h / 2
        th_md, _, a_md = desired_motion(tm, kinematics)
        guess.append(inertia * a_md + G * np.cos(th_md))
    x0 = np.concatenate(guess)
    lbx, ubx = np.full(x0.size, -np.inf), np.full(x0.size, np.inf)
    lbx[0] = ubx[0] = th_d[0]  # theta(0)
    lbx[n + 1] = ubx[n + 1] = w_d[0]  # theta'(0)
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
    return CollocationResult(
        scheme=scheme, t=t, theta=z[: n + 1], theta_dot=z[n + 1 : 2 * n + 2], torque=z[2 * n + 2 : 3 * n + 3],
        torque_mid=z[3 * n + 3 :] if hs else None, objective=f, ipopt_status=status, iterations=iterations,
        solve_time_s=solved - built, build_time_s=built - began,
    )
