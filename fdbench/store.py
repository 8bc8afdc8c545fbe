"""The results store: an embedded SQLite database, one row per run (settings and their hash,
indicators, history, best parameters, versions, commit, machine, time).

Every write is one transaction; WAL journaling and a busy timeout let several processes write.
Only an empty file or a new name becomes a database; another program's file, or one another local
user could have planted or can change, is refused before SQLite opens it. A run replaced by
``--rerun`` is kept, with its id, in ``superseded_runs``: a cited id always names a stored run.
"""

from __future__ import annotations

import json
import os
import platform
import sqlite3
import stat
import subprocess
import tempfile
import time
from contextlib import contextmanager
from datetime import datetime, timezone
from functools import lru_cache
from pathlib import Path

DEFAULT_DB = "fdbench-results.sqlite"
SCHEMA_NAME = "fdbench-results"
SCHEMA_VERSION = "1"
SUPERSEDED = "superseded_runs"  # runs replaced by a rerun, kept with their ids
OPEN_PATIENCE_S = 10.0  # how long opening waits for a lock held by another program
COMPANIONS = ("-wal", "-shm", "-journal")  # the files SQLite keeps beside a database

_SCHEMA = """
CREATE TABLE IF NOT EXISTS fdbench_meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    spec_hash TEXT NOT NULL UNIQUE,
    command TEXT NOT NULL,
    seed INTEGER,
    spec_json TEXT NOT NULL,
    record_json TEXT NOT NULL,
    history_json TEXT NOT NULL,
    params_json TEXT,
    rmse_rot_deg REAL,
    rmse_torque_nm REAL,
    runtime_s REAL,
    t_end REAL,
    status TEXT,
    jobs INTEGER,
    fdbench_version TEXT,
    versions_json TEXT,
    git_commit TEXT,
    machine TEXT,
    created_at TEXT NOT NULL
);
"""


class StoreError(Exception):
    """The database cannot be used; the message says which file and why."""


class DamagedRow(StoreError):
    """A stored run whose JSON cannot be read; the message names the column and why."""


def parse_stored(text, column: str, kinds: tuple = (dict,)):
    """The value of a stored JSON column, of one of the types ``kinds`` (None allowed where
    ``type(None)`` is among them); DamagedRow (one line) for text that is not JSON, is nested too
    deeply, or holds another type."""
    if text is None and type(None) in kinds:
        return None
    try:
        value = json.loads(text)
    except RecursionError:
        raise DamagedRow(f"{column} is nested too deeply") from None
    except (TypeError, ValueError) as exc:
        raise DamagedRow(f"{column} is not JSON ({str(exc).split(':')[0]})") from None
    if not isinstance(value, kinds):
        raise DamagedRow(f"{column} holds {type(value).__name__}, not {' or '.join(k.__name__ for k in kinds)}")
    wrong = _not_a_number(value, column)
    if wrong:
        raise DamagedRow(f"{column} holds {wrong} where a number is stored")
    return value


# a record's fields that hold numbers (besides every rmse_* and residual_* field)
NUMBER_FIELDS = {"dt", "seed", "budget", "runtime_s", "evaluations", "best_objective", "initial_objective", "t_end",
                 "max_violation", "n_params", "alpha", "xi", "omega", "penalty_weight", "noise_deg", "jobs"}


def _is_number(value) -> bool:
    return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool))


def _not_a_number(value, column: str) -> str | None:
    """What, in a stored record's number fields or in a history or parameter list (numbers, or lists
    of numbers), is not a number (None where all are): read, a report would fail on it midway."""
    if column == "record_json":
        for key, item in value.items():
            if (key in NUMBER_FIELDS or key.startswith(("rmse_", "residual_"))) and not _is_number(item):
                return f"{json.dumps(item)[:40]} in {key}"
    elif column in ("history_json", "params_json") and isinstance(value, list):
        for item in value:
            if not (_is_number(item) or (isinstance(item, list) and all(map(_is_number, item)))):
                return json.dumps(item)[:40]
    return None


def default_path() -> Path:
    return Path(os.environ.get("FDBENCH_DB") or DEFAULT_DB)


@contextmanager
def open_store(path=None):
    store = Store(path if path is not None else default_path())
    try:
        yield store
    finally:
        store.close()


