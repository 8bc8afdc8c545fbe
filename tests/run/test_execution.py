"""Execution of run specifications: the runner stores what any backend yields, in any order, once;
a local worker process dies with its parent however the parent ends; ``fdbench report --jobs 2``
killed by SIGKILL or SIGTERM leaves no process behind, keeps its stored runs, and a rerun
completes them with the numbers of an uninterrupted report. Tests that need signals or /proc
skip where they cannot run."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from fdbench.execution import Backend, LocalBackend, Outcome, execute_specs, failed_record, run_spec
from fdbench.spec import control_spec
from fdbench.store import open_store
from helpers.processes import GATED_OPTIMIZER, Gate, wait_until

FDBENCH = [sys.executable, "-m", "fdbench.cli"]
needs_proc = pytest.mark.skipif(not (sys.platform.startswith("linux") and Path("/proc/self/stat").exists()),
                                reason="needs Linux /proc to list processes")
needs_signals = pytest.mark.skipif(not hasattr(signal, "SIGKILL") or not hasattr(os, "killpg"),
                                   reason="needs POSIX signals")


# ----------------------------------------------------------------------------- the runner


class Reversed(Backend):
    """A backend that computes in this process and yields the outcomes in reverse order, as a
    cluster may; it also counts what it was asked to run."""

    name = "reversed"

    def __init__(self):
        self.asked = []
        self.stopped = 0

    def start(self, n_runs):
        self.workers = 3

    def outcomes(self, specs):
        self.asked.extend(specs)
        results = [(i, run_spec(spec)) for i, spec in enumerate(specs)]
        yield from reversed(results)

    def stop(self):
        self.stopped += 1


def test_runner_stores_each_outcome_under_its_own_spec_whatever_the_order(tmp_path):
    gains = [10.0, 20.0, 40.0, 80.0]
    specs = [control_spec(kp, 0.3) for kp in gains]
    backend = Reversed()
    progress = []
    with open_store(tmp_path / "r.sqlite") as store:
        runs = execute_specs(specs + specs[:2], store, backend, on_done=lambda done, total: progress.append((done, total)))
    assert len(backend.asked) == 4 and backend.stopped == 1  # duplicates asked for once
    assert progress == [(0, 4), (1, 4), (2, 4), (3, 4), (4, 4)]
    for spec in specs:
        record = runs[spec.hash()]["record"]
        assert record["kp"] == spec.kp and record["spec_hash"] == spec.hash() and record["jobs"] == 3
    # higher gains track better: the stored numbers belong to their own gains
    errors = [runs[s.hash()]["record"]["rmse_rot_deg"] for s in specs]
    assert errors == sorted(errors, reverse=True)


def test_runner_reuses_stored_runs_and_asks_the_backend_for_nothing(tmp_path):
    specs = [control_spec(kp, 0.3) for kp in (30.0, 60.0)]
    with open_store(tmp_path / "r.sqlite") as store:
        first = execute_specs(specs, store, LocalBackend(jobs=1))
        backend = Reversed()
        second = execute_specs(specs, store, backend)
        assert backend.asked == [] and backend.stopped == 0  # no worker acquired for nothing
        assert second == first
        third = execute_specs(specs, store, backend, rerun=True)
        assert len(backend.asked) == 2
    assert [third[s.hash()]["record"]["rmse_rot_deg"] for s in specs] == \
        [first[s.hash()]["record"]["rmse_rot_deg"] for s in specs]


def test_runner_stops_the_backend_when_storing_fails(tmp_path):
    class Failing(Reversed):
        def outcomes(self, specs):
            yield 0, Outcome(failed_record(specs[0], RuntimeError("boom")), [], None)
            raise RuntimeError("the cluster went away")

    backend = Failing()
    with open_store(tmp_path / "r.sqlite") as store:
        spec = control_spec(80.0, 0.3)
        with pytest.raises(RuntimeError, match="went away"):
            execute_specs([spec, control_spec(70.0, 0.3)], store, backend)
        assert backend.stopped == 1
        kept = store.get(spec.hash())["record"]  # what arrived before the failure is kept
    assert kept["status"] == "error" and kept["message"] == "RuntimeError: boom"


def _dies_on_kp_13(spec):
    """A run that kills its worker process (as the kernel's out-of-memory killer would)."""
    if spec.kp == 13.0:
        os._exit(9)
    return run_spec(spec)


def test_a_local_worker_that_dies_stops_the_sweep_with_a_clear_error_and_keeps_stored_runs(tmp_path, monkeypatch):
    import fdbench.execution as execution

    monkeypatch.setattr(execution, "run_spec", _dies_on_kp_13)  # workers fork with it
    specs = [control_spec(kp, 0.3) for kp in (80.0, 13.0)] + [control_spec(kp, 0.3) for kp in range(20, 30)]
    with open_store(tmp_path / "r.sqlite") as store:
        with pytest.raises(execution.ExecutionError, match="worker process died"):
            execute_specs(specs, store, LocalBackend(jobs=2))
        assert specs[1].hash() not in store.hashes()  # the lost run is not stored: a rerun computes it
        kept = store.count()
        monkeypatch.undo()
        execute_specs(specs, store, LocalBackend(jobs=2))
        assert store.count() == len(specs) and kept < len(specs)


# ----------------------------------------------------------------------------- parent death


def _alive(pid: int) -> bool:
    """True if ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as handle:
            text = handle.read()
    except OSError:
        return False
    return text[text.rindex(")") + 2] != "Z"


def _wait_gone(pids, timeout_s: float) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        alive = [pid for pid in pids if _alive(pid)]
        if not alive:
            return []
        time.sleep(0.05)
    return [pid for pid in pids if _alive(pid)]


@needs_proc
@needs_signals
@pytest.mark.parametrize("mechanism", ["pdeathsig", "watchdog"])
def test_a_worker_dies_with_its_parent(tmp_path, mechanism):
    """A middle process starts a child that calls die_with_parent and sleeps; the middle one is
    SIGKILLed. With 'watchdog' the kernel request is skipped (as on a system without prctl), so
    the polling thread alone must end the child."""
    child = textwrap.dedent(f"""
        import os, sys, time
        if {mechanism!r} == "watchdog":
            sys.platform = "other"
        from fdbench.execution import die_with_parent
        die_with_parent(os.getppid(), poll_s=0.05)
        print(os.getpid(), flush=True)
        time.sleep(600)  # until killed with its parent
    """)
    middle = textwrap.dedent(f"""
        import subprocess, sys, time
        child = subprocess.Popen([sys.executable, "-c", {child!r}], stdout=sys.stdout)
        time.sleep(600)  # until killed
    """)
    proc = subprocess.Popen([sys.executable, "-c", middle], stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        child_pid = int(proc.stdout.readline())
        assert _alive(child_pid)
        proc.kill()
        proc.wait(timeout=60)
        assert _wait_gone([child_pid], 60) == []
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()


# ----------------------------------------------------------------------------- killing a report


def _session(sid: int) -> list[int]:
    """Live processes of the session ``sid`` (the report and every process it started)."""
    pids = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat") as handle:
                    text = handle.read()
            except OSError:
                continue
            fields = text[text.rindex(")") + 2:].split()
            if int(fields[3]) == sid and fields[0] != "Z":
                pids.append(int(name))
    return pids


def _records(db: Path) -> dict:
    """{spec hash: record without its execution fields (times, job count)}."""
    con = sqlite3.connect(db, timeout=10)
    try:
        rows = con.execute("SELECT id, spec_hash, record_json FROM runs ORDER BY id").fetchall()
    finally:
        con.close()
    out = {}
    for _, key, text in rows:
        record = json.loads(text)
        out[key] = {k: v for k, v in record.items() if not _timing(k)}
    assert len(out) == len(rows)  # each run stored once
    return out


def _optimizations(records: dict) -> int:
    return sum(r["command"] == "optimize" for r in records.values())


def _timing(field: str) -> bool:
    """Fields that say how long or how parallel, not what was computed (runtime_s, jobs, and any
    other *time_s a method reports)."""
    return field == "jobs" or field.endswith("time_s")


def _count(db: Path) -> int:
    """Stored optimisation runs (the sweep's runs)."""
    try:
        con = sqlite3.connect(db, timeout=5)
        try:
            return con.execute("SELECT COUNT(*) FROM runs WHERE command = 'optimize'").fetchone()[0]
        finally:
            con.close()
    except sqlite3.OperationalError:
        return 0


SWEEP = ["report", "--torque", "cs", "--opt", GATED_OPTIMIZER, "--no-feedforward", "--no-control", "--seeds", "10",
         "--budget", "150", "--format", "csv", "-q"]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> dict:
    """The stored records of the sweep run to its end without interruption."""
    db = tmp_path_factory.mktemp("whole") / "whole.sqlite"
    gate = Gate(db.parent)
    gate.open()
    done = subprocess.run(FDBENCH + SWEEP + ["--jobs", "2", "--db", str(db)], capture_output=True, text=True,
                          timeout=300, cwd=db.parent, env=gate.env)
    assert done.returncode == 0, done.stderr
    return _records(db)


@needs_proc
@needs_signals
@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_killed_report_leaves_no_process_and_resumes_with_identical_numbers(tmp_path, signum, uninterrupted):
    db, gate = tmp_path / "killed.sqlite", Gate(tmp_path, from_seed=2)
    cmd = FDBENCH + SWEEP + ["--jobs", "2", "--db", str(db)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            start_new_session=True, env=gate.env)
    try:  # seeds 0 and 1 stored, both workers inside a run of a later seed
        wait_until(lambda: _count(db) == 2 and len(_session(proc.pid)) >= 3,
                   "seeds 0 and 1 were stored with the workers running", proc)
        members = _session(proc.pid)
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=120)  # also waits for every holder of its pipes
        assert _wait_gone(members, 60) == [] and _session(proc.pid) == []
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
    if signum == signal.SIGKILL:
        assert proc.returncode == -signal.SIGKILL
    else:
        assert proc.returncode in (143, 130)
        assert out == "" and "Traceback" not in err
        assert err.strip().splitlines() == ["fdbench: error: terminated"]
    kept = _records(db)
    assert sorted(r["seed"] for r in kept.values()) == [0, 1]

    gate.open()
    resumed = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path, env=gate.env)
    assert resumed.returncode == 0, resumed.stderr
    after = _records(db)
    assert {k: after[k] for k in kept} == kept  # nothing stored before the kill was redone or lost
    assert after == uninterrupted  # the numbers of an uninterrupted report
    assert _optimizations(after) == 10


