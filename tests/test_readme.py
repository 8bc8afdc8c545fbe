"""The README as a new user meets it: its commands run exactly as written, and every figure it
prints agrees with what the command prints, within 2 in the last digit shown.

That tolerance holds on any CPU because every figure checked comes from a path that rounding
does not fork: simulations, PD control, collocation, and BFGS with exact gradients (on the
forearm, a CPU's other rounding, numba for a generic x86-64 and numpy and OpenBLAS without
AVX, moves these by 3e-12 relative at most, and PD and the open loop not at all). BFGS with
finite differences is not checked to the digit: its gradient divides the objective's rounding
(1e-15) by the step (1.5e-8), and its line search decides on those values, so the same run moves
by 1e-4 relative from one CPU to another; the README marks such figures as machine-dependent.

The commands run through bash with this interpreter's bin/ (the virtualenv) first on PATH, in one
temporary working directory shared by the module, where the plain ``fdbench report`` of the
README's first line runs first and creates ``fdbench-results.sqlite`` there.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from decimal import Decimal
from pathlib import Path

import pytest

from helpers.paths import ROOT

README = (ROOT / "README.md").read_text()

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="the README's commands need bash")


# ---- reading the README ----------------------------------------------------------------------


def section(heading: str) -> str:
    start = README.index(f"\n## {heading}\n")
    end = README.find("\n## ", start + 1)
    return README[start:] if end < 0 else README[start:end]


def code_blocks(text: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced block."""
    return re.findall(r"```(\w*)\n(.*?)```", text, flags=re.DOTALL)


def close(shown: str, actual: float) -> bool:
    """``actual`` agrees with the number ``shown`` within 2 in its last digit."""
    value = Decimal(shown)
    exponent = value.as_tuple().exponent
    return abs(float(value) - actual) <= 2 * 10.0**exponent + 1e-15


# ---- running commands ------------------------------------------------------------------------


def shell_env() -> dict:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    for name in ("FDBENCH_DEBUG", "FDBENCH_DB", "FDBENCH_PLUGINS"):
        env.pop(name, None)
    return env