def check_path(path) -> Path:
    """Refuse (StoreError), touching nothing, a name that cannot be or become a results database,
    or one another local user could have planted or can change (:func:`check_trusted`)."""
    if str(path) in ("", ":memory:"):
        raise StoreError(f"{str(path) or 'an empty name'} is not a file: the results database must be a file "
                         "that keeps the runs")
    path = Path(path)
    target = resolve(path)
    if path.is_dir():
        raise StoreError(f"{path} is a directory, not a results database")
    if not path.parent.is_dir():
        raise StoreError(f"directory {path.parent} of the results database does not exist")
    if path.exists() and not path.is_file():
        raise StoreError(f"{path} is not a regular file (a device or a pipe cannot hold results)")
    if not path.exists() and not os.access(path.parent, os.W_OK):
        raise StoreError(f"directory {path.parent} is not writable; the results database cannot be created there")
    check_trusted(target)
    return path


def _lstat(path: Path) -> os.stat_result | None:
    try:
        return os.lstat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise StoreError(f"cannot inspect {path}: {exc.strerror or exc}") from None


def resolve(path: Path) -> Path:
    """The file SQLite opens for the name ``path`` (a link followed); StoreError for a link to
    nothing and for one the kernel's ``fs.protected_symlinks`` would not follow."""
    st = _lstat(path)
    if st is None or not stat.S_ISLNK(st.st_mode):
        return path
    if not os.path.exists(path):
        raise StoreError(f"{path} is a symbolic link to {os.readlink(path)}, which does not exist; fdbench makes a "
                         "new results database only under the name it is given, not where a link points")
    from .files import planted_link  # lazily, as the rest of files (numpy) is not needed here

    reason = planted_link(path, st)
    if reason:
        raise StoreError(reason)
    return Path(os.path.realpath(path))


def companions(target: Path) -> list[tuple[Path, os.stat_result]]:
    """[(file, lstat)] of the ``-wal``, ``-shm`` and ``-journal`` files beside ``target``;
    StoreError for a link or a file that is not regular (SQLite would write through it)."""
    found = []
    for suffix in COMPANIONS:
        file = Path(f"{target}{suffix}")
        st = _lstat(file)
        if st is None:
            continue
        if stat.S_ISLNK(st.st_mode):
            raise StoreError(f"{file} is a symbolic link (to {os.readlink(file)}), not SQLite's own {suffix} file: "
                             "SQLite would write through it; remove it (fdbench never makes one)")
        if not stat.S_ISREG(st.st_mode):
            raise StoreError(f"{file} is not a regular file, not SQLite's own {suffix} file; remove it")
        found.append((file, st))
    return found


def foreign(file: Path, st: os.stat_result) -> str | None:
    """Why another local user could have planted or can change ``file``: owned by another user,
    or writable by every user; None if neither."""
    if st.st_uid != os.geteuid():
        return f"{file} belongs to another user (uid {st.st_uid})"
    if st.st_mode & stat.S_IWOTH:
        return f"{file} is writable by every user (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def check_trusted(target: Path) -> None:
    """Refuse a database file (``target``, resolved) or companion another local user could have
    planted or can change."""
    files = companions(target)
    st = _lstat(target)
    for file, file_st in ([(target, st)] if st is not None else []) + files:
        reason = foreign(file, file_st)
        if reason:
            raise StoreError(f"{reason}: another user could have planted it or could change its runs; fdbench writes "
                             "only to a database of its own user that no other user can write: use another --db")


