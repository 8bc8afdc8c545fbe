"""The multibody engine's compiled kernels (see ``fdbench.multibody.engine`` for the formulation).

Every kernel takes arrays only: the engine's data layout (indices and constants built once per
``Engine``), so numba compiles and caches each kernel once for every model. Three layouts travel
with the calls, each a tuple of arrays in a fixed order:

* the penalty layout (``Engine._kernel_layout``): pt_index, pt_fixed, body_pts, body_geom,
  joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params;
* the inverse-dynamics layout (``Engine.inverse_torques_layout``): joint_parent, joint_offset,
  joint_at_parent, joint_at_child, pt_owner, pt_local, pt_index, mass, q_ext;
* the simulation layout (``Engine.simulation_layout``): the plant's joint offsets, its penalty
  layout, then the inverse-dynamics layout of the model computed-torque control believes.

One RK4 driver (``rk4``) serves every feedback law (``mode``): PD (per-joint PD plus feedforward),
COMPUTED (computed torque through the believed model's inverse dynamics) and GAINS (a full gain
matrix on the half-step grid); ``derivatives`` is the same right-hand side for k states at once
(the adaptive integrators), ``rk4_candidates`` the population's open-loop simulations with eq. 18.
Strict IEEE arithmetic.
"""

from __future__ import annotations

import math

import numpy as np

from ..dynamics import CONSTRAINT, NONFINITE, OK, SINGULAR
from ..jit import njit
from ..population import DEGREES_PER_RADIAN

# named indices into the kernels' arrays
ALPHA, TWO_XI_OMEGA, OMEGA2, SWITCH_COS, VIOLATION, N_PARAMS = 0, 1, 2, 3, 4, 5  # params
LENGTH, BETA = 0, 1  # body_geom columns: d (m), beta (rad)
LAMBDA, PIVOT, VELOCITY_TERM, FORM, N_AUX = 0, 1, 2, 3, 4  # aux columns per body
FIXED = -1  # pt_index of a point fixed to ground (and lin_idx padding)
PD, COMPUTED, GAINS = 0, 1, 2  # feedback laws (``rk4``'s mode)
# columns of the inverse dynamics' per-body scratch: angle (rad), its cos and sin, rate (rad/s),
# angular acceleration (rad/s^2), the joint point (m), the frame origin (m) and its acceleration (m/s^2)
PHI, COS, SIN, RATE, ACC, JOINT_X, JOINT_Y, ORIGIN_X, ORIGIN_Y, ORIGIN_AX, ORIGIN_AY, N_KIN = range(12)


# ---------------------------------------------------------------------- eq. 12
@njit(inline="always")
def _point(y, n_q, pt, pt_index, pt_fixed):
    """x, y, x', y' of a point (fixed points: their position and zero velocity)."""
    k = pt_index[pt]
    if k < 0:
        return pt_fixed[pt, 0], pt_fixed[pt, 1], 0.0, 0.0
    return y[k], y[k + 1], y[n_q + k], y[n_q + k + 1]


@njit(inline="always")
def _angle_form(c, switch):
    """1 for the sin form of the angle constraint (|cos| >= switch), 0 for the cos form."""
    return 1 if abs(c) >= switch else 0


@njit(inline="always")
def _violation(y, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base,
               q_ext, params):
    """max |Phi_i| (m^2 and m) of the state y: distances, angles (the form in force), linear."""
    n_b = body_pts.shape[0]
    n_q = base.shape[0] + n_b
    worst = 0.0
    for b in range(n_b):
        xi, yi, _, _ = _point(y, n_q, body_pts[b, 0], pt_index, pt_fixed)
        xj, yj, _, _ = _point(y, n_q, body_pts[b, 1], pt_index, pt_fixed)
        dx, dy, d = xj - xi, yj - yi, body_geom[b, LENGTH]
        psi = y[base.shape[0] + b] + body_geom[b, BETA]
        c = math.cos(psi)
        angle = dy - d * math.sin(psi) if _angle_form(c, params[SWITCH_COS]) == 1 else dx - d * c
        worst = max(worst, max(abs(dx * dx + dy * dy - d * d), abs(angle)))
    for r in range(lin_const.shape[0]):
        value = lin_const[r]
        for e in range(lin_idx.shape[1]):
            if lin_idx[r, e] >= 0:
                value += lin_coef[r, e] * y[lin_idx[r, e]]
        worst = max(worst, abs(value))
    return worst


