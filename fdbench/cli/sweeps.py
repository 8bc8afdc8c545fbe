"""Commands that carry out many runs through an execution backend and the results store:
report and study."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from .. import __version__
from .app import BadInput, MAX_JOBS, MAX_SEEDS, REPORT_FORMATS, STUDY_FORMATS, _error, app
from .options import (
    AllCells, Alpha, Atol, BackendName, Budget, Dt, FeedforwardSelection, Gradient, Hidden, Integrator, Jobs,
    Kd, Kinematics, Knots, Kp, Omega, OptSelection, Output, PenaltyWeight, Popsize, Quiet, Rerun, Rtol,
    Scheduler, Sigma0, StoreDb, Terms, TorqueSelection, WithControl, Xi, _common, _spec_inputs,
    _with_conditions,
)
from .common import (
    _bracketed_all, _check_choice, _check_finite, _check_gradient, _check_method_options, _check_names, _check_outputs, _emit,
    _parse_hidden, _progress, _say, _validated, _with_option,
)


@app.command()
@_with_conditions
def report(
    ctx: typer.Context,
    torque: TorqueSelection = None,
    opt: OptSelection = None,
    feedforward: FeedforwardSelection = None,
    control: WithControl = True,
    beyond: Annotated[bool, typer.Option("--beyond/--no-beyond", help="Include the table 'Beyond the paper': computed-torque and LQR control, direct collocation (on a model with a floating base: --no-beyond leaves out its slow collocation row).")] = True,
    all_cells: AllCells = False,
    peers: Annotated[Optional[str], typer.Option("--peers", metavar="opensim,opensim-cmc,moco", help="Add the section 'Peers': opensim (OpenSim's forward simulation under the same PD law), opensim-cmc (OpenSim's CMCTool), moco (MocoTrack, its torque replayed by fdbench), comma-separated. Needs pip install 'fdbench\\[opensim]'.", show_default=False)] = None,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per cell, in [1, 1000]: seeds 0..N-1; medians and IQRs over them.")] = 5,
    budget: Budget = 200,
    jobs: Jobs = None,
    backend: BackendName = "local",
    scheduler: Scheduler = None,
    db: StoreDb = None,
    rerun: Rerun = False,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write PNG figures into DIR (created if missing) and link them.")] = None,
    kp: Kp = None,
    kd: Kd = None,
    hidden: Hidden = "4",
    knots: Knots = None,
    terms: Terms = 4,
    sigma0: Sigma0 = None,
    popsize: Popsize = None,
    gradient: Gradient = "fd",
    penalty_weight: PenaltyWeight = 1.0,
    kinematics: Kinematics = None,
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Annotated[str, typer.Option("--format", "-f", help="Report format: md (Markdown), csv (one row per cell) or json (settings and cells with medians, IQRs, success counts and the ids of their stored runs).")] = "md",
    output: Output = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """The paper's whole comparison: PD control, Table 2 and Table 3, with our figures beside the published ones, as Markdown, CSV or JSON.

    Every run is stored in the results database; stored runs are reused, so an interrupted report resumes and a repeated one returns at once. On a model with a floating base (a recorded walk, with --loads) it gives the walk's comparison instead: one run per method, the same methods on the forearm, the paper's claim tested; --torque, --opt, --feedforward or --all-cells add the paper's cells on the model."""
    from ..report.paper_methods import default_cells, make_plan
    from ..store import default_path

    db_path = db if db is not None else default_path()
    inputs = _spec_inputs(conditions, kinematics)
    _check_outputs(fmt, REPORT_FORMATS, db=db_path, output=output, inputs=inputs)
    if _floating_base(conditions):  # compared with the forearm (report.comparison)
        return _comparison_report(
            ctx, conditions=conditions, torque=torque, opt=opt, feedforward=feedforward, control=control,
            beyond=beyond, all_cells=all_cells, peers=peers, seeds=seeds, budget=budget, jobs=jobs, backend=backend,
            scheduler=scheduler, db=db, db_path=db_path, inputs=inputs, rerun=rerun, figures=figures, kp=kp, kd=kd,
            hidden=hidden, knots=knots, terms=terms, sigma0=sigma0, popsize=popsize, gradient=gradient,
            penalty_weight=penalty_weight, kinematics=kinematics, integrator=integrator, dt=dt, rtol=rtol, atol=atol,
            alpha=alpha, xi=xi, omega=omega, fmt=fmt, output=output, quiet=quiet)
    if figures is not None:
        _check_figures_dir(figures, output, db_path, inputs)
    torque, opt, torque_options, optimizer_options = _sweep_options(ctx, seeds, jobs, torque, opt, hidden, knots, terms,
                                                                    sigma0, popsize, penalty_weight)
    executor = _backend(backend, jobs, scheduler)
    cells = default_cells(torque, opt, feedforward, all_cells)
    if not cells and not control and not beyond and not peers:
        raise BadInput("nothing to run: the options select no cell, --no-control and --no-beyond")
    _check_gradient(gradient, opt)
    peer_names = _peer_names(peers)
    plan = make_plan(
        cells, seeds, budget, control, kp, kd, torque_options=torque_options,
        optimizer_options=optimizer_options, penalty_weight=penalty_weight,
        **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions),
    )  # Tables 2 and 3 keep the paper's finite differences; exact gradients go to "Beyond the paper"
    for spec in ([plan.control] if plan.control else []) + [plan.specs[c][0] for c in plan.cells]:
        _validated(spec)
    from ..store import open_store

    methods = None
    if beyond:
        from ..report.methods import beyond_methods

        methods = beyond_methods(**_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions))
    if gradient == "exact":
        from ..report.methods import exact_gradient_methods

        methods = (methods or []) + exact_gradient_methods(
            plan.cells, budget, torque_options, optimizer_options, penalty_weight,
            **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions))
        for method in methods:
            _validated(method.spec)
    peer_methods = []
    if peer_names:
        from ..peers.report import peer_methods as make_peer_methods

        try:
            peer_methods = make_peer_methods(peer_names, kp, kd, **_common(kinematics, integrator, dt, rtol, atol,
                                                                          alpha, xi, omega, conditions))
        except ValueError as exc:
            raise BadInput(str(exc)) from None
        for method in peer_methods:
            _validated(method.spec)
        _check_peers_available()
    extra = ([m.spec for m in methods] if methods else []) + [m.spec for m in peer_methods]
    runs = _run_specs(plan.all_specs() + extra, db_path, db is None, executor, rerun, quiet)
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
        from ..peers.report import peer_rows

        peers_found = (peer_methods, peer_rows(peer_methods, runs, made))
    _emit(_report_text(fmt, plan, runs, rows, extra_rows, methods, inverse, inverse_runtime, seeds,
                       executor.describe(), figures, output, quiet, peers_found), output)
    if output is not None and str(output) != "-":
        _say(quiet, f"wrote {output} ({len(runs)} runs, database {db_path})")