# ----------------------------------------------------------------------------- warm workers

WARM_PROBE = textwrap.dedent("""
    import gc, json, sys
    from numba.core.registry import CPUDispatcher
    import fdbench.method_runs as runs
    import fdbench.torques.ann as ann
    from fdbench.execution import LocalBackend, execute_specs
    from fdbench.spec import optimize_spec
    from fdbench.store import open_store

    def signatures():
        return sum(len(d.signatures) for d in gc.get_objects() if isinstance(d, CPUDispatcher))

    pretrained, calls, run = [], [], runs.run
    pretrain = ann.pretrain
    ann.pretrain = lambda *a, **k: pretrained.append(1) or pretrain(*a, **k)

    def watched(spec, *args, **kwargs):  # compiled signatures and ANN pretrainings during each run
        before, fits = signatures(), len(pretrained)
        outcome = run(spec, *args, **kwargs)
        calls.append({"budget": spec.budget, "compiled": signatures() - before, "pretrained": len(pretrained) - fits})
        return outcome

    runs.run = watched
    specs = [optimize_spec("ann", "cmaes", seed=s, budget=12) for s in (0, 1)]
    specs += [optimize_spec("cs", "bfgs", seed=0, budget=6)]
    with open_store(sys.argv[1]) as store:
        execute_specs(specs, store, LocalBackend(jobs=1))
    print(json.dumps(calls))
""")


