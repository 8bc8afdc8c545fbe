"""The results store (fdbench.store): schema, round trip, settings hash, one row per run,
several writer processes at once, refusal of files that are not fdbench databases (never
touching them), and the FDBENCH_DB default. Every database lives in tmp_path."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from fdbench.spec import OMITTED_AT_DEFAULT
from typer.testing import CliRunner

from fdbench import store as store_module
from fdbench.cli import app
from fdbench.spec import RunSpec, control_spec, optimize_spec
from fdbench.store import DEFAULT_DB, Store, StoreError, default_path, open_store

SQLITE_MAGIC = b"SQLite format 3\x00"  # the first 16 bytes of every SQLite 3 file (sqlite.org/fileformat.html)


def fake_record(spec: RunSpec, rmse: float = 1.5) -> dict:
    """A record as ``run`` would give it, without running anything."""
    return {
        "command": spec.command, "seed": spec.seed, "budget": spec.budget, "torque": spec.torque,
        "optimizer": spec.optimizer, "feedforward": spec.feedforward, "rmse_rot_deg": rmse,
        "rmse_torque_nm": 0.25, "runtime_s": 0.01, "t_end": 1.0, "status": "success",
        "best_objective": rmse, "initial_objective": 2.0 * rmse, "spec_hash": spec.hash(),
        "fdbench_version": "0.1.0", "message": "reached t = 1 s",
    }


def spec_for(seed: int, torque: str = "cs") -> RunSpec:
    return RunSpec(command="optimize", torque=torque, optimizer="bfgs", seed=seed, budget=10)


def tables_of(path: Path) -> set[str]:
    con = sqlite3.connect(path)
    try:
        return {row[0] for row in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    finally:
        con.close()


def same(a, b) -> bool:
    """Equality that treats NaN as equal to NaN (JSON round trips keep NaN)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


# ----------------------------------------------------------------------------- schema, round trip


def test_new_store_creates_runs_and_meta_tables(tmp_path):
    path = tmp_path / "new.sqlite"
    with open_store(path) as store:
        assert store.count() == 0
        assert store.hashes() == set()
        assert store.records() == []
    assert path.read_bytes()[:16] == SQLITE_MAGIC
    assert {"runs", "fdbench_meta"} <= tables_of(path)
    con = sqlite3.connect(path)
    columns = {row[1] for row in con.execute("PRAGMA table_info(runs)")}
    meta = dict(con.execute("SELECT key, value FROM fdbench_meta"))
    con.close()
    assert {"spec_hash", "seed", "record_json", "history_json", "params_json", "rmse_rot_deg",
            "rmse_torque_nm", "runtime_s", "created_at", "fdbench_version", "machine"} <= columns
    assert meta["schema"] == "fdbench-results"
    # reopening an existing fdbench database works and keeps it
    with open_store(path) as store:
        assert store.count() == 0


def test_real_run_is_read_back_with_same_record_history_and_params(tmp_path):
    from fdbench.api import run

    spec = optimize_spec("cs", "bfgs", False, seed=0, budget=6)
    outcome = run(spec)
    assert outcome.params is not None and len(outcome.history) > 0
    with open_store(tmp_path / "r.sqlite") as store:
        assert store.add(spec, outcome, jobs=3) is True
        assert store.count() == 1
        assert store.hashes() == {spec.hash()}
        got = store.get(spec.hash())
        assert store.get("0" * 16) is None
        records = store.records()
    expected = {k: v for k, v in outcome.record.items() if k != "command_time_s"}
    expected["jobs"] = 3
    assert set(got["record"]) == set(expected)
    for key, value in expected.items():
        assert same(got["record"][key], value), key
    assert got["history"] == [float(v) for v in outcome.history]
    assert got["params"] == [float(v) for v in outcome.params]
    assert records == [got["record"]]
    # the indexed columns hold the same numbers as the record
    con = sqlite3.connect(tmp_path / "r.sqlite")
    row = con.execute("SELECT spec_hash, command, seed, rmse_rot_deg, rmse_torque_nm, status, spec_json "
                      "FROM runs").fetchone()
    con.close()
    assert row[:6] == (spec.hash(), "optimize", 0, outcome.record["rmse_rot_deg"],
                       outcome.record["rmse_torque_nm"], outcome.record["status"])
    assert json.loads(row[6])["budget"] == 6 and json.loads(row[6])["torque"] == "cs"


