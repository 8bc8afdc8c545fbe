"""No file lost under any name, and a kernel cache nobody else can write: --figures and --db
against the command's inputs, the order check / work / write, the atomic writer's temporary
files, outputs found unwritable, and the numba cache folder's owner, mode and links."""

from __future__ import annotations

import os
import signal
import socket
import sqlite3
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fdbench import files
from fdbench.cli import app
from fdbench.store import open_store

runner = CliRunner()
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0
SMALL_REPORT = ["--seeds", "1", "--budget", "2", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "-q"]
MOTION_CSV = "t,theta\n" + "".join(f"{i / 100:g},{-45 + 30 * (i / 100) ** 2:g}\n" for i in range(101))


def invoke(args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(result, code=2) -> str:
    assert "Traceback" not in result.stderr, result.stderr
    assert result.exit_code == code, f"exit {result.exit_code}: {result.stderr!r} {result.exception!r}"
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:"), result.stderr
    return lines[0]


def temporaries(folder: Path) -> list:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".fdbench-"))


# ---- --figures against the command's inputs -----------------------------------------------------

FIGURE_OF = {"report": "figure2_inverse_dynamics.png", "study": "study_noise_rmse_rot_deg.png"}
COMMAND = {"report": ["report", "--no-beyond"], "study": ["study", "noise", "--levels", "0"]}


@pytest.mark.parametrize("command", ["report", "study"])
@pytest.mark.parametrize("option", ["--motion", "--model-file"])
@pytest.mark.parametrize("link", ["symlink", "hard link"])
def test_figure_name_that_is_an_input_is_refused_before_work(tmp_path, monkeypatch, command, option, link):
    monkeypatch.chdir(tmp_path)
    source = tmp_path / ("motion.csv" if option == "--motion" else "model.toml")
    source.write_text(MOTION_CSV if option == "--motion" else "I1 = 0.0437\n")
    before = source.read_bytes()
    (tmp_path / "figs").mkdir()
    figure = tmp_path / "figs" / FIGURE_OF[command]
    os.symlink(source, figure) if link == "symlink" else os.link(source, figure)
    result = invoke(COMMAND[command] + SMALL_REPORT + [option, source.name, "--db", "r.sqlite", "--figures", "figs"])
    line = one_line_error(result)
    assert "--figures" in line and option in line, line
    assert source.read_bytes() == before
    assert not (tmp_path / "r.sqlite").exists()


@pytest.mark.parametrize("command", ["report", "study"])
@pytest.mark.parametrize("kind", ["symlink", "hard link", "fifo"])
def test_figure_name_that_is_not_a_file_of_its_own_is_refused_before_work(tmp_path, monkeypatch, command, kind):
    """The user names the folder, not what a figure's name in it leads to: a link to another file,
    a file with another name, a FIFO (which would block the report) are refused, nothing written."""
    monkeypatch.chdir(tmp_path)
    other = tmp_path / "notes.txt"
    other.write_text("keep")
    (tmp_path / "figs").mkdir()
    figure = tmp_path / "figs" / FIGURE_OF[command]
    {"symlink": lambda: os.symlink(other, figure), "hard link": lambda: os.link(other, figure),
     "fifo": lambda: os.mkfifo(figure)}[kind]()
    result = invoke(COMMAND[command] + SMALL_REPORT + ["--db", "r.sqlite", "--figures", "figs"])
    line = one_line_error(result)
    assert "--figures" in line and FIGURE_OF[command] in line, line
    assert other.read_text() == "keep"
    assert not (tmp_path / "r.sqlite").exists()


def test_an_output_that_is_the_pipe_of_an_input_is_refused(tmp_path):
    """Writing into the FIFO an input is read from would hand the output back to the reader (or
    block): refused; another FIFO as output is written in place as before."""
    fifo, other = tmp_path / "in.fifo", tmp_path / "out.fifo"
    os.mkfifo(fifo)
    os.mkfifo(other)
    with pytest.raises(files.BadFile, match="--output: .*in.fifo is the pipe the input of --motion is read from"):
        files.check_distinct({"--output": fifo}, {"--motion": fifo})
    files.check_distinct({"--output": other}, {"--motion": fifo})


