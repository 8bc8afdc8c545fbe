"""Child Python processes that import nothing from the folder they start in.

``python -c CODE`` puts the current folder first on ``sys.path``: a ``json.py`` that another user
left in a shared folder (/tmp, a group's project folder) would run as the user running fdbench.
fdbench's children therefore run in isolated mode (``-I``: neither the current folder, nor
PYTHONPATH, nor the user's site folder enter their path) from a private temporary folder, and are
given this process's own import path, so that they import what this process imports (the
PYTHONPATH and user site folder it honoured, an OpenSim found through PYTHONPATH, this fdbench)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

PACKAGE_ROOT = str(Path(__file__).resolve().parents[1])  # the folder holding this fdbench package


def python_command(code: str) -> list[str]:
    """The argv of a child Python that runs ``code`` (statements) in isolated mode with this
    process's import path (its absolute entries: ``''``, the current folder of a ``python -c``
    parent, is left out), then the folder of this fdbench."""
    path = [p for p in sys.path if os.path.isabs(p)]
    if PACKAGE_ROOT not in path:
        path.append(PACKAGE_ROOT)
    return [sys.executable, "-I", "-c", f"import sys; sys.path[:0] = {path!r}\n{code}"]
