"""The report's "Peers" section: OpenSim's PD simulation, its CMCTool and Moco's MocoTrack on the
report's model, motion and settings, with the columns of the PD row, then each peer beside the
fdbench method it stands for (PD control beside OpenSim's simulation, fdbench's computed muscle control beside
CMC on a model with muscles, else computed-torque control, direct collocation beside MocoTrack): accuracy and time, their ratio,
and whether fdbench meets its goal against that peer (``GOAL``: at least 10 times faster at equal
or better RMSE_rot)."""

from __future__ import annotations

import math

from .methods import Method, method_csv_rows, rows as method_rows
from .paper import significant

# peer: the fdbench methods it stands beside, the first found among the report's rows: (command, controller, table)
PAIRS = {"opensim": (("control", "pd", "control"),),
         "opensim-cmc": (("control", "cmc", None), ("control", "computed-torque", None), ("control", "pd", "control")),
         "moco": (("collocate", None, None),)}
GOAL = 10.0  # fdbench's goal: at least this many times faster than each peer...
SAME_ACCURACY = 0.01  # ...at equal or better RMSE_rot: fdbench's at most 1 % above the peer's


def peer_methods(names, kp=None, kd=None, **common) -> list[Method]:
    """The report's peers ``names`` as methods (label, summary, spec) on the settings ``common``;
    the opensim peer takes the report's PD gains."""
    from ..peers import peer
    from ..spec import peer_spec

    return [Method(peer(name).label, peer(name).summary, peer_spec(name, None, kp, kd, **common)) for name in names]


def peer_rows(methods: list[Method], runs: dict, provenance: dict | None = None) -> list:
    """The report rows (``report.Row``, table "peers") of the peers, from their stored runs."""
    return method_rows(methods, runs, provenance, "peers")


def peers_markdown(rows: list, methods: list[Method], ours: list) -> list[str]:
    """The section's Markdown lines: a sentence per peer, the table (PD's columns), then each peer
    beside its fdbench method among ``ours`` (the report's other rows)."""
    from .paper import results_table, failure_lines

    if not rows:
        return []
    out = ["## Peers", "", "The tools fdbench's methods are compared with, on the same model, motion and indicators "
           "(one run each, stored and reused like every run):", ""]
    out += [f"- {m.name}: {m.description}." for m in methods]
    out += [""] + results_table(rows, with_success=False)
    pairs = side_by_side(rows, ours)
    if pairs:
        out += ["", f"Each peer beside the fdbench method it stands for. Time: the run's runtime_s (OpenSim: its "
                f"integrate call, best of 3; CMC: CMCTool's whole run; MocoTrack: its whole run, building and "
                f"solving its problem, then the replay; fdbench's control: its inverse dynamics, design and "
                f"simulation; fdbench's collocation: its inverse dynamics, transcription, solve and replay); "
                f"MocoTrack's second row: its solve() (building its CasADi problem and IPOPT) against collocate's "
                f"transcription and IPOPT solve. The goal: fdbench at least {GOAL:g}× faster than each peer at equal "
                f"or better RMSE_rot (at most {100 * SAME_ACCURACY:g} % above the peer's).", "",
                "| fdbench | peer | RMSE_rot fdbench (deg) | RMSE_rot peer (deg) | time fdbench (s) | time peer (s) "
                "| peer time / fdbench time | goal met |", "|---|---|---:|---:|---:|---:|---:|---|"]
        out += [f"| {p['fdbench']} | {p['peer']}{' (solve)' if p.get('solve_alone') else ''} "
                f"| {significant(p['rmse_rot_deg_fdbench'])} | {significant(p['rmse_rot_deg_peer'])} "
                f"| {significant(p['runtime_s_fdbench'])} | {significant(p['runtime_s_peer'])} | {_ratio(p['time_ratio'])} "
                f"| {_verdict(p)} |" for p in pairs]
        out += [""] + [goal_sentence(p) for p in pairs if not p.get("solve_alone")]
    records = [row.records[0] for row in rows]
    details = [f"MocoTrack: {rec.get('ipopt_status')}, {rec.get('ipopt_iterations')} iterations, whole run "
               f"{significant(rec.get('moco_run_s'))} s, solve {significant(rec.get('solve_time_s'))} s (tolerance {rec.get('tolerance')}, {rec.get('nodes')} mesh "
               f"intervals); its own RMSE_rot at its mesh points {significant(rec.get('collocation_rmse_rot_deg'))} deg."
               for rec in records if rec.get("peer") == "moco"]
    versions = sorted({str(rec["opensim_version"]) for rec in records if rec.get("opensim_version")})
    out += [""] + details + ([f"OpenSim {', '.join(versions)}."] if versions else [])
    failed = failure_lines(rows)
    if failed:
        out += ["", "Did not succeed (`status`, `t_end` and `message` in the CSV and JSON):", ""] + failed
    return out + [""]


