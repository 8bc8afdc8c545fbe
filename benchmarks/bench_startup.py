"""Start-up of the command line: ``fdbench --help``, ``fdbench control --help`` and a warm
``fdbench control`` (kernels cached: a first run loads or compiles them before the timings), each
a new process of this Python (``-m fdbench.cli``), best of --runs.

Printed per command: the wall time and the CPU time (user + system) of the whole process; on a busy
machine the CPU time is the fairer figure (other processes do not inflate it), and on an idle one
the wall time is about the CPU time. Goals: ``--help`` under 0.5 s, a warm ``control`` under 1.5 s.
The machine's load average is printed. Where the time goes: ``python -X importtime -m fdbench.cli
--help``.

Run: python benchmarks/bench_startup.py
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time

from timing import positive

COMMANDS = [  # (arguments, goal in s or None)
    (["--help"], 0.5),
    (["control", "--help"], None),
    (["control", "--format", "json", "--quiet"], 1.5),
]


def timed(args: list[str]) -> tuple[float, float]:
    """(wall s, CPU s) of one process ``python -m fdbench.cli *args``; exit 1 if it fails."""
    before, start = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "fdbench.cli", *args], capture_output=True, text=True)
    wall, after = time.perf_counter() - start, resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        first = (done.stderr.strip().splitlines() or ["no message"])[0]
        raise SystemExit(f"error: fdbench {' '.join(args)} failed: {first}")
    return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def main(runs: int) -> None:
    print(f"load average {os.getloadavg()}, cores {len(os.sched_getaffinity(0))}")
    timed(COMMANDS[-1][0])  # kernels loaded or compiled into the cache: the runs below are warm
    print(f"{'fdbench ...':<40}{'wall s':>8}{'CPU s':>8}  goal (wall; on a busy machine read CPU)")
    for args, goal in COMMANDS:
        wall, cpu = (min(values) for values in zip(*(timed(args) for _ in range(runs))))
        verdict = "" if goal is None else f"under {goal:g} s: wall {'yes' if wall < goal else 'no'}, " \
                                          f"CPU {'yes' if cpu < goal else 'no'}"
        print(f"{' '.join(args):<40}{wall:>8.3f}{cpu:>8.3f}  {verdict}".rstrip())


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=positive, default=5, help="runs per command, best of (default: %(default)s)")
    main(parser.parse_args().runs)