@njit(error_model="numpy", inline="always")
def _derivative(y, tau, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first,
                base, q_ext, params, K, rhs, aux, q_phi, out):
    """y' = [q', q''] of eq. 12 into out for the state y and joint torques tau (N m). K, rhs, aux,
    q_phi: scratch (``_workspace``). Returns OK, or SINGULAR where a pivot of the points' matrix is
    not positive (then out[n_q:] is left unfinished)."""
    n_p, n_b = base.shape[0], body_pts.shape[0]
    n_q = n_p + n_b
    alpha, txo, om2 = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2]
    for k in range(n_q):
        out[k] = y[n_q + k]
    for k in range(n_b):  # joint torques -> generalised forces of the absolute angles
        q_phi[k] = tau[k]
    for k in range(n_b):
        if joint_parent[k] >= 0:
            q_phi[joint_parent[k]] -= tau[k]
    for r in range(n_p):
        rhs[r] = q_ext[r]
        for c in range(first[r], r + 1):
            K[r, c] = base[r, c]
    for r in range(lin_const.shape[0]):  # linear constraints: their J^T J is in base
        phi, rate = lin_const[r], 0.0
        for e in range(lin_idx.shape[1]):
            k = lin_idx[r, e]
            if k >= 0:
                phi += lin_coef[r, e] * y[k]
                rate += lin_coef[r, e] * y[n_q + k]
        cc = alpha * (txo * rate + om2 * phi)
        for e in range(lin_idx.shape[1]):
            k = lin_idx[r, e]
            if k >= 0:
                rhs[k] -= lin_coef[r, e] * cc
    for b in range(n_b):
        ki, kj = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        xi, yi, vxi, vyi = _point(y, n_q, body_pts[b, 0], pt_index, pt_fixed)
        xj, yj, vxj, vyj = y[kj], y[kj + 1], y[n_q + kj], y[n_q + kj + 1]
        dx, dy, dvx, dvy = xj - xi, yj - yi, vxj - vxi, vyj - vyi
        d = body_geom[b, LENGTH]
        psi = y[n_p + b] + body_geom[b, BETA]
        w = y[n_q + n_p + b]
        s, c = math.sin(psi), math.cos(psi)
        # distance: Phi = |dr|^2 - d^2, J = 2 dr on j, -2 dr on i
        cd = 2 * (dvx * dvx + dvy * dvy) + txo * 2 * (dx * dvx + dy * dvy) + om2 * (dx * dx + dy * dy - d * d)
        p4 = 4 * alpha
        K[kj, kj] += p4 * dx * dx
        K[kj + 1, kj] += p4 * dx * dy
        K[kj + 1, kj + 1] += p4 * dy * dy
        rhs[kj] -= 2 * alpha * dx * cd
        rhs[kj + 1] -= 2 * alpha * dy * cd
        if ki >= 0:
            K[ki, ki] += p4 * dx * dx
            K[ki + 1, ki] += p4 * dx * dy
            K[ki + 1, ki + 1] += p4 * dy * dy
            K[kj, ki] -= p4 * dx * dx
            K[kj, ki + 1] -= p4 * dx * dy
            K[kj + 1, ki] -= p4 * dx * dy
            K[kj + 1, ki + 1] -= p4 * dy * dy
            rhs[ki] += 2 * alpha * dx * cd
            rhs[ki + 1] += 2 * alpha * dy * cd
        # angle: its row gives the multiplier lambda = Q_phi / (dPhi/dphi)
        form = _angle_form(c, params[SWITCH_COS])
        if form == 1:  # (y_j - y_i) - d sin(psi)
            pivot = -d * c
            ca = d * s * w * w + txo * (dvy - d * c * w) + om2 * (dy - d * s)
            axis = 1
        else:  # (x_j - x_i) - d cos(psi)
            pivot = d * s
            ca = d * c * w * w + txo * (dvx + d * s * w) + om2 * (dx - d * c)
            axis = 0
        lam = q_phi[b] / pivot
        rhs[kj + axis] -= lam
        if ki >= 0:
            rhs[ki + axis] += lam
        aux[b, LAMBDA], aux[b, PIVOT], aux[b, VELOCITY_TERM], aux[b, FORM] = lam, pivot, ca, axis
    code = _solve_envelope(K, first, rhs)
    if code != OK:
        return code
    for r in range(n_p):
        out[n_q + r] = rhs[r]
    for b in range(n_b):
        ki, kj = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        axis = int(aux[b, FORM])
        rel = rhs[kj + axis] - (rhs[ki + axis] if ki >= 0 else 0.0)
        out[n_q + n_p + b] = (aux[b, LAMBDA] / alpha - aux[b, VELOCITY_TERM] - rel) / aux[b, PIVOT]
    return OK


