"""The Dask backend against a real cluster on 127.0.0.1: a scheduler and two workers started as
subprocesses, as a user starts them. A report through ``--backend dask --scheduler`` gives
exactly the numbers of the local backend; a worker killed during a sweep loses and duplicates no
run; a worker running another fdbench version is refused; a client stopped by SIGTERM leaves no
process and resumes; without Dask installed the backend is refused with the install command.
Network traffic stays on 127.0.0.1; every subprocess is stopped in a ``finally``."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from helpers.processes import GATED_OPTIMIZER, Gate, scheduler_address, start_in_session, stop_session, wait_until

FDBENCH = [sys.executable, "-m", "fdbench.cli"]
SMALL = ["report", "--torque", "cs", "--opt", "bfgs", "--seeds", "2", "--budget", "20"]
def _execution_field(name: str) -> bool:
    """How long and how parallel (runtime_s, jobs, any other *time_s): the only fields that may differ."""
    return name == "jobs" or name.endswith("time_s")


def _needs_dask():
    pytest.importorskip("distributed", reason="Dask distributed is not installed (pip install '.[dask]')")


@contextmanager
def dask_cluster(tmp_path: Path, workers: int = 2, preload: Path | None = None):
    """A scheduler on 127.0.0.1 (a free port chosen by the system) and ``workers`` single-threaded
    workers, each a subprocess in its own session; yields (address, worker processes, scheduler
    process)."""
    _needs_dask()
    from distributed import Client

    procs = []
    try:
        log = tmp_path / "scheduler.log"
        scheduler = start_in_session([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                            "--port", "0", "--no-dashboard"], log, tmp_path)
        procs.append(scheduler)
        address = scheduler_address(scheduler, log)
        assert address.startswith("tcp://127.0.0.1:")
        worker_procs = []
        for i in range(workers):
            args = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--host", "127.0.0.1",
                    "--nthreads", "1", "--nworkers", "1", "--no-dashboard", "--name", f"w{i}",
                    "--local-directory", str(tmp_path / f"w{i}")]
            if preload is not None:
                args += ["--preload", str(preload)]
            worker_procs.append(start_in_session(args, tmp_path / f"w{i}.log", tmp_path))
        procs.extend(worker_procs)
        if workers:
            with Client(address, timeout="30s", set_as_default=False) as client:
                client.wait_for_workers(workers, timeout=60)
        yield address, worker_procs, scheduler
    finally:
        for proc in reversed(procs):
            stop_session(proc)


def _fdbench(*args, cwd, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run(FDBENCH + [str(a) for a in args], capture_output=True, text=True, timeout=timeout, cwd=cwd)


def stored(db: Path) -> dict:
    """{spec hash: record without its execution fields} straight from SQLite, and the row count."""
    con = sqlite3.connect(db)
    try:
        rows = con.execute("SELECT spec_hash, record_json FROM runs").fetchall()
    finally:
        con.close()
    records = {}
    for key, text in rows:
        records[key] = {k: v for k, v in json.loads(text).items() if not _execution_field(k)}
    assert len(records) == len(rows)
    return records


def _numbers(csv_text: str) -> list[list[str]]:
    """The report's CSV without its time columns (time depends on the machine, nothing else may)."""
    import csv
    import io

    lines = list(csv.reader(io.StringIO(csv_text)))
    keep = [i for i, name in enumerate(lines[0]) if "time" not in name and "speedup" not in name]
    return [[row[i] for i in keep] for row in lines]


def test_report_on_a_dask_cluster_equals_the_local_backend(tmp_path):
    with dask_cluster(tmp_path) as (address, _, _):
        remote = _fdbench(*SMALL, "--backend", "dask", "--scheduler", address, "--db", tmp_path / "dask.sqlite",
                          "--format", "csv", "-q", cwd=tmp_path)
    assert remote.returncode == 0, remote.stderr
    local = _fdbench(*SMALL, "--backend", "local", "--jobs", 2, "--db", tmp_path / "local.sqlite", "--format", "csv",
                     "-q", cwd=tmp_path)
    assert local.returncode == 0, local.stderr
    on_dask, on_local = stored(tmp_path / "dask.sqlite"), stored(tmp_path / "local.sqlite")
    assert _optimizations(on_local) == 4 and "control" in {r["command"] for r in on_local.values()}  # 2 cells x 2 seeds
    assert on_dask == on_local  # every number and setting of every run, exactly
    assert all(r["status"] == "success" for r in on_dask.values())
    assert _numbers(remote.stdout) == _numbers(local.stdout)


