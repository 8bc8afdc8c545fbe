"""The compiled forearm kernels give the numbers of the plain formulas to the last bit: eq. 12 and
RK4 written out here in Python (sin and cos at every stage, every check done afresh), against
``dynamics.rk4_feedback``, the population kernel and the sensitivity kernel, whatever the speed-ups
inside them (inlined stages, sin and cos computed once per state)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fdbench import dynamics
from fdbench.integrate import Settings, constants, half_step_reference, initial_state, steps
from fdbench.inverse import Feedforward
from fdbench.population import rk4_candidates, tracking_objective
from fdbench.sensitivity import rk4_sensitivity

SETTINGS = Settings()
N = steps(SETTINGS.dt)
HALF, REF_TH, REF_W = half_step_reference(N, SETTINGS.kinematics)
FEEDFORWARD = np.array(Feedforward(SETTINGS.model, SETTINGS.kinematics)(HALF))
CONSTS = constants(SETTINGS)
Y0 = initial_state(SETTINGS.kinematics, SETTINGS.model)


def plain_accelerations(x, y, th, vx, vy, w, tau, consts):
    """Eq. 12 of the forearm solved in closed form (x2'', y2'', theta'', cos theta), term by term."""
    a, L, load_y, alpha, two_xi_omega, omega2, cos_tol = consts[:7]
    s, c = math.sin(th), math.cos(th)
    lc = L * c
    if abs(c) < cos_tol:
        return 0.0, 0.0, 0.0, c
    c1 = 2 * vx * vx + 2 * vy * vy + two_xi_omega * (2 * x * vx + 2 * y * vy) + omega2 * (x * x + y * y - L * L)
    c2 = L * s * w * w + two_xi_omega * (vy - lc * w) + omega2 * (y - L * s)
    b1 = -2 * alpha * x * c1
    b2 = load_y + tau / lc - 2 * alpha * y * c1
    det = a * a + 4 * alpha * a * (x * x + y * y)
    ax = ((a + 4 * alpha * y * y) * b1 - 4 * alpha * x * y * b2) / det
    ay = ((a + 4 * alpha * x * x) * b2 - 4 * alpha * x * y * b1) / det
    return ax, ay, tau / (alpha * lc * lc) + (c2 + ay) / lc, c


def plain_derivative(y, tau, ref_th, ref_w, kp, kd, g_c, c0, consts):
    total = tau + kp * (ref_th - y[2]) + kd * (ref_w - y[5])
    if g_c != 0.0:
        total += g_c * math.cos(y[2])
    ax, ay, ath, c = plain_accelerations(*y, total, consts)
    code = dynamics.OK
    if not math.isfinite(c):
        code = dynamics.NONFINITE
    elif abs(c) < consts[6] or c * c0 <= 0.0:
        code = dynamics.SINGULAR
    return code, [y[3], y[4], y[5], ax, ay, ath]


def plain_rk4(tau, kp, kd, g_c=0.0, consts=CONSTS):
    """RK4 under tau + kp (ref - theta) + kd (ref' - theta') + g_c cos(theta) (kp, kd: arrays on
    the half-step grid): (status, steps done, largest violation, states (n+1, 6))."""
    with np.errstate(all="ignore"):  # a run driven to overflow is one of the cases
        return _plain_rk4(tau, kp, kd, g_c, consts)


def _plain_rk4(tau, kp, kd, g_c, consts):
    L, viol_tol, dt = consts[1], consts[7], SETTINGS.dt
    y = [float(v) for v in Y0]
    states = np.full((N + 1, 6), np.nan)
    violation = lambda q: max(abs(q[0] * q[0] + q[1] * q[1] - L * L), abs(q[1] - L * math.sin(q[2])))  # noqa: E731
    max_viol = violation(y)
    for i in range(N + 1):
        j = 2 * i
        c0 = math.cos(y[2])
        code, k1 = plain_derivative(y, tau[j], REF_TH[j], REF_W[j], kp[j], kd[j], g_c, c0, consts)
        states[i] = y
        if code != dynamics.OK or i == N:
            return code, i, max_viol, states
        ks = [k1]
        for weight, half in ((0.5, j + 1), (0.5, j + 1), (1.0, j + 2)):
            stage = [y[m] + weight * dt * ks[-1][m] for m in range(6)]
            code, k = plain_derivative(stage, tau[half], REF_TH[half], REF_W[half], kp[half], kd[half], g_c, c0,
                                       consts)
            if code != dynamics.OK:
                return code, i, max_viol, states
            ks.append(k)
        new = [y[m] + dt / 6.0 * (ks[0][m] + 2.0 * ks[1][m] + 2.0 * ks[2][m] + ks[3][m]) for m in range(6)]
        if not all(math.isfinite(v) for v in new):
            return dynamics.NONFINITE, i, max_viol, states
        if math.cos(new[2]) * c0 <= 0.0:
            return dynamics.SINGULAR, i, max_viol, states
        if violation(new) > viol_tol:
            return dynamics.CONSTRAINT, i, max(max_viol, violation(new)), states
        max_viol, y = max(max_viol, violation(new)), new
    raise AssertionError("unreachable")


def open_loop_torques():
    """Drive torques (N m) on the half-step grid that end in every way: the end reached, the
    singularity, a non-finite state (the constraint tolerance exceeded: see ``TIGHT``)."""
    ramp = np.linspace(0.0, 1.0, 2 * N + 1)
    blow_up = FEEDFORWARD.copy()
    blow_up[700:] = 1e300
    return {"reached": FEEDFORWARD + 0.05 * np.sin(9 * ramp), "singular": FEEDFORWARD + 40.0 * ramp,
            "non-finite": blow_up}


TIGHT = CONSTS.copy()
TIGHT[7] = 1e-9  # a violation tolerance below what a good run reaches (~2e-8): the run stops part-way


def kernel_run(tau, kp, kd, g_c=0.0, consts=CONSTS):
    states, qdd, applied = np.full((N + 1, 6), np.nan), np.full((N + 1, 3), np.nan), np.full(N + 1, np.nan)
    code, done, max_viol = dynamics.rk4_feedback(Y0, SETTINGS.dt, N, tau, REF_TH, REF_W, kp, kd, g_c, consts,
                                                 states, qdd, applied)
    return code, done, max_viol, states


def assert_same_run(kernel, plain):
    assert kernel[:3] == plain[:3]  # status, steps done, largest violation: exactly
    done = kernel[1]
    assert np.array_equal(kernel[3][: done + 1], plain[3][: done + 1])


@pytest.mark.parametrize("name", ["reached", "singular", "constraint", "non-finite"])
def test_open_loop_kernel_is_the_plain_formulas_to_the_bit(name):
    tau, consts = (open_loop_torques()["reached"], TIGHT) if name == "constraint" else (open_loop_torques()[name],
                                                                                         CONSTS)
    zero = np.zeros(2 * N + 1)
    plain = plain_rk4(tau, zero, zero, consts=consts)
    assert plain[0] == {"reached": dynamics.OK, "singular": dynamics.SINGULAR, "constraint": dynamics.CONSTRAINT,
                        "non-finite": dynamics.NONFINITE}[name]
    assert_same_run(kernel_run(tau, np.zeros(1), np.zeros(1), consts=consts), plain)


def test_pd_kernel_is_the_plain_formulas_to_the_bit():
    """The paper's PD (kp 80, kd 0.3) on the feedforward, and gains that vary along the motion
    with a gravity term, as the LQR and computed-torque controllers use them."""
    kp, kd = np.full(2 * N + 1, 80.0), np.full(2 * N + 1, 0.3)
    assert_same_run(kernel_run(FEEDFORWARD, kp[:1], kd[:1]), plain_rk4(FEEDFORWARD, kp, kd))
    varying_kp, varying_kd = 40.0 + 30.0 * HALF, 0.2 + 0.1 * HALF
    assert_same_run(kernel_run(FEEDFORWARD, varying_kp, varying_kd, 2.5),
                    plain_rk4(FEEDFORWARD, varying_kp, varying_kd, 2.5))


def test_population_and_sensitivity_kernels_are_the_plain_formulas_to_the_bit():
    torques = np.array(list(open_loop_torques().values()))
    zero = np.zeros(2 * N + 1)
    plain = [plain_rk4(tau, zero, zero) for tau in torques]
    every, theta_ref = 1, np.ascontiguousarray(REF_TH[::2])
    objective = np.empty(len(torques))
    rk4_candidates(Y0, SETTINGS.dt, N, torques, REF_TH, REF_W, CONSTS, every, theta_ref, 1.0,
                   np.empty((N + 1, 6)), np.empty((N + 1, 3)), np.empty(N + 1), objective, 0, 1)
    expected = [tracking_objective.py_func(states, done, every, theta_ref, N, 1.0) for _, done, _, states in plain]
    assert np.array_equal(objective, expected)
    states, dtheta = np.full((N + 1, 6), np.nan), np.empty((N + 1, 1))
    code, done = rk4_sensitivity(Y0, SETTINGS.dt, N, torques[0], np.ones((2 * N + 1, 1)), REF_TH, REF_W, CONSTS,
                                 states, dtheta)
    assert (code, done) == plain[0][:2]
    assert np.array_equal(states, plain[0][3])
