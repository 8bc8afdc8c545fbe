"""Helpers for tests that start fdbench commands: their Python path, and stopping a sweep in a
known state without timing anything.

A test that interrupts or kills a running sweep needs it mid-way: some runs stored, workers busy,
more runs to come. Waiting a while and hoping fails on a loaded machine (the sweep ends first, or
has not started). Instead the sweep uses the optimiser ``gated-bfgs`` of ``plugins/gate_plugin.py`` (BFGS
whose runs from seed ``from_seed`` on wait for a file): it stores exactly the runs of the seeds
below ``from_seed`` and then holds still until the test opens the gate.
"""

from __future__ import annotations

import os
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