def side_by_side(rows: list, ours: list) -> list[dict]:
    """Per peer row whose fdbench method is among ``ours``: both RMSE_rot (deg), both runtimes (s),
    the peer's time over fdbench's and whether the goal is met (``goal_met``); for MocoTrack a
    second entry (``solve_alone``): its solve() (its CasADi problem's building and IPOPT) against
    collocate's transcription and IPOPT solve."""
    pairs = []
    for row in rows:
        rec = row.records[0]
        match = _match(PAIRS.get(rec.get("peer"), ()), ours, rec.get("actuation"))
        if match is None:
            continue
        mine = match.records[0]
        times = [(rec.get("runtime_s"), mine.get("runtime_s"), False)]
        if rec.get("peer") == "moco":
            built = (mine.get("build_time_s") or 0.0) + (mine.get("solve_time_s") or math.nan)
            times.append((rec.get("solve_time_s"), built, True))
        for theirs, our, alone in times:
            pair = {"fdbench": match.name, "peer": row.name, "model": _model_name(row),
                    "rmse_rot_deg_fdbench": mine.get("rmse_rot_deg"), "rmse_rot_deg_peer": rec.get("rmse_rot_deg"),
                    "runtime_s_fdbench": our, "runtime_s_peer": theirs, "time_ratio": _quotient(theirs, our)}
            pair.update(goal_met=goal_met(pair), **({"solve_alone": True} if alone else {}))
            pairs.append(pair)
    return pairs


def _match(wanted, ours, actuation=None):
    """The first of ``ours`` (report rows) that is one of the methods ``wanted`` ((command,
    controller or None, table or None), in order of preference) and drives what the peer drives
    (``actuation``: the peer record's, "muscles" or None); None without one."""
    for command, controller, table in wanted:
        for row in ours:
            rec = row.records[0] if row.records else {}
            if (rec.get("command") == command and (controller is None or (rec.get("controller") or "pd") == controller)
                    and (table is None or row.table == table) and rec.get("actuation") == actuation):
                return row
    return None


def _accurate(pair: dict) -> bool:
    """fdbench's RMSE_rot at most ``SAME_ACCURACY`` above the peer's."""
    ours, theirs = pair["rmse_rot_deg_fdbench"], pair["rmse_rot_deg_peer"]
    return ours is not None and theirs is not None and ours <= theirs * (1 + SAME_ACCURACY)


def goal_met(pair: dict) -> bool:
    """fdbench at least ``GOAL`` times faster than the peer at equal or better RMSE_rot."""
    return bool(_accurate(pair) and math.isfinite(pair["time_ratio"]) and pair["time_ratio"] >= GOAL)


def goal_sentence(pair: dict) -> str:
    """One sentence on the pair: the measured ratio, both RMSE_rot, the goal met or not and why."""
    ratio = pair["time_ratio"]
    if not math.isfinite(ratio):
        speed = "no time to compare"
    elif ratio >= 1:
        speed = f"fdbench {significant(ratio)}× faster"
    else:
        speed = f"fdbench {significant(1 / ratio)}× slower"
    ours, theirs = pair["rmse_rot_deg_fdbench"], pair["rmse_rot_deg_peer"]
    if pair["goal_met"]:
        verdict = "the goal is met"
    else:
        missing = [f"{significant(ratio)}× is below {GOAL:g}×"] if not (math.isfinite(ratio) and ratio >= GOAL) else []
        missing += [] if _accurate(pair) else [f"its RMSE_rot {significant(ours)} deg is above the peer's {significant(theirs)} deg"]
        verdict = "the goal is not met: " + " and ".join(missing)
    where = f" on {pair['model']}" if pair.get("model") else ""
    return (f"- {pair['fdbench']} against {pair['peer']}{where}: {speed} (RMSE_rot {significant(ours)} against {significant(theirs)} "
            f"deg); {verdict}.")


def _model_name(row) -> str | None:
    """The row's model as the reader knows it: its name, or a model file's name without its folder."""
    from pathlib import Path

    return Path(str(row.specs[0].model_name)).name if row.specs else None


def plain_pair(pair: dict) -> dict:
    """A pair for JSON: NaN as null, without the peer's name (the cell's)."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in pair.items()
            if k not in ("peer", "solve_alone")}


def _verdict(pair: dict) -> str:
    return "yes" if pair["goal_met"] else "**no**"


def _quotient(a, b) -> float:
    return a / b if a is not None and b else math.nan


def _ratio(value) -> str:
    return "-" if not math.isfinite(value) else f"{value:.3g}×"


def peer_csv_rows(rows: list) -> list[list]:
    """CSV rows (the report's ``CSV_COLUMNS``) of the peers, the peer named in ``torque``."""
    return method_csv_rows(rows, named=lambda record: record.get("peer"))


PEER_FIELDS = ("opensim_version", "solve_time_s", "moco_run_s", "ipopt_status", "ipopt_iterations",
               "collocation_rmse_rot_deg", "nodes", "tolerance", "opensim_forward_s", "opensim_steps")


def with_peer_fields(cells: list, rows: list, ours: list) -> list:
    """The JSON report's cells with the peers' own: the peer named in ``torque`` and ``peer``, its
    record's fields (``PEER_FIELDS``, where it has them) and, beside the fdbench method it stands
    for among ``ours``, ``vs_fdbench`` (both RMSE_rot, both runtimes, the peer's time over ours)."""
    found = side_by_side(rows, ours)
    pairs = {p["peer"]: p for p in found if not p.get("solve_alone")}
    solves = {p["peer"]: p for p in found if p.get("solve_alone")}
    entries = iter(rows)
    for cell in cells:
        if cell.get("table") != "peers":
            continue
        row = next(entries)
        rec = row.records[0]
        cell.update(torque=rec.get("peer"), peer=rec.get("peer"), feedforward=rec.get("feedforward"), in_paper=False,
                    optimizer="", **{k: rec[k] for k in PEER_FIELDS if rec.get(k) is not None})
        pair = pairs.get(row.name)
        if pair is not None:
            cell["vs_fdbench"] = plain_pair(pair)
        if row.name in solves:
            cell["vs_fdbench_solve"] = plain_pair(solves[row.name])
    return cells
