"""benchmarks/bench_speed_limit.py refuses what it cannot measure: one line on stderr, exit 2,
before any work."""

import os
import subprocess
import sys

from helpers.paths import ROOT

SCRIPT = ROOT / "benchmarks" / "bench_speed_limit.py"


def bench(*args, env=None):
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, env=env, timeout=120)


def test_a_missing_c_file_is_named_on_one_line(tmp_path):
    done = bench("--c-source", str(tmp_path / "absent.c"))
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.strip().splitlines() == [f"error: --c-source: no such file {tmp_path / 'absent.c'}"]


def test_no_c_compiler_is_said_on_one_line(tmp_path):
    source = tmp_path / "loop.c"
    source.write_text("int main(){return 0;}\n")
    env = {**os.environ, "PATH": str(tmp_path)}  # a PATH without cc
    done = bench("--c-source", str(source), env=env)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == ["error: no C compiler (cc) on PATH: the C baseline cannot be built"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loop.c"]  # nothing built, nothing written


def test_help_prints_what_is_measured_and_the_baseline():
    done = bench("--help")
    assert done.returncode == 0
    assert "pd_forearm.c" in done.stdout and "1.5x" in done.stdout
