"""The forearm against its speed limit: fdbench's costs on the multibody engine beside the same
algorithm in C, measured in one run.

Baseline, measured in the same run: ../shared/bench/pd_forearm.c (or the file given by
--c-source), compiled with ``cc -O2`` into a temporary folder and run: PD (kp 80, kd 0.3) plus the
computed feedforward, the penalty formulation (eq. 12), RK4 with dt = 1 ms over the paper motion,
feedforward and reference precomputed on the half-step grid; it prints the RMSE of rotation and
the time of one simulation (mean of 2000 in one process). Its RMSE must equal that of
``fdbench control --kp 80 --kd 0.3`` to the digits it prints (the same algorithm).

fdbench, in this process, on one thread (``population.set_threads(1)``), each after a warm-up
(kernels loaded, cma imported), best of several rounds:

  (a) kernel      the engine's compiled RK4 alone on the library's forearm
                  (``multibody.kernels.rk4`` under the same PD law, feedforward and reference on
                  the half-step grid, buffers allocated once)
  (b) one-shot    the runtime_s of ``fdbench control --kp 80 --kd 0.3 --format json`` (the CLI's
                  own path: a new process each time, as its user runs it; best of the runs), and
                  beside it (b') ``run(control_spec())``'s runtime_s in this process after a warm-up
                  run (what a report's warm worker pays; its CPU time that of the whole ``run``
                  call, an upper bound). Both are the run's own work: the
                  controller's design, the simulation and its samples; what the C loop also
                  prepares beforehand (the reference and feedforward on the half-step grid) and
                  the start state are made before the clock, and the process's start-up (imports,
                  loading the kernels and a warm-up on a still model) is excluded, as README's
                  runtime_s says. The part beyond the kernel (a) is printed beside them
  (c) CMA-ES      runtime_s / evaluations of ``run(optimize_spec(torque, "cmaes", ...))``, budget
                  BUDGET, for cs and ann without and pf with feedforward: the path ``fdbench
                  optimize`` takes. Beside it, where the time goes, per evaluation: the
                  population's simulations and eq. 18 (``TrackingProblem.objectives_scaled`` on
                  one generation of the cell's size, torques excluded), its torques
                  (``torques_on_grid_batch``), cma's own work (ask, tell, set-up and the budget's
                  records: the same optimiser and options on a trivial objective), and the rest
                  (the problem's set-up, the final simulation of the best parameters)

Each is printed in ms and as a ratio to C; the goals are at most 2x for a one-shot control and
1.5x for a CMA-ES evaluation.
The C loop runs again before every CMA-ES run and its least disturbed time is the baseline (its
median is printed beside it). C's figure is a mean over one block of 2000 simulations (about
0.25 s), fdbench's are the best of short rounds: on a busy machine the C block is the more likely
to be interrupted, which flatters the ratios; compare runs whose C minimum is the same. The
columns 'CPU ms' and its 'x C' compare CPU times instead (user and system time, which other
processes do not inflate; C's over its block of 2000 simulations, the kernel's over as many calls,
a CMA-ES run's over the whole ``run`` call, its warm-up included): on a busy machine the fairer
comparison. The machine's load
average is printed.

Run: python benchmarks/bench_speed_limit.py
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from timing import best_of, cpu_per_call, positive

GOAL = 1.5  # x C, for a CMA-ES evaluation
ONE_SHOT_GOAL = 2.0  # x C, for a one-shot control run's runtime_s
BUDGET = 200
RUNS = 7  # runs per figure (best of)
ROUNDS, CALLS = 7, 50  # kernel timings: best of ROUNDS rounds of CALLS calls
KP, KD = 80.0, 0.3
CELLS = [("cs", False), ("pf", True), ("ann", False)]
C_FILE = Path("shared", "bench", "pd_forearm.c")
C_REPETITIONS = 2000  # simulations per run of the C loop (its reps)


def default_c_source() -> Path:
    """../shared/bench/pd_forearm.c from the checkout, or from the nearest folder above it that has one."""
    root = Path(__file__).resolve().parents[1]
    found = [folder / C_FILE for folder in root.parents if (folder / C_FILE).is_file()]
    return found[0] if found else root.parent / C_FILE


def compile_c(source: Path, folder: str) -> Path:
    """The C loop compiled with cc -O2 into folder; exit 1 with cc's first line if it fails."""
    binary = Path(folder) / "pd_forearm"
    done = subprocess.run(["cc", "-O2", "-o", str(binary), str(source), "-lm"], capture_output=True, text=True)
    if done.returncode != 0:
        first = (done.stderr.strip().splitlines() or ["no message"])[0]
        raise SystemExit(f"error: cc -O2 failed on {source}: {first}")
    return binary


