"""The tracking problem of section 4: parameters -> torque history -> forward simulation ->
objective f*(p) = RMSE_rot_deg(p) + w_penal (1 - t_end / T)  (eq. 18; T = 1 s in the paper, the
motion's duration in general: the penalty is the fraction of the motion not reached)."""

from __future__ import annotations

import math

import numpy as np

from .indicators import rmse_rot_deg, rmse_torque_nm
from .integrate import (Settings, SimulationResult, constants, half_step_reference, initial_state, simulate,
                        simulate_rk4_on_grid, steps)
from .inverse import Feedforward, inverse_dynamics
from .torques import TorqueParameterisation


class TrackingProblem:
    """Optimise the parameters of ``torque`` so the simulated rotation tracks the desired one.

    With ``feedforward`` the parameterised torque is added to the inverse-dynamics torque
    (eq. 19); without, it is the whole drive torque (eq. 15). Optimisers work on scaled
    parameters x = p / scale (``x0``, ``objective_scaled``), which puts every parameter on a
    comparable footing."""

    def __init__(self, torque: TorqueParameterisation, settings: Settings = Settings(),
                 feedforward: bool = False, penalty_weight: float = 1.0):
        if not (math.isfinite(penalty_weight) and penalty_weight >= 0):
            raise ValueError(f"penalty weight must be a non-negative finite number, got {penalty_weight}")
        self.torque, self.settings = torque, settings
        self.feedforward, self.penalty_weight = feedforward, penalty_weight
        self.inverse = inverse_dynamics(None, settings.nominal_model, settings.kinematics)
        self._ff = Feedforward(settings.nominal_model, settings.kinematics)
        self.duration = settings.motion.duration
        self.p0 = np.asarray(torque.prepare(self.inverse.t, self.inverse.torque, feedforward), dtype=float)
        self.scale = np.asarray(torque.scale(), dtype=float)
        self.x0 = self.p0 / self.scale
        self._fast = False
        self._jacobian, self._dtheta, self._population = None, None, None
        if settings.integrator == "rk4":
            n = steps(settings.dt, self.duration)
            half, _, _ = half_step_reference(n, settings.kinematics)
            self._on_grid = torque.on_grid(half)
            self._jacobian = torque.on_grid_jacobian(half)  # d tau / d p for exact gradients, or None
            self._ff_half = np.array(self._ff(half)) if feedforward else np.zeros_like(half)
            self._fast = settings.motion.uniform and n % (len(self.inverse.t) - 1) == 0
            if self._fast:  # buffers for the kernel, reused by every evaluation
                self._n, self._every = n, n // (len(self.inverse.t) - 1)
                self._buffers = (np.empty((n + 1, 6)), np.empty((n + 1, 3)), np.empty(n + 1))

    @property
    def n_params(self) -> int:
        return self.torque.n_params

    def torque_function(self, p):
        """The open-loop drive torque for parameters p, as a function of time (s) -> N m."""
        if self.feedforward:
            return lambda t: self._ff(t) + self.torque.evaluate(p, t)
        return lambda t: self.torque.evaluate(p, t)

    def simulate(self, p) -> SimulationResult:
        p = np.asarray(p, dtype=float)
        if self.settings.integrator == "rk4":
            with np.errstate(all="ignore"):
                tau = self._ff_half + self._on_grid(p)
            return simulate_rk4_on_grid(tau, self.settings)
        return simulate(self.torque_function(p), self.settings)

    def objective_of(self, result: SimulationResult) -> float:
        """Eq. 18 for a finished simulation."""
        rmse = rmse_rot_deg(result, self.inverse.theta)
        if not math.isfinite(rmse):
            rmse = 0.0  # nothing reached beyond t = 0: the penalty term says it all
        return rmse + self.penalty_weight * (1.0 - result.t_end / self.duration)

    def objective(self, p) -> float:
        if self._fast:
            return self._objective_on_samples(np.asarray(p, dtype=float))
        return self.objective_of(self.simulate(p))

    def _objective_on_samples(self, p) -> float:
        """Eq. 18 straight from the kernel's buffers (the same numbers as ``objective_of``
        of ``simulate``, without building a SimulationResult)."""
        from . import dynamics

        settings = self.settings
        _, ref_th, ref_w = half_step_reference(self._n, settings.kinematics)
        with np.errstate(all="ignore"):
            tau = self._ff_half + self._on_grid(p)
        states, qdd, applied = self._buffers
        _, done, _ = dynamics.rk4(initial_state(settings.kinematics, settings.model), self.duration / self._n, self._n,
                                  tau, ref_th, ref_w, 0.0, 0.0, constants(settings), states, qdd, applied)
        return self._objective_of_states(states, done)

    def _objective_of_states(self, states, done: int) -> float:
        """Eq. 18 from the kernel's states, shape (n+1, 6), filled up to step ``done``."""
        theta = states[: done + 1 : self._every, 2]
        error = np.degrees(theta - self.inverse.theta[: len(theta)])
        rmse = float(np.sqrt(np.mean(error**2)))
        if not math.isfinite(rmse):
            rmse = 0.0
        return rmse + self.penalty_weight * (1.0 - done / self._n)

    def objective_scaled(self, x) -> float:
        return self.objective(np.asarray(x) * self.scale)

    @property
    def batched(self) -> bool:
        """True when ``objectives`` runs a population in one compiled call (RK4 on the samples'
        grid); else it evaluates the candidates one by one."""
        return self._fast

    def objectives(self, P) -> np.ndarray:
        """Eq. 18 for every row of P, shape (lam, n_params) -> (lam,): the simulations in one
        parallel compiled call (``population.rk4_population``). Equal, to the last bit, to
        ``objective`` of each row."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        if not self._fast:
            return np.array([self.objective(p) for p in P])
        from .population import rk4_population

        settings, n = self.settings, self._n
        _, ref_th, ref_w = half_step_reference(n, settings.kinematics)
        lam = len(P)
        with np.errstate(all="ignore"):
            tau = np.empty((lam, 2 * n + 1))
            for c in range(lam):  # row by row: the same arithmetic as a single evaluation
                tau[c] = self._ff_half + self._on_grid(P[c])
        if self._population is None or self._population[0].shape[0] < lam:
            self._population = (np.empty((lam, n + 1, 6)), np.empty((lam, n + 1, 3)), np.empty((lam, n + 1)))
        states, qdd, applied = (buffer[:lam] for buffer in self._population)
        done = np.empty(lam, dtype=np.int64)
        rk4_population(initial_state(settings.kinematics, settings.model), self.duration / n, n, tau, ref_th, ref_w,
                       constants(settings), states, qdd, applied, done)
        return np.array([self._objective_of_states(states[c], int(done[c])) for c in range(lam)])

    def objectives_scaled(self, X) -> np.ndarray:
        return self.objectives(np.atleast_2d(np.asarray(X, dtype=float)) * self.scale)

    def value_and_gradient(self, p) -> tuple[float, np.ndarray]:
        """Eq. 18 and its exact gradient with respect to p, shape (n_params,) (see ``gradient``)."""
        from .gradient import value_and_gradient

        return value_and_gradient(self, np.asarray(p, dtype=float))

    def value_and_gradient_scaled(self, x) -> tuple[float, np.ndarray]:
        """``value_and_gradient`` on the scaled parameters x = p / scale."""
        f, g = self.value_and_gradient(np.asarray(x, dtype=float) * self.scale)
        return f, g * self.scale

    def indicators(self, result: SimulationResult) -> dict:
        return {
            "rmse_rot_deg": rmse_rot_deg(result, self.inverse.theta),
            "rmse_torque_nm": rmse_torque_nm(result, self.inverse.torque),
        }
