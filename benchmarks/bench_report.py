"""Wall-clock time of the default ``fdbench report`` (PD control + the paper's 10 cells x 5 seeds,
budget 200, and the three methods beyond the paper; default --jobs) on a fresh results database, then of the same report repeated from
the store (nothing recomputed). Each command runs as a subprocess in a temporary directory, as a
user would run it; the time of ``fdbench --version`` is printed as the interpreter's start-up
cost included in both.

Run: python benchmarks/bench_report.py
"""

from __future__ import annotations

import os
import platform
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import fdbench

FDBENCH = [sys.executable, "-m", "fdbench.cli"]


def timed(args, cwd) -> float:
    start = time.perf_counter()
    done = subprocess.run(FDBENCH + [str(a) for a in args], cwd=cwd, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"fdbench {' '.join(map(str, args))} failed ({done.returncode}): {done.stderr.strip()}")
    return elapsed


def runs_in(db: Path) -> tuple[int, int, int]:
    """(rows, distinct settings hashes, largest row id) of the results database."""
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT COUNT(*), COUNT(DISTINCT spec_hash), MAX(id) FROM runs").fetchone()
    finally:
        con.close()


def default_report_runs() -> int:
    """The runs the default report stores: PD, the paper's cells x seeds, the methods beyond the paper."""
    from fdbench.report.paper_methods import default_cells, make_plan
    from fdbench.report.methods import beyond_methods

    return len(make_plan(default_cells()).all_specs()) + len(beyond_methods())


def main() -> None:
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fdbench-bench-") as tmp:
        tmp = Path(tmp)
        db = tmp / "results.sqlite"
        env_note = " (FDBENCH_DB ignored: --db given)" if os.environ.get("FDBENCH_DB") else ""
        startup = min(timed(["--version"], tmp) for _ in range(3))
        fresh = timed(["report", "--db", db, "--output", tmp / "report.md", "-q"], tmp)
        rows, distinct, max_id = runs_in(db)
        repeated = timed(["report", "--db", db, "--output", tmp / "report2.md", "-q"], tmp)
        rows2, distinct2, max_id2 = runs_in(db)
        report_lines = (tmp / "report.md").read_text().count("\n")

    print(f"fdbench {fdbench.__version__}, python {platform.python_version()}, {platform.machine()}, "
          f"{os.cpu_count()} cores (default --jobs = {os.cpu_count()}){env_note}")
    expected = default_report_runs()
    print(f"fdbench report, default matrix: PD control + 10 cells x 5 seeds, budget 200 evaluations, and the "
          f"methods beyond the paper ({expected} runs)")
    print(f"  interpreter start-up (fdbench --version, min of 3)  {startup:8.2f} s")
    print(f"  fresh database (computes every run)                 {fresh:8.2f} s   {rows} runs stored "
          f"({distinct} distinct settings), report {report_lines} lines")
    print(f"  repeated report (every run from the store)          {repeated:8.2f} s   {rows2} runs stored, "
          f"{max_id2 - max_id} computed")
    if repeated > 0:
        print(f"  speed-up of the repeated report                     {fresh / repeated:8.1f} x")
    if not (rows == distinct == rows2 == distinct2 == expected and max_id2 == max_id):
        print(f"  WARNING: expected {expected} runs stored once each and nothing recomputed")
    print(f"total benchmark time: {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