def sh(command: str, cwd: Path) -> subprocess.CompletedProcess:
    out = subprocess.run(["bash", "-c", command], cwd=cwd, env=shell_env(), capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, f"{command}\nexit {out.returncode}\nstdout:\n{out.stdout}\nstderr:\n{out.stderr}"
    assert "Traceback" not in out.stderr, out.stderr
    return out


def record(command: str, cwd: Path) -> dict:
    return json.loads(sh(command + " --format json --quiet", cwd).stdout)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A fresh working directory in which the README's first line's ``fdbench report`` ran, with
    the source folder's examples/ (the commands' example files) as a reader has them."""
    workdir = tmp_path_factory.mktemp("readme")
    shutil.copytree(ROOT / "examples", workdir / "examples")
    return workdir


@pytest.fixture(scope="module")
def first_report(workdir):
    line = code_blocks(README.split("\n## ", 1)[0])[0][1].splitlines()[0]
    command = line.split(" && ")[-1]
    assert command == "fdbench report"
    return sh(command, workdir)


# ---- the two set-up lines --------------------------------------------------------------------


def test_the_two_setup_lines_are_the_install_and_the_tests_ci_runs():
    lang, body = code_blocks(README.split("\n## ", 1)[0])[0]
    lines = body.strip().splitlines()
    venv = "python3 -m venv .venv && . .venv/bin/activate && "
    assert lines == [venv + "pip install . && fdbench report", venv + "pip install '.[test]' && pytest -q -n 2"]
    ci = (ROOT / ".ci" / "run").read_text()
    for step in ("python3 -m venv .venv", ". .venv/bin/activate", "pip install --quiet '.[test]'", "pytest -q -n 2"):
        assert step in ci


def test_first_report_says_it_creates_its_database_and_prints_the_report(first_report, workdir):
    assert first_report.stdout.startswith("# fdbench report\n")
    for heading in ("## Table 2", "## Table 3", "## Where we differ from the paper, and why",
                    "## When and where the runs were made"):
        assert heading in first_report.stdout
    assert "creating results database fdbench-results.sqlite" in first_report.stderr
    assert (workdir / "fdbench-results.sqlite").is_file()
    again = sh("fdbench report", workdir)  # once stored: the same tables, and no creation line
    assert "creating results database" not in again.stderr
    def stored(text):  # the report without what is measured anew: the date, the inverse-dynamics time,
        # and what was carried out (everything the first time, nothing the second)
        text = re.sub(r"\| parallel jobs \|.*\|", "", re.sub(r"\| date \|.*\|", "", text))
        return re.sub(r"computed in [\d.]+ ms", "", text)

    assert "| parallel jobs | none: every run was stored |" in again.stdout
    assert "| parallel jobs | none" not in first_report.stdout
    assert stored(again.stdout) == stored(first_report.stdout)


# ---- Quick start and the commands table ------------------------------------------------------


def quick_start_commands() -> list[str]:
    (_, body), = code_blocks(section("Quick start"))
    return [line.split("#")[0].strip() for line in body.strip().splitlines()]


def test_every_quick_start_command_runs_as_written(first_report, workdir):
    commands = quick_start_commands()
    assert len(commands) == 5
    outputs = {command: sh(command, workdir) for command in commands}
    report = (workdir / "report.md").read_text()
    assert (workdir / "figures").is_dir() and len(list((workdir / "figures").glob("*.png"))) == 5
    assert "![Figure 6: with feedforward](figures/figure6_tracking.png)" in report
    json.loads(outputs["fdbench optimize --torque ann --opt cmaes --feedforward --seed 3 --format json"].stdout)
    assert "cs " in outputs["fdbench methods"].stdout and "bfgs " in outputs["fdbench methods"].stdout


def test_the_quick_start_comment_figures(workdir):
    (_, body), = code_blocks(section("Quick start"))
    line = next(line for line in body.splitlines() if line.startswith("fdbench control"))
    command, comment = line.split("#")
    found = re.search(r"([\d.]+) deg, ([\d.]+) N m \(paper: ([\d.]+), ([\d.]+)\)", comment)
    run = record(command.strip(), workdir)
    assert close(found[1], run["rmse_rot_deg"]) and close(found[2], run["rmse_torque_nm"])
    # the paper's figures as the report prints them beside ours
    pd_line = next(line for line in sh("fdbench report --no-feedforward --seeds 1 --budget 5 -q", workdir)
                   .stdout.splitlines() if line.startswith("| PD control"))
    cells = [c.strip() for c in pd_line.strip("|").split("|")]
    assert (cells[2], cells[5]) == (found[3], found[4])


def test_every_command_of_the_commands_table_runs_as_written(first_report, workdir):
    rows = [line for line in section("Commands").splitlines() if line.startswith("| `")]
    commands = [re.findall(r"`([^`]+)`", row)[-1] for row in rows]
    assert len(commands) == 13 and all(c.startswith("fdbench ") for c in commands)
    for command in commands:  # in order: inverse writes id.csv, simulate reads it
        sh(command, workdir)
    assert (workdir / "id.csv").read_text().startswith("t,theta,theta_vel,theta_acc,theta_torque")
    assert (workdir / "conv.csv").read_text().splitlines()[0] == "evaluation,best_objective"
    assert len((workdir / "report.csv").read_text().splitlines()) == 15  # header, PD, 4 + 6 cells, 3 beyond


def test_the_pipelines_of_the_output_section_work(first_report, workdir):
    text = section("Output fields").replace("\n", " ")
    pipes = [c for c in re.findall(r"`(fdbench [^`]+)`", text) if "|" in c or ">" in c]
    assert any("json.load" in c for c in pipes)
    for command in pipes:
        if command.split("|")[-1].strip().startswith("jq") and shutil.which("jq") is None:
            continue
        sh(re.sub(r"\s+", " ", command), workdir)


# ---- figures printed in prose and examples ---------------------------------------------------


PROSE = [  # (pattern whose group is the printed figure, command, field)
    (r"`fdbench simulate`, RMSE ≈ ([\d.]+)°", "fdbench simulate", "rmse_rot_deg"),
    (r"PD control leaves an error of ([\d.]+)°", "fdbench control", "rmse_rot_deg"),
    (r"PD control leaves an error of [\d.]+° \(paper: ([\d.]+)°\)", None, 0.116),
    (r"inverse-dynamics torque tracks to ([\de.-]+)°", "fdbench simulate --kinematics exact", "rmse_rot_deg"),
    (r"PD control to ([\de.-]+)°", "fdbench control --kinematics exact", "rmse_rot_deg"),
    (r"`fdbench collocate --model arm2` replays\s+to\s+RMSE_rot\s+([\d.]+)°", "fdbench collocate --model arm2",
     "rmse_rot_deg"),
    (r"replays\s+to\s+RMSE_rot\s+[\d.]+°\s+\(its\s+own\s+nodes:\s+([\d.]+)°", "fdbench collocate --model arm2",
     "collocation_rmse_rot_deg"),
    (r"IPOPT\s+converges\s+in\s+(\d+)\s+iterations", "fdbench collocate --model arm2", "ipopt_iterations"),
    (r"--rtol\s+1e-9\s+--atol\s+1e-12`\s+replays\s+the\s+inverse-dynamics\s+torques\s+to\s+RMSE_rot\s+([\d.]+)°",
     "fdbench simulate --model arm2 --integrator dop853 --rtol 1e-9 --atol 1e-12", "rmse_rot_deg"),
    (r"RMSE_rot\s+[\d.]+°,\s+as\s+RK4\s+does\s+\(([\d.]+)°\)", "fdbench simulate --model arm2", "rmse_rot_deg"),
    (r"`--scheme\s+trapezoidal`\s+the\s+replay\s+drifts\s+by\s+([\d.]+)°",
     "fdbench collocate --model arm2 --scheme trapezoidal", "rmse_rot_deg"),
]


@pytest.fixture(scope="module")
def record_once(workdir):
    """``record(command, workdir)``, each distinct command run once for the module: several
    figures of the prose come from one command's output."""
    done = {}

    def run(command: str) -> dict:
        if command not in done:
            done[command] = record(command, workdir)
        return done[command]

    return run


