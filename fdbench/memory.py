"""The memory a run may take, checked before its large arrays are allocated: a run whose
estimate exceeds ``budget_bytes()`` (a quarter of the machine's physical memory; 4 GiB where the
system does not say; at most a quarter of a ``ulimit -v``) is refused with one line naming the
option to change, instead of dying of MemoryError minutes later.

The estimates count the arrays that grow with the options (in float64 values of 8 bytes): the
reporting grid (samples), a noisy capture, the RK4 steps of one simulation and the torques of a
population evaluated at once (CMA-ES), with generous constants for the temporaries around them.
"""

from __future__ import annotations

import os

VALUES_PER_SAMPLE = 64  # per joint: motion, histories, inverse dynamics, indicators, trajectory rows
VALUES_PER_CAPTURED_SAMPLE = 16  # per joint: the noisy angle, its filter and spline
VALUES_PER_STEP = 32  # per joint: states, accelerations, torques and references on the half-step grid
VALUES_PER_CANDIDATE_STEP = 8  # per candidate and half step: its torque per joint, temporaries (+ ANN neurons)
FALLBACK_BYTES = 4 * 2**30


def budget_bytes() -> int:
    """The bytes one run may take: a quarter of the physical memory (4 GiB if unknown), and at most
    a quarter of the address space the process may use (``ulimit -v``, RLIMIT_AS)."""
    try:
        budget = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 4
    except (AttributeError, OSError, ValueError):
        budget = FALLBACK_BYTES
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    except (ImportError, OSError, ValueError):
        return budget
    return budget if limit == resource.RLIM_INFINITY else min(budget, limit // 4)


def check_fits(needs: dict) -> None:
    """ValueError (one line) if the estimates together exceed the budget, naming the largest:
    ``needs`` maps advice ('give a larger --dt') to an estimate in bytes."""
    total, budget = sum(needs.values()), budget_bytes()
    if total <= budget:
        return
    advice = max(needs, key=needs.get)
    raise ValueError(f"this run would need about {_size(total)} of memory, more than the {_size(budget)} fdbench "
                     f"allows one run on this machine (a quarter of its memory or of ulimit -v); {advice}")


def _size(count: float) -> str:
    return f"{count / 2**30:.3g} GiB" if count >= 2**30 else f"{count / 2**20:.3g} MiB"


def check_grid(duration: float, step: float, option: str, joints: int = 1,
               values: int = VALUES_PER_SAMPLE) -> None:
    """A grid every ``step`` s over ``duration`` s (the reporting grid of --sample-dt, a capture at
    --capture-hz) must fit; ``option`` names what to change."""
    count = duration / step + 2
    larger = "a smaller --capture-hz" if option == "--capture-hz" else f"a larger {option}"
    check_fits({f"give {larger} or a shorter motion ({count:.3g} samples over {duration:g} s)":
                count * values * joints * 8})


def check_run(duration: float, samples: int, joints: int, dt: float | None, population: int = 1,
              hidden: int = 0) -> None:
    """A run over ``duration`` s reported on ``samples`` samples of ``joints`` joints, by RK4
    steps of ``dt`` s (None: an adaptive integrator, whose work is bounded otherwise) with
    ``population`` candidates evaluated at once, ``hidden`` neurons per joint's ANN."""
    needs = {f"give a larger --sample-dt ({samples:.3g} samples)": samples * VALUES_PER_SAMPLE * joints * 8.0}
    if dt is not None:
        steps = max(1.0, duration / dt)
        where = f"{steps:.3g} RK4 steps of {dt:g} s over the motion's {duration:g} s"
        needs[f"give a larger --dt or a shorter motion ({where})"] = steps * VALUES_PER_STEP * joints * 8.0
        if population > 1:
            per_candidate = 2 * steps * (VALUES_PER_CANDIDATE_STEP * joints + hidden) * 8.0
            needs[f"give a smaller --popsize{' or --hidden' if hidden else ''} ({population} candidates of {where})"] = \
                population * per_candidate + min(population, os.cpu_count() or 1) * needs[
                    f"give a larger --dt or a shorter motion ({where})"]
    check_fits(needs)

