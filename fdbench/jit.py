"""Compiled kernels: numba's ``njit`` with its on-disk cache in ``$FDBENCH_CACHE_DIR``, else
``$XDG_CACHE_HOME/fdbench``, else ``~/.cache/fdbench`` (not inside the installed package); failing
that in a folder of the temporary directory (not a link), failing that no cache, said once on
stderr. A cache folder holds code this process runs, so it must be the user's own and writable by
nobody else (created mode 0700).
"""

from __future__ import annotations

import functools
import os
import stat
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

CACHE_VARIABLE = "FDBENCH_CACHE_DIR"


def _candidate() -> Path:
    if os.environ.get(CACHE_VARIABLE):
        return Path(os.environ[CACHE_VARIABLE])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "fdbench"


def why_not_private(folder: Path, follow_links: bool) -> str | None:
    """Why another user could put code into folder (or None if nobody can): a symbolic link
    (unless ``follow_links``), not a directory, owned by another user, writable by group or others."""
    st = os.stat(folder) if follow_links else os.lstat(folder)
    if stat.S_ISLNK(st.st_mode):
        return f"{folder} is a symbolic link"
    if not stat.S_ISDIR(st.st_mode):
        return f"{folder} is not a directory"
    if hasattr(os, "geteuid") and st.st_uid != os.geteuid():
        return f"{folder} belongs to another user (uid {st.st_uid})"
    if st.st_mode & 0o022:
        return f"{folder} is writable by other users (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def _unusable(folder: Path, follow_links: bool = True) -> str | None:
    """Make folder (mode 0700 if it is new) and check that it is private and a file can be made
    in it: None if so, else why not."""
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.mkdir(folder, 0o700)
        except FileExistsError:
            pass
        problem = why_not_private(folder, follow_links)
        if problem is None:
            with tempfile.TemporaryFile(dir=folder):
                pass
        return problem
    except OSError as exc:
        return f"{folder}: {exc.strerror or exc}"


def _choose_cache_dir() -> Path | None:
    folder = _candidate()
    problem = _unusable(folder)
    if problem is None:
        return folder
    fallback = Path(tempfile.gettempdir()) / f"fdbench-cache-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
    again = _unusable(fallback, follow_links=False)
    if again is None:
        _warn(f"cannot use the kernel cache: {problem}; using {fallback} (set ${CACHE_VARIABLE} to choose)")
        return fallback
    _warn(f"cannot use the kernel cache: {problem}; nor {again}; kernels are compiled on every run")
    return None


def _warn(message: str) -> None:
    sys.stderr.write(f"fdbench: warning: {message}\n")


CACHE_DIR = _choose_cache_dir()


@functools.lru_cache(maxsize=None)
def source_digest(package: Path | None = None) -> str:
    """16 hex digits of SHA-256 over the Python sources of ``package`` (default: fdbench's): each
    version gets its own kernel folder (numba's cache does not see a changed inlined callee)."""
    import hashlib

    package = Path(__file__).resolve().parent if package is None else Path(package)
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        digest.update(str(path.relative_to(package)).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def _configure():
    import numba

    if CACHE_DIR is not None:
        numba.config.CACHE_DIR = str(CACHE_DIR / "numba" / source_digest())
    _CompileNotice.install()
    return numba


FIRST_RUN = "a first run takes from half a minute to a few minutes"  # measured: README, first lines


class _CompileNotice:  # state of the process, on the class
    """On a terminal (and not ``quiet()``), says on stderr that kernels are being compiled, with a
    spinner counting them while numba compiles (its ``numba:compile`` events: cache misses)."""

    _installed = False
    enabled = True
    spinner = True
    depth = compiled = 0
    started = status = None
    make_status = None  # the spinner's maker (``spin_with``): the command line's; none, the line alone

    @classmethod
    def install(cls) -> None:
        if cls._installed:
            return
        cls._installed = True
        from numba.core import event

        class Listener(event.Listener):
            def on_start(self, _event):
                cls.on_start()

            def on_end(self, _event):
                cls.on_end()

        event.register("numba:compile", Listener())
        import atexit

        atexit.register(cls.stop)  # a spinner left on would leave the terminal's cursor hidden

    @classmethod
    def on_start(cls) -> None:
        import time

        cls.depth += 1
        if cls.depth > 1 or not cls.enabled or not _stderr_is_terminal():
            return
        if cls.started is None:
            cls.started = time.monotonic()
            sys.stderr.write(f"fdbench: compiling the kernels for this machine, once per fdbench version ({FIRST_RUN}; "
                             f"later runs load them from {CACHE_DIR or 'nowhere: no cache'})\n")
            sys.stderr.flush()
        if not cls.spinner or cls.make_status is None:
            return
        try:
            cls.status = cls.make_status(cls())  # its text from __rich__ at every refresh
            cls.status.start()
        except Exception:  # noqa: BLE001 - no spinner (another live display): the line above said it
            cls.status = None

    @classmethod
    def on_end(cls) -> None:
        cls.depth = max(0, cls.depth - 1)
        if cls.depth == 0:
            cls.compiled += 1
            cls.stop()  # at once: the command's own output may follow

    @classmethod
    def stop(cls) -> None:
        status, cls.status = cls.status, None
        if status is not None:
            status.stop()

    def __rich__(self) -> str:
        import time

        return f"compiling kernel {self.compiled + 1}: {time.monotonic() - self.started:.0f} s since the first"


@contextmanager
def compile_notice():
    """The notice of compilation (its line, once, and the spinner) over a block in which other
    processes compile kernels for this one."""
    _CompileNotice.on_start()
    try:
        yield
    finally:
        _CompileNotice.on_end()


def quiet() -> None:
    """No notice of compilation on stderr from now on in this process (``--quiet``, worker processes)."""
    _CompileNotice.enabled = False
    _CompileNotice.stop()


def spin_with(make_status) -> None:
    """The notice's spinner: ``make_status(notice)`` gives a live status (``start``, ``stop``) that
    shows the notice's text (``__rich__``); the command line gives rich's. Without one, the notice
    is its line alone."""
    _CompileNotice.make_status = make_status


def no_spinner() -> None:
    """The notice's line without its spinner from now on: a progress bar holds the terminal's last
    line (and shows the line above itself)."""
    _CompileNotice.spinner = False
    _CompileNotice.stop()


def _stderr_is_terminal() -> bool:
    try:
        return sys.stderr is not None and sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def njit(*args, **options):
    """``numba.njit`` caching in fdbench's cache folder (``cache`` is set here, not by callers)."""
    numba = _configure()
    options["cache"] = CACHE_DIR is not None
    return numba.njit(*args, **options)
