"""The engine's compiled RK4 driver (``Engine.simulate``, ``kernels.rk4``) on the paper's forearm
gives the numbers of classical RK4 written out here in Python to the last bit: the stages
y + h k, the step y + dt/6 (k1 + 2 k2 + 2 k3 + k4), the torques and references of each stage on the
half-step grid, the checks done afresh after every step, with the right-hand side taken from
``Engine.rates`` (the adaptive integrators' one, a separate entry point) at each stage's state.
Whatever the speed-ups inside the driver, its status, steps, largest violation, states and
applied torques are those of the plain formulas."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.layout import COMPUTED, CONSTRAINT, GAINS, NONFINITE, OK, PD, VIOLATION
from fdbench.multibody.motions import joint_motion

MODEL = find_model("forearm")
N = 1000  # steps of 1 ms over eq. 5's 1 s
DT = 1.0 / N
HALF = np.linspace(0.0, 1.0, 2 * N + 1)  # the half-step grid, s
REF, REFD, REFDD = joint_motion("paper", MODEL)(HALF)  # (2N + 1, 1) each
ZERO = np.zeros(1)


def engine(violation_tolerance=None) -> Engine:
    made = Engine(MODEL)
    if violation_tolerance is not None:
        made.params[VIOLATION] = violation_tolerance
    return made


def feedforward() -> np.ndarray:
    """The closed form's elbow torque on the half-step grid, (2N + 1, 1) N m."""
    return 0.04 * REFDD + np.cos(REF) * (15.0 * 0.33 + 9.81 * 0.11)


def plain_rk4(plant: Engine, tau, kp, kd, mode=PD, gains=None):
    """Classical RK4 over N steps from the motion's start: (status, steps done, largest violation,
    states (N + 1, n_state), applied torques (N + 1, 1)), NaN after the last step done."""
    with np.errstate(all="ignore"):  # a run driven to overflow is one of the cases
        return _plain_rk4(plant, tau, kp, kd, mode, gains)


def _plain_rk4(plant, tau, kp, kd, mode, gains):
    def rate(y, row):
        law_gains = None if gains is None else gains[row][None]
        k, applied = plant.rates(y[None], tau[row][None], REF[row][None], REFD[row][None], REFDD[row][None], kp, kd,
                                 mode, law_gains)
        return k[0], applied[0]

    y = plant.state_from_joints(REF[0], REFD[0])
    states, applied = np.full((N + 1, plant.n_state), np.nan), np.full((N + 1, 1), np.nan)
    max_viol = plant.constraint_violation(y)
    for i in range(N + 1):
        j = 2 * i
        k1, applied[i] = rate(y, j)
        states[i] = y
        if not np.all(np.isfinite(k1)):
            return NONFINITE, i, max_viol, states, applied
        if i == N:
            return OK, N, max_viol, states, applied
        ks = [k1]
        for h, row in ((0.5 * DT, j + 1), (0.5 * DT, j + 1), (DT, j + 2)):
            k = rate(y + h * ks[-1], row)[0]
            if not np.all(np.isfinite(k)):
                return NONFINITE, i, max_viol, states, applied
            ks.append(k)
        new = y + DT / 6.0 * (ks[0] + 2.0 * ks[1] + 2.0 * ks[2] + ks[3])
        if not np.all(np.isfinite(new)):
            return NONFINITE, i, max_viol, states, applied
        viol = plant.constraint_violation(new)
        if viol > plant.params[VIOLATION]:
            return CONSTRAINT, i, max(max_viol, viol), states, applied
        max_viol, y = max(max_viol, viol), new
    raise AssertionError("unreachable")


def compiled_rk4(plant: Engine, tau, kp, kd, mode=PD, gains=None):
    result = plant.simulate(plant.state_from_joints(REF[0], REFD[0]), DT, N, tau, REF, REFD, REFDD, kp, kd, mode, gains)
    return result.status, result.steps_done, result.max_violation, result.states, result.applied


def assert_same_run(compiled, plain):
    assert compiled[:3] == plain[:3]  # status, steps done, largest violation: exactly
    done = compiled[1]
    assert np.array_equal(compiled[3][: done + 1], plain[3][: done + 1])
    assert np.array_equal(compiled[4][: done + 1], plain[4][: done + 1])


def open_loop_torques() -> dict:
    """Drive torques (N m) on the half-step grid that end in every way: the end reached, a spin
    (through theta = pi/2, the paper's singular configuration, which the engine does not have, on
    to ~10 rad, where 1 ms steps leave the constraints), a non-finite state, a constraint violation
    (with a tolerance below what a good run reaches)."""
    ramp = np.linspace(0.0, 1.0, 2 * N + 1)[:, None]
    blow_up = feedforward().copy()
    blow_up[700:] = 1e300
    return {"reached": feedforward() + 0.05 * np.sin(9 * ramp), "spin": feedforward() + 40.0 * ramp,
            "non-finite": blow_up, "constraint": feedforward() + 0.05 * np.sin(9 * ramp)}


@pytest.mark.parametrize("name, status", [("reached", OK), ("spin", CONSTRAINT), ("non-finite", NONFINITE),
                                          ("constraint", CONSTRAINT)])
def test_open_loop_driver_is_the_plain_formulas_to_the_bit(name, status):
    plant = engine(1e-12 if name == "constraint" else None)
    tau = open_loop_torques()[name]
    plain = plain_rk4(plant, tau, ZERO, ZERO)
    assert plain[0] == status
    if name == "spin":
        assert np.nanmax(plain[3][:, 2]) > 3 * math.pi
    if status != OK:
        assert 0 < plain[1] < N
    assert_same_run(compiled_rk4(plant, tau, ZERO, ZERO), plain)


def test_feedback_laws_are_the_plain_formulas_to_the_bit():
    """The paper's PD (kp 80, kd 0.3) on the feedforward, computed torque, and a gain matrix that
    varies along the motion, as the LQR controller's."""
    plant, tau = engine(), feedforward()
    assert_same_run(compiled_rk4(plant, tau, [80.0], [0.3]), plain_rk4(plant, tau, [80.0], [0.3]))
    assert_same_run(compiled_rk4(plant, np.zeros_like(tau), [400.0], [40.0], COMPUTED),
                    plain_rk4(plant, np.zeros_like(tau), [400.0], [40.0], COMPUTED))
    gains = np.stack([40.0 + 30.0 * HALF, 0.2 + 0.1 * HALF], -1)[:, None, :]  # (2N + 1, 1, 2)
    assert_same_run(compiled_rk4(plant, tau, ZERO, ZERO, GAINS, gains), plain_rk4(plant, tau, ZERO, ZERO, GAINS, gains))