def _create_new(path: Path) -> None:
    """Make a new, empty results database at ``path``: built beside it and linked into place whole
    (a failure leaves nothing; one another process made meanwhile is kept)."""
    fd, name = tempfile.mkstemp(prefix=".fdbench-", suffix=".tmp", dir=path.parent)
    os.close(fd)
    temporary = Path(name)
    db = None
    try:
        from .files import umask  # lazy: as planted_link above

        os.chmod(temporary, 0o666 & ~umask())  # as SQLite would create it
        db = sqlite3.connect(temporary, isolation_level=None)
        _write_schema(db)
        db.execute("PRAGMA journal_mode = WAL")  # kept in the file: every later connection uses it
        db.close()
        db = None
        try:
            os.link(temporary, path)  # never replaces a database made meanwhile
        except FileExistsError:
            pass
        except OSError:  # a file system without hard links
            if not path.exists():
                os.rename(temporary, path)
    except (sqlite3.Error, OSError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise StoreError(f"cannot create the results database {path}: {reason}; nothing was left behind") from None
    finally:
        if db is not None:
            db.close()
        for leftover in [temporary] + [Path(f"{temporary}{suffix}") for suffix in COMPANIONS]:
            try:
                os.unlink(leftover)
            except FileNotFoundError:
                pass


def _write_schema(db) -> None:
    """The tables and metadata in one transaction: other processes see no database or a whole one."""
    db.executescript("BEGIN IMMEDIATE;" + _SCHEMA)
    db.execute("INSERT OR IGNORE INTO fdbench_meta VALUES ('schema', ?), ('version', ?)", (SCHEMA_NAME, SCHEMA_VERSION))
    db.execute("COMMIT")


def _remove_empty_companions(target: Path, before: set) -> None:
    """After a failed initialisation of the empty file ``target``: remove the companions it made
    (not in ``before``) while nothing was written, lest a later open meet a half-made ``-shm``."""
    made = [Path(f"{target}{suffix}") for suffix in COMPANIONS if Path(f"{target}{suffix}") not in before]
    try:
        if os.path.getsize(target) > 0 or any(f.exists() and f.stat().st_size > 0 for f in made if f.name[-4:] != "-shm"):
            return
    except OSError:
        return
    for file in made:
        try:
            os.unlink(file)
        except OSError:
            pass


class Store:
    def __init__(self, path):
        self.path = check_path(path)
        if not self.path.exists():
            _create_new(self.path)
            check_trusted(resolve(self.path))  # the database made by another process meanwhile, if any
        elif self.path.stat().st_size > 0:
            check_header(self.path)
        self.db = None
        try:
            self.db = sqlite3.connect(self.path, timeout=OPEN_PATIENCE_S, isolation_level=None)
            self.db.execute("BEGIN")  # one read: what the file holds, as another process may be creating it
            objects = self.db.execute("SELECT type, name FROM sqlite_master").fetchall()
            pages = self.db.execute("PRAGMA page_count").fetchone()[0]
            self.db.execute("COMMIT")
            self.db.execute("PRAGMA busy_timeout = 60000")  # writers of a parallel report wait their turn
        except sqlite3.OperationalError as exc:
            self.close()
            if "locked" in str(exc) or "busy" in str(exc):
                raise StoreError(f"{self.path} is locked by another program; try again when it is done") from None
            raise StoreError(f"{self.path} cannot be opened ({exc}); it was left untouched") from None
        except sqlite3.DatabaseError as exc:
            self.close()
            raise StoreError(f"{self.path} is not an fdbench results database ({exc}); it was left untouched") from None
        try:
            if ("table", "fdbench_meta") in objects:
                self._check_meta({name for kind, name in objects if kind == "table"})
            elif pages > 0:  # only an empty file or a new name becomes a results database
                raise StoreError(f"{self.path} is an SQLite database of something else ({_contents(objects)}); "
                                 "it was left untouched")
            else:  # an empty file of the user's own: made a database in place
                target = resolve(self.path)
                before = {file for file, _ in companions(target)}
                try:
                    self._create()
                except BaseException:
                    self.close()
                    _remove_empty_companions(target, before)
                    raise
        except sqlite3.DatabaseError as exc:
            self.close()
            raise StoreError(f"{self.path} cannot be used as a results database ({exc}); it was left untouched") from None
        except BaseException:
            self.close()
            raise

    def check_usable(self, lock_patience_s: float = 10.0) -> None:
        """Make sure, before any work, that runs can be written here: the file is intact, not
        read-only, and not locked by another program for longer than ``lock_patience_s``."""
        try:
            problems = [row[0] for row in self.db.execute("PRAGMA quick_check")]
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{self.path} is damaged ({exc}); it was left untouched: use another --db") from None
        if problems != ["ok"]:
            raise StoreError(f"{self.path} is damaged ({'; '.join(problems[:2])}); it was left untouched: "
                             "use another --db")
        if not os.access(self.path, os.W_OK) or not (self.path.stat().st_mode & 0o222):
            raise StoreError(f"{self.path} is read-only; results could not be stored")
        if not os.access(self.path.parent, os.W_OK):
            raise StoreError(f"directory {self.path.parent} is not writable (the database keeps its journal there)")
        self.db.execute(f"PRAGMA busy_timeout = {int(lock_patience_s * 1000)}")
        try:
            self.db.execute("BEGIN IMMEDIATE")
            self.db.execute("ROLLBACK")
        except sqlite3.OperationalError as exc:
            if "locked" in str(exc) or "busy" in str(exc):
                raise StoreError(f"{self.path} is locked by another program; try again when it is done") from None
            raise StoreError(f"{self.path} cannot be written: {exc}") from None
        finally:
            self.db.execute("PRAGMA busy_timeout = 60000")

    def _create(self):
        try:
            _write_schema(self.db)
            self._set_wal()
        except sqlite3.Error as exc:
            raise StoreError(f"cannot create the results database {self.path}: {exc}") from None

    def _set_wal(self, patience_s: float = 60.0):
        """WAL journaling lets several processes write; the pragma does not wait on a lock held
        by another process creating the same database, so retry it."""
        deadline = time.monotonic() + patience_s
        while True:
            try:
                self.db.execute("PRAGMA journal_mode = WAL")
                return
            except sqlite3.OperationalError as exc:
                if "locked" not in str(exc) or time.monotonic() > deadline:
                    raise
                time.sleep(0.02)

    def _check_meta(self, tables: set):
        meta = dict(self.db.execute("SELECT key, value FROM fdbench_meta"))
        if meta.get("schema") != SCHEMA_NAME:
            raise StoreError(f"{self.path} is not an fdbench results database; it was left untouched")
        if meta.get("version") != SCHEMA_VERSION:
            raise StoreError(f"{self.path} has results schema version {meta.get('version')}; this fdbench "
                             f"reads version {SCHEMA_VERSION}: use another --db")
        if "runs" not in tables:
            raise StoreError(f"{self.path} has lost its table of runs; it was left untouched: use another --db")

    def close(self):
        if getattr(self, "db", None) is not None:
            self.db.close()
            self.db = None

    # ---- reading -----------------------------------------------------------------------------

    def _query(self, sql: str, args=()) -> list:
        try:
            return self.db.execute(sql, args).fetchall()
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"cannot read the results database {self.path}: {exc}") from None

    def get(self, spec_hash: str) -> dict | None:
        """The stored run with this settings hash, or None."""
        rows = self._query("SELECT id, record_json, history_json, params_json FROM runs WHERE spec_hash = ?",
                           (spec_hash,))
        return self._run(rows[0]) if rows else None

    def _run(self, row) -> dict:
        """{id, record, history, params} of a row (id, record_json, history_json, params_json);
        StoreError naming the database and the row for a damaged one."""
        try:
            return {"id": row[0], "record": parse_stored(row[1], "record_json"),
                    "history": parse_stored(row[2], "history_json", (list,)),
                    "params": parse_stored(row[3] or None, "params_json", (list, type(None)))}
        except DamagedRow as exc:
            raise StoreError(f"{self.path}: stored run id {row[0]} is damaged ({exc}); it was left untouched: "
                             "--rerun replaces it, or use another --db") from None

    def hashes(self) -> set[str]:
        return {row[0] for row in self._query("SELECT spec_hash FROM runs")}

    def count(self) -> int:
        return self._query("SELECT COUNT(*) FROM runs")[0][0]

    def records(self) -> list[dict]:
        return [self._run((row[0], row[1], "[]", None))["record"]
                for row in self._query("SELECT id, record_json FROM runs ORDER BY id")]

    def ids(self, hashes) -> dict[str, int]:
        """{spec hash: row id} of the runs stored now under ``hashes``."""
        wanted = set(hashes)
        return {row[0]: row[1] for row in self._query("SELECT spec_hash, id FROM runs") if row[0] in wanted}

    def runs_by_id(self, ids) -> dict[int, dict]:
        """{row id: {id, record, history, params}} of these rows, whether current or replaced
        since by a rerun (see :meth:`put`): an id once read stays readable."""
        return {row[0]: self._run(row) for row in self._rows_by_id("id, record_json, history_json, params_json", ids)}

    def provenance(self, runs) -> dict:
        """{spec hash: {id, created_at, machine, jobs, git_commit, fdbench_version}} of ``runs``:
        {spec hash: stored run} (each run's own row) or spec hashes (the rows stored now)."""
        fields = ("id", "created_at", "machine", "jobs", "git_commit", "fdbench_version")
        if isinstance(runs, dict) and all(isinstance(run, dict) and "id" in run for run in runs.values()):
            hash_of = {run["id"]: key for key, run in runs.items()}
            rows = self._rows_by_id(", ".join(fields), hash_of)
            return {hash_of[row[0]]: dict(zip(fields, row)) for row in rows}
        wanted = set(runs)
        return {row[0]: dict(zip(fields, row[1:])) for row in self._query(f"SELECT spec_hash, {', '.join(fields)} "
                                                                           "FROM runs ORDER BY id")
                if row[0] in wanted}

    def _rows_by_id(self, columns: str, ids) -> list:
        """Rows (``columns``, id first) of the current and replaced runs with these ids."""
        ids = sorted(set(ids))
        tables = ["runs"] + ([SUPERSEDED] if self._has_table(SUPERSEDED) else [])
        rows = []
        for start in range(0, len(ids), 500):  # SQLite bounds the number of parameters of a statement
            chunk = ids[start:start + 500]
            marks = ", ".join("?" * len(chunk))
            for table in tables:
                rows += self._query(f"SELECT {columns} FROM {table} WHERE id IN ({marks})", chunk)
        return rows

    def _has_table(self, name: str) -> bool:
        return bool(self._query("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,)))

    # ---- writing -----------------------------------------------------------------------------

    def add(self, spec, outcome, jobs: int = 1, replace: bool = False) -> bool:
        """Store one run (a RunSpec and its RunOutcome); True if written. An existing run with
        the same settings hash is kept unless ``replace``."""
        return self.add_record(spec, outcome.record, outcome.history, outcome.params, jobs, replace)

    def add_record(self, spec, record: dict, history, params=None, jobs: int = 1, replace: bool = False) -> bool:
        """Store one run; True if written (see :meth:`put`)."""
        return self.put(spec, record, history, params, jobs, replace) is not None

    def put(self, spec, record: dict, history, params=None, jobs: int = 1, replace: bool = False) -> int | None:
        """Store one run; its row id, or None when a run with its settings hash is kept (not
        ``replace``). A replaced row moves, with its id, to ``superseded_runs`` in the same
        transaction; ids are never reused (AUTOINCREMENT)."""
        record = dict(record, jobs=jobs)
        record.pop("command_time_s", None)
        values = (
            spec.hash(), spec.command, spec.seed, json.dumps(spec.as_dict(), sort_keys=True, default=str),
            json.dumps(record, default=_json_default), json.dumps([float(v) for v in history]),
            json.dumps([float(v) for v in params]) if params is not None else None,
            record.get("rmse_rot_deg"), record.get("rmse_torque_nm"), record.get("runtime_s"),
            record.get("t_end"), record.get("status"), jobs, record.get("fdbench_version"),
            json.dumps(dependency_versions()), git_commit(), machine(),
            datetime.now(timezone.utc).isoformat(timespec="seconds"),
        )
        insert = ("INSERT OR IGNORE INTO runs (spec_hash, command, seed, spec_json, record_json, history_json, "
                  "params_json, rmse_rot_deg, rmse_torque_nm, runtime_s, t_end, status, jobs, fdbench_version, "
                  "versions_json, git_commit, machine, created_at) "
                  "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)")
        try:
            if not replace:
                cursor = self.db.execute(insert, values)
            else:
                self.db.execute("BEGIN IMMEDIATE")
                try:
                    self._supersede(values[0])
                    cursor = self.db.execute(insert, values)
                    self.db.execute("COMMIT")
                except BaseException:
                    self.db.execute("ROLLBACK")
                    raise
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write to the results database {self.path}: {exc}") from None
        return cursor.lastrowid if cursor.rowcount == 1 else None

    def _supersede(self, spec_hash: str) -> None:
        """Move the current run of this hash, if any, to ``superseded_runs`` (within a transaction)."""
        self.db.execute(f"CREATE TABLE IF NOT EXISTS {SUPERSEDED} AS SELECT * FROM runs WHERE 0")
        self.db.execute(f"INSERT INTO {SUPERSEDED} SELECT * FROM runs WHERE spec_hash = ?", (spec_hash,))
        self.db.execute("DELETE FROM runs WHERE spec_hash = ?", (spec_hash,))


def _contents(objects: list) -> str:
    """What a foreign SQLite database holds, for a message: 'tables: a, b', 'views: v' or 'no tables'."""
    parts = []
    for kind in ("table", "view"):
        names = sorted(name for k, name in objects if k == kind)
        if names:
            parts.append(f"{kind}s: {', '.join(names[:5])}{', ...' if len(names) > 5 else ''}")
    return "; ".join(parts) or "no tables"


def check_header(path: Path) -> None:
    try:
        with open(path, "rb") as handle:
            header = handle.read(16)
    except OSError as exc:
        raise StoreError(f"cannot read the results database {path}: {exc}") from None
    if header != b"SQLite format 3\x00":
        raise StoreError(f"{path} is not an fdbench results database (not SQLite); it was left untouched")


def _json_default(value):
    if hasattr(value, "item"):
        return value.item()
    return str(value)


@lru_cache(maxsize=1)
def dependency_versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    versions = {"python": platform.python_version()}
    for name in ("fdbench", "numpy", "scipy", "numba", "cma", "typer", "rich", "pandas", "matplotlib", "opensim"):
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            versions[name] = None
    return versions


@lru_cache(maxsize=1)
def git_commit() -> str | None:
    """The commit of the fdbench source tree, if it is a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


@lru_cache(maxsize=1)
def machine() -> str:
    return f"{platform.node()} {platform.system()} {platform.machine()} {os.cpu_count()} cores"