@njit(error_model="numpy", inline="always")
def _solve_envelope(K, first, rhs):
    """Solve K x = rhs in place (x into rhs) for K symmetric positive definite, its lower triangle
    given inside the envelope first[r] <= c <= r, by L D L^T (L into K's strict lower triangle, D on
    its diagonal). Returns OK, NONFINITE for a pivot that is NaN, or SINGULAR for one that is not
    positive (rank lost; rhs is then unfinished)."""
    n = rhs.shape[0]
    for r in range(n):
        fr = first[r]
        for c in range(fr, r):
            total = K[r, c]
            for k in range(max(fr, first[c]), c):
                total -= K[r, k] * K[c, k]  # K[r, k] holds L[r, k] D[k] until row r is done
            K[r, c] = total
        diag = K[r, r]
        for c in range(fr, r):
            lrc = K[r, c] / K[c, c]
            diag -= lrc * K[r, c]
            K[r, c] = lrc
        if math.isnan(diag):
            return NONFINITE
        if not diag > 0.0:
            return SINGULAR
        K[r, r] = diag
    for r in range(n):  # L z = rhs
        total = rhs[r]
        for k in range(first[r], r):
            total -= K[r, k] * rhs[k]
        rhs[r] = total
    for r in range(n):
        rhs[r] /= K[r, r]
    for r in range(n - 1, -1, -1):  # L^T x = z, column by column
        x = rhs[r]
        for k in range(first[r], r):
            rhs[k] -= K[r, k] * x
    return OK


# ---------------------------------------------------------------------- inverse dynamics (eq. 3)
@njit(inline="always")
def _body_point(kin, b, lx, ly):
    """Position (m) and acceleration (m/s^2) of the point (lx, ly) (m, body frame) of body b, from
    the bodies' kinematics ``kin``: x, y, ax, ay."""
    c, s = kin[b, COS], kin[b, SIN]
    arm_x, arm_y = lx * c - ly * s, lx * s + ly * c
    al, w2 = kin[b, ACC], kin[b, RATE] * kin[b, RATE]
    return (kin[b, ORIGIN_X] + arm_x, kin[b, ORIGIN_Y] + arm_y, kin[b, ORIGIN_AX] - al * arm_y - w2 * arm_x,
            kin[b, ORIGIN_AY] + al * arm_x - w2 * arm_y)


