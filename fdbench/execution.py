"""Execution of a list of run specifications by a backend, and storage of each run as it ends.

A backend receives the runs still missing and yields each one's outcome as soon as it is known:
``local`` runs them in worker processes on this machine (``--jobs`` of them), ``dask`` on the
workers of a Dask distributed cluster (a scheduler given by its address, or a local cluster).
Everything else is the same code for every backend (:func:`execute_specs`): stored runs are
reused by settings hash, each new run is stored by this process alone (workers never open the
results database) as soon as its outcome arrives, so an interrupted sweep loses at most the runs
in flight and resumes where it stopped. A run that raises is stored as a failed run
(``status = "error"``) with the exception as its message, whatever the backend.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import tempfile
import threading
from abc import ABC, abstractmethod
from contextlib import closing, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from . import __version__
from .compile_guard import compiling, interrupts_end_compiling  # noqa: F401 (fdbench.execution's names before)
from .registry import Registry

DASK_INSTALL = "pip install '.[dask]' in fdbench's source folder (or pip install 'dask[distributed]' cryptography)"
PARENT_POLL_S = 0.5  # how often a local worker checks that its parent is alive
SAFE_PATH = sys.version_info >= (3, 11)  # PYTHONSAFEPATH keeps the current folder off a child Python's path


class BackendError(Exception):
    """The backend cannot be used (not installed, unreachable, another fdbench version on a
    worker): bad usage, checked before any run starts where possible. One-line message."""


class ExecutionError(Exception):
    """The backend failed during a sweep (a worker process died, a task kept failing); the runs
    stored so far are kept and a rerun resumes."""


class Terminated(KeyboardInterrupt):
    """SIGTERM was received: the command stops as it does on Ctrl-C."""


class VersionMismatch(Exception):
    """Raised on a worker whose fdbench version differs from the client's."""


@dataclass(frozen=True)
class Outcome:
    """What the store needs of one finished run; small and picklable.

    record: the flat record of the command-line contract; history: best-so-far objective per
    evaluation (length = evaluations, empty for control); params: the best parameters of an
    optimisation (length n_params) or None."""

    record: dict
    history: list
    params: list | None = None


# ---- one run, on whichever worker ----------------------------------------------------------------


def run_spec(spec) -> Outcome:
    """Carry out one run, once this process is warm for its method (:func:`warm_up_for`); an
    exception becomes a failed run's outcome, never a lost run."""
    from .method_runs import run

    warm_up_for(spec)
    try:
        outcome = run(spec)
    except Exception as exc:  # noqa: BLE001 - a benchmark run never dies: it is recorded as failed
        return Outcome(failed_record(spec, exc), [], None)
    params = None if outcome.params is None else [float(v) for v in outcome.params]
    return Outcome(outcome.record, [float(v) for v in outcome.history], params)


WARM_UP_BUDGET = 2  # evaluations of the miniature optimisation that warms a process for a run
_WARM: set = set()  # what this process is warm for (see warm_up_for)


def warm_up_for(spec) -> None:
    """Before a timed run, make this process warm for it by a miniature run, neither stored nor
    timed: every kernel and import the run uses (RK4, population and torque kernels; with
    ``--actuation muscles`` the muscles' population and sensitivity kernels on the run's model;
    scipy, cma) is then loaded or compiled, and what a method computes once per settings and keeps (the
    ANN's pretraining) is there, so a worker's first run costs what its later runs cost, on
    every backend. An optimisation is warmed per settings (seed 0, ``WARM_UP_BUDGET``
    evaluations), control once per controller, model and integrator. Collocation is left to its
    own run, which imports CasADi before its clock starts."""
    from dataclasses import replace

    if spec.command == "optimize":
        miniature = replace(spec, budget=WARM_UP_BUDGET, seed=0)
        key = miniature.hash()
    elif spec.command == "control":
        miniature = spec
        key = ("control", spec.controller, spec.model_name, spec.integrator)
    else:
        return
    if key in _WARM:
        return
    _WARM.add(key)
    from .method_runs import run

    try:
        run(miniature)
    except Exception:  # noqa: BLE001 - the run itself records what is wrong with its spec
        pass


def run_batch(specs, client_version: str | None = None) -> list[Outcome]:
    """Carry out several runs in order (one task of a distributed backend). ``client_version``,
    when given, must equal this worker's fdbench version."""
    if client_version is not None and client_version != __version__:
        raise VersionMismatch(f"this worker runs fdbench {__version__}, the client {client_version}")
    return [run_spec(spec) for spec in specs]


