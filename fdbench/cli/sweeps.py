"""Commands that carry out many runs through an execution backend and the results store:
report and study."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from .app import BadInput, MAX_JOBS, MAX_SEEDS, REPORT_FORMATS, STUDY_FORMATS, app, error
from .common import (
    bracketed_all, check_choice, check_finite, check_gradient, check_method_ranges, check_names, check_outputs, emit,
    Progress, say, validated, with_option,
)
from .conditions import spec_inputs, with_conditions
from .options import (
    Cells, Execution, Kinematics, MethodValues, Optimisation, Output, Quiet, Simulation, methods_command, with_groups,
)

SWEEP_METHODS = ("torques", "optimizers", "controllers:pd")  # the method options of a report or a study


@app.command(cls=methods_command(*SWEEP_METHODS))
@with_conditions
@with_groups
def report(
    ctx: typer.Context,
    beyond: Annotated[bool, typer.Option("--beyond/--no-beyond", help="Include the table 'Beyond the paper': computed-torque and LQR control, direct collocation (on a model with a floating base: --no-beyond leaves out its slow collocation row).")] = True,
    peers: Annotated[Optional[str], typer.Option("--peers", metavar="opensim,opensim-cmc,moco", help="Add the section 'Peers': opensim (OpenSim's forward simulation under the same PD law), opensim-cmc (OpenSim's CMCTool), moco (MocoTrack, its torque replayed by fdbench), comma-separated. Needs pip install 'fdbench\\[opensim]'.", show_default=False)] = None,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per cell, in [1, 1000]: seeds 0..N-1; medians and IQRs over them.")] = 5,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write PNG figures into DIR (created if missing) and link them.")] = None,
    fmt: Annotated[str, typer.Option("--format", "-f", help="Report format: md (Markdown), csv (one row per cell) or json (settings and cells with medians, IQRs, success counts and the ids of their stored runs).")] = "md",
    output: Output = None,
    quiet: Quiet = False,
    kinematics: Kinematics = None,
    selection: Cells = None,
    optim: Optimisation = None,
    run: Execution = None,
    sim: Simulation = None,
    flags: MethodValues = None,
    conditions: dict = None,
):
    """The paper's whole comparison: PD control, Table 2 and Table 3, with our figures beside the published ones, as Markdown, CSV or JSON.

    Every run is stored in the results database; stored runs are reused, so an interrupted report resumes and a repeated one returns at once. On a model with a floating base (a recorded walk, with --loads) it gives the walk's comparison instead: one run per method, the same methods on the forearm, the paper's claim tested; --torque, --opt, --feedforward or --all-cells add the paper's cells on the model."""
    from ..report.paper_methods import default_cells, make_plan

    db_path = run.db_path
    inputs = spec_inputs(conditions, kinematics)
    check_outputs(fmt, REPORT_FORMATS, db=db_path, output=output, inputs=inputs)
    if _floating_base(conditions):  # compared with the forearm (report.comparison)
        return _comparison_report(ctx, conditions, kinematics, selection, optim, run, sim, flags, beyond=beyond,
                                  peers=peers, seeds=seeds, figures=figures, fmt=fmt, output=output, quiet=quiet,
                                  inputs=inputs)
    if figures is not None:
        _check_figures_dir(figures, output, db_path, inputs)
    torque, opt, torque_options, optimizer_options = _sweep_options(ctx, seeds, run, selection, flags, optim)
    executor = run.executor()
    control, (kp, kd) = selection.control, (flags["controllers"].get("kp"), flags["controllers"].get("kd"))
    cells = default_cells(torque, opt, selection.feedforward, selection.all_cells)
    if not cells and not control and not beyond and not peers:
        raise BadInput("nothing to run: the options select no cell, --no-control and --no-beyond")
    check_gradient(optim.gradient, opt)
    peer_names = _peer_names(peers)
    plan = make_plan(
        cells, seeds, optim.budget, control, kp, kd, torque_options=torque_options,
        optimizer_options=optimizer_options, penalty_weight=optim.penalty_weight,
        **sim.spec_fields(kinematics, conditions),
    )  # Tables 2 and 3 keep the paper's finite differences; exact gradients go to "Beyond the paper"
    for spec in ([plan.control] if plan.control else []) + [plan.specs[c][0] for c in plan.cells]:
        validated(spec)
    from ..store import open_store

    methods = None
    if beyond:
        from ..report.methods import beyond_methods

        methods = beyond_methods(**sim.spec_fields(kinematics, conditions))
    if optim.gradient == "exact":
        from ..report.methods import exact_gradient_methods

        methods = (methods or []) + exact_gradient_methods(
            plan.cells, optim.budget, torque_options, optimizer_options, optim.penalty_weight,
            **sim.spec_fields(kinematics, conditions))
        for method in methods:
            validated(method.spec)
    peer_methods = []
    if peer_names:
        from ..report.peers import peer_methods as make_peer_methods

        try:
            peer_methods = make_peer_methods(peer_names, kp, kd, **sim.spec_fields(kinematics, conditions))
        except ValueError as exc:
            raise BadInput(str(exc)) from None
        for method in peer_methods:
            validated(method.spec)
        _check_peers_available()
    extra = ([m.spec for m in methods] if methods else []) + [m.spec for m in peer_methods]
    runs = _run_specs(plan.all_specs() + extra, db_path, run.db is None, executor, run.rerun, quiet)
    from ..report import build_rows

    start = time.perf_counter()
    inverse = (plan.control or plan.all_specs()[0]).reference()
    inverse_runtime = time.perf_counter() - start
    with open_store(db_path) as store:
        made = store.provenance(runs)
    rows = build_rows(plan, runs, made)
    extra_rows = []
    if methods:
        from ..report.methods import rows as method_rows

        extra_rows = method_rows(methods, runs, made)
    peers_found = None
    if peer_methods:
        from ..report.peers import peer_rows

        peers_found = (peer_methods, peer_rows(peer_methods, runs, made))
    emit(_report_text(fmt, plan, runs, rows, extra_rows, methods, inverse, inverse_runtime, seeds,
                       executor.describe(), figures, output, quiet, peers_found), output)
    if output is not None and str(output) != "-":
        say(quiet, f"wrote {output} ({len(runs)} runs, database {db_path})")


