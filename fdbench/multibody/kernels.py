"""The multibody engine's compiled kernels (see ``fdbench.multibody.engine`` for the formulation):
one RK4 driver of eq. 12 under a feedback law, one inverse dynamics (eq. 3), one sensitivity
derivation, over one data layout (``fdbench.multibody.layout``: named tuples of arrays built once
per ``Engine``, so numba compiles and caches each kernel once for every model of a kind).

Muscles (``layout.Muscles``, entry ``rk4_muscles``: activations and compliant tendons' forces as
states, their moment arms times force as generalised forces) are optional too.
Paths, free joints and external loads are optional arguments, None when a model has none; numba
resolves every ``is None`` test when it compiles, so each pattern of None is its own variant with
none of the absent parts' code. A model of pin joints only (paths, free and loads all None) takes
the banded solve: the angle rows hold no mass and each holds one angle, so the angles are
eliminated and the points' matrix K (inside its envelope) is factored by L D L^T (``_drive``'s
``assemble`` and ``solve``). Any other model takes the dense solve: eq. 12,
(M + alpha J^T J) q'' = Q - alpha J^T (J' q' + 2 xi omega Phi' + omega^2 Phi), over points and
angles together by a Cholesky factorisation inside its envelope, each constraint row kept as its few
nonzero entries (``constraints``):

* a free joint's body has its joint point i among the free points with no constraint to ground;
  its coordinates are the body's angle (minus the offset) and point i's x and y (minus
  ``at_parent``), whose generalised forces (N) act on point i's coordinates;
* a joint with a path ties the child's point i to its parent by two constraints,
  r_i - r_pi - G(theta) e_p = 0 with e_p = r_pj - r_pi, G = c1 I + c2 R90 and (c1, c2) the
  parent-frame point at_parent + path(theta) in the parent's basic-point frame (linear in the
  path's offset s: (c1, c2) = base + L s); on ground, r_i - at_parent - path(theta) = 0;
* external loads from data: F on the body's joint point i and (P - r_i) x F + M on its angle.

The family, one algorithm a module: ``layout`` (the data), ``inverse`` (eq. 3), ``tangents`` (the
sensitivities of a stage), this module (the RK4 driver and its entries) and, above the engine, the
shooting problem's eq. 18 and population (``fdbench.tracking``).

One RK4 driver (``_drive``, called as ``rk4``) serves every feedback law (``Law.mode``): PD (per
coordinate, plus feedforward), COMPUTED (computed torque through the believed model's inverse
dynamics) and GAINS (a full gain matrix on the half-step grid). Its stage code is the only one:
``derivatives`` (the adaptive integrators' right-hand side), ``constraint_violation``,
``rk4_sensitivity`` (the driver runs the tangents after each stage) and the population of
``fdbench.tracking`` all run it. Strict IEEE arithmetic.

Speed (``python benchmarks/bench_engine.py``): numba increments and decrements the reference count
of every array that an inlined function takes at each of its calls whenever the callee branches
or loops, which cost more than the arithmetic. So the stage code is closures over the driver's own
arrays (inlined without such counts), the stages run in one loop, per-body indices and geometry
are hoisted out of it, a step's start reuses the sin and cos of its violation check, and the
banded solve is unrolled for one free point. The operations on every number are those of the plain
formulas.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from .inverse import N_KIN, _inverse, _no_loads, _spline_at
from .inverse import inverse_torques  # noqa: F401 - eq. 3, one of the kernels
from .muscle import (F0, SMOOTHING, TAU_ACT, TAU_DEACT, activation_derivative, activation_partials, compliant_tendon,
                     compliant_tendon_partials, rigid_tendon_force, rigid_tendon_partials)
from .muscle_paths import (N_FRAME, POINTS, _frames, _points_length, _polynomial_hessian, _polynomial_length, _powers,
                           points_hessians)
from .muscles import MAX_POWER
from .tangents import (FORM, LAMBDA, MAX_ENTRIES, N_AUX, N_STAGE, PIVOT, VELOCITY_TERM, _load_in_ground,
                       _stage_sensitivity, _stage_tangents)
from .layout import (ALPHA, AT_PARENT_X, AT_PARENT_Y, BASE_1, BASE_2, BETA, COLUMN, COMPUTED, CONSTRAINT, D, FREE,
                     GAINS, KI, KJ, L_11, L_12, L_21, L_22, LENGTH, LOAD_BODY, MOMENT, NONFINITE, OFFSET, OK, OMEGA2,
                     PARENT, PD, SINGULAR, SWITCH_COS, TWO_XI_OMEGA, VIOLATION, Law)

CHECK, ASSEMBLE = 0, 1  # what the driver's ``constraints`` does with each row
# a muscle's partial derivatives at a stage (the sensitivities' ``muscle_part`` columns): its force
# (N) and dF/da, dF/dl (N/m), dF/dv (N s/m), dF/df_T; its activation rate's d/de, d/da; a compliant
# tendon's rate of f_T: d/da, d/df_T, d/dl, d/dv
(M_FORCE, M_FA, M_FL, M_FV, M_FT, M_AE, M_AA, M_RA, M_RT, M_RL, M_RV, N_MUSCLE_PART) = range(12)


@njit
def n_rows(model, paths):
    """The number of constraint rows of the dense solve: distance and angle per body, the linear
    rows, two per path."""
    return 2 * model.body_int.shape[0] + model.lin_const.shape[0] + (0 if paths is None else 2 * paths.body.shape[0])


# ---------------------------------------------------------------------- the RK4 driver (eq. 12 under a feedback law)
@njit(error_model="numpy")
def _drive(y0, dt, n_steps, start, law, model, paths, free, loads, believed, believed_paths, believed_loads, out,
           residuals, G, param_col, every, dz, muscles):
    """Classical RK4 of eq. 12 over n_steps steps of dt (s) from the state y0 (n_state,) under the
    feedback ``law`` (``layout.Law``), its grid starting at row ``start`` (step i uses rows
    start + 2 i, start + 2 i + 1, start + 2 i + 2); with n_steps 0 the state derivative of y0 alone
    (into rates[0]), with -1 only the constraints of y0 (the returned violation). model, paths,
    free, loads: the plant's layout (``layout``; paths, free, loads None when absent); believed,
    believed_paths, believed_loads: the model computed-torque control believes. out: (states,
    rates (n + 1, n_state), applied (n + 1, J)), filled up to the last step reached. residuals:
    None, or (phi_rows, jv_rows) (n_rows,) to hold the dense solve's Phi and J q' of every
    constraint row at the last state checked or stage run. Returns (status, steps_done, max
    constraint violation).

    With dz not None, also the forward sensitivities of the coordinates (``rk4_sensitivity``; open
    loop only, the torque not depending on the state): G (rows, P) d tau / d p on the grid,
    parameter q moving coordinate param_col[q]'s generalised force; dz (n_steps // every + 1, J, P)
    the derivatives of the coordinates at every ``every``-th step reached.

    With muscles not None (``layout.Muscles``), the state is [q, q'] followed by the muscles'
    activations and their compliant tendons' normalised forces (``rk4_muscles``), and each stage
    adds the muscles' generalised forces (moment arms times force) to the law's torque. With dz
    too, the sensitivities carry the muscle states (their paths' Hessians, the curves'
    and the activation dynamics' derivatives), and a parameter q with param_col[q] = J + m moves
    muscle m's excitation by G[:, q] instead of a generalised force.

    Speed: the stage code is written once, as closures over this function's arrays (numba inlines
    them without the reference counting that array arguments of inlined functions cost at every
    call), and runs in a loop over the four stages; ``state`` holds the stage's state, ``ks`` 0 to
    3 its derivatives k1 to k4. The operations on every number are the plain formulas'."""
    tau, ref, refd, refdd, kp, kd, mode, gains = law
    states, rates, applied = out
    pt_index, pt_fixed, body_pts, body_geom = model.pt_index, model.pt_fixed, model.body_pts, model.body_geom
    joint_parent, offset, first, base = model.joint_parent, model.offset, model.first, model.base
    lin_idx, lin_coef, lin_const = model.lin_idx, model.lin_coef, model.lin_const
    mass, q_ext, params = model.mass, model.q_ext, model.params
    body_int, body_float, dense_first = model.body_int, model.body_float, model.dense_first
    n_b, n_p = body_int.shape[0], mass.shape[0]
    n_q = n_p + n_b
    n_muscles, n, framed = 0, 2 * n_q, 0
    if muscles is not None:  # the muscle states after [q, q']: activations, compliant tendons' forces
        n_muscles = muscles.params.shape[0]
        n += n_muscles
        for m in range(n_muscles):
            if muscles.tendon_row[m] >= 0:
                n += 1
            if muscles.paths.kind[m] == POINTS:  # the bodies' frames needed
                framed = body_int.shape[0] + 1
    J = tau.shape[1]
    alpha, txo, om2, switch = params[ALPHA], params[TWO_XI_OMEGA], params[OMEGA2], params[SWITCH_COS]
    p4 = 4 * alpha
    one_point = n_p == 2 and first[1] == 0  # one free point: the banded solve's unrolled form
    load_frames, load_values = _no_loads(loads)
    believed_frames, believed_values = _no_loads(believed_loads)
    if paths is None:
        path_body, path_float = np.zeros(0, dtype=np.int64), np.zeros((0, L_22 + 1))
        knots, spline_start = np.zeros((0, 5)), np.zeros(1, dtype=np.int64)
    else:
        path_body, path_float, knots, spline_start = paths.body, paths.maps, paths.knots, paths.start
    if residuals is None:
        phi_rows, jv_rows = np.empty(n_rows(model, paths)), np.empty(n_rows(model, paths))
    else:
        phi_rows, jv_rows = residuals[0], residuals[1]
    y, state, ks = np.empty(n), np.empty(n), np.empty((4, n))
    torque, z, zd, v, err = np.empty(J), np.empty(J), np.empty(J), np.empty(J), np.empty(J)
    kin, points = np.zeros((believed.body_int.shape[0], N_KIN)), np.zeros((3, believed.mass.shape[0]))
    # the muscles' scratch (``muscle_paths.geometry``'s) and their lengths (m) and moment arms (M, J)
    muscle_frames, muscle_slopes = np.zeros((framed, N_FRAME)), np.zeros((framed, N_FRAME, J))
    muscle_points = np.zeros((2 if n_muscles else 0, 3, max(2, J)))
    muscle_length, muscle_arms = np.zeros(n_muscles), np.zeros((n_muscles, J))
    muscle_powers = np.zeros((J if n_muscles else 0, 2, MAX_POWER + 1))  # the coordinates' powers
    rhs = np.zeros(n_q)  # the right-hand side, then the solution (the banded solve: its first n_p)
    K, aux, q_phi = np.zeros((n_p, n_p)), np.zeros((n_b, N_AUX)), np.zeros(n_b)  # the banded solve's
    trig, shape, ends = np.zeros((n_b, 2)), np.zeros((n_b, 4)), np.empty((n_b, 2), dtype=np.int64)
    A = np.empty((n_q, n_q))  # the dense solve's
    idx, val = np.empty(MAX_ENTRIES, dtype=np.int64), np.empty(MAX_ENTRIES)
    # the constraint rows ``constraints`` keeps for ``row``: entries, count, value, velocity term
    n_dense = phi_rows.shape[0]
    kept_idx, kept_val = np.empty((n_dense, MAX_ENTRIES), dtype=np.int64), np.empty((n_dense, MAX_ENTRIES))
    kept_count, kept_phi, kept_jdv = np.empty(n_dense, dtype=np.int64), np.empty(n_dense), np.empty(n_dense)
    for m in range(n):
        y[m] = y0[m]
    # per body, hoisted: the coordinate indices of its points i and j (i: FIXED on ground), and its
    # d (m), beta (rad) and point i's position (m) where it is fixed
    for b in range(n_b):
        ends[b, 0], ends[b, 1] = pt_index[body_pts[b, 0]], pt_index[body_pts[b, 1]]
        shape[b, 0], shape[b, 1] = body_geom[b, LENGTH], body_geom[b, BETA]
        shape[b, 2], shape[b, 3] = pt_fixed[body_pts[b, 0], 0], pt_fixed[body_pts[b, 0], 1]
    # the sensitivities: S = dy/dp, the stage's input U and derivative dk, their RK4 sum acc; the
    # dense solve's D = d(b - A x)/dy (jac), then A^-1 D; force_rows (n_q, J): where each
    # coordinate's force enters b; the banded solve's tangents' scratch (``dz is None`` tests are
    # resolved when numba compiles: a kernel without sensitivities has none of their code)
    P = 0 if G is None else G.shape[1]
    ns = 0 if dz is None else n
    S, U, acc, dk = np.zeros((ns, P)), np.zeros((ns, P)), np.zeros((ns, P)), np.zeros((ns, P))
    n_qs = 0 if dz is None else n_q
    jac, moved = np.zeros((n_qs, n)), np.zeros((n_qs, P))
    force_rows, solved_rows = np.zeros((n_qs, J)), np.zeros((n_qs, J))
    # the muscles' sensitivities: per muscle its partials, path Hessian (J, J) and Hessian times q';
    # the directions' coordinates and rates dzq, dzdq (J, P), the muscles' generalised forces' change
    # dtm (J, P) and on the body angles muscle_dtau (the banded solve's)
    n_mt = 0 if dz is None else n_muscles
    muscle_part, muscle_hess = np.zeros((n_mt, N_MUSCLE_PART)), np.zeros((n_mt, J, J))
    muscle_hzd = np.zeros((n_mt, J))
    muscle_curves = np.zeros((framed if dz is not None else 0, 2, J, J))  # the origins' second derivatives
    dzq, dzdq, dtm = np.zeros((J if n_mt else 0, P)), np.zeros((J if n_mt else 0, P)), np.zeros((J if n_mt else 0, P))
    muscle_dtau = np.zeros((n_b if n_mt else 0, P))
    n_kept = 0 if dz is None else phi_rows.shape[0]  # per constraint row: its entries, Hessian, term
    row_count, row_term = np.zeros(n_kept, dtype=np.int64), np.zeros(n_kept)
    row_idx, row_val = np.zeros((n_kept, MAX_ENTRIES), dtype=np.int64), np.zeros((n_kept, MAX_ENTRIES))
    row_third, row_hess = np.zeros((n_kept, MAX_ENTRIES)), np.zeros((n_kept, MAX_ENTRIES, MAX_ENTRIES))
    path_kept = np.zeros((path_body.shape[0] if dz is not None else 0, 12))  # per path: its first row, geometry
    kept_rows = (row_count, row_term, row_idx, row_val, row_hess, row_third)
    nb_s = 0 if dz is None else n_b
    torque_sign = np.zeros((nb_s, P))  # the banded tangents: coordinate -> generalised forces of the body angles
    tangent_work = (np.empty((nb_s, N_STAGE)), np.empty(n_p if dz is not None else 0), np.empty((nb_s, P)),
                    np.empty((n_p if dz is not None else 0, P)), np.empty((nb_s, P)), np.empty((nb_s, P)),
                    np.empty((nb_s, P)), dk)
    factor = (K, rhs, aux)
    banded_layout = (pt_index, pt_fixed, body_pts, body_geom, joint_parent, lin_idx, lin_coef, lin_const, first, base,
                     q_ext, params)
    if dz is not None:
        for k in range(n_b):
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            force_rows[n_p + k, col] += 1.0
            if p >= 0:
                force_rows[n_p + p, col] -= 1.0
            if body_int[k, FREE] == 1:
                force_rows[body_int[k, KI], col + 1] += 1.0
                force_rows[body_int[k, KI] + 1, col + 2] += 1.0
        if paths is None and free is None and loads is None:  # the banded solve: a coordinate per body
            for q in range(P):
                if param_col[q] < J:  # not an excitation
                    torque_sign[param_col[q], q] = 1.0
                    if joint_parent[param_col[q]] >= 0:
                        torque_sign[joint_parent[param_col[q]], q] = -1.0

    def point(b):
        """x, y, x', y' of body b's point i in the stage's state (fixed: its position, zero velocity)."""
        k = ends[b, 0]
        if k < 0:
            return shape[b, 2], shape[b, 3], 0.0, 0.0
        return state[k], state[k + 1], state[n_q + k], state[n_q + k + 1]

    # ------------------------------------------------------------------ the banded solve (pin joints)
    def violation():
        """max |Phi_i| (m^2 and m) of the stage's state: distances, angles (the form in force), linear;
        sin and cos of the bodies' angles into trig, for the state's first stage."""
        worst = 0.0
        for b in range(n_b):
            xi, yi, _, _ = point(b)
            kj = ends[b, 1]
            dx, dy, d = state[kj] - xi, state[kj + 1] - yi, shape[b, 0]
            psi = state[n_p + b] + shape[b, 1]
            s, c = math.sin(psi), math.cos(psi)
            trig[b, 0], trig[b, 1] = s, c
            angle = dy - d * s if abs(c) >= switch else dx - d * c
            worst = max(worst, max(abs(dx * dx + dy * dy - d * d), abs(angle)))
        for r in range(lin_const.shape[0]):
            value = lin_const[r]
            for e in range(lin_idx.shape[1]):
                if lin_idx[r, e] >= 0:
                    value += lin_coef[r, e] * state[lin_idx[r, e]]
            worst = max(worst, abs(value))
        return worst

    def assemble(carried):
        """The points' matrix K (its envelope) and right-hand side rhs of eq. 12 at the stage's state
        under the joint torques, and per body the angle row's values into aux. carried: the state's
        sin and cos are those in trig (the state's violation was computed)."""
        for k in range(n_b):  # joint torques -> generalised forces of the absolute angles
            q_phi[k] = torque[k]
        for k in range(n_b):
            if joint_parent[k] >= 0:
                q_phi[joint_parent[k]] -= torque[k]
        for r in range(n_p):
            rhs[r] = q_ext[r]
            for c in range(first[r], r + 1):
                K[r, c] = base[r, c]
        for r in range(lin_const.shape[0]):  # linear constraints: their J^T J is in base
            phi, rate = lin_const[r], 0.0
            for e in range(lin_idx.shape[1]):
                k = lin_idx[r, e]
                if k >= 0:
                    phi += lin_coef[r, e] * state[k]
                    rate += lin_coef[r, e] * state[n_q + k]
            cc = alpha * (txo * rate + om2 * phi)
            for e in range(lin_idx.shape[1]):
                k = lin_idx[r, e]
                if k >= 0:
                    rhs[k] -= lin_coef[r, e] * cc
        for b in range(n_b):
            ki, kj = ends[b, 0], ends[b, 1]
            xi, yi, vxi, vyi = point(b)
            xj, yj, vxj, vyj = state[kj], state[kj + 1], state[n_q + kj], state[n_q + kj + 1]
            dx, dy, dvx, dvy = xj - xi, yj - yi, vxj - vxi, vyj - vyi
            d = shape[b, 0]
            w = state[n_q + n_p + b]
            if carried:
                s, c = trig[b, 0], trig[b, 1]
            else:
                psi = state[n_p + b] + shape[b, 1]
                s, c = math.sin(psi), math.cos(psi)
            # distance: Phi = |dr|^2 - d^2, J = 2 dr on j, -2 dr on i
            cd = 2 * (dvx * dvx + dvy * dvy) + txo * 2 * (dx * dvx + dy * dvy) + om2 * (dx * dx + dy * dy - d * d)
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
            if abs(c) >= switch:  # the sin form, (y_j - y_i) - d sin(psi)
                pivot = -d * c
                ca = d * s * w * w + txo * (dvy - d * c * w) + om2 * (dy - d * s)
                axis = 1
            else:  # the cos form, (x_j - x_i) - d cos(psi)
                pivot = d * s
                ca = d * c * w * w + txo * (dvx + d * s * w) + om2 * (dx - d * c)
                axis = 0
            lam = q_phi[b] / pivot
            rhs[kj + axis] -= lam
            if ki >= 0:
                rhs[ki + axis] += lam
            aux[b, LAMBDA], aux[b, PIVOT], aux[b, VELOCITY_TERM], aux[b, FORM] = lam, pivot, ca, axis

    def solve_banded():
        """Solve K x = rhs in place (x into rhs) for K symmetric positive definite, its lower triangle
        given inside the envelope first[r] <= c <= r, by L D L^T (L into K's strict lower triangle, D
        on its diagonal). Returns OK, NONFINITE for a pivot that is NaN, or SINGULAR for one that is
        not positive (rank lost; rhs is then unfinished)."""
        if one_point:  # the same operations, unrolled for one free point (a 2 x 2 matrix)
            if math.isnan(K[0, 0]):
                return NONFINITE
            if not K[0, 0] > 0.0:
                return SINGULAR
            l10 = K[1, 0] / K[0, 0]
            diag = K[1, 1] - l10 * K[1, 0]
            if math.isnan(diag):
                return NONFINITE
            if not diag > 0.0:
                return SINGULAR
            K[1, 0], K[1, 1] = l10, diag
            rhs[1] = (rhs[1] - l10 * rhs[0]) / diag
            rhs[0] = rhs[0] / K[0, 0] - l10 * rhs[1]
            return OK
        status = OK
        for r in range(n_p):
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
                status = NONFINITE
                break
            if not diag > 0.0:
                status = SINGULAR
                break
            K[r, r] = diag
        if status == OK:
            for r in range(n_p):  # L z = rhs
                total = rhs[r]
                for k in range(first[r], r):
                    total -= K[r, k] * rhs[k]
                rhs[r] = total
            for r in range(n_p):
                rhs[r] /= K[r, r]
            for r in range(n_p - 1, -1, -1):  # L^T x = z, column by column
                x = rhs[r]
                for k in range(first[r], r):
                    rhs[k] -= K[r, k] * x
        return status

    # ------------------------------------------------------------------ the dense solve (free and path joints, loads)
    def keep(r, phi, jdv, count):
        """Constraint row r of value phi and velocity term J' q' jdv, its count nonzero entries in
        idx, val, kept for ``row`` (``constraints`` sends every row to it from one call: numba inlines
        a closure's code at each of its calls, and compile time grows with it). Returns |phi|."""
        for e in range(count):
            kept_idx[r, e], kept_val[r, e] = idx[e], val[e]
        kept_count[r], kept_phi[r], kept_jdv[r] = count, phi, jdv
        return abs(phi)

    def row(r, task):
        """Constraint row r as ``keep`` has it (value phi, velocity term J' q' jdv, its count nonzero
        entries, copied into idx, val): Phi and J q' into phi_rows, jv_rows; in task ASSEMBLE, its
        alpha J^T J into A's lower triangle and -alpha J^T (J' q' + 2 xi omega J q' + omega^2 Phi)
        into rhs, and with the sensitivities its entries and that term into the row_* arrays
        (``constraints`` puts its Hessian H and third derivative T(q', q', .) on those entries into
        row_hess, row_third)."""
        count, phi, jdv = kept_count[r], kept_phi[r], kept_jdv[r]
        for e in range(count):
            idx[e], val[e] = kept_idx[r, e], kept_val[r, e]
        jv = 0.0
        for e in range(count):
            jv += val[e] * state[n_q + idx[e]]
        phi_rows[r], jv_rows[r] = phi, jv
        if dz is not None and task == ASSEMBLE:  # kept for ``_stage_tangents`` (the sites keep H and T)
            row_count[r], row_term[r] = count, jdv + txo * jv + om2 * phi
            for e in range(count):
                row_idx[r, e], row_val[r, e] = idx[e], val[e]
        if task == ASSEMBLE:
            cc = alpha * (jdv + txo * jv + om2 * phi)
            for e in range(count):
                rhs[idx[e]] -= val[e] * cc
                for f in range(count):
                    if idx[e] >= idx[f]:
                        A[idx[e], idx[f]] += alpha * val[e] * val[f]

    def constraints(task):
        """Every constraint row at the stage's state (``row`` in task CHECK or ASSEMBLE): the bodies'
        distance and angle rows (the form in force), the linear rows, two rows per path. Returns max
        |Phi| (m^2 and m). Every test of the task compares it with a constant and every test of the
        sensitivities dz with None, so that numba drops the code of the others from each (inlined) call."""
        worst, r = 0.0, 0
        for b in range(n_b):
            ki, kj = body_int[b, KI], body_int[b, KJ]
            xi, yi, vxi, vyi = point(b)
            ex, ey, evx, evy = state[kj] - xi, state[kj + 1] - yi, state[n_q + kj] - vxi, state[n_q + kj + 1] - vyi
            d = body_float[b, D]
            idx[0], val[0], idx[1], val[1] = kj, 2 * ex, kj + 1, 2 * ey
            if ki >= 0:
                idx[2], val[2], idx[3], val[3] = ki, -2 * ex, ki + 1, -2 * ey
            if dz is not None and task == ASSEMBLE:  # |e|^2 - d^2: H = 2 on (j, j), (i, i), -2 on (i, j) per axis
                hess = row_hess[r]
                hess[0, 0], hess[1, 1] = 2.0, 2.0
                if ki >= 0:
                    hess[2, 2], hess[3, 3] = 2.0, 2.0
                    hess[0, 2], hess[2, 0], hess[1, 3], hess[3, 1] = -2.0, -2.0, -2.0, -2.0
            worst = max(worst, keep(r, ex * ex + ey * ey - d * d, 2 * (evx * evx + evy * evy), 4 if ki >= 0 else 2))
            psi, w = state[n_p + b] + body_float[b, BETA], state[n_q + n_p + b]
            s, c = math.sin(psi), math.cos(psi)
            if abs(c) >= switch:  # the sin form, (y_j - y_i) - d sin(psi)
                axis, phi, pivot, jdv = 1, ey - d * s, -d * c, d * s * w * w
            else:  # the cos form, (x_j - x_i) - d cos(psi)
                axis, phi, pivot, jdv = 0, ex - d * c, d * s, d * c * w * w
            idx[0], val[0], idx[1], val[1] = kj + axis, 1.0, n_p + b, pivot
            if ki >= 0:
                idx[2], val[2] = ki + axis, -1.0
            if dz is not None and task == ASSEMBLE:  # d2 Phi / d psi2 and d3 Phi / d psi3 w^2 of the form
                row_hess[r + 1, 1, 1] = d * s if axis == 1 else d * c
                row_third[r + 1, 1] = d * c * w * w if axis == 1 else -d * s * w * w
            worst = max(worst, keep(r + 1, phi, jdv, 3 if ki >= 0 else 2))
            r += 2
        for lr in range(lin_const.shape[0]):
            total, count = 0.0, 0
            for e in range(lin_idx.shape[1]):
                if lin_idx[lr, e] >= 0:
                    total += lin_coef[lr, e] * state[lin_idx[lr, e]]
                    idx[count], val[count] = lin_idx[lr, e], lin_coef[lr, e]
                    count += 1
            worst = max(worst, keep(r, total + lin_const[lr], 0.0, count))
            r += 1
        for m in range(path_body.shape[0]):
            k = path_body[m]
            p, ki = body_int[k, PARENT], body_int[k, KI]
            theta = state[n_p + k] - (state[n_p + p] if p >= 0 else 0.0) - body_float[k, OFFSET]
            rate = state[n_q + n_p + k] - (state[n_q + n_p + p] if p >= 0 else 0.0)
            sx0, sx1, sx2, sx3 = _spline_at(knots, spline_start[2 * m], spline_start[2 * m + 1], theta)
            sy0, sy1, sy2, sy3 = _spline_at(knots, spline_start[2 * m + 1], spline_start[2 * m + 2], theta)
            if p < 0:  # on ground: r_i - at_parent - s(theta)
                idx[0], val[0], idx[1], val[1] = ki, 1.0, n_p + k, -sx1
                if dz is not None and task == ASSEMBLE:
                    row_hess[r, 1, 1], row_third[r, 1] = -sx2, -sx3 * rate * rate
                worst = max(worst, keep(r, state[ki] - body_float[k, AT_PARENT_X] - sx0, -sx2 * rate * rate, 2))
                idx[0], val[0], idx[1], val[1] = ki + 1, 1.0, n_p + k, -sy1
                if dz is not None and task == ASSEMBLE:
                    row_hess[r + 1, 1, 1], row_third[r + 1, 1] = -sy2, -sy3 * rate * rate
                worst = max(worst, keep(r + 1, state[ki + 1] - body_float[k, AT_PARENT_Y] - sy0, -sy2 * rate * rate,
                                       2))
                r += 2
                continue
            pi, pj = body_int[p, KI], body_int[p, KJ]
            xpi, ypi, vxpi, vypi = point(p)
            ex, ey = state[pj] - xpi, state[pj + 1] - ypi
            evx, evy = state[n_q + pj] - vxpi, state[n_q + pj + 1] - vypi
            f = path_float[m]
            c0a, c0b = f[BASE_1] + (f[L_11] * sx0 + f[L_12] * sy0), f[BASE_2] + (f[L_21] * sx0 + f[L_22] * sy0)
            c1a, c1b = f[L_11] * sx1 + f[L_12] * sy1, f[L_21] * sx1 + f[L_22] * sy1
            c2a, c2b = f[L_11] * sx2 + f[L_12] * sy2, f[L_21] * sx2 + f[L_22] * sy2
            # G(c, x) = c_a x + c_b R90 x; the angle columns -G(c1, e_p) on the child, + on the parent
            tx, ty = -(c1a * ex - c1b * ey), -(c1a * ey + c1b * ex)
            jx = -2 * (c1a * evx - c1b * evy) * rate - (c2a * ex - c2b * ey) * rate * rate
            jy = -2 * (c1a * evy + c1b * evx) * rate - (c2a * ey + c2b * ex) * rate * rate
            for axis in range(2):
                if axis == 0:
                    phi, t, jdv = state[ki] - xpi - (c0a * ex - c0b * ey), tx, jx
                    gj0, gj1 = c0a, -c0b  # row 0 of G's matrix [[c0a, -c0b], [c0b, c0a]]
                else:
                    phi, t, jdv = state[ki + 1] - ypi - (c0a * ey + c0b * ex), ty, jy
                    gj0, gj1 = c0b, c0a
                idx[0], val[0] = ki + axis, 1.0
                idx[1], val[1], idx[2], val[2] = pj, -gj0, pj + 1, -gj1
                idx[3], val[3], idx[4], val[4] = n_p + k, t, n_p + p, -t
                count = 5
                if pi >= 0:
                    idx[5], val[5] = pi, gj0 - (1.0 if axis == 0 else 0.0)
                    idx[6], val[6] = pi + 1, gj1 - (1.0 if axis == 1 else 0.0)
                    count = 7
                worst = max(worst, keep(r + axis, phi, jdv, count))
            if dz is not None and task == ASSEMBLE:  # for ``_path_hessian``
                path_kept[m, 0], path_kept[m, 1], path_kept[m, 2], path_kept[m, 3] = r, ex, ey, evx
                path_kept[m, 4], path_kept[m, 5], path_kept[m, 6], path_kept[m, 7] = evy, rate, c1a, c1b
                path_kept[m, 8], path_kept[m, 9] = c2a, c2b
                path_kept[m, 10] = f[L_11] * sx3 + f[L_12] * sy3
                path_kept[m, 11] = f[L_21] * sx3 + f[L_22] * sy3
            r += 2
        for k in range(r):
            row(k, task)
        return worst

    def coordinates():
        """The coordinates z and rates zd (J,) of the stage's state."""
        for k in range(n_b):
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            z[col] = state[n_p + k] - (state[n_p + p] if p >= 0 else 0.0) - body_float[k, OFFSET]
            zd[col] = state[n_q + n_p + k] - (state[n_q + n_p + p] if p >= 0 else 0.0)
            if body_int[k, FREE] == 1:
                ki = body_int[k, KI]
                z[col + 1] = state[ki] - body_float[k, AT_PARENT_X]
                z[col + 2] = state[ki + 1] - body_float[k, AT_PARENT_Y]
                zd[col + 1], zd[col + 2] = state[n_q + ki], state[n_q + ki + 1]

    def solve_dense():
        """Solve A x = rhs in place (x into rhs) by the Cholesky factor L of A's lower triangle (into
        it), row by row inside the envelope dense_first[r] <= c <= r (which L keeps). Returns OK,
        NONFINITE for a matrix that is not finite, SINGULAR for one that is not positive definite."""
        for r in range(n_q):
            for c in range(dense_first[r], r + 1):
                if not math.isfinite(A[r, c]):
                    return NONFINITE
        for r in range(n_q):
            fr = dense_first[r]
            for c in range(fr, r):
                total = A[r, c]
                for k in range(max(fr, dense_first[c]), c):
                    total -= A[r, k] * A[c, k]
                A[r, c] = total / A[c, c]
            diag = A[r, r]
            for k in range(fr, r):
                diag -= A[r, k] * A[r, k]
            if not diag > 0.0:
                return SINGULAR
            A[r, r] = math.sqrt(diag)
        for r in range(n_q):  # L w = rhs
            total = rhs[r]
            for k in range(dense_first[r], r):
                total -= A[r, k] * rhs[k]
            rhs[r] = total / A[r, r]
        for r in range(n_q - 1, -1, -1):  # L^T x = w, column by column
            x = rhs[r] / A[r, r]
            rhs[r] = x
            for k in range(dense_first[r], r):
                rhs[k] -= A[r, k] * x
        return OK

    def muscle_forces(stage, half):
        """The muscles at the stage's state: their generalised forces (moment arms times force, N m;
        N for a translation) onto torque, their states' derivatives (activation dynamics under the
        excitations of grid row half; a compliant tendon's normalised force) into ks[stage]."""
        coordinates()
        geometry = muscles.paths
        if framed:
            _frames(z, geometry, muscle_frames, muscle_slopes)
            if dz is not None:  # a plain kernel's one call: compiled once, not inlined into each variant
                points_hessians(z, geometry, muscle_frames, muscle_slopes, muscle_curves, muscle_hess)
        _powers(z, geometry, muscle_powers)
        after = 2 * n_q
        for m in range(n_muscles):
            arm = muscle_arms[m]
            if geometry.kind[m] == POINTS:
                length = _points_length(geometry, m, muscle_frames, muscle_slopes, muscle_points, arm, n_b)
            else:
                length = _polynomial_length(geometry, m, arm, muscle_powers)
            lengthening = 0.0
            for j in range(J):
                lengthening -= arm[j] * zd[j]
            p = muscles.params[m]
            activation, tendon = state[after + m], muscles.tendon_row[m]
            if tendon < 0:
                force = rigid_tendon_force(activation, length, lengthening, p)
            else:
                force, rate = compliant_tendon(activation, state[after + tendon], length, lengthening, p)
                ks[stage, after + tendon] = rate
            ks[stage, after + m] = activation_derivative(muscles.excitation[half, m], activation, p[TAU_ACT],
                                                        p[TAU_DEACT], p[SMOOTHING])
            for j in range(J):
                torque[j] += arm[j] * force
            if dz is not None:  # the partials the sensitivities need (``muscle_tangents``)
                part = muscle_part[m]
                if geometry.kind[m] != POINTS:  # a path of points' from ``points_hessians`` above
                    _polynomial_hessian(geometry, m, muscle_hess[m], muscle_powers)
                for i in range(J):
                    total = 0.0
                    for k in range(J):
                        total += muscle_hess[m, k, i] * zd[k]
                    muscle_hzd[m, i] = total
                part[M_FORCE] = force
                if tendon < 0:
                    part[M_FA], part[M_FL], part[M_FV] = rigid_tendon_partials(activation, length, lengthening, p)
                    part[M_FT] = 0.0
                else:
                    part[M_FA], part[M_FL], part[M_FV], part[M_FT] = 0.0, 0.0, 0.0, p[F0]
                    part[M_RA], part[M_RT], part[M_RL], part[M_RV] = compliant_tendon_partials(
                        activation, state[after + tendon], length, lengthening, p)
                part[M_AE], part[M_AA] = activation_partials(muscles.excitation[half, m], activation, p[TAU_ACT],
                                                             p[TAU_DEACT], p[SMOOTHING])

    def muscle_tangents(half):
        """The muscles' part of the stage's tangents in the directions U: the change of their
        generalised forces into dtm (J, P) (d(arm F) = -H dz F + arm dF, with dl = -arm . dz and
        dv = (H q') . dz - arm . dz'), and their states' rows of dk (an excitation parameter moving its
        muscle's activation rate), from the partials ``muscle_forces`` kept."""
        for k in range(n_b):  # the directions' coordinates and rates
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            for q in range(P):
                dzq[col, q] = U[n_p + k, q] - (U[n_p + p, q] if p >= 0 else 0.0)
                dzdq[col, q] = U[n_q + n_p + k, q] - (U[n_q + n_p + p, q] if p >= 0 else 0.0)
                if body_int[k, FREE] == 1:
                    ki = body_int[k, KI]
                    dzq[col + 1, q], dzq[col + 2, q] = U[ki, q], U[ki + 1, q]
                    dzdq[col + 1, q], dzdq[col + 2, q] = U[n_q + ki, q], U[n_q + ki + 1, q]
        dtm[:, :] = 0.0
        after = 2 * n_q
        for m in range(n_muscles):
            part, arm, hess, tendon = muscle_part[m], muscle_arms[m], muscle_hess[m], muscles.tendon_row[m]
            force = part[M_FORCE]
            for q in range(P):
                dl, dv = 0.0, 0.0
                for j in range(J):
                    dl -= arm[j] * dzq[j, q]
                    dv += muscle_hzd[m, j] * dzq[j, q] - arm[j] * dzdq[j, q]
                da = U[after + m, q]
                df = part[M_FL] * dl + part[M_FV] * dv + part[M_FA] * da
                if tendon >= 0:
                    dt_ = U[after + tendon, q]
                    df += part[M_FT] * dt_
                    dk[after + tendon, q] = part[M_RA] * da + part[M_RT] * dt_ + part[M_RL] * dl + part[M_RV] * dv
                rate = part[M_AA] * da
                if param_col[q] == J + m:
                    rate += part[M_AE] * G[half, q]
                dk[after + m, q] = rate
                for j in range(J):
                    bend = 0.0
                    for i in range(J):
                        bend += hess[j, i] * dzq[i, q]
                    dtm[j, q] += arm[j] * df - bend * force

    # ------------------------------------------------------------------ either solve
    def check():
        """max |Phi_i| (m^2 and m) of the stage's state (the value the steps check)."""
        if paths is None and free is None and loads is None:
            return violation()
        return constraints(CHECK)

    def law(half):
        """The applied generalised forces (N m; N for a free joint's x and y) at the stage's state and
        grid row ``half`` into torque, under ``law``'s mode: the errors e = ref - z, e' = refd - zd
        (for pin joints taken as (ref + offset) - (the body angles' difference), z then less the
        offsets for the inverse dynamics)."""
        if paths is None and free is None and loads is None:
            for k in range(n_b):
                p = joint_parent[k]
                z[k] = state[n_p + k] - (state[n_p + p] if p >= 0 else 0.0)
                zd[k] = state[n_q + n_p + k] - (state[n_q + n_p + p] if p >= 0 else 0.0)
                err[k] = (ref[half, k] + offset[k]) - z[k]
        else:
            coordinates()
            for k in range(J):
                err[k] = ref[half, k] - z[k]
        if mode == GAINS:
            for k in range(J):  # term by term onto tau: K = [diag kp, diag kd] gives PD's numbers to the bit
                total = tau[half, k]
                for j in range(J):
                    total += gains[half, k, j] * err[j]
                for j in range(J):
                    total += gains[half, k, J + j] * (refd[half, j] - zd[j])
                torque[k] = total
        elif mode == COMPUTED:
            for k in range(J):
                v[k] = refdd[half, k] + kp[k] * err[k] + kd[k] * (refd[half, k] - zd[k])
            if paths is None and free is None and loads is None:
                for k in range(n_b):
                    z[k] -= offset[k]
            _inverse(z, zd, v, believed, believed_paths, believed_frames,
                     believed_values[half if believed_values.shape[1] > 0 else 0], kin, points, torque)
            for k in range(J):
                torque[k] += tau[half, k]
        else:
            for k in range(J):
                torque[k] = tau[half, k] + kp[k] * err[k] + kd[k] * (refd[half, k] - zd[k])

    def derivative(stage, half):
        """y' = [q', q''] of eq. 12 at the stage's state under torque (and the loads of grid row half)
        into ks[stage] (stage 0: the step's start, whose sin and cos the banded solve takes from
        trig). Returns OK, or the solve's status (then the accelerations are left unfinished)."""
        for k in range(n_q):
            ks[stage, k] = state[n_q + k]
        if paths is None and free is None and loads is None:
            assemble(stage == 0)
            status = solve_banded()
            if status == OK:
                for r in range(n_p):
                    ks[stage, n_q + r] = rhs[r]
                for b in range(n_b):
                    ki, kj = ends[b, 0], ends[b, 1]
                    axis = int(aux[b, FORM])
                    rel = rhs[kj + axis] - (rhs[ki + axis] if ki >= 0 else 0.0)
                    ks[stage, n_q + n_p + b] = (aux[b, LAMBDA] / alpha - aux[b, VELOCITY_TERM] - rel) / aux[b, PIVOT]
            return status
        for r in range(n_q):
            for c in range(dense_first[r], r + 1):
                A[r, c] = mass[r, c] if r < n_p else 0.0
            rhs[r] = q_ext[r] if r < n_p else 0.0
        for k in range(n_b):  # generalised forces: a joint's torque on its child's and parent's angles
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            rhs[n_p + k] += torque[col]
            if p >= 0:
                rhs[n_p + p] -= torque[col]
            if body_int[k, FREE] == 1:
                rhs[body_int[k, KI]] += torque[col + 1]
                rhs[body_int[k, KI] + 1] += torque[col + 2]
        values = load_values[half if load_values.shape[1] > 0 else 0]
        for k in range(load_frames.shape[0]):  # external loads: F on the body's point i, (P - r_i) x F + M on its angle
            fx, fy, px, py = _load_in_ground(values, k, load_frames, body_int, body_float, state, n_p, n_q)
            b = load_frames[k, LOAD_BODY]
            xi, yi, _, _ = point(b)
            if body_int[b, KI] >= 0:
                rhs[body_int[b, KI]] += fx
                rhs[body_int[b, KI] + 1] += fy
            rhs[n_p + b] += (px - xi) * fy - (py - yi) * fx + values[k, MOMENT]
        if dz is not None:  # the rows' Hessians, filled where nonzero by the assembly
            row_hess[:], row_third[:] = 0.0, 0.0
        constraints(ASSEMBLE)
        status = solve_dense()
        if status == OK:
            for r in range(n_q):
                ks[stage, n_q + r] = rhs[r]
        return status

    def coordinate_sensitivities(sample):
        """dz[sample] = the coordinates' rows of S: a body's angle minus its parent's, a free joint's
        point i."""
        for k in range(n_b):
            p, col = body_int[k, PARENT], body_int[k, COLUMN]
            for q in range(P):
                dz[sample, col, q] = S[n_p + k, q] - (S[n_p + p, q] if p >= 0 else 0.0)
                if body_int[k, FREE] == 1:
                    dz[sample, col + 1, q] = S[body_int[k, KI], q]
                    dz[sample, col + 2, q] = S[body_int[k, KI] + 1, q]

    for m in range(n):
        state[m] = y[m]
    max_viol, code = 0.0, OK
    for i in range(max(n_steps, 0) + 1):
        # the state reached (the given one at i = 0) is checked at the driver's one call of
        # ``check``: numba inlines a closure's code at each of its calls, and compile time grows with it
        viol = check()
        if i > 0 and viol > params[VIOLATION]:
            return CONSTRAINT, i - 1, max(max_viol, viol)
        max_viol = viol if i == 0 else max(max_viol, viol)
        if n_steps < 0:
            break
        if i > 0:
            if dz is not None:
                for m in range(n):
                    for q in range(P):
                        S[m, q] += dt / 6.0 * acc[m, q]
            for m in range(n):
                y[m] = state[m]
        j = start + 2 * i
        for stage in range(4):  # k1 at y, k2 and k3 at the half step, k4 at the full step
            if stage > 0:
                h = dt if stage == 3 else 0.5 * dt
                for m in range(n):
                    state[m] = y[m] + h * ks[stage - 1, m]
            half = j + (stage + 1) // 2
            law(half)
            if muscles is not None:
                muscle_forces(stage, half)
            code = derivative(stage, half)
            if stage == 0:
                for m in range(n):
                    states[i, m] = y[m]
                    if paths is None and free is None and loads is None:
                        rates[i, m] = ks[0, m]
                    else:
                        rates[i, m] = ks[0, m] if (code == OK or m < n_q) else np.nan
                for m in range(J):
                    applied[i, m] = torque[m]
                if dz is not None:
                    if i % every == 0 and i // every < dz.shape[0]:
                        coordinate_sensitivities(i // every)
            if code != OK or i == n_steps:
                break
            if dz is not None:  # dk of this stage: acc += weight dk, U = S + (the next stage's step) dk
                if stage == 0:
                    for m in range(n):
                        for q in range(P):
                            U[m, q], acc[m, q] = S[m, q], 0.0
                weight = 1.0 if stage == 0 or stage == 3 else 2.0
                next_step = 0.5 * dt if stage < 2 else (dt if stage == 2 else 0.0)
                if muscles is not None:
                    muscle_tangents(half)
                if paths is None and free is None and loads is None:
                    if muscles is None:
                        _stage_sensitivity(state, ks[stage], S, U, acc, weight, next_step, half, G, torque_sign, None,
                                           factor, tangent_work, banded_layout)
                    else:  # the muscles' generalised forces on the body angles: + on the child, - on the parent
                        muscle_dtau[:, :] = 0.0
                        for k in range(n_b):
                            col = body_int[k, COLUMN]
                            for q in range(P):
                                muscle_dtau[k, q] += dtm[col, q]
                                if joint_parent[k] >= 0:
                                    muscle_dtau[joint_parent[k], q] -= dtm[col, q]
                        _stage_sensitivity(state, ks[stage], S, U, acc, weight, next_step, half, G, torque_sign,
                                           muscle_dtau, factor, tangent_work, banded_layout)
                else:
                    _stage_tangents(state, rhs, A, dense_first, values_at(load_values, half), load_frames, body_int,
                                    body_float, path_body, params, kept_rows, path_kept, force_rows, G[half],
                                    param_col, U, jac, solved_rows, moved, dk)
                    if muscles is not None:  # A^-1 (force_rows dtm): the muscles' generalised forces' change
                        for r in range(n_q):
                            for q in range(P):
                                total = 0.0
                                for j in range(J):
                                    total += solved_rows[r, j] * dtm[j, q]
                                dk[n_q + r, q] += total
                    for m in range(n):
                        for q in range(P):
                            acc[m, q] += weight * dk[m, q]
                            U[m, q] = S[m, q] + next_step * dk[m, q]
        if code != OK:
            return code, i, max_viol
        if i == n_steps:
            break
        finite = True
        for m in range(n):
            state[m] = y[m] + dt / 6.0 * (ks[0, m] + 2.0 * ks[1, m] + 2.0 * ks[2, m] + ks[3, m])
            finite = finite and math.isfinite(state[m])
        if not finite:
            return NONFINITE, i, max_viol
    return OK, n_steps, max_viol


@njit(inline="always")
def values_at(values, half):
    """Row ``half`` of the loads' values on the grid (row 0 of an empty table)."""
    return values[half if values.shape[1] > 0 else 0]


@njit(error_model="numpy")
def rk4(y0, dt, n_steps, start, law, model, paths, free, loads, believed, believed_paths, believed_loads, states,
        rates, applied):
    """Classical RK4 of eq. 12 over n_steps steps of dt (s) from the state y0 (n_state,) under the
    feedback law ``law`` (``layout.Law``: mode PD, tau + kp (ref - z) + kd (refd - z'); GAINS,
    tau + gains[half] [ref - z, refd - z'], accumulated term by term onto tau (so that
    K = [diag kp, diag kd] gives PD's numbers to the last bit); COMPUTED, the believed model's
    inverse dynamics at (z, z') for the accelerations refdd + kp e + kd e', plus tau), its grid
    from row ``start`` (step i uses rows start + 2 i to start + 2 i + 2). model, paths, free, loads:
    the plant (``fdbench.multibody.layout``; None for what it lacks); believed, believed_paths,
    believed_loads: the model computed-torque control believes. Fills states, rates (n+1, n_state)
    (the state and its derivative) and applied (n+1, J) up to the last step reached. Returns
    (status, steps_done, max constraint violation)."""
    return _drive(y0, dt, n_steps, start, law, model, paths, free, loads, believed, believed_paths, believed_loads,
                  (states, rates, applied), None, None, None, 1, None, None)


@njit(error_model="numpy")
def rk4_muscles(y0, dt, n_steps, start, law, model, paths, free, loads, believed, believed_paths, believed_loads,
                muscles, states, rates, applied):
    """``rk4`` of a model with muscles (``layout.Muscles``, its excitations on the law's grid): the
    state (n_state,) is [q, q'] followed by the activations (M,) and the compliant tendons' normalised
    forces, and the muscles' generalised forces add to the law's torque (``applied`` holds their sum).
    With muscles None, ``rk4`` itself (the same compiled driver)."""
    return _drive(y0, dt, n_steps, start, law, model, paths, free, loads, believed, believed_paths, believed_loads,
                  (states, rates, applied), None, None, None, 1, None, muscles)


@njit(error_model="numpy")
def derivatives(states, law, model, paths, free, loads, believed, believed_paths, believed_loads, out, applied):
    """The state derivatives (into out, (k, n_state)) and applied generalised forces (into applied,
    (k, J)) of k states (k, n_state) under ``rk4``'s feedback law, row i with row i of the law's
    arrays and of the loads' values; the accelerations are NaN where the solve fails."""
    n, J = states.shape[1], law.tau.shape[1]
    state, rate, torque = np.empty((1, n)), np.empty((1, n)), np.empty((1, J))
    for i in range(states.shape[0]):
        # np.int64(0), not 0: a literal argument would make numba compile the whole driver again
        code, _, _ = _drive(states[i], 0.0, np.int64(0), i, law, model, paths, free, loads, believed, believed_paths,
                            believed_loads, (state, rate, torque), None, None, None, 1, None, None)
        out[i] = rate[0]
        applied[i] = torque[0]
        if code != OK:
            out[i, n // 2:] = np.nan


@njit(error_model="numpy")
def constraint_violation(y, model, paths, free, loads, residuals):
    """max |Phi| (m^2 and m) of the state y (n_state,), the angle constraints in the form in force
    (the value ``rk4`` checks). residuals: None, or (phi_rows, jv_rows) (n_rows,) to receive the
    dense solve's Phi and J q' of every constraint row (distance and angle per body, the linear
    rows, two per path)."""
    n, J = y.shape[0], model.joint_parent.shape[0] + 2 * (0 if free is None else free.shape[0])
    rows, gains = np.zeros((1, J)), np.zeros((1, J, 2 * J))
    law = Law(rows, rows, rows, rows, rows[0], rows[0], PD, gains)
    # np.int64, not literals: a literal argument would make numba compile the whole driver again
    _, _, worst = _drive(y, 0.0, np.int64(-1), np.int64(0), law, model, paths, free, loads, model, paths, loads,
                         (np.empty((1, n)), np.empty((1, n)), np.empty((1, J))), residuals, None, None, 1, None,
                         None)
    return worst


@njit(error_model="numpy")
def _rk4_sensitivity(y0, dt, n_steps, tau, ref, refd, G, param_col, every, model, paths, free, loads, states, rates,
                     applied, dz, muscles):
    """``rk4_sensitivity``'s compiled kernel (muscles None or a ``layout.Muscles``)."""
    J = tau.shape[1]
    zero = np.zeros(J)
    law = Law(tau, ref, refd, ref, zero, zero, PD, np.zeros((1, J, 2 * J)))
    code, done, _ = _drive(y0, dt, n_steps, 0, law, model, paths, free, loads, model, paths, loads,
                           (states, rates, applied), None, G, param_col, every, dz, muscles)
    return code, done


def rk4_sensitivity(y0, dt, n_steps, tau, ref, refd, G, param_col, every, model, paths, free, loads, states, rates,
                    applied, dz, muscles=None):
    """Open-loop RK4 (``rk4`` in PD mode with zero gains, as the population runs it) and the forward
    sensitivities of the coordinates (``fdbench.multibody.sensitivity``): tau, ref, refd (rows, J)
    on the half-step grid, G (rows, P) d tau / d p, parameter q moving coordinate param_col[q]'s
    generalised force only (N m or N per parameter unit). The initial state does not depend on p.
    Fills states, rates, applied as ``rk4`` does and dz (n_steps // every + 1, J, P), the derivative
    of the coordinates (rad; m for a free joint's x and y, per parameter unit) at every ``every``-th
    step reached. Returns (status, steps_done).

    ``muscles`` (``layout.Muscles``, its excitations (rows, M) on the grid; None: none): the state
    (n_state + muscle states) and its sensitivities carry the muscles' activations and compliant
    tendons' forces as ``rk4_muscles`` does, and a parameter q with param_col[q] = J + m moves
    muscle m's excitation by G[:, q] (per parameter unit) instead of a generalised force. Either path
    form is exact (``muscle_paths.hessians``)."""
    return _rk4_sensitivity(y0, dt, n_steps, tau, ref, refd, G, param_col, every, model, paths, free, loads, states,
                            rates, applied, dz, muscles)
