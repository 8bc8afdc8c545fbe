"""fdbench under bad input, collisions and interruption: it never clobbers what the user did not
name as output, never hangs on a valid-looking value, and ends quietly when its reader goes away.

The adversarial matrix runs every case in a folder of prepared files and checks, besides exit
code 2 and one line on stderr, that no file there changed in content, mode, identity or kind,
and that no file appeared.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
import stat
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fdbench import files
from fdbench.cli import app
from fdbench.spec import control_spec
from fdbench.store import Store, StoreError, open_store

from helpers.processes import python_path

runner = CliRunner()
PREFIX = "fdbench: error:"
FDBENCH = [sys.executable, "-m", "fdbench.cli"]
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


def invoke(args, env=None):
    return runner.invoke(app, [str(a) for a in args], env=env)


def assert_one_line_error(result, code=2):
    assert "Traceback" not in result.stderr, result.stderr
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == code, f"exit {result.exit_code}: {result.stderr!r} {result.stdout[:200]!r}"
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(PREFIX), result.stderr
    return lines[0]


# ---- the prepared folder ---------------------------------------------------------------------

TORQUE_CSV = "t,torque\n0,4.26\n0.5,2\n1,0\n"


def _params_json(**changes) -> str:
    data = {"torque": "cs", "torque_options": {"knots": 11}, "feedforward": False, "kinematics": "paper",
            "params": [4.0] * 11}
    data.update(changes)
    return json.dumps(data)


def _fdbench_db(path: Path, runs: int = 1) -> None:
    with open_store(path) as store:
        for i in range(runs):
            store.add_record(control_spec(float(i), 0.3), {"note": "x" * 400}, [1.0] * 20)
    db = sqlite3.connect(path)
    db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    db.execute("PRAGMA journal_mode = DELETE")
    db.close()


def prepare(folder: Path) -> None:
    (folder / "in.csv").write_text(TORQUE_CSV)
    (folder / "params.json").write_text(_params_json())
    (folder / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (folder / "wrongtype.json").write_text(_params_json(torque=["cs"]))
    (folder / "notobject.json").write_text("[1, 2, 3]")
    (folder / "boolparams.json").write_text(_params_json(params=[True] * 11))
    (folder / "options_list.json").write_text(_params_json(torque_options=[["knots", 11]]))
    (folder / "binary.csv").write_bytes(b"t,torque\n\xff\xfe\x00\x01\n")
    (folder / "ro.txt").write_text("protected\n")
    (folder / "ro.txt").chmod(0o444)
    (folder / "report.md").write_text("# an earlier report\n")
    (folder / "afile").write_text("not a folder\n")
    (folder / "adir").mkdir()
    _fdbench_db(folder / "db.sqlite")
    _fdbench_db(folder / "ro.sqlite")
    (folder / "ro.sqlite").chmod(0o444)
    _fdbench_db(folder / "corrupt.sqlite", runs=60)
    with open(folder / "corrupt.sqlite", "r+b") as handle:
        handle.seek(4096 * 3)
        handle.write(bytes(range(256)) * 32)
    foreign = sqlite3.connect(folder / "foreign.sqlite")
    foreign.execute("CREATE TABLE patients (name TEXT)")
    foreign.commit()
    foreign.close()
    (folder / "garbage.sqlite").write_text("just text\n" * 10)
    app_db = sqlite3.connect(folder / "app_id.sqlite")  # another program's database, no table yet
    app_db.execute("PRAGMA application_id = 1234567")
    app_db.commit()
    app_db.close()
    view_db = sqlite3.connect(folder / "view.sqlite")
    view_db.execute("CREATE VIEW v AS SELECT 1")
    view_db.commit()
    view_db.close()
    (folder / "empty.toml").write_text("")  # a model file that could become a database
    os.symlink("empty.toml", folder / "link_to_empty.toml")
    os.symlink("loop", folder / "loop")
    os.symlink("in.csv", folder / "link_to_in.csv")
    os.link(folder / "in.csv", folder / "hard_in.csv")
    os.symlink("db.sqlite", folder / "link_to_db")
    os.link(folder / "db.sqlite", folder / "hard_db")
    (folder / "figs_ro").mkdir()
    (folder / "figs_ro" / "figure5_tracking.png").write_bytes(b"png")
    (folder / "figs_ro" / "figure5_tracking.png").chmod(0o444)
    (folder / "figs_dir").mkdir()
    (folder / "figs_dir" / "figure2_inverse_dynamics.png").mkdir()
    (folder / "figs_db").mkdir()
    os.symlink("../db.sqlite", folder / "figs_db" / "convergence_table2.png")
    (folder / "plugins").mkdir()
    (folder / "plugins" / "exits_at_import.py").write_text("import sys\nsys.exit(3)\n")
    (folder / "plugins" / "raises_at_import.py").write_text("raise RuntimeError('broken plugin')\n")


def snapshot(folder: Path) -> dict:
    """Every path below folder: its kind, mode, inode, link target and content digest."""
    state = {}
    for path in sorted(folder.rglob("*")):
        st = os.lstat(path)
        entry = (stat.S_IFMT(st.st_mode), stat.S_IMODE(st.st_mode), st.st_ino)
        if path.is_symlink():
            entry += (os.readlink(path),)
        elif stat.S_ISREG(st.st_mode):
            entry += (hashlib.sha256(path.read_bytes()).hexdigest(),)
        state[str(path.relative_to(folder))] = entry
    return state


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    folder = tmp_path_factory.mktemp("adversarial")
    prepare(folder)
    return folder


SMALL = ["--seeds", "1", "--budget", "2", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--no-control"]

# (arguments, extra environment, words the error must contain)
MATRIX = [
    # inverse
    (["inverse", "-o", "adir"], {}, ["directory"]),
    (["inverse", "-o", "ro.txt"], {}, ["read-only"]),
    (["inverse", "-o", "missing/x.csv"], {}, ["does not exist"]),
    (["inverse", "-o", ""], {}, ["empty"]),
    (["inverse", "-f", "xml"], {}, ["--format"]),
    (["inverse", "-o", "loop"], {}, ["--output", "cannot inspect"]),
    (["inverse", "-f", "csv", "-o", "afile/x.csv"], {}, ["afile"]),
    # simulate: outputs against inputs
    (["simulate", "--torque-file", "in.csv", "-o", "in.csv"], {}, ["--torque-file"]),
    (["simulate", "--torque-file", "in.csv", "--save-history", "in.csv"], {}, ["--torque-file"]),
    (["simulate", "--torque-file", "in.csv", "-o", "link_to_in.csv"], {}, ["--torque-file"]),
    (["simulate", "--torque-file", "in.csv", "-o", "hard_in.csv"], {}, ["--torque-file"]),
    (["simulate", "--torque-file", "./adir/../in.csv", "-o", "in.csv"], {}, ["--torque-file"]),
    (["simulate", "--params", "params.json", "-o", "params.json"], {}, ["--params"]),
    (["simulate", "--params", "params.json", "--save-history", "params.json"], {}, ["--params"]),
    (["simulate", "-o", "out.csv", "--save-history", "out.csv"], {}, ["same file"]),
    (["simulate", "--torque-file", "in.csv", "--params", "params.json"], {}, ["not both"]),
    # simulate: inputs that are not what they claim
    (["simulate", "--torque-file", "/dev/zero"], {}, ["larger than"]),
    (["simulate", "--params", "/dev/zero"], {}, ["larger than"]),
    (["simulate", "--params", "deep.json"], {}, ["nested"]),
    (["simulate", "--params", "wrongtype.json"], {}, ["torque"]),
    (["simulate", "--params", "notobject.json"], {}, ["object"]),
    (["simulate", "--params", "boolparams.json"], {}, ["params"]),
    (["simulate", "--params", "options_list.json"], {}, ["torque_options"]),
    (["simulate", "--torque-file", "adir"], {}, ["directory"]),
    (["simulate", "--torque-file", "binary.csv"], {}, ["UTF-8"]),
    (["simulate", "--torque-file", "nothere.csv"], {}, ["does not exist"]),
    # simulate: tolerances scipy cannot use
    (["simulate", "--integrator", "lsoda", "--atol", "1e-170"], {}, ["--atol"]),
    (["simulate", "--integrator", "rk45", "--atol", "10"], {}, ["--atol"]),
    (["simulate", "--integrator", "rk45", "--rtol", "0"], {}, ["--rtol"]),
    (["simulate", "--integrator", "radau", "--rtol", "nan"], {}, ["--rtol"]),
    # control: the database
    (["control", "--db", ":memory:"], {}, ["--db"]),
    (["control", "--db", ""], {}, ["--db"]),
    (["control", "--db", "db.sqlite", "-o", "db.sqlite"], {}, ["database"]),
    (["control", "--db", "db.sqlite", "--save-history", "db.sqlite"], {}, ["database"]),
    (["control", "--db", "db.sqlite", "-o", "db.sqlite-wal"], {}, ["database"]),
    (["control", "--db", "db.sqlite", "-o", "db.sqlite-journal"], {}, ["database"]),
    (["control", "--db", "db.sqlite", "-o", "link_to_db"], {}, ["database"]),
    (["control", "--db", "db.sqlite", "-o", "hard_db"], {}, ["database"]),
    (["control", "--db", "ro.sqlite"], {}, ["read-only"]),
    (["control", "--db", "foreign.sqlite"], {}, ["something else"]),
    (["control", "--db", "garbage.sqlite"], {}, ["not"]),
    (["control", "--db", "app_id.sqlite"], {}, ["something else", "no tables"]),
    (["control", "--db", "view.sqlite"], {}, ["something else", "views: v"]),
    (["control", "--model-file", "empty.toml", "--db", "empty.toml"], {}, ["--db", "--model-file"]),
    (["optimize", "--model-file", "empty.toml", "--db", "link_to_empty.toml"], {}, ["--db", "--model-file"]),
    (["collocate", "--model-file", "empty.toml", "--db", "empty.toml"], {}, ["--db", "--model-file"]),
    (["report", "--model-file", "link_to_empty.toml", "--db", "empty.toml"], {}, ["--db", "--model-file"]),
    (["study", "noise", "--levels", "0", "--model-file", "empty.toml", "--db", "empty.toml"], {},
     ["--db", "--model-file"]),
    (["control", "--db", "corrupt.sqlite"], {}, ["damaged"]),
    (["control", "--db", "adir"], {}, ["directory"]),
    (["control", "--db", "/dev/null"], {}, ["regular file"]),
    (["control", "--db", "missing/x.sqlite"], {}, ["does not exist"]),
    (["control", "--kp", "nan"], {}, ["--kp"]),
    (["control", "--kp", "-1"], {}, ["--kp"]),
    (["control", "--kd", "inf"], {}, ["--kd"]),
    (["control", "-o", "ro.txt"], {}, ["read-only"]),
    # optimize
    (["optimize", "--popsize", "100000000"], {}, ["--popsize"]),
    (["optimize", "--popsize", "1"], {}, ["--popsize"]),
    (["optimize", "--budget", "0"], {}, ["--budget"]),
    (["optimize", "--budget", "10000000"], {}, ["--budget"]),
    (["optimize", "--seed", "-1"], {}, ["--seed"]),
    (["optimize", "--history", "h.csv", "--save-params", "h.csv"], {}, ["same file"]),
    (["optimize", "-o", "p.json", "--save-params", "p.json"], {}, ["same file"]),
    (["optimize", "--db", "db.sqlite", "--save-params", "db.sqlite"], {}, ["database"]),
    (["optimize", "--db", "db.sqlite", "--history", "db.sqlite"], {}, ["database"]),
    (["optimize", "--db", "db.sqlite", "--save-params", "hard_db"], {}, ["database"]),
    (["optimize", "--terms", "101"], {}, ["--terms"]),
    (["optimize", "--knots", "3"], {}, ["--knots"]),
    (["optimize", "--hidden", "0"], {}, ["--hidden"]),
    (["optimize", "--sigma0", "-1"], {}, ["--sigma0"]),
    (["optimize", "--penalty-weight", "nan"], {}, ["--penalty-weight"]),
    (["optimize", "--db", ":memory:"], {}, ["--db"]),
    (["optimize", "--db", "corrupt.sqlite"], {}, ["damaged"]),
    # report
    (["report", "--db", "db.sqlite", "-o", "db.sqlite"], {}, ["database"]),
    (["report", "-o", "fdbench-results.sqlite"], {}, ["database"]),
    (["report", "-o", "db.sqlite"], {"FDBENCH_DB": "db.sqlite"}, ["database"]),
    (["report", "--db", "db.sqlite", "-o", "link_to_db"], {}, ["database"]),
    (["report", "--seeds", "100000000"], {}, ["--seeds"]),
    (["report", "--seeds", "0"], {}, ["--seeds"]),
    (["report", "--jobs", "0"], {}, ["--jobs"]),
    (["report", "--jobs", "100000"], {}, ["--jobs"]),
    (["report", "--db", "db.sqlite", "--figures", "report.md", "-o", "report.md"], {}, ["--figures"]),
    (["report", "--db", "db.sqlite", "--figures", "new.md", "-o", "new.md"], {}, ["--figures"]),
    (["report", "--db", "db.sqlite", "--figures", "afile"], {}, ["not a directory"]),
    (["report", "--db", "db.sqlite", "--figures", "missing/figs"], {}, ["does not exist"]),
    (["report", "--db", "db.sqlite", "--figures", "figs_ro"], {}, ["read-only"]),
    (["report", "--db", "db.sqlite", "--figures", "figs_dir"], {}, ["directory"]),
    (["report", "--db", "db.sqlite", "--figures", "figs_db"], {}, ["database"]),
    (["report", "--db", "db.sqlite", "--figures", "adir", "-o", "adir/figure5_tracking.png"], {}, ["same file"]),
    (["report", "--db", "db.sqlite", "--figures", "db.sqlite-wal"] + SMALL, {}, ["--figures", "database"]),
    (["report", "--db", "db.sqlite", "--figures", "db.sqlite-journal"] + SMALL, {}, ["--figures", "database"]),
    (["study", "noise", "--levels", "0", "--db", "db.sqlite", "--figures", "db.sqlite-shm"] + SMALL, {},
     ["--figures", "database"]),
    (["report", "--db", "view.sqlite"], {}, ["something else"]),
    (["report", "--db", "ro.sqlite"], {}, ["read-only"]),
    (["report", "--db", "garbage.sqlite"], {}, ["not"]),
    (["report", "--db", "corrupt.sqlite"], {}, ["damaged"]),
    (["report", "--db", ":memory:"], {}, ["--db"]),
    # collocate, study, motion and model files
    (["collocate", "--nodes", "1"], {}, ["--nodes"]),
    (["collocate", "--db", "db.sqlite", "--save-torque", "db.sqlite"], {}, ["database"]),
    (["collocate", "--motion", "in.csv", "--save-torque", "in.csv"], {}, ["--motion"]),
    (["study", "noise", "--levels", "0,1", "--db", "db.sqlite", "-o", "db.sqlite"], {}, ["database"]),
    (["study", "noise", "--levels", "0,1", "--db", "db.sqlite", "--figures", "afile"], {}, ["not a directory"]),
    (["study", "mismatch", "--levels", "0,1", "--db", "corrupt.sqlite"], {}, ["damaged"]),
    (["control", "--motion", "binary.csv"], {}, ["UTF-8"]),
    (["control", "--model-file", "/dev/zero"], {}, ["larger than"]),
    (["control", "--model-file", "params.json", "-o", "params.json"], {}, ["--model-file"]),
    (["inverse", "--motion", "params.json"], {}, ["columns"]),
    (["optimize", "--motion", "in.csv", "--save-params", "link_to_in.csv"], {}, ["--motion"]),
    # plugins
    (["optimize", "--budget", "2"], {"FDBENCH_PLUGINS": "exits_at_import"}, ["sys.exit(3)"]),
    (["methods"], {"FDBENCH_PLUGINS": "raises_at_import"}, ["broken plugin"]),
]


@pytest.mark.parametrize("args, env, words", MATRIX, ids=[" ".join(map(str, c[0]))[:60] for c in MATRIX])
def test_adversarial_case_is_refused_and_changes_nothing(prepared, monkeypatch, args, env, words):
    monkeypatch.chdir(prepared)
    monkeypatch.delenv("FDBENCH_DB", raising=False)
    if "FDBENCH_PLUGINS" in env:
        import fdbench.registry as registry

        monkeypatch.setattr(registry, "_plugins_loaded", False)
        monkeypatch.syspath_prepend(str(prepared / "plugins"))
        _reload_registries(monkeypatch)
    before = snapshot(prepared)
    result = invoke(args, env=env)
    line = assert_one_line_error(result)
    for word in words:
        assert word in line, line
    assert snapshot(prepared) == before


def _reload_registries(monkeypatch):
    """Plugins load when the registries' packages are imported: import them afresh."""
    for name in [m for m in sys.modules if m.startswith(("fdbench.torques", "fdbench.optimizers"))]:
        monkeypatch.delitem(sys.modules, name)