@app.command()
@_with_conditions
def study(
    ctx: typer.Context,
    kind: Annotated[str, typer.Argument(help="noise: the motion captured with white noise of each level (deg); mismatch: one constant of the simulated body changed by each level (percent) while the methods keep the nominal model.", metavar="noise|mismatch")],
    levels: Annotated[str, typer.Option("--levels", help="The levels, comma-separated: deg for noise (e.g. 0,0.25,0.5,1,2), percent for mismatch (e.g. -20,-10,0,10,20).")] = "",
    param: Annotated[str, typer.Option("--param", help="mismatch: the plant constant changed: L12, L1G, m, I1, F_ext or g (arm2 also L01, L0G, m0, I0; any model: a path such as thigh.mass, see 'fdbench models show').")] = "I1",
    torque: TorqueSelection = None,
    opt: OptSelection = None,
    feedforward: FeedforwardSelection = None,
    control: WithControl = True,
    all_cells: AllCells = False,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per method and level, in [1, 1000]: seeds 0..N-1 (the noise realisation and the optimiser's seed).")] = 5,
    budget: Budget = 200,
    jobs: Jobs = None,
    backend: BackendName = "local",
    scheduler: Scheduler = None,
    db: StoreDb = None,
    rerun: Rerun = False,
    figures: Annotated[Optional[Path], typer.Option("--figures", help="Write one PNG per indicator into DIR (created if missing): level on x, median and IQR band per method.")] = None,
    kp: Kp = None,
    kd: Kd = None,
    hidden: Hidden = "4",
    knots: Knots = None,
    terms: Terms = 4,
    sigma0: Sigma0 = None,
    popsize: Popsize = None,
    gradient: Gradient = "fd",
    penalty_weight: PenaltyWeight = 1.0,
    kinematics: Kinematics = None,
    integrator: Integrator = "rk4",
    dt: Dt = 1e-3,
    rtol: Rtol = 1e-6,
    atol: Atol = 1e-9,
    alpha: Alpha = 1e7,
    xi: Xi = 1.0,
    omega: Omega = 10.0,
    fmt: Annotated[str, typer.Option("--format", "-f", help="md (tables per indicator), csv (one row per method and level) or json (the settings and those rows).")] = "md",
    output: Output = None,
    quiet: Quiet = False,
    conditions: dict = None,
):
    """Sweep one condition over the methods: 'fdbench study noise --levels 0,0.25,0.5,1,2 --seeds 10' or 'fdbench study mismatch --param I1 --levels -20,-10,0,10,20'.

    Runs are stored and reused like a report's (resume, --jobs, --rerun); the table gives the median and IQR of each indicator per method and level."""
    from .. import study as studies
    from ..report.paper_methods import default_cells
    from ..store import default_path

    _check_choice("study", kind, studies.KINDS)
    db_path = db if db is not None else default_path()
    inputs = _spec_inputs(conditions, kinematics)
    _check_outputs(fmt, STUDY_FORMATS, db=db_path, output=output, inputs=inputs)
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

        _check_choice("--param", param, model_keys(conditions["model_name"]))
    if figures is not None:
        _check_study_figures(figures, output, db_path, inputs)
    torque, opt, torque_options, optimizer_options = _sweep_options(ctx, seeds, jobs, torque, opt, hidden, knots, terms,
                                                                    sigma0, popsize, penalty_weight)
    executor = _backend(backend, jobs, scheduler)
    cells = default_cells(torque, opt, feedforward, all_cells)
    if not cells and not control:
        raise BadInput("nothing to run: the options select no cell and --no-control")
    _check_gradient(gradient, opt)
    try:
        sweep = studies.make_sweep(kind, parsed, seeds, cells, control, kp, kd, budget, torque_options,
                                   optimizer_options, penalty_weight, param if kind == "mismatch" else None,
                                   gradient=gradient,
                                   **_common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions))
    except ValueError as exc:
        raise BadInput(_with_option(str(exc))) from None
    for key in sweep.specs:
        _validated(sweep.specs[key][0])
    runs = _run_specs(sweep.all_specs(), db_path, db is None, executor, rerun, quiet)
    rows = studies.summary(sweep, runs)
    if fmt == "csv":
        from ..files import csv_text

        _emit(csv_text(list(studies.CSV_COLUMNS), studies.csv_rows(sweep, rows)), output)
    elif fmt == "json":
        settings = _study_settings(sweep, seeds, budget, executor.describe(), kinematics, integrator, dt)
        _emit(_study_json(sweep, rows, settings), output)
    else:
        links = None
        if figures is not None:
            from ..files import new_folder

            with new_folder(figures):  # removed again if a figure cannot be written
                written = studies.write_figures(sweep, rows, figures)
            base = output.parent if output is not None else Path(".")
            links = {title: os.path.relpath(path, base) for title, path in written.items()}
            _say(quiet, f"wrote {len(written)} figures to {figures}")
        settings = _study_settings(sweep, seeds, budget, executor.describe(), kinematics, integrator, dt)
        _emit(studies.markdown(sweep, rows, settings, links), output)
    if output is not None and str(output) != "-":
        _say(quiet, f"wrote {output} ({len(sweep.all_specs())} runs, database {db_path})")


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


