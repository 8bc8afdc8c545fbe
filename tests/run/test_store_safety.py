"""A results database or output that another local user planted or can change, a damaged stored
run, a full disk and a full standard output: each is one line on stderr and exit code 2 (or a
warning naming a skipped run), and nothing is left behind.

"Another user" is simulated as root can: files chowned to another uid, mode o+w, a sticky
world-writable folder like /tmp; a reader without root's power over files is a child started by
``setpriv`` without CAP_DAC_OVERRIDE. A full disk is a child with RLIMIT_FSIZE (writes past the
limit fail as on a full disk, SIGXFSZ ignored); a full stdout is /dev/full."""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fdbench.cli import app
from fdbench.spec import RunSpec, control_spec
from fdbench.store import Store, StoreError, open_store
from fdbench.store_queries import method_label

from helpers.cli_checks import assert_one_line_error
from helpers.processes import python_path
from helpers.paths import ROOT

PREFIX = "fdbench: error: "
OTHER = 12345  # a uid that is not ours
FDBENCH = [sys.executable, "-m", "fdbench.cli"]
IS_ROOT = os.geteuid() == 0
needs_root = pytest.mark.skipif(not IS_ROOT, reason="files of another user are made with chown, which needs root")
runner = CliRunner()


def invoke(*args, code=0):
    result = runner.invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.stderr, result.stderr
    assert result.exit_code == code, f"exit {result.exit_code}; stderr: {result.stderr!r}"
    return result


def refused(*args, contains=()) -> str:
    """Exit 2, nothing on stdout, one line on stderr holding every word of ``contains``."""
    return assert_one_line_error(invoke(*args, code=2), *contains)


def sticky_folder(tmp_path: Path) -> Path:
    """A folder like /tmp: everyone may write in it, only a file's owner remove it (mode 1777)."""
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o1777)
    return shared


def listing(folder: Path) -> dict:
    """Every name in ``folder``: (owner, mode, size, mtime, link target) - what a refusal must not change."""
    out = {}
    for entry in sorted(os.listdir(folder)):
        st = os.lstat(folder / entry)
        link = os.readlink(folder / entry) if os.path.islink(folder / entry) else None
        out[entry] = (st.st_uid, st.st_mode, st.st_size, st.st_mtime_ns, link)
    return out


def fake_record(spec: RunSpec, rmse: float) -> dict:
    return {"command": spec.command, "seed": spec.seed, "rmse_rot_deg": rmse, "rmse_torque_nm": 0.25,
            "runtime_s": 0.01, "t_end": 1.0, "status": "success", "fdbench_version": "0.1.0"}


def filled(path: Path, n: int = 3) -> list[RunSpec]:
    """A results database at ``path`` with ``n`` stored control runs (seeds 0..n-1), as fdbench makes it."""
    specs = [control_spec(kp=80.0 + i, kd=0.3) for i in range(n)]
    with open_store(path) as store:
        for i, spec in enumerate(specs):
            store.add_record(spec, fake_record(spec, 1.0 + i), [1.0, 0.5])
    return specs


def damage(path: Path, row_id: int, column: str, text: str) -> None:
    con = sqlite3.connect(path)
    con.execute(f"UPDATE runs SET {column} = ? WHERE id = ?", (text, row_id))
    con.commit()
    con.close()


# ---- 1. a database another user planted or can change ------------------------------------------


def _planted_empty_by_another_user(db: Path):
    db.touch()
    os.chown(db, OTHER, -1)
    db.chmod(0o666)


def _empty_writable_by_all(db: Path):
    db.touch()
    db.chmod(0o666)


def _database_of_another_user(db: Path):
    filled(db)
    os.chown(db, OTHER, -1)


def _wal_of_another_user(db: Path):
    filled(db)
    Path(f"{db}-wal").touch()
    os.chown(f"{db}-wal", OTHER, -1)


