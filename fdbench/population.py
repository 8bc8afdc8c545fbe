"""Population evaluation: the forward simulations of many candidates in compiled calls, spread
over threads (a compiled kernel that releases the GIL, run by a small thread pool; each thread takes
every T-th candidate). Each call runs about 0.1 s of steps, a candidate's simulation resuming where
the call before stopped, so that Ctrl-C ends a large model's population within a fraction of a second.

Each candidate runs the kernel of a plain simulation on its own torque history, in its thread's
work buffers, and eq. 18 straight from its states (``multibody.kernels.rk4_candidates``). A single
evaluation is a population of one through the same kernel, so a population's numbers equal those
of its candidates evaluated one by one, to the last bit, whatever the number of threads.
(numba's ``parallel=True`` was measured too: its OpenMP workers spin while they wait, which on a
loaded machine made two threads twice as slow as one.)
"""

from __future__ import annotations

import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np


DEGREES_PER_RADIAN = 180.0 / math.pi

_threads = {"count": None, "pool": None}
if hasattr(os, "register_at_fork"):  # a forked worker starts without the parent's pool threads
    os.register_at_fork(after_in_child=lambda: _threads.update(count=None, pool=None))


def available_cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


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


def workspace(n_steps: int, count: int, widths) -> tuple:
    """Work buffers of ``count`` threads for simulations of n_steps steps, one per entry of
    ``widths`` (the trailing shape of a row), each of shape (count, n_steps + 1, *width)."""
    return tuple(np.empty((count, n_steps + 1, *width)) for width in widths)


def spread(kernel, args, buffers, objective) -> None:
    """Run ``kernel(*args, *thread's buffers, objective, candidate, stride, step, budget)`` over the
    ``len(objective)`` candidates, shared among ``threads()`` threads (at most as many as ``buffers``
    holds, see ``workspace``): thread k takes candidates k, k + T, ... in its own buffers, in calls of
    ``budget`` steps (``_in_steps``). ``kernel`` must be compiled with ``nogil=True``, fill
    objective[c] for the candidates it finishes and return the (candidate, step) to resume at.
    Ctrl-C is acted on between two calls: the other threads stop after their call."""
    count = max(1, min(threads(), len(objective), buffers[0].shape[0]))
    stop = threading.Event()
    if count == 1:
        _in_steps(kernel, args, tuple(buffer[0] for buffer in buffers), objective, 0, 1, stop)
        return
    jobs = [_threads["pool"].submit(_in_steps, kernel, args, tuple(buffer[k] for buffer in buffers), objective, k,
                                    count, stop) for k in range(count)]
    try:
        for job in jobs:
            job.result()
    finally:
        stop.set()


def _in_steps(kernel, args, buffers, objective, first, stride, stop) -> None:
    """``spread``'s kernel over candidates first, first + stride, ... in calls of about CHUNK_S
    seconds each (the first of FIRST_CHUNK_VALUES state values), as ``Engine.simulate``'s RK4 runs,
    until done or ``stop`` is set."""
    from .multibody.engine import CHUNK_S, FIRST_CHUNK_VALUES

    budget = max(1, FIRST_CHUNK_VALUES // buffers[0].shape[1])
    candidate, step = first, 0
    while candidate < len(objective) and not stop.is_set():
        began = time.perf_counter()
        candidate, step = kernel(*args, *buffers, objective, candidate, stride, step, budget)
        budget = max(1, int(CHUNK_S * budget / max(time.perf_counter() - began, 1e-9)))


class Population:
    """Eq. 18 of whole populations by a candidate kernel (see ``spread``) whose simulations have
    n_steps steps, keeping the threads' work buffers (``workspace`` with ``widths``) from call to
    call."""

    def __init__(self, kernel, n_steps: int, widths):
        self.kernel, self.n_steps, self.widths, self._buffers = kernel, n_steps, widths, None

    def __call__(self, count: int, args) -> np.ndarray:
        """The objectives of ``count`` candidates, shape (count,): ``kernel(*args, ...)``."""
        used = min(threads(), count)
        if self._buffers is None or self._buffers[0].shape[0] < used:
            self._buffers = workspace(self.n_steps, used, self.widths)
        values = np.empty(count)
        spread(self.kernel, args, self._buffers, values)
        return values
