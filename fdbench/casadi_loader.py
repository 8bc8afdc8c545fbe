"""The one way fdbench imports CasADi: ``casadi()``.

OpenSim's Python package bundles its own, older libcasadi, and importing ``opensim`` (or following
OpenSim's Linux install instructions) puts its library folder on ``LD_LIBRARY_PATH``, which the
dynamic loader searches before the casadi package's own folder (its RUNPATH). The casadi package's
``_casadi.so`` then binds to OpenSim's libcasadi and fails with "undefined symbol". So the casadi
package's own libcasadi is loaded first, by absolute path, from the folder ``importlib`` finds
for the package without importing it: the loader then reuses it (same soname) for ``_casadi.so``,
and CasADi's plugins (IPOPT) are loaded from beside it."""

from __future__ import annotations

import functools
import re
import sys

LIBRARY = re.compile(r"^libcasadi(\.so(\.\d+)*|(\.\d+)*\.dylib)$")  # libcasadi.so.3.7, libcasadi.3.7.dylib


class CasadiClash(ImportError):
    """casadi's own libraries could not be loaded first and others on LD_LIBRARY_PATH were (one line)."""


def casadi():
    """The casadi module, imported after its own libcasadi is loaded (``_preload``); CasadiClash
    (one line naming LD_LIBRARY_PATH and the folder at fault) when another libcasadi got in first,
    ImportError when casadi cannot be imported otherwise."""
    if "casadi" in sys.modules:
        return sys.modules["casadi"]
    _preload()
    try:
        import casadi as ca
    except ImportError as exc:
        if "undefined symbol" in str(exc):
            raise CasadiClash(_clash_message()) from None
        raise
    return ca


def _clash_message() -> str:
    """One line: the first folder of LD_LIBRARY_PATH holding a libcasadi, and what to do."""
    import os

    def holds_casadi(folder: str) -> bool:
        try:
            return any(LIBRARY.match(name) for name in os.listdir(folder))
        except OSError:
            return False

    folders = [f for f in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if f and holds_casadi(f)]
    where = f" ({folders[0][:200]!r}, OpenSim's?)" if folders else ""
    return (f"casadi's libraries clash with another libcasadi found first on LD_LIBRARY_PATH{where}: run fdbench "
            "with that folder removed from LD_LIBRARY_PATH (env -u LD_LIBRARY_PATH fdbench ...)")


@functools.lru_cache(maxsize=None)
def _preload() -> str | None:
    """Load the casadi package's own libcasadi (RTLD_GLOBAL) by absolute path; its path, or None
    where there is nothing to load (no casadi package, Windows, a layout without it)."""
    import ctypes
    import importlib.util
    from pathlib import Path

    if sys.platform.startswith("win"):
        return None
    try:
        spec = importlib.util.find_spec("casadi")
    except (ImportError, ValueError):
        return None
    found = []
    for folder in list(spec.submodule_search_locations or []) if spec is not None else []:
        try:
            found += [path for path in Path(folder).iterdir() if LIBRARY.match(path.name)]
        except OSError:
            continue
    found.sort(key=lambda path: (-len(path.name), path.name))  # the versioned name (the soname) first
    for path in found:
        try:
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
        except OSError:
            continue
        return str(path)
    return None
