"""The report's "Peers" section: OpenSim's PD simulation and Moco's MocoTrack on the report's model,
motion and settings, with the columns of the PD row, then each peer beside the fdbench method it
stands for (PD control, direct collocation): accuracy and time, and their ratio."""

from __future__ import annotations

import math

from ..beyond import Method
from ..benchmark import summarise

PAIRS = {"opensim": "control", "moco": "collocate"}  # the peer and the command of the fdbench method it stands beside


def peer_methods(names, kp=None, kd=None, **common) -> list[Method]:
    """The report's peers ``names`` as methods (label, summary, spec) on the settings ``common``;
    the opensim peer takes the report's PD gains."""
    from . import peer, peer_spec

    return [Method(peer(name).label, peer(name).summary, peer_spec(name, None, kp, kd, **common)) for name in names]


def peer_rows(methods: list[Method], runs: dict, provenance: dict | None = None) -> list:
    """The report rows (``report.Row``, table "peers") of the peers, from their stored runs."""
    from ..report import Row

    provenance = provenance or {}
    rows = []
    for method in methods:
        key = method.spec.hash()
        record = runs[key]["record"]
        rows.append(Row(method.name, "peers", None, summarise([record]), None, [record],
                        provenance=[provenance[key]] if key in provenance else [], hashes=[key], specs=[method.spec]))
    return rows


def peers_markdown(rows: list, methods: list[Method], ours: list) -> list[str]:
    """The section's Markdown lines: a sentence per peer, the table (PD's columns), then each peer
    beside its fdbench method among ``ours`` (the report's other rows)."""
    from ..report import _table, failure_lines

    if not rows:
        return []
    out = ["## Peers", "", "The tools fdbench's methods are compared with, on the same model, motion and indicators "
           "(one run each, stored and reused like every run):", ""]
    out += [f"- {m.name}: {m.description}." for m in methods]
    out += [""] + _table(rows, with_success=False)
    pairs = side_by_side(rows, ours)
    if pairs:
        out += ["", "Each peer beside the fdbench method it stands for (time: the run's runtime_s; Moco's is its "
                "solve() and the replay, fdbench's collocation its inverse dynamics, transcription, solve and "
                "replay):", "",
                "| fdbench | peer | RMSE_rot fdbench (deg) | RMSE_rot peer (deg) | time fdbench (s) | time peer (s) "
                "| peer time / fdbench time |", "|---|---|---:|---:|---:|---:|---:|"]
        out += [f"| {p['fdbench']} | {p['peer']} | {_g(p['rmse_rot_deg_fdbench'])} | {_g(p['rmse_rot_deg_peer'])} "
                f"| {_g(p['runtime_s_fdbench'])} | {_g(p['runtime_s_peer'])} | {_ratio(p['time_ratio'])} |"
                for p in pairs]
    records = [row.records[0] for row in rows]
    details = [f"MocoTrack: {rec.get('ipopt_status')}, {rec.get('ipopt_iterations')} iterations, solve "
               f"{_g(rec.get('solve_time_s'))} s (tolerance {rec.get('tolerance')}, {rec.get('nodes')} mesh "
               f"intervals); its own RMSE_rot at its mesh points {_g(rec.get('collocation_rmse_rot_deg'))} deg."
               for rec in records if rec.get("peer") == "moco"]
    versions = sorted({str(rec["opensim_version"]) for rec in records if rec.get("opensim_version")})
    out += [""] + details + ([f"OpenSim {', '.join(versions)}."] if versions else [])
    failed = failure_lines(rows)
    if failed:
        out += ["", "Did not succeed (`status`, `t_end` and `message` in the CSV and JSON):", ""] + failed
    return out + [""]


def side_by_side(rows: list, ours: list) -> list[dict]:
    """Per peer row whose fdbench method is among ``ours``: both RMSE_rot (deg), both runtimes (s)
    and the peer's time over fdbench's."""
    pairs = []
    for row in rows:
        rec = row.records[0]
        command = PAIRS.get(rec.get("peer"))
        match = next((r for r in ours if r.records and r.records[0].get("command") == command
                      and (command != "control" or r.table == "control")), None)
        if match is None:
            continue
        mine = match.records[0]
        pairs.append({"fdbench": match.name, "peer": row.name, "rmse_rot_deg_fdbench": mine.get("rmse_rot_deg"),
                      "rmse_rot_deg_peer": rec.get("rmse_rot_deg"), "runtime_s_fdbench": mine.get("runtime_s"),
                      "runtime_s_peer": rec.get("runtime_s"),
                      "time_ratio": _quotient(rec.get("runtime_s"), mine.get("runtime_s"))})
    return pairs


def _quotient(a, b) -> float:
    return a / b if a is not None and b else math.nan


def _g(value) -> str:
    return "-" if value is None or (isinstance(value, float) and not math.isfinite(value)) else f"{value:.3g}"


def _ratio(value) -> str:
    return "-" if not math.isfinite(value) else f"{value:.3g}×"


def peer_csv_rows(rows: list) -> list[list]:
    """CSV rows (the report's ``CSV_COLUMNS``) of the peers, the peer named in ``torque``."""
    from ..report import CSV_COLUMNS, csv_rows

    out = csv_rows(rows)
    for values, row in zip(out, rows):
        rec = row.records[0]
        for column, value in {"torque": rec.get("peer"), "feedforward": rec.get("feedforward"),
                              "in_paper": False, "optimizer": ""}.items():
            values[CSV_COLUMNS.index(column)] = value
    return out


PEER_FIELDS = ("opensim_version", "solve_time_s", "ipopt_status", "ipopt_iterations", "collocation_rmse_rot_deg",
               "nodes", "tolerance")


def with_peer_fields(cells: list, rows: list, ours: list) -> list:
    """The JSON report's cells with the peers' own: the peer named in ``torque`` and ``peer``, its
    record's fields (``PEER_FIELDS``, where it has them) and, beside the fdbench method it stands
    for among ``ours``, ``vs_fdbench`` (both RMSE_rot, both runtimes, the peer's time over ours)."""
    pairs = {p["peer"]: p for p in side_by_side(rows, ours)}
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
            cell["vs_fdbench"] = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                                  for k, v in pair.items() if k != "peer"}
    return cells
