"""``fdbench report`` on a model with a floating base (a recorded walk): the walk's comparison
(``fdbench.walk``) instead of the paper's Tables 2 and 3."""

from __future__ import annotations

import json
import time
from pathlib import Path

from .. import __version__
from .app import BadInput

# report options that shape the paper's tables and have no meaning in the walk's report
NOT_FOR_THE_WALK = {"torque": "--torque", "opt": "--opt", "feedforward": "--feedforward", "all_cells": "--all-cells",
                    "seeds": "--seeds", "gradient": "--gradient", "hidden": "--hidden",
                    "knots": "--knots", "terms": "--terms", "sigma0": "--sigma0", "kp": "--kp", "kd": "--kd",
                    "penalty_weight": "--penalty-weight", "control": "--control/--no-control"}


def check_walk_options(ctx) -> None:
    """Refuse, in one line, the report options given that do not apply to the walk's report."""
    given = [option for name, option in NOT_FOR_THE_WALK.items() if _given(ctx, name)]
    if given:
        raise BadInput(f"{', '.join(given)}: not used by the report of a model with a floating base (one run per "
                       "method; its options: --budget, --popsize, --no-beyond, --peers, --figures, --jobs, --db, "
                       "--rerun, --format, --output)")


def _given(ctx, name: str) -> bool:
    """Whether the option ``name`` was given (on the command line or by an environment variable)."""
    return getattr(ctx.get_parameter_source(name), "name", None) in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def walk_report(ctx, *, conditions: dict, kinematics: str, integrator: str, dt: float, rtol: float, atol: float,
                alpha: float, xi: float, omega: float, budget: int, popsize, beyond: bool, executor, db, db_path: Path,
                rerun: bool, figures, fmt: str, output, quiet: bool, peers: str | None = None) -> None:
    """Carry out the walk's report: check, plan, run (stored and resumed), write; with ``peers``
    (--peers) the peers on the walk too, in a section of their own."""
    from .. import walk
    from .common import emit as _emit, say as _say, validated as _validated
    from .conditions import run_fields as _common, warn_opensim as _warn_opensim
    from .sweeps import _check_peers_available, _peer_names, _run_specs

    check_walk_options(ctx)
    popsize = walk.WALK_POPSIZE if popsize is None else popsize
    walk_common = _common(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions)
    forearm_common = _common("paper", integrator, dt, rtol, atol, alpha, xi, omega, None)
    try:
        plan = walk.make_plan(walk_common, forearm_common, budget, popsize, collocation=beyond)
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    peer_methods = _peer_methods(_peer_names(peers), walk.on_samples(walk_common))
    for spec in plan.all_specs() + [m.spec for m in peer_methods]:
        _validated(spec)
    if peer_methods:
        _check_peers_available()
    _warn_opensim(conditions["model_name"], kinematics, quiet)  # the import's notes before the work, not after it
    runs = _run_specs(plan.all_specs() + [m.spec for m in peer_methods], db_path, db is None, executor, rerun, quiet)
    from ..store import open_store

    with open_store(db_path) as store:
        made = store.provenance(runs)
    walk_rows, forearm_rows = walk.rows(plan.walk, runs, made), walk.rows(plan.forearm, runs, made)
    spec = plan.walk[0].spec
    inverse = spec.reference()
    text = _text(fmt, plan, walk_rows, forearm_rows, spec, inverse, runs, executor.describe(), figures, output, quiet,
                 getattr(executor, "jobs", 1), _peers_found(peer_methods, runs, made))
    _emit(text, output)
    if output is not None and str(output) != "-":
        _say(quiet, f"wrote {output} ({len(runs)} runs, database {db_path})")


def _peer_methods(names: list, common: dict) -> list:
    """The peers ``names`` as methods on the walk's settings ``common`` (its PD's gains); bad input
    in one line."""
    if not names:
        return []
    from ..peers.report import peer_methods

    try:
        return peer_methods(names, **common)
    except ValueError as exc:
        raise BadInput(str(exc)) from None


def _peers_found(methods: list, runs: dict, made: dict):
    """(methods, their report rows (table "peers")) of the peers run; None without peers."""
    if not methods:
        return None
    from ..peers.report import peer_rows

    return methods, peer_rows(methods, runs, made)


def _beside(walk_rows) -> list:
    """The walk's methods as report rows a peer stands beside (``peers.report.side_by_side``): PD
    control as the paper report's control row, open loop (PD with zero gains) left out."""
    from ..report import Row
    from ..walk import OPEN_LOOP

    return [Row(row.name, "control", None, {}, None, [row.record]) for row in walk_rows if row.key != OPEN_LOOP]


def _peer_walk_rows(peer_rows) -> list:
    """The peers' report rows as the walk's rows (for its CSV), keyed by the peer's name."""
    from ..walk import WalkRow

    return [WalkRow(row.records[0].get("peer"), row.name, row.records[0], row.specs[0], row.hashes[0],
                    row.provenance[0] if row.provenance else {}) for row in peer_rows]


