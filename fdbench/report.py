"""The report: the paper's comparison laid out as its Tables 2 and 3, our figures beside the
published ones, as Markdown or CSV."""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone

from . import __version__
from .benchmark import PAPER_CONTROL, PAPER_INVERSE_RUNTIME_S, Cell, Plan, summarise

TORQUE_LABELS = {"ann": "ANN ({hidden} hidden neurons)", "cs": "CS ({knots} points)", "pf": "PF ({terms} terms)"}
OPTIMIZER_LABELS = {"cmaes": "CMA-ES", "bfgs": "BFGS quasi-Newton"}

CSV_COLUMNS = (
    "cell", "table", "torque", "optimizer", "feedforward", "in_paper", "kinematics", "integrator", "dt",
    "budget", "seeds", "runs", "rmse_rot_deg_median", "rmse_rot_deg_iqr", "rmse_torque_nm_median",
    "rmse_torque_nm_iqr", "runtime_s_median", "runtime_s_iqr", "success_rate", "paper_rmse_rot_deg",
    "paper_rmse_torque_nm", "paper_runtime_s", "speedup_vs_paper",
)


@dataclass
class Row:
    """One row of the report: a cell (or the PD control run) and its summary."""

    name: str
    table: int | str  # 2, 3 or "control"
    cell: Cell | None
    summary: dict
    paper: tuple | None
    records: list

    @property
    def speedup(self) -> float:
        ours = self.summary.get("runtime_s_median", math.nan)
        if not self.paper or not ours or not math.isfinite(ours):
            return math.nan
        return self.paper[2] / ours


def torque_label(torque: str, options: dict) -> str:
    template = TORQUE_LABELS.get(torque)
    if template is None:
        return torque
    defaults = {"hidden": 4, "knots": 11, "terms": 4}
    return template.format(**{**defaults, **options})


def build_rows(plan: Plan, runs: dict) -> list[Row]:
    """Summaries of every cell of the plan from the stored runs ({hash: stored run})."""
    rows = []
    if plan.control is not None:
        record = runs[plan.control.hash()]["record"]
        rows.append(Row("PD control + feedforward", "control", None, summarise([record]), PAPER_CONTROL, [record]))
    for cell in plan.cells:
        specs = plan.specs[cell]
        records = [runs[s.hash()]["record"] for s in specs]
        name = f"{torque_label(cell.torque, dict(specs[0].torque_options))} + {OPTIMIZER_LABELS.get(cell.optimizer, cell.optimizer)}"
        rows.append(Row(name, cell.table, cell, summarise(records), cell.paper, records))
    return rows


