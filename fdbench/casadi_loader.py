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


def casadi():
    """The casadi module, imported after its own libcasadi is loaded (``_preload``); ImportError
    (one line naming LD_LIBRARY_PATH where that is the cause) when it cannot be imported."""
    if "casadi" in sys.modules:
        return sys.modules["casadi"]
    _preload()
    try:
        import casadi as ca
    except ImportError as exc:
        if "undefined symbol" in str(exc):
            raise ImportError("casadi's libraries clash with others found first on LD_LIBRARY_PATH (OpenSim's "
                              "bundle their own libcasadi): run fdbench without OpenSim's library folder on "
                              "LD_LIBRARY_PATH") from None
        raise
    return ca


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
