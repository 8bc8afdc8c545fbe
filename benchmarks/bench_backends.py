"""Wall-clock time of the default ``fdbench report --no-beyond`` (PD control + the paper's 10 cells x
5 seeds, budget 200: the plan the library runs below too) on the two execution backends, each from an empty results database:

- ``--backend local --jobs 2``: two forked worker processes (the baseline);
- ``--backend dask --jobs 2``: a Dask LocalCluster of two single-threaded worker processes
  started by the command (cluster start-up included, as a user pays it);

then the Dask backend with a fixed number of specs per task (1 and 8; the automatic choice gives 6
here) to show what batching buys against the scheduler's cost per task, and the fixed cost of
starting and stopping the cluster alone. Every command runs as a subprocess in
a temporary directory; the ratios are against the local baseline measured in the same run.

Run: python benchmarks/bench_backends.py        (needs pip install '.[dask]')
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
from fdbench.report.paper_methods import default_cells, make_plan

FDBENCH = [sys.executable, "-m", "fdbench.cli"]

# A child process that runs the default plan on a LocalCluster of 2 workers with a fixed batch size.
BATCHED = """
import sys
from fdbench.report.paper_methods import default_cells, execute, make_plan
from fdbench.execution import DaskBackend
from fdbench.store import open_store
batch = None if sys.argv[2] == "auto" else int(sys.argv[2])
with open_store(sys.argv[1]) as store:
    execute(make_plan(default_cells(), seeds=5), store, backend=DaskBackend(jobs=2, batch=batch))
"""


# A child process that only starts and stops the same LocalCluster (its fixed cost), warming the
# workers' kernels as the first run does.
CLUSTER_ONLY = """
import logging
from distributed import Client, LocalCluster
from fdbench.execution import warm_up_worker
with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None,
                  silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
    client.run(warm_up_worker)
"""


def timed(command, cwd) -> float:
    start = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(map(str, command))} failed ({done.returncode}): {done.stderr.strip()}")
    return elapsed


def stored(db: Path) -> tuple[int, int]:
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT COUNT(*), COUNT(DISTINCT spec_hash) FROM runs").fetchone()
    finally:
        con.close()


def main() -> None:
    try:
        import distributed
    except ImportError:
        sys.exit("this benchmark needs Dask distributed: pip install '.[dask]' in fdbench's source folder")
    start = time.perf_counter()
    results = []
    with tempfile.TemporaryDirectory(prefix="fdbench-bench-") as tmp:
        tmp = Path(tmp)

        def report(label, *options):
            db = tmp / f"{len(results)}.sqlite"
            seconds = timed(FDBENCH + ["report", "--no-beyond", "--db", str(db), "--format", "csv", "-q", *options], tmp)
            results.append((label, seconds, stored(db)))

        def batched(label, batch):
            db = tmp / f"{len(results)}.sqlite"
            seconds = timed([sys.executable, "-c", BATCHED, str(db), str(batch)], tmp)
            results.append((label, seconds, stored(db)))

        startup = min(timed(FDBENCH + ["--version"], tmp) for _ in range(3))
        report("report --backend local --jobs 2 (baseline)", "--backend", "local", "--jobs", "2")
        report("report --backend dask --jobs 2 (LocalCluster, automatic batch)", "--backend", "dask", "--jobs", "2")
        report("report --backend local --jobs 2 (again)", "--backend", "local", "--jobs", "2")
        for batch in (1, 8):
            batched(f"library, LocalCluster of 2, {batch} spec(s) per task", batch)
        cluster = timed([sys.executable, "-c", CLUSTER_ONLY], tmp)

    baseline = min(s for label, s, _ in results if label.startswith("report --backend local"))
    print(f"fdbench {fdbench.__version__}, dask distributed {distributed.__version__}, python "
          f"{platform.python_version()}, {platform.machine()}, {os.cpu_count()} cores")
    print(f"default report: PD control + 10 cells x 5 seeds, budget 200, empty database each time; "
          f"interpreter start-up {startup:.2f} s")
    expected = len(make_plan(default_cells(), seeds=5).all_specs())
    for label, seconds, (rows, distinct) in results:
        note = "" if rows == distinct == expected else f"   WARNING: {rows} rows, {distinct} distinct, expected {expected}"
        print(f"  {label:<66} {seconds:7.2f} s   x{seconds / baseline:5.2f} of local{note}")
    print(f"  {'LocalCluster of 2 started, kernels loaded, closed; no run':<66} {cluster:7.2f} s")
    print("(x = wall time / the faster local --jobs 2 run of this benchmark)")
    print(f"total benchmark time: {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
