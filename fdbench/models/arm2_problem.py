"""The tracking problem of section 4 on the two-segment arm: one block of torque parameters per
joint (each joint its own instance of the parameterisation, prepared on that joint's
inverse-dynamics torque), the blocks concatenated into one parameter vector, and

    f*(p) = RMSE_rot_deg(p) + w_penal (1 - t_end / T)

with RMSE_rot_deg over both joints and all samples reached (eq. 18 for n joints). Optimisers see
one objective of scaled parameters x = p / scale and work unchanged; budgets keep their meaning
(one evaluation, one forward simulation).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..model import Penalty
from ..problem import ShootingProblem
from .arm2 import JOINTS, Arm2
from .arm2_motion import JointMotion, as_joint_motion
from . import arm2_sim as sim


class ArmTrackingProblem(ShootingProblem):
    """Optimise per-joint torque parameters so that the simulated arm tracks ``motion``.

    ``torque``: a registered parameterisation's name, made once per joint with ``options``.
    With ``feedforward`` the parameterised torques are added to the inverse-dynamics torques
    (eq. 19); without, they are the whole drive torques (eq. 15). ``model`` is the simulated body;
    ``nominal`` (default: the same) the model whose inverse dynamics prepare the parameters, give
    the feedforward and the objective's reference. ``penalty``, ``dt``, ``integrator``, ``rtol``
    and ``atol`` say how to simulate (``arm2_sim.simulate``): with rk4 the torques are computed
    on its half-step grid at once, with an adaptive integrator at the times it asks for."""

    def __init__(self, torque: str, model: Arm2 = Arm2(), motion: str | JointMotion = "reach",
                 feedforward: bool = False, penalty_weight: float = 1.0, penalty: Penalty = Penalty(),
                 dt: float = 1e-3, nominal: Arm2 | None = None, integrator: str = "rk4", rtol: float = 1e-6,
                 atol: float = 1e-9, **options):
        from ..integrate import check_integrator, steps
        from ..torques import make_torque

        if not (math.isfinite(penalty_weight) and penalty_weight >= 0):
            raise ValueError(f"penalty weight must be a non-negative finite number, got {penalty_weight}")
        self.model, self.motion, self.penalty, self.dt = model, as_joint_motion(motion), penalty, dt
        self.integrator, self.rtol, self.atol = check_integrator(integrator), rtol, atol
        self.feedforward, self.penalty_weight = feedforward, penalty_weight
        nominal = model if nominal is None else nominal
        self._nominal = nominal
        self.inverse = sim.inverse_dynamics(None, nominal, self.motion)
        self.duration = self.motion.duration
        self.parts = [make_torque(torque, **options) for _ in JOINTS]
        p0 = [np.asarray(part.prepare(self.inverse.t, self.inverse.torque[:, j], feedforward), dtype=float)
              for j, part in enumerate(self.parts)]
        self.blocks = np.cumsum([0] + [len(p) for p in p0])
        self.p0 = np.concatenate(p0)
        self.scale = np.concatenate([np.asarray(part.scale(), dtype=float) for part in self.parts])
        self.x0 = self.p0 / self.scale
        n = steps(dt, self.duration)
        self._half = np.linspace(0.0, self.duration, 2 * n + 1)
        self._on_grid_batch = [part.on_grid_batch(self._half) for part in self.parts]
        self._ff_half = (np.array(sim.inverse_dynamics(self._half, nominal, self.motion).torque) if feedforward
                         else np.zeros((2 * n + 1, len(JOINTS))))
        self._every = (sim.samples_on_grid(np.linspace(0.0, self.duration, n + 1), self.motion.samples)
                       if self.integrator == "rk4" else 0)  # the population kernel is RK4's
        self._population = None
        if self._every:  # the motion's samples fall on steps: eq. 18 straight from the kernel's states
            from . import arm2_kernels as kernels

            references = (np.ascontiguousarray(r, dtype=float) for r in self.motion(self._half))
            # the population kernel's arguments before and after the torques (see ``objectives``)
            self._kernel_start = (sim.initial_state(model, self.motion), self.duration / n, n)
            self._kernel_rest = (*references, kernels.kernel_constants(model, penalty), self._every,
                                 np.ascontiguousarray(self.inverse.angles, dtype=float))

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
        (lam, n_params) -> (lam, 2 n + 1, 2): each joint's population evaluator on its block, plus
        the inverse-dynamics torques with feedforward. Row c depends on P[c] alone, to the last bit."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        with np.errstate(all="ignore"):
            own = np.stack([f(P[:, a:b]) for f, a, b in zip(self._on_grid_batch, self.blocks[:-1], self.blocks[1:])],
                           axis=-1)
        return self._ff_half + own

    def torques_on_grid(self, p) -> np.ndarray:
        """The drive torques (N m) on the half-step grid for parameters p, shape (2 n + 1, 2)
        (``torques_on_grid_batch`` of a population of one)."""
        return self.torques_on_grid_batch(np.asarray(p, dtype=float)[None])[0]

    def torque_function(self, p):
        """The drive torques for parameters p as a function t (s), shape (k,) -> (k, 2) N m (the
        feedforward, if any, computed at t)."""
        p = np.asarray(p, dtype=float)

        def drive(t):
            t = np.asarray(t, dtype=float)
            own = np.stack([part.evaluate(p[a:b], t) for part, a, b in zip(self.parts, self.blocks[:-1], self.blocks[1:])],
                           axis=-1)
            return own + sim.inverse_dynamics(t, self._nominal, self.motion).torque if self.feedforward else own

        return drive

    def simulate(self, p) -> sim.ArmSimulation:
        """The forward simulation of parameters p: RK4 on the torques of ``torques_on_grid``, or
        an adaptive integrator on ``torque_function``."""
        how = dict(penalty=self.penalty, dt=self.dt, integrator=self.integrator, rtol=self.rtol, atol=self.atol)
        if self.integrator != "rk4":
            return sim.simulate(self.torque_function(p), self.model, self.motion, **how)
        tau = self.torques_on_grid(p)
        half = self._half
        return sim.simulate(lambda t: tau if t is half else _interp(half, tau, t), self.model, self.motion, **how)

    def rmse_deg(self, result: sim.ArmSimulation) -> float:
        """RMSE of the joint angles (deg) over both joints and the samples reached."""
        return sim.rmse_deg(result, self.inverse.angles)[0]

    def objectives(self, P) -> np.ndarray:
        """Eq. 18 for every row of P, shape (lam, n_params) -> (lam,): the torque histories as array
        operations (``torques_on_grid_batch``), the simulations and their objectives in one
        compiled call spread over threads (``arm2_kernels.rk4_candidates`` via
        ``population.Population``). ``objective`` is this with a population of one, so the numbers
        equal those of the rows one by one, to the last bit, whatever the number of threads."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        if not self.batched:
            return np.array([self.objective(p) for p in P])
        if self._population is None:
            from ..population import Population
            from .arm2_kernels import N_STATE, rk4_candidates

            self._population = Population(rk4_candidates, self._kernel_start[2], ((N_STATE,), (6,), (2,)))
        tau = self.torques_on_grid_batch(P)
        return self._population(len(P), (*self._kernel_start, tau, *self._kernel_rest, self.penalty_weight))