def _comparison_report(ctx, *, conditions, torque, opt, feedforward, control, beyond, all_cells, peers, seeds, budget,
                       jobs, backend, scheduler, db, db_path, inputs, rerun, figures, kp, kd, hidden, knots, terms,
                       sigma0, popsize, gradient, penalty_weight, kinematics, integrator, dt, rtol, atol, alpha, xi,
                       omega, fmt, output, quiet) -> None:
    """The report of a model with a floating base: the registered methods on it and on the
    forearm (``report.comparison``); the paper's cells on it when --torque, --opt, --feedforward or
    --all-cells select them; checked, planned, run (stored and resumed), written."""
    from ..figures import MODEL_FIGURE_FILES
    from ..report import comparison
    from ..report.methods import FLOATING_BASE_PENALTY, SHOOTING_POPSIZE, Options, exact_gradient_methods
    from ..report.paper_methods import default_cells, make_plan
    from .options import _warn_opensim

    if figures is not None:
        _check_figures_dir(figures, output, db_path, inputs, MODEL_FIGURE_FILES)
    torque, opt, torque_options, optimizer_options = _sweep_options(ctx, seeds, jobs, torque, opt, hidden, knots, terms,
                                                                    sigma0, popsize, penalty_weight)
    _check_gradient(gradient, opt)
    executor = _backend(backend, jobs, scheduler)
    weight = penalty_weight if _given(ctx, "penalty_weight") else FLOATING_BASE_PENALTY
    options = Options(budget, SHOOTING_POPSIZE if popsize is None else popsize, sigma0, knots, kp, kd)
    studied = _common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)
    forearm = _common("paper", integrator, dt, rtol, atol, alpha, xi, omega, None)
    selected = any(_given(ctx, name) for name in ("torque", "opt", "feedforward", "all_cells"))
    try:
        plan = comparison.make_plan(studied, forearm, options, collocation=beyond, control=control,
                                    penalty_weight=weight)
        if selected:
            cells = default_cells(torque, opt, feedforward, all_cells)
            common = plan.datasets[0].common
            plan.cells = make_plan(cells, seeds, budget, False, kp, kd, torque_options=torque_options,
                                   optimizer_options=optimizer_options, penalty_weight=weight, **common)
            if gradient == "exact":
                plan.extra = exact_gradient_methods(cells, budget, torque_options, optimizer_options, weight, **common)
        peer_methods = _peer_methods(_peer_names(peers), kp, kd, plan.datasets[0].common)
    except ValueError as exc:
        raise BadInput(_with_option(str(exc))) from None
    for spec in plan.all_specs() + [m.spec for m in peer_methods]:
        _validated(spec)
    if peer_methods:
        _check_peers_available()
    _warn_opensim(conditions["model_name"], kinematics, quiet)  # the import's notes before the work, not after it
    runs = _run_specs(plan.all_specs() + [m.spec for m in peer_methods], db_path, db is None, executor, rerun, quiet)
    from ..store import open_store

    with open_store(db_path) as store:
        made = store.provenance(runs)
    found = comparison.report_rows(plan, runs, made, peer_methods)
    base = output.parent if output is not None and str(output) != "-" else Path(".")
    text, written = comparison.text(fmt, plan, found, runs, executor.describe(), figures, base,
                                    getattr(executor, "jobs", 1), peer_methods, seeds)
    if figures is not None and fmt == "md":
        _say(quiet, f"wrote {written} figures to {figures}")
    _emit(text, output)
    if output is not None and str(output) != "-":
        _say(quiet, f"wrote {output} ({len(runs)} runs, database {db_path})")