def test_the_matrix_is_large():
    assert len(MATRIX) >= 60


# ---- writing outputs as the shell's '>' does -------------------------------------------------


def test_regular_file_is_replaced_keeping_its_mode(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    target.chmod(0o640)
    files.write_atomic(target, "new")
    assert target.read_text() == "new"
    assert stat.S_IMODE(target.stat().st_mode) == 0o640


def test_new_file_gets_the_umask_mode(tmp_path):
    mask = os.umask(0o027)
    try:
        files.write_atomic(tmp_path / "new.txt", "x")
    finally:
        os.umask(mask)
    assert stat.S_IMODE((tmp_path / "new.txt").stat().st_mode) == 0o640


def test_symlink_is_written_through(tmp_path):
    (tmp_path / "real.txt").write_text("old")
    (tmp_path / "link.txt").symlink_to("real.txt")
    files.write_atomic(tmp_path / "link.txt", "new")
    assert (tmp_path / "link.txt").is_symlink()
    assert (tmp_path / "real.txt").read_text() == "new"


def test_dangling_symlink_creates_its_target(tmp_path):
    (tmp_path / "link.txt").symlink_to("made.txt")
    files.write_atomic(tmp_path / "link.txt", "new")
    assert (tmp_path / "link.txt").is_symlink() and (tmp_path / "made.txt").read_text() == "new"


def test_hard_link_is_kept(tmp_path):
    (tmp_path / "a.txt").write_text("old")
    os.link(tmp_path / "a.txt", tmp_path / "b.txt")
    files.write_atomic(tmp_path / "a.txt", "new")
    assert (tmp_path / "b.txt").read_text() == "new"
    assert os.path.samefile(tmp_path / "a.txt", tmp_path / "b.txt")


def test_read_only_file_is_refused_even_for_root(tmp_path):
    target = tmp_path / "ro.txt"
    target.write_text("keep")
    target.chmod(0o444)
    with pytest.raises(files.BadFile, match="read-only"):
        files.write_atomic(target, "new")
    assert target.read_text() == "keep"


def test_longest_file_name_is_written(tmp_path):
    target = tmp_path / ("x" * 255)
    files.write_atomic(target, "content")
    assert target.read_text() == "content"
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]  # no temporary file left


