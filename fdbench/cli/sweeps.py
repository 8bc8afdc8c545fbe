"""Commands that carry out many runs through an execution backend and the results store:
report and study."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from .app import SWEEP_FORMATS, BadInput, app, bad_input, error
from .common import (
    Progress, check_choice, check_count, check_gradient, check_outputs, emit, given, say, shooting_methods, validated,
    with_option, wrote,
)
from .conditions import spec_inputs, with_conditions
from .options import (
    Cells, Execution, Kinematics, MethodValues, Optimisation, Output, Quiet, Simulation, methods_command, option_group,
    with_groups,
)

SWEEP_METHODS = ("torques", "optimizers", "controllers:pd")  # the method options of a study
REPORT_METHODS = SWEEP_METHODS[:2] + ("controllers:pd,cmc",)  # and of a report: computed muscle control's too
CMC_OPTIONS = ("window", "reserve_optimal_force", "tendons")  # the report's options of computed muscle control
MAX_SEEDS = 1000  # runs per cell of a report
MAX_JOBS = 256  # worker processes


@option_group(None)
class Batch:
    """What a report or a study runs, where it carries the runs out and where it writes."""

    output: Output = None
    quiet: Quiet = False
    kinematics: Kinematics = None
    selection: Cells = None
    optim: Optimisation = None
    run: Execution = None
    sim: Simulation = None

    def check(self, fmt: str, conditions: dict) -> dict:
        """--format and --output checked before any work; returns the command's input files."""
        inputs = spec_inputs(conditions, self.kinematics)
        check_outputs(fmt, SWEEP_FORMATS, db=self.run.db_path, output=self.output, inputs=inputs)
        return inputs

    @property
    def base(self) -> Path:
        """The folder of --output (links to figures are relative to it)."""
        return self.output.parent if self.output is not None else Path(".")

    def fields(self, conditions: dict) -> dict:
        """The RunSpec fields of every run on the motion under ``conditions``."""
        return self.sim.spec_fields(self.kinematics, conditions)

    def cells(self, torques, optimizers) -> list:
        """The paper's cells of --torque, --opt, --feedforward and --all-cells."""
        from ..report.paper_methods import default_cells

        return default_cells(torques, optimizers, self.selection.feedforward, self.selection.all_cells)

    def wrote(self, runs: int) -> None:
        wrote(self.output, self.quiet, f"{runs} runs, database {self.run.db_path}")

    def carry_out(self, specs, executor) -> dict:
        """Make sure every spec is stored in the database (missing runs carried out by the backend,
        each stored as it finishes), with a progress bar; {spec hash: stored run}. An unusable
        database or backend is bad input; SIGTERM ends the command like Ctrl-C, exit 143. A new
        database is created only once the backend has its workers: a refused or unreachable
        backend leaves no file behind."""
        from ..execution import Terminated, execute_specs, sigterm_as_interrupt
        from ..store import check_path, open_store

        db_path = self.run.db_path
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
                            hint = " (choose another with --db or $FDBENCH_DB)" if self.run.db is None else ""
                            say(self.quiet, f"creating results database {db_path}{hint}")
                        with Progress(self.quiet, "runs") as progress:

                            def on_done(done, total):
                                if progress.bar is None:
                                    progress.start(total, show_best=False)
                                progress.update(done)

                            return execute_specs(specs, store, executor, self.run.rerun, on_done)
                finally:
                    executor.stop()
        except Terminated:
            error("terminated")
            raise typer.Exit(143) from None

    def provenance(self, runs: dict) -> dict:
        """Where, when and by what each stored run was made."""
        from ..store import open_store

        with open_store(self.run.db_path) as store:
            return store.provenance(runs)


