"""Reading input files with limits and writing outputs safely (as the shell's ``>``, made atomic)."""

from __future__ import annotations

import csv
import errno
import io
import math
import os
import re
import signal
import stat
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np


class BadFile(ValueError):
    """A file that cannot be used; the message names it and says why."""


MAX_INPUT_BYTES = 64 * 2**20  # a torque or motion CSV, a parameter file: far more than any real one


SHOWN_CHARACTERS = 80  # a name or label from a file, as an error line quotes it


def shown(text, limit: int = SHOWN_CHARACTERS) -> str:
    """``text`` as one line of a message: whitespace runs as one space, other invisible characters
    escaped (``\\x1b``), cut after about ``limit`` characters (on a word boundary if near) with '...'."""
    line = "".join(c if c.isprintable() else repr(c)[1:-1] for c in " ".join(str(text).split()))
    if len(line) <= limit:
        return line
    cut = line[:limit]
    space = cut.rfind(" ")
    if space >= limit * 3 // 4:
        cut = cut[:space]
    elif "\\" in cut[-9:]:  # an escape is not cut in two
        cut = cut[:cut.rfind("\\", len(cut) - 9)]
    return cut.rstrip() + "..."


def quoted(text, limit: int = SHOWN_CHARACTERS) -> str:
    """``text`` quoted for a message: in single quotes, as ``shown`` makes it (every whitespace
    character but the space escaped too, so that 'a\\tb' is not 'a b')."""
    escaped = "".join(c if c == " " or c.isprintable() else repr(c)[1:-1] for c in str(text))
    return "'" + shown(escaped, limit) + "'"


def _stat(path, option: str | None = None) -> os.stat_result | None:
    """os.stat following symlinks, or None where nothing exists (a dangling link included);
    BadFile (naming ``option``) for a path that cannot be inspected (a loop of links)."""
    try:
        return os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        where = f"{option}: " if option else ""
        raise BadFile(f"{where}cannot inspect {path}: {exc.strerror or exc}") from None


def _in_place(path: Path, st: os.stat_result | None) -> bool:
    """Targets that the shell's ``>`` writes in place and an atomic rename must not replace:
    devices, FIFOs and sockets, anything under /dev or /proc, and files with other hard links."""
    if st is None:
        return False
    special = str(path).startswith(("/dev/", "/proc/")) or os.path.realpath(path).startswith(("/dev/", "/proc/"))
    return special or not stat.S_ISREG(st.st_mode) or st.st_nlink > 1


def _shared(folder: Path) -> os.stat_result | None:
    """The stat of ``folder`` if it is sticky and writable by every user (/tmp), else None."""
    try:
        st = os.stat(folder)
    except OSError:
        return None
    return st if st.st_mode & stat.S_ISVTX and st.st_mode & stat.S_IWOTH else None


def planted_link(path: Path, link: os.stat_result) -> str | None:
    """Why the kernel's ``fs.protected_symlinks`` would not follow ``path`` (``link``, its lstat):
    a symbolic link made by another user in a sticky folder writable by every user (/tmp) that is
    not theirs; None where it would."""
    if not stat.S_ISLNK(link.st_mode):
        return None
    folder = _shared(path.parent)
    if folder is None or link.st_uid in (os.geteuid(), folder.st_uid):
        return None
    return (f"{path} is a symbolic link made by another user (uid {link.st_uid}) in the shared folder "
            f"{path.parent}; fdbench does not follow it (as the kernel's protected_symlinks does not)")


def check_shared_folder(path: Path, option: str) -> None:
    """Refuse, in a sticky folder writable by every user (/tmp), what the kernel's
    ``fs.protected_symlinks`` and ``fs.protected_regular`` refuse: another user's link or file."""
    try:
        link = os.lstat(path)
    except OSError:
        return
    reason = planted_link(path, link)
    if reason:
        raise BadFile(f"{option}: {reason}: choose another name")
    target = Path(os.path.realpath(path))
    st = _stat(target, option)
    folder = _shared(target.parent)
    if st is not None and stat.S_ISREG(st.st_mode) and folder is not None \
            and st.st_uid not in (os.geteuid(), folder.st_uid):
        raise BadFile(f"{option}: {target} belongs to another user (uid {st.st_uid}) in the shared folder "
                      f"{target.parent}; fdbench does not write over it (as the kernel's protected_regular does not): "
                      "choose another name")


