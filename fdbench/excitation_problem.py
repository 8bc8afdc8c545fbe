"""The shooting problem with the muscles' excitations as its inputs: eq. 18 (``fdbench.problem``) of
a muscle-driven forward simulation plus an effort term,

    f(p) = RMSE_rot_deg(p) + w_penal (1 - t_end / T) + w_e * integral_0^T sum_m e_m(t)^2 dt,

one block of parameters per muscle, each a registered torque parameterisation (``fdbench.torques``:
cs, pf, ann) whose signal s_m(t) is mapped into [0, 1] by the logistic e = 1 / (1 + exp(-s)). The
logistic is smooth and strictly increasing, takes every real number into (0, 1) (so every
parameter vector is a valid excitation history: CMA-ES and BFGS need no bounds and no clipping,
which would leave the gradient zero where it clips), and its slope e (1 - e) costs nothing more.
A tanh map 0.5 (1 + tanh s) is the same curve at half the scale; a sine or a clip would fold or
flatten the parameters' space.

The parameterisations are prepared (fitted) on the logit of static optimisation's activations along
the motion (``multibody.static_optimization``, clipped to [0.02, 0.98]), a start that roughly
meets the motion's inverse dynamics. With ``feedforward`` static optimisation's excitations are
the feedforward instead, as the inverse-dynamics torque is the torque problem's (eq. 19): muscle
m's signal is s_m(t) = logit(a_SO,m(t)) + the parameterisation's output, static optimisation run
on RK4's half-step grid (its activations clipped as above), each parameterisation starting from
zero output (``prepare`` with feedforward; its scale from that logit's range). The effort integral is the trapezoidal rule on RK4's half-step
grid (excitation^2 s; its weight w_e in deg per excitation^2 s) and is added outside the compiled
kernels, its gradient 2 w_e sum_k w_k e_k de_k/dp by numpy. The start: the motion's first sample,
each activation at the initial parameters' excitation at t = 0 (a compliant tendon at the fibre's
static equilibrium), fixed: it does not move with the parameters.

A population is evaluated in one compiled call per thread (``tracking.rk4_candidates`` with the
candidates' excitations), the exact gradient by one RK4 with forward sensitivities through the
activation and tendon states (``multibody.kernels.rk4_sensitivity`` with muscles; paths of points
or polynomials, both with their exact Hessians).
"""

from __future__ import annotations

import copy
import math

import numpy as np

from .multibody import simulation as sim
from .problem import ShootingProblem, tracking_gradient, tracking_setup

DEFAULT_EFFORT_WEIGHT = 1.0  # deg per (excitation^2 s)
START_RANGE = (0.02, 0.98)  # static optimisation's activations clipped to this before the logit


def logistic(s):
    """The excitation 1 / (1 + exp(-s)) in (0, 1) of the signal s (any shape)."""
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(s, dtype=float)))  # the logistic without overflow


def start_signal(activation) -> np.ndarray:
    """The logit of static optimisation's activations (any shape), clipped to START_RANGE first."""
    start = np.clip(np.asarray(activation, dtype=float), *START_RANGE)
    return np.log(start / (1.0 - start))