def test_a_process_is_warm_before_its_first_timed_run(tmp_path):
    """In a fresh process (a worker), the first run of a method neither compiles a kernel nor
    pretrains the ANN inside its clock: the runner warms the process for it first, so the first
    run's runtime is comparable with the others'."""
    done = subprocess.run([sys.executable, "-c", WARM_PROBE, str(tmp_path / "warm.sqlite")], capture_output=True,
                          text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    calls = json.loads(done.stdout.strip().splitlines()[-1])
    timed = [c for c in calls if c["budget"] in (12, 6)]
    assert len(timed) == 3
    assert all(c["compiled"] == 0 and c["pretrained"] == 0 for c in timed), calls


def test_report_settings_say_what_was_carried_out_and_where(tmp_path):
    from typer.testing import CliRunner

    from fdbench.cli import app

    args = ["report", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--no-control", "--no-beyond",
            "--seeds", "2", "--budget", "5", "--jobs", "1", "--db", str(tmp_path / "s.sqlite"), "-f", "json", "-q"]
    first = CliRunner().invoke(app, args)
    again = CliRunner().invoke(app, args)
    assert first.exit_code == again.exit_code == 0, first.stderr + again.stderr
    assert json.loads(first.stdout)["settings"]["parallel jobs"] == "2 runs on this machine, one at a time"
    assert json.loads(again.stdout)["settings"]["parallel jobs"] == "none: every run was stored"


FLOATING = """
name = "floating"

[[bodies]]
name = "trunk"
mass = 10.0
com = [0.0, 0.2]
inertia = 0.5

[[joints]]
name = "base"
type = "free"
parent = "ground"
child = "trunk"
at_parent = [0.0, 0.0]
at_child = [0.0, 0.0]
coordinates = ["tilt", "tx", "ty"]
"""


def test_the_parent_warms_the_kernels_of_every_family_its_runs_use(tmp_path, monkeypatch):
    """Before forking its workers the local backend loads the kernels once for them all: for every
    kind of model its runs use (a free joint's variant too, else every worker would compile it at
    once), and scipy's integrators when a run uses one."""
    import fdbench.multibody.simulation as simulation
    from fdbench import execution
    from fdbench.spec import with_model_file

    asked = []
    for owner in (simulation, execution):  # wherever execution finds it
        if hasattr(owner, "warm_up"):
            monkeypatch.setattr(owner, "warm_up", lambda adaptive=False, engines=():
                                asked.append((adaptive, {simulation.kind(e) for e in engines})) or [])
    model = tmp_path / "floating.toml"
    model.write_text(FLOATING)
    floating = with_model_file(control_spec(model_name=str(model)))
    execution._prepare_parent([control_spec(), control_spec(model_name="arm2")])
    execution._prepare_parent([control_spec(), floating])
    execution._prepare_parent([control_spec(integrator="rk45")])
    pins, free = (True, True, True), (True, False, True)  # (no paths, no free joints, no loads)
    assert asked == [(False, {pins}), (False, {pins, free}), (True, {pins})]


def test_compile_tasks_give_one_task_per_kernel_variant(tmp_path):
    """The kernels compiled side by side: RK4 once per kind of model (the forearm's pin joints
    always, arm2 and arm26 share them; a free joint is another kind), and the muscles' RK4 once per
    kind of model with muscles (arm26's)."""
    from fdbench.models import find_model
    from fdbench.multibody.engine import Engine
    from fdbench.multibody.simulation import COMPILE_S, compile_tasks

    model = tmp_path / "floating.toml"
    model.write_text(FLOATING)
    arm2, floating, arm26 = (Engine(find_model(name)) for name in ("arm2", str(model), "arm26"))
    seconds = sorted(s for s, _ in compile_tasks([arm2, floating, arm2, arm26, floating, arm26]))
    assert seconds == sorted([COMPILE_S["rk4", False], COMPILE_S["rk4", True], COMPILE_S["muscles", False]])


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_compiling_side_by_side_runs_every_task_once_in_other_processes(tmp_path):
    """Each task runs once, in one of at most ``processes`` child processes, never in the caller;
    a failing task does not stop the others."""
    from fdbench.execution import compile_side_by_side

    def task(name):
        def run():
            (tmp_path / name).write_text(str(os.getpid()))
            if name == "c":
                raise RuntimeError("a kernel that fails to compile")
        return run

    names = ["a", "b", "c", "d", "e"]
    compile_side_by_side([(float(k), task(n)) for k, n in enumerate(names)], processes=2)
    pids = {(tmp_path / name).read_text() for name in names}
    assert len(pids) == 2 and str(os.getpid()) not in pids