def failed_record(spec, exc: BaseException) -> dict:
    """The record of a run that raised: its settings, status 'error', the exception as message."""
    from .records import base_record

    record = base_record(spec)
    if spec.command == "control":
        record.update(torque="id", kp=spec.kp, kd=spec.kd)
    elif spec.command == "optimize":
        record.update(torque=spec.torque, optimizer=spec.optimizer, seed=spec.seed, budget=spec.budget,
                      penalty_weight=spec.penalty_weight)
    message = " ".join(f"{type(exc).__name__}: {exc}".split())
    record.update(status="error", message=message)
    return record


def worker_version() -> str:
    """fdbench's version where this function runs (asked of every Dask worker)."""
    return __version__


def warm_up_worker() -> None:
    """Compile or load the kernels once, before the first run (not counted in any runtime)."""
    from .multibody.simulation import warm_up
    from .tracking import warm_up as warm_up_population

    warm_up_population(warm_up())


# ---- the backends ---------------------------------------------------------------------------------


class Backend(ABC):
    """Executes runs. ``connect()`` reaches remote workers before the store is opened,
    ``start(n)`` acquires the workers for n runs (raising BackendError if they cannot be had),
    ``outcomes(specs)`` yields ``(index into specs, Outcome)`` as runs end, ``stop()`` releases
    everything (also after an interruption). ``workers`` is the number of runs carried out at
    once, stored with every run as ``jobs``; ``carried_out`` counts the runs this backend made."""

    name = ""
    workers = 1
    carried_out = 0

    def check(self) -> None:
        """Checks that need no worker (an installed library, option combinations, an address):
        run before any work, also when every run is already stored."""

    def connect(self) -> None:
        """Reach the workers that exist independently of this command (a Dask scheduler), so
        that an unreachable one is refused before anything is written; nothing by default."""

    def start(self, n_runs: int) -> None:
        """Acquire workers for ``n_runs`` runs; calling it again with the same count changes nothing."""

    @abstractmethod
    def outcomes(self, specs: list) -> Iterator[tuple[int, Outcome]]:
        """Yield ``(i, outcome of specs[i])`` for every spec, in the order runs end."""

    def stop(self) -> None:
        """Release the workers; safe to call more than once."""

    def describe(self) -> str:
        """What was carried out where, for a report's settings: 'none: every run was stored',
        or the number of runs and the workers that made them."""
        if not self.carried_out:
            return "none: every run was stored"
        runs = f"{self.carried_out} run{'s' if self.carried_out != 1 else ''}"
        return f"{runs} on {self.where()}"

    def where(self) -> str:
        return f"{self.workers} {self.name} worker{'s' if self.workers != 1 else ''}"


BACKENDS: Registry[type] = Registry("backend")


def make_backend(name: str, jobs: int | None = None, scheduler: str | None = None, **options) -> Backend:
    """The backend of this name (``local`` or ``dask``), checked (``BackendError`` otherwise)."""
    from .registry import UnknownName

    try:
        cls = BACKENDS[name]
    except UnknownName as exc:
        raise BackendError(f"--backend: {exc}") from None
    backend = cls(jobs=jobs, scheduler=scheduler, **options)
    backend.check()
    return backend


@BACKENDS.register("local")
class LocalBackend(Backend):
    """``jobs`` worker processes on this machine (forked after the kernels are loaded), one run
    per task; with one job, or one run, everything happens in this process. Workers die with
    this process, whatever ends it (SIGKILL included)."""

    name = "local"

    def __init__(self, jobs: int | None = None, scheduler: str | None = None):
        if scheduler is not None:
            raise BackendError("--scheduler is an option of --backend dask; the local backend uses --jobs")
        if jobs is not None and jobs < 1:
            raise BackendError(f"--jobs must be an integer >= 1, got {jobs}")
        self.jobs = jobs or os.cpu_count() or 1

    def start(self, n_runs: int) -> None:
        self.workers = max(1, min(self.jobs, n_runs))

    def where(self) -> str:
        if self.workers == 1:
            return "this machine, one at a time"
        return f"this machine, {self.workers} worker processes at a time"

    def outcomes(self, specs):
        _prepare_parent(specs, self.workers)
        if self.workers == 1 or len(specs) == 1:
            for index, spec in enumerate(specs):
                yield index, run_spec(spec)
            return
        yield from _pool_outcomes(specs, self.workers)


