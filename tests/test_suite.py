"""The suite's own conditions (tests/conftest.py): the commands the tests start see Ctrl-C as a
terminal sends it, share one kernel cache with this process, and none of the caller's fdbench
settings (database, plugins, debug mode) reaches a test. And its structure: test modules import
no other test module (what they share is in tests/helpers), none skips itself when a module of
fdbench fails to import, and their names are unique across the folders (pytest imports them by
their base names)."""

import ast
import os
import subprocess
import sys
from collections import Counter

import helpers

TESTS = os.path.dirname(os.path.dirname(os.path.abspath(helpers.__file__)))

PROBE = """
import signal, sys
from fdbench import jit
print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)
print(jit.CACHE_DIR)
"""


def test_commands_started_by_the_tests_get_ctrl_c_and_the_sessions_kernel_cache():
    from fdbench import jit

    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    ctrl_c, cache = out.stdout.splitlines()
    assert ctrl_c == "True"  # also when pytest itself runs as a background job (SIGINT ignored)
    assert cache == str(jit.CACHE_DIR) == os.environ["FDBENCH_CACHE_DIR"]


def test_the_callers_fdbench_settings_do_not_reach_the_tests():
    for name in ("FDBENCH_DB", "FDBENCH_PLUGINS", "FDBENCH_DEBUG"):
        assert name not in os.environ, name


def _modules():
    """(path, parsed module) of every Python file of the suite, helpers included."""
    for folder, _, names in os.walk(TESTS):
        for name in sorted(names):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                with open(path, encoding="utf-8") as handle:
                    yield path, ast.parse(handle.read(), path)


def _imported(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module


def test_no_test_module_imports_another():
    found = [(os.path.relpath(path, TESTS), name) for path, tree in _modules() for name in _imported(tree)
             if name.split(".")[0].startswith("test_") or name.split(".")[0] == "conftest"]
    assert found == [], "share code through tests/helpers, not by importing a test module"


def test_no_module_of_fdbench_is_imported_through_importorskip():
    """An engine that fails to import must fail the suite, not skip its checks."""
    found = []
    for path, tree in _modules():
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) == "importorskip"
                    and node.args and isinstance(node.args[0], ast.Constant)
                    and str(node.args[0].value).split(".")[0] == "fdbench"):
                found.append((os.path.relpath(path, TESTS), node.lineno))
    assert found == []


def test_test_module_names_are_unique():
    names = Counter(name for _, _, names in os.walk(TESTS) for name in names
                    if name.startswith("test_") and name.endswith(".py"))
    assert [name for name, count in names.items() if count > 1] == []