@app.command(cls=methods_command(*REPORT_METHODS))
@with_conditions
@with_groups
def report(
    ctx: typer.Context,
    beyond: Annotated[bool, typer.Option("--beyond/--no-beyond", help="Include the table 'Beyond the paper': computed-torque and LQR control, direct collocation, and on a model with muscles computed muscle control with a table of the muscles (on a model with a floating base: --no-beyond leaves out its slow collocation row).")] = True,
    peers: Annotated[Optional[str], typer.Option("--peers", metavar="opensim,opensim-cmc,moco", help="Add the section 'Peers': opensim (OpenSim's forward simulation under the same PD law), opensim-cmc (OpenSim's CMCTool), moco (MocoTrack, muscle-driven on a model with muscles, replayed by fdbench), comma-separated. Needs pip install 'fdbench\\[opensim]'.", show_default=False)] = None,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per cell, in [1, 1000]: seeds 0..N-1; medians and IQRs over them.")] = 5,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write PNG figures into DIR (created if missing) and link them.")] = None,
    fmt: Annotated[str, typer.Option("--format", "-f", help="Report format: md (Markdown), csv (one row per cell) or json (settings and cells with medians, IQRs, success counts and the ids of their stored runs).")] = "md",
    batch: Batch = None,
    flags: MethodValues = None,
    conditions: dict = None,
):
    """The paper's whole comparison: PD control, Table 2 and Table 3, with our figures beside the published ones, as Markdown, CSV or JSON.

    Every run is stored in the results database; stored runs are reused, so an interrupted report resumes and a repeated one returns at once. On a model with a floating base (a recorded walk, with --loads) it gives the walk's comparison instead: one run per method, the same methods on the forearm, the paper's claim tested; --torque, --opt, --feedforward or --all-cells add the paper's cells on the model."""
    from ..report.paper_methods import make_plan

    from ..report.comparison import has_floating_base

    inputs = batch.check(fmt, conditions)
    with bad_input():
        floating = has_floating_base(conditions["model_name"], conditions.get("model", ()))
    if floating:  # compared with the forearm (report.comparison)
        return _comparison_report(ctx, conditions, batch, flags, beyond=beyond, peers=peers, seeds=seeds,
                                  figures=figures, fmt=fmt, inputs=inputs)
    if figures is not None:
        _check_figures_dir(figures, batch, inputs)
    cells, torque_options, optimizer_options, executor = _selected(ctx, seeds, batch, flags)
    optim, control, (kp, kd) = batch.optim, batch.selection.control, _gains(flags)
    if not cells and not control and not beyond and not peers:
        raise BadInput("nothing to run: the options select no cell, --no-control and --no-beyond")
    fields = batch.fields(conditions)
    plan = make_plan(cells, seeds, optim.budget, control, kp, kd, torque_options=torque_options,
                     optimizer_options=optimizer_options, penalty_weight=optim.penalty_weight, **fields)
    # Tables 2 and 3 keep the paper's finite differences; exact gradients go to "Beyond the paper"
    for spec in ([plan.control] if plan.control else []) + [plan.specs[c][0] for c in plan.cells]:
        validated(spec)
    from ..report.methods import Options, beyond_methods, exact_gradient_methods

    cmc = _cmc_options(flags)
    methods, skipped = beyond_methods(Options(budget=optim.budget, cmc=cmc), **fields) if beyond else (None, [])
    _check_cmc_options(cmc, methods or [])
    if optim.gradient == "exact":
        methods = (methods or []) + exact_gradient_methods(plan.cells, optim.budget, torque_options,
                                                           optimizer_options, optim.penalty_weight, **fields)
        for method in methods:
            validated(method.spec)
    peer_methods = _peer_methods(peers, kp, kd, fields)
    extra = [m.spec for m in methods or []] + [m.spec for m in peer_methods]
    runs = batch.carry_out(plan.all_specs() + extra, executor)
    from ..report import build_rows
    from ..report.methods import rows as method_rows
    from ..report.peers import peer_rows

    start = time.perf_counter()
    inverse = (plan.control or plan.all_specs()[0]).reference()
    inverse_runtime = time.perf_counter() - start
    made = batch.provenance(runs)
    rows = build_rows(plan, runs, made)
    extra_rows = method_rows(methods, runs, made) if methods else []
    peers_found = (peer_methods, peer_rows(peer_methods, runs, made)) if peer_methods else None
    emit(_report_text(fmt, plan, runs, rows, extra_rows, methods, inverse, inverse_runtime, seeds,
                      executor.describe(), figures, batch, peers_found, skipped), batch.output)
    batch.wrote(len(runs))


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
    batch: Batch = None,
    flags: MethodValues = None,
    conditions: dict = None,
):
    """Sweep one condition over the methods: 'fdbench study noise --levels 0,0.25,0.5,1,2 --seeds 10' or 'fdbench study mismatch --param I1 --levels -20,-10,0,10,20'.

    Runs are stored and reused like a report's (resume, --jobs, --rerun); the table gives the median and IQR of each indicator per method and level."""
    from .. import study as studies

    check_choice("study", kind, studies.KINDS)
    inputs = batch.check(fmt, conditions)
    if not levels:
        raise BadInput("--levels: give the levels to sweep, e.g. --levels " + ("0,0.5,1,2" if kind == "noise" else "-20,0,20"))
    with bad_input():
        parsed = studies.parse_levels(levels, kind)
    if kind == "noise" and conditions["noise_deg"]:
        raise BadInput("--noise-deg: the noise study sets the noise itself (--levels)")
    if kind == "mismatch":
        from ..models import model_keys

        check_choice("--param", param, model_keys(conditions["model_name"]))
        if param in dict(conditions.get("plant") or ()):
            raise BadInput(f"--plant: the mismatch study sets {param} itself (--param, --levels); leave {param} out "
                           "of --plant")
    if figures is not None:
        _check_figures_dir(figures, batch, inputs, studies.FIGURE_NAMES)
    cells, torque_options, optimizer_options, executor = _selected(ctx, seeds, batch, flags)
    optim, control, (kp, kd) = batch.optim, batch.selection.control, _gains(flags)
    if not cells and not control:
        raise BadInput("nothing to run: the options select no cell and --no-control")
    with bad_input(wording=with_option):
        sweep = studies.make_sweep(kind, parsed, seeds, cells, control, kp, kd, optim.budget, torque_options,
                                   optimizer_options, optim.penalty_weight, param if kind == "mismatch" else None,
                                   gradient=optim.gradient, **batch.fields(conditions))
    for key in sweep.specs:
        validated(sweep.specs[key][0])
    runs = batch.carry_out(sweep.all_specs(), executor)
    rows = studies.summary(sweep, runs)
    if fmt == "csv":
        from ..files import csv_text

        text = csv_text(list(studies.CSV_COLUMNS), studies.csv_rows(sweep, rows))
    else:
        settings = studies.settings(sweep, seeds, optim.budget, executor.describe(), batch.kinematics,
                                    batch.sim.integrator, batch.sim.dt)
        if fmt == "json":
            text = studies.json_text(sweep, rows, settings)
        else:
            links = None if figures is None else _write_figures(figures, batch, lambda base: {
                title: os.path.relpath(path, base) for title, path in studies.write_figures(sweep, rows, figures).items()})
            text = studies.markdown(sweep, rows, settings, links)
    emit(text, batch.output)
    batch.wrote(len(sweep.all_specs()))