def _prepare_parent(specs, workers: int = 1) -> None:
    """Compile/load the kernels (and import cma) once, before worker processes fork: those of
    every kind of model the runs use (pin joints; paths, free joints, loads: the kernels compile
    one variant per kind), the population kernel for optimisations, scipy's integrators, so that
    the workers inherit them instead of each
    compiling the same kernels at the same time (a first walk report compiled its dense RK4 and
    population kernels in both workers: about 140 s of CPU twice). With several workers, RK4 of
    each kind is first compiled side by side in as many processes (``compile_side_by_side``). What
    only some runs need (the sensitivities of exact gradients) the workers compile, beside the other
    runs."""
    from .multibody.simulation import compile_tasks, warm_up
    from .tracking import warm_up as warm_up_population

    engines = [e for e in map(_engine, specs) if e is not None]
    if workers > 1:
        compile_side_by_side(compile_tasks(engines), workers)
    engines = warm_up(any(getattr(s, "integrator", "rk4") != "rk4" for s in specs), engines)
    if any(getattr(s, "command", None) == "optimize" for s in specs):
        warm_up_population(engines)
    if any(getattr(s, "optimizer", None) == "cmaes" for s in specs):
        import cma  # noqa: F401


NOTICE_AFTER_S = 1.0  # kernels loaded from the cache take less: no notice of compiling


def compile_side_by_side(tasks, processes: int) -> None:
    """Run ``tasks`` ((seconds, function) pairs: ``simulation.compile_tasks``) in up to
    ``processes`` forked processes at once, the longest first each to the least loaded process,
    so that numba's cache holds their kernels when this process loads them. A task that fails is
    left to this process (which compiles what is not in the cache); the processes die with this
    one (Ctrl-C included)."""
    import multiprocessing
    import time

    shares = [[] for _ in range(min(processes, len(tasks)))]
    loads = [0.0] * len(shares)
    for seconds, task in sorted(tasks, key=lambda t: -t[0]):
        least = loads.index(min(loads))
        shares[least].append(task)
        loads[least] += seconds
    if len(shares) < 2 or not hasattr(os, "fork"):
        return
    context = multiprocessing.get_context("fork")
    children = [context.Process(target=_compile_share, args=(share, os.getpid()), daemon=True) for share in shares]
    try:
        with compiling():  # Ctrl-C ends this process, and the children with it
            for child in children:
                child.start()
            deadline = time.monotonic() + NOTICE_AFTER_S
            for child in children:
                child.join(max(0.0, deadline - time.monotonic()))
            if any(child.is_alive() for child in children):
                from .jit import compile_notice

                with compile_notice():
                    for child in children:
                        child.join()
    finally:
        for child in children:
            if child.is_alive():
                child.kill()
                child.join()


def _compile_share(tasks, parent_pid: int) -> None:
    """A compiling process's work (``compile_side_by_side``): its tasks, quietly, errors ignored."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent_pid)
    from .jit import quiet

    quiet()
    for task in tasks:
        try:
            task()
        except Exception:  # noqa: BLE001 - the parent compiles it again and reports what fails
            pass


def _engine(spec):
    """The engine of the spec's model (the kernels compile one variant per kind of model: paths,
    free joints, loads); None where it cannot be built (the run itself records why)."""
    from .run_inputs import engine

    try:
        return engine(spec)
    except Exception:  # noqa: BLE001 - the run reports it
        return None


def _pool_outcomes(specs, workers: int):
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    context = multiprocessing.get_context("fork") if hasattr(os, "fork") else None
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_local_worker_init,
                               initargs=(os.getpid(),))
    try:
        futures = {pool.submit(run_spec, spec): index for index, spec in enumerate(specs)}
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                try:
                    outcome = future.result()
                except BrokenProcessPool:
                    raise ExecutionError("a worker process died unexpectedly (killed, or out of memory); "
                                         "the runs stored so far are kept: run the command again to resume") from None
                yield futures[future], outcome
    except BaseException:
        _kill_workers(pool)
        raise
    pool.shutdown(wait=True)


def _kill_workers(pool) -> None:
    """Stop a process pool at once: its workers hold nothing worth keeping (only this process
    writes the store), so they are killed rather than left to finish their runs."""
    kill_workers = getattr(pool, "kill_workers", None)  # Python >= 3.14
    if kill_workers is not None:
        kill_workers()
        return
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        try:
            process.kill()
        except (OSError, ValueError, AttributeError):
            pass
    for process in processes:
        try:
            process.join(timeout=5)
        except (OSError, ValueError, AssertionError):
            pass


def _local_worker_init(parent_pid: int) -> None:
    """Initializer of a local worker process: Ctrl-C and SIGTERM are the parent's business (it
    stops the workers), and the worker dies with its parent."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    die_with_parent(parent_pid)
    from .jit import quiet
    from .population import set_threads

    quiet()  # the parent said it once if kernels are compiled; workers' lines would cross its display

    set_threads(1)  # the workers already share the cores: one thread each for population evaluation