def test_a_name_that_is_not_utf8_is_written_back_as_its_bytes(tmp_path):
    """A file name read from the file system with bytes that are not UTF-8 (kept as surrogates)
    goes into an output as those bytes, as the shell's '>' would write it."""
    name = os.fsdecode(b"bad\xff.csv")
    files.write_atomic(tmp_path / "out.txt", f"motion {name}\n")
    assert (tmp_path / "out.txt").read_bytes() == b"motion bad\xff.csv\n"


def test_figures_as_a_link_to_a_missing_folder_is_refused_before_work(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    os.symlink("not-yet", tmp_path / "figs")
    line = one_line_error(invoke(COMMAND["report"] + SMALL_REPORT + ["--db", "r.sqlite", "--figures", "figs"]))
    assert "--figures" in line and "not-yet" in line, line
    assert not (tmp_path / "r.sqlite").exists()


# ---- check, then work, then write ----------------------------------------------------------------


def _dropping_runs_table(monkeypatch, db: Path):
    """The database loses its runs table while the run is under way."""
    import fdbench.method_runs as runs

    original = runs.run

    def run(spec, *args, **kwargs):
        outcome = original(spec, *args, **kwargs)
        con = sqlite3.connect(db)
        con.execute("DROP TABLE runs")
        con.commit()
        con.close()
        return outcome

    monkeypatch.setattr(runs, "run", run)


@pytest.mark.parametrize("command", [
    ["control", "--save-trajectory", "traj.csv", "-o", "out.json"],
    ["optimize", "--budget", "2", "--save-trajectory", "traj.csv", "--save-params", "p.json",
     "--save-convergence", "conv.csv", "-o", "out.json"],
])
def test_no_output_is_written_when_the_database_refuses_the_run(tmp_path, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    with open_store(tmp_path / "r.sqlite"):
        pass
    _dropping_runs_table(monkeypatch, tmp_path / "r.sqlite")
    line = one_line_error(invoke(command + ["--db", "r.sqlite", "-q", "-f", "json"]))
    assert "--db" in line and "runs" in line, line
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith("r.sqlite")) == []


def test_refused_backend_creates_no_database(tmp_path, monkeypatch):
    from fdbench import execution

    def unreachable(self, n_runs):
        raise execution.BackendError("--scheduler tcp://192.0.2.1:8786: cannot connect to the Dask scheduler")

    monkeypatch.setattr(execution.DaskBackend, "start", unreachable)
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("FDBENCH_DB", raising=False)
    for db in ([], ["--db", "new.sqlite"]):
        result = invoke(COMMAND["report"] + SMALL_REPORT + ["--backend", "dask"] + db)
        assert "cannot connect" in one_line_error(result)
    assert list(tmp_path.iterdir()) == []


def test_write_error_after_the_work_is_one_line_and_keeps_the_stored_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)

    def disk_full(*args):
        raise OSError(28, "No space left on device")

    # the output's own write fails (not os.replace for everyone: numba saves a kernel it compiles with it)
    monkeypatch.setattr(files, "_replace", disk_full)
    line = one_line_error(invoke(["control", "--db", "r.sqlite", "-o", "out.json", "-q"]))
    assert "--output" in line and "No space left" in line, line
    with open_store(tmp_path / "r.sqlite") as store:
        assert store.count() == 1


# ---- outputs that cannot be written, found before the work --------------------------------------


def test_socket_as_output_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    server = socket.socket(socket.AF_UNIX)
    server.bind("sock")
    try:
        line = one_line_error(invoke(["inverse", "-o", "sock"]))
    finally:
        server.close()
    assert "--output" in line and "socket" in line, line


def _chattr(flag: str, path: Path) -> bool:
    try:
        return subprocess.run(["chattr", flag, str(path)], capture_output=True, timeout=30).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


@pytest.mark.parametrize("flag", ["+a", "+i"])
def test_append_only_or_immutable_output_is_refused_before_work(tmp_path, monkeypatch, flag):
    monkeypatch.chdir(tmp_path)
    target = tmp_path / "kept.json"
    target.write_text("old\n")
    if not _chattr(flag, target):
        pytest.skip(f"chattr {flag} does not work here (needs root and a file system with attributes)")
    try:
        line = one_line_error(invoke(["control", "--db", "r.sqlite", "-o", "kept.json", "-q"]))
        assert "--output" in line and "append-only or immutable" in line, line
        assert target.read_text() == "old\n"
        assert not (tmp_path / "r.sqlite").exists()
    finally:
        _chattr(flag.replace("+", "-"), target)