def test_device_is_written_in_place():
    before = os.stat("/dev/null")
    files.write_atomic("/dev/null", "discarded")
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and after.st_ino == before.st_ino and after.st_rdev == before.st_rdev


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_fifo_is_written_in_place(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_text()))
    reader.start()
    files.write_atomic(fifo, "through the pipe")
    reader.join(timeout=120)
    assert received == ["through the pipe"]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "out.txt"
    target.write_text("old")

    def refuse(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(files.os, "replace", refuse)
    with pytest.raises(files.BadFile, match="--output: cannot write .* No space left on device"):
        files.write_atomic(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_cli_output_through_a_symlink_and_to_dev_null(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("real.csv").write_text("old")
    Path("link.csv").symlink_to("real.csv")
    result = invoke(["inverse", "-f", "csv", "-o", "link.csv", "-q"])
    assert result.exit_code == 0, result.stderr
    assert Path("link.csv").is_symlink() and Path("real.csv").read_text().startswith("t,theta")
    result = invoke(["inverse", "-f", "csv", "-o", "/dev/null", "-q"])
    assert result.exit_code == 0 and stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_output_to_dev_stdout_reaches_stdout(tmp_path):
    out = subprocess.run(FDBENCH + ["inverse", "-f", "json", "-o", "/dev/stdout", "-q"], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["command"] == "inverse"


def test_check_distinct_allows_two_outputs_to_a_device():
    files.check_distinct({"--output": "/dev/null", "--save-history": "/dev/null"})


# ---- inputs ----------------------------------------------------------------------------------


def test_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes("\ufefft,torque\n0,1\n1,2\n".encode())
    t, q = files.read_history_csv(path, "--torque-file", 1.0, ("torque",))
    assert list(t) == [0.0, 1.0] and list(q[:, 0]) == [1.0, 2.0]


def test_input_size_is_limited(tmp_path):
    path = tmp_path / "big.csv"
    path.write_text("t,torque\n" + "0.5,1\n" * 100)
    with pytest.raises(files.BadFile, match="larger than"):
        files.read_input_text(path, "--torque-file", limit=200)


def _simulate_hash(folder: Path, name: str, text: str) -> str:
    (folder / name).write_text(text)
    result = invoke(["simulate", "--torque-file", folder / name, "-f", "json", "-q"])
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)["spec_hash"]


def test_torque_file_enters_the_hash_by_content(tmp_path):
    a = _simulate_hash(tmp_path, "a.csv", "t,torque\n0,1\n1,1\n")
    b = _simulate_hash(tmp_path, "b.csv", "t,torque\n0,2\n1,2\n")
    same_numbers = _simulate_hash(tmp_path, "c.csv", "t , torque\n0.0,1.000\n1,1e0\n")
    assert a != b
    assert a == same_numbers  # the same history written differently is the same input


# ---- documented-valid values that must work -----------------------------------------------------


@pytest.mark.parametrize("terms", [68, 100])
def test_pf_fit_works_for_every_allowed_term_count(terms):
    """The fit of every allowed term count reproduces the forearm's closed-form inverse-dynamics torque."""
    from helpers.forearm_closed_form import torque_along as elbow_torque

    from fdbench.multibody.motions import eq5
    from fdbench.models import find_model
    from fdbench.multibody.engine import Engine
    from fdbench.multibody.motions import joint_motion
    from fdbench.problem import TrackingProblem

    model = find_model("forearm")
    problem = TrackingProblem("pf", Engine(model), joint_motion("paper", model), feedforward=False, terms=terms)
    t = problem.inverse.t
    fitted, target = problem.parts[0].evaluate(problem.p0, t), elbow_torque(*eq5(t, "paper"))
    assert np.sqrt(np.mean((fitted - target) ** 2)) < 0.01 * np.ptp(target)


def test_cmaes_with_population_two_and_many_parameters():
    from fdbench.optimizers import make_optimizer

    result = make_optimizer("cmaes", popsize=2).minimize(lambda x: float(np.sum((x - 1) ** 2)), np.zeros(300), 40, 0)
    assert result.evaluations == 40
    assert result.fun <= 300.0  # never worse than the start, the best point evaluated is kept


def test_extreme_torque_prints_no_numpy_warning(tmp_path):
    (tmp_path / "huge.csv").write_text("t,torque\n0,1e308\n1,-1e308\n")
    out = subprocess.run(FDBENCH + ["simulate", "--torque-file", "huge.csv", "-q", "-f", "json"], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0
    assert out.stderr == ""
    assert json.loads(out.stdout)["status"] in ("nonfinite", "singular")


# ---- the results store ---------------------------------------------------------------------


@pytest.mark.parametrize("journal", ["WAL", "DELETE"])
def test_locked_database_is_refused_before_work(tmp_path, monkeypatch, journal):
    import fdbench.store

    path = tmp_path / "db.sqlite"
    _fdbench_db(path)
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute(f"PRAGMA journal_mode = {journal}")
    holder.execute("BEGIN EXCLUSIVE")
    monkeypatch.setattr(fdbench.store, "OPEN_PATIENCE_S", 0.2)
    try:
        with pytest.raises(StoreError, match="locked"):
            with open_store(path) as store:
                store.check_usable(lock_patience_s=0.2)
    finally:
        holder.execute("ROLLBACK")
        holder.close()


def test_memory_database_is_refused():
    with pytest.raises(StoreError, match="file"):
        Store(":memory:")


# ---- closed pipes ----------------------------------------------------------------------------


def test_reader_that_goes_away_ends_quietly(tmp_path):
    out = subprocess.run(["bash", "-c", f"{' '.join(FDBENCH)} inverse -f csv | true; echo ${{PIPESTATUS[0]}}"],
                         capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.stdout.strip() in ("0", "141")
    assert out.stderr == ""


def test_closed_stdout_ends_quietly(tmp_path):
    out = subprocess.run(["bash", "-c", f"{' '.join(FDBENCH)} inverse -f json >&-; echo $?"],
                         capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.stdout.strip() in ("0", "141")
    assert out.stderr == ""


# ---- the kernel cache ------------------------------------------------------------------------


def test_cache_folder_falls_back_when_home_is_not_writable(tmp_path, monkeypatch, capsys):
    from fdbench import jit

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv(jit.CACHE_VARIABLE, str(blocker / "cache"))  # below a file: never writable
    monkeypatch.setattr(jit.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    chosen = jit._choose_cache_dir()
    assert chosen == tmp_path / "tmp" / f"fdbench-cache-{os.getuid()}"
    monkeypatch.setattr(jit.tempfile, "gettempdir", lambda: str(blocker))
    assert jit._choose_cache_dir() is None
    warnings = capsys.readouterr().err.splitlines()
    assert len(warnings) == 2 and all(w.startswith("fdbench: warning:") for w in warnings)


def test_unwritable_cache_folder_gives_one_warning_and_a_result(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    env = dict(os.environ, FDBENCH_CACHE_DIR=str(blocker / "cache"), TMPDIR=str(tmp_path))
    out = subprocess.run(FDBENCH + ["control", "-f", "json", "-q"], capture_output=True, text=True,
                         timeout=300, cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["status"] == "success"
    assert len(out.stderr.splitlines()) == 1 and "warning" in out.stderr


def test_kernels_are_cached_outside_the_package(tmp_path):
    import fdbench

    package = Path(fdbench.__file__).parent
    before = {p for p in package.rglob("*.nbi")}
    env = dict(os.environ, FDBENCH_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run(FDBENCH + ["control", "-q", "-f", "csv"], capture_output=True, text=True, timeout=300,
                         cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr
    assert list((tmp_path / "cache").rglob("*.nbi")), "no kernel cached in FDBENCH_CACHE_DIR"
    assert {p for p in package.rglob("*.nbi")} == before


@pytest.mark.skipif(not IS_ROOT or shutil.which("setpriv") is None, reason="needs root and setpriv")
def test_non_root_user_with_read_only_home(tmp_path):
    tmp_path.chmod(0o777)
    env = {k: v for k, v in os.environ.items() if k not in ("XDG_CACHE_HOME", "FDBENCH_CACHE_DIR")}
    env.update(HOME="/nonexistent", TMPDIR=str(tmp_path))
    out = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"] + FDBENCH
                         + ["control", "-q", "-f", "json"], capture_output=True, text=True, timeout=300,
                         cwd=tmp_path, env=env)
    if out.returncode != 0 and "Permission denied" in out.stderr and "python" in out.stderr.lower():
        pytest.skip("the test environment is not readable by another user")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["status"] == "success"
    assert len(out.stderr.splitlines()) <= 1


def test_dash_output_is_stdout(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = invoke(["inverse", "-f", "json", "-o", "-", "-q"])
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["command"] == "inverse"
    assert list(tmp_path.iterdir()) == []


def test_plugin_prints_do_not_reach_the_results(tmp_path):
    (tmp_path / "noisy.py").write_text("print('hello from a plugin')\n")
    env = dict(os.environ, PYTHONPATH=python_path(tmp_path), FDBENCH_PLUGINS="noisy")
    out = subprocess.run(FDBENCH + ["methods"], capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr
    assert "hello" not in out.stdout and "hello from a plugin" in out.stderr