@app.command(cls=methods_command(*SWEEP_METHODS))
@with_conditions
@with_groups
def study(
    ctx: typer.Context,
    kind: Annotated[str, typer.Argument(help="noise: the motion captured with white noise of each level (deg); mismatch: one constant of the simulated body changed by each level (percent) while the methods keep the nominal model.", metavar="noise|mismatch")],
    levels: Annotated[str, typer.Option("--levels", help="The levels, comma-separated: deg for noise (e.g. 0,0.25,0.5,1,2), percent for mismatch (e.g. -20,-10,0,10,20).")] = "",
    param: Annotated[str, typer.Option("--param", help="mismatch: the plant constant changed: L12, L1G, m, I1, F_ext or g (arm2 also L01, L0G, m0, I0; any model: a path such as thigh.mass, see 'fdbench models show').")] = "I1",
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per method and level, in [1, 1000]: seeds 0..N-1 (the noise realisation and the optimiser's seed).")] = 5,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write one PNG per indicator into DIR (created if missing): level on x, median and IQR band per method.")] = None,
    fmt: Annotated[str, typer.Option("--format", "-f", help="md (tables per indicator), csv (one row per method and level) or json (the settings and those rows).")] = "md",
    output: Output = None,
    quiet: Quiet = False,
    kinematics: Kinematics = None,
    selection: Cells = None,
    optim: Optimisation = None,
    run: Execution = None,
    sim: Simulation = None,
    flags: MethodValues = None,
    conditions: dict = None,
):
    """Sweep one condition over the methods: 'fdbench study noise --levels 0,0.25,0.5,1,2 --seeds 10' or 'fdbench study mismatch --param I1 --levels -20,-10,0,10,20'.

    Runs are stored and reused like a report's (resume, --jobs, --rerun); the table gives the median and IQR of each indicator per method and level."""
    from .. import study as studies
    from ..report.paper_methods import default_cells

    check_choice("study", kind, studies.KINDS)
    db_path = run.db_path
    inputs = spec_inputs(conditions, kinematics)
    check_outputs(fmt, STUDY_FORMATS, db=db_path, output=output, inputs=inputs)
    if not levels:
        raise BadInput("--levels: give the levels to sweep, e.g. --levels " + ("0,0.5,1,2" if kind == "noise" else "-20,0,20"))
    try:
        parsed = studies.parse_levels(levels, kind)
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    if kind == "noise" and conditions["noise_deg"]:
        raise BadInput("--noise-deg: the noise study sets the noise itself (--levels)")
    if kind == "mismatch":
        from ..models import model_keys

        check_choice("--param", param, model_keys(conditions["model_name"]))
    if figures is not None:
        _check_figures_dir(figures, output, db_path, inputs, studies.FIGURE_NAMES)
    torque, opt, torque_options, optimizer_options = _sweep_options(ctx, seeds, run, selection, flags, optim)
    executor = run.executor()
    control, (kp, kd) = selection.control, (flags["controllers"].get("kp"), flags["controllers"].get("kd"))
    cells = default_cells(torque, opt, selection.feedforward, selection.all_cells)
    if not cells and not control:
        raise BadInput("nothing to run: the options select no cell and --no-control")
    check_gradient(optim.gradient, opt)
    try:
        sweep = studies.make_sweep(kind, parsed, seeds, cells, control, kp, kd, optim.budget, torque_options,
                                   optimizer_options, optim.penalty_weight, param if kind == "mismatch" else None,
                                   gradient=optim.gradient, **sim.spec_fields(kinematics, conditions))
    except ValueError as exc:
        raise BadInput(with_option(str(exc))) from None
    for key in sweep.specs:
        validated(sweep.specs[key][0])
    runs = _run_specs(sweep.all_specs(), db_path, run.db is None, executor, run.rerun, quiet)
    rows = studies.summary(sweep, runs)
    if fmt == "csv":
        from ..files import csv_text

        emit(csv_text(list(studies.CSV_COLUMNS), studies.csv_rows(sweep, rows)), output)
    elif fmt == "json":
        settings = studies.settings(sweep, seeds, optim.budget, executor.describe(), kinematics, sim.integrator, sim.dt)
        emit(studies.json_text(sweep, rows, settings), output)
    else:
        links = None
        if figures is not None:
            from ..files import new_folder

            with new_folder(figures):  # removed again if a figure cannot be written
                written = studies.write_figures(sweep, rows, figures)
            base = output.parent if output is not None else Path(".")
            links = {title: os.path.relpath(path, base) for title, path in written.items()}
            say(quiet, f"wrote {len(written)} figures to {figures}")
        settings = studies.settings(sweep, seeds, optim.budget, executor.describe(), kinematics, sim.integrator, sim.dt)
        emit(studies.markdown(sweep, rows, settings, links), output)
    if output is not None and str(output) != "-":
        say(quiet, f"wrote {output} ({len(sweep.all_specs())} runs, database {db_path})")


def _floating_base(conditions: dict) -> bool:
    """Whether the report's model has a floating base (a free joint on ground)."""
    from ..report.comparison import has_floating_base

    try:
        return has_floating_base(conditions["model_name"], conditions.get("model", ()))
    except ValueError as exc:
        raise BadInput(str(exc)) from None


def _given(ctx, name: str) -> bool:
    """Whether the option ``name`` was given (on the command line or by an environment variable)."""
    return getattr(ctx.get_parameter_source(name), "name", None) in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def _comparison_report(ctx, conditions: dict, kinematics: str, selection: Cells, optim: Optimisation, run: Execution,
                       sim: Simulation, flags: MethodValues, *, beyond: bool, peers, seeds: int, figures, fmt: str,
                       output, quiet: bool, inputs: dict) -> None:
    """The report of a model with a floating base: the registered methods on it and on the
    forearm (``report.comparison``); the paper's cells on it when --torque, --opt, --feedforward or
    --all-cells select them; checked, planned, run (stored and resumed), written."""
    from ..figures import MODEL_FIGURE_FILES
    from ..report import comparison
    from ..report.methods import FLOATING_BASE_PENALTY, SHOOTING_POPSIZE, Options, exact_gradient_methods
    from ..report.paper_methods import default_cells, make_plan
    from ..store import open_store
    from .conditions import warn_opensim

    db_path = run.db_path
    if figures is not None:
        _check_figures_dir(figures, output, db_path, inputs, MODEL_FIGURE_FILES)
    torque, opt, torque_options, optimizer_options = _sweep_options(ctx, seeds, run, selection, flags, optim)
    check_gradient(optim.gradient, opt)
    executor = run.executor()
    (kp, kd), popsize = (flags["controllers"].get("kp"), flags["controllers"].get("kd")), flags["optimizers"].get("popsize")
    weight = optim.penalty_weight if _given(ctx, "penalty_weight") else FLOATING_BASE_PENALTY
    options = Options(optim.budget, SHOOTING_POPSIZE if popsize is None else popsize, flags["optimizers"].get("sigma0"),
                      flags["torques"].get("knots"), kp, kd)
    studied = sim.spec_fields(kinematics, conditions)
    forearm = sim.spec_fields("paper", None)
    selected = any(_given(ctx, name) for name in ("torque", "opt", "feedforward", "all_cells"))
    try:
        plan = comparison.make_plan(studied, forearm, options, collocation=beyond, control=selection.control,
                                    penalty_weight=weight)
        if selected:
            cells = default_cells(torque, opt, selection.feedforward, selection.all_cells)
            common = plan.datasets[0].common
            plan.cells = make_plan(cells, seeds, optim.budget, False, kp, kd, torque_options=torque_options,
                                   optimizer_options=optimizer_options, penalty_weight=weight, **common)
            if optim.gradient == "exact":
                plan.extra = exact_gradient_methods(cells, optim.budget, torque_options, optimizer_options, weight,
                                                    **common)
        peer_methods = _peer_methods(_peer_names(peers), kp, kd, plan.datasets[0].common)
    except ValueError as exc:
        raise BadInput(with_option(str(exc))) from None
    for spec in plan.all_specs() + [m.spec for m in peer_methods]:
        validated(spec)
    if peer_methods:
        _check_peers_available()
    warn_opensim(conditions["model_name"], kinematics, quiet)  # the import's notes before the work, not after it
    runs = _run_specs(plan.all_specs() + [m.spec for m in peer_methods], db_path, run.db is None, executor, run.rerun,
                      quiet)
    with open_store(db_path) as store:
        made = store.provenance(runs)
    found = comparison.report_rows(plan, runs, made, peer_methods)
    base = output.parent if output is not None and str(output) != "-" else Path(".")
    text, written = comparison.text(fmt, plan, found, runs, executor.describe(), figures, base,
                                    getattr(executor, "jobs", 1), peer_methods, seeds)
    if figures is not None and fmt == "md":
        say(quiet, f"wrote {written} figures to {figures}")
    emit(text, output)
    if output is not None and str(output) != "-":
        say(quiet, f"wrote {output} ({len(runs)} runs, database {db_path})")


def _peer_methods(names: list, kp, kd, common: dict) -> list:
    """The peers ``names`` as methods on the settings ``common`` with the report's PD gains."""
    if not names:
        return []
    from ..report.peers import peer_methods

    return peer_methods(names, kp, kd, **common)


def _sweep_options(ctx, seeds, run: Execution, selection: Cells, flags: MethodValues, optim: Optimisation):
    """The checks shared by the commands that run many specs (report, study), before any work;
    returns the torque and optimiser names (their NAME[KEY=VALUE,...] options taken out) and the
    (torque options, optimizer options) of their cells."""
    from ..optimizers import OPTIMIZERS
    from ..torques import TORQUES

    if not 1 <= seeds <= MAX_SEEDS:
        raise BadInput(f"--seeds must be an integer in [1, {MAX_SEEDS}], got {seeds}")
    if run.jobs is not None and not 1 <= run.jobs <= MAX_JOBS:
        raise BadInput(f"--jobs must be an integer in [1, {MAX_JOBS}], got {run.jobs}")
    check_finite(**{k: v for k, v in flags["optimizers"].items() if isinstance(v, float)},
                 penalty_weight=optim.penalty_weight)
    torques, torque_options = bracketed_all(ctx, selection.torque, "--torque", flags["torques"], TORQUES, "torque")
    optimizers, optimizer_options = bracketed_all(ctx, selection.opt, "--opt", flags["optimizers"], OPTIMIZERS,
                                                  "optimizer")
    check_names(torques, optimizers)
    check_method_ranges(TORQUES, torque_options)
    check_method_ranges(OPTIMIZERS, optimizer_options)
    return torques, optimizers, torque_options, optimizer_options


def _run_specs(specs, db_path: Path, default_db: bool, executor, rerun: bool, quiet: bool) -> dict:
    """Make sure every spec is stored in the database (missing runs carried out by the backend,
    each stored as it finishes), with a progress bar; {spec hash: stored run}. An unusable
    database or backend is bad input; SIGTERM ends the command like Ctrl-C, exit 143. A new
    database is created only once the backend has its workers: a refused or unreachable backend
    leaves no file behind."""
    from ..execution import BackendError, Terminated, execute_specs, sigterm_as_interrupt
    from ..store import StoreError, check_path, open_store

    existed = db_path.exists()
    try:
        with sigterm_as_interrupt():
            executor.connect()  # an unreachable scheduler is refused before the database is made
            if not existed:  # workers first: a backend that cannot start leaves no new database behind
                check_path(db_path)
                executor.start(len({spec.hash() for spec in specs}))
            try:
                with open_store(db_path) as store:
                    store.check_usable()
                    if not existed:  # say where it is, and how to choose another
                        hint = " (choose another with --db or $FDBENCH_DB)" if default_db else ""
                        say(quiet, f"creating results database {db_path}{hint}")
                    with Progress(quiet, "runs") as progress:

                        def on_done(done, total):
                            if progress.bar is None:
                                progress.start(total, show_best=False)
                            progress.update(done)

                        return execute_specs(specs, store, executor, rerun, on_done)
            finally:
                executor.stop()
    except StoreError as exc:
        raise BadInput(f"--db: {exc}") from None
    except BackendError as exc:
        raise BadInput(str(exc)) from None
    except Terminated:
        error("terminated")
        raise typer.Exit(143) from None


def _peer_names(text: Optional[str]) -> list:
    """The peers of --peers (none without it); an unknown one is bad input listing the valid."""
    if text is None:
        return []
    from ..peers import parse_names

    try:
        return parse_names(text)
    except ValueError as exc:
        raise BadInput(str(exc)) from None


def _check_peers_available() -> None:
    """Refuse --peers, before any run, where the opensim package cannot be imported."""
    from ..peers import check_available

    try:
        check_available()
    except ValueError as exc:
        raise BadInput(str(exc)) from None


def _report_text(fmt, plan, runs, rows, extra_rows, methods, inverse, inverse_runtime, seeds, jobs, figures, output,
                 quiet, peers_found=None) -> str:
    from ..report import settings_table

    peer_methods, peer_rows = peers_found or ([], [])
    if fmt == "csv":
        from ..report.methods import beyond_csv_rows
        from ..files import csv_text
        from ..report.peers import peer_csv_rows
        from ..report import CSV_COLUMNS, csv_rows

        return csv_text(list(CSV_COLUMNS), csv_rows(rows) + beyond_csv_rows(extra_rows) + peer_csv_rows(peer_rows))
    if fmt == "json":
        from ..report import json_report

        report = json_report(rows + extra_rows + peer_rows, settings_table(plan, seeds, jobs))
        if peer_rows:
            from ..report.peers import with_peer_fields

            with_peer_fields(report["cells"], peer_rows, rows + extra_rows)
        return json.dumps(report, indent=2) + "\n"
    from ..report.methods import beyond_markdown
    from ..report import markdown

    links = None
    if figures is not None:
        from ..figures import write_report_figures

        from ..files import new_folder

        with new_folder(figures):  # removed again if a figure cannot be written
            links = write_report_figures(plan, runs, rows, inverse, figures,
                                         output.parent if output is not None else Path("."))
        say(quiet, f"wrote {len(links)} figures to {figures}")
    section = beyond_markdown(extra_rows, methods) if methods else None
    if peer_rows:
        from ..report.peers import peers_markdown

        section = (section or []) + peers_markdown(peer_rows, peer_methods, rows + extra_rows)
    return markdown(rows, inverse, inverse_runtime, settings_table(plan, seeds, jobs), links, beyond=section,
                    extra_rows=extra_rows + peer_rows)


def _check_figures_dir(directory: Path, output: Optional[Path], db: Path, inputs: dict, names=None) -> None:
    """Refuse, before the work, a --figures folder that cannot take the figures: a file, a link
    to a missing folder, the report's own output, the database's journal, a missing parent, an
    unwritable folder, or a figure file in it that would be refused (read-only, a directory, the
    database, an input of the command, by any name)."""
    from ..figures import FIGURE_FILES
    from ..files import BadFile, check_distinct, check_writable, same_file

    if directory.exists() and not directory.is_dir():
        raise BadInput(f"--figures: {directory} exists and is not a directory")
    if directory.is_symlink() and not directory.exists():
        raise BadInput(f"--figures: {directory} is a symbolic link to {os.readlink(directory)}, which does not exist; "
                       "create that folder or choose another")
    if output is not None and same_file(directory, output):
        raise BadInput(f"--figures: {directory} is also the report's --output; give the figures a folder of their own")
    try:
        check_distinct({"--figures": directory}, inputs, db)  # a new folder named as the database's journal
    except BadFile as exc:
        raise BadInput(str(exc)) from None
    if not directory.exists():
        if not directory.parent.is_dir():
            raise BadInput(f"--figures: directory {directory.parent} does not exist")
        if not os.access(directory.parent, os.W_OK):
            raise BadInput(f"--figures: directory {directory.parent} is not writable")
        return
    if not os.access(directory, os.W_OK):
        raise BadInput(f"--figures: directory {directory} is not writable")
    try:
        paths = {f"--figures ({name})": directory / name for name in (names or FIGURE_FILES)}
        for option, path in paths.items():
            check_writable(path, option)
        check_distinct({"--output": output, **paths}, inputs, db)
    except BadFile as exc:
        raise BadInput(str(exc)) from None