def _journal_writable_by_all(db: Path):
    filled(db)
    Path(f"{db}-journal").touch()
    Path(f"{db}-journal").chmod(0o666)


@needs_root
@pytest.mark.parametrize("plant, says", [
    (_planted_empty_by_another_user, f"belongs to another user (uid {OTHER})"),
    (_empty_writable_by_all, "writable by every user"),
    (_database_of_another_user, f"belongs to another user (uid {OTHER})"),
    (_wal_of_another_user, f"-wal belongs to another user (uid {OTHER})"),
    (_journal_writable_by_all, "-journal is writable by every user"),
])
def test_a_database_another_user_planted_or_can_change_is_refused_untouched(tmp_path, plant, says):
    db = tmp_path / "team.sqlite"
    plant(db)
    before = listing(tmp_path)
    refused("control", "--db", db, "-q", contains=("--db", says))
    assert listing(tmp_path) == before


@needs_root
def test_a_report_does_not_adopt_a_planted_database(tmp_path):
    """The issue's case: an empty team.sqlite of another user, writable by all, was taken as a new
    database; that user then changed a stored number and the next report printed it."""
    db = tmp_path / "team.sqlite"
    _planted_empty_by_another_user(db)
    refused("report", "--db", db, "--no-control", "--torque", "cs", "--opt", "bfgs", "--no-feedforward",
            "--seeds", "1", "--budget", "2", "-q", contains=("team.sqlite", "another user"))
    assert db.stat().st_size == 0 and sorted(os.listdir(tmp_path)) == ["team.sqlite"]


def test_a_dangling_link_as_db_creates_nothing_where_it_points(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "db.sqlite").symlink_to(elsewhere / "theirs.sqlite")
    refused("control", "--db", tmp_path / "db.sqlite", "-q", contains=("symbolic link", "does not exist"))
    assert os.listdir(elsewhere) == []


@needs_root
def test_a_link_another_user_made_in_a_shared_folder_is_not_followed(tmp_path):
    """As the kernel's fs.protected_symlinks: in a sticky world-writable folder, a link of another user."""
    shared = sticky_folder(tmp_path)
    filled(tmp_path / "mine.sqlite")
    link = shared / "db.sqlite"
    link.symlink_to(tmp_path / "mine.sqlite")
    os.lchown(link, OTHER, -1)
    before = listing(tmp_path)
    refused("control", "--db", link, "-q", contains=("made by another user", "protected_symlinks"))
    assert listing(tmp_path) == before


@pytest.mark.parametrize("suffix", ["-wal", "-shm"])
@pytest.mark.parametrize("command", [("control", "-q"), ("runs", "list")])
def test_a_planted_wal_or_shm_link_is_refused_before_sqlite_opens_and_kept(tmp_path, suffix, command):
    """SQLite would write through the link, fail with "unable to open database file", and delete it."""
    db = tmp_path / "a.sqlite"
    filled(db)
    victim = tmp_path / "victim"
    victim.write_text("not SQLite's")
    Path(f"{db}{suffix}").symlink_to(victim)
    before = listing(tmp_path)
    args = (*command, "--db", db) if command[0] == "runs" else (command[0], "--db", db, command[1])
    refused(*args, contains=(f"{db}{suffix}", "symbolic link", "remove it"))
    assert listing(tmp_path) == before and victim.read_text() == "not SQLite's"


def test_an_empty_file_of_ours_becomes_a_database_without_a_creating_line(tmp_path):
    """A 0-byte file counts as existing: it is made a database in place, and only a database
    fdbench creates is announced."""
    db = tmp_path / "mine.sqlite"
    db.touch()
    with open_store(db) as store:
        assert store.count() == 0
    assert db.read_bytes()[:16] == b"SQLite format 3\x00"


# ---- 2. damaged stored runs ---------------------------------------------------------------------


