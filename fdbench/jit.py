"""Compiled kernels: numba's ``njit`` with its on-disk cache kept in a user cache folder.

numba caches a compiled kernel next to its source by default, which puts files inside the
installed package (left behind by ``pip uninstall``, and failing on a read-only install). fdbench
keeps them in ``$FDBENCH_CACHE_DIR``, else ``$XDG_CACHE_HOME/fdbench``, else ``~/.cache/fdbench``;
when none of these can be written (a read-only home), in a folder of the temporary directory, and
when not even that can, kernels are compiled on every run without a cache. Either fallback is
said once on stderr.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

CACHE_VARIABLE = "FDBENCH_CACHE_DIR"


def _candidates() -> list[Path]:
    if os.environ.get(CACHE_VARIABLE):
        return [Path(os.environ[CACHE_VARIABLE])]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return [Path(base) / "fdbench"]


def _usable(folder: Path) -> bool:
    """True if folder exists (or can be made) and a file can be created in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
        return True
    except OSError:
        return False


def _choose_cache_dir() -> Path | None:
    for folder in _candidates():
        if _usable(folder):
            return folder
    fallback = Path(tempfile.gettempdir()) / f"fdbench-cache-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
    tried = ", ".join(str(c) for c in _candidates())
    if _usable(fallback):
        _warn(f"cannot write the kernel cache in {tried}; using {fallback} (set ${CACHE_VARIABLE} to choose)")
        return fallback
    _warn(f"cannot write a kernel cache in {tried} nor {fallback}; kernels are compiled on every run")
    return None


def _warn(message: str) -> None:
    sys.stderr.write(f"fdbench: warning: {message}\n")


CACHE_DIR = _choose_cache_dir()


def _configure():
    import numba

    if CACHE_DIR is not None:
        numba.config.CACHE_DIR = str(CACHE_DIR / "numba")
    return numba


def njit(*args, **options):
    """``numba.njit`` caching in fdbench's cache folder (``cache`` is set here, not by callers)."""
    numba = _configure()
    options["cache"] = CACHE_DIR is not None
    return numba.njit(*args, **options)
