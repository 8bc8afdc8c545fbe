"""Reading torque histories and writing outputs safely (a temporary file, then a rename)."""

from __future__ import annotations

import csv
import io
import math
import os
import tempfile
from pathlib import Path

import numpy as np


class BadFile(ValueError):
    """A file that cannot be used; the message names it and says why."""


def check_writable(path: str | os.PathLike, option: str) -> Path:
    """Fail early, before any work, if ``path`` cannot be written."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise BadFile(f"{option}: {path} is a directory")
    if not parent.is_dir():
        raise BadFile(f"{option}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise BadFile(f"{option}: directory {parent} is not writable")
    return path


def write_atomic(path: str | os.PathLike, text: str, option: str = "--output") -> None:
    """Write text to path so that a reader sees either the old file or the whole new one."""
    path = check_writable(path, option)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent if str(path.parent) else ".")
    try:
        with os.fdopen(fd, "w", newline="") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def csv_text(header: list[str], rows) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buffer.getvalue()


def read_torque_csv(path: str | os.PathLike, option: str = "--torque-file") -> tuple[np.ndarray, np.ndarray]:
    """A torque history from a CSV file with a header and columns ``t`` (s) and ``torque`` (N m).

    Times must be finite and strictly increasing and cover [0, 1] s; returns (t, torque)."""
    path = Path(path)
    if not path.is_file():
        raise BadFile(f"{option}: {path} does not exist or is not a file")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise BadFile(f"{option}: cannot read {path}: {exc}") from None
    rows = [row for row in csv.reader(io.StringIO(text)) if row and any(cell.strip() for cell in row)]
    if not rows:
        raise BadFile(f"{option}: {path} is empty; expected a header 't,torque' and rows of numbers")
    header = [cell.strip().lower() for cell in rows[0]]
    if "t" not in header or "torque" not in header:
        raise BadFile(f"{option}: {path} needs columns 't' and 'torque' in its header, found {', '.join(header)}")
    it, iq = header.index("t"), header.index("torque")
    t, q = [], []
    for number, row in enumerate(rows[1:], start=2):
        try:
            t.append(float(row[it]))
            q.append(float(row[iq]))
        except (ValueError, IndexError):
            raise BadFile(f"{option}: {path} line {number}: expected numbers in columns t and torque") from None
    t, q = np.array(t), np.array(q)
    if len(t) < 2:
        raise BadFile(f"{option}: {path} needs at least 2 rows of data, found {len(t)}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise BadFile(f"{option}: {path} holds non-finite values")
    if np.any(np.diff(t) <= 0):
        raise BadFile(f"{option}: {path}: times must be strictly increasing")
    if t[0] > 1e-9 or t[-1] < 1 - 1e-9:
        raise BadFile(f"{option}: {path} covers [{t[0]:g}, {t[-1]:g}] s; it must cover [0, 1] s")
    return t, q


def finite_or_none(value):
    """JSON-safe float: NaN and infinities become None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
