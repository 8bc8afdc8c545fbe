"""Static optimisation as OpenSim's StaticOptimization analysis does it (``use_model_force_set`` and
``use_muscle_physiology`` true): at each sample of a motion, the muscle activations a (M,) in [0, 1]
and one reserve actuator per coordinate, r (J,) in (-inf, inf), that minimise
sum |a_m|^p + sum |r_j|^p (OpenSim's ``StaticOptimizationTarget``: every actuator's control to the
activation exponent p) subject to the inverse dynamics

    sum_m arm_mj (a_m F_active_m + F_passive_m) + rho_j r_j = tau_j,

arm = -dl/dq (m), rho_j the reserve's optimal force (N m per unit control). A muscle's force along
its path is OpenSim's ``calcInextensibleTendonActiveFiberForce``: a rigid tendon at the motion's
muscle-tendon length and lengthening speed, F0 (a f_L f_V + f_PE + d v) cos(alpha) (De Groote and
Fregly's curves, ``fdbench.multibody.muscle``) whatever the model's tendon.

The reserves are unbounded, so r = (tau - arm (a F_act + F_pas)) / rho and each sample is a problem
in a alone over the box [0, 1]^M: for p = 2 a strictly convex bounded least-squares problem, solved
exactly by a primal active-set method (``box_qp``); for p > 2 projected Newton (a box QP a step);
for p < 2 L-BFGS-B with the exact gradient; each started from the previous sample's solution.

The reserves are the model's torque actuators (``[[actuators]]``, each with its optimal force) where
it has any; a coordinate without one has no reserve: its torque is a requirement the muscles may
fail to meet. It is solved as a reserve whose optimal force is ``NO_RESERVE`` (1e-3) of the
strongest muscle's torque on the coordinate at full activation at that sample (at least 1e-3 N m),
its torque reported as the torque left unmet: the problem stays the same box QP for p = 2 (solved
to 1e-10 of its activations); leaving unmet what the strongest muscle gives at activation 1e-3
costs as much as a muscle at full activation, so the muscles saturate before torque is left unmet,
and a torque they can meet is met within 1e-6 of itself (one muscle: a = tau / k / (1 + 1e-6)).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .actuators import optimal_forces
from .muscle import ALPHA_OPT, L_OPT, L_SLACK, fiber_length, rigid_tendon_force
from .muscle_paths import muscle_geometry

NO_RESERVE = 1e-3  # of the strongest muscle's torque: a coordinate without a reserve, its torque counted unmet
UNMET, UNMET_SHARE = 1e-3, 1e-4  # N m (N) and of the torque: unmet torque beyond both is reported


@dataclass(frozen=True)
class StaticOptimization:
    """Per sample t (s, (n,)): activations (n, M), muscle forces along the paths (N, (n, M)),
    reserve torques (N m, (n, J); N for a translation; 0 where a coordinate has no reserve) and the
    joint torques (n, J); ``runtime_s`` the optimisation's time (s, the paths and curves excluded);
    ``unmet`` (n, J) the torque the muscles leave unmet on the coordinates without a reserve (0 on
    the others), ``optimal_force`` (J,) each reserve's (0: none), ``moment_arms`` (n, M, J) m."""

    t: np.ndarray
    activation: np.ndarray
    force: np.ndarray
    reserve: np.ndarray
    torque: np.ndarray
    muscles: tuple
    joints: tuple
    runtime_s: float
    unmet: np.ndarray | None = None
    optimal_force: np.ndarray | None = None
    moment_arms: np.ndarray | None = None


