"""Direct collocation of any model: the transcription of ``fdbench.collocation.transcribe`` (trapezoidal
or Hermite-Simpson, IPOPT through CasADi) on the model's minimal equations z'' = M(z)^-1 (tau - h(z, z'))
(``fdbench.multibody.symbolic``), with 2J states (z, z') and J torques per node.

The objective is the integral of the squared joint-angle errors in deg^2, summed over the joints, plus
``regularization`` times the integral of |tau|^2 (N^2 m^2 s); the initial state is the desired
motion's at t = 0, the initial guess the desired motion and the model's inverse-dynamics torques.
A motion is anything with ``duration`` (s) and ``motion(t) -> (z, z', z'')`` (rad, rad/s, rad/s^2),
each of shape t.shape + (J,). ``casadi`` is imported only when the transcription is built.
"""

from __future__ import annotations

import time

import numpy as np

from ..collocation import (DEFAULT_MAX_ITER, DEFAULT_MAX_TIME, DEFAULT_NODES, DEFAULT_REGULARIZATION,
                           CollocationResult, check_options, transcribe)
from .description import Model
from .symbolic import MinimalDynamics


def desired_samples(model: Model, motion, t: np.ndarray):
    """The motion's (z, z', z'') at times t (s), each (len(t), J); ValueError (one line) when the
    motion does not give one column per joint of the model."""
    values = tuple(np.asarray(v, dtype=float) for v in motion(t))
    shape = (len(t), model.n_joints)
    if any(v.shape != shape for v in values):
        raise ValueError(f"the motion gives joint values of shape {values[0].shape}; model {model.name!r} needs "
                         f"{shape} (one column per joint: {', '.join(model.coordinates)})")
    return values


def collocate(model: Model, motion, nodes: int = DEFAULT_NODES, scheme: str = "hermite-simpson",
              regularization: float = DEFAULT_REGULARIZATION, max_iter: int = DEFAULT_MAX_ITER,
              max_time: float = DEFAULT_MAX_TIME) -> CollocationResult:
    """Transcribe and solve the tracking problem of ``motion`` with ``model`` on ``nodes`` intervals
    over the motion's span: node arrays of shape (N + 1, J) in the model's joint order. ValueError
    (one line) for options out of range or a motion of other joints; never raises on a solver
    failure: IPOPT's status says what happened."""
    check_options(nodes, scheme, regularization, max_iter, max_time)
    began = time.perf_counter()
    dynamics = MinimalDynamics(model)
    n = int(nodes)
    t = np.linspace(0.0, motion.duration, n + 1)
    z_d, w_d, a_d = desired_samples(model, motion, t)
    z_md = um_guess = None
    if scheme == "hermite-simpson":
        z_md, w_md, a_md = desired_samples(model, motion, t[:-1] + motion.duration / n / 2)
        um_guess = dynamics.inverse(z_md, w_md, a_md)
    return transcribe(dynamics.forward_rows, t, z_d, w_d, z_md, dynamics.inverse(z_d, w_d, a_d), um_guess, scheme,
                      regularization, max_iter, max_time, began)
