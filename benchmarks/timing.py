"""The benchmarks' one way of timing a call: the fastest of several rounds (the machine may be busy;
the minimum is the least disturbed measurement)."""

import argparse
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


def cpu_per_call(fn, calls: int) -> float:
    """The process's CPU time (user + system, s) per call over one block of ``calls`` calls of fn:
    a figure other processes on a busy machine do not inflate, as the C loop's CPU time."""
    start = time.process_time()
    for _ in range(calls):
        fn()
    return (time.process_time() - start) / calls


def positive(text: str) -> int:
    """A positive integer, for --runs."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return int(text)
