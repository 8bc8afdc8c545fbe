"""Exact sensitivities and population evaluation with muscle states
(``fdbench.multibody.kernels.rk4_sensitivity`` with ``muscles``, ``fdbench.tracking.rk4_candidates``
with excitations): the polynomial paths' Hessians against central differences of the moment arms,
the muscle model's partial derivatives against central differences of its functions, the
coordinates' derivatives with respect to excitations (and a torque) against central differences of
whole simulations on the library's arm26 (compliant tendons as in the library, rigid, and rigid with
three muscles through points), and each candidate of a population against its own
``Engine.simulate``. (The Hessians of paths of points: tests/engine/test_muscle_paths.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from fdbench.models import find_model
from fdbench.multibody import muscle as mu
from fdbench.multibody.engine import Engine
from fdbench.multibody.kernels import rk4_sensitivity
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.muscle_paths import muscle_geometry, path_hessians
from fdbench.multibody.simulation import muscle_start, static_tendon_force
from fdbench.population import Population, set_threads
from fdbench.tracking import rk4_candidates
from helpers.models import with_arm26_points
from helpers.population_checks import restore_threads  # noqa: F401 - a fixture

N_STEPS, DT = 40, 2e-3  # s: a short motion
Z0, ZD0 = np.array([0.3, 0.8]), np.array([0.2, -0.5])  # rad, rad/s


def arm26(tendon: str | None = None, points: bool = False) -> Engine:
    """The library's arm26 (compliant tendons), or with every tendon ``tendon``; ``points``: TRIlong,
    BIClong and BRA (muscles 0, 3, 5) through their path points (``helpers.models.ARM26_POINTS``)."""
    data = to_dict(find_model("arm26"))
    if tendon is not None:
        for m in data["muscles"]:
            m["tendon"] = tendon
    return Engine(model_from_dict(with_arm26_points(data) if points else data, "arm26.toml"))


@pytest.fixture(scope="module")
def engines() -> dict:
    return {"compliant": arm26(), "rigid": arm26("rigid"), "points": arm26("rigid", points=True)}


def grid_excitations(engine: Engine, n_steps: int = N_STEPS, dt: float = DT) -> np.ndarray:
    """Smooth excitations in [0.2, 0.5] on the half-step grid, shape (2 n + 1, M)."""
    t = np.arange(2 * n_steps + 1) * (0.5 * dt)
    return 0.2 + 0.3 * np.sin(5.0 * np.outer(t, np.arange(1, engine.n_muscles + 1))) ** 2


def start(engine: Engine, excitation0: np.ndarray) -> np.ndarray:
    y = engine.state_from_joints(Z0, ZD0)
    return np.concatenate([y, muscle_start(engine, y, excitation0)])


def test_polynomial_path_hessians_are_the_slopes_of_the_moment_arms(engines):
    """d2l/dq2 of arm26's six polynomial paths equals minus the central differences (step 1e-4 rad:
    measured 1e-9 off, the step's truncation; the fitted polynomials of degree up to 20 cancel, so
    that smaller steps drown in rounding) of muscle_geometry's moment arms, and is symmetric."""
    model = engines["rigid"].model
    rng = np.random.default_rng(26)
    for _ in range(4):
        q = rng.uniform([-0.3, 0.1], [1.2, 2.0])
        out = path_hessians(model, q)
        h = 1e-4
        slopes = np.stack([-(muscle_geometry(model, q + h * e)[1] - muscle_geometry(model, q - h * e)[1]) / (2 * h)
                           for e in np.eye(2)], axis=-1)
        assert np.abs(out).max() > 1e-2
        np.testing.assert_allclose(out, slopes, rtol=0, atol=1e-6 * np.abs(out).max())
        np.testing.assert_array_equal(out, np.swapaxes(out, 1, 2))


