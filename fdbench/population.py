"""Population evaluation: the forward simulations of many candidates in one compiled call,
spread over threads (a compiled kernel that releases the GIL, run by a small thread pool; each
thread takes every T-th candidate).

Each candidate runs the very kernel of a single evaluation (``dynamics.rk4``) on its own torque
history and buffers, so a population's numbers equal those of its candidates evaluated one by
one, to the last bit, whatever the number of threads. (numba's ``parallel=True`` was measured
too: its OpenMP workers spin while they wait, which on a loaded machine made two threads twice
as slow as one.)
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

from .dynamics import rk4
from .jit import njit

_threads = {"count": None, "pool": None}
if hasattr(os, "register_at_fork"):  # a forked worker starts without the parent's pool threads
    os.register_at_fork(after_in_child=lambda: _threads.update(count=None, pool=None))


def available_cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


@njit(nogil=True)
def rk4_candidates(y0, dt, n_steps, tau, ref_th_half, ref_w_half, consts, states, qdd, applied, done, first, stride):
    """Open-loop RK4 (``dynamics.rk4`` with zero gains) for rows first, first + stride, ... of tau.

    tau: the torques (N m) on the half-step grid, shape (lam, 2 n_steps + 1); states (lam, n+1, 6),
    qdd (lam, n+1, 3), applied (lam, n+1): each candidate's buffers; done (lam,): the steps each
    reached (filled for the rows run). Runs without the GIL."""
    for c in range(first, tau.shape[0], stride):
        _, steps_done, _ = rk4(y0, dt, n_steps, tau[c], ref_th_half, ref_w_half, 0.0, 0.0, consts, states[c], qdd[c],
                               applied[c])
        done[c] = steps_done


def set_threads(threads: int | None) -> int:
    """Use ``threads`` threads for population evaluation (None: every available core); returns
    the number set."""
    count = available_cores() if threads is None else int(threads)
    if count < 1:
        raise ValueError(f"--threads must be a positive integer, got {threads}")
    if count != _threads["count"]:
        if _threads["pool"] is not None:
            _threads["pool"].shutdown()
        _threads["count"], _threads["pool"] = count, ThreadPoolExecutor(count) if count > 1 else None
    return count


def threads() -> int:
    """The number of threads population evaluation uses (every available core until set)."""
    return _threads["count"] or set_threads(None)


def rk4_population(y0, dt, n_steps, tau, ref_th_half, ref_w_half, consts, states, qdd, applied, done) -> None:
    """``rk4_candidates`` for every row of tau, the rows shared among ``threads()`` threads."""
    count = min(threads(), tau.shape[0])
    args = (y0, dt, n_steps, tau, ref_th_half, ref_w_half, consts, states, qdd, applied, done)
    if count <= 1:
        rk4_candidates(*args, 0, 1)
        return
    jobs = [_threads["pool"].submit(rk4_candidates, *args, k, count) for k in range(count)]
    for job in jobs:
        job.result()


def warm_up() -> None:
    """Load (or compile) the population kernel and start the threads, so that later timings
    exclude both."""
    import numpy as np

    from .integrate import Settings, constants, initial_state

    settings = Settings(dt=0.1)
    n = 10
    tau = np.zeros((2, 2 * n + 1))
    ref = np.zeros(2 * n + 1)
    rk4_population(initial_state(settings.kinematics, settings.model), 0.1, n, tau, ref, ref, constants(settings),
                   np.empty((2, n + 1, 6)), np.empty((2, n + 1, 3)), np.empty((2, n + 1)), np.empty(2, dtype=np.int64))