def run_c(binary: Path) -> tuple[str, float, float]:
    """One run of the C loop: (its RMSE of rotation as printed, deg; ms per simulation as it
    prints it, wall time; ms per simulation in CPU time, the process's user + system time over its
    REPETITIONS simulations, which a busy machine's other work does not inflate)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run([str(binary)], check=True, capture_output=True, text=True).stdout
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    match = re.search(r"rmse_deg\s+(\S+)\s+per_sim_ms\s+(\S+)", out)
    if match is None:
        raise SystemExit(f"error: unexpected output of the C loop: {out.strip()!r}")
    cpu_s = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return match[1], float(match[2]), 1e3 * cpu_s / C_REPETITIONS


def best_per_call(fn, rounds=ROUNDS, calls=CALLS) -> float:
    """Seconds of one call of fn: the minimum over ``rounds`` rounds of ``calls`` calls."""
    return best_of(fn, rounds, calls)


def forearm_kernel():
    """(a): one call of the engine's compiled RK4 on the forearm under PD plus feedforward, and the
    RMSE of rotation (deg) it gives at the steps."""
    from kernel_call import half_step_grid, model_and_motion, rk4_call

    engine, motion = model_and_motion("forearm")
    grid = half_step_grid(engine, motion)
    call = rk4_call(engine, grid, KP, KD)
    call()
    z = engine.joints_from_state(call.states)[0]
    return call, float(np.degrees(np.sqrt(np.mean((z - grid.ref[::2]) ** 2))))


def c_loop_ms(source: Path | None = None, runs: int = 3) -> tuple[float, float] | None:
    """ms of one simulation of the C loop (source, default ../shared/bench/pd_forearm.c) compiled
    with cc -O2 in a temporary folder, in wall time and in CPU time, each the least of ``runs``
    runs; None without a C compiler or the source."""
    source = source or default_c_source()
    if shutil.which("cc") is None or not source.is_file():
        return None
    with tempfile.TemporaryDirectory() as folder:
        binary = compile_c(source, folder)
        found = [run_c(binary)[1:] for _ in range(runs)]
    return min(wall for wall, _ in found), min(cpu for _, cpu in found)


def timed_run(spec) -> tuple[dict, float]:
    """``run(spec)``'s record and the CPU time (s) of the whole call (its warm-up of loaded kernels
    and its record included: an upper bound of its runtime_s's CPU time)."""
    import fdbench

    start = time.process_time()
    record = fdbench.run(spec).record
    return record, time.process_time() - start


def control_runtime(runs: int) -> tuple[float, float, float]:
    """(b'): the best runtime_s (s) of ``run(control_spec())`` over ``runs`` runs after a warm-up,
    the least CPU time (s) of a whole ``run`` call (an upper bound of its runtime_s's: the call's
    warm-up, record and trajectory table included), and its RMSE of rotation (deg)."""
    import fdbench

    spec = fdbench.control_spec(KP, KD)
    timed = [timed_run(spec) for _ in range(runs + 1)][1:]
    records = [record for record, _ in timed]
    return min(r["runtime_s"] for r in records), min(cpu for _, cpu in timed), records[0]["rmse_rot_deg"]