def test_record_without_params_round_trips(tmp_path):
    spec = control_spec(80.0, 0.3)
    record = fake_record(spec)
    with open_store(tmp_path / "c.sqlite") as store:
        store.add_record(spec, record, [3.0, 2.0, 1.0])
        got = store.get(spec.hash())
    assert got["params"] is None
    assert got["history"] == [3.0, 2.0, 1.0]
    assert got["record"] == dict(record, jobs=1)


# ----------------------------------------------------------------------------- the settings hash


HASH_SCRIPT = """
from fdbench.spec import control_spec, optimize_spec
print(optimize_spec("ann", "cmaes", True, seed=3, budget=50, torque_options={"hidden": 4},
                    optimizer_options={"sigma0": 0.2}).hash())
print(control_spec(80.0, 0.3).hash())
"""


def test_hash_is_stable_within_and_across_processes():
    a = optimize_spec("ann", "cmaes", True, seed=3, budget=50, torque_options={"hidden": 4},
                      optimizer_options={"sigma0": 0.2})
    b = optimize_spec("ann", "cmaes", True, seed=3, budget=50, torque_options={"hidden": 4},
                      optimizer_options={"sigma0": 0.2})
    assert a is not b and a.hash() == b.hash() == a.hash()
    assert len(a.hash()) == 16 and int(a.hash(), 16) >= 0
    # a new interpreter, with another string-hash seed, computes the same digests
    env = dict(os.environ, PYTHONHASHSEED="12345")
    out = subprocess.run([sys.executable, "-c", HASH_SCRIPT], capture_output=True, text=True, env=env,
                         timeout=120, check=True).stdout.split()
    assert out == [a.hash(), control_spec(80.0, 0.3).hash()]


def _other_value(name, value):
    if name == "command":
        return "control" if value != "control" else "optimize"
    if isinstance(value, bool):
        return not value
    if isinstance(value, (int, float)) and value is not None:
        return value * 2 + 1
    if isinstance(value, str):
        return value + "x"
    if isinstance(value, tuple):
        return value + (("extra", 1),)
    return 7  # None -> a value


def test_hash_changes_with_every_setting_and_the_seed():
    rk4 = optimize_spec("cs", "bfgs", False, seed=0, budget=20)
    adaptive = dataclasses.replace(rk4, integrator="rk45")  # the tolerances apply to adaptive integrators only
    hashes = {rk4.hash(), adaptive.hash()}
    for field in dataclasses.fields(RunSpec):
        base = adaptive if field.name in ("rtol", "atol") else rk4
        changed = dataclasses.replace(base, **{field.name: _other_value(field.name, getattr(base, field.name))})
        assert changed != base
        assert changed.hash() != base.hash(), field.name
        hashes.add(changed.hash())
    assert len(hashes) == len(dataclasses.fields(RunSpec)) + 2
    # consecutive seeds, torque options and optimizer options, as the benchmark varies them
    seeds = {optimize_spec("cs", "bfgs", False, seed=s, budget=20).hash() for s in range(50)}
    assert len(seeds) == 50
    assert optimize_spec("cs", "bfgs", torque_options={"knots": 12}).hash() != optimize_spec("cs", "bfgs").hash()
    assert optimize_spec("cs", "cmaes", optimizer_options={"sigma0": 0.3}).hash() != \
        optimize_spec("cs", "cmaes").hash()
    assert optimize_spec("cs", "bfgs", True).hash() != optimize_spec("cs", "bfgs", False).hash()


def test_options_a_method_ignores_do_not_change_the_hash():
    # the report passes every torque option to every cell; an option the torque does not take
    # must not make the same run look different
    assert optimize_spec("cs", "bfgs", torque_options={"knots": 11, "hidden": 4, "terms": 4},
                         shared_options=True).hash() == optimize_spec("cs", "bfgs", torque_options={"knots": 11}).hash()


# ----------------------------------------------------------------------------- one row per run