def check_writable(path: str | os.PathLike, option: str) -> Path:
    """Fail before any work if ``path`` cannot be written as an output (a directory, a socket, a
    missing or unwritable folder, a read-only, append-only or immutable file, see check_shared_folder)."""
    path = Path(path)
    if str(path) in ("", "."):
        raise BadFile(f"{option}: an empty file name")
    check_shared_folder(path, option)
    st = _stat(path, option)
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise BadFile(f"{option}: {path} is a directory")
    if st is not None and stat.S_ISSOCK(st.st_mode):
        raise BadFile(f"{option}: {path} is a socket; choose a file")
    if st is None:
        target = Path(os.path.realpath(path))  # a dangling link creates its target, as '>' does
        if not target.parent.is_dir():
            raise BadFile(f"{option}: directory {target.parent} does not exist")
        if not os.access(target.parent, os.W_OK):
            raise BadFile(f"{option}: directory {target.parent} is not writable")
        return path
    if stat.S_ISREG(st.st_mode) and not (st.st_mode & 0o222):
        raise BadFile(f"{option}: {path} is read-only; make it writable or choose another file")
    if stat.S_ISREG(st.st_mode):
        _probe_writable(path, option)
    elif not os.access(path, os.W_OK):
        raise BadFile(f"{option}: {path} is not writable")
    return path


def check_own_file(path: Path, option: str) -> None:
    """Refuse a name that fdbench chooses inside a folder the user named (a figure in --figures)
    where it is not a file of its own: a symbolic link, a FIFO or device, a file with other hard
    links. The user named the folder, not what such a name leads to, and writing it would write over that."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise BadFile(f"{option}: cannot inspect {path}: {exc.strerror or exc}") from None
    if stat.S_ISLNK(st.st_mode):
        what = f"a symbolic link to {os.readlink(path)}"
    elif stat.S_ISDIR(st.st_mode) or (stat.S_ISREG(st.st_mode) and st.st_nlink == 1):
        return  # a directory: check_writable names it
    elif not stat.S_ISREG(st.st_mode):
        what = "not a regular file (a FIFO, socket or device)"
    else:
        what = f"a file with {st.st_nlink - 1} other hard link(s)"
    raise BadFile(f"{option}: {path} is {what}; fdbench writes its figures as files of their own: "
                  "remove it or choose another folder")


def _probe_writable(path: Path, option: str) -> None:
    """Open a regular file for writing, changing nothing: sees append-only and immutable files."""
    try:
        os.close(os.open(path, os.O_WRONLY | getattr(os, "O_NONBLOCK", 0)))
    except PermissionError as exc:
        if exc.errno == errno.EPERM:
            raise BadFile(f"{option}: {path} is append-only or immutable (see lsattr); choose another file") from None
        raise BadFile(f"{option}: {path} is not writable") from None
    except OSError as exc:
        raise BadFile(f"{option}: {path} cannot be written: {exc.strerror or exc}") from None


_FS_IOC_GETFLAGS = 0x80086601  # 64-bit Linux: read a file's attributes, as lsattr does
_FS_APPEND_FL = 0x20


def _append_only(folder: Path) -> bool:
    """True if folder is append-only (``chattr +a``; Linux): names can be added to it but not
    renamed or removed, so an atomic rename would fail and leave its temporary file behind."""
    try:
        import fcntl

        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except (ImportError, OSError):
        return False
    try:
        flags = fcntl.ioctl(fd, _FS_IOC_GETFLAGS, bytes(8))
        return bool(int.from_bytes(flags[:4], sys.byteorder) & _FS_APPEND_FL)
    except OSError:
        return False  # a file system without attributes, or not Linux
    finally:
        os.close(fd)


def umask() -> int:
    """The process's umask (read without changing it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


STALE_TEMPORARY_S = 15 * 60  # a temporary file of the atomic writer this old was left by a killed writer
_TEMPORARY_NAME = re.compile(r"\.fdbench-[a-z0-9_]{8}\.tmp")  # tempfile.mkstemp(prefix=".fdbench-", suffix=".tmp")