def die_with_parent(parent_pid: int, poll_s: float = PARENT_POLL_S) -> None:
    """Make this process end when the process ``parent_pid`` ends, however it ends: on Linux the
    kernel sends SIGKILL (prctl PR_SET_PDEATHSIG); everywhere a daemon thread polls the parent
    id every ``poll_s`` seconds and exits when this process has been re-parented."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before the request above took effect
        os._exit(1)
    watchdog = threading.Thread(target=_watch_parent, args=(parent_pid, poll_s), name="fdbench-parent-watch",
                                daemon=True)
    watchdog.start()


def _watch_parent(parent_pid: int, poll_s: float) -> None:
    import time

    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    os._exit(1)


@BACKENDS.register("dask")
class DaskBackend(Backend):
    """The workers of a Dask distributed cluster: the scheduler at ``scheduler`` (started by the
    user with ``dask scheduler``, workers with ``dask worker ADDRESS``), or a local cluster of
    ``jobs`` single-threaded worker processes. Runs travel in batches of ``batch`` specs per task
    (default: chosen from the number of runs and workers); a task whose worker dies is run again
    elsewhere by the scheduler, and a task that raises is retried ``retries`` times.

    Whatever goes wrong says so in one line: the address is checked before anything else
    (:func:`scheduler_address`), the server there must answer as a Dask scheduler within
    ``connect_timeout_s`` seconds, and Dask's own logging is silenced (fdbench reports)."""

    name = "dask"

    def __init__(self, jobs: int | None = None, scheduler: str | None = None, batch: int | None = None,
                 retries: int = 2, connect_timeout_s: float = 5.0, workers_timeout_s: float = 60.0):
        if jobs is not None and jobs < 1:
            raise BackendError(f"--jobs must be an integer >= 1, got {jobs}")
        if batch is not None and batch < 1:
            raise BackendError(f"batch must be an integer >= 1, got {batch}")
        self.jobs = jobs or os.cpu_count() or 1
        self.scheduler = scheduler
        self.address = None  # the scheduler's checked address, tcp:// or tls://HOST:PORT
        self.security = None  # the client's TLS files (Dask's configuration), for a tls:// scheduler
        self.batch, self.retries = batch, retries
        self.connect_timeout_s, self.workers_timeout_s = connect_timeout_s, workers_timeout_s
        self.client = self.cluster = self.folder = None

    def check(self) -> None:
        _import_distributed()
        if self.scheduler is None:
            import importlib.util

            if importlib.util.find_spec("cryptography") is None:
                raise BackendError("the local Dask cluster is secured by TLS, which needs the cryptography package: "
                                   f"{DASK_INSTALL}")
            if not SAFE_PATH:
                from .jit import why_not_private

                problem = why_not_private(Path.cwd(), follow_links=True)
                if problem:
                    raise BackendError(f"a local Dask cluster's processes import modules from the current folder "
                                       f"before Python 3.11, and {problem}: run fdbench from a folder of your own, "
                                       "or with Python >= 3.11")
        else:
            self.address = scheduler_address(self.scheduler)
            self.security = client_security(self.address, self._label)

    @property
    def _label(self) -> str:
        return f"--scheduler {_shown(self.scheduler)}" if self.scheduler is not None else "local Dask cluster"

    def where(self) -> str:
        if self.scheduler is None:
            return f"a local Dask cluster of {self.workers} worker processes"
        return f"{self.workers} Dask worker threads of the scheduler {self.address}"

    def connect(self) -> None:
        """Connect to the scheduler given, if any (its workers are awaited by ``start``, only
        when runs are missing)."""
        if self.scheduler is None or self.client is not None:
            return
        if self.address is None:
            self.check()
        distributed = _import_distributed()
        _quiet_dask_logs()
        _probe_scheduler(self.address, self.connect_timeout_s, self._label, self.security)
        try:
            self.client = _quiet_client_class(distributed)(self.address, timeout=f"{self.connect_timeout_s}s",
                                                           security=self.security,
                                                           set_as_default=False)
        except Exception as exc:  # noqa: BLE001 - a scheduler that went away since it answered
            raise BackendError(f"{self._label}: cannot connect to the Dask scheduler: {_reason(exc)}") from None

    def start(self, n_runs: int) -> None:
        try:
            if self.scheduler is not None:
                self.connect()
            elif self.client is None:
                distributed = _import_distributed()
                _quiet_dask_logs()
                self.folder = tempfile.mkdtemp(prefix="fdbench-dask-")
                self.safe_path = os.environ.get("PYTHONSAFEPATH")
                os.environ["PYTHONSAFEPATH"] = "1"  # for the Python processes the cluster starts (below)
                self.cluster = _local_cluster(distributed, max(1, min(self.jobs, n_runs)), self.folder)
                self.client = _quiet_client_class(distributed)(self.cluster, set_as_default=False)
                self.client.run_on_scheduler(_stop_http_server)
                self.client.run(_stop_http_server)
            self._join_workers()
        except BaseException:
            self.stop()
            raise

    def _join_workers(self) -> None:
        """Wait for a worker, check every worker's fdbench version, count the worker threads."""
        import asyncio

        try:
            self.client.wait_for_workers(1, timeout=self.workers_timeout_s)
        except Exception as exc:  # noqa: BLE001 - a timeout, or the scheduler gone meanwhile
            if isinstance(exc, (TimeoutError, asyncio.TimeoutError)):
                hint = f"start workers with 'dask worker {self.address}'" if self.address else "see 'dask worker'"
                raise BackendError(f"{self._label}: no worker joined within {self.workers_timeout_s:g} s; "
                                   f"{hint}") from None
            raise BackendError(f"{self._label}: lost the Dask scheduler while waiting for workers: "
                               f"{_reason(exc)}") from None
        self._check_versions(self._label)
        self.workers = max(1, sum(self.client.nthreads().values()))

    def _check_versions(self, where: str) -> None:
        try:
            versions = self.client.run(worker_version)
        except Exception as exc:  # noqa: BLE001 - a worker that cannot even import fdbench
            raise BackendError(f"{where}: the workers cannot run fdbench ({_reason(exc)}); "
                               f"install fdbench {__version__} on every worker") from None
        wrong = {address: version for address, version in versions.items() if version != __version__}
        if wrong:
            address, version = sorted(wrong.items())[0]
            raise BackendError(f"{where}: worker {address} runs fdbench {version}, this client fdbench "
                               f"{__version__} ({len(wrong)} of {len(versions)} workers differ); install "
                               f"fdbench {__version__} on every worker")

    def outcomes(self, specs):
        from distributed import as_completed

        size = self.batch or auto_batch(len(specs), self.workers)
        batches = [list(range(start, min(start + size, len(specs)))) for start in range(0, len(specs), size)]
        futures = []
        try:
            for indices in batches:
                future = self.client.submit(run_batch, [specs[i] for i in indices], __version__,
                                            retries=self.retries, pure=False)
                futures.append((future, indices))
            index_of = {future.key: indices for future, indices in futures}
            for future in as_completed([f for f, _ in futures], loop=self.client.loop):
                outcomes = _task_result(future, self._label)
                for index, outcome in zip(index_of[future.key], outcomes):
                    yield index, outcome
                future.release()
        except (ExecutionError, BackendError):
            raise
        except Exception as exc:  # noqa: BLE001 - the connection failed while submitting or waiting
            raise ExecutionError(_lost(self._label, _reason(exc))) from None
        finally:
            unfinished = [f for f, _ in futures if not f.done()]
            if unfinished and self.client is not None and self.client.status == "running":
                try:
                    self.client.cancel(unfinished)
                except Exception:  # noqa: BLE001 - the connection may already be gone
                    pass

    def stop(self) -> None:
        client, cluster, folder = self.client, self.cluster, self.folder
        self.client = self.cluster = self.folder = None
        if client is not None or cluster is not None:
            _quiet_dask_logs()
        for thing in (client, cluster):
            if thing is not None:
                try:
                    if thing is client:
                        thing.close(timeout=self.connect_timeout_s)
                    else:
                        thing.close()
                except Exception:  # noqa: BLE001 - closing after a failure must not hide it
                    pass
        if folder is not None:  # the scratch folders that Dask's servers put on this process's path go too
            sys.path[:] = [p for p in sys.path if p != folder and not p.startswith(folder + os.sep)]
            shutil.rmtree(folder, ignore_errors=True)
            if self.safe_path is None:
                os.environ.pop("PYTHONSAFEPATH", None)
            else:
                os.environ["PYTHONSAFEPATH"] = self.safe_path