class ExcitationProblem(ShootingProblem):
    """Optimise per-muscle excitation parameters so that ``engine``'s model (with muscles) tracks
    ``motion``: ``excitation`` a registered parameterisation's name (made once per muscle with
    ``options``) or a parameterisation (copied per muscle); ``penalty_weight`` eq. 18's; ``effort_weight``
    w_e (deg per excitation^2 s, >= 0); RK4 with steps of about ``dt`` s on the motion's samples.
    ``feedforward``: the signals add to static optimisation's logit on the grid (see the module's
    text); without, the parameterisations alone, fitted to it.
    No joint torques: the muscles alone move the model."""

    def __init__(self, excitation, engine, motion, penalty_weight: float = 1.0,
                 effort_weight: float = DEFAULT_EFFORT_WEIGHT, dt: float = 1e-3, feedforward: bool = False,
                 **options):
        from .multibody.static_optimization import static_optimization
        from .torques import make_torque

        if not engine.n_muscles:
            raise ValueError(f"the model {engine.model.name!r} has no muscles to excite")
        for name, value in (("penalty weight", penalty_weight), ("effort weight", effort_weight)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a non-negative finite number, got {value}")
        self.engine, self.motion, self.dt, self.feedforward = engine, motion, dt, bool(feedforward)
        self.penalty_weight, self.effort_weight = float(penalty_weight), float(effort_weight)
        setup = tracking_setup(engine, motion, dt)
        self.inverse, grid = setup.inverse, setup.grid
        self._grid = grid
        if not grid.every:
            raise ValueError("the motion's samples must lie on the RK4 grid (uniform, every k steps)")
        self.duration, self._n_steps, self._every, self._half = motion.duration, grid.n, grid.every, grid.t
        M = engine.n_muscles
        self.parts = ([make_torque(excitation, **options) for _ in range(M)] if isinstance(excitation, str)
                      else [copy.deepcopy(excitation) for _ in range(M)])
        inv = self.inverse
        rows = 2 * self._n_steps + 1
        if self.feedforward:  # static optimisation on the grid; the motion's samples are among its rows
            half = sim.inverse_dynamics(grid.t, engine, motion)
            self._ff_half = start_signal(static_optimization(engine.model, engine.muscle_params, half.t, half.angles,
                                                             half.velocities, half.torque).activation)
            signal = self._ff_half[::2 * self._every]
        else:
            so = static_optimization(engine.model, engine.muscle_params, inv.t, inv.angles, inv.velocities, inv.torque)
            signal, self._ff_half = start_signal(so.activation), np.zeros((rows, M))
        p0 = [np.asarray(part.prepare(inv.t, signal[:, m], self.feedforward), dtype=float)
              for m, part in enumerate(self.parts)]
        self.blocks = np.cumsum([0] + [len(p) for p in p0])
        self.p0 = np.concatenate(p0)
        self.scale = np.concatenate([np.asarray(part.scale(), dtype=float) for part in self.parts])
        self.x0 = self.p0 / self.scale
        self._on_grid_batch = [part.on_grid_batch(self._half) for part in self.parts]
        self._jacobians = None
        self._trapezoid = np.full(rows, 0.5 * grid.step)  # the half-step grid's trapezoidal weights (s)
        self._trapezoid[[0, -1]] *= 0.5
        z0, zd0, _ = motion(np.zeros(1))
        y0 = engine.state_from_joints(z0[0], zd0[0])
        self.y0 = np.concatenate([y0, sim.muscle_start(engine, y0, self.excitations_on_grid(self.p0)[0])])
        self._zero = np.zeros((rows, engine.n_joints))
        self._kernel_rest = (grid.ref, grid.refd, self._every, np.ascontiguousarray(inv.angles), self.penalty_weight)
        self._population = None

    @property
    def n_params(self) -> int:
        return int(self.blocks[-1])

    @property
    def batched(self) -> bool:
        return True

    def excitations_on_grid_batch(self, P) -> np.ndarray:
        """The excitations in (0, 1) on the half-step grid for every row of P, shape (lam, n_params)
        -> (lam, 2 n + 1, M): each muscle's parameterisation on its block (plus, with feedforward,
        static optimisation's logit), through the logistic."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        with np.errstate(all="ignore"):
            signal = np.stack([f(P[:, a:b]) for f, a, b in zip(self._on_grid_batch, self.blocks[:-1], self.blocks[1:])],
                              axis=-1)
        return logistic(signal + self._ff_half if self.feedforward else signal)

    def excitations_on_grid(self, p) -> np.ndarray:
        """The excitations on the half-step grid for parameters p, shape (2 n + 1, M)."""
        return self.excitations_on_grid_batch(np.asarray(p, dtype=float)[None])[0]

    def effort(self, E) -> np.ndarray:
        """w_e times the trapezoidal integral of sum_m e_m^2 over the grid (deg) of excitation
        histories E (lam, 2 n + 1, M), shape (lam,)."""
        return np.array([self.effort_weight * (self._trapezoid @ np.sum(e * e, axis=1)) for e in E])

    def simulate(self, p):
        """The forward simulation of parameters p (``Engine.simulate``'s ``SimResult``: RK4 under the
        excitations, no joint torques)."""
        zero = self._zero
        return self.engine.simulate(self.y0, self.duration / self._n_steps, self._n_steps, zero, zero, zero, zero,
                                    0.0, 0.0, excitation_half=self.excitations_on_grid(p))

    def simulation(self, p) -> sim.Simulation:
        """The forward simulation of parameters p on the motion's samples (``simulation.simulate``
        from the start y0, muscle states included): the angles, the applied generalised forces (the
        muscles'), each muscle's activation, excitation and force (N)."""
        E, half = self.excitations_on_grid(p), self._half

        def excitation(t):
            return E if t is half else np.stack([np.interp(t, half, E[:, m]) for m in range(E.shape[1])], axis=-1)

        return sim.simulate(None, self.engine, self.motion, dt=self.dt, start=self.y0, grid=self._grid,
                            excitation=excitation)

    def objectives(self, P) -> np.ndarray:
        """f of every row of P, shape (lam, n_params) -> (lam,): the simulations and eq. 18 in compiled
        calls over threads, the effort by numpy; a population of one gives ``objective``'s numbers."""
        from .population import Population
        from .tracking import rk4_candidates

        P = np.atleast_2d(np.asarray(P, dtype=float))
        if self._population is None:
            self._population = Population(rk4_candidates, self._n_steps, self.engine.population_widths_with(True))
        E = self.excitations_on_grid_batch(P)
        tau = np.zeros((len(P), *self._zero.shape))
        args = self.engine.population_args(self.y0, self.duration / self._n_steps, self._n_steps, tau,
                                           *self._kernel_rest, excitation=E)
        return self._population(len(P), args) + self.effort(E)

    def objective(self, p) -> float:
        return float(self.objectives(np.asarray(p, dtype=float)[None])[0])

    def check_exact_gradient(self) -> None:
        """ValueError (one line) where the exact gradient is not available: a parameterisation without
        d signal / d p (either muscle path form has its exact Hessian)."""
        if self._jacobians is None:
            self._jacobians = [part.on_grid_jacobian(self._half) for part in self.parts]
        if any(jacobian is None for jacobian in self._jacobians):
            raise ValueError(f"--gradient exact: parameterisation {self.parts[0].name!r} gives no derivative")

    def value_and_gradient(self, p) -> tuple[float, np.ndarray]:
        """f(p) and its exact gradient, shape (n_params,): one RK4 with forward sensitivities through
        the muscle states, parameter q of muscle m's block moving its excitation by
        G[:, q] = e (1 - e) d s_m / d p_q; eq. 18's tracking term's gradient as the torque problem's
        (``problem.tracking_gradient``; the penalty term is piecewise constant), the effort's by numpy.
        The value equals ``objective(p)`` (the same kernels' states)."""
        from .multibody.kernels import rk4_sensitivity
        from .tracking import tracking_objective

        self.check_exact_gradient()
        p = np.asarray(p, dtype=float)
        E = self.excitations_on_grid(p)
        slope = E * (1.0 - E)
        with np.errstate(all="ignore"):
            G = np.concatenate([slope[:, [m]] * np.asarray(jacobian(p[a:b]), dtype=float).reshape(len(self._half), b - a)
                                for m, (jacobian, a, b) in enumerate(zip(self._jacobians, self.blocks[:-1],
                                                                         self.blocks[1:]))], axis=1)
        engine, n, every = self.engine, self._n_steps, self._every
        J = engine.n_joints
        muscle_of = np.repeat(np.arange(engine.n_muscles), np.diff(self.blocks))
        y0, dt, _, tau, ref, refd, _, angles_ref, weight, *layout, muscles = engine.population_args(
            self.y0, self.duration / n, n, np.zeros((1, *self._zero.shape)), *self._kernel_rest, excitation=E[None])
        width = self.y0.shape[0]
        states, rates = np.empty((n + 1, width)), np.empty((n + 1, width))
        applied, dz = np.empty((n + 1, J)), np.empty((n // every + 1, J, len(p)))
        muscles = muscles._replace(excitation=np.ascontiguousarray(E))
        _, done = rk4_sensitivity(y0, dt, n, tau[0], ref, refd, np.ascontiguousarray(G), J + muscle_of, every,
                                  *layout, states, rates, applied, dz, muscles)
        value = tracking_objective(states, done, every, angles_ref, n, weight, engine.layout) + self.effort(E[None])[0]
        effort_gradient = 2.0 * self.effort_weight * np.einsum("k,kq,kq->q", self._trapezoid, E[:, muscle_of], G)
        return float(value), tracking_gradient(engine, states, done, every, angles_ref, dz) + effort_gradient

    def value_and_gradient_scaled(self, x) -> tuple[float, np.ndarray]:
        """``value_and_gradient`` on the scaled parameters x = p / scale."""
        f, g = self.value_and_gradient(np.asarray(x, dtype=float) * self.scale)
        return f, g * self.scale


def warm_up(engine, sensitivities: bool = False) -> None:
    """Load (or compile) the kernels an ``ExcitationProblem`` on ``engine`` (a model with muscles)
    runs, on two steps from rest at excitations 0.1, with the very argument types of its calls: the
    population's (``tracking.rk4_candidates`` with muscles) and, with ``sensitivities``,
    ``rk4_sensitivity`` with muscles (polynomial paths only), so that later timings exclude them."""
    from .compile_guard import compiling
    from .multibody.kernels import rk4_sensitivity
    from .population import Population
    from .tracking import rk4_candidates

    J, M, n = engine.n_joints, engine.n_muscles, 2
    rows = 2 * n + 1
    y0 = engine.state_from_joints(np.zeros(J), np.zeros(J))
    y0 = np.concatenate([y0, sim.muscle_start(engine, y0, np.full(M, 0.1))])
    ref, E = np.zeros((rows, J)), np.full((1, rows, M), 0.1)
    with compiling():  # Ctrl-C while a kernel compiles ends the command at once
        args = engine.population_args(y0, 0.05, n, np.zeros((1, rows, J)), ref, ref, 1, np.zeros((n + 1, J)), 1.0,
                                      excitation=E)
        Population(rk4_candidates, n, engine.population_widths_with(True))(1, args)
        if not sensitivities:
            return
        y0, dt, _, tau, ref, refd, every, _, _, *layout, muscles = args
        width, P = y0.shape[0], M
        muscles = muscles._replace(excitation=np.ascontiguousarray(E[0]))
        rk4_sensitivity(y0, dt, n, tau[0], ref, refd, np.ones((rows, P)), J + np.arange(M), every, *layout,
                        np.empty((n + 1, width)), np.empty((n + 1, width)), np.empty((n + 1, J)),
                        np.empty((n // every + 1, J, P)), muscles)
