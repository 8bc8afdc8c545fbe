"""Checks on the dense solve's state (paths, free joints and loads taken, pin joints not banded):
its constraint residuals and the leading matrix of eq. 12."""

from __future__ import annotations

import numpy as np

from fdbench.multibody import kernels


def dense_args(engine):
    """The kernels' (model, paths, free) of the engine with the dense solve taken: free an empty
    array (not None) for a model without free joints."""
    return engine.layout, engine.paths, np.zeros(0, dtype=np.int64) if engine.free is None else engine.free


def residuals(engine, y):
    """(max |Phi|, Phi, J q') of the dense solve at the state y."""
    rows = kernels.n_rows(engine.layout, engine.paths)
    phi, jv = np.empty(rows), np.empty(rows)
    worst = kernels.constraint_violation(y, *dense_args(engine), engine.loads_at(np.zeros(1)), (phi, jv))
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


def load_forces(engine, z, t) -> np.ndarray:
    """The external loads' generalised forces (J,) at the coordinates z (J,) and the time t (s), by
    the compiled eq. 3: at rest, without gravity (Q_ext = 0), it leaves minus the loads' forces."""
    out = np.empty((1, engine.n_joints))
    z = np.ascontiguousarray(z, dtype=float).reshape(1, -1)
    kernels.inverse_torques(z, np.zeros_like(z), np.zeros_like(z), engine.layout._replace(q_ext=0.0 * engine.q_ext),
                            engine.paths, engine.loads_at(np.array([float(t)])), out)
    return -out[0]