def _local_cluster(distributed, n_workers: int, folder: str):
    """A Dask cluster on 127.0.0.1 that only this process can use: its scheduler, nannies and
    workers speak TLS with a certificate made for it (``Security.temporary()``, kept in memory),
    so a client without it (another user of this machine) cannot connect; their scratch folders
    (which Dask puts first on their import path) are in ``folder``, a private folder; their HTTP
    servers serve nothing (and are stopped once started). The Python processes it starts (worker
    processes, multiprocessing's resource tracker) must find PYTHONSAFEPATH set in this process's
    environment (``DaskBackend.start``), so that the current folder does not enter their import
    path (Python >= 3.11)."""
    import logging

    import dask
    from distributed.security import Security

    security = Security.temporary()  # needs the cryptography package (DaskBackend.check)
    private = {"temporary-directory": folder, "distributed.scheduler.http.routes": [],
               "distributed.worker.http.routes": []}
    with dask.config.set(private):
        return distributed.LocalCluster(
            n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1", security=security,
            protocol="tls://", dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False},
            local_directory=folder, silence_logs=logging.CRITICAL,
        )


def _stop_http_server(dask_scheduler=None, dask_worker=None) -> None:
    """Stop the HTTP server that every Dask scheduler and worker starts (no dashboard is asked for)."""
    (dask_scheduler or dask_worker).http_server.stop()


