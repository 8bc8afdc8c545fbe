"""The paper's table of methods (PD control, Tables 2 and 3), its execution (handed to an
execution backend, see ``execution``: stored runs are reused by settings hash, missing ones are
computed by workers and stored one by one as they finish, so an interrupted benchmark resumes
where it stopped) and its statistics."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spec import RunSpec, control_spec, gradient_for, optimize_spec

# The paper's published figures: (RMSE_rot deg, RMSE_torque N m, runtime s).
PAPER_INVERSE_RUNTIME_S = 0.12
PAPER_CONTROL = (0.116, 0.149, 0.075)
PAPER_CELLS = {
    ("ann", "cmaes", False): (1.250, 0.149, 411.56),
    ("ann", "bfgs", False): (0.310, 0.121, 449.37),
    ("cs", "cmaes", False): (0.558, 0.118, 29.03),
    ("cs", "bfgs", False): (0.197, 0.116, 41.59),
    ("ann", "cmaes", True): (27.383, 0.366, 2439.15),
    ("ann", "bfgs", True): (2.079, 0.009, 1482.89),
    ("cs", "cmaes", True): (1.284, 0.105, 35.53),
    ("cs", "bfgs", True): (0.696, 0.046, 35.67),
    ("pf", "cmaes", True): (1.829, 0.012, 24.11),
    ("pf", "bfgs", True): (1.816, 0.095, 17.09),
}
PAPER_TORQUES = ("ann", "cs", "pf")
PAPER_OPTIMIZERS = ("cmaes", "bfgs")


@dataclass(frozen=True)
class Cell:
    """One cell of the comparison: a torque parameterisation, an optimiser, feedforward or not."""

    torque: str
    optimizer: str
    feedforward: bool

    @property
    def key(self):
        return (self.torque, self.optimizer, self.feedforward)

    @property
    def in_paper(self) -> bool:
        return self.key in PAPER_CELLS

    @property
    def table(self) -> int:
        return 3 if self.feedforward else 2

    @property
    def paper(self):
        return PAPER_CELLS.get(self.key)


def default_cells(torques=None, optimizers=None, feedforward=None, all_cells=False) -> list[Cell]:
    """The cells of Tables 2 and 3 (PF without feedforward only on request: ``all_cells`` or
    asking for pf without feedforward explicitly)."""
    torques = list(torques or PAPER_TORQUES)
    optimizers = list(optimizers or PAPER_OPTIMIZERS)
    modes = [False, True] if feedforward is None else [feedforward]
    explicit_pf = "pf" in torques and torques != list(PAPER_TORQUES) and feedforward is False
    cells = []
    for ff in modes:
        for torque in torques:
            for opt in optimizers:
                cell = Cell(torque, opt, ff)
                known = torque in PAPER_TORQUES and opt in PAPER_OPTIMIZERS
                if known and not cell.in_paper and not (all_cells or explicit_pf):
                    continue
                cells.append(cell)
    return cells


@dataclass(frozen=True)
class Plan:
    """What a benchmark runs: the control run (or None) and every cell with its seeds."""

    control: RunSpec | None
    cells: tuple
    specs: dict  # Cell -> tuple of RunSpec, one per seed

    def all_specs(self) -> list[RunSpec]:
        out = [self.control] if self.control is not None else []
        for cell in self.cells:
            out.extend(self.specs[cell])
        return out


def make_plan(cells, seeds=5, budget=200, control=True, kp=None, kd=None, torque_options=None,
              optimizer_options=None, penalty_weight=1.0, gradient="fd", **common) -> Plan:
    control_run = control_spec(kp, kd, **common) if control else None
    specs = {
        cell: tuple(
            optimize_spec(cell.torque, cell.optimizer, cell.feedforward, seed, budget, torque_options,
                          optimizer_options, penalty_weight=penalty_weight, shared_options=True,
                          gradient=gradient_for(cell.optimizer, gradient), **common)
            for seed in range(seeds)
        )
        for cell in cells
    }
    return Plan(control_run, tuple(cells), specs)


def execute(plan: Plan, store, jobs: int | None = None, rerun: bool = False, on_done=None, backend=None) -> dict:
    """Make sure every run of the plan is in the store; return {spec hash: stored run}.

    ``backend`` (an ``execution.Backend``; default: local worker processes, ``jobs`` of them)
    carries out the missing runs; ``on_done(finished, total)`` reports progress. Runs already
    stored are reused unless ``rerun``; each new run is stored as soon as it finishes."""
    from ..execution import LocalBackend, execute_specs

    if backend is None:
        backend = LocalBackend(jobs)
    return execute_specs(plan.all_specs(), store, backend, rerun, on_done)


# ---- statistics ------------------------------------------------------------------------------

INDICATORS = ("rmse_rot_deg", "rmse_torque_nm", "runtime_s")


def succeeded(record: dict) -> bool:
    """A run that reached the end of its motion and (for an optimisation) beat its unoptimised initial guess."""
    if record.get("status") != "success":
        return False
    best, initial = record.get("best_objective"), record.get("initial_objective")
    return best is None or initial is None or best < initial


WORSE_THAN_START = "no-better-than-start"
OUTCOME_TEXT = {"success": "succeeded", WORSE_THAN_START: "ended no better than their start", "singular": "singular",
                "nonfinite": "non-finite (driven unstable)", "constraint": "constraint violated",
                "solver": "integrator failed"}


def outcome(record: dict) -> str:
    """How a run ended: 'success' (see ``succeeded``), the simulation's status code when it stopped
    before the motion's end ('singular', 'nonfinite', 'constraint', 'solver'), or
    'no-better-than-start' (it reached the end without beating its initial guess)."""
    if record.get("status") != "success":
        return record.get("status") or "unknown"
    return "success" if succeeded(record) else WORSE_THAN_START


def outcome_counts(records: list[dict]) -> dict:
    """{outcome: number of runs}, successes first, then the most frequent."""
    counts = {}
    for record in records:
        counts[outcome(record)] = counts.get(outcome(record), 0) + 1
    return dict(sorted(counts.items(), key=lambda item: (item[0] != "success", -item[1])))


def outcome_text(records: list[dict], codes: bool = False) -> str:
    """'3 singular, 2 ended no better than their start' (``codes``: '3 singular, 2 no-better-than-start')."""
    return ", ".join(f"{n} {name if codes else OUTCOME_TEXT.get(name, name)}"
                     for name, n in outcome_counts(records).items())


def failure_message(records: list[dict]) -> str | None:
    """Why the first run that did not succeed stopped (its simulation's message), or None."""
    for record in records:
        kind = outcome(record)
        if kind == WORSE_THAN_START:
            return (f"reached the end with objective {record['best_objective']:.4g} deg, not below its initial "
                    f"guess's {record['initial_objective']:.4g} deg")
        if kind != "success":
            return record.get("message") or kind
    return None


def summarise(records: list[dict]) -> dict:
    """Median and interquartile range of each indicator, the success rate, how many runs reached
    the motion's end and the median time (s) they stopped at."""
    out = {"runs": len(records)}
    per_joint = dict.fromkeys(k for r in records for k in r if k.startswith(("rmse_rot_deg_", "rmse_torque_nm_")))
    for name in tuple(INDICATORS) + tuple(per_joint):  # per joint: rmse_rot_deg_<joint>, of a model with joints
        values = np.array([r.get(name) if r.get(name) is not None else np.nan for r in records], dtype=float)
        values = values[np.isfinite(values)]
        if values.size:
            q1, med, q3 = np.percentile(values, [25, 50, 75])
            out[f"{name}_median"], out[f"{name}_iqr"] = float(med), float(q3 - q1)
        else:
            out[f"{name}_median"] = out[f"{name}_iqr"] = float("nan")
    out["success_rate"] = sum(succeeded(r) for r in records) / len(records) if records else float("nan")
    out["reached_end"] = sum(r.get("status") == "success" for r in records)
    ends = [r["t_end"] for r in records if isinstance(r.get("t_end"), (int, float))]
    out["t_end"] = float(np.median(ends)) if ends else float("nan")
    return out