def test_output_in_an_append_only_folder_is_written_leaving_no_temporary_file(tmp_path):
    folder = tmp_path / "log"
    folder.mkdir()
    (folder / "old.txt").write_text("old")
    if not _chattr("+a", folder):
        pytest.skip("chattr +a does not work here (needs root and a file system with attributes)")
    try:
        files.write_atomic(folder / "new.txt", "new")  # names can be added: as '>' does
        files.write_atomic(folder / "old.txt", "rewritten")  # but not renamed over: written in place
    finally:
        _chattr("-a", folder)
    assert (folder / "new.txt").read_text() == "new" and (folder / "old.txt").read_text() == "rewritten"
    assert temporaries(folder) == []


# ---- --db naming an input ------------------------------------------------------------------------


@pytest.mark.parametrize("command", [
    ["control"], ["collocate"], ["optimize", "--budget", "2"], COMMAND["report"] + SMALL_REPORT,
    COMMAND["study"] + SMALL_REPORT,
])
def test_db_naming_the_model_file_is_refused(tmp_path, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "model.toml").write_text("")  # empty: a file that could become a database
    os.symlink("model.toml", tmp_path / "link.sqlite")
    for db in ("model.toml", "link.sqlite"):
        line = one_line_error(invoke(command + ["--model-file", "model.toml", "--db", db, "-q"]))
        assert "--db" in line and "--model-file" in line, line
    assert (tmp_path / "model.toml").read_bytes() == b""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.sqlite", "model.toml"]


# ---- the atomic writer's temporary files ---------------------------------------------------------


def test_ctrl_c_during_a_write_waits_for_it_and_leaves_no_temporary_file(tmp_path, monkeypatch):
    target = tmp_path / "out.txt"
    target.write_text("old")
    chmod = os.chmod

    def interrupted_chmod(path, mode):
        os.kill(os.getpid(), signal.SIGINT)
        chmod(path, mode)

    monkeypatch.setattr(files.os, "chmod", interrupted_chmod)
    with pytest.raises(KeyboardInterrupt):
        files.write_atomic(target, "new")
    assert target.read_text() == "new"
    assert temporaries(tmp_path) == []


def test_sigterm_during_a_write_leaves_no_temporary_file(tmp_path):
    script = (
        "import os, signal, sys\n"
        "from fdbench import files\n"
        "chmod = os.chmod\n"
        "def terminated_chmod(path, mode):\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    chmod(path, mode)\n"
        "files.os.chmod = terminated_chmod\n"
        "files.write_atomic(sys.argv[1], 'new')\n"
        "print('not reached')\n"
    )
    target = tmp_path / "out.txt"
    target.write_text("old")
    out = subprocess.run([sys.executable, "-c", script, str(target)], capture_output=True, text=True, timeout=120)
    assert out.returncode == -signal.SIGTERM, out.stderr
    assert "not reached" not in out.stdout
    assert target.read_text() == "new"
    assert temporaries(tmp_path) == []


