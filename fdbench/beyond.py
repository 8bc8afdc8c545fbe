"""The report's "Beyond the paper" table: the methods the field uses today (computed-torque and
LQR control, direct collocation) on the report's model, motion and simulation settings, with the
columns of the PD row. Each method is deterministic, so, like the PD row, it is one run; runs are
stored and reused by their spec hash like every other run of the report."""

from __future__ import annotations

from dataclasses import dataclass

from .spec import RunSpec, collocate_spec, control_spec


@dataclass(frozen=True)
class Method:
    """One row of the table: its label, one sentence on what it does and which tool uses it, and
    the run's specification."""

    name: str
    description: str
    spec: RunSpec


COLLOCATION_SUMMARY = ("states and torque are the unknowns of one sparse problem whose defects discretise the "
                       "equation of motion, solved by IPOPT (as OpenSim Moco, bioptim and Drake do); fdbench replays "
                       "the torque found through its own forward simulation, and the indicators are the replay's")


def beyond_methods(**common) -> list[Method]:
    """The methods of the table with their default options, on the settings ``common``
    (kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions, model_name): computed
    torque, LQR and direct collocation, on the forearm or on another model (the arm)."""
    from .collocation import DEFAULT_NODES
    from .controllers import CONTROLLERS

    ct, lqr = CONTROLLERS["computed-torque"], CONTROLLERS["lqr"]
    return [
        Method("Computed torque (omega_n 20 rad/s, zeta 1)", ct.summary,
               control_spec(controller="computed-torque", controller_options=dict(bandwidth=20.0, damping=1.0),
                            **common)),
        Method("Time-varying LQR (q 1e4, 1; r 1)", lqr.summary, control_spec(controller="lqr", **common)),
        Method(f"Direct collocation (Hermite-Simpson, {DEFAULT_NODES} intervals) + forward replay",
               COLLOCATION_SUMMARY, collocate_spec(DEFAULT_NODES, "hermite-simpson", **common)),
    ]


EXACT_GRADIENT_SUMMARY = ("the paper's cell with the gradient computed exactly, by forward sensitivities of the "
                          "RK4 simulation, instead of by finite differences; a simulation with its sensitivities "
                          "counts as one evaluation of the budget; seed 0")


def exact_gradient_methods(cells, budget, torque_options, optimizer_options, penalty_weight, **common) -> list[Method]:
    """A row per gradient-based cell of ``cells`` (benchmark.Cell) run with ``--gradient exact``
    (seed 0: one run, like the other rows of the table)."""
    from .spec import gradient_for, optimize_spec

    methods = []
    for cell in cells:
        if gradient_for(cell.optimizer, "exact") != "exact":
            continue
        ff = " + ff" if cell.feedforward else ""
        spec = optimize_spec(cell.torque, cell.optimizer, cell.feedforward, 0, budget, torque_options,
                             optimizer_options, gradient="exact", penalty_weight=penalty_weight,
                             shared_options=True, **common)
        methods.append(Method(f"{cell.torque.upper()} + {cell.optimizer}{ff}, exact gradient", EXACT_GRADIENT_SUMMARY,
                              spec))
    return methods


def beyond_rows(methods: list[Method], runs: dict, provenance: dict | None = None) -> list:
    """The report rows (``report.Row``, table "beyond") of the methods from their stored runs;
    ``provenance`` ({hash: info}, from ``Store.provenance``) adds when and where each was made."""
    from .benchmark import summarise
    from .report import Row

    provenance = provenance or {}
    rows = []
    for method in methods:
        key = method.spec.hash()
        record = runs[key]["record"]
        rows.append(Row(method.name, "beyond", None, summarise([record]), None, [record],
                        provenance=[provenance[key]] if key in provenance else [], hashes=[key], specs=[method.spec]))
    return rows


def beyond_markdown(rows: list, methods: list[Method]) -> list[str]:
    """The section's Markdown lines: one sentence per method, then the table (PD's columns)."""
    from .report import _table, failure_lines

    if not rows:
        return []
    out = ["## Beyond the paper", "",
           "The methods the field uses today, on the same model, motion and indicators (one run each: "
           "they are deterministic; the paper has no figures for them):", ""]
    described = {}
    for m in methods:  # one line per description (the exact-gradient rows share theirs)
        described.setdefault(m.description, []).append(m.name)
    out += [f"- {'; '.join(names)}: {description}." for description, names in described.items()]
    out += [""] + _table(rows, with_success=False)
    collocation = [r for r in rows if r.records[0].get("command") == "collocate"]
    if collocation:
        rec = collocation[0].records[0]
        out += ["", f"Direct collocation's own RMSE_rot at its nodes: {_deg(rec.get('collocation_rmse_rot_deg'))} deg; "
                    f"IPOPT: {rec.get('ipopt_status')}, {rec.get('ipopt_iterations')} iterations, "
                    f"{_deg(rec.get('solve_time_s'))} s."]
    failed = failure_lines(rows)
    if failed:
        out += ["", "Did not succeed (`status`, `t_end` and `message` in the CSV and JSON):", ""] + failed
    return out + [""]


def _deg(value) -> str:
    return "-" if value is None else f"{value:.3g}"


def beyond_csv_rows(rows: list) -> list[list]:
    """CSV rows (the report's ``CSV_COLUMNS``) of the table, the method named in ``torque``."""
    from .report import CSV_COLUMNS, csv_rows

    out = csv_rows(rows)
    for values, row in zip(out, rows):
        rec = row.records[0]
        method = rec.get("torque") if rec.get("command") == "optimize" else rec.get("command")
        fixed = {"torque": rec.get("controller") or method, "feedforward": rec.get("feedforward"),
                 "in_paper": False}
        for column, value in fixed.items():
            if column in CSV_COLUMNS:
                values[CSV_COLUMNS.index(column)] = value
    return out