DAMAGES = [("record_json", "{not json", "record_json is not JSON"),
           ("spec_json", "[" * 100_000, "spec_json is nested too deeply"),
           ("record_json", "[1, 2]", "record_json holds list"),
           ("record_json", '{"status": "success", "rmse_rot_deg": "abc"}', 'record_json holds "abc" in rmse_rot_deg')]


@pytest.mark.parametrize("column, text, says", DAMAGES)
def test_runs_skip_a_damaged_run_with_a_warning_naming_the_database_and_the_row(tmp_path, column, text, says):
    db = tmp_path / "a.sqlite"
    filled(db)
    damage(db, 2, column, text)
    for args in (("runs", "list", "-f", "json"), ("runs", "export", "-f", "json")):
        result = invoke(*args, "--db", db)
        assert [row["id"] for row in json.loads(result.stdout)] == [1, 3]
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"fdbench: warning: {db}: stored run id 2 is damaged ({says}")
        assert lines[0].endswith("skipped")
    refused("runs", "show", "2", "--db", db, contains=("run id 2", str(db), says))
    invoke("runs", "show", "3", "--db", db)


@pytest.mark.parametrize("column, text, says", DAMAGES)
def test_a_report_reading_a_damaged_run_is_refused_naming_the_database_and_the_row(tmp_path, column, text, says):
    """What a report reads of its stored runs (Store.runs_by_id, get, records): a StoreError, which
    the command line gives as one line with exit code 2, naming the way out (--rerun)."""
    db = tmp_path / "a.sqlite"
    specs = filled(db)
    damage(db, 2, column if column != "spec_json" else "record_json", text)
    with open_store(db) as store:
        for read in (lambda: store.runs_by_id([1, 2, 3]), lambda: store.get(specs[1].hash()), store.records):
            with pytest.raises(StoreError) as caught:
                read()
            message = str(caught.value)
            assert str(db) in message and "run id 2" in message and "--rerun" in message
        assert store.runs_by_id([1, 3]).keys() == {1, 3}  # the other rows read as before


@pytest.mark.parametrize("column, text", [("history_json", '["x"]'), ("params_json", '[0.5, {"a": 1}]')])
def test_a_run_whose_history_or_parameters_are_not_numbers_is_refused(tmp_path, column, text):
    db = tmp_path / "a.sqlite"
    specs = filled(db)
    damage(db, 2, column, text)
    with open_store(db) as store:
        with pytest.raises(StoreError, match=f"run id 2 is damaged \\({column} holds .* where a number is stored"):
            store.get(specs[1].hash())
        assert store.get(specs[0].hash())["id"] == 1


# ---- 3. a full disk ----------------------------------------------------------------------------