def cli_control_runtime(runs: int) -> tuple[float, float]:
    """(b): the best runtime_s (s) of ``fdbench control --kp KP --kd KD --format json`` over ``runs``
    new processes (this Python, ``-m fdbench.cli``: the CLI's own path, each run a one-shot), and
    the least CPU time (s) of such a whole process (start-up, imports and kernel loading
    included)."""
    import json

    command = [sys.executable, "-m", "fdbench.cli", "control", "--kp", f"{KP:g}", "--kd", f"{KD:g}", "--format",
               "json", "--quiet"]
    best, cpu = math.inf, math.inf
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(command, capture_output=True, text=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0:
            first = (done.stderr.strip().splitlines() or ["no message"])[0]
            raise SystemExit(f"error: fdbench control failed: {first}")
        best = min(best, json.loads(done.stdout)["runtime_s"])
        cpu = min(cpu, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime))
    return best, cpu


def cell_timers(torque: str, feedforward: bool):
    """(c) for one cell: a function that times one BUDGET-evaluation CMA-ES run (runtime_s /
    evaluations and CPU time / evaluations, s) and one that times its parts per evaluation (s): the simulations with eq. 18
    of one generation (torques excluded), its torques, cma's own work on a trivial objective."""
    import fdbench
    from fdbench.optimizers import make_optimizer
    from fdbench.problem import TrackingProblem
    from kernel_call import model_and_motion

    spec = fdbench.optimize_spec(torque, "cmaes", feedforward, seed=0, budget=BUDGET)
    options = dict(spec.optimizer_options)
    problem = TrackingProblem(torque, *model_and_motion("forearm"), feedforward, **dict(spec.torque_options))
    size = options.get("popsize") or 4 + int(3 * np.log(problem.n_params))  # cma's default generation
    X = problem.x0 + options.get("sigma0", 0.1) * np.random.default_rng(0).standard_normal((size, problem.n_params))
    optimizer = make_optimizer("cmaes", **options)

    def one_run():
        record, cpu = timed_run(spec)
        return np.array([record["runtime_s"], cpu]) / record["evaluations"]

    def parts():
        population = best_per_call(lambda: problem.objectives_scaled(X), 3, 10) / size
        torques = best_per_call(lambda: problem.torques_on_grid_batch(X * problem.scale), 3, 10) / size
        cma = best_per_call(lambda: optimizer.minimize(lambda x: float(x @ x), problem.x0, BUDGET, seed=0,
                                                       batch=lambda P: np.einsum("ij,ij->i", P, P)), 1, 1) / BUDGET
        return np.array([population - torques, torques, cma])

    one_run()  # warm-up
    parts()
    return one_run, parts