def _peers_json(peer_rows, walk_rows) -> list:
    """The peers for the JSON report: per peer its name, label, hash and record, and beside the
    fdbench method it stands for ``vs_fdbench`` (and MocoTrack's ``vs_fdbench_solve``)."""
    from ..files import finite_or_none
    from ..peers.report import _plain, side_by_side

    pairs = side_by_side(peer_rows, _beside(walk_rows))
    out = []
    for row in peer_rows:
        rec = row.records[0]
        entry = {"peer": rec.get("peer"), "method": row.name, "spec_hash": row.hashes[0],
                 "run_id": row.provenance[0].get("id") if row.provenance else None,
                 "record": {k: finite_or_none(v) for k, v in rec.items()}}
        for pair in pairs:
            if pair["peer"] == row.name:
                entry["vs_fdbench_solve" if pair.get("solve_alone") else "vs_fdbench"] = _plain(pair)
        out.append(entry)
    return out


def _text(fmt, plan, walk_rows, forearm_rows, spec, inverse, runs, jobs, figures, output, quiet, processes=1,
          peers_found=None) -> str:
    from .. import walk, walk_report
    from .common import say as _say

    peer_methods, peer_rows = peers_found or ([], [])

    fields = walk.inverse_residuals(spec, inverse)
    settings = settings_table(plan, spec, jobs)
    if fmt == "csv":
        from ..files import csv_text

        return csv_text(list(walk_report.CSV_COLUMNS),
                        walk_report.csv_rows(walk_rows + _peer_walk_rows(peer_rows), forearm_rows))
    duration, forearm_duration = float(inverse.t[-1]), walk_report._duration(forearm_rows)
    claim = walk_report.claim_lines(walk_rows, forearm_rows, duration, forearm_duration, True, fields)
    if fmt == "json":
        report = walk_report.json_report(plan, walk_rows, forearm_rows, fields, settings, claim)
        if peer_rows:
            report["peers"] = _peers_json(peer_rows, walk_rows)
        return json.dumps(report, indent=2) + "\n"
    links = None
    if figures is not None:
        from ..files import new_folder
        from ..walk_figures import write_walk_figures

        with new_folder(figures):  # removed again if a figure cannot be written
            links = write_walk_figures(spec, inverse, walk_rows, runs, figures,
                                       output.parent if output is not None and str(output) != "-" else Path("."),
                                       processes)
        _say(quiet, f"wrote {len(links)} figures to {figures}")
    names, kinds = walk.coordinates(spec)
    section = None
    if peer_rows:
        from ..peers.report import peers_markdown

        section = peers_markdown(peer_rows, peer_methods, _beside(walk_rows))
    return walk_report.markdown(plan, walk_rows, forearm_rows, inverse, fields, names, kinds, settings,
                                _provenance(walk_rows + forearm_rows + _peer_walk_rows(peer_rows)), links, section)


def _provenance(rows) -> list[str]:
    """When and where the runs were made (the paper report's paragraph, ``report._provenance``)."""
    from ..report import Row, _provenance

    return _provenance([Row(row.name, "walk", None, {}, None, [row.record], provenance=[row.provenance])
                        for row in rows if row.provenance], "fdbench report --rerun")


def settings_table(plan, spec, jobs: str) -> dict:
    """The report's settings: the model, motion, loads, estimate, simulation, budgets, versions."""
    from datetime import datetime, timezone

    from ..models import summary
    from ..report import condition_settings
    from ..store import git_commit, machine

    loads = dict(spec.inputs).get("--loads")
    conditions = {key: value.replace("Figure 2", "the coordinates figure")
                  for key, value in condition_settings(spec, [m.spec for m in plan.walk]).items()}
    table = {"model": f"{spec.model_name}: {summary(spec.model_name)}",
             **conditions,
             "external loads": f"{spec.loads}" + (f", SHA-256 {loads[:16]} (with its data file)" if loads else "")
             if spec.loads else "none",
             "integrator": spec.integrator + (f" (dt = {spec.dt:.6g} s)" if spec.integrator == "rk4" else ""),
             "penalty formulation": f"alpha = {spec.alpha:g}, xi = {spec.xi:g}, omega = {spec.omega:g} rad/s",
             "shooting": f"CMA-ES, budget {plan.budget} simulations, population {plan.popsize}, seed 0 "
                         "(the same on the forearm)",
             "forearm": "the paper's model and motion (eq. 5, as printed), the same methods and settings",
             "runtime_s": "the method's own wall time per run (set-up and simulations; imports and kernel loading "
                          "excluded)",
             "parallel jobs": jobs,
             "fdbench": __version__ + (f" (commit {git_commit()[:12]})" if git_commit() else ""),
             "machine": machine(),
             "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}
    return table
