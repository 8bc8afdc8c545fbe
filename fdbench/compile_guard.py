"""Ctrl-C while numba loads or compiles kernels (``compiling``): the command line's process ends at
once instead of leaving a half-built kernel. A utility below the engine, which wraps its kernels'
first calls in it; the command line turns it on (``interrupts_end_compiling``)."""

from __future__ import annotations

import os
import signal
import sys
import threading
from contextlib import contextmanager

_COMMAND_LINE = {"pid": None}  # the command line's process (``interrupts_end_compiling``)


def interrupts_end_compiling() -> None:
    """Called by the command line: in this process, Ctrl-C within ``compiling`` ends it at once."""
    _COMMAND_LINE["pid"] = os.getpid()


@contextmanager
def compiling():
    """Within the block (kernels being loaded or compiled: numba and LLVM run compiled code and
    callbacks that a KeyboardInterrupt cannot cross cleanly, and leave a half-built kernel that
    fails later), Ctrl-C ends the command line's process at once with its usual line and exit code
    130. numba writes a cache entry by renaming a complete file, and nothing else is written yet.
    Elsewhere (the Python API, worker processes, other threads, a handler of the caller's own)
    nothing changes."""
    if (_COMMAND_LINE["pid"] != os.getpid() or threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return

    def stop(signum, frame):
        sys.stderr.write("fdbench: error: interrupted\n")
        sys.stderr.flush()
        os._exit(130)

    previous = signal.signal(signal.SIGINT, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
