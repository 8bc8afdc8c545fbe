"""Checks on the dense kernels' state: its constraint residuals and the leading matrix of eq. 12."""

from __future__ import annotations

import numpy as np

from fdbench.multibody import kernels_general as kg


def residuals(engine, y):
    """(max |Phi|, Phi, J q') of the dense kernels at the state y."""
    layout = engine.dense_layout
    rows = kg.n_rows(layout[0], layout[2], engine.lin_const)
    phi, jv = np.empty(rows), np.empty(rows)
    worst = kg.constraint_residuals(y, *layout, phi, jv)
    return worst, phi, jv


def leading_matrix(engine, y):
    """M + alpha J^T J of eq. 12 at the state y, J read column by column as J e_c (unit velocities)."""
    columns = []
    for c in range(engine.n_q):
        unit = y.copy()
        unit[engine.n_q:] = 0.0
        unit[engine.n_q + c] = 1.0
        columns.append(residuals(engine, unit)[2])
    jacobian = np.array(columns).T
    mass = np.zeros((engine.n_q, engine.n_q))
    mass[:engine.n_p, :engine.n_p] = engine.mass
    return mass + engine.params[0] * jacobian.T @ jacobian
