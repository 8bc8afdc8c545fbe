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
from helpers.paths import ROOT  # the repository: pyproject.toml (the contracts), README.md

PACKAGE = Path(fdbench.__file__).resolve().parent  # the fdbench under test (installed or a checkout's)


def lint_imports(config: Path = ROOT / "pyproject.toml", package: Path = PACKAGE) -> subprocess.CompletedProcess:
    """``lint-imports`` (the test extra's import-linter) run by this interpreter with the contracts
    of ``config`` on the fdbench package at ``package``."""
    where = str(package.parent)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([where, os.environ.get("PYTHONPATH", "")])}
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    return subprocess.run([sys.executable, "-c", code, "--no-cache", "--config", str(config)],
                          capture_output=True, text=True, env=env, cwd=where, timeout=600)


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
    shutil.copytree(PACKAGE, tmp_path / "fdbench", ignore=shutil.ignore_patterns("__pycache__", "library"))
    engine = tmp_path / "fdbench" / "multibody" / "engine.py"
    engine.write_text(engine.read_text() + "\n\ndef _up():\n    from ..spec import RunSpec\n\n    return RunSpec\n")
    done = lint_imports(tmp_path / "pyproject.toml", tmp_path / "fdbench")
    assert done.returncode != 0
    assert "fdbench.multibody.engine -> fdbench.spec" in done.stdout
    assert "layers point down: CLI, report, run, methods, engine, utilities BROKEN" in done.stdout


def test_the_readme_architecture_names_modules_that_exist_and_every_layer_of_the_contract():
    """The README's section "Architecture" agrees with the code: every module or package it names
    (``name.py`` or ``name/``) exists in fdbench, and every top-level module of fdbench is named."""
    import re
    import tomllib

    readme = (ROOT / "README.md").read_text()
    start = readme.index("\n## Architecture\n")
    text = readme[start:readme.index("\n## ", start + 1)]
    named = set(re.findall(r"`([a-z_]+(?:\.py|/))`", text))
    files = {p.relative_to(PACKAGE) for p in PACKAGE.rglob("*") if "__pycache__" not in p.parts}
    for name in named:
        assert any(p.name == name.rstrip("/") for p in files), f"the README names {name}, which fdbench does not have"
    top = {p.name if p.suffix == ".py" else p.name + "/" for p in PACKAGE.iterdir()
           if (p.suffix == ".py" and p.name != "__init__.py") or (p.is_dir() and (p / "__init__.py").exists())}
    assert top <= named, f"modules of fdbench the README's architecture does not name: {sorted(top - named)}"
    layers = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"][0]["layers"]
    in_contract = {m.strip("() ") for layer in layers for m in re.split(r"[|:]", layer)}
    assert {n.removesuffix(".py").rstrip("/") for n in top} == in_contract