def scheduler_address(text) -> str:
    """The Dask scheduler's address as ``tcp://HOST:PORT`` or ``tls://HOST:PORT`` (``HOST:PORT``
    means tcp), or BackendError saying what is wrong, before any connection is tried: fdbench
    reaches a scheduler over TCP or TLS (no UCX or in-process scheduler), HOST is a host name or
    an IP address ([...] for IPv6), PORT is in [1, 65535]."""
    import ipaddress
    import re

    example = "e.g. tcp://10.0.0.5:8786"
    address = str(text).strip()
    where = f"--scheduler {_shown(text)}"
    if not address:
        raise BackendError(f"--scheduler: give the scheduler's address, {example}")
    if not address.isprintable() or any(c.isspace() for c in address):
        raise BackendError(f"{where}: an address has no spaces or control characters; {example}")
    scheme, separator, rest = address.partition("://")
    if not separator:
        scheme, rest = "tcp", address
    scheme = scheme.lower()
    if scheme not in ("tcp", "tls"):
        raise BackendError(f"{where}: fdbench reaches a Dask scheduler over tcp:// or tls://, not "
                           f"{_shown(scheme)}://; {example}")
    host, colon, port = rest.rpartition(":")
    if not colon or not host:
        raise BackendError(f"{where}: give the host and the port, {example}")
    if host.startswith("[") and host.endswith("]"):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            raise BackendError(f"{where}: {_shown(host)} is not an IPv6 address; {example}") from None
    elif not re.fullmatch(r"[A-Za-z0-9_]([A-Za-z0-9_-]*[A-Za-z0-9_])?(\.[A-Za-z0-9_]([A-Za-z0-9_-]*[A-Za-z0-9_])?)*", host):
        raise BackendError(f"{where}: {_shown(host)} is not a host name or an IP address; {example}")
    if not (port.isascii() and port.isdigit() and len(port) <= 5 and 1 <= int(port) <= 65535):
        raise BackendError(f"{where}: the port must be an integer in [1, 65535], got {_shown(port)}; {example}")
    return f"{scheme}://{host}:{int(port)}"


TLS_CONFIG = "DASK_DISTRIBUTED__COMM__TLS__"  # Dask's configuration of a client's TLS files, by environment


