"""The layers point down: import-linter's contracts in pyproject.toml ([tool.importlinter]) hold
for the fdbench under test (every import counts, those inside functions too), so that this suite
fails on an import that points up a layer or pulls typer, rich, matplotlib or opensim where they
do not belong."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import fdbench

ROOT = Path(fdbench.__file__).resolve().parents[1]  # the checkout holding the fdbench under test


def lint_imports(root: Path = ROOT) -> subprocess.CompletedProcess:
    """``lint-imports`` (the test extra's import-linter) run by this interpreter on the pyproject.toml
    and the fdbench package of the checkout ``root``."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    return subprocess.run([sys.executable, "-c", code, "--no-cache", "--config", str(root / "pyproject.toml")],
                          capture_output=True, text=True, env=env, cwd=root, timeout=600)


def test_the_import_contracts_hold():
    done = lint_imports()
    assert done.returncode == 0, done.stdout[-6000:] + done.stderr[-2000:]
    assert "0 broken" in done.stdout
    for contract in ("layers point down", "typer and rich only in the command line", "matplotlib only in the figures",
                     "opensim only in its child process"):
        assert f"{contract}" in done.stdout and "KEPT" in done.stdout.split(contract, 1)[1].splitlines()[0]


def test_an_import_pointing_up_breaks_the_contract(tmp_path):
    """The contract is not vacuous: the engine importing the spec (a copy of the package with that
    one import added) is reported, naming both modules, and lint-imports exits non-zero."""
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    shutil.copytree(ROOT / "fdbench", tmp_path / "fdbench", ignore=shutil.ignore_patterns("__pycache__", "library"))
    engine = tmp_path / "fdbench" / "multibody" / "engine.py"
    engine.write_text(engine.read_text() + "\n\ndef _up():\n    from ..spec import RunSpec\n\n    return RunSpec\n")
    done = lint_imports(tmp_path)
    assert done.returncode != 0
    assert "fdbench.multibody.engine -> fdbench.spec" in done.stdout
    assert "layers point down: CLI, report, run, methods, engine, utilities BROKEN" in done.stdout
