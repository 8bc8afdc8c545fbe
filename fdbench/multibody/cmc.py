"""Computed muscle control (Thelen, Anderson and Delp 2003; Thelen and Anderson 2006; OpenSim's
``CMCTool``) of a model with muscles along a desired motion, window by window, as OpenSim's
``CMC::computeControls`` does it.

At the start t of each control window of length T (the state there: coordinates q, rates q', the
muscles' activations and compliant tendons' forces), the muscles' forces are aimed at the window's
end, t_a = t + T, as OpenSim's CMC aims them (``AIM``). With h = t_a - t:

1. the task errors at t, e = q_d(t) - q, e' = q'_d(t) - q' (OpenSim's ``CMC_Joint``), and the
   state at t_a as OpenSim poses its model there: the motion plus those errors, q_a = q_d(t_a) - e,
   q'_a = q'_d(t_a) - e';
2. desired accelerations q''* = q''_d(t_a) + kd e' + kp e (kp 1/s^2, kd 1/s);
3. the generalised forces tau (N m) that give q''* at (q_a, q'_a): the nominal model's inverse
   dynamics;
4. static optimisation (p = 2: the exact active-set QP, ``static_optimization.box_qp``) for the
   muscles' controls c and the reserves (control r / rho, rho its optimal force,
   ``reserve_strengths``: the model's actuators as static optimisation takes them; a coordinate
   without one weighed as ``static_optimization.qp_reserve_forces`` weighs it, its torque left
   unmet, not applied): min sum c^2 + sum (r / rho)^2 subject to
   sum_m arm_mj (c_m G_m + P_m) + r_j = tau_j, the moment arms and G_m, P_m (muscle m's force along
   its path per unit activation and at zero activation, ``cmc_muscles.muscle_gains``) at q_a; c is
   the activation, or for a compliant tendon (a - 0.01) / 0.99: its explicit form acts as if the
   activation were at least ``muscle.MIN_ACTIVATION``. Each c is bounded by the forces the muscle
   can reach at t_a under the excitations 0 and 1 (``cmc_muscles.forces_after``), as OpenSim bounds
   them, so that what activation dynamics cannot deliver within the window falls to the reserves;
5. each muscle's constant excitation u in [0, 1] whose force at t_a is the one wanted, c G + P: the
   muscle's own activation and tendon dynamics integrated by the simulation's RK4 steps, its path
   moving from its length and speed at t with the constant acceleration that reaches its length at
   q_a (``cmc_muscles.excitations_for``, as OpenSim's CMC solves for the controls that give the
   optimal forces along the motion);
6. the plant simulated over the window by the compiled RK4 (``Engine.simulate``) with those
   excitations held and each reserve torque linear from its last window's value to its new one
   (OpenSim's muscles' controls are steps, its other actuators' linear between the windows' ends),
   the muscles' forces its own; the next window starts from its end state.

The run starts on the desired motion at t = 0 with static optimisation's activations and reserves
there, the compliant tendons settled: at the fibres' static equilibrium (``simulation.muscle_start``)
and static optimisation repeated with the forces per unit activation at those tendons' forces until
the activations stop moving (OpenSim's CMC settles its muscles' states before it starts).

On arm26's mid_range (compliant tendons, 5e-5 s RK4 steps) these steps took the angles' RMS error
from 0.41 deg to 0.04 deg: the reachable bounds alone to 0.23 (BIClong saturates from 0.63 s and
the muscles' forces fell short of what static optimisation assumed), with the paths' acceleration
to 0.17, with the ramped reserves (a reserve held at its t_a value over the whole window leads the
muscles by half a window) to 0.056, with the settled start (its first window's torque no longer
kicks the arm) to 0.050, with OpenSim's errors at t to 0.038.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .cmc_muscles import excitations_for, forces_after, muscle_gains
from .engine import Engine
from .muscle import L_OPT, L_SLACK, MIN_ACTIVATION
from .muscle_paths import muscle_geometry
from .simulation import STATUS_OF_CODE, HalfSteps, Simulation, _on_samples, half_steps, muscle_forces, muscle_start
from .actuators import optimal_forces
from .static_optimization import box_qp, muscle_capacity, qp_reserve_forces, solve_sample

# OpenSim's CMC examples' task gains (CMC_Joint kp, kv: critically damped, natural frequency 10 rad/s)
# and default time window
START_ROUNDS = 20  # static optimisation's rounds at most with the compliant tendons settled at the start
AIM = 1.0  # the share of a window after which its forces are aimed (RK4 steps rounded, at least one)
DEFAULT_KP, DEFAULT_KD, DEFAULT_WINDOW = 100.0, 20.0, 0.01  # 1/s^2, 1/s, s


@dataclass
class ComputedMuscleControl:
    """A CMC run: ``simulation`` (on the motion's samples, with each muscle's activation, excitation
    and force, the applied torques the reserves plus the muscles' generalised forces), per window its
    start time ``window_t`` (s, (w,)), length ``window_s`` (s, (w,)), reserve torques ``reserve``
    (N m, (w, J); 0 on a coordinate without a reserve), the torque the muscles left unmet there
    (``unmet``, N m, (w, J); 0 elsewhere) and excitations (w, M); the reserves and excitations held
    on the motion's samples (``reserve_on_samples`` (n, J)); the windows run (``windows_done``)."""

    simulation: Simulation
    window_t: np.ndarray
    window_s: np.ndarray
    reserve: np.ndarray
    excitation: np.ndarray
    reserve_on_samples: np.ndarray
    windows_done: int
    window: float
    unmet: np.ndarray

    def reserve_rms(self) -> np.ndarray:
        """Each reserve's RMS torque over the windows run, weighted by their lengths (N m, (J,))."""
        return self._rms(self.reserve)

    def unmet_rms(self) -> np.ndarray:
        """Each coordinate's RMS torque left unmet over the windows run (N m, (J,))."""
        return self._rms(self.unmet)

    def _rms(self, per_window: np.ndarray) -> np.ndarray:
        w = self.windows_done
        if not w:
            return np.full(per_window.shape[1], np.nan)
        weights = self.window_s[:w] / self.window_s[:w].sum()
        return np.sqrt(weights @ per_window[:w] ** 2)


def reserve_strengths(model, optimal_force: float | None = None) -> np.ndarray:
    """The reserves' optimal forces rho (N m per unit control; N for a translation) per coordinate of
    ``model``, shape (J,), 0 where a coordinate has none: its actuators' (``optimal_force`` for every
    one of them if given), a model without actuators one per coordinate of ``optimal_force``
    (default 1). ValueError for a value that is not finite and > 0."""
    if optimal_force is not None and not (math.isfinite(optimal_force) and optimal_force > 0):
        raise ValueError(f"the reserves' optimal force must be a finite number > 0, not {optimal_force:g}")
    return np.array(optimal_forces(model, optimal_force), dtype=float)


def check_window(window: float, duration: float, step: float) -> None:
    """ValueError (one line) for a control window (s) that is not positive, is longer than the motion
    (``duration`` s) or shorter than one RK4 step (``step`` s)."""
    if not (math.isfinite(window) and window > 0):
        raise ValueError(f"--window must be a positive number of seconds, not {window:g}")
    if window > duration + 1e-12:
        raise ValueError(f"--window {window:g} s is longer than the motion ({duration:g} s)")
    if window < step * (1 - 1e-9):
        raise ValueError(f"--window {window:g} s is shorter than one RK4 step (--dt {step:g} s)")


def computed_muscle_control(plant: Engine, motion, kp: float = DEFAULT_KP, kd: float = DEFAULT_KD,
                            window: float = DEFAULT_WINDOW, reserve_optimal_force: float | None = None,
                            dt: float = 1e-3,
                            nominal: Engine | None = None, grid: HalfSteps | None = None) -> ComputedMuscleControl:
    """CMC of ``plant`` (an Engine of a model with muscles) along ``motion`` (``simulation``'s motion)
    with the task gains kp (1/s^2) and kd (1/s), control windows of ``window`` s (a whole number of
    RK4 steps of about ``dt`` s: the nearest, at least one; the last window ends with the motion),
    the reserves of ``reserve_strengths(model, reserve_optimal_force)``. ``nominal``: the believed model
    (inverse dynamics, muscle paths and capacities; None: the plant). ``grid``: the motion's
    ``HalfSteps`` for dt (made here if None). ValueError for bad settings."""
    nominal = plant if nominal is None else nominal
    if not plant.n_muscles or nominal.n_muscles != plant.n_muscles:
        raise ValueError(f"computed muscle control needs a model with muscles; {plant.model.name!r} has none")
    for name, gain in (("kp", kp), ("kd", kd)):
        if not (math.isfinite(gain) and gain >= 0):
            raise ValueError(f"{name} must be a non-negative finite number, got {gain}")
    grid = half_steps(motion, dt) if grid is None else grid
    check_window(window, motion.duration, grid.step)
    rho = reserve_strengths(nominal.model, reserve_optimal_force)
    began = time.perf_counter()
    per_window = max(1, int(round(window / grid.step)))
    bounds = list(range(0, grid.n, per_window)) + [grid.n]
    n_windows, J, M, S = len(bounds) - 1, plant.n_joints, plant.n_muscles, plant.n_state
    states, rates = (np.full((grid.n + 1, S + plant.n_muscle_states), np.nan) for _ in range(2))
    applied = np.full((grid.n + 1, J), np.nan)
    reserve, excitation = np.full((n_windows, J), np.nan), np.full((n_windows, M), np.nan)
    unmet = np.full((n_windows, J), np.nan)
    floor = np.where(nominal.tendon_row >= 0, MIN_ACTIVATION, 0.0)  # the activation a muscle acts at, at least
    y, control, start_reserve = _start(plant, nominal, grid, rho, floor)
    last, aims, u = start_reserve, np.full(n_windows, np.nan), y[S:S + M].copy()
    code, done, worst, windows_done, zeros, ramps = 0, 0, 0.0, 0, {}, {}
    for w in range(n_windows):
        i0, i1 = bounds[w], bounds[w + 1]
        n = i1 - i0
        k = i0 + max(1, int(round(AIM * n)))  # the step the forces are aimed at
        h, aims[w] = grid.t_steps[k] - grid.t_steps[i0], grid.t_steps[k]
        z, zd = plant.joints_from_state(y[:S])
        # the errors at t; the state at t_a as OpenSim's CMC poses its model there: the motion plus those errors
        error, rate_error = grid.ref[2 * i0] - z, grid.refd[2 * i0] - zd
        z_aim, zd_aim = grid.ref[2 * k] - error, grid.refd[2 * k] - rate_error
        wanted = grid.refdd[2 * k] + kd * rate_error + kp * error
        tau = nominal.inverse_torques(z_aim, zd_aim, wanted, grid.t_steps[k])
        lengths, arms = muscle_geometry(nominal.model, z_aim, nominal.muscle_paths)
        gain, passive = muscle_gains(y[S:], lengths, -arms @ zd_aim, nominal.muscle_params, nominal.tendon_row)
        passive, gain = passive + floor * gain, gain * (1.0 - floor)
        moment_gain = arms.T * gain  # (J, M): N m per unit control
        need = tau - arms.T @ passive
        # the paths from t to t_a: lengths (m), speeds (m/s) and the constant acceleration (m/s^2) reaching
        # the predicted state's lengths
        now, arms_now = muscle_geometry(nominal.model, z, nominal.muscle_paths)
        speed = -arms_now @ zd
        speeding = 2.0 * (lengths - now - speed * h) / (h * h)
        reach = [forces_after(e, y[S:], now, speed, speeding, grid.step, k - i0, plant.muscle_params,
                              plant.tendon_row) for e in (0.0, 1.0)]
        low, high = _reachable_controls(reach, gain, passive)
        control = _bounded_controls(moment_gain, need, qp_reserve_forces(rho, moment_gain), low, high, control)
        left = need - moment_gain @ control
        reserve[w], unmet[w] = np.where(rho > 0, left, 0.0), np.where(rho > 0, 0.0, left)
        u = excitation[w] = excitations_for(gain * control + passive, u, y[S:], now, speed, speeding, grid.step,
                                            k - i0, plant.muscle_params, plant.tendon_row)
        if n not in ramps:  # each reserve linear from its last window's value to its new one at t_a
            ramps[n] = np.minimum(np.linspace(0.0, n / (k - i0), 2 * n + 1), 1.0)[:, None]
            zeros[n] = np.zeros((2 * n + 1, J))
        result = plant.simulate(y, grid.step, n, last + ramps[n] * (reserve[w] - last), zeros[n], zeros[n],
                                zeros[n], 0.0, 0.0, excitation_half=np.broadcast_to(u, (2 * n + 1, M)),
                                t0=grid.t_steps[i0])
        reached = slice(i0, i0 + result.steps_done + 1)
        for whole, part in ((states, result.states), (rates, result.rates), (applied, result.applied)):
            whole[reached] = part[:result.steps_done + 1]
        worst, done, code, windows_done = max(worst, result.max_violation), i0 + result.steps_done, result.status, w + 1
        if code != 0:
            break
        y, last = result.states[-1], reserve[w]
    simulation = _on_motion_samples(plant, motion, grid, states, rates, applied, done, code, worst)
    window_t = grid.t_steps[bounds[:-1]]
    held = np.clip(np.searchsorted(window_t, motion.samples, side="right") - 1, 0, n_windows - 1)
    simulation.excitation = excitation[held]
    nodes = np.concatenate([[0.0], aims[:windows_done]])  # the reserves' ramps' ends
    values = np.vstack([start_reserve, reserve[:windows_done]])
    reserve_on_samples = np.column_stack([np.interp(motion.samples, nodes, values[:, j]) for j in range(J)])
    simulation.excitation[~simulation.reached], reserve_on_samples[~simulation.reached] = np.nan, np.nan
    simulation.runtime_s = time.perf_counter() - began
    return ComputedMuscleControl(simulation, window_t, np.diff(grid.t_steps[bounds]), reserve, excitation,
                                 reserve_on_samples, windows_done, per_window * grid.step, unmet)


def _start_activations(nominal: Engine, grid: HalfSteps, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The activations (M,) and reserve torques (N m, (J,); 0 where a coordinate has none) of static
    optimisation on the desired motion at t = 0 (rigid tendons)."""
    z, zd, zdd = grid.ref[0], grid.refd[0], grid.refdd[0]
    tau = nominal.inverse_torques(z, zd, zdd, 0.0)
    lengths, arms = muscle_geometry(nominal.model, z, nominal.muscle_paths)
    active, passive = muscle_capacity(nominal.muscle_params, lengths[None], (-arms @ zd)[None])
    gain = arms.T * active[0]
    need = tau - arms.T @ passive[0]
    activation = solve_sample(gain, need, qp_reserve_forces(rho, gain), 2.0)
    return activation, np.where(rho > 0, need - gain @ activation, 0.0)


def _start(plant: Engine, nominal: Engine, grid: HalfSteps, rho: np.ndarray, floor: np.ndarray,
           rounds: int = START_ROUNDS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The run's start on the desired motion at t = 0: the state (mechanical and muscles',
    (n_state + n_muscle_states,)), the controls (M,) and the reserve torques (N m, (J,)) of static
    optimisation there, settled with the compliant tendons (as OpenSim's CMC settles its muscles'
    states before it starts): from rigid tendons' activations, the tendons at the fibres' static
    equilibrium (``simulation.muscle_start``), static optimisation again with the forces per unit
    activation at those tendons' forces, ``rounds`` times at most (until the activations move less
    than 1e-12)."""
    activation, reserve = _start_activations(nominal, grid, rho)
    mechanical, S = plant.state_from_joints(grid.ref[0], grid.refd[0]), plant.n_state
    y = np.concatenate([mechanical, muscle_start(plant, mechanical, activation)])
    control = np.clip((activation - floor) / (1.0 - floor), 0.0, 1.0)
    if not (nominal.tendon_row >= 0).any():
        return y, control, reserve
    z, zd = grid.ref[0], grid.refd[0]
    tau = nominal.inverse_torques(z, zd, grid.refdd[0], 0.0)
    lengths, arms = muscle_geometry(nominal.model, z, nominal.muscle_paths)
    for _ in range(rounds):
        gain, passive = muscle_gains(y[S:], lengths, -arms @ zd, nominal.muscle_params, nominal.tendon_row)
        passive, gain = passive + floor * gain, gain * (1.0 - floor)
        moment_gain, need = arms.T * gain, tau - arms.T @ passive
        control = solve_sample(moment_gain, need, qp_reserve_forces(rho, moment_gain), 2.0, control)
        reserve = np.where(rho > 0, need - moment_gain @ control, 0.0)
        moved, activation = np.abs(floor + (1.0 - floor) * control - activation).max(), floor + (1.0 - floor) * control
        y = np.concatenate([mechanical, muscle_start(plant, mechanical, activation)])
        if moved < 1e-12:
            break
    return y, control, reserve


def _reachable_controls(reach: list, gain: np.ndarray, passive: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The controls (M,) in [0, 1] whose forces c gain + passive (N) are the least and the most a
    window can reach, ``reach`` (N, the forces at its end under excitations 0 and 1, (M,) each)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        low, high = ((np.where(gain > 0, (f - passive) / gain, 0.0)) for f in reach)
    low = np.clip(low, 0.0, 1.0)
    return low, np.clip(high, low, 1.0)


def _bounded_controls(gain: np.ndarray, need: np.ndarray, reserve_force: np.ndarray, low: np.ndarray,
                      high: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Static optimisation's controls c (M,) with low <= c <= high: min sum c^2 + sum ((need - gain c) /
    reserve_force)^2 (``gain`` (J, M) N m per unit control, ``need`` and ``reserve_force`` (J,)), as
    OpenSim's CMC bounds each muscle's force by those its controls can reach within the window; c =
    low + (high - low) x with x in [0, 1] for ``box_qp``, a muscle with no range held at low."""
    control, free = low.copy(), high - low > 1e-9
    if not free.any():
        return control
    scaled, rest = gain / reserve_force[:, None], (need - gain @ low) / reserve_force
    span = (high - low)[free]
    part = scaled[:, free] * span
    hessian = np.diag(span * span) + part.T @ part
    linear = part.T @ rest - span * low[free]
    x = box_qp(hessian, linear, np.clip((start[free] - low[free]) / span, 0.0, 1.0))
    control[free] = low[free] + span * x
    return control


def _on_motion_samples(plant: Engine, motion, grid: HalfSteps, states, rates, applied, done: int, code: int,
                       worst: float) -> Simulation:
    """The run's Simulation on the motion's samples, the muscles' activations and forces included."""
    y, torque = _on_samples(grid.t_steps, grid.every, states, rates, applied, done, motion.samples)
    z, zd = plant.joints_from_state(y[:, :plant.n_state])
    result = Simulation(motion.samples, z, zd, y[:, :plant.n_state], torque, done * motion.duration / grid.n,
                        STATUS_OF_CODE[code], worst)
    result.activation = y[:, plant.n_state:plant.n_state + plant.n_muscles]
    result.muscle_force = muscle_forces(plant, z, zd, y[:, plant.n_state:])
    return result


def warm_up(engine: Engine) -> None:
    """Load (or compile) CMC's compiled parts for ``engine``'s muscles, so that a run's time excludes it."""
    if not engine.n_muscles:
        return
    p, rows = engine.muscle_params, engine.tendon_row
    states = np.full(engine.n_muscle_states, 0.1)
    lengths = p[:, L_OPT] + p[:, L_SLACK]  # m
    gain, passive = muscle_gains(states, lengths, np.zeros(engine.n_muscles), p, rows)
    still = np.zeros(engine.n_muscles)
    excitations_for(gain * 0.1 + passive, np.full(engine.n_muscles, 0.1), states, lengths, still, still, 1e-4, 2, p,
                    rows)
    forces_after(0.0, states, lengths, still, still, 1e-4, 2, p, rows)
