"""The benchmarks' one way of timing a call: the fastest of several rounds (the machine may be busy;
the minimum is the least disturbed measurement)."""

import math
import time


def best_of(fn, rounds: int, calls: int = 1) -> float:
    """The fastest of ``rounds`` rounds of ``calls`` calls of fn, in s per call."""
    best = math.inf
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - start) / calls)
    return best