def warm_up() -> None:
    """Load (or compile) the population kernel and start the threads, so that later timings
    exclude both: a population of two candidates of two steps."""
    from ..population import Population
    from . import arm2_kernels as kernels

    arm, motion, n = Arm2(), as_joint_motion("reach"), 2
    grid = np.zeros((2 * n + 1, 2))
    Population(kernels.rk4_candidates, n, ((kernels.N_STATE,), (6,), (2,)))(
        2, (sim.initial_state(arm, motion), 0.5, n, np.zeros((2, 2 * n + 1, 2)), grid, grid, grid,
            kernels.kernel_constants(arm, Penalty()), 1, np.zeros((n + 1, 2)), 1.0))


def _interp(grid, values, t):
    return np.stack([np.interp(t, grid, values[:, j]) for j in range(values.shape[1])], axis=-1)


def optimize(problem: ArmTrackingProblem, optimizer: str = "cmaes", budget: int = 200, seed: int = 0,
             on_evaluation=None, **options):
    """Minimise the problem's objective with a registered optimiser within ``budget`` forward
    simulations (``on_evaluation(count, best)`` after each); returns (the best parameters p, the
    OptimizationResult, the final simulation, runtime in s)."""
    from ..optimizers import make_optimizer

    began = time.perf_counter()
    batch = problem.objectives_scaled if problem.batched else None
    found = make_optimizer(optimizer, **options).minimize(problem.objective_scaled, problem.x0, budget, seed,
                                                          on_evaluation, batch=batch)
    p = np.asarray(found.x) * problem.scale
    result = problem.simulate(p)
    return p, found, result, time.perf_counter() - began