@pytest.mark.parametrize("pattern, command, field", PROSE)
def test_figures_in_the_prose(pattern, command, field, record_once):
    found = re.search(pattern, README.replace("\n", " "))
    assert found, pattern
    if command is None:  # the paper's published figure (section 5 of the paper)
        assert float(found[1]) == field
        return
    assert close(found[1], record_once(command)[field])


def _examples() -> dict:
    """{command: block} of the 'Example (`command`, abridged...)' blocks of Output fields."""
    text = section("Output fields")
    return dict(re.findall(r"Example \(`([^`]+)`, abridged[^)]*\):\s*```\w*\n(.*?)```", text, flags=re.DOTALL))


def _same(shown, actual) -> bool:
    if isinstance(shown, (bool, int, str)) or shown is None:
        return shown == actual
    return close(repr(shown), float(actual))


def test_the_json_example_is_what_the_command_prints(workdir):
    examples = _examples()
    command = next(c for c in examples if "--format json" in c)
    shown = json.loads(examples[command])
    actual = json.loads(sh(command, workdir).stdout)
    assert len(shown) >= 10
    for key, value in shown.items():
        assert _same(value, actual[key]), (key, value, actual[key])


def test_the_csv_example_is_what_the_command_prints(workdir):
    examples = _examples()
    command = next(c for c in examples if "--format csv" in c)
    header, row = examples[command].strip().splitlines()
    out = sh(command, workdir).stdout.splitlines()
    import csv

    actual = dict(zip(*csv.reader(out)))
    pairs = [(k, v) for k, v in zip(header.split(","), row.split(",")) if k != "..."]
    assert all(v != "..." for _, v in pairs)  # the placeholders line up
    assert len(pairs) >= 10
    for key, value in pairs:
        if re.fullmatch(r"-?\d+\.\d+(e-?\d+)?", value) and key != "dt":
            assert close(value, float(actual[key])), (key, value, actual[key])
        else:
            assert value == actual[key], (key, value, actual[key])