def _gains(flags: MethodValues) -> tuple:
    """The PD gains (kp, kd) of the command's --kp and --kd (None: the default)."""
    return flags["controllers"].get("kp"), flags["controllers"].get("kd")


def _comparison_report(ctx, conditions: dict, batch: Batch, flags: MethodValues, *, beyond: bool, peers, seeds: int,
                       figures, fmt: str, inputs: dict) -> None:
    """The report of a model with a floating base: the registered methods on it and on the
    forearm (``report.comparison``); the paper's cells on it when --torque, --opt, --feedforward or
    --all-cells select them; checked, planned, run (stored and resumed), written."""
    from ..figures import MODEL_FIGURE_FILES
    from ..report import comparison
    from ..report.methods import FLOATING_BASE_PENALTY, SHOOTING_POPSIZE, Options, exact_gradient_methods
    from ..report.paper_methods import make_plan
    from .conditions import warn_opensim

    if figures is not None:
        _check_figures_dir(figures, batch, inputs, MODEL_FIGURE_FILES)
    cells, torque_options, optimizer_options, executor = _selected(ctx, seeds, batch, flags)
    optim, (kp, kd), popsize = batch.optim, _gains(flags), flags["optimizers"].get("popsize")
    weight = optim.penalty_weight if given(ctx, "penalty_weight") else FLOATING_BASE_PENALTY
    options = Options(optim.budget, SHOOTING_POPSIZE if popsize is None else popsize, flags["optimizers"].get("sigma0"),
                      flags["torques"].get("knots"), kp, kd, _cmc_options(flags))
    studied, forearm = batch.fields(conditions), batch.sim.spec_fields("paper", None)
    with bad_input(wording=with_option):
        plan = comparison.make_plan(studied, forearm, options, collocation=beyond, control=batch.selection.control,
                                    penalty_weight=weight)
        if any(given(ctx, name) for name in ("torque", "opt", "feedforward", "all_cells")):
            common = plan.datasets[0].common
            plan.cells = make_plan(cells, seeds, optim.budget, False, kp, kd, torque_options=torque_options,
                                   optimizer_options=optimizer_options, penalty_weight=weight, **common)
            if optim.gradient == "exact":
                plan.extra = exact_gradient_methods(cells, optim.budget, torque_options, optimizer_options, weight,
                                                    **common)
    _check_cmc_options(options.cmc, plan.studied)
    for spec in plan.all_specs():
        validated(spec)
    peer_methods = _peer_methods(peers, kp, kd, plan.datasets[0].common)
    specs = plan.all_specs() + [m.spec for m in peer_methods]
    warn_opensim(conditions["model_name"], batch.kinematics, batch.quiet)  # the import's notes before the work
    runs = batch.carry_out(specs, executor)
    found = comparison.report_rows(plan, runs, batch.provenance(runs), peer_methods)
    text, written = comparison.text(fmt, plan, found, runs, executor.describe(), figures, batch.base,
                                    getattr(executor, "jobs", 1), peer_methods, seeds)
    if figures is not None and fmt == "md":
        say(batch.quiet, f"wrote {written} figures to {figures}")
    emit(text, batch.output)
    batch.wrote(len(runs))