def central(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_the_muscle_partials_are_the_derivatives_of_its_functions():
    """activation_partials, rigid_tendon_partials and compliant_tendon_partials equal central
    differences of activation_derivative, rigid_tendon_force and compliant_tendon's rate at random
    muscles and states (the tendon's force near the fibre's static equilibrium), within 1e-6 relative."""
    rng = np.random.default_rng(2016)
    for _ in range(50):
        p = mu.parameters(rng.uniform(200, 1000), rng.uniform(0.05, 0.15), rng.uniform(0.1, 0.3),
                          pennation_angle_at_optimal=rng.uniform(0, 0.4), fiber_damping=rng.uniform(0, 0.1))
        e, a, v = rng.uniform(0, 1), rng.uniform(0.05, 1), rng.uniform(-0.3, 0.3)
        length = p[mu.L_SLACK] + p[mu.L_OPT] * rng.uniform(0.7, 1.3)
        tau = (0.015, 0.060, 0.1)
        expected = (central(lambda x: mu.activation_derivative(x, a, *tau), e, 1e-6),
                    central(lambda x: mu.activation_derivative(e, x, *tau), a, 1e-6))
        np.testing.assert_allclose(mu.activation_partials(e, a, *tau), expected, rtol=1e-6)
        expected = (central(lambda x: mu.rigid_tendon_force(x, length, v, p), a, 1e-6),
                    central(lambda x: mu.rigid_tendon_force(a, x, v, p), length, 1e-8),
                    central(lambda x: mu.rigid_tendon_force(a, length, x, p), v, 1e-6))
        np.testing.assert_allclose(mu.rigid_tendon_partials(a, length, v, p), expected, rtol=1e-6)
        force = static_tendon_force(a, length, p) * rng.uniform(0.97, 1.03)
        rate = [lambda x: mu.compliant_tendon(x, force, length, v, p)[1],
                lambda x: mu.compliant_tendon(a, x, length, v, p)[1],
                lambda x: mu.compliant_tendon(a, force, x, v, p)[1],
                lambda x: mu.compliant_tendon(a, force, length, x, p)[1]]
        expected = [central(f, x, h) for f, x, h in zip(rate, (a, force, length, v), (1e-7, 1e-7, 1e-9, 1e-6))]
        np.testing.assert_allclose(mu.compliant_tendon_partials(a, force, length, v, p), expected, rtol=1e-6,
                                   atol=1e-7 * np.abs(expected).max())


@pytest.mark.parametrize("tendon", ["compliant", "rigid", "points"])
def test_coordinates_derivatives_by_excitations_equal_central_differences(engines, tendon):
    """On arm26, 40 RK4 steps of 2 ms from a moving start: dz/dp of four parameters (three move one
    muscle's excitation each by a shape on the grid, param_col J + m; one moves the elbow's torque)
    equals central differences of whole simulations (``Engine.simulate`` with excitation_half; step
    1e-4, whose truncation and rounding are each below 1e-7 here) within 1e-5 relative, and the
    kernel's states are those of ``Engine.simulate`` to the last bit. ``points``: the three muscles
    moved run through points (their paths' Hessians ``muscle_paths.points_hessians``')."""
    engine = engines[tendon]
    J, n, rows = engine.n_joints, N_STEPS, 2 * N_STEPS + 1
    t = np.arange(rows) * (0.5 * DT)
    excitation, zero = grid_excitations(engine), np.zeros((rows, J))
    G = np.column_stack([np.exp(-((t - 0.03) / 0.02) ** 2), t / t[-1], np.cos(20 * t), 1.0 + t])
    param_col = np.array([J + 0, J + 3, J + 5, 1], dtype=np.int64)
    y0 = start(engine, excitation[0])

    def inputs(p):
        e, tau = excitation.copy(), zero.copy()
        for q, column in enumerate(param_col):
            if column >= J:
                e[:, column - J] += p[q] * G[:, q]
            else:
                tau[:, column] += p[q] * G[:, q]
        return e, tau

    def z_of(p):
        e, tau = inputs(p)
        return engine.simulate(y0, DT, n, tau, zero, zero, zero, 0.0, 0.0, excitation_half=e).z

    width = engine.n_state + engine.n_muscle_states
    states, rates, applied, dz = (np.empty((n + 1, width)), np.empty((n + 1, width)), np.empty((n + 1, J)),
                                  np.empty((n + 1, J, 4)))
    e, tau = inputs(np.zeros(4))
    code, done = rk4_sensitivity(y0, DT, n, tau, zero, zero, G, param_col, 1, *engine.kernel_args(), None, states,
                                 rates, applied, dz, engine.muscles_at(e))
    assert (code, done) == (0, n)
    plain = engine.simulate(y0, DT, n, tau, zero, zero, zero, 0.0, 0.0, excitation_half=e)
    np.testing.assert_array_equal(states, plain.states)
    h = 1e-4
    expected = np.stack([(z_of(h * unit) - z_of(-h * unit)) / (2 * h) for unit in np.eye(4)], axis=-1)
    assert np.all(np.abs(expected).max(axis=(0, 1)) > 1e-3)  # every parameter moves the arm
    relative = np.abs(dz - expected).max(axis=(0, 1)) / np.abs(expected).max(axis=(0, 1))
    assert relative.max() < 1e-5, relative


def test_each_candidate_of_a_muscle_population_is_eq_18_of_its_own_simulation(engines, restore_threads):
    """rk4_candidates with excitations (Engine.population_args(..., excitation=...)): each of five
    candidates' eq. 18 (its angles' RMSE in deg at every 5th step against a reference, by numpy from
    ``Engine.simulate`` with its excitation_half, plus the penalty, zero here as every run ends)
    within 1e-12 relative, on one thread and on two, and a candidate alone gives its number in a
    population to the bit."""
    engine = engines["compliant"]
    J, n, rows, every, weight = engine.n_joints, N_STEPS, 2 * N_STEPS + 1, 5, 1.0
    rng = np.random.default_rng(18)
    base = grid_excitations(engine)
    excitation = np.clip(base[None] * rng.uniform(0.5, 1.5, (5, 1, engine.n_muscles)), 0.0, 1.0)
    tau, zero = np.zeros((5, rows, J)), np.zeros((rows, J))
    y0 = start(engine, base[0])
    reference = Z0 + np.outer(np.arange(n // every + 1) * every * DT, [0.5, -1.0])
    expected = []
    for c in range(5):
        run = engine.simulate(y0, DT, n, tau[c], zero, zero, zero, 0.0, 0.0, excitation_half=excitation[c])
        error = np.degrees(run.z[::every] - reference)
        expected.append(np.sqrt(np.mean(error**2)) + weight * (1.0 - run.steps_done / n))
    assert np.ptp(expected) > 1e-3  # the candidates differ
    population = Population(rk4_candidates, n, engine.population_widths_with(True))
    args = engine.population_args(y0, DT, n, tau, zero, zero, every, reference, weight, excitation=excitation)
    for threads in (1, 2):
        set_threads(threads)
        values = population(5, args)
        np.testing.assert_allclose(values, expected, rtol=1e-12)
    alone = population(1, engine.population_args(y0, DT, n, tau[3:4], zero, zero, every, reference, weight,
                                                  excitation=excitation[3:4]))
    assert alone[0] == values[3]
