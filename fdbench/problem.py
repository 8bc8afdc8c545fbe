"""The tracking problem of section 4 on any model of the engine: parameters -> torque histories ->
forward simulation -> objective

    f*(p) = RMSE_rot_deg(p) + w_penal (1 - t_end / T)

(eq. 18 for J joints: RMSE_rot_deg over every joint and all samples reached; T the motion's duration,
1 s in the paper: the penalty is the fraction of the motion not reached). A model with translations
(a free joint's x, y) never pools them with the angles: its tracking term is RMSE_rot_deg over the
angles plus RMSE_trans_cm over the translations, so 1 cm of pelvis error weighs as 1 deg. One block of torque
parameters per joint (each joint its own instance of the parameterisation, prepared on that joint's
inverse-dynamics torque), the blocks concatenated into one parameter vector. Optimisers see one
objective of scaled parameters x = p / scale and work unchanged; budgets keep their meaning (one
evaluation, one forward simulation).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from .multibody import simulation as sim

# eq. 18's residual term on a floating base with external loads: deg per N of the residual force's
# RMS (FX, FY) and per N m of the moment's (MZ), so that inverse dynamics' residuals on a recorded
# walk (about 35 N, 15 N m) cost about half a degree: tracking first, the smaller residuals among
# motions that track alike
DEFAULT_RESIDUAL_WEIGHT = 0.01


def residual_weight(given: float | None, model, loads) -> float:
    """The weight of eq. 18's residual term: ``given``, else DEFAULT_RESIDUAL_WEIGHT on a model with a
    floating base under external loads, else 0 (without loads the residuals carry the body's weight)."""
    if given is not None:
        return float(given)
    return DEFAULT_RESIDUAL_WEIGHT if model.floating_base is not None and loads is not None else 0.0


class ShootingProblem:
    """Eq. 18 of a shooting problem, whatever the model: a subclass gives ``simulate(p)``,
    ``rmse_deg(result)`` (eq. 18's tracking term over the samples reached, deg), ``objectives(P)``,
    ``batched``, ``scale``, ``duration`` and ``penalty_weight``."""

    def objective_of(self, result) -> float:
        """Eq. 18 for a finished simulation."""
        rmse = self.rmse_deg(result)
        if not math.isfinite(rmse):
            rmse = 0.0  # nothing reached beyond t = 0: the penalty term says it all
        return rmse + self.penalty_weight * (1.0 - result.t_end / self.duration)

    def objective(self, p) -> float:
        if self.batched:  # a population of one: the very numbers of a population's evaluation
            return float(self.objectives(np.asarray(p, dtype=float)[None])[0])
        return self.objective_of(self.simulate(p)) + self.residual_cost(p)

    def residual_cost(self, p) -> float:
        """Eq. 18's residual term for parameters p (deg); 0 without one."""
        return 0.0

    def objective_scaled(self, x) -> float:
        return self.objective(np.asarray(x) * self.scale)

    def objectives_scaled(self, X) -> np.ndarray:
        return self.objectives(np.atleast_2d(np.asarray(X, dtype=float)) * self.scale)


@dataclass(frozen=True)
class TrackingSetup:
    """What a tracking problem takes from the nominal model on the desired motion, made before an
    optimisation's clock starts as the C loop precomputes its references and feedforward: eq. 3 on
    the motion's samples (``inverse``, a ``simulation.JointInverse``: the parameters' fit and eq.
    18's reference), RK4's half-step grid of the motion (``grid``, a ``simulation.HalfSteps``) and,
    with feedforward, eq. 3 on its half steps (``feedforward``, N m, (2 n + 1, J), read-only; else None)."""

    inverse: sim.JointInverse
    grid: sim.HalfSteps
    feedforward: np.ndarray | None


def tracking_setup(nominal, motion, dt: float = 1e-3, feedforward: bool = False) -> TrackingSetup:
    """The ``TrackingSetup`` of the engine ``nominal`` on ``motion`` with steps of about dt (s)."""
    grid = sim.half_steps(motion, dt)
    torque = None
    if feedforward:
        torque = np.array(sim.inverse_dynamics(grid.t, nominal, motion).torque)
        torque.flags.writeable = False
    return TrackingSetup(sim.inverse_dynamics(None, nominal, motion), grid, torque)


class TrackingProblem(ShootingProblem):
    """Optimise per-joint torque parameters so that the simulated body (``engine``) tracks ``motion``.

    ``torque``: a registered parameterisation's name, made once per joint with ``options``, or a
    parameterisation (``torques.TorqueParameterisation``), copied once per joint.
    With ``feedforward`` the parameterised torques are added to the inverse-dynamics torques
    (eq. 19); without, they are the whole drive torques (eq. 15). ``nominal`` (an engine of the same
    joints; default: ``engine``) gives the inverse dynamics that prepare the parameters, the
    feedforward and the objective's reference. ``dt``, ``integrator``, ``rtol`` and ``atol`` say how
    to simulate (``simulation.simulate``): with rk4 the torques are computed on its half-step grid at
    once, with an adaptive integrator at the times it asks for. ``setup``: the ``TrackingSetup`` of
    ``nominal`` on ``motion`` with this dt and feedforward, made beforehand (default: made here)."""

    def __init__(self, torque, engine, motion, feedforward: bool = False, penalty_weight: float = 1.0,
                 dt: float = 1e-3, nominal=None, integrator: str = "rk4", rtol: float = 1e-6, atol: float = 1e-9,
                 residual_weight: float = 0.0, setup: TrackingSetup | None = None, **options):
        from .integrate import check_integrator
        from .torques import make_torque

        if not (math.isfinite(penalty_weight) and penalty_weight >= 0):
            raise ValueError(f"penalty weight must be a non-negative finite number, got {penalty_weight}")
        self.engine, self.motion, self.dt = engine, motion, dt
        self.integrator, self.rtol, self.atol = check_integrator(integrator), rtol, atol
        self.feedforward, self.penalty_weight = feedforward, penalty_weight
        base = engine.model.floating_base
        self.residual_weight = float(residual_weight) if base is not None else 0.0
        self.base_column = engine.model.coordinates.index(base.coordinate_names[0]) if base is not None else None
        self._nominal = engine if nominal is None else nominal
        if setup is None:
            setup = tracking_setup(self._nominal, motion, dt, feedforward)
        elif setup.grid.motion is not motion or setup.grid.dt != dt or (setup.feedforward is None) == bool(feedforward):
            raise ValueError("the tracking set-up is of another motion, step or feedforward")
        self.inverse, self._grid = setup.inverse, setup.grid
        self.duration = motion.duration
        n_joints = self.inverse.torque.shape[1]
        self.parts = ([make_torque(torque, **options) for _ in range(n_joints)] if isinstance(torque, str)
                      else [copy.deepcopy(torque) for _ in range(n_joints)])
        p0 = [np.asarray(part.prepare(self.inverse.t, self.inverse.torque[:, j], feedforward), dtype=float)
              for j, part in enumerate(self.parts)]
        self.blocks = np.cumsum([0] + [len(p) for p in p0])
        self.p0 = np.concatenate(p0)
        self.scale = np.concatenate([np.asarray(part.scale(), dtype=float) for part in self.parts])
        self.x0 = self.p0 / self.scale
        n = self._grid.n
        self._half = self._grid.t
        self._on_grid_batch = [part.on_grid_batch(self._half) for part in self.parts]
        self._ff_half = setup.feedforward if feedforward else np.zeros((2 * n + 1, n_joints))
        self._every = self._grid.every if self.integrator == "rk4" else 0  # the population kernel is RK4's
        self._population, self._jacobians = None, None
        self._n_steps = n
        if self._every:  # the motion's samples fall on steps: eq. 18 straight from the kernel's states
            z0, zd0, _ = motion(np.zeros(1))
            # the population kernel's arguments around the candidates' torques (see ``objectives``)
            self._kernel_start = (engine.state_from_joints(z0[0], zd0[0]), self.duration / n, n)
            self._kernel_rest = (self._grid.ref, self._grid.refd, self._every, np.ascontiguousarray(self.inverse.angles),
                                 penalty_weight)

    @property
    def n_params(self) -> int:
        return int(self.blocks[-1])

    @property
    def batched(self) -> bool:
        """True when ``objectives`` runs a population in one compiled call (the motion's samples
        on the integrator's grid); else it evaluates the candidates one by one."""
        return bool(self._every)

    def torques_on_grid_batch(self, P) -> np.ndarray:
        """The drive torques (N m) on the half-step grid for every row of P, shape
        (lam, n_params) -> (lam, 2 n + 1, J): each joint's population evaluator on its block, plus
        the inverse-dynamics torques with feedforward. Row c depends on P[c] alone, to the last bit."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        with np.errstate(all="ignore"):
            own = np.stack([f(P[:, a:b]) for f, a, b in zip(self._on_grid_batch, self.blocks[:-1], self.blocks[1:])],
                           axis=-1)
        return self._ff_half + own

    def torques_on_grid(self, p) -> np.ndarray:
        """The drive torques (N m) on the half-step grid for parameters p, shape (2 n + 1, J)."""
        return self.torques_on_grid_batch(np.asarray(p, dtype=float)[None])[0]

    def torque_function(self, p):
        """The drive torques for parameters p as a function t (s), shape (k,) -> (k, J) N m (the
        feedforward, if any, computed at t)."""
        p = np.asarray(p, dtype=float)

        def drive(t):
            t = np.asarray(t, dtype=float)
            own = np.stack([part.evaluate(p[a:b], t) for part, a, b in zip(self.parts, self.blocks[:-1], self.blocks[1:])],
                           axis=-1)
            return own + sim.inverse_dynamics(t, self._nominal, self.motion).torque if self.feedforward else own

        return drive

    def simulate(self, p) -> sim.Simulation:
        """The forward simulation of parameters p: RK4 on the torques of ``torques_on_grid``, or
        an adaptive integrator on ``torque_function``."""
        how = dict(dt=self.dt, integrator=self.integrator, rtol=self.rtol, atol=self.atol)
        if self.integrator != "rk4":
            return sim.simulate(self.torque_function(p), self.engine, self.motion, **how)
        tau = self.torques_on_grid(p)
        half = self._half
        return sim.simulate(lambda t: tau if t is half else _interp(half, tau, t), self.engine, self.motion, **how,
                            grid=self._grid)

    def rmse_deg(self, result: sim.Simulation) -> float:
        """Eq. 18's tracking term over the samples reached: the RMSE of the angles (deg), plus that of
        the translations (cm) for a model that has any (units never pooled)."""
        kinds = self._nominal.model.coordinate_kinds
        rot, trans, _ = sim.rmse_coordinates(result, self.inverse.angles, kinds)
        return rot + trans if "translation" in kinds else rot

    def objectives(self, P) -> np.ndarray:
        """Eq. 18 for every row of P, shape (lam, n_params) -> (lam,): the torque histories as array
        operations (``torques_on_grid_batch``), the simulations and their objectives in
        compiled calls spread over threads (``population.Population``). ``objective`` is this with a
        population of one, so the numbers equal those of the rows one by one, to the last bit,
        whatever the number of threads."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        if not self.batched:
            return np.array([self.objective(p) for p in P])
        if self._population is None:
            from .population import Population

            from .tracking import rk4_candidates

            self._population = Population(rk4_candidates, self._n_steps, self.engine.population_widths)
        tau = self.torques_on_grid_batch(P)
        args = self.engine.population_args(*self._kernel_start, tau, *self._kernel_rest)
        return self._population(len(P), args) + self._residual_costs(tau)

    def _residual_costs(self, tau) -> np.ndarray:
        """Eq. 18's residual term of the torque histories tau (lam, 2 n + 1, J) on the half-step grid
        (deg): the weight times the RMS of the floating base's force (FX, FY; N) plus that of its
        moment (MZ; N m) over the grid, the histories the parameters define (whether or not the
        simulation reaches their end). Zeros without a floating base or a weight."""
        if not self.residual_weight:
            return np.zeros(len(tau))
        c = self.base_column
        force = np.sqrt(np.mean(tau[:, :, c + 1] ** 2 + tau[:, :, c + 2] ** 2, axis=1))
        return self.residual_weight * (force + np.sqrt(np.mean(tau[:, :, c] ** 2, axis=1)))

    def residual_cost(self, p) -> float:
        return float(self._residual_costs(self.torques_on_grid(p)[None])[0])

    def _residual_gradient(self, tau, G, joint) -> np.ndarray:
        """d/dp of ``_residual_costs`` for one history tau (2 n + 1, J), G and joint as
        ``torque_jacobian`` gives them."""
        gradient = np.zeros(G.shape[1])
        if not self.residual_weight:
            return gradient
        c, rows = self.base_column, len(tau)
        force = math.sqrt(np.mean(tau[:, c + 1] ** 2 + tau[:, c + 2] ** 2))
        moment = math.sqrt(np.mean(tau[:, c] ** 2))
        for column, rms in ((c, moment), (c + 1, force), (c + 2, force)):
            if rms > 0:
                mine = joint == column
                gradient[mine] = self.residual_weight * (tau[:, column] @ G[:, mine]) / (rows * rms)
        return gradient

    def check_exact_gradient(self) -> None:
        """ValueError with a one-line message where exact gradients are not available: they need
        RK4 with the motion's samples on its grid and a parameterisation that gives d tau / d p."""
        if self.integrator != "rk4":
            raise ValueError(f"--gradient exact needs --integrator rk4, got {self.integrator}")
        if not self.batched:
            raise ValueError("--gradient exact needs motion samples on the RK4 grid (uniform, every k steps)")
        if self._jacobians is None:
            self._jacobians = [part.on_grid_jacobian(self._half) for part in self.parts]
        if any(jacobian is None for jacobian in self._jacobians):
            raise ValueError(f"--gradient exact: torque {self.parts[0].name!r} gives no d tau / d p")

    def torque_jacobian(self, p) -> tuple[np.ndarray, np.ndarray]:
        """(G, joint): d tau / d p on the half-step grid, shape (2 n + 1, n_params) (N m per
        parameter unit), parameter q moving the torque of joint joint[q] only (one block per joint)."""
        self.check_exact_gradient()
        p = np.asarray(p, dtype=float)
        with np.errstate(all="ignore"):
            G = np.concatenate([np.asarray(jacobian(p[a:b]), dtype=float).reshape(len(self._half), b - a)
                                for jacobian, a, b in zip(self._jacobians, self.blocks[:-1], self.blocks[1:])], axis=1)
        return np.ascontiguousarray(G), np.repeat(np.arange(len(self.parts)), np.diff(self.blocks))

    def value_and_gradient(self, p) -> tuple[float, np.ndarray]:
        """Eq. 18 and its exact gradient with respect to p, shape (n_params,), from one RK4
        simulation with forward sensitivities (``kernels.rk4_sensitivity``). The value equals
        ``objective(p)`` to the last bit (the same states and kernel). Over the m samples reached,
        eq. 18's tracking term is the RMSE of the angles (deg) plus, for a model with translations,
        that of the translations (cm); for each, with e its errors (m x J_kind, in its unit u per
        rad or m), d RMSE / d p = sum e u dz / dp / (m J_kind RMSE). The penalty term is piecewise
        constant in p (t_end moves by whole steps), so a failing simulation's gradient is the
        RMSE's over the samples reached (zero where an RMSE is zero). On a floating base the residual
        term (``_residual_costs``) and its gradient, which need no simulation, are added."""
        p = np.asarray(p, dtype=float)
        G, joint = self.torque_jacobian(p)
        engine = self.engine
        y0, dt, n, tau, ref, refd, every, angles_ref, weight, *layout, _ = engine.population_args(
            *self._kernel_start, self.torques_on_grid(p)[None], *self._kernel_rest)
        residual, residual_gradient = self._residual_costs(tau)[0], self._residual_gradient(tau[0], G, joint)
        states, rates = np.empty((n + 1, engine.n_state)), np.empty((n + 1, engine.n_state))
        applied, dz = np.empty((n + 1, engine.n_joints)), np.empty((n // every + 1, engine.n_joints, len(p)))
        from .multibody.kernels import rk4_sensitivity
        from .tracking import tracking_objective

        _, done = rk4_sensitivity(y0, dt, n, tau[0], ref, refd, G, joint, every, *layout, states, rates, applied, dz)
        value = tracking_objective(states, done, every, angles_ref, n, weight, engine.layout)
        return float(value + residual), tracking_gradient(engine, states, done, every, angles_ref, dz) + residual_gradient

    def value_and_gradient_scaled(self, x) -> tuple[float, np.ndarray]:
        """``value_and_gradient`` on the scaled parameters x = p / scale."""
        f, g = self.value_and_gradient(np.asarray(x, dtype=float) * self.scale)
        return f, g * self.scale


def tracking_gradient(engine, states, done: int, every: int, angles_ref, dz) -> np.ndarray:
    """d/dp of eq. 18's tracking term, shape (P,), from a simulation's states (n + 1, width) reached
    up to step ``done`` and the coordinates' derivatives dz (samples, J, P) at its samples (every
    ``every``-th step; desired coordinates angles_ref (samples, J)): over the m samples reached, for
    the angles (deg) and, on a model with translations, the translations (cm), each with e its errors
    (m x J_kind, in its unit u per rad or m), d RMSE / d p = sum e u dz / dp / (m J_kind RMSE)
    (zero where an RMSE is zero or not finite)."""
    m = done // every + 1
    error = engine.joints_from_state(states[: done + 1 : every, :engine.n_state])[0] - angles_ref[:m]
    gradient = np.zeros(dz.shape[2])
    translation = np.array([kind == "translation" for kind in engine.model.coordinate_kinds])
    for columns, unit in ((~translation, np.degrees(1.0)), (translation, sim.CM_PER_M)):
        if not columns.any():
            continue
        scaled = unit * error[:, columns]
        rmse = float(np.sqrt(np.mean(scaled**2)))
        if not (math.isfinite(rmse) and rmse > 0):
            continue
        with np.errstate(all="ignore"):
            part = unit * np.einsum("kj,kjq->q", scaled, dz[:m][:, columns]) / (scaled.size * rmse)
        if np.all(np.isfinite(part)):
            gradient += part
    return gradient


def _interp(grid, values, t):
    return np.stack([np.interp(t, grid, values[:, j]) for j in range(values.shape[1])], axis=-1)