def muscle_capacity(params: np.ndarray, lengths: np.ndarray, lengthening: np.ndarray,
                    along_tendon: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(active, passive), each (n, M) N: a rigid-tendon muscle's force along its path per unit
    activation and at zero activation, at muscle-tendon ``lengths`` (m) and ``lengthening`` speeds
    (m/s), both (n, M); ``params`` (M, len(muscle.PARAMETERS)). ``along_tendon`` False: the active
    force of the fibre itself, not times cos(alpha), as OpenSim 4.6's DeGrooteFregly2016Muscle gives
    it to StaticOptimization (its calcInextensibleTendonActiveFiberForce; Thelen's and Millard's
    muscles project it on the tendon)."""
    passive = np.empty(lengths.shape)
    full = np.empty(lengths.shape)
    for k in range(lengths.shape[0]):
        for m in range(lengths.shape[1]):
            passive[k, m] = rigid_tendon_force(0.0, lengths[k, m], lengthening[k, m], params[m])
            full[k, m] = rigid_tendon_force(1.0, lengths[k, m], lengthening[k, m], params[m])
            if not along_tendon:
                full[k, m] = passive[k, m] + (full[k, m] - passive[k, m]) / fiber_length(
                    lengths[k, m] - params[m][L_SLACK], params[m][L_OPT], params[m][ALPHA_OPT])[1]
    return full - passive, passive


def qp_reserve_forces(optimal_force: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """The reserves' optimal forces the QP weighs (J,): ``optimal_force``, and on a coordinate
    without a reserve (0) ``NO_RESERVE`` of its strongest muscle's torque per unit control (``gain``
    (J, M), N m), whose torque is then reported unmet."""
    reserved = optimal_force > 0
    if reserved.all():
        return optimal_force
    strongest = np.abs(gain).max(axis=1, initial=0.0)
    return np.where(reserved, optimal_force, NO_RESERVE * np.maximum(strongest, 1.0))


def solve_sample(gain: np.ndarray, need: np.ndarray, reserve_force: np.ndarray, exponent: float = 2.0,
                 start: np.ndarray | None = None) -> np.ndarray:
    """The activations a (M,) in [0, 1] minimising sum a^p + sum |(need - gain a) / reserve_force|^p:
    ``gain`` (J, M) the joint torques per unit activation (arm * F_active, N m), ``need`` (J,) the
    torques the activations must meet (tau - arm * F_passive), ``reserve_force`` (J,) > 0."""
    scaled_gain, scaled_need = gain / reserve_force[:, None], need / reserve_force
    n_muscles = gain.shape[1]
    if exponent == 2.0:  # 1/2 a' H a - c' a with H = I + G'G, c = G' need (G, need scaled)
        return box_qp(np.eye(n_muscles) + scaled_gain.T @ scaled_gain, scaled_gain.T @ scaled_need, start)
    x0 = np.full(n_muscles, 0.1) if start is None else np.clip(start, 0.0, 1.0)
    if exponent > 2.0:
        return _newton(scaled_gain, scaled_need, exponent, x0)
    from scipy.optimize import minimize  # heavy: scipy

    found = minimize(lambda a: _objective(a, scaled_gain, scaled_need, exponent)[:2], x0, jac=True,
                     method="L-BFGS-B", bounds=[(0.0, 1.0)] * n_muscles,
                     options={"ftol": 1e-13, "gtol": 1e-10, "maxiter": 2000})
    return np.clip(found.x, 0.0, 1.0)


def _objective(a, gain, need, p):
    """sum a^p + sum |need - gain a|^p, its gradient (M,) and (p > 2) its Hessian (M, M)."""
    reserve = need - gain @ a
    value = np.sum(a**p) + np.sum(np.abs(reserve) ** p)
    slope = p * (a ** (p - 1.0) - gain.T @ (np.sign(reserve) * np.abs(reserve) ** (p - 1.0)))
    if p <= 2.0:
        return value, slope, None
    curvature = p * (p - 1.0) * (np.diag(a ** (p - 2.0)) + gain.T @ (np.abs(reserve)[:, None] ** (p - 2.0) * gain))
    return value, slope, curvature


def _newton(gain, need, p, a, max_iterations=100):
    """Projected Newton for p > 2: each step the box QP of the objective's second-order model
    (``box_qp``), then backtracking; stops when a step moves a by less than 1e-13."""
    for _ in range(max_iterations):
        value, slope, curvature = _objective(a, gain, need, p)
        curvature = curvature + 1e-12 * (1.0 + np.trace(curvature)) * np.eye(len(a))
        step = box_qp(curvature, curvature @ a - slope, a) - a
        if np.abs(step).max() < 1e-13:
            return a
        t = 1.0
        while t > 1e-10 and _objective(a + t * step, gain, need, p)[0] > value + 1e-4 * t * (slope @ step):
            t *= 0.5
        a = np.clip(a + t * step, 0.0, 1.0)
    return a


def box_qp(hessian: np.ndarray, linear: np.ndarray, start: np.ndarray | None = None,
           max_iterations: int = 200) -> np.ndarray:
    """The minimiser x (M,) in [0, 1]^M of 1/2 x' H x - c' x, H (M, M) symmetric positive definite:
    a primal active-set method from ``start`` (clipped into the box; default 0), exact to rounding."""
    n = len(linear)
    x = np.zeros(n) if start is None else np.clip(np.asarray(start, dtype=float), 0.0, 1.0)
    free = (x > 0.0) & (x < 1.0)
    for _ in range(max_iterations):
        target = x.copy()
        if free.any():
            rest = hessian[np.ix_(free, ~free)] @ x[~free] if (~free).any() else 0.0
            target[free] = np.linalg.solve(hessian[np.ix_(free, free)], linear[free] - rest)
        if np.all((target >= 0.0) & (target <= 1.0)):
            x = target
            slope = hessian @ x - linear  # a bound's multiplier: >= 0 at 0, <= 0 at 1
            wrong = np.where(~free, np.where(x <= 0.0, -slope, slope), 0.0)
            worst = int(np.argmax(wrong))
            if wrong[worst] <= 1e-12 * (1.0 + np.abs(linear).max()):
                return x
            free[worst] = True
            continue
        step = target - x  # to the first bound on the way to target
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(step < 0, -x / step, np.where(step > 0, (1.0 - x) / step, np.inf))
        room[~free] = np.inf
        blocking = int(np.argmin(room))
        x = x + room[blocking] * step
        x[blocking] = 0.0 if step[blocking] < 0 else 1.0
        free[blocking] = False
    raise ArithmeticError("the active-set method did not converge")  # a numerical failure, as LinAlgError


def static_optimization(model, params: np.ndarray, t: np.ndarray, z: np.ndarray, zd: np.ndarray, torque: np.ndarray,
                        exponent: float = 2.0, reserve_optimal_force: float | None = None,
                        passive: bool = False, geometry: tuple | None = None,
                        along_tendon: bool = True, reserve_forces=None) -> StaticOptimization:
    """Static optimisation of ``model``'s muscles (``params`` (M, len(muscle.PARAMETERS)), the
    engine's ``muscle_params``) on the samples t (s, (n,)) with coordinates z, rates zd and the
    inverse-dynamics torques ``torque`` (N m), each (n, J). The reserves: the model's actuators,
    each with its optimal force (N m per unit control), or ``reserve_optimal_force`` for every one
    of them; a model without actuators: one per coordinate of ``reserve_optimal_force`` (default 1);
    ``reserve_forces`` (J,): each coordinate's instead (0: none). ValueError for an exponent or
    optimal force <= 0."""
    if not np.isfinite(exponent) or exponent <= 0:
        raise ValueError(f"the activation exponent must be a finite number > 0, not {exponent:g}")
    if reserve_optimal_force is not None and (not np.isfinite(reserve_optimal_force) or reserve_optimal_force <= 0):
        raise ValueError(f"the reserves' optimal force must be a finite number > 0, not {reserve_optimal_force:g}")
    if reserve_forces is None:
        reserve_forces = optimal_forces(model, reserve_optimal_force)
    optimal_force = np.array(reserve_forces, dtype=float).reshape(z.shape[1])
    if not np.all(np.isfinite(optimal_force) & (optimal_force >= 0)):
        raise ValueError("the reserves' optimal forces must be finite numbers >= 0 (0: no reserve)")
    if geometry is None:
        lengths, arms = muscle_geometry(model, z)
        lengthening = -np.einsum("nmj,nj->nm", arms, zd)
    else:
        lengths, arms, lengthening = (np.asarray(g, dtype=float) for g in geometry)
    active, passive_force = muscle_capacity(params, lengths, lengthening, along_tendon)
    passive_force = passive_force if passive else np.zeros_like(active)
    reserved = optimal_force > 0
    activation = np.empty(active.shape)
    began = time.perf_counter()
    start = None
    for k in range(len(t)):
        gain = arms[k].T * active[k]  # (J, M)
        need = torque[k] - arms[k].T @ passive_force[k]
        start = activation[k] = solve_sample(gain, need, qp_reserve_forces(optimal_force, gain), exponent, start)
    runtime = time.perf_counter() - began
    force = activation * active + passive_force
    left = torque - np.einsum("nmj,nm->nj", arms, force)
    reserve, unmet = np.where(reserved, left, 0.0), np.where(reserved, 0.0, left)
    return StaticOptimization(np.asarray(t, dtype=float), activation, force, reserve, np.asarray(torque, dtype=float),
                              tuple(m.name for m in model.muscles), tuple(model.coordinates), runtime, unmet,
                              optimal_force, arms)


def unmet_notes(so: StaticOptimization, units: tuple | None = None) -> list[str]:
    """One text per coordinate whose torque the muscles leave unmet (beyond ``UNMET`` N m and
    ``UNMET_SHARE`` of its torque) at some
    sample: its peak unmet torque, the spans of time where it is unmet and the muscles at full
    activation there that would help it ('elbow: 12.3 N m unmet at t 0.31-0.42 s, BIClong, BRA at
    full activation'); ``units`` per coordinate ('N m' default, 'N' for a translation)."""
    notes = []
    for j, joint in enumerate(so.joints):
        where = np.abs(so.unmet[:, j]) > UNMET + UNMET_SHARE * np.abs(so.torque[:, j])
        if not where.any():
            continue
        spans = _spans(so.t, where)
        unit = "N m" if units is None else units[j]
        arms = so.moment_arms[where][:, :, j] * np.sign(so.unmet[where, j])[:, None]  # > 0: the muscle helps
        full = (so.activation[where] >= 1.0 - 1e-9) & (arms > 0)
        helping = (arms > 0).any(axis=0)
        saturated = [m for i, m in enumerate(so.muscles) if full[:, i].any()]
        if saturated:
            tail = f"{', '.join(saturated)} at full activation"
        elif helping.any():
            tail = "the muscles that would help held back by the other coordinates"
        else:
            tail = "no muscle acts on it that way"
        peak = np.abs(so.unmet[:, j]).max()
        notes.append(f"{joint}: {peak:.3g} {unit} unmet at t {spans}, {tail}")
    return notes


def _spans(t: np.ndarray, where: np.ndarray, most: int = 3) -> str:
    """'0.31-0.42 s' or '0.1-0.2, 0.5 and 0.8-0.9 s': the runs of samples where ``where`` holds."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], where.astype(int), [0]])))
    runs = [(t[a], t[b - 1]) for a, b in zip(edges[::2], edges[1::2])]
    texts = [f"{a:.3g}" if a == b else f"{a:.3g}-{b:.3g}" for a, b in runs[:most]]
    texts += [f"{len(runs) - most} more spans"] if len(runs) > most else []
    return (", ".join(texts[:-1]) + " and " + texts[-1] if len(texts) > 1 else texts[0]) + " s"