def _cmc_options(flags: MethodValues) -> tuple:
    """Computed muscle control's options given (--window, --reserve-optimal-force, --tendons), as
    sorted (name, value) pairs, checked: a bad value is bad input."""
    from ..controllers import make_controller

    given = tuple(sorted((name, value) for name, value in flags["controllers"].items()
                         if name in CMC_OPTIONS and value is not None))
    with bad_input(wording=with_option):
        make_controller("cmc", **dict(given))
    return given


def _check_cmc_options(given: tuple, methods) -> None:
    """Refuse computed muscle control's options where the report runs no CMC (a model without muscles)."""
    from ..report.methods import CMC

    if given and not any(method.key == CMC for method in methods):
        names = ", ".join("--" + name.replace("_", "-") for name, _ in given)
        raise BadInput(f"{names}: computed muscle control's options, and this report runs no computed muscle control "
                       "(a model without muscles, or --no-beyond)")


def _peer_methods(text: Optional[str], kp, kd, common: dict) -> list:
    """The peers of --peers (none without it) as methods on the settings ``common`` with the
    report's PD gains, checked: an unknown peer is bad input listing the valid, and so are peers
    where the opensim package cannot be imported."""
    if text is None:
        return []
    from ..peers import check_available, parse_names
    from ..report.peers import peer_methods

    with bad_input(wording=with_option):
        methods = peer_methods(parse_names(text), kp, kd, **common)
    for method in methods:
        validated(method.spec)
    with bad_input():
        check_available()
    return methods


def _selected(ctx, seeds: int, batch: Batch, flags: MethodValues) -> tuple:
    """The checks shared by report and study before any work; returns the paper's cells selected,
    the torque and optimiser options of their cells and the execution backend."""
    check_count("--seeds", seeds, MAX_SEEDS)
    check_count("--jobs", batch.run.jobs, MAX_JOBS)
    torques, optimizers, torque_options, optimizer_options = shooting_methods(
        ctx, batch.selection.torque, batch.selection.opt, flags, batch.optim.penalty_weight)
    check_gradient(batch.optim.gradient, optimizers)
    return batch.cells(torques, optimizers), torque_options, optimizer_options, batch.run.executor()