def main(c_source: Path, runs: int) -> None:
    if shutil.which("cc") is None:
        print("error: no C compiler (cc) on PATH: the C baseline cannot be built", file=sys.stderr)
        raise SystemExit(2)
    if not c_source.is_file():
        print(f"error: --c-source: no such file {c_source}", file=sys.stderr)
        raise SystemExit(2)
    import fdbench
    from fdbench.population import set_threads

    print(f"fdbench {fdbench.__version__}, {platform.python_implementation()} {platform.python_version()}, "
          f"{platform.machine()}; load average {os.getloadavg()}, cores {len(os.sched_getaffinity(0))}")
    set_threads(1)
    with tempfile.TemporaryDirectory() as folder:
        binary = compile_c(c_source, folder)
        c_text, c_ms, c_cpu = run_c(binary)
        one_shot, one_shot_cpu, control_rmse = control_runtime(runs)
        digits = len(c_text.split(".")[-1])
        print(f"C loop ({c_source.name}, cc -O2): rmse_rot_deg {c_text}; fdbench control --kp {KP:g} --kd {KD:g}: "
              f"{control_rmse:.{digits}f}")
        if f"{control_rmse:.{digits}f}" != c_text:
            raise SystemExit("error: the C loop and fdbench control disagree: not the same algorithm")
        kernel, kernel_rmse = forearm_kernel()
        kernel_s = best_per_call(kernel)
        cli_shot, cli_cpu = cli_control_runtime(runs)
        rows = [("(a) engine forearm kernel, kernels.rk4", kernel_s, cpu_per_call(kernel, C_REPETITIONS),
                 f"rmse {kernel_rmse:.{digits}f}"),
                ("(b) one-shot fdbench control (CLI)", cli_shot, math.nan,
                 f"runtime_s of a new process; beyond the kernel {1e3 * (cli_shot - kernel_s):.3f} ms; the whole "
                 f"process {cli_cpu:.2f} s CPU"),
                ("(b') run(control_spec()), warm process", one_shot, one_shot_cpu,
                 f"beyond the kernel {1e3 * (one_shot - kernel_s):.3f} ms (CPU: the whole run call, an upper "
                 "bound)")]
        parts = []
        c_times, c_cpus = [c_ms], [c_cpu]
        for torque, ff in CELLS:  # runs, their parts and the C loop alternately: each sees the same load
            one_run, cell_parts = cell_timers(torque, ff)
            per, split = np.full(2, np.inf), np.full(3, np.inf)
            for _ in range(runs):
                _, wall, cpu = run_c(binary)
                c_times.append(wall), c_cpus.append(cpu)
                per, split = np.minimum(per, one_run()), np.minimum(split, cell_parts())
            rows.append((f"(c) CMA-ES {torque}{' + ff' if ff else ''} per evaluation", *per, ""))
            parts.append((rows[-1][0], per[0], split))
        c_ms, c_cpu = min(c_times), min(c_cpus)  # the least disturbed
    c_s = c_ms / 1e3
    print(f"{'single thread, best of ' + str(runs):<42}{'ms':>9}{'x C':>8}{'CPU ms':>9}{'x C':>8}")
    print(f"{'C loop, one PD simulation (the baseline)':<42}{c_ms:>9.4f}{1.0:>8.2f}{c_cpu:>9.4f}{1.0:>8.2f}  "
          f"median of {len(c_times)} runs {np.median(c_times):.4f} ms")
    for label, seconds, cpu, note in rows:
        if label.startswith("(c)"):
            note = " ".join(f"{how} {'meets' if ratio <= GOAL else 'misses'} the goal"
                            for how, ratio in (("wall", seconds / c_s), ("CPU", cpu * 1e3 / c_cpu)))
        elif label.startswith("(b) "):
            note = f"{'meets' if seconds / c_s <= ONE_SHOT_GOAL else 'misses'} the goal; {note}"
        print(f"{label:<42}{seconds * 1e3:>9.4f}{seconds / c_s:>8.2f}{cpu * 1e3:>9.4f}{cpu * 1e3 / c_cpu:>8.2f}  "
              f"{note}".rstrip())
    print("where a CMA-ES evaluation's time goes (x C): simulations + eq. 18, torques, cma's own work, rest")
    for label, per, (simulations, torques, cma) in parts:
        rest = per - simulations - torques - cma
        print(f"  {label[4:]:<38}{simulations / c_s:>6.2f}{torques / c_s:>8.2f}{cma / c_s:>8.2f}{rest / c_s:>8.2f}")
    print(f"goals: a one-shot control within {ONE_SHOT_GOAL:g}x and a CMA-ES evaluation within {GOAL:g}x of the C "
          "loop, single thread")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--c-source", type=Path, default=None, help="the C loop (default: ../shared/bench/pd_forearm.c)")
    parser.add_argument("--runs", type=positive, default=RUNS, help="runs per figure, best of (default: %(default)s)")
    args = parser.parse_args()
    main(args.c_source or default_c_source(), args.runs)