def write_atomic(path: str | os.PathLike, data: str | bytes, option: str = "--output") -> None:
    """Write ``data`` to ``path`` as the shell's ``>`` would: a regular file or new name replaced
    atomically by a rename (mode and owner kept), a symlink written through, devices, FIFOs, files
    with other hard links or in an append-only folder written in place. BadFile naming ``option``."""
    path = check_writable(path, option)  # checked again: a link may have been planted since the first check
    # a name from the file system that is not UTF-8 (its bytes kept as surrogates) written back as those bytes
    payload = data.encode("utf-8", "surrogateescape") if isinstance(data, str) else bytes(data)
    try:
        st = _stat(path)
        target = Path(os.path.realpath(path))
        if _in_place(path, st) or not os.access(target.parent, os.W_OK) or _append_only(target.parent):
            with open(path, "wb") as handle:
                handle.write(payload)
            return
        _remove_stale_temporaries(target.parent)
        with _signals_deferred():
            _replace(target, payload, st)
    except OSError as exc:
        raise BadFile(f"{option}: cannot write {path}: {exc.strerror or exc}") from None


def _replace(target: Path, payload: bytes, st: os.stat_result | None) -> None:
    """Write payload to a temporary file beside target, then rename it over target; the
    temporary file is removed if anything fails."""
    # a short temporary name: the target's own name may already be as long as the system allows
    fd, tmp = tempfile.mkstemp(prefix=".fdbench-", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
        os.chmod(tmp, stat.S_IMODE(st.st_mode) if st is not None else 0o666 & ~umask())
        if st is not None and hasattr(os, "chown") and (st.st_uid, st.st_gid) != (os.geteuid(), os.getegid()):
            try:
                os.chown(tmp, st.st_uid, st.st_gid)
            except OSError:
                pass  # not allowed: the file becomes the writer's, as with any rewrite
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass  # an append-only folder keeps it; nothing more can be done
        raise


@contextmanager
def _signals_deferred():
    """Within the block (in the main thread), SIGINT and SIGTERM are held back until it ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received = []
    previous = {}
    for number in (signal.SIGINT, signal.SIGTERM):
        previous[number] = signal.signal(number, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler if handler is not None else signal.SIG_DFL)
        for number in dict.fromkeys(received):
            signal.raise_signal(number)


def _remove_stale_temporaries(folder: Path) -> None:
    """Remove the atomic writer's temporary files (``.fdbench-XXXXXXXX.tmp``) in ``folder`` that a
    killed writer left: regular files of this user older than STALE_TEMPORARY_S seconds."""
    now = time.time()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for entry in entries:
        if not _TEMPORARY_NAME.fullmatch(entry.name):
            continue
        try:
            st = entry.stat(follow_symlinks=False)
            if stat.S_ISREG(st.st_mode) and st.st_uid == os.geteuid() and now - st.st_mtime > STALE_TEMPORARY_S:
                os.unlink(entry.path)
        except OSError:
            pass


@contextmanager
def new_folder(directory: str | os.PathLike):
    """Within the block, ``directory`` exists; one created here is removed if the block fails."""
    import shutil

    directory = Path(directory)
    created = not os.path.lexists(directory)
    if created:
        try:
            directory.mkdir()
        except OSError as exc:
            raise BadFile(f"--figures: cannot create {directory}: {exc.strerror or exc}") from None
    try:
        yield directory
    except BaseException:
        if created:
            shutil.rmtree(directory, ignore_errors=True)
        raise


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True if a and b name one file: by identity where both exist (hard and symbolic links
    included), by resolved path otherwise."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def check_distinct(outputs: dict, inputs: dict | None = None, database=None) -> None:
    """Refuse, before any work, an output naming an input, the results database (or its journal)
    or another output, and a database naming an input ({option: path or None}; devices may repeat)."""
    named = [(o, Path(p)) for o, p in outputs.items() if p is not None]
    protected = [(o, Path(p)) for o, p in (inputs or {}).items() if p is not None]
    if database is not None and str(database) != ":memory:":
        for other, guarded in protected:
            if same_file(database, guarded):
                raise BadFile(f"--db: {database} is the input of {other}; choose another file for the results")
        protected += [("--db", Path(database))]
        protected += [("--db", Path(f"{database}{suffix}")) for suffix in ("-wal", "-shm", "-journal")]
    for i, (option, path) in enumerate(named):
        st = _stat(path, option)
        if st is not None and stat.S_ISFIFO(st.st_mode):  # a pipe read as an input would take back the output
            for other, guarded in protected:
                if other != "--db" and same_file(path, guarded):
                    raise BadFile(f"{option}: {path} is the pipe the input of {other} is read from; "
                                  "choose another output")
        if st is not None and not stat.S_ISREG(st.st_mode):
            continue  # a device or another FIFO: writing it destroys nothing
        for other, guarded in protected:
            if same_file(path, guarded):
                what = "the results database" if other == "--db" else f"the input of {other}"
                raise BadFile(f"{option}: {path} is {what}; choose another file")
        for other, earlier in named[:i]:
            if same_file(path, earlier):
                raise BadFile(f"{option} and {other} name the same file {path}; give each its own")


INPUT_TIMEOUT_S = 10.0  # s: a pipe or FIFO that sends nothing for this long is refused (no writer?)
_READ_CACHE: dict = {}  # what each input held when first read, by identity (a pipe can be read only once)
_READ_CACHE_SIZE = 8


def read_input_bytes(path: str | os.PathLike, option: str, limit: int = MAX_INPUT_BYTES) -> bytes:
    """The bytes of an input file, read once per process (a pipe serves a digest and a parse); a
    pipe silent for INPUT_TIMEOUT_S s, a directory and more than ``limit`` bytes are refused."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise BadFile(f"{option}: {path} does not exist") from None
    except OSError as exc:
        raise BadFile(f"{option}: cannot read {path}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(st.st_mode):
        raise BadFile(f"{option}: {path} is a directory")
    if _identity(st) in _READ_CACHE:
        return _READ_CACHE[_identity(st)]
    try:
        raw = _read_regular(path, limit) if stat.S_ISREG(st.st_mode) else _read_stream(path, option, limit)
        st = os.stat(path)  # a pipe's times change while it is written: it is known by its final ones
    except OSError as exc:
        raise BadFile(f"{option}: cannot read {path}: {exc.strerror or exc}") from None
    if len(raw) > limit:
        raise BadFile(f"{option}: {path} is larger than {limit // 2**20} MiB; this is not a file fdbench reads")
    while len(_READ_CACHE) >= _READ_CACHE_SIZE:
        _READ_CACHE.pop(next(iter(_READ_CACHE)))
    _READ_CACHE[_identity(st)] = raw
    return raw


def _identity(st: os.stat_result) -> tuple:
    """What tells one content of a file from another: its inode, size and change times (a new
    pipe that reuses an inode number has other times)."""
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns


def _read_regular(path: Path, limit: int) -> bytes:
    with open(path, "rb") as handle:
        return handle.read(limit + 1)


def _read_stream(path: Path, option: str, limit: int) -> bytes:
    """At most limit + 1 bytes of a pipe, FIFO or device, waiting at most INPUT_TIMEOUT_S s for
    each piece."""
    import select

    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO with no writer would block open()
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN)
        chunks, size = [], 0
        while size <= limit:
            if not poller.poll(INPUT_TIMEOUT_S * 1000):
                raise BadFile(f"{option}: {path} sent nothing for {INPUT_TIMEOUT_S:g} s (a FIFO with no writer?); "
                              "give a regular file or a pipe that is being written")
            try:
                chunk = os.read(fd, min(2**16, limit + 1 - size))
            except BlockingIOError:
                continue
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        return b"".join(chunks)
    finally:
        os.close(fd)


def read_input_text(path: str | os.PathLike, option: str, limit: int = MAX_INPUT_BYTES) -> str:
    """The text of an input file (UTF-8, a byte-order mark allowed), read once as
    ``read_input_bytes`` does, refusing one larger than ``limit`` bytes and a directory."""
    raw = read_input_bytes(path, option, limit)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise BadFile(f"{option}: {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def parse_json(text: str):
    """JSON text as Python objects (integers beyond 2**63 as floats); ValueError (one line)."""
    import json

    def integer(digits: str):
        value = float(digits)
        return int(digits) if abs(value) < 2**63 else value

    try:
        return json.loads(text, parse_int=integer)
    except RecursionError:
        raise ValueError("nested too deeply") from None


def csv_text(header: list[str], rows) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buffer.getvalue()


def read_columns(path: str | os.PathLike, option: str, required: tuple, optional: tuple = ()) -> dict:
    """{name: array (n,)} of the named number columns of a CSV file with a header (names matched
    ignoring case; absent optional ones left out). BadFile naming the file's line."""
    path = Path(path)
    rows = _csv_rows(path, option, read_input_text(path, option))
    expected = ",".join(required)
    if not rows:
        raise BadFile(f"{option}: {path} is empty; expected a header '{expected}' and rows of numbers")
    header_line, labels = rows[0]
    header = [cell.strip().lower() for cell in labels]
    missing = [name for name in required if name not in header]
    if missing:
        raise BadFile(f"{option}: {path} needs columns {', '.join(repr(n) for n in required)} in its header, "
                      f"found {shown(', '.join(labels), 120)}")
    for k, name in enumerate(header):
        first = header.index(name)
        if first != k and name in required + tuple(optional):
            raise BadFile(f"{option}: {path} line {header_line}: columns {quoted(labels[first].strip())} and "
                          f"{quoted(labels[k].strip())} both name {quoted(name)} (names are matched ignoring case); "
                          "keep one")
    index = {name: header.index(name) for name in required + tuple(optional) if name in header}
    values = {name: [] for name in index}
    for number, row in rows[1:]:
        for name, i in index.items():
            if i >= len(row):
                raise BadFile(f"{option}: {path} line {number}: {len(row)} value{'s' if len(row) != 1 else ''}, fewer than the {len(labels)} "
                              f"columns of the header (no value for {quoted(labels[i].strip())})")
            try:
                values[name].append(float(row[i]))
            except ValueError:
                raise BadFile(f"{option}: {path} line {number}: column {quoted(labels[i].strip())} holds "
                              f"{quoted(row[i], 20)} where numbers are expected") from None
    return {name: np.array(column) for name, column in values.items()}


def _csv_rows(path: Path, option: str, text: str) -> list:
    """(line number, cells) of the non-blank rows of a CSV text; old Mac line endings (CR only)
    are read as line ends."""
    reader = csv.reader(io.StringIO(text.replace("\r\n", "\n").replace("\r", "\n")))
    rows = []
    try:
        for row in reader:
            if row and any(cell.strip() for cell in row):
                rows.append((reader.line_num, row))
    except csv.Error as exc:
        raise BadFile(f"{option}: {path} line {reader.line_num}: not a CSV file of numbers ({exc})") from None
    return rows


def read_history_csv(path: str | os.PathLike, option: str, duration: float, columns: tuple, preferred: tuple = ()
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(t (n,) s, values (n, len(columns))) of a CSV file with columns ``t`` and ``columns`` (or the
    names of ``preferred``: one tuple or several, tried first); t increasing over [0, duration] s."""
    path = Path(path)
    choices = [tuple(c) for c in preferred] if preferred and not isinstance(preferred[0], str) else [tuple(preferred)]
    choices = [c for c in choices if c] + [tuple(columns)]
    read = read_columns(path, option, ("t",), tuple(dict.fromkeys(name for c in choices for name in c)))
    found = next((c for c in choices if all(name in read for name in c)), None)
    if found is None:
        others = " or ".join(", ".join(repr(name) for name in c) for c in choices[:-1])
        raise BadFile(f"{option}: {path} needs columns 't', {', '.join(repr(c) for c in columns)}"
                      + (f" (or {others})" if others else "") + " in its header")
    t, values = read["t"], np.stack([read[c] for c in found], axis=-1)
    if len(t) < 2:
        raise BadFile(f"{option}: {path} needs at least 2 rows of data, found {len(t)}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(values))):
        raise BadFile(f"{option}: {path} holds non-finite values")
    if np.any(np.diff(t) <= 0):
        raise BadFile(f"{option}: {path}: times must be strictly increasing")
    if t[0] > 1e-9 or t[-1] < duration - 1e-9:
        raise BadFile(f"{option}: {path} covers [{t[0]:g}, {t[-1]:g}] s; it must cover [0, {duration:g}] s")
    return t, values


def finite_or_none(value):
    """JSON-safe float: NaN and infinities become None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