def _write_figures(figures: Path, batch: Batch, write) -> dict:
    """The figures written into the folder ``figures`` by ``write(base)``, which returns their
    links relative to ``base`` (the folder of --output); the folder is removed again if one fails."""
    from ..files import new_folder

    with new_folder(figures):
        links = write(batch.base)
    say(batch.quiet, f"wrote {len(links)} figures to {figures}")
    return links


def _report_text(fmt, plan, runs, rows, extra_rows, methods, inverse, inverse_runtime, seeds, jobs, figures,
                 batch: Batch, peers_found=None, skipped=()) -> str:
    from ..report import CSV_COLUMNS, csv_rows, json_report, markdown, settings_table
    from ..report.methods import beyond_csv_rows, beyond_markdown
    from ..report.peers import peer_csv_rows, peers_markdown, with_peer_fields

    peer_methods, peer_rows = peers_found or ([], [])
    if fmt == "csv":
        from ..files import csv_text

        return csv_text(list(CSV_COLUMNS), csv_rows(rows) + beyond_csv_rows(extra_rows) + peer_csv_rows(peer_rows))
    if fmt == "json":
        report = json_report(rows + extra_rows + peer_rows, settings_table(plan, seeds, jobs))
        if peer_rows:
            with_peer_fields(report["cells"], peer_rows, rows + extra_rows)
        return json.dumps(report, indent=2) + "\n"
    links = None
    if figures is not None:
        from ..figures import write_activations_figure, write_report_figures

        links = _write_figures(figures, batch, lambda base: {
            **write_report_figures(plan, runs, rows, inverse, figures, base),
            **write_activations_figure(extra_rows, runs, figures, base)})
    section = beyond_markdown(extra_rows, methods, skipped) if methods else None
    if peer_rows:
        section = (section or []) + peers_markdown(peer_rows, peer_methods, rows + extra_rows)
    return markdown(rows, inverse, inverse_runtime, settings_table(plan, seeds, jobs), links, beyond=section,
                    extra_rows=extra_rows + peer_rows)


def _check_figures_dir(directory: Path, batch: Batch, inputs: dict, names=None) -> None:
    """Refuse, before the work, a --figures folder that cannot take the figures: a file, a link
    to a missing folder, the report's own output, the database's journal, a missing parent, an
    unwritable folder, or a figure file in it that would be refused (read-only, a directory, the
    database, an input of the command, by any name)."""
    from ..figures import REPORT_FIGURE_FILES
    from ..files import check_distinct, check_own_file, check_writable, same_file

    output, db = batch.output, batch.run.db_path
    if directory.exists() and not directory.is_dir():
        raise BadInput(f"--figures: {directory} exists and is not a directory")
    if directory.is_symlink() and not directory.exists():
        raise BadInput(f"--figures: {directory} is a symbolic link to {os.readlink(directory)}, which does not exist; "
                       "create that folder or choose another")
    if output is not None and same_file(directory, output):
        raise BadInput(f"--figures: {directory} is also the report's --output; give the figures a folder of their own")
    check_distinct({"--figures": directory}, inputs, db)  # a new folder named as the database's journal
    if not directory.exists():
        if not directory.parent.is_dir():
            raise BadInput(f"--figures: directory {directory.parent} does not exist")
        if not os.access(directory.parent, os.W_OK):
            raise BadInput(f"--figures: directory {directory.parent} is not writable")
        return
    if not os.access(directory, os.W_OK):
        raise BadInput(f"--figures: directory {directory} is not writable")
    paths = {f"--figures ({name})": directory / name for name in (names or REPORT_FIGURE_FILES)}
    for option, path in paths.items():
        check_writable(path, option)
    check_distinct({"--output": output, **paths}, inputs, db)
    for option, path in paths.items():  # after the refusals that name an input or the database
        check_own_file(path, option)