def test_failed_write_removes_its_temporary_file(tmp_path, monkeypatch):
    target = tmp_path / "out.txt"
    target.write_text("old")

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(files.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        files.write_atomic(target, "new")
    assert target.read_text() == "old"
    assert temporaries(tmp_path) == []


def test_next_write_removes_stale_temporary_files_of_its_own_only(tmp_path):
    old = time.time() - files.STALE_TEMPORARY_S - 60
    stale = tmp_path / ".fdbench-abc_1234.tmp"
    fresh = tmp_path / ".fdbench-fresh123.tmp"
    not_ours = [tmp_path / ".fdbench-abc_1234.txt", tmp_path / "fdbench-abc_1234.tmp", tmp_path / ".fdbench-toolongname.tmp"]
    for path in [stale, fresh, *not_ours]:
        path.write_text("x")
    (tmp_path / "precious").write_text("keep")
    link = tmp_path / ".fdbench-link1234.tmp"
    os.symlink("precious", link)
    for path in [stale, *not_ours, tmp_path / "precious"]:
        os.utime(path, (old, old))
    os.utime(link, (old, old), follow_symlinks=False)
    others = tmp_path / ".fdbench-others12.tmp"
    others.write_text("x")
    os.utime(others, (old, old))
    other_user = IS_ROOT
    if other_user:
        os.chown(others, 65534, 65534)
    files.write_atomic(tmp_path / "out.txt", "new")
    left = set(p.name for p in tmp_path.iterdir())
    assert stale.name not in left
    assert {fresh.name, link.name, "precious", "out.txt", *(p.name for p in not_ours)} <= left
    assert (others.name in left) == other_user
    assert (tmp_path / "precious").read_text() == "keep"


# ---- the kernel cache folder ---------------------------------------------------------------------


@pytest.fixture
def no_preferred_cache(tmp_path, monkeypatch):
    """The preferred cache folder cannot be made (it would be below a file): the fallback in the
    temporary folder, here tmp_path/tmp, is tried."""
    from fdbench import jit

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv(jit.CACHE_VARIABLE, str(blocker / "cache"))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(jit.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    return tmp_path / "tmp" / f"fdbench-cache-{os.getuid()}"


def test_cache_fallback_is_created_private(no_preferred_cache, capsys):
    from fdbench import jit

    assert jit._choose_cache_dir() == no_preferred_cache
    assert stat.S_IMODE(os.lstat(no_preferred_cache).st_mode) == 0o700
    err = capsys.readouterr().err  # names the folder it cannot use, why, and the one it uses
    assert "warning: cannot use the kernel cache:" in err and "a_file" in err and f"using {no_preferred_cache}" in err


def test_cache_fallback_made_writable_by_others_is_not_used(no_preferred_cache, capsys):
    from fdbench import jit

    no_preferred_cache.mkdir()
    no_preferred_cache.chmod(0o777)
    assert jit._choose_cache_dir() is None
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "writable by other users" in err and "compiled on every run" in err


def test_cache_fallback_that_is_a_symlink_is_not_used(no_preferred_cache, tmp_path, capsys):
    from fdbench import jit

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir(mode=0o700)
    os.symlink(elsewhere, no_preferred_cache)
    assert jit._choose_cache_dir() is None
    assert "symbolic link" in capsys.readouterr().err
    assert list(elsewhere.iterdir()) == []


@pytest.mark.skipif(not IS_ROOT, reason="giving a folder to another user needs root")
def test_cache_fallback_owned_by_another_user_is_not_used(no_preferred_cache, capsys):
    from fdbench import jit

    no_preferred_cache.mkdir(mode=0o700)
    os.chown(no_preferred_cache, 65534, 65534)
    assert jit._choose_cache_dir() is None
    assert "another user" in capsys.readouterr().err


@pytest.mark.parametrize("problem", ["writable by other users", "another user"])
def test_preferred_cache_folder_that_others_control_is_not_used(tmp_path, monkeypatch, capsys, problem):
    from fdbench import jit

    preferred = tmp_path / "cache"
    preferred.mkdir(mode=0o700)
    if problem == "another user":
        if not IS_ROOT:
            pytest.skip("giving a folder to another user needs root")
        os.chown(preferred, 65534, 65534)
    else:
        preferred.chmod(0o777)
    monkeypatch.setenv(jit.CACHE_VARIABLE, str(preferred))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(jit.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    assert jit._choose_cache_dir() == tmp_path / "tmp" / f"fdbench-cache-{os.getuid()}"
    assert problem in capsys.readouterr().err


def test_the_kernel_cache_folder_follows_the_sources(tmp_path):
    """numba would load a kernel whose inlined callee changed from its stale cache: each version of
    fdbench's sources has its own kernel folder, and a changed source gives another."""
    import shutil

    import numba

    from fdbench import jit

    package = tmp_path / "fdbench"
    shutil.copytree(Path(jit.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    before = jit.source_digest(package)
    assert jit.source_digest(package) == before and len(before) == 16
    kernels = package / "multibody" / "kernels.py"
    kernels.write_text(kernels.read_text() + "\n# changed\n")
    jit.source_digest.cache_clear()
    assert jit.source_digest(package) != before
    jit.njit(lambda x: x)
    assert numba.config.CACHE_DIR.endswith(jit.source_digest())