@njit(error_model="numpy", inline="always")
def _inverse_torques(z, zd, zdd, joint_parent, joint_offset, joint_at_parent, joint_at_child, pt_owner, pt_local,
                     pt_index, mass, q_ext, kin, points, out):
    """Eq. 3, tau = R^T (M_p p'' - Q_ext) (N m), into out (J,) for the joint angles z (rad), rates zd
    (rad/s) and accelerations zdd (rad/s^2), shape (J,): the bodies' kinematics from ground out
    (parents before children), the free points' positions and accelerations, then each point's
    force M_p p'' - Q_ext projected on R90 (r_P - r_joint) for every joint on its owner's path.
    kin (J, N_KIN), points (3, n_p): scratch."""
    n_b = joint_parent.shape[0]
    for k in range(n_b):
        p = joint_parent[k]
        if p < 0:
            phi, w, al = z[k] + joint_offset[k], zd[k], zdd[k]
            rx, ry, ax, ay = joint_at_parent[k, 0], joint_at_parent[k, 1], 0.0, 0.0
        else:
            phi, w, al = kin[p, PHI] + z[k] + joint_offset[k], kin[p, RATE] + zd[k], kin[p, ACC] + zdd[k]
            rx, ry, ax, ay = _body_point(kin, p, joint_at_parent[k, 0], joint_at_parent[k, 1])
        c, s = math.cos(phi), math.sin(phi)
        arm_x = joint_at_child[k, 0] * c - joint_at_child[k, 1] * s
        arm_y = joint_at_child[k, 0] * s + joint_at_child[k, 1] * c
        kin[k, PHI], kin[k, COS], kin[k, SIN], kin[k, RATE], kin[k, ACC] = phi, c, s, w, al
        kin[k, JOINT_X], kin[k, JOINT_Y] = rx, ry
        kin[k, ORIGIN_X], kin[k, ORIGIN_Y] = rx - arm_x, ry - arm_y
        kin[k, ORIGIN_AX], kin[k, ORIGIN_AY] = ax + al * arm_y + w * w * arm_x, ay - al * arm_x + w * w * arm_y
    for pt in range(pt_index.shape[0]):  # positions (row 0) and accelerations (row 1) of the free points
        i = pt_index[pt]
        if i >= 0:
            points[0, i], points[0, i + 1], points[1, i], points[1, i + 1] = _body_point(
                kin, pt_owner[pt], pt_local[pt, 0], pt_local[pt, 1])
    n_p = mass.shape[0]
    for r in range(n_p):  # row 2: M_p p'' - Q_ext
        total = 0.0
        for c in range(n_p):
            total += mass[r, c] * points[1, c]
        points[2, r] = total - q_ext[r]
    for k in range(n_b):
        out[k] = 0.0
    for pt in range(pt_index.shape[0]):
        i = pt_index[pt]
        if i < 0:
            continue
        b = pt_owner[pt]
        while b >= 0:
            lever_x, lever_y = points[0, i] - kin[b, JOINT_X], points[0, i + 1] - kin[b, JOINT_Y]
            out[b] += lever_x * points[2, i + 1] - lever_y * points[2, i]
            b = joint_parent[b]


@njit(error_model="numpy")
def inverse_torques(z, zd, zdd, joint_parent, joint_offset, joint_at_parent, joint_at_child, pt_owner, pt_local,
                    pt_index, mass, q_ext, out):
    """The joint torques (N m) of the minimal motion (z, zd, zdd) (rad, rad/s, rad/s^2; shape (J,))
    into out (J,): eq. 3 over the inverse-dynamics layout (``Engine.inverse_torques_layout``)."""
    kin, points = np.empty((joint_parent.shape[0], N_KIN)), np.empty((3, mass.shape[0]))
    _inverse_torques(z, zd, zdd, joint_parent, joint_offset, joint_at_parent, joint_at_child, pt_owner, pt_local,
                     pt_index, mass, q_ext, kin, points, out)


# ---------------------------------------------------------------------- feedback laws
@njit(inline="always")
def _law_torques(y, half, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, kin, points, z, zd,
                 v, torque):
    """The applied joint torques (N m) at the state y and grid index ``half`` into torque (J,).
    ref holds the reference joint angles plus the plant's joint offsets (``offset``), as z here is
    the difference of the body angles. mode PD: tau + kp (ref - z) + kd (refd - z'); GAINS: tau +
    gains[half] [ref - z, refd - z'], accumulated term by term onto tau (so that K = [diag kp,
    diag kd] gives PD's numbers to the last bit); COMPUTED: the believed model's (``nominal``)
    inverse dynamics at (z, z') for the accelerations refdd + kp e + kd e', plus tau. z, zd, v: scratch (J,)."""
    joint_parent, n_p = layout[4], layout[9].shape[0]
    n_b = joint_parent.shape[0]
    n_q = n_p + n_b
    for k in range(n_b):
        p = joint_parent[k]
        z[k] = y[n_p + k] - (y[n_p + p] if p >= 0 else 0.0)
        zd[k] = y[n_q + n_p + k] - (y[n_q + n_p + p] if p >= 0 else 0.0)
    if mode == GAINS:
        for k in range(n_b):
            total = tau[half, k]
            for j in range(n_b):
                total += gains[half, k, j] * (ref[half, j] - z[j])
            for j in range(n_b):
                total += gains[half, k, n_b + j] * (refd[half, j] - zd[j])
            torque[k] = total
    elif mode == COMPUTED:
        for k in range(n_b):
            v[k] = refdd[half, k] + kp[k] * (ref[half, k] - z[k]) + kd[k] * (refd[half, k] - zd[k])
            z[k] -= offset[k]
        n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext = nominal
        _inverse_torques(z, zd, v, n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass,
                         n_q_ext, kin, points, torque)
        for k in range(n_b):
            torque[k] += tau[half, k]
    else:
        for k in range(n_b):
            torque[k] = tau[half, k] + kp[k] * (ref[half, k] - z[k]) + kd[k] * (refd[half, k] - zd[k])