def client_security(address: str, where: str):
    """The ``distributed.security.Security`` of a client of the scheduler at ``address``, from
    Dask's configuration (``distributed.comm.tls``: a Dask configuration file, or the environment
    variables DASK_DISTRIBUTED__COMM__TLS__CA_FILE, __CLIENT__CERT and __CLIENT__KEY). A tls://
    address needs the CA file and the client's certificate, readable: BackendError otherwise."""
    from distributed.security import Security

    security = Security()
    if not address.startswith("tls://"):
        return security
    missing = [TLS_CONFIG + name for name, value in (("CA_FILE", security.tls_ca_file),
                                                      ("CLIENT__CERT", security.tls_client_cert)) if not value]
    if missing:
        raise BackendError(f"{where}: a tls:// scheduler needs the client's TLS files in Dask's configuration: "
                           f"set {' and '.join(missing)} (and {TLS_CONFIG}CLIENT__KEY unless the certificate "
                           "file holds the key)")
    try:
        security.get_connection_args("client")
    except (OSError, ValueError) as exc:  # ssl.SSLError is an OSError
        raise BackendError(f"{where}: cannot load the TLS files of Dask's configuration ({TLS_CONFIG}*): "
                           f"{_reason(exc)}") from None
    return security


def _shown(text, limit: int = 60) -> str:
    """``text`` as a message can show it on one line: quoted if it has control characters,
    cut after ``limit`` characters."""
    text = str(text)
    cut = text[:limit] + ("..." if len(text) > limit else "")
    return cut if cut.isprintable() else repr(cut)


def _reason(exc: BaseException) -> str:
    return " ".join(f"{type(exc).__name__}: {exc}".split())


def _probe_scheduler(address: str, timeout_s: float, where: str, security=None) -> None:
    """Ask the server at ``address`` who it is, within ``timeout_s`` seconds in all, before a
    Dask client is made: BackendError (one line) for a port where nothing listens, a server
    that never answers, one that answers in another protocol, or (tls://, with ``security``'s
    files) a TLS handshake that fails."""
    import asyncio
    import socket
    import ssl
    import time

    from distributed.comm import connect

    started = time.monotonic()
    host, _, port = address.partition("://")[2].rpartition(":")
    silent = f"{where}: no answer from a Dask scheduler within {timeout_s:g} s"
    args = security.get_connection_args("client") if address.startswith("tls://") else {}
    try:  # a refused port, an unknown host or a failed handshake is said at once, not after the timeout
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s) as raw:
            if args:
                args["ssl_context"].wrap_socket(raw).close()
    except socket.timeout:
        raise BackendError(silent) from None
    except ssl.SSLError as exc:
        raise BackendError(f"{where}: the TLS handshake with the scheduler failed ({_reason(exc)}); check the TLS "
                           f"files of Dask's configuration ({TLS_CONFIG}*)") from None
    except OSError as exc:
        raise BackendError(f"{where}: cannot connect to a Dask scheduler: {_reason(exc)}") from None
    left_s = max(0.1, timeout_s - (time.monotonic() - started))

    async def identity():
        comm = await connect(address, timeout=left_s + 5, **args)  # the deadline below comes first
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def ask():
        return asyncio.run(asyncio.wait_for(identity(), left_s))

    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1, thread_name_prefix="fdbench-probe") as pool:  # its own event loop, always
        try:
            reply = pool.submit(ask).result()
        except (TimeoutError, asyncio.TimeoutError):
            raise BackendError(silent) from None
        except OSError:
            refused = (f" (does the scheduler accept the client certificate of {TLS_CONFIG}CLIENT__CERT?)"
                       if args else "")
            raise BackendError(f"{where}: the server there closed the connection without answering as a Dask "
                               f"scheduler{refused}") from None
        except Exception:  # noqa: BLE001 - e.g. a length of exabytes read from another protocol's bytes
            raise BackendError(f"{where}: the server there is not a Dask scheduler (it answers in another "
                               "protocol)") from None
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        raise BackendError(f"{where}: the server there is not a Dask scheduler")


_QUIET_CLIENT = None


def _quiet_client_class(distributed):
    """distributed.Client whose collection never blocks nor prints: a client that failed to
    start would otherwise wait 20 s at exit, then print a traceback from ``__del__``. fdbench
    closes its clients itself (``DaskBackend.stop``)."""
    global _QUIET_CLIENT
    if _QUIET_CLIENT is None:

        class QuietClient(distributed.Client):
            def __del__(self):
                try:
                    if getattr(self, "status", "closed") not in ("closed", "newly-created"):
                        self.close(timeout=1)
                except Exception:  # noqa: BLE001 - nothing can be reported from a finaliser
                    pass

        _QUIET_CLIENT = QuietClient
    return _QUIET_CLIENT