def test_same_spec_twice_keeps_one_row_unless_replace(tmp_path):
    spec = spec_for(4)
    with open_store(tmp_path / "d.sqlite") as store:
        assert store.add_record(spec, fake_record(spec, 1.0), [1.0], [0.5]) is True
        assert store.add_record(spec, fake_record(spec, 9.0), [9.0], [0.9]) is False
        assert store.count() == 1
        assert store.get(spec.hash())["record"]["rmse_rot_deg"] == 1.0
        assert store.get(spec.hash())["params"] == [0.5]
        assert store.add_record(spec, fake_record(spec, 2.0), [2.0], [0.7], replace=True) is True
        assert store.count() == 1
        got = store.get(spec.hash())
        assert got["record"]["rmse_rot_deg"] == 2.0 and got["history"] == [2.0] and got["params"] == [0.7]
        other = spec_for(5)
        assert store.add_record(other, fake_record(other), [1.0]) is True
        assert store.count() == 2
    # a second connection (another process would be the same) sees the same rows
    with open_store(tmp_path / "d.sqlite") as store:
        assert store.count() == 2
        assert store.hashes() == {spec.hash(), other.hash()}


def test_a_replaced_run_keeps_its_id_and_numbers(tmp_path):
    """--rerun replaces a run without deleting it: the old row, id and record, stays readable."""
    spec = spec_for(4)
    with open_store(tmp_path / "d.sqlite") as store:
        first = store.put(spec, fake_record(spec, 1.0), [1.0], [0.5])
        second = store.put(spec, fake_record(spec, 2.0), [2.0], [0.7], replace=True)
        assert first is not None and second is not None and second != first
        assert store.count() == 1 and store.get(spec.hash())["record"]["rmse_rot_deg"] == 2.0
        kept = store.runs_by_id([first, second])
    assert kept[first]["record"]["rmse_rot_deg"] == 1.0 and kept[first]["params"] == [0.5]
    assert kept[second]["record"]["rmse_rot_deg"] == 2.0


SMALL_REPORT = ["report", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--no-control", "--no-beyond",
                "--seeds", "2", "--budget", "5", "--format", "json", "-q"]


def _stored_runtimes(db: Path) -> dict:
    """{row id: runtime_s} of every run the file holds, current or replaced by a rerun."""
    con = sqlite3.connect(db)
    try:
        tables = {row[0] for row in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        rows = []
        for table in {"runs", "superseded_runs"} & tables:
            rows += con.execute(f"SELECT id, runtime_s FROM {table}").fetchall()
    finally:
        con.close()
    return dict(rows)


def _cited(report: dict) -> list:
    """(run id, the cell's median runtime) of every run the report cites."""
    return [(run_id, cell["runtime_s_median"]) for cell in report["cells"] for run_id in cell["run_ids"]]


def test_ids_a_report_cites_stay_in_the_store_after_another_rerun(tmp_path):
    db = tmp_path / "cited.sqlite"
    first = CliRunner().invoke(app, [*SMALL_REPORT, "--db", str(db)])
    assert first.exit_code == 0, first.stderr
    second = CliRunner().invoke(app, [*SMALL_REPORT, "--db", str(db), "--rerun"])
    assert second.exit_code == 0, second.stderr
    cited = [i for text in (first.stdout, second.stdout) for i, _ in _cited(json.loads(text))]
    assert len(cited) == 4 and len(set(cited)) == 4  # the rerun made new rows
    assert set(cited) <= set(_stored_runtimes(db))


def test_a_report_cites_the_rows_it_ran_while_another_rerun_replaces_them(tmp_path, monkeypatch):
    """Another ``report --rerun`` on the same database replaces every run between this report's
    runs and its reading of their provenance (made deterministic by running it at that moment):
    the report still cites the rows whose numbers it shows, and they are still stored."""
    from fdbench import execution

    db = tmp_path / "raced.sqlite"
    execute = execution.execute_specs

    def with_a_rerun_meanwhile(specs, store, backend, rerun=False, on_done=None):
        runs = execute(specs, store, backend, rerun, on_done)
        with open_store(db) as other:
            execute(specs, other, execution.LocalBackend(jobs=1), rerun=True)
        return runs

    monkeypatch.setattr(execution, "execute_specs", with_a_rerun_meanwhile)
    done = CliRunner().invoke(app, [*SMALL_REPORT, "--seeds", "1", "--db", str(db)])
    assert done.exit_code == 0, done.stderr
    cited = _cited(json.loads(done.stdout))
    stored = _stored_runtimes(db)
    con = sqlite3.connect(db)
    current = {row[0] for row in con.execute("SELECT id FROM runs")}
    con.close()
    assert len(cited) == 1
    for run_id, runtime in cited:
        assert run_id not in current  # replaced by the other rerun...
        assert stored[run_id] == runtime  # ...and still stored, with the numbers the report shows


# ----------------------------------------------------------------------------- concurrent writers


WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from fdbench.store import Store

    path, worker, n, go, light = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[4]), sys.argv[5]
    if light == "1":  # the store only needs hash(), command, seed and as_dict(): start fast (no numpy)
        class Spec:
            command = "optimize"
            def __init__(self, seed):
                self.seed = seed
            def hash(self):
                return f"light-{self.seed}"
            def as_dict(self):
                return {"command": self.command, "seed": self.seed}
    else:
        from fdbench.spec import RunSpec
        Spec = lambda seed: RunSpec(command="optimize", torque="cs", optimizer="bfgs", seed=seed, budget=10)
    specs = [Spec(worker * 100000 + i) for i in range(n)]
    (go.parent / f"{go.name}.ready{worker}").touch()
    deadline = time.time() + 120  # a bound against a lost test process, not a timing
    while not go.exists() and time.time() < deadline:
        time.sleep(0.001)
    store = Store(path)  # every writer opens (and possibly creates) the file at the same moment
    written = 0
    for spec in specs:
        record = {"command": "optimize", "seed": spec.seed, "rmse_rot_deg": float(spec.seed),
                  "status": "success", "spec_hash": spec.hash()}
        written += store.add_record(spec, record, [float(spec.seed)], [float(worker)])
    store.close()
    print(written)
