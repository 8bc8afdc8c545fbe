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


class ShootingProblem:
    """Eq. 18 of a shooting problem, whatever the model: a subclass gives ``simulate(p)``,
    ``rmse_deg(result)`` (the RMSE of rotation over the samples reached, deg), ``objectives(P)``,
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
        return self.objective_of(self.simulate(p))

    def objective_scaled(self, x) -> float:
        return self.objective(np.asarray(x) * self.scale)

    def objectives_scaled(self, X) -> np.ndarray:
        return self.objectives(np.atleast_2d(np.asarray(X, dtype=float)) * self.scale)


class TrackingProblem(ShootingProblem):
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
            self._half = half
            self._on_grid_batch = torque.on_grid_batch(half)
            self._ff_half = np.array(self._ff(half)) if feedforward else None
            self._fast = settings.motion.uniform and n % (len(self.inverse.t) - 1) == 0
            if self._fast:  # the motion's samples fall on steps: eq. 18 straight from the kernel's states
                self._n, self._every = n, n // (len(self.inverse.t) - 1)
                self._theta_ref = np.ascontiguousarray(self.inverse.theta, dtype=float)
                self._buffers = (np.empty((n + 1, 6)), np.empty((n + 1, 3)), np.empty(n + 1))
                _, ref_th, ref_w = half_step_reference(n, settings.kinematics)
                # the population kernel's arguments before the torques (see ``population.rk4_candidates``)
                self._kernel_start = (initial_state(settings.kinematics, settings.model), self.duration / n, n)
                self._kernel_rest = (ref_th, ref_w, constants(settings), self._every, self._theta_ref)

    def torque_jacobian(self):
        """The evaluator p -> d tau / d p on the RK4 half-step grid, shape (2 n + 1, n_params)
        (N m per parameter unit), for exact gradients; None where the parameterisation (or the
        integrator) gives none. Made on first use."""
        if self._jacobian is None:
            grid = self.settings.integrator == "rk4"
            self._jacobian = (self.torque.on_grid_jacobian(self._half) if grid else None,)
        return self._jacobian[0]

    @property
    def n_params(self) -> int:
        return self.torque.n_params

    def torque_function(self, p):
        """The open-loop drive torque for parameters p, as a function of time (s) -> N m."""
        if self.feedforward:
            return lambda t: self._ff(t) + self.torque.evaluate(p, t)
        return lambda t: self.torque.evaluate(p, t)

    def torques_on_grid(self, P) -> np.ndarray:
        """The drive torques (N m) on the RK4 half-step grid for every row of P, shape
        (lam, n_params) -> (lam, 2 n + 1): the parameterisation's population evaluator, plus the
        inverse-dynamics torque with feedforward. Row c depends on P[c] alone, to the last bit."""
        with np.errstate(all="ignore"):
            tau = self._on_grid_batch(np.atleast_2d(np.asarray(P, dtype=float)))
            if self._ff_half is not None:
                tau += self._ff_half
        return tau

    def simulate(self, p) -> SimulationResult:
        p = np.asarray(p, dtype=float)
        if self.settings.integrator == "rk4":
            return simulate_rk4_on_grid(self.torques_on_grid(p[None])[0], self.settings)
        return simulate(self.torque_function(p), self.settings)

    def rmse_deg(self, result: SimulationResult) -> float:
        """RMSE of rotation (deg) against the reference, over the samples reached."""
        return rmse_rot_deg(result, self.inverse.theta)

    @property
    def batched(self) -> bool:
        """True when ``objectives`` runs a population in one compiled call (RK4 on the samples'
        grid); else it evaluates the candidates one by one."""
        return self._fast

    def objectives(self, P) -> np.ndarray:
        """Eq. 18 for every row of P, shape (lam, n_params) -> (lam,): the torque histories as array
        operations (``torques_on_grid``), the simulations and their objectives in one compiled call
        spread over threads (``population.Population``). ``objective`` is this with a
        population of one, so the numbers equal those of the rows one by one, to the last bit."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        if not self._fast:
            return np.array([self.objective(p) for p in P])
        if self._population is None:
            from .population import Population, rk4_candidates

            self._population = Population(rk4_candidates, self._n)
        tau = self.torques_on_grid(P)
        return self._population(len(P), (*self._kernel_start, tau, *self._kernel_rest, self.penalty_weight))

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