def _peer_methods(names: list, kp, kd, common: dict) -> list:
    """The peers ``names`` as methods on the settings ``common`` with the report's PD gains."""
    if not names:
        return []
    from ..peers.report import peer_methods

    return peer_methods(names, kp, kd, **common)


def _study_json(sweep, rows, settings: dict) -> str:
    """The study as one JSON object: its settings and one object per method and level with the
    CSV's columns (null for a statistic no run gave)."""
    from .. import study as studies
    from ..files import finite_or_none

    table = [{name: finite_or_none(value.item() if hasattr(value, "item") else value)
              for name, value in zip(studies.CSV_COLUMNS, row)} for row in studies.csv_rows(sweep, rows)]
    return json.dumps({"settings": settings, "rows": table}, indent=2) + "\n"


def _study_settings(sweep, seeds, budget, carried_out: str, kinematics, integrator, dt) -> dict:
    """The study's settings table: what was swept, the conditions every run shares (model, its
    changes, the plant's, the motion and its digest, the estimate, the noise), the run settings."""
    from ..report import condition_settings
    from ..store import machine

    spec = sweep.all_specs()[0]
    described = spec.describe()
    shared = condition_settings(spec, sweep.all_specs())
    shared.pop("RMSE_rot against", None)  # the study's introduction says it
    if sweep.kind == "noise":
        shared.pop("noise", None)  # the levels are the noise; the seeds are below
    else:
        from ..study import conditions

        shared.pop("plant", None)  # the swept constant is the level; other plant changes stay
        if conditions(sweep)["plant"]:
            shared["plant"] = f"{conditions(sweep)['plant']} (the simulated body only), then {sweep.param} by each level"
    return {
        "study": sweep.kind + (f" of {sweep.param}" if sweep.param else ""),
        "levels": ", ".join(f"{v:g}" for v in sweep.levels) + f" {'deg' if sweep.kind == 'noise' else '%'}",
        "model": spec.model_name + (f" ({described['model_options']})" if described.get("model_options") else ""),
        **shared,
        "motion": f"{kinematics} ({described['duration_s']:g} s, {described['samples']} samples)"
                  + (f", SHA-256 {dict(spec.inputs)['--motion'][:16]}" if dict(spec.inputs).get("--motion") else ""),
        "derivative estimate": ("Butterworth zero-lag, then spline" if spec.smoothing == "butterworth"
                                else "smoothing spline") + (f", cutoff {spec.cutoff_hz:g} Hz" if spec.smoothing == "butterworth" else ""),
        "integrator": integrator + (f" (dt = {dt} s)" if integrator == "rk4" else ""),
        "seeds": f"{seeds} per method and level (PD: one run where the runs would be identical)",
        "budget": f"{budget} evaluations per optimisation",
        "runs": str(len(sweep.all_specs())),
        "parallel jobs": carried_out,
        "fdbench": __version__,
        "machine": machine(),
    }