@njit(error_model="numpy", inline="always")
def _rate(y, half, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, work, torque, out):
    """The state derivative under the feedback law (``_law_torques``) into out; the applied
    torques into torque. work: ``_scratch``. Returns a status code (``_derivative``)."""
    K, rhs, aux, q_phi, kin, points, z, zd, v = work
    _law_torques(y, half, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, kin, points, z, zd, v,
                 torque)
    (pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext,
     params) = layout
    return _derivative(y, torque, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const,
                       first, base, q_ext, params, K, rhs, aux, q_phi, out)


@njit(inline="always")
def _scratch(layout, nominal):
    """The work arrays of ``_rate`` for the plant's layout and the believed model's."""
    n_p, n_b, n_nominal = layout[9].shape[0], layout[2].shape[0], nominal[7].shape[0]
    return (np.zeros((n_p, n_p)), np.zeros(n_p), np.zeros((n_b, N_AUX)), np.zeros(n_b), np.zeros((n_b, N_KIN)),
            np.zeros((3, n_nominal)), np.zeros(n_b), np.zeros(n_b), np.zeros(n_b))


@njit(error_model="numpy")
def rk4(y0, dt, n_steps, tau, ref, refd, refdd, kp, kd, mode, gains, offset, pt_index, pt_fixed, body_pts, body_geom,
        joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent, n_offset, n_at_parent,
        n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states, rates, applied):
    """Classical RK4 of eq. 12 over n_steps steps of dt (s) under the feedback law ``mode`` (PD,
    COMPUTED or GAINS, see ``_law_torques``), from the state y0 (n_state,).

    tau, ref, refd, refdd: shape (2 n_steps + 1, J), the feedforward torques (N m), the reference
    joint angles plus the joint offsets (rad), velocities (rad/s) and accelerations (rad/s^2) on
    the half-step grid t_k = k dt / 2; kp, kd: shape (J,) (PD: N m/rad, N m s/rad; COMPUTED: 1/s^2,
    1/s); gains: shape (2 n_steps + 1, J, 2J) for GAINS (N m/rad, N m s/rad), any (m, J, 2J)
    otherwise; offset: the plant's joint offsets (rad); then the penalty layout and the believed
    model's inverse-dynamics layout (``Engine.simulation_layout``). Fills states (n+1, n_state),
    rates (n+1, n_state) (the state derivative) and applied (n+1, J) (N m) up to the last step
    reached. Returns (status, steps_done, max constraint violation)."""
    layout = (pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext,
              params)
    nominal = (n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext)
    work = _scratch(layout, nominal)
    n = y0.shape[0]
    torque = np.zeros(joint_parent.shape[0])
    y = y0.copy()
    k1, k2, k3, k4, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    max_viol = _violation(y, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first,
                          base, q_ext, params)
    for i in range(n_steps + 1):
        j = 2 * i
        code = _rate(y, j, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, work, torque, k1)
        for m in range(n):
            states[i, m] = y[m]
            rates[i, m] = k1[m]
        for m in range(torque.shape[0]):
            applied[i, m] = torque[m]
        if code != OK:
            return code, i, max_viol
        if i == n_steps:
            break
        for m in range(n):
            tmp[m] = y[m] + 0.5 * dt * k1[m]
        code = _rate(tmp, j + 1, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, work, torque, k2)
        if code == OK:
            for m in range(n):
                tmp[m] = y[m] + 0.5 * dt * k2[m]
            code = _rate(tmp, j + 1, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, work, torque,
                         k3)
        if code == OK:
            for m in range(n):
                tmp[m] = y[m] + dt * k3[m]
            code = _rate(tmp, j + 2, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, work, torque,
                         k4)
        if code != OK:
            return code, i, max_viol
        finite = True
        for m in range(n):
            tmp[m] = y[m] + dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            finite = finite and math.isfinite(tmp[m])
        if not finite:
            return NONFINITE, i, max_viol
        viol = _violation(tmp, pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const,
                          first, base, q_ext, params)
        if viol > params[VIOLATION]:
            return CONSTRAINT, i, max(max_viol, viol)
        max_viol = max(max_viol, viol)
        y[:] = tmp
    return OK, n_steps, max_viol