# ---- Python API and the plugin example ---------------------------------------------------------


def test_the_python_api_example_prints_what_the_readme_shows(tmp_path):
    blocks = code_blocks(section("Python API"))
    (code,) = [body for lang, body in blocks if lang == "python"]
    (shown,) = [body for lang, body in blocks if lang == ""]
    (tmp_path / "example.py").write_text(code)
    out = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, env=shell_env(), capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    printed, expected = out.stdout.strip().splitlines(), shown.strip().splitlines()
    assert len(printed) == len(expected)
    for got, want in zip(printed, expected):
        got_tokens, want_tokens = got.split(), want.split()
        assert len(got_tokens) == len(want_tokens), (got, want)
        for g, w in zip(got_tokens, want_tokens):
            if re.fullmatch(r"\d+\.\d+", w.rstrip(",")):
                assert close(w.rstrip(","), float(g.rstrip(","))), (got, want)
            else:
                assert g == w, (got, want)


def test_the_optimisations_checked_to_the_digit_use_exact_gradients():
    """BFGS in a checked example uses exact gradients (see the module's docstring)."""
    (code,) = [body for lang, body in code_blocks(section("Python API")) if lang == "python"]
    checked = [code, *_examples()] + [command for _, command, _ in PROSE if command]
    for text in checked:
        for call in re.findall(r"optimize_spec\([^)]*\)|fdbench optimize [^`\n]*", text):
            if "bfgs" in call or "lbfgsb" in call or "--opt" not in call and "optimize " in call:
                assert "exact" in call, call


def test_the_plugin_example_runs_exactly_as_written():
    text = section("Adding a method")
    python = [body for lang, body in code_blocks(text) if lang == "python"][0]
    module = (ROOT / "examples" / "my_methods.py").read_text()
    assert python.strip() in module  # the README shows the module's code
    (_, command), = [(lang, body) for lang, body in code_blocks(text) if lang == "bash"]
    command = command.strip()
    assert command.startswith("PYTHONPATH=examples FDBENCH_PLUGINS=my_methods fdbench optimize")
    out = sh(command, ROOT)  # from the repository's top folder, as the README says
    assert re.search(r"torque\s+│ linear", out.stdout) and re.search(r"optimizer\s+│ random", out.stdout)
    assert re.search(r"evaluations\s+│ 50 ", out.stdout) and re.search(r"status\s+│ success", out.stdout)
    listed = sh(command.split(" fdbench ")[0] + " fdbench methods", ROOT).stdout
    assert "linear" in listed and "random" in listed


def test_the_commands_of_your_own_data_run_as_written(first_report, tmp_path):
    """From the repository's top folder, as the section says (in a copy, so nothing is written
    into the checkout)."""
    top = tmp_path / "checkout"
    (top / "examples").mkdir(parents=True)
    shutil.copy(ROOT / "examples" / "elbow_flexion.csv", top / "examples")
    (lang, body), = [b for b in code_blocks(section("Your own data")) if b[0] == "bash"]
    commands = [line for line in body.splitlines() if line.startswith("fdbench ")]
    assert len(commands) == 6
    for command in commands:
        sh(command + " --quiet", top)
    assert (top / "elbow_torque.csv").read_text().startswith("t,theta,theta_vel,theta_acc,theta_torque")
    # fdbench's output is valid input: the history read back as --motion starts where the recording does
    again = json.loads(sh("fdbench inverse --motion elbow_torque.csv --format json", top).stdout)
    first = json.loads(sh("fdbench inverse --motion examples/elbow_flexion.csv --format json", top).stdout)
    assert again["theta_start_deg"] == pytest.approx(first["theta_start_deg"], abs=1e-9)
    assert len((top / "elbow_torque.csv").read_text().splitlines()) == 302  # 2.5 s at 120 Hz and a header
    assert (top / "study" / "study_noise_rmse_rot_deg.png").is_file() and (top / "mismatch.md").is_file()
    assert (ROOT / "docs" / "study_noise_rmse_rot_deg.png").is_file()