def _check_study_figures(directory: Path, output: Optional[Path], db: Path, inputs: dict) -> None:
    """As for the report's --figures: refuse before the work a folder that cannot take them."""
    from ..study import FIGURE_NAMES

    _check_figures_dir(directory, output, db, inputs, FIGURE_NAMES)


def _sweep_options(ctx, seeds, jobs, torques, optimizers, hidden, knots, terms, sigma0, popsize, penalty_weight):
    """The checks shared by the commands that run many specs (report, study), before any work;
    returns the torque and optimiser names (their NAME[KEY=VALUE,...] options taken out) and the
    (torque options, optimizer options) of their cells."""
    from ..optimizers import OPTIMIZERS
    from ..torques import TORQUES

    if not 1 <= seeds <= MAX_SEEDS:
        raise BadInput(f"--seeds must be an integer in [1, {MAX_SEEDS}], got {seeds}")
    if jobs is not None and not 1 <= jobs <= MAX_JOBS:
        raise BadInput(f"--jobs must be an integer in [1, {MAX_JOBS}], got {jobs}")
    _check_finite(sigma0=sigma0 if sigma0 is not None else 1.0, penalty_weight=penalty_weight)
    torques, torque_options = _bracketed_all(ctx, torques, "--torque", {"hidden": _parse_hidden(hidden), "knots": knots,
                                                                        "terms": terms}, TORQUES, "torque")
    optimizers, optimizer_options = _bracketed_all(ctx, optimizers, "--opt", {"sigma0": sigma0, "popsize": popsize},
                                                   OPTIMIZERS, "optimizer")
    _check_names(torques, optimizers)
    _check_method_options(torque_options, optimizer_options)
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
                    if not existed:
                        _say_creating(db_path, default_db, quiet)
                    with _progress(quiet, "runs") as progress:

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
        _error("terminated")
        raise typer.Exit(143) from None


def _say_creating(db_path: Path, default: bool, quiet: bool) -> None:
    """One line on stderr when a report has created its results database."""
    hint = " (choose another with --db or $FDBENCH_DB)" if default else ""
    _say(quiet, f"creating results database {db_path}{hint}")


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
        from ..peers.report import peer_csv_rows
        from ..report import CSV_COLUMNS, csv_rows

        return csv_text(list(CSV_COLUMNS), csv_rows(rows) + beyond_csv_rows(extra_rows) + peer_csv_rows(peer_rows))
    if fmt == "json":
        from ..report import json_report

        report = json_report(rows + extra_rows + peer_rows, settings_table(plan, seeds, jobs))
        if peer_rows:
            from ..peers.report import with_peer_fields

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
        _say(quiet, f"wrote {len(links)} figures to {figures}")
    section = beyond_markdown(extra_rows, methods) if methods else None
    if peer_rows:
        from ..peers.report import peers_markdown

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


def _backend(name: str, jobs: Optional[int], scheduler: Optional[str]):
    """The execution backend of --backend/--jobs/--scheduler, checked before any work."""
    from ..execution import BackendError, make_backend

    try:
        return make_backend(name, jobs=jobs, scheduler=scheduler)
    except BackendError as exc:
        raise BadInput(str(exc)) from None