@njit(error_model="numpy")
def derivatives(states, tau, ref, refd, refdd, kp, kd, mode, gains, offset, pt_index, pt_fixed, body_pts, body_geom,
                joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params, n_parent, n_offset,
                n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, out, applied):
    """The state derivatives (into out, shape (k, n_state)) and the applied joint torques (N m, into
    applied, shape (k, J)) of k states (shape (k, n_state)) under ``rk4``'s feedback law, row i with
    row i of tau, ref, refd, refdd (each (k, J)) and of gains ((k, J, 2J) for GAINS); the
    accelerations are NaN where the points' matrix is singular."""
    layout = (pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext,
              params)
    nominal = (n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext)
    work = _scratch(layout, nominal)
    n_q = states.shape[1] // 2
    for i in range(states.shape[0]):
        code = _rate(states[i], i, mode, tau, ref, refd, refdd, kp, kd, gains, offset, layout, nominal, work,
                     applied[i], out[i])
        if code != OK:
            out[i, n_q:] = np.nan


# ---------------------------------------------------------------------- the population (eq. 18)
@njit(nogil=True)
def tracking_objective(states, done, every, angles_ref, n_steps, penalty_weight, offset, joint_parent, n_p):
    """Eq. 18 for J joints from a simulation's states, shape (n_steps + 1, n_state), filled up to
    step ``done``: the RMSE (deg) of the joint angles (the body angles' differences minus the
    offsets) at the motion's samples (every ``every``-th step; desired angles angles_ref (rad),
    shape (samples, J)) over the samples reached and all joints, plus penalty_weight times the
    fraction of the steps not reached. The squared errors are summed sample by sample, joint by
    joint in order; a non-finite RMSE counts as 0."""
    n_b = angles_ref.shape[1]
    count = done // every + 1
    total = 0.0
    for k in range(count):
        y = states[k * every]
        for j in range(n_b):
            p = joint_parent[j]
            z = y[n_p + j] - (y[n_p + p] if p >= 0 else 0.0) - offset[j]
            error = (z - angles_ref[k, j]) * DEGREES_PER_RADIAN
            total += error * error
    rmse = math.sqrt(total / (n_b * count))
    if not math.isfinite(rmse):
        rmse = 0.0
    return rmse + penalty_weight * (1.0 - done / n_steps)


@njit(nogil=True)
def rk4_candidates(y0, dt, n_steps, tau, ref, refd, every, angles_ref, penalty_weight, offset, pt_index, pt_fixed,
                   body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params,
                   n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext, states,
                   rates, applied, objective, first_candidate, stride):
    """Open-loop RK4 (``rk4`` in PD mode with zero gains) and eq. 18 (``tracking_objective``) for
    candidates first_candidate, first_candidate + stride, ... of tau (N m, shape (lam, 2 n_steps + 1,
    J)), for ``fdbench.population.Population``. ref, refd: the half-step references as for ``rk4``
    (unused by an open loop but for the layout of its call); states (n+1, n_state), rates
    (n+1, n_state), applied (n+1, J): this call's work buffers, reused candidate after candidate;
    objective (lam,): filled for the candidates run. Runs without the GIL."""
    n_b = joint_parent.shape[0]
    zero, no_gains = np.zeros(n_b), np.zeros((1, n_b, 2 * n_b))
    n_p = base.shape[0]
    for c in range(first_candidate, tau.shape[0], stride):
        _, done, _ = rk4(y0, dt, n_steps, tau[c], ref, refd, ref, zero, zero, PD, no_gains, offset, pt_index, pt_fixed,
                         body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base, q_ext, params,
                         n_parent, n_offset, n_at_parent, n_at_child, n_owner, n_local, n_index, n_mass, n_q_ext,
                         states, rates, applied)
        objective[c] = tracking_objective(states, done, every, angles_ref, n_steps, penalty_weight, offset,
                                          joint_parent, n_p)
