"""The suite's conditions, for every test under tests/ (its layers' folders: cli, report, run,
methods, engine, util; the tests of the whole at the top). This file's folder is on sys.path
(pytest puts a rootdir conftest's folder there), so every test imports what the tests share from
the ``helpers`` package; test modules are imported by their base names, unique across folders."""

import os
import signal

import pytest
from hypothesis import HealthCheck, settings

# Numba compiles on first use (cached afterwards): no per-example deadline. CI runs a fixed
# sequence of examples so a red run can be reproduced.
settings.register_profile("fdbench", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("ci", parent=settings.get_profile("fdbench"), derandomize=True)
settings.load_profile("ci" if os.environ.get("CI") else "fdbench")

# A shell starts a background job (`pytest -q &`, a CI script's `&`) with Ctrl-C ignored, and an
# ignored signal stays ignored in every program it starts: the commands the tests interrupt
# would never see their SIGINT. The tests interrupt commands as a terminal's Ctrl-C does, so
# their children start with the default disposition, whatever this process inherited.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    """Every fdbench of the session, in this process and in the commands the tests start, keeps
    its compiled kernels in one folder beside pytest's temporary folders (private to the user,
    kept across sessions): kernels compile once, not once per command, and the user's own cache
    is neither used nor written. A FDBENCH_CACHE_DIR set by the caller is kept; its database,
    plugins and debug mode are not: the tests start from fdbench's defaults."""
    for name in ("FDBENCH_DB", "FDBENCH_PLUGINS", "FDBENCH_DEBUG"):  # the caller's choices are not the tests'
        os.environ.pop(name, None)
    if not os.environ.get("FDBENCH_CACHE_DIR"):
        root = config._tmp_path_factory.getbasetemp().parent  # /tmp/pytest-of-USER, mode 0700
        os.environ["FDBENCH_CACHE_DIR"] = str(root / "fdbench-kernels")