""")


def _run_writers(path: Path, go: Path, n_proc: int, n_runs: int, offset: int = 0, light: bool = False):
    procs = [subprocess.Popen([sys.executable, "-c", WRITER, str(path), str(offset + w), str(n_runs), str(go),
                               "1" if light else "0"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for w in range(n_proc)]
    deadline = time.time() + 120  # let every interpreter start and wait for the signal
    while time.time() < deadline and not all((go.parent / f"{go.name}.ready{offset + w}").exists()
                                              for w in range(n_proc)):
        time.sleep(0.01)
    go.touch()
    outputs = [p.communicate(timeout=300) for p in procs]
    return [(p.returncode, out, err) for p, (out, err) in zip(procs, outputs)]


def _check_all_there(path: Path, seeds_expected: list[int]) -> None:
    con = sqlite3.connect(path)
    total, distinct = con.execute("SELECT COUNT(*), COUNT(DISTINCT spec_hash) FROM runs").fetchone()
    seeds = sorted(row[0] for row in con.execute("SELECT seed FROM runs"))
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    meta = con.execute("SELECT COUNT(*) FROM fdbench_meta WHERE key = 'schema'").fetchone()[0]
    con.close()
    assert total == distinct == len(seeds_expected)
    assert seeds == sorted(seeds_expected)
    assert meta == 1


def test_concurrent_writer_processes_all_succeed(tmp_path):
    path = tmp_path / "shared.sqlite"
    with open_store(path):  # an existing database, as when several commands share one
        pass
    n_proc, n_runs = 4, 150
    results = _run_writers(path, tmp_path / "go", n_proc, n_runs)
    for code, out, err in results:
        assert code == 0, err
        assert out.strip() == str(n_runs), err
    _check_all_there(path, [w * 100000 + i for w in range(n_proc) for i in range(n_runs)])
    with open_store(path) as store:
        for w in range(n_proc):
            spec = RunSpec(command="optimize", torque="cs", optimizer="bfgs", seed=w * 100000 + 7, budget=10)
            assert store.get(spec.hash())["params"] == [float(w)]


def test_concurrent_writers_creating_a_fresh_database(tmp_path):
    # several rounds make the race likely; every process must succeed
    n_proc, rounds = 6, 10
    for r in range(rounds):
        path = tmp_path / f"fresh{r}.sqlite"
        results = _run_writers(path, tmp_path / f"go{r}", n_proc, 3, light=True)
        failures = [err.strip().splitlines()[-1] for code, _, err in results if code != 0]
        assert not failures, f"round {r}: {failures}"
        _check_all_there(path, [w * 100000 + i for w in range(n_proc) for i in range(3)])


# ----------------------------------------------------------------------------- foreign files


def _random_bytes(path: Path) -> None:
    data = os.urandom(8192)
    while data.startswith(SQLITE_MAGIC[:6]):  # vanishingly unlikely
        data = os.urandom(8192)
    path.write_bytes(data)


def _text(path: Path) -> None:
    path.write_text("run,rmse\n1,0.5\nthese are my precious notes, not a database\n")


def _foreign_sqlite(path: Path) -> None:
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE people (name TEXT, age INTEGER)")
    con.execute("INSERT INTO people VALUES ('Ada', 36)")
    con.commit()
    con.close()


def _sqlite_header_then_garbage(path: Path) -> None:
    path.write_bytes(SQLITE_MAGIC + os.urandom(8192))


def _other_schema_meta(path: Path) -> None:
    # another program that happens to use a table named fdbench_meta
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE fdbench_meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
    con.execute("INSERT INTO fdbench_meta VALUES ('schema', 'something-else')")
    con.commit()
    con.close()


def _future_version(path: Path) -> None:
    with open_store(path):
        pass
    con = sqlite3.connect(path)
    con.execute("UPDATE fdbench_meta SET value = '99' WHERE key = 'version'")
    con.commit()
    con.close()


def _empty_sqlite_of_another_program(path: Path) -> None:
    # a program's fresh database: its own application_id and user_version, no table yet
    con = sqlite3.connect(path)
    con.execute("PRAGMA application_id = 1234567")
    con.execute("PRAGMA user_version = 3")
    con.commit()
    con.close()


def _only_a_view(path: Path) -> None:
    con = sqlite3.connect(path)
    con.execute("CREATE VIEW answer AS SELECT 42 AS value")
    con.commit()
    con.close()


FOREIGN = {
    "empty-sqlite-of-another-program": (_empty_sqlite_of_another_program, "something else (no tables)"),
    "only-a-view": (_only_a_view, "views: answer"),
    "random-bytes": (_random_bytes, "not an fdbench results database"),
    "text": (_text, "not an fdbench results database"),
    "foreign-sqlite": (_foreign_sqlite, "people"),
    "sqlite-header-garbage": (_sqlite_header_then_garbage, "not an fdbench results database"),
    "other-meta": (_other_schema_meta, "not an fdbench results database"),
    "future-version": (_future_version, "version 99"),
}


def _snapshot(directory: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


@pytest.mark.parametrize("kind", list(FOREIGN))
def test_foreign_file_is_refused_and_left_untouched(tmp_path, kind):
    make, words = FOREIGN[kind]
    path = tmp_path / "results.sqlite"
    make(path)
    before = _snapshot(tmp_path)
    with pytest.raises(StoreError) as info:
        with open_store(path):
            pass  # pragma: no cover - must not be reached
    message = str(info.value)
    assert str(path) in message
    assert words in message
    assert "\n" not in message
    assert path.read_bytes() == before[path.name]
    if kind != "future-version":  # see test_refused_store_closes_its_connection for that one
        assert _snapshot(tmp_path) == before  # and no file created beside it


def test_refused_store_closes_its_connection(tmp_path):
    path = tmp_path / "results.sqlite"
    _future_version(path)
    before = _snapshot(tmp_path)
    with pytest.raises(StoreError) as info:
        Store(path)
    assert "version 99" in str(info.value)
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("kind", ["random-bytes", "text", "foreign-sqlite", "sqlite-header-garbage",
                                  "empty-sqlite-of-another-program", "only-a-view"])
def test_cli_report_refuses_foreign_db_with_one_line(tmp_path, kind):
    make, words = FOREIGN[kind]
    path = tmp_path / "results.sqlite"
    make(path)
    before = _snapshot(tmp_path)
    result = CliRunner().invoke(app, ["report", "--db", str(path), "--torque", "cs", "--opt", "bfgs",
                                      "--no-feedforward", "--seeds", "1", "--budget", "10", "--jobs", "1",
                                      "--format", "csv"])
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("fdbench: error: --db: ")
    assert str(path) in lines[0] and words in lines[0]
    assert result.stdout == ""
    assert _snapshot(tmp_path) == before


def test_empty_file_becomes_a_database_in_wal_mode(tmp_path):
    path = tmp_path / "results.sqlite"
    path.write_bytes(b"")
    with open_store(path) as store:
        assert store.count() == 0
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    con.close()


def test_database_without_its_runs_table_is_refused_and_left_untouched(tmp_path):
    path = tmp_path / "results.sqlite"
    with open_store(path):
        pass
    con = sqlite3.connect(path)
    con.execute("DROP TABLE runs")
    con.commit()
    con.close()
    before = path.read_bytes()
    with pytest.raises(StoreError, match="lost its table of runs"):
        Store(path)
    assert path.read_bytes() == before


def test_directory_or_missing_parent_is_refused(tmp_path):
    with pytest.raises(StoreError, match="is a directory"):
        Store(tmp_path)
    with pytest.raises(StoreError, match="does not exist"):
        Store(tmp_path / "missing" / "db.sqlite")
    assert not (tmp_path / "missing").exists()


# ----------------------------------------------------------------------------- FDBENCH_DB


def test_fdbench_db_environment_variable_selects_default_path(tmp_path, monkeypatch):
    target = tmp_path / "from-env.sqlite"
    monkeypatch.setenv("FDBENCH_DB", str(target))
    assert default_path() == target
    with open_store() as store:
        assert store.path == target
    assert target.exists() and {"runs", "fdbench_meta"} <= tables_of(target)

    monkeypatch.delenv("FDBENCH_DB")
    assert default_path() == Path(DEFAULT_DB) == Path("fdbench-results.sqlite")
    monkeypatch.setenv("FDBENCH_DB", "")
    assert default_path() == Path("fdbench-results.sqlite")


def test_report_without_db_uses_fdbench_db_then_the_working_directory(tmp_path, monkeypatch):
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    target = tmp_path / "env" / "results.sqlite"
    target.parent.mkdir()
    monkeypatch.setenv("FDBENCH_DB", str(target))
    args = ["report", "--torque", "cs", "--opt", "bfgs", "--no-feedforward", "--no-control", "--no-beyond", "--seeds", "1",
            "--budget", "5", "--jobs", "1", "--format", "csv", "-q"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.stderr
    with open_store(target) as store:
        assert store.count() == 1
    assert list(cwd.iterdir()) == []

    monkeypatch.delenv("FDBENCH_DB")
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.stderr
    assert (cwd / store_module.DEFAULT_DB).exists()
    with open_store(cwd / store_module.DEFAULT_DB) as store:
        assert store.count() == 1


def test_equivalent_specs_hash_alike():
    """Settings that cannot change the numbers do not change the identity of a run."""
    base = control_spec(0.0, 0.3)
    assert control_spec(-0.0, 0.3).hash() == base.hash()
    assert control_spec(0, 0.3).hash() == base.hash()  # an int where a float is meant
    assert control_spec(0.0, 0.3, rtol=1e-3, atol=1e-5).hash() == base.hash()  # rk4 has no tolerances
    adaptive = control_spec(0.0, 0.3, integrator="rk45")
    assert control_spec(0.0, 0.3, integrator="rk45", dt=0.01).hash() == adaptive.hash()  # nor rk45 a step
    assert adaptive.hash() != base.hash()


def test_stored_identity_of_default_specs_is_kept():
    """Fields added to RunSpec since the first schema leave a default spec's hash unchanged: the
    digest of the specification written without them."""
    import hashlib
    import json

    spec = optimize_spec("cs", "bfgs", False, seed=3, budget=20)
    legacy = {k: v for k, v in spec.as_dict().items() if k not in OMITTED_AT_DEFAULT}
    expected = hashlib.sha256(json.dumps(legacy, sort_keys=True, default=str).encode()).hexdigest()[:16]
    assert spec.hash() == expected