def _num(value, digits=3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if value != 0 and (abs(value) >= 1e4 or abs(value) < 10 ** -digits):
        return f"{value:.2e}"
    return f"{value:.{digits}f}"


def _paper_runtime(value) -> str:
    return "-" if value is None else f"{value:g}"  # as published: 0.075, 41.59, 2439.15


def _median_iqr(summary: dict, name: str, digits=3) -> str:
    med, iqr = summary.get(f"{name}_median"), summary.get(f"{name}_iqr")
    if summary.get("runs", 0) <= 1:
        return _num(med, digits)
    return f"{_num(med, digits)} ± {_num(iqr / 2 if iqr is not None else None, digits)}"


def markdown(rows: list[Row], inverse, inverse_runtime_s: float, settings: dict, figures: dict | None = None,
             beyond: list[str] | None = None) -> str:
    """The report as Markdown. ``settings`` describes the run (kinematics, versions, machine...);
    ``figures`` maps figure names to relative paths of written PNG files."""
    out = ["# fdbench report", ""]
    out += [
        "Trajectory tracking in the forward dynamic simulation of a 1-DOF forearm: PD control with "
        "computed feedforward against optimised torque histories, reproducing Tables 2 and 3 of the "
        "paper. Figures are the median over seeds ± half the interquartile range; the paper's "
        "published figures stand beside ours. RMSE of rotation in degrees, of torque in N m, runtime in "
        "seconds.",
        "",
        "## Settings",
        "",
        "| setting | value |",
        "|---|---|",
    ]
    out += [f"| {key} | {value} |" for key, value in settings.items()]
    out += ["", "## Inverse dynamics (Figure 2)", ""]
    runtime = inverse_runtime_s
    out += [
        f"Elbow torque from {_num(float(inverse.torque.min()))} to {_num(float(inverse.torque.max()))} N m over "
        f"1001 samples of [0, 1] s ({inverse.kinematics} kinematics); computed in {_num(runtime * 1e3)} ms "
        f"(paper: {PAPER_INVERSE_RUNTIME_S} s).",
        "",
    ]
    control = [r for r in rows if r.table == "control"]
    if control:
        row = control[0]
        rec = row.records[0]
        out += ["## PD control with computed feedforward (section 3)", "",
                f"Kp = {rec['kp']} N m/rad, Kd = {rec['kd']} N m s/rad.", ""]
        out += _table(control, with_success=False) + [""]
    for table, title in ((2, "Table 2: optimisation without computed feedforward"),
                         (3, "Table 3: optimisation with computed feedforward")):
        cells = [r for r in rows if r.table == table]
        if cells:
            out += [f"## {title}", ""]
            out += _table(cells, with_success=True)
            if any(r.cell and not r.cell.in_paper for r in cells):
                out += ["", "Cells marked * are not in the paper."]
            out += [""]
    out += beyond or []  # the "Beyond the paper" section (beyond.beyond_markdown)
    out += ["## Comparison", ""] + _comparison(rows) + [""]
    if figures:
        out += ["## Figures", ""]
        out += [f"![{name}]({path})" for name, path in figures.items()] + [""]
    return "\n".join(out).rstrip() + "\n"


def _table(rows: list[Row], with_success: bool) -> list[str]:
    head = "| method | RMSE_rot (deg) | paper | RMSE_torque (N m) | paper | runtime (s) | paper | speed-up |"
    rule = "|---|---:|---:|---:|---:|---:|---:|---:|"
    if with_success:
        head += " success |"
        rule += "---:|"
    lines = [head, rule]
    for row in rows:
        paper = row.paper or (None, None, None)
        star = "*" if row.cell is not None and not row.cell.in_paper else ""
        speedup = f"{row.speedup:,.0f}x" if math.isfinite(row.speedup) else "-"
        line = (f"| {row.name}{star} | {_median_iqr(row.summary, 'rmse_rot_deg')} | {_num(paper[0])} "
                f"| {_median_iqr(row.summary, 'rmse_torque_nm')} | {_num(paper[1])} "
                f"| {_median_iqr(row.summary, 'runtime_s', 4)} | {_paper_runtime(paper[2])} | {speedup} |")
        if with_success:
            line += f" {row.summary['success_rate']:.0%} ({row.summary['runs']} runs) |"
        lines.append(line)
    return lines


def _comparison(rows: list[Row]) -> list[str]:
    """A few sentences written from the numbers."""
    # cells none of whose runs reached t = 1 s are left out: eq. 18 can score an early failure
    # below a complete run, and a rotation error over a few samples says nothing of tracking
    finite = [r for r in rows if math.isfinite(r.summary.get("rmse_rot_deg_median", math.nan))
              and r.summary.get("success_rate", 0) > 0]
    failed = [r.name for r in rows if r not in finite]
    if not finite:
        return ["No method reached t = 1 s with a finite RMSE of rotation."]
    best = min(finite, key=lambda r: r.summary["rmse_rot_deg_median"])
    fastest = min(finite, key=lambda r: r.summary["runtime_s_median"])
    lines = [
        f"- Most accurate: {best.name} (median RMSE_rot {_num(best.summary['rmse_rot_deg_median'])} deg).",
        f"- Fastest: {fastest.name} (median runtime {_num(fastest.summary['runtime_s_median'], 4)} s).",
    ]
    optimised = [r for r in finite if r.table != "control"]
    control = [r for r in finite if r.table == "control"]
    if control and optimised:
        c = control[0].summary["rmse_rot_deg_median"]
        beaten = [r for r in optimised if r.summary["rmse_rot_deg_median"] < c]
        lines.append(f"- {len(beaten)} of {len(optimised)} optimisation cells track more accurately than PD control "
                     f"({_num(c)} deg) within their budget.")
    for table in (2, 3):
        cells = [r for r in optimised if r.table == table and r.cell is not None]
        if cells:
            top = min(cells, key=lambda r: r.summary["rmse_rot_deg_median"])
            lines.append(f"- Table {table}: best {top.name}, {_num(top.summary['rmse_rot_deg_median'])} deg.")
    if failed:
        lines.append(f"- Left out of this comparison, no successful run: {', '.join(failed)}.")
    speedups = [r.speedup for r in finite if math.isfinite(r.speedup)]
    if speedups:
        span = f"{min(speedups):,.0f}x" if len(speedups) == 1 else f"from {min(speedups):,.0f}x to {max(speedups):,.0f}x"
        lines.append(f"- Speed-up against the paper's runtimes: {span} "
                     "(different machines and languages: an order of magnitude, not a measurement).")
    return lines


def csv_rows(rows: list[Row]) -> list[list]:
    """One row per cell (and the control run), the columns of ``CSV_COLUMNS``."""
    out = []
    for row in rows:
        rec = row.records[0]
        cell = row.cell
        paper = row.paper or (None, None, None)
        values = {
            "cell": row.name, "table": row.table,
            "torque": cell.torque if cell else "id", "optimizer": cell.optimizer if cell else "",
            "feedforward": cell.feedforward if cell else True, "in_paper": cell.in_paper if cell else True,
            "kinematics": rec.get("kinematics"), "integrator": rec.get("integrator"), "dt": rec.get("dt"),
            "budget": rec.get("budget") or "", "seeds": len(row.records), **row.summary,
            "paper_rmse_rot_deg": paper[0], "paper_rmse_torque_nm": paper[1], "paper_runtime_s": paper[2],
            "speedup_vs_paper": row.speedup,
        }
        out.append(["" if values.get(c) is None else values.get(c) for c in CSV_COLUMNS])
    return out


def settings_table(plan: Plan, seeds: int, jobs: int) -> dict:
    from .store import dependency_versions, git_commit, machine

    spec = plan.control or next(iter(plan.specs.values()))[0]
    versions = dependency_versions()
    integrator = spec.integrator + (f" (dt = {spec.dt} s)" if spec.integrator == "rk4"
                                    else f" (rtol = {spec.rtol}, atol = {spec.atol})")
    table = {
        "kinematics": spec.kinematics,
        "integrator": integrator,
        "penalty formulation": f"alpha = {spec.alpha:g}, xi = {spec.xi:g}, omega = {spec.omega:g} rad/s",
    }
    if plan.cells:
        first = next(iter(plan.specs.values()))[0]
        table.update({
            "objective": f"RMSE_rot_deg + {first.penalty_weight:g} (1 - t_end) (eq. 18)",
            "budget": f"{first.budget} evaluations per optimisation",
            "seeds": f"{seeds} per cell (0 to {seeds - 1})",
        })
    table.update({
        "parallel jobs": str(jobs),
        "fdbench": f"{__version__}" + (f" (commit {git_commit()[:12]})" if git_commit() else ""),
        "dependencies": ", ".join(f"{k} {v}" for k, v in versions.items() if k not in ("fdbench",) and v),
        "machine": machine(),
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    })
    return table