def _lost(where: str, reason: str) -> str:
    return (f"{where}: lost the connection to the Dask scheduler during the sweep ({reason}); the runs "
            "stored so far are kept: run the command again to resume")


def _quiet_dask_logs() -> None:
    """Dask and asyncio log broken connections with tracebacks (a lost scheduler, Ctrl-C with
    tasks in flight): what stopped the command is said once, by fdbench."""
    import logging

    silent = logging.CRITICAL + 1
    roots = ("distributed", "asyncio", "tornado")
    names = [name for name in list(logging.root.manager.loggerDict) if name.split(".")[0] in roots]
    for name in set(names) | set(roots):  # Dask's configuration gives some of them levels of their own
        logger = logging.getLogger(name)
        logger.setLevel(silent)
        for handler in logger.handlers:
            handler.setLevel(silent)


def auto_batch(n_runs: int, workers: int) -> int:
    """Specs per Dask task: about four tasks per worker keeps every worker busy to the end while
    the scheduler's cost per task (a few ms) stays small against runs of 10-200 ms; never more
    than 8 runs in flight per task, so an interruption loses little."""
    return max(1, min(8, n_runs // (4 * max(1, workers))))


def _task_result(future, where: str = "Dask") -> list:
    from distributed import KilledWorker
    from distributed.client import FutureCancelledError

    try:
        return future.result()
    except VersionMismatch as exc:
        raise BackendError(f"a Dask worker cannot be used: {exc}; install fdbench {__version__} on every worker") from None
    except KilledWorker as exc:
        raise ExecutionError(f"Dask workers kept dying while running a task ({exc}); the runs stored so far "
                             "are kept: run the command again to resume") from None
    except (KeyboardInterrupt, ExecutionError, BackendError):
        raise
    except FutureCancelledError as exc:  # the scheduler went away: its tasks are cancelled
        raise ExecutionError(_lost(where, getattr(exc, "reason", None) or "its tasks were cancelled")) from None
    except OSError as exc:
        raise ExecutionError(_lost(where, _reason(exc))) from None
    except Exception as exc:  # noqa: BLE001 - e.g. a worker that cannot unpickle the task
        raise ExecutionError(f"a Dask task failed: {type(exc).__name__}: {exc}") from None


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise BackendError(f"--backend dask needs Dask distributed, which is not installed: {DASK_INSTALL}") from None
    return distributed


# ---- the runner: the same code for every backend ---------------------------------------------


def execute_specs(specs, store, backend: Backend, rerun: bool = False, on_done=None) -> dict:
    """Make sure every spec is in the store; return {spec hash: stored run} (each run with its
    row ``id``).

    Runs already stored are reused unless ``rerun``; the missing ones (each settings hash once)
    are handed to the backend and each is stored as soon as its outcome arrives.
    ``on_done(finished, total)`` reports progress (total = distinct specs). The runs returned
    are the rows this call found or wrote, read by id: another process replacing them meanwhile
    (``--rerun`` on the same database) changes neither the numbers nor the ids returned, and a
    replaced row stays in the store (``Store.put``)."""
    distinct = {spec.hash(): spec for spec in specs}
    ids = {} if rerun else store.ids(distinct)
    missing = [spec for key, spec in distinct.items() if key not in ids]
    done = len(distinct) - len(missing)
    if on_done:
        on_done(done, len(distinct))
    if missing:
        backend.start(len(missing))
        try:
            with closing(backend.outcomes(missing)) as outcomes:
                for index, outcome in outcomes:
                    spec = missing[index]
                    row = store.put(spec, outcome.record, outcome.history, outcome.params, jobs=backend.workers,
                                    replace=rerun)
                    ids[spec.hash()] = row if row is not None else store.ids([spec.hash()])[spec.hash()]
                    backend.carried_out += 1
                    done += 1
                    if on_done:
                        on_done(done, len(distinct))
        finally:
            backend.stop()
    stored = store.runs_by_id(ids.values())
    return {key: stored.get(ids[key]) for key in distinct}


@contextmanager
def sigterm_as_interrupt():
    """Within the block, SIGTERM raises :class:`Terminated` (a KeyboardInterrupt) in the main
    thread, so a terminated command stops as cleanly as on Ctrl-C: workers stopped, stored runs
    kept. Outside the main thread, nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(signum, frame):
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
