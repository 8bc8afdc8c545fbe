"""The suite's own conditions (tests/conftest.py): the commands the tests start see Ctrl-C as a
terminal sends it, share one kernel cache with this process, and none of the caller's fdbench
settings (database, plugins, debug mode) reaches a test."""

import os
import subprocess
import sys

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
