"""Helpers for tests that start fdbench commands: their Python path, stopping a sweep in a known
state without timing anything, and processes in sessions of their own (a Dask scheduler, its
workers).

A test that interrupts or kills a running sweep needs it mid-way: some runs stored, workers busy,
more runs to come. Waiting a while and hoping fails on a loaded machine (the sweep ends first, or
has not started). Instead the sweep uses the optimiser ``gated-bfgs`` of ``plugins/gate_plugin.py`` (BFGS
whose runs from seed ``from_seed`` on wait for a file): it stores exactly the runs of the seeds
below ``from_seed`` and then holds still until the test opens the gate.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

PLUGINS = Path(__file__).resolve().parent / "plugins"  # the plugins the started commands load
GATED_OPTIMIZER = "gated-bfgs"


def python_path(*folders) -> str:
    """A PYTHONPATH of ``folders`` followed by this process's own, so that commands started
    with it import the same fdbench as the tests (a working copy's, not another install)."""
    inherited = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    return os.pathsep.join([str(f) for f in folders] + inherited)


class Gate:
    """``env``: the environment of a command that loads the plugin; its runs of ``gated-bfgs``
    with seed >= ``from_seed`` wait until :meth:`open` is called (the file ``path`` exists)."""

    def __init__(self, folder: Path, from_seed: int = 2):
        self.path = Path(folder) / "gate-open"
        self.env = dict(os.environ, FDBENCH_PLUGINS="gate_plugin", FDBENCH_GATE=str(self.path),
                        FDBENCH_GATE_FROM=str(from_seed), PYTHONPATH=python_path(PLUGINS))

    def open(self) -> None:
        self.path.touch()


def wait_until(condition, what: str, proc=None, timeout_s: float = 120.0) -> None:
    """Poll ``condition()`` until it is true. Fails, naming ``what``, if ``proc`` (a Popen) ends
    first or after ``timeout_s`` seconds: a bound against hangs, not a timing."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"the command ended (exit {proc.returncode}) before {what}")
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} after {timeout_s:g} s")
        time.sleep(0.02)


def children(pid: int) -> list[int]:
    """The live child processes of ``pid`` (Linux /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # ended meanwhile
            continue
        state, ppid = text[text.rindex(")") + 2:].split()[:2]
        if int(ppid) == pid and state != "Z":
            found.append(int(stat.parent.name))
    return found


def start_in_session(args, log: Path, cwd: Path) -> subprocess.Popen:
    """Start ``args`` in ``cwd`` in a session of its own, its output (both streams) into ``log``."""
    with open(log, "wb") as handle:  # the child keeps its own descriptor
        return subprocess.Popen(args, stdout=handle, stderr=subprocess.STDOUT, cwd=cwd, start_new_session=True)


def stop_session(proc: subprocess.Popen) -> None:
    """Kill a subprocess and everything it started (its own session)."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()


def scheduler_address(proc: subprocess.Popen, log: Path, timeout_s: float = 120) -> str:
    """The address of the Dask scheduler ``proc`` as its ``log`` says it, once it does."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for line in log.read_text(errors="replace").splitlines():
            if "Scheduler at:" in line:
                return line.split("Scheduler at:")[1].strip()
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    raise AssertionError(f"the scheduler did not start:\n{log.read_text(errors='replace')}")