def test_a_worker_killed_during_a_sweep_loses_and_duplicates_nothing(tmp_path, monkeypatch):
    db, gate = tmp_path / "killed.sqlite", Gate(tmp_path, from_seed=2)
    for name in ("FDBENCH_PLUGINS", "FDBENCH_GATE", "FDBENCH_GATE_FROM", "PYTHONPATH"):
        monkeypatch.setenv(name, gate.env[name])  # for the workers as for the client
    seeds = 8
    sweep_args = ["report", "--torque", "cs", "--opt", GATED_OPTIMIZER, "--no-feedforward", "--no-control",
                  "--seeds", seeds, "--budget", 150]
    args = sweep_args + ["--db", db, "--format", "csv", "-q"]
    with dask_cluster(tmp_path) as (address, workers, _):
        sweep = subprocess.Popen(FDBENCH + [str(a) for a in args] + ["--backend", "dask", "--scheduler", address],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
        try:  # seeds 0 and 1 stored, both workers inside runs of later seeds: kill one, open the gate
            wait_until(lambda: _count(db) == 2, "seeds 0 and 1 were stored", sweep)
            os.killpg(workers[0].pid, signal.SIGKILL)  # the worker and its nanny, mid-run
            stored_at_kill = _count(db)
            gate.open()
            out, err = sweep.communicate(timeout=300)
        finally:
            if sweep.poll() is None:
                sweep.kill()
                sweep.wait()
    assert sweep.returncode == 0, err
    assert stored_at_kill == 2  # killed mid-sweep, with runs in flight
    runs = stored(db)
    con = sqlite3.connect(db)
    try:
        total, distinct = con.execute("SELECT COUNT(*), COUNT(DISTINCT spec_hash) FROM runs "
                                      "WHERE command = 'optimize'").fetchone()
        seeds_stored = sorted(row[0] for row in con.execute("SELECT seed FROM runs WHERE command = 'optimize'"))
    finally:
        con.close()
    assert total == distinct == seeds and seeds_stored == list(range(seeds))
    # the same runs computed locally give the same numbers: the retried run was not corrupted
    local = _fdbench(*sweep_args, "--db", tmp_path / "local.sqlite", "--jobs", 2, "-q", cwd=tmp_path)
    assert local.returncode == 0, local.stderr
    assert stored(tmp_path / "local.sqlite") == runs


def _optimizations(records: dict) -> int:
    return sum(r["command"] == "optimize" for r in records.values())


def _count(db: Path, command: str = "optimize") -> int:
    """Stored runs of this command (those of the sweeps here), or of every command (None)."""
    if not db.exists():
        return 0
    try:
        con = sqlite3.connect(db, timeout=5)
        try:
            if command is None:
                return con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
            return con.execute("SELECT COUNT(*) FROM runs WHERE command = ?", (command,)).fetchone()[0]
        finally:
            con.close()
    except sqlite3.OperationalError:
        return 0


def test_a_worker_with_another_fdbench_version_is_refused(tmp_path):
    preload = tmp_path / "other_version.py"
    preload.write_text("import fdbench, fdbench.execution\n"
                       "fdbench.__version__ = fdbench.execution.__version__ = '0.0.0-other'\n")
    db = tmp_path / "refused.sqlite"
    with dask_cluster(tmp_path, workers=1, preload=preload) as (address, _, _):
        done = _fdbench(*SMALL, "--backend", "dask", "--scheduler", address, "--db", db, "-q", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error: ")
    assert "0.0.0-other" in lines[0] and "fdbench" in lines[0] and address in lines[0]
    assert _count(db, None) == 0  # nothing ran


def test_a_run_that_raises_is_stored_as_failed_on_a_local_dask_cluster_as_on_the_local_backend(tmp_path):
    """Without --scheduler the backend starts a LocalCluster of --jobs workers. A spec that cannot
    run (an unknown torque, past the command line's checks) is stored as a failed run with its
    message, the same record on both backends."""
    _needs_dask()
    from fdbench.execution import DaskBackend, LocalBackend, execute_specs
    from fdbench.spec import control_spec, optimize_spec
    from fdbench.store import open_store

    specs = [control_spec(80.0, 0.3), control_spec(40.0, 0.3), optimize_spec("no-such-torque", "bfgs", seed=0, budget=5)]
    results = {}
    for name, backend in (("local", LocalBackend(jobs=2)), ("dask", DaskBackend(jobs=2))):
        with open_store(tmp_path / f"{name}.sqlite") as store:
            runs = execute_specs(specs, store, backend)
        assert backend.client is None if name == "dask" else True  # the cluster is closed
        assert set(runs) == {s.hash() for s in specs}
        results[name] = stored(tmp_path / f"{name}.sqlite")
    assert results["dask"] == results["local"]
    failed = results["local"][specs[2].hash()]
    assert failed["status"] == "error" and "no-such-torque" in failed["message"]
    assert failed["rmse_rot_deg"] is None and failed["seed"] == 0 and failed["torque"] == "no-such-torque"
    assert [results["local"][s.hash()]["status"] for s in specs[:2]] == ["success", "success"]


def test_dask_backend_without_dask_installed_exits_2_with_the_install_command(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    db = tmp_path / "none.sqlite"
    result = CliRunner().invoke(app, [*SMALL, "--backend", "dask", "--db", str(db), "-q"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error: ")
    assert "pip install '.[dask]'" in lines[0]
    assert not db.exists()  # refused before anything was opened or run


@pytest.mark.parametrize("args, option", [
    (["--backend", "spark"], "--backend"),
    (["--scheduler", "tcp://127.0.0.1:8786"], "--scheduler"),  # without --backend dask
    (["--backend", "dask", "--scheduler", " "], "--scheduler"),
])
def test_bad_backend_options_exit_2_before_any_work(tmp_path, args, option):
    if "dask" in args:
        _needs_dask()
    db = tmp_path / "bad.sqlite"
    result = CliRunner().invoke(app, [*SMALL, *args, "--db", str(db), "-q"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error: ") and option in lines[0]
    assert not db.exists()


BAD_ADDRESSES = ["http://x:1", "tcps://x:1", "ucx://x:1", "inproc://x", "not an address", "tcp://x:1\nx",
                 "tcp://127.0.0.1:" + "9" * 5000, "tcp://127.0.0.1:0", "127.0.0.1", "tcp://:8786", "tcp://a b:1", "tcp://x:\u00b2"]


@pytest.mark.parametrize("address", BAD_ADDRESSES, ids=lambda a: a[:20].replace("\n", "NL"))
def test_an_invalid_scheduler_address_exits_2_with_one_line_before_anything_is_written(tmp_path, address):
    _needs_dask()
    db = tmp_path / "never.sqlite"
    result = CliRunner().invoke(app, [*SMALL, "--backend", "dask", "--scheduler", address, "--db", str(db), "-q"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error: --scheduler ") and len(lines[0]) < 300
    assert "tcp://" in lines[0]  # says what an address looks like
    assert not db.exists()


def test_an_invalid_scheduler_address_leaves_no_traceback_at_exit(tmp_path):
    _needs_dask()
    done = _fdbench(*SMALL, "--backend", "dask", "--scheduler", "http://x:1", "--db", tmp_path / "t.sqlite", "-q",
                    cwd=tmp_path, timeout=120)
    assert done.returncode == 2 and done.stdout == ""
    assert len(done.stderr.splitlines()) == 1 and "Traceback" not in done.stderr
    assert not (tmp_path / "t.sqlite").exists()


@contextmanager
def loopback_server(answer: bytes | None):
    """A TCP server on 127.0.0.1 that accepts every connection and sends ``answer`` (None: says
    nothing); yields its port, and stops (closing every connection) on leaving."""
    import socket
    import threading

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    listener.settimeout(0.2)
    accepted, stopping = [], threading.Event()

    def serve():
        while not stopping.is_set():
            try:
                conn, _ = listener.accept()
            except OSError:
                continue
            accepted.append(conn)
            if answer is not None:
                try:
                    conn.sendall(answer)
                except OSError:
                    pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield listener.getsockname()[1]
    finally:
        stopping.set()
        thread.join(timeout=5)
        for conn in accepted:
            conn.close()
        listener.close()


def test_a_server_that_is_not_a_dask_scheduler_exits_2_with_one_line(tmp_path):
    _needs_dask()
    db = tmp_path / "never.sqlite"
    with loopback_server(b"HTTP/1.1 400 Bad Request\r\n\r\n") as port:
        done = _fdbench(*SMALL, "--backend", "dask", "--scheduler", f"tcp://127.0.0.1:{port}", "--db", db, "-q",
                        cwd=tmp_path, timeout=120)
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and f"127.0.0.1:{port}" in lines[0] and "not a Dask scheduler" in lines[0]
    assert not db.exists()


def test_a_silent_server_is_refused_within_the_connect_timeout():
    """A server that accepts and never answers: the backend gives up after its timeout (5 s
    from the command line, 1 s here) with one line, instead of waiting for ever."""
    _needs_dask()
    import threading

    from fdbench.execution import BackendError, DaskBackend

    failures = []
    with loopback_server(None) as port:
        backend = DaskBackend(scheduler=f"tcp://127.0.0.1:{port}", connect_timeout_s=1)
        backend.check()

        def start():
            try:
                backend.start(1)
            except BackendError as exc:
                failures.append(str(exc))

        attempt = threading.Thread(target=start, daemon=True)
        attempt.start()
        attempt.join(timeout=60)
    assert not attempt.is_alive(), "the backend still waits for a server that never answers"
    assert len(failures) == 1 and "no answer from a Dask scheduler within 1 s" in failures[0]
    assert backend.client is None


def test_a_scheduler_lost_mid_report_exits_1_with_one_line_and_keeps_the_stored_runs(tmp_path, monkeypatch):
    db, gate = tmp_path / "lost.sqlite", Gate(tmp_path, from_seed=2)
    for name in ("FDBENCH_PLUGINS", "FDBENCH_GATE", "FDBENCH_GATE_FROM", "PYTHONPATH"):
        monkeypatch.setenv(name, gate.env[name])  # for the workers as for the client
    args = ["report", "--torque", "cs", "--opt", GATED_OPTIMIZER, "--no-feedforward", "--no-control", "--no-beyond",
            "--seeds", 8, "--budget", 150, "--db", db, "--format", "csv", "-q"]
    with dask_cluster(tmp_path, workers=1) as (address, _, scheduler):
        sweep = subprocess.Popen(FDBENCH + [str(a) for a in args] + ["--backend", "dask", "--scheduler", address],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
        try:  # seeds 0 and 1 stored, the worker held inside a later seed's run: the scheduler goes
            wait_until(lambda: _count(db) == 2, "seeds 0 and 1 were stored", sweep)
            os.killpg(scheduler.pid, signal.SIGKILL)
            out, err = sweep.communicate(timeout=120)
        finally:
            if sweep.poll() is None:
                sweep.kill()
                sweep.wait()
    assert sweep.returncode == 1 and out == ""
    lines = err.splitlines()
    assert len(lines) == 1 and "lost the connection to the Dask scheduler" in lines[0] and address in lines[0]
    assert "run the command again to resume" in lines[0]
    assert _count(db) == 2  # the runs stored before the scheduler went are kept


def test_a_fully_stored_report_needs_no_dask_worker_and_says_nothing_ran(tmp_path):
    db = tmp_path / "stored.sqlite"
    tiny = ["report", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--no-control", "--no-beyond", "--seeds", "1",
            "--budget", "5", "--db", str(db), "-f", "json", "-q"]
    assert CliRunner().invoke(app, [*tiny, "--jobs", "1"]).exit_code == 0
    with dask_cluster(tmp_path, workers=0) as (address, _, _):
        done = CliRunner().invoke(app, [*tiny, "--backend", "dask", "--scheduler", address])
    assert done.exit_code == 0, done.stderr
    assert json.loads(done.stdout)["settings"]["parallel jobs"] == "none: every run was stored"


def test_an_unreachable_scheduler_exits_2_naming_it(tmp_path):
    _needs_dask()
    import socket

    with socket.socket() as probe:  # a port on 127.0.0.1 where nothing listens
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    from fdbench.execution import BackendError, DaskBackend

    backend = DaskBackend(scheduler=address, connect_timeout_s=1)
    backend.check()
    with pytest.raises(BackendError, match=f"--scheduler {address}: cannot connect"):
        backend.start(1)
    assert backend.client is None


def _session(sid: int) -> list[int]:
    """Live processes of the session ``sid``: a command and everything it started."""
    pids = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                text = Path(f"/proc/{name}/stat").read_text()
            except OSError:
                continue
            fields = text[text.rindex(")") + 2:].split()
            if int(fields[3]) == sid and fields[0] != "Z":
                pids.append(int(name))
    return pids


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc to list processes")
def test_a_terminated_client_of_a_local_dask_cluster_leaves_nothing_and_resumes(tmp_path):
    """SIGTERM: the client cancels its tasks, closes its cluster and exits 143; the runs stored
    are kept and the same command completes the rest."""
    _needs_dask()
    signum = signal.SIGTERM
    db, gate = tmp_path / "client.sqlite", Gate(tmp_path, from_seed=2)
    seeds = 6
    cmd = FDBENCH + ["report", "--torque", "cs", "--opt", GATED_OPTIMIZER, "--no-feedforward", "--no-control",
                     "--seeds", str(seeds), "--budget", "150", "--backend", "dask", "--jobs", "2", "--db", str(db), "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            start_new_session=True, env=gate.env)
    try:  # seeds 0 and 1 stored, the cluster's workers inside runs of later seeds
        wait_until(lambda: _count(db) == 2 and len(_session(proc.pid)) >= 3,
                   "seeds 0 and 1 were stored with the cluster's workers running", proc)
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=120)
        wait_until(lambda: _session(proc.pid) == [], "every process of the client's session ended")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
    assert proc.returncode == 143 and out == ""
    assert err.strip().splitlines()[-1] == "fdbench: error: terminated" and "Traceback" not in err
    kept = stored(db)
    assert sorted(r["seed"] for r in kept.values()) == [0, 1]
    gate.open()
    resumed = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path, env=gate.env)
    assert resumed.returncode == 0, resumed.stderr
    after = stored(db)
    assert _optimizations(after) == seeds and {k: after[k] for k in kept} == kept


def test_task_failures_become_one_line_errors_that_say_what_to_do():
    """How a finished task's failure reaches the user: workers that kept dying, a worker of
    another version, anything else a worker raised."""
    _needs_dask()
    from distributed import KilledWorker

    from fdbench.execution import BackendError, ExecutionError, VersionMismatch, _task_result

    class Failed:
        def __init__(self, exc):
            self.exc = exc

        def result(self):
            raise self.exc

    class Died(KilledWorker):  # the constructor's arguments vary across Dask versions
        def __init__(self):
            Exception.__init__(self, "task-1")

        def __str__(self):
            return "attempted to run task-1 on 3 different workers, which all died"

    with pytest.raises(ExecutionError, match="kept dying.*run the command again to resume"):
        _task_result(Failed(Died()))
    with pytest.raises(BackendError, match="fdbench 9.9"):
        _task_result(Failed(VersionMismatch("this worker runs fdbench 9.9, the client 0.1.0")))
    with pytest.raises(ExecutionError, match="ModuleNotFoundError: No module named 'fdbench'"):
        _task_result(Failed(ModuleNotFoundError("No module named 'fdbench'")))
    with pytest.raises(KeyboardInterrupt):
        _task_result(Failed(KeyboardInterrupt()))