def _with_file_size_limit(limit: int, args: list, cwd: Path) -> subprocess.CompletedProcess:
    """fdbench ``args`` in a child whose writes past ``limit`` bytes of a file fail as on a full disk."""
    code = ("import resource, signal, sys, runpy; signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
            f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit})); "
            "sys.argv = ['fdbench'] + sys.argv[1:]; runpy.run_module('fdbench.cli', run_name='__main__')")
    env = dict(os.environ, PYTHONPATH=python_path(ROOT), PYTHONDONTWRITEBYTECODE="1")
    return subprocess.run([sys.executable, "-c", code, *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=120)


@pytest.mark.parametrize("existing", [False, True], ids=["new name", "empty file"])
def test_a_full_disk_leaves_no_database_and_no_journal(tmp_path, existing):
    """The issue's case (a refused report) left a 0-byte database, an empty figs/, a 3-byte -shm
    and an empty -wal, and sqlite3 then said "disk I/O error". The limit (2 KiB) is below one
    SQLite page (4 KiB); the report is refused before any run (no kernel is compiled)."""
    db = tmp_path / "new.sqlite"
    if existing:
        db.touch()
    done = _with_file_size_limit(2048, ["report", "--db", str(db), "--figures", "figs", "--no-control", "--torque",
                                        "cs", "--opt", "bfgs", "--no-feedforward", "--seeds", "1", "--budget", "2",
                                        "--jobs", "1", "-q"], tmp_path)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(PREFIX) and "new.sqlite" in lines[0], done.stderr
    assert sorted(os.listdir(tmp_path)) == (["new.sqlite"] if existing else [])
    if existing:
        assert db.stat().st_size == 0
    with open_store(db) as store:  # once there is room, the name works as a database
        assert store.count() == 0


def test_a_new_database_appears_whole_or_not_at_all(tmp_path, monkeypatch):
    """A creation that fails after its tables were written (here, at the link into place) leaves
    no file: the database is made under a temporary name beside its own."""
    def fail(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "link", fail)
    monkeypatch.setattr(os, "rename", fail)
    with pytest.raises(StoreError, match="No space left on device; nothing was left behind"):
        Store(tmp_path / "new.sqlite")
    assert os.listdir(tmp_path) == []


def test_a_figures_folder_made_for_figures_that_fail_is_removed(tmp_path):
    from fdbench.files import new_folder

    made, kept = tmp_path / "figs", tmp_path / "mine"
    kept.mkdir()
    (kept / "old.png").write_bytes(b"x")
    for folder in (made, kept):
        with pytest.raises(OSError):
            with new_folder(folder):
                (folder / "fig1.png").write_bytes(b"half")
                raise OSError(28, "No space left on device")
    assert not made.exists()
    assert sorted(os.listdir(kept)) == ["fig1.png", "old.png"]  # a folder that existed is not removed


# ---- 4. a full standard output -----------------------------------------------------------------


@pytest.mark.parametrize("args", [["inverse", "-f", "json"], ["methods"], ["--version"], ["--help"],
                                  ["runs", "list", "--db", "{db}"]])
def test_a_full_stdout_is_one_line_and_exit_2_as_a_full_output_file(tmp_path, args):
    db = tmp_path / "a.sqlite"
    filled(db)
    args = [a.format(db=db) for a in args]
    env = dict(os.environ, PYTHONPATH=python_path(ROOT))
    with open("/dev/full", "w") as full:
        done = subprocess.run(FDBENCH + args, stdout=full, stderr=subprocess.PIPE, text=True, env=env, timeout=120)
    lines = done.stderr.splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith(PREFIX + "standard output: cannot write") and "No space left" in lines[0]
    if args[0] == "inverse":  # the same as naming /dev/full with -o
        named = subprocess.run(FDBENCH + args + ["-o", "/dev/full"], capture_output=True, text=True, env=env,
                               timeout=120)
        assert named.returncode == 2 and len(named.stderr.splitlines()) == 1, named.stderr


# ---- 6. another user reads a readable database -------------------------------------------------


def _foreign_wal_database(tmp_path: Path) -> Path:
    """A WAL database of another user (uid OTHER), readable by all, in a folder of theirs (0755)."""
    folder = tmp_path / "theirs"
    folder.mkdir()
    db = folder / "r.sqlite"
    filled(db)
    for path in (folder, db):
        os.chown(path, OTHER, -1)
    folder.chmod(0o755)
    db.chmod(0o644)
    return db


@needs_root
def test_another_users_database_is_read_without_writing_anything(tmp_path):
    db = _foreign_wal_database(tmp_path)
    before = listing(db.parent)
    rows = json.loads(invoke("runs", "list", "--db", db, "-f", "json").stdout)
    assert [row["id"] for row in rows] == [1, 2, 3]
    assert listing(db.parent) == before  # not even a -wal or -shm of root's in their folder


@needs_root
@pytest.mark.skipif(shutil.which("setpriv") is None, reason="needs setpriv to drop CAP_DAC_OVERRIDE")
def test_a_user_who_cannot_write_the_folder_reads_the_database(tmp_path):
    """The issue's case ("attempt to write a readonly database"): a reader without write access to
    the folder, here root without CAP_DAC_OVERRIDE (a plain user's rights on another's files)."""
    db = _foreign_wal_database(tmp_path)
    before = listing(db.parent)
    drop = ["setpriv", "--inh-caps=-dac_override,-dac_read_search", "--bounding-set=-dac_override,-dac_read_search"]
    env = dict(os.environ, PYTHONPATH=python_path(ROOT))
    done = subprocess.run(drop + FDBENCH + ["runs", "list", "--db", str(db), "-f", "csv"], capture_output=True,
                          text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert [line.split(",")[0] for line in done.stdout.splitlines()] == ["id", "1", "2", "3"]
    assert listing(db.parent) == before


@needs_root
def test_changes_still_in_another_users_wal_are_named_as_not_shown(tmp_path):
    db = _foreign_wal_database(tmp_path)
    writer = sqlite3.connect(db)  # another user's writer at work: its change is in the -wal only
    writer.execute("PRAGMA wal_autocheckpoint = 0")
    writer.execute("UPDATE runs SET rmse_rot_deg = 0.0001")
    writer.commit()
    try:
        os.chown(f"{db}-wal", OTHER, -1)
        result = invoke("runs", "list", "--db", db, "-f", "json")
        assert len(json.loads(result.stdout)) == 3
        assert result.stderr.startswith("fdbench: warning: ") and "r.sqlite-wal" in result.stderr
        assert "not shown" in result.stderr and len(result.stderr.splitlines()) == 1
    finally:
        writer.close()


# ---- outputs in a shared folder ----------------------------------------------------------------


@needs_root
def test_an_output_link_another_user_made_in_a_shared_folder_is_refused(tmp_path):
    """The shell's '>' is refused there by fs.protected_symlinks; a resolve-and-rename would get past it."""
    shared = sticky_folder(tmp_path)
    target = tmp_path / "precious.txt"
    target.write_text("keep")
    link = shared / "out.json"
    link.symlink_to(target)
    os.lchown(link, OTHER, -1)
    refused("inverse", "-f", "json", "-o", link, contains=("made by another user", "protected_symlinks"))
    assert target.read_text() == "keep" and os.readlink(link) == str(target)


@needs_root
def test_an_output_file_of_another_user_in_a_shared_folder_is_refused(tmp_path):
    shared = sticky_folder(tmp_path)
    theirs = shared / "out.json"
    theirs.write_text("theirs")
    os.chown(theirs, OTHER, -1)
    refused("inverse", "-f", "json", "-o", theirs, contains=("belongs to another user", "protected_regular"))
    assert theirs.read_text() == "theirs" and theirs.stat().st_uid == OTHER


def test_an_output_link_of_ours_in_a_shared_folder_is_written_through(tmp_path):
    shared = sticky_folder(tmp_path)
    target = tmp_path / "out.json"
    target.write_text("old")
    link = shared / "out.json"
    link.symlink_to(target)
    invoke("inverse", "-f", "json", "-o", link, "-q")
    assert json.loads(target.read_text())["command"] == "inverse" and link.is_symlink()


# ---- 7. smaller points -------------------------------------------------------------------------


def test_runs_export_says_what_it_wrote(tmp_path):
    db = tmp_path / "a.sqlite"
    filled(db)
    out = tmp_path / "runs.csv"
    result = invoke("runs", "export", "--db", db, "-o", out)
    assert result.stdout == "" and result.stderr == f"wrote {out} (3 runs)\n"
    assert len(out.read_text().splitlines()) == 4


def test_the_walks_open_loop_is_listed_as_open_loop():
    """The walk's open loop is stored as PD with Kp = Kd = 0 (report.methods); the PD with gains is PD."""
    from fdbench.report import methods

    found = methods.methods((methods.OPEN_LOOP, methods.PD, methods.LQR), methods.Dataset("", {}))
    listed = {m.key: method_label(m.spec.as_dict()) for m in found}
    assert listed[methods.OPEN_LOOP] == "open loop" and listed[methods.PD] == "pd" and listed[methods.LQR] == "lqr"
