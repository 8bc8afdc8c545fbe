"""The report of a model compared with the paper's forearm (on a model with a floating base, a
recorded walk): which tracking method keeps the motion, how closely, how fast and with how much
residual force; and the same methods on the forearm, to test the paper's claim that the forearm
"generates the same problems as more complex models". Its datasets (``methods.Dataset``) × the
registered methods (``methods``), its sections (the indicators per kind of coordinate and per
coordinate, the residuals of a floating base, the paper's Tables 2 and 3 when cells are selected,
the peers, the claim), every sentence built from the runs' numbers; as Markdown, CSV or JSON."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from .. import __version__
from .methods import (BFGS, CMAES, CMC, COLLOCATION, COMPUTED_TORQUE, EVERY, FLOATING_BASE_PENALTY, LQR, MUSCLE_COLLOCATION,
                      MUSCLE_DRIVEN, OPEN_LOOP, PD, SLOWEST_FIRST, Dataset, Options, methods, muscles_markdown, rows, select)
from .paper import Row, figure_lines, provenance_section, render, settings_lines
from .paper import significant as number

# OpenSim RRA's average residuals for OpenSim's example walk, subject01 (FX, FY in N, MZ in N m),
# shown beside any floating base's as a reference point, after RRA adjusted the model's masses and
# the kinematics, which fdbench does not do
RRA_MEANS = {"residual_fx_mean_n": -3.8, "residual_fy_mean_n": -2.8, "residual_mz_mean_nm": -3.4}


# ---- the plan: datasets x methods ------------------------------------------------------------------


@dataclass
class ComparisonPlan:
    """The report's runs: the methods on the studied dataset and the same on the forearm, the
    methods that do not apply and why ((key, reason)), the paper's cells selected on the studied
    dataset (``paper_methods.Plan`` or None) and the exact-gradient rows of those cells."""

    datasets: list
    studied: list
    forearm: list
    skipped: list = field(default_factory=list)
    options: Options = field(default_factory=Options)
    cells: object = None
    extra: list = field(default_factory=list)

    @property
    def bfgs_note(self) -> str | None:
        return next((reason for key, reason in self.skipped if key == BFGS), None)

    @property
    def budget(self) -> int:
        return self.options.budget

    @property
    def popsize(self) -> int:
        return self.options.popsize

    def all_specs(self) -> list:
        """Every run's spec, the slowest first (so that two workers share the work evenly): on the
        studied dataset collocation, computed torque (inverse dynamics at every stage), LQR, the
        shooting optimisation, then the others; the forearm's, then the paper's cells."""
        return ([m.spec for m in sorted(self.studied, key=lambda m: SLOWEST_FIRST.index(m.key))]
                + [m.spec for m in self.forearm] + (self.cells.all_specs() if self.cells is not None else [])
                + [m.spec for m in self.extra])


def on_samples(common: dict) -> dict:
    """``common`` (RunSpec fields) with an RK4 step lowered, where needed, to put the motion's
    samples on its grid (``simulation.dt_on_samples``: a 60 Hz recording at 1 ms runs at 1/1020 s),
    so that the shooting methods read eq. 18 from the kernel's states and BFGS has exact gradients."""
    from ..spec import control_spec
    from ..run_inputs import motions
    from ..multibody.simulation import dt_on_samples
    from ..spec import RunSpec

    if common.get("integrator", "rk4") != "rk4":
        return common
    samples = motions(control_spec(**common))[0].samples
    return {**common, "dt": dt_on_samples(common.get("dt", RunSpec.dt), samples)}


def make_plan(studied_common: dict, forearm_common: dict, options: Options | None = None, collocation: bool = True,
              control: bool = True, penalty_weight: float = FLOATING_BASE_PENALTY) -> ComparisonPlan:
    """The report's runs: the registered methods that apply on the studied dataset (``studied_common``:
    RunSpec fields of the model, motion, loads and simulation settings; its RK4 step fitted to the
    recording by ``on_samples``) and the same on the forearm (``forearm_common``: the paper's motion
    and model), with the same options; ``collocation`` False leaves out collocation, ``control``
    False PD."""
    options = options or Options()
    studied = Dataset("walk", on_samples(studied_common), penalty_weight)
    forearm = Dataset("forearm", forearm_common, 1.0)
    wanted = [key for key in EVERY if (collocation or key != COLLOCATION) and (control or key != PD)]
    kept, skipped = select(wanted, [studied], options)
    muscle_driven, left_out = select(MUSCLE_DRIVEN if collocation else (), [studied], options)
    if muscle_driven:  # the studied model has muscles: the forearm has none
        skipped += left_out
    return ComparisonPlan([studied, forearm], methods(kept + muscle_driven, studied, options),
                          methods(kept, forearm, options), skipped, options)


def inverse_residuals(spec, inverse) -> dict:
    """The residual fields (``outcomes.residual_fields``) of the inverse dynamics ``inverse``
    (``JointInverse``) of the spec's model: what open loop applies to the floating base."""
    from ..outcomes import residual_fields
    from ..run_inputs import nominal

    return residual_fields(nominal(spec), inverse.torque)


def coordinates(spec) -> tuple[tuple, tuple]:
    """(names, kinds) of the spec's model's coordinates ('angle' or 'translation')."""
    from ..run_inputs import nominal

    model = nominal(spec)
    return tuple(model.coordinates), tuple(model.coordinate_kinds)


def has_floating_base(model_name: str, model_changes=()) -> bool:
    """Whether the model (a library name or file) has a free joint on ground."""
    from ..models import with_changes

    return with_changes(model_name, model_changes).floating_base is not None


# the main table's indicators and their columns' labels
MAIN_LABELS = {"rmse_rot_deg": "RMSE_rot (deg)", "rmse_trans_cm": "RMSE_trans (cm)", "rmse_torque_nm": "RMSE_torque (N m)",
               "rmse_force_n": "RMSE_force (N)", "residual_force_rms_n": "residual force RMS (N)",
               "residual_moment_rms_nm": "residual moment RMS (N m)", "runtime_s": "runtime (s)"}
MAIN_FIELDS = tuple(MAIN_LABELS)
CSV_COLUMNS = ("model", "method", "key", "command", "controller", "status", "t_end", *MAIN_FIELDS,
               "residual_fx_mean_n", "residual_fy_mean_n", "residual_mz_mean_nm", "reserve_rms_nm", "effort",
               "evaluations", "budget", "n_params",
               "spec_hash", "run_id")
RESIDUAL_MEANS = (("residual_fx_mean_n", "FX (N)"), ("residual_fy_mean_n", "FY (N)"), ("residual_mz_mean_nm", "MZ (N m)"))


def ended(row: Row, duration: float) -> str:
    """'reached 2.5 s' or 'constraint at 0.441 s'."""
    t_end = row.get("t_end", math.nan)
    if row.reached_end:
        return f"reached {duration:g} s"
    return f"{row.get('status', 'not run')} at {number(t_end)} s"


# ---- tables ------------------------------------------------------------------------------------


def main_table(rows: list[Row], duration: float, fields=MAIN_FIELDS) -> list[str]:
    """Every method's status and indicators ``fields``, one line each (Markdown)."""
    lines = ["| method | status / t_end | " + " | ".join(MAIN_LABELS[name] for name in fields) + " |",
             "|---|---|" + "---:|" * len(fields)]
    for row in rows:
        values = " | ".join(number(row.record.get(name)) for name in fields)
        lines.append(f"| {row.name} | {ended(row, duration)} | {values} |")
    return lines


def collocation_own_lines(rows: list[Row]) -> list[str]:
    """A sentence on the collocation's own solution at its points (the table gives its torque's
    forward replay), or nothing when no collocation row ran."""
    out = []
    for row in rows:
        own = row.record.get("collocation_rmse_rot_deg")
        if row.key in (COLLOCATION, MUSCLE_COLLOCATION) and own is not None:
            get = row.record.get
            name, replayed = (("Collocation", "its torque") if row.key == COLLOCATION
                              else ("Muscle-driven collocation", "its excitations and reserves"))
            out += ["", f"{name}'s own solution, at its points (its row above is {replayed} replayed open loop "
                        f"through fdbench's simulation): RMSE_rot {number(own)} deg, RMSE_trans "
                        f"{number(get('collocation_rmse_trans_cm'))} cm, residual force RMS "
                        f"{number(get('collocation_residual_force_rms_n'))} N, moment RMS "
                        f"{number(get('collocation_residual_moment_rms_nm'))} N m."]
    return out


def coordinate_table(rows: list[Row], names: tuple, kinds: tuple) -> list[str]:
    """RMSE of each coordinate per method: angles in deg, translations in cm (Markdown)."""
    units = ["cm" if kind == "translation" else "deg" for kind in kinds]
    lines = ["| method | " + " | ".join(f"{name} ({unit})" for name, unit in zip(names, units)) + " |",
             "|---|" + "---:|" * len(names)]
    for row in rows:
        lines.append(f"| {row.name} | " + " | ".join(number(row.record.get(_coordinate_field(name, kind)))
                                                     for name, kind in zip(names, kinds)) + " |")
    return lines


def _coordinate_field(name: str, kind: str) -> str:
    return f"rmse_trans_cm_{name}" if kind == "translation" else f"rmse_rot_deg_{name}"


def residual_means_table(inverse_fields: dict, rows: list[Row]) -> list[str]:
    """The mean residuals FX, FY, MZ of the inverse dynamics and of each method that reached the
    end, beside OpenSim RRA's published averages for OpenSim's example walk (subject01) (Markdown)."""
    lines = ["| | " + " | ".join(label for _, label in RESIDUAL_MEANS) + " |", "|---|---:|---:|---:|",
             "| fdbench inverse dynamics (the model as imported, the recorded kinematics) | "
             + " | ".join(number(inverse_fields.get(name)) for name, _ in RESIDUAL_MEANS) + " |"]
    for row in rows:
        if row.reached_end and row.key != OPEN_LOOP:
            lines.append(f"| {row.name} | " + " | ".join(number(row.record.get(name)) for name, _ in RESIDUAL_MEANS)
                         + " |")
    lines.append("| OpenSim RRA, published for OpenSim's example walk subject01 (after its mass and kinematics adjustment) | "
                 + " | ".join(number(RRA_MEANS[name]) for name, _ in RESIDUAL_MEANS) + " |")
    return lines


# ---- the claim tested -----------------------------------------------------------------------------

SHORT = {OPEN_LOOP: "open loop", PD: "PD", COMPUTED_TORQUE: "computed torque", LQR: "LQR",
         COLLOCATION: "collocation", CMAES: "CMA-ES", BFGS: "BFGS", CMC: "CMC", MUSCLE_COLLOCATION: "muscle collocation"}
TIE_FACTOR = 1.25  # two methods that both reach the end (or both stop) within this factor of RMSE_rot: a tie
SAME_RESIDUALS = 0.01  # residual force RMS within 1 % of each other: the same


def short(row: Row) -> str:
    """The method's short name in the claim's sentences."""
    return SHORT.get(row.key, row.name)


def _rank_key(row: Row):
    """Methods that reach the end first, then by RMSE_rot (missing last)."""
    rmse = row.record.get("rmse_rot_deg")
    rmse = rmse if rmse is not None and math.isfinite(rmse) else math.inf
    return (not row.reached_end, rmse)


def ranking(rows: list[Row]) -> list[str]:
    """The keys of the rows from best to worst: reaching the end first, then RMSE_rot."""
    return [row.key for row in sorted(rows, key=_rank_key)]


def order(a: Row, b: Row) -> int:
    """-1 when a ranks above b (it reaches the end and b does not, or its RMSE_rot is lower by more
    than TIE_FACTOR), 1 when below, 0 for a tie."""
    if a.reached_end != b.reached_end:
        return -1 if a.reached_end else 1
    x, y = (row.record.get("rmse_rot_deg") for row in (a, b))
    x, y = (v if v is not None and math.isfinite(v) else math.inf for v in (x, y))
    if x == y or (math.isfinite(x) and math.isfinite(y) and max(x, y) <= TIE_FACTOR * min(x, y)):
        return 0
    return -1 if x < y else 1


def _names(rows: list[Row]) -> str:
    names = [short(row) for row in rows]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _order_text(rows: list[Row]) -> str:
    return ", ".join(f"{short(row)} ({number(row.record.get('rmse_rot_deg'))} deg"
                     + ("" if row.reached_end else f", stops at {number(row.record.get('t_end'))} s") + ")"
                     for row in sorted(rows, key=_rank_key))


def claim_lines(studied: list[Row], forearm: list[Row], studied_duration: float, forearm_duration: float,
                floating_base: bool = True, inverse_fields: dict | None = None) -> list[str]:
    """The paper's claim ("the forearm generates the same problems as more complex models") tested
    on these runs: where the walk's ranking of the methods (reaching the end, then RMSE_rot) agrees
    with the forearm's, where not, and why; every sentence from the rows' numbers (and the inverse
    dynamics' residual fields, ``inverse_fields``)."""
    pairs = _pairs(studied, forearm)
    if not pairs:
        return ["No method ran on both models; nothing to compare."]
    out = _reaching_lines(pairs, studied_duration, forearm_duration, floating_base)
    out += _ranking_lines(pairs)
    out += _open_loop_lines(pairs)
    out += _residual_lines([w for w, _ in pairs], floating_base, inverse_fields or {})
    out += _cost_lines(pairs)
    return out


def _reaching_lines(pairs, studied_duration, forearm_duration, floating_base) -> list[str]:
    both = [w for w, f in pairs if w.reached_end and f.reached_end]
    neither = [(w, f) for w, f in pairs if not w.reached_end and not f.reached_end]
    studied_only = [(w, f) for w, f in pairs if not w.reached_end and f.reached_end]
    forearm_only = [(w, f) for w, f in pairs if w.reached_end and not f.reached_end]
    agree = len(both) + len(neither)
    out = [f"- **Reaching the end**: {agree} of {len(pairs)} methods behave alike on both models."
           + (f" {_names(both)} reach the end of both motions." if both else "")]
    for w, f in neither:
        out.append(f"- {short(w)} stops on both: the forearm at t = {number(f.get('t_end'))} s of {forearm_duration:g} s "
                   f"({f.get('status')}), the walk at t = {number(w.get('t_end'))} s of {studied_duration:g} s "
                   f"({w.get('status')}).")
    for w, f in studied_only:
        why = ""
        if w.key == OPEN_LOOP and floating_base:
            why = (" Without feedback nothing holds the walk's floating base: the pelvis's three coordinates are "
                   "driven by the inverse-dynamics residuals alone, so the error that open loop accumulates is never "
                   "corrected and the model falls, whereas the forearm's elbow is pinned to the ground.")
        out.append(f"- **Disagrees**: {short(w)} reaches the end of the forearm's motion ({forearm_duration:g} s) but "
                   f"stops on the walk at t = {number(w.get('t_end'))} s of {studied_duration:g} s ({w.get('status')})."
                   + why + _shooting_start(w))
    for w, f in forearm_only:
        out.append(f"- **Disagrees**: {short(w)} reaches the end of the walk ({studied_duration:g} s) but stops on the "
                   f"forearm at t = {number(f.get('t_end'))} s of {forearm_duration:g} s ({f.get('status')}).")
    return out


def _shooting_start(row: Row) -> str:
    """For an optimisation that ended worse than its initial guess: says so, with both objectives."""
    best, initial = row.record.get("best_objective"), row.record.get("initial_objective")
    if best is None or initial is None or not best > initial:
        return ""
    return (f" Its best objective (eq. 18: {number(best)}) is worse than that of its initial guess ({number(initial)}, "
            f"the inverse-dynamics torques alone): none of the {row.get('evaluations')} candidates it evaluated "
            "around that guess did better.")


def _classify(pairs) -> tuple[list, list, list, list]:
    """The pairs of methods (each a (walk row, forearm row) pair) ordered alike on both models, tied
    on at least one, ordered the other way because one reaches the end on one model only, and
    ordered the other way by RMSE_rot ((a, b, order on the forearm))."""
    both = [(pairs[i], pairs[k]) for i in range(len(pairs)) for k in range(i + 1, len(pairs))]
    agree, ties, by_end, by_error = [], [], [], []
    for (wa, fa), (wb, fb) in both:
        on_studied, on_forearm = order(wa, wb), order(fa, fb)
        if 0 in (on_studied, on_forearm):
            ties.append((wa, wb))
        elif on_studied == on_forearm:
            agree.append((wa, wb))
        elif wa.reached_end != wb.reached_end or fa.reached_end != fb.reached_end:
            by_end.append((wa, wb))
        else:
            by_error.append((wa, wb, on_forearm))
    return agree, ties, by_end, by_error


def _pairs(studied: list[Row], forearm: list[Row]) -> list[tuple[Row, Row]]:
    """(walk row, forearm row) of each method run on both."""
    on_forearm = {row.key: row for row in forearm}
    return [(w, on_forearm[w.key]) for w in studied if w.key and w.key in on_forearm]


def claim_facts(studied: list[Row], forearm: list[Row], inverse_fields: dict | None = None) -> dict:
    """The facts behind the claim's sentences (``claim_lines``), by method key, for the JSON
    report: which methods reach the end on which model, the rankings and how many pairs of
    methods they order alike, open loop's rank and its error over PD's, the residual force RMS of
    the methods that reach the walk's end, and the runtimes' ratio walk / forearm."""
    pairs = _pairs(studied, forearm)
    if not pairs:
        return {}
    agree, ties, by_end, by_error = _classify(pairs)
    studied_rows, forearm_rows = [w for w, _ in pairs], [f for _, f in pairs]
    facts = {
        "methods": [w.key for w in studied_rows],
        "reach_the_end": {"both": [w.key for w, f in pairs if w.reached_end and f.reached_end],
                          "neither": [w.key for w, f in pairs if not w.reached_end and not f.reached_end],
                          "forearm_only": [w.key for w, f in pairs if not w.reached_end and f.reached_end],
                          "walk_only": [w.key for w, f in pairs if w.reached_end and not f.reached_end]},
        "ranking": {"forearm": ranking(forearm_rows), "walk": ranking(studied_rows),
                    "pairs": len(agree) + len(ties) + len(by_end) + len(by_error), "alike": len(agree),
                    "ties": len(ties), "other_way_by_reaching_the_end": len(by_end),
                    "other_way_by_rmse_rot": [[a.key, b.key] if on_forearm < 0 else [b.key, a.key]
                                              for a, b, on_forearm in by_error]},
        "worse_than_start": [w.key for w in studied_rows if _shooting_start(w)],
    }
    if OPEN_LOOP in facts["methods"] and PD in facts["methods"]:
        (w, f), (pw, pf) = (next(p for p in pairs if p[0].key == key) for key in (OPEN_LOOP, PD))
        facts["open_loop_over_pd"] = {"forearm": _quotient(f.get("rmse_rot_deg"), pf.get("rmse_rot_deg")),
                                      "walk": _quotient(w.get("rmse_rot_deg"), pw.get("rmse_rot_deg"))}
    reached = sorted((row.get("residual_force_rms_n"), row.key) for row in studied_rows if row.reached_end
                     and row.get("residual_force_rms_n") is not None and math.isfinite(row.get("residual_force_rms_n")))
    facts["residual_force_rms_n"] = {key: value for value, key in reached}
    facts["residual_force_rms_n_inverse"] = (inverse_fields or {}).get("residual_force_rms_n")
    ratios = sorted(r for r in (_quotient(w.get("runtime_s"), f.get("runtime_s")) for w, f in pairs)
                    if r is not None and math.isfinite(r))
    facts["runtime_walk_over_forearm"] = {"min": ratios[0], "median": ratios[len(ratios) // 2], "max": ratios[-1]} \
        if ratios else None
    return facts


def _quotient(a, b):
    return a / b if a is not None and b else None


def _ranking_lines(pairs) -> list[str]:
    studied_rows, forearm_rows = [w for w, _ in pairs], [f for _, f in pairs]
    agree, ties, by_end, by_error = _classify(pairs)
    both = agree + ties + by_end + by_error
    out = [f"- **Ranking** (reaching the end first, then RMSE_rot; best first): forearm {_order_text(forearm_rows)}; "
           f"walk {_order_text(studied_rows)}."]
    best_w, best_f = (min(rows, key=_rank_key) for rows in (studied_rows, forearm_rows))
    best = (f"{short(best_w)} is the best on both" if best_w.key == best_f.key
            else f"the best is {short(best_f)} on the forearm and {short(best_w)} on the walk")
    text = f"- Of the {len(both)} pairs of methods, {len(agree)} {_are(len(agree))} ordered alike on both models"
    if ties:
        text += (f"; {len(ties)} {_are(len(ties))} a tie on at least one model (both reach the end, or both stop, "
                 f"with RMSE_rot within a factor {TIE_FACTOR:g})")
    swapped = len(by_end) + len(by_error)
    text += f"; {swapped} the other way" if swapped else "; none is ordered the other way"
    if by_end:
        text += f" ({len(by_end)} because one of the two reaches the end on one model only, as above"
        text += (")" if not by_error else f"; {len(by_error)} by RMSE_rot: "
                 + "; ".join(_swap_text(a, b, on_forearm) for a, b, on_forearm in by_error) + ")")
    elif by_error:
        text += ": " + "; ".join(_swap_text(a, b, on_forearm) for a, b, on_forearm in by_error)
    out.append(text + f". {best[0].upper() + best[1:]}.")
    return out


def _are(count: int) -> str:
    return "is" if count == 1 else "are"


def _swap_text(a: Row, b: Row, on_forearm: int) -> str:
    first, second = (a, b) if on_forearm < 0 else (b, a)
    return f"{short(first)} above {short(second)} on the forearm, below it on the walk"


def _open_loop_lines(pairs) -> list[str]:
    """Where open loop ranks on each model, and how far its error is from PD's."""
    found = [(w, f) for w, f in pairs if w.key == OPEN_LOOP]
    pd = [(w, f) for w, f in pairs if w.key == PD]
    if not found:
        return []
    w, f = found[0]
    rank_w, rank_f = ranking([a for a, _ in pairs]).index(OPEN_LOOP) + 1, ranking([b for _, b in pairs]).index(OPEN_LOOP) + 1
    text = (f"- **Open loop** ranks {rank_f} of {len(pairs)} on the forearm (RMSE_rot {number(f.get('rmse_rot_deg'))} deg"
            f"{' over the whole motion' if f.reached_end else ' until it stops'}) and {rank_w} of {len(pairs)} on the "
            f"walk ({number(w.get('rmse_rot_deg'))} deg{' over the whole walk' if w.reached_end else ' until it falls'})")
    if pd:
        ratios = [o.get("rmse_rot_deg") / p.get("rmse_rot_deg") for o, p in zip((f, w), pd[0][::-1])
                  if o.get("rmse_rot_deg") and p.get("rmse_rot_deg")]
        if len(ratios) == 2 and min(ratios) > TIE_FACTOR:
            text += (f": on both models the inverse-dynamics torques alone drift from the motion, {_times(ratios[0])} "
                     f"(forearm) and {_times(ratios[1])} (walk) PD's error, as the paper says of the forearm")
        elif len(ratios) == 2:
            text += f"; its error is {_times(ratios[0])} PD's on the forearm and {_times(ratios[1])} on the walk"
    return [text + "."]


def _residual_lines(studied_rows: list[Row], floating_base: bool, inverse_fields: dict) -> list[str]:
    if not floating_base:
        return []
    found = sorted(((row.get("residual_force_rms_n"), row) for row in studied_rows if row.reached_end
                    and row.record.get("residual_force_rms_n") is not None
                    and math.isfinite(row.record["residual_force_rms_n"])), key=lambda x: x[0])
    if not found:
        return ["- **Residuals** exist only on the walk (the forearm has no floating base); no method reached the "
                "walk's end, so none gives the residuals of a whole walk."]
    (low, low_row), (high, high_row) = found[0], found[-1]
    inverse = inverse_fields.get("residual_force_rms_n")
    beside = f" (the inverse dynamics' own: {number(inverse)} N)" if inverse is not None else ""
    text = ("- **Residuals** exist only on the walk: the forearm has no floating base, so the fourth indicator has no "
            "counterpart there. ")
    if len(found) == 1:
        text += (f"{short(low_row)} is the only method that reaches the walk's end: residual force RMS {number(low)} N"
                 f"{beside}.")
    elif high <= (1 + SAME_RESIDUALS) * low:
        text += (f"The {len(found)} methods that reach the walk's end leave the same "
                 f"residual force RMS to within {100 * SAME_RESIDUALS:g} %: {number(low)} N{beside}; tracking the "
                 "recorded kinematics this closely keeps the residuals inverse dynamics needs, so on this walk the "
                 "fourth indicator does not separate them.")
    else:
        text += (f"Among the methods that reach the walk's end, the residual force RMS goes from {number(low)} N "
                 f"({short(low_row)}) to {number(high)} N ({short(high_row)}){beside}.")
    return [text]


def _cost_lines(pairs) -> list[str]:
    ratios = sorted(w.get("runtime_s") / f.get("runtime_s") for w, f in pairs
                    if w.get("runtime_s") and f.get("runtime_s") and math.isfinite(w.get("runtime_s") / f.get("runtime_s")))
    out = []
    if ratios:
        out.append(f"- **Cost**: a walk's run takes {_times(ratios[0])} to {_times(ratios[-1])} the forearm's runtime "
                   f"(median {_times(ratios[len(ratios) // 2])}).")
    for w, f in pairs:
        if w.record.get("n_params") and f.record.get("n_params"):
            out.append(f"- {short(w)}: the same budget of {w.get('budget')} simulations is spread over "
                       f"{w.get('n_params')} spline parameters on the walk against {f.get('n_params')} on the forearm; "
                       f"it ends at RMSE_rot {number(w.get('rmse_rot_deg'))} deg on the walk, "
                       f"{number(f.get('rmse_rot_deg'))} deg on the forearm.")
    return out


def _times(ratio: float) -> str:
    return f"{ratio:,.0f} times" if ratio >= 9.5 else f"{ratio:.2g} times"


# ---- the whole report ----------------------------------------------------------------------------


@dataclass
class Parts:
    """What the report's sections are written from: the plan, the rows per dataset (``studied``: the
    studied one), the inverse dynamics and its residual fields, the coordinates' names and kinds,
    the settings, every row (for the provenance), the figures' links, the peers' lines, the paper's cells."""

    plan: ComparisonPlan
    studied: list
    forearm: list
    inverse: object
    inverse_fields: dict
    names: tuple
    kinds: tuple
    settings: dict
    provenance: list  # every row, for "When and where the runs were made"
    figures: dict | None = None
    peers: list | None = None
    cells: list = field(default_factory=list)
    extra: list = field(default_factory=list)

    @property
    def duration(self) -> float:
        return float(self.inverse.t[-1])


def _intro(p: Parts) -> list[str]:
    return ["# fdbench report: a recorded walk", "",
            f"Trajectory tracking of a recorded motion of {len(p.names)} coordinates ({', '.join(p.names)}) on a "
            "model with a floating base, driven by its measured external loads: which method keeps the recording, how "
            "closely, how fast and with how much residual force; then the same methods on the paper's forearm, to test "
            "its claim that the forearm \"generates the same problems as more complex models\".", ""]


def _residuals(p: Parts) -> list[str]:
    return ["", "## Inverse dynamics and its residuals", "",
            "The inverse dynamics of the recording (its derivatives estimated as the settings say) with the measured "
            "loads leaves residual forces and a moment on the floating base: what the recorded kinematics, the model "
            "and the loads do not agree on. Their means over the walk, beside OpenSim RRA's published averages for "
            "OpenSim's example walk (subject01, the trial in examples/opensim: a reference point for another "
            "recording, not its own); RRA's come after it adjusted the model's masses and the kinematics to shrink "
            "them, which fdbench does not do, so larger means here are expected:", ""] \
        + residual_means_table(p.inverse_fields, p.studied)


def _methods(p: Parts) -> list[str]:
    return (["", "## Methods", ""] + [f"- **{m.name}**: {m.description}." for m in p.plan.studied]
            + [f"- {reason}" for reason in dict.fromkeys(reason for _, reason in p.plan.skipped)])


def _indicators(p: Parts) -> list[str]:
    return ["", "## Results on the walk", "",
            "RMSE_rot over the angles (deg) and RMSE_trans over the pelvis's translations (cm), never pooled; "
            "RMSE_torque (N m) and RMSE_force (N) of the applied generalised forces against the inverse dynamics'; "
            "the residual force's and moment's RMS on the floating base (the fourth indicator: the smaller, the more "
            "dynamically consistent the tracked walk); all over the samples reached, one run each.", ""] \
        + main_table(p.studied, p.duration) + collocation_own_lines(p.studied)


def _per_coordinate(p: Parts) -> list[str]:
    return ["", "### Error per coordinate", ""] + coordinate_table(p.studied, p.names, p.kinds)


def _forearm(p: Parts) -> list[str]:
    return ["", "## The same methods on the forearm", "",
            "The paper's forearm and motion (eq. 5), the same methods, budget and population:", ""] \
        + main_table(p.forearm, _duration(p.forearm), ("rmse_rot_deg", "rmse_torque_nm", "runtime_s"))


def _claim(p: Parts) -> list[str]:
    return ["", "## The paper's claim tested", "",
            "The paper offers the forearm as a stand-in that \"generates the same problems as more complex models\". "
            "From the runs above:", ""] \
        + claim_lines(p.studied, p.forearm, p.duration, _duration(p.forearm), True, p.inverse_fields)


# the report's sections in order, each with when it applies
SECTIONS = (
    (_intro, lambda p: True),
    (lambda p: settings_lines(p.settings), lambda p: True),
    (_residuals, lambda p: bool(p.inverse_fields)),  # a floating base
    (_methods, lambda p: True),
    (_indicators, lambda p: True),
    (_per_coordinate, lambda p: len(p.names) > 1),
    (lambda p: ["", "### The muscles"] + muscles_markdown(p.studied), lambda p: bool(muscles_markdown(p.studied))),
    (lambda p: _cells_lines(p.cells, p.extra), lambda p: bool(p.cells or p.extra)),
    (_forearm, lambda p: bool(p.forearm)),
    (_claim, lambda p: bool(p.forearm)),
    (lambda p: [""] + p.peers, lambda p: bool(p.peers)),
    (lambda p: [""] + provenance_section(p.provenance), lambda p: True),
    (lambda p: [""] + figure_lines(p.figures), lambda p: bool(p.figures)),
)


def markdown(plan, studied: list[Row], forearm: list[Row], inverse, inverse_fields: dict, names: tuple,
             kinds: tuple, settings: dict, provenance: list[Row], figures: dict | None = None,
             peers: list[str] | None = None, cells: list[Row] | None = None, extra: list[Row] | None = None) -> str:
    """The report as Markdown: every section of ``SECTIONS`` that applies. ``peers``: the lines of
    its section "Peers" (``--peers``); ``cells`` and ``extra``: the rows of the paper's cells
    selected on the studied dataset and of their exact gradients."""
    return render(SECTIONS, Parts(plan, studied, forearm, inverse, inverse_fields, names, kinds, settings, provenance,
                                  figures, peers, list(cells or []), list(extra or [])))


def _cells_lines(cells: list[Row], extra: list[Row]) -> list[str]:
    """The section of the paper's cells selected on the studied dataset (--torque, --opt,
    --feedforward, --all-cells; --seeds runs each): its Tables 2 and 3 without the paper's figures
    (it has none for this model), then the rows of their exact gradients (--gradient exact)."""
    from .paper import results_table, failure_lines

    if not cells and not extra:
        return []
    out = ["", "## The paper's Tables 2 and 3 on the walk", "",
           "The paper's cells selected by the options, on the walk (the paper has no figures for this model); "
           "median ± half the IQR over the seeds:"]
    for table in (2, 3):
        found = [row for row in cells if row.table == table]
        if found:
            out += ["", f"Table {table} ({'with' if table == 3 else 'without'} computed feedforward):", ""]
            out += results_table(found, with_success=True)
    if extra:
        out += ["", "The same cells with exact gradients (seed 0):", ""] + results_table(extra, with_success=False)
    failed = failure_lines(cells + extra)
    if failed:
        out += ["", "Runs that did not succeed:", ""] + failed
    return out


def _duration(rows: list[Row]) -> float:
    """The motion's duration of the rows' runs, from their specs (1 s for eq. 5)."""
    for row in rows:
        if row.specs:
            return float(row.specs[0].motions()[1].duration)
    return 1.0


def csv_rows(studied: list[Row], forearm: list[Row], cells: list[Row] = ()) -> list[list]:
    """One row per method and model (the columns of ``CSV_COLUMNS``), then one per run of the
    paper's cells on the studied dataset."""
    return [[("" if value is None else value) for value in _flat(row, model, k).values()]
            for model, found in (("walk", studied), ("forearm", forearm), ("walk", cells)) for row in found
            for k in range(len(row.records))]


def _flat(row: Row, model: str, index: int = 0) -> dict:
    rec = row.records[index]
    provenance = row.provenance[index] if index < len(row.provenance) else {}
    key = row.key or (f"table{row.table}-seed{index}" if row.cell is not None else "")
    values = {"model": model, "method": row.name, "key": key, "command": rec.get("command"),
              "controller": rec.get("controller"), "status": rec.get("status"), "t_end": rec.get("t_end"),
              **{name: rec.get(name) for name in CSV_COLUMNS[7:-2]},
              "spec_hash": row.hashes[index] if index < len(row.hashes) else "", "run_id": provenance.get("id")}
    return {name: values.get(name) for name in CSV_COLUMNS}


def json_report(plan, studied: list[Row], forearm: list[Row], inverse_fields: dict, settings: dict,
                claim: list[str], cells: list[Row] = ()) -> dict:
    """The report as one JSON-ready object: settings, the inverse dynamics' residuals beside RRA's,
    every run's record per model, the methods left out and why (``skipped``; ``bfgs``: BFGS's
    reason), the claim's sentences and, with cells selected, their entries (``paper.json_report``)."""
    from ..files import finite_or_none

    def entry(row):
        return {"method": row.name, "key": row.key, "spec_hash": row.hashes[0] if row.hashes else "",
                "run_id": row.provenance[0].get("id") if row.provenance else None,
                "record": {k: finite_or_none(v) for k, v in row.record.items()}}

    out = {"command": "report", "kind": "walk", "fdbench_version": __version__, "settings": settings,
           "inverse_residuals": {k: finite_or_none(v) for k, v in inverse_fields.items()},
           "rra_published_means": dict(RRA_MEANS), "bfgs": plan.bfgs_note,
           "skipped": [{"key": key, "reason": reason} for key, reason in plan.skipped],
           "walk": [entry(row) for row in studied], "forearm": [entry(row) for row in forearm],
           "claim": [line.removeprefix("- ").replace("**", "") for line in claim],
           "claim_facts": claim_facts(studied, forearm, inverse_fields)}
    if cells:
        from .paper import json_report as cell_report

        out["cells"] = cell_report(list(cells), {})["cells"]
    return out


# ---- the whole report ------------------------------------------------------------------------------


def beside(studied: list[Row]) -> list[Row]:
    """The studied dataset's methods as rows a peer stands beside (``report.peers.side_by_side``):
    PD control as the paper report's control row, open loop (PD with zero gains) left out."""
    return [Row(row.name, "control" if row.key == PD else row.table, None, row.summary, None, row.records,
                key=row.key) for row in studied if row.key != OPEN_LOOP]


def peers_json(peer_rows: list[Row], studied: list[Row]) -> list:
    """The peers for the JSON report: per peer its name, label, hash and record, and beside the
    fdbench method it stands for ``vs_fdbench`` (and MocoTrack's ``vs_fdbench_solve``)."""
    from ..files import finite_or_none
    from ..report.peers import plain_pair, side_by_side

    pairs = side_by_side(peer_rows, beside(studied))
    out = []
    for row in peer_rows:
        rec = row.records[0]
        entry = {"peer": rec.get("peer"), "method": row.name, "spec_hash": row.hashes[0],
                 "run_id": row.provenance[0].get("id") if row.provenance else None,
                 "record": {k: finite_or_none(v) for k, v in rec.items()}}
        for pair in pairs:
            if pair["peer"] == row.name:
                entry["vs_fdbench_solve" if pair.get("solve_alone") else "vs_fdbench"] = plain_pair(pair)
        out.append(entry)
    return out


def _peer_keyed(peer_rows: list[Row]) -> list[Row]:
    """The peers' rows keyed by the peer's name (the CSV's key column)."""
    import dataclasses

    return [dataclasses.replace(row, key=row.records[0].get("peer")) for row in peer_rows]


def settings_table(plan: ComparisonPlan, spec, jobs: str, seeds: int = 1) -> dict:
    """The report's settings: the model, motion, loads, estimate, simulation, budgets, versions."""
    from datetime import datetime, timezone

    from ..models import summary
    from ..store import git_commit, machine
    from .paper import condition_settings

    loads = dict(spec.inputs).get("--loads")
    conditions = {key: value.replace("Figure 2", "the coordinates figure")
                  for key, value in condition_settings(spec, [m.spec for m in plan.studied]).items()}
    options = plan.options
    cmaes = f"CMA-ES, budget {options.budget} simulations, population {options.popsize}" + (
        f", sigma0 {options.sigma0:g}" if options.sigma0 is not None else "") + (
        f", {options.knots} knots" if options.knots is not None else "")
    table = {"model": f"{spec.model_name}: {summary(spec.model_name)}",
             **conditions,
             "external loads": f"{spec.loads}" + (f", SHA-256 {loads[:16]} (with its data file)" if loads else "")
             if spec.loads else "none",
             "integrator": spec.integrator + (f" (dt = {spec.dt:.6g} s)" if spec.integrator == "rk4" else ""),
             "penalty formulation": f"alpha = {spec.alpha:g}, xi = {spec.xi:g}, omega = {spec.omega:g} rad/s",
             "shooting": f"{cmaes}, seed 0 (the same on the forearm)"}
    if options.kp is not None or options.kd is not None:
        table["PD gains"] = (f"Kp = {options.kp if options.kp is not None else 'default'}, "
                             f"Kd = {options.kd if options.kd is not None else 'default'} (on both models)")
    if plan.studied and plan.datasets[0].penalty_weight != FLOATING_BASE_PENALTY:
        table["penalty weight"] = f"{plan.datasets[0].penalty_weight:g} deg on the walk (eq. 18)"
    if plan.cells is not None and plan.cells.cells:
        table["paper's cells"] = (f"{len(plan.cells.cells)} on the walk, {seeds} seed(s) each, budget "
                                  f"{options.budget} evaluations")
    table.update({
        "forearm": "the paper's model and motion (eq. 5, as printed), the same methods and settings",
        "runtime_s": "the method's own wall time per run (design or optimisation, simulations and their samples); "
                     "before the clock starts, as in the C speed limit: the references and eq. 3's feedforward on "
                     "the RK4 half-step grid, eq. 3 on the samples, imports and kernel loading",
        "parallel jobs": jobs,
        "fdbench": __version__ + (f" (commit {git_commit()[:12]})" if git_commit() else ""),
        "machine": machine(),
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")})
    return table


def report_rows(plan: ComparisonPlan, runs: dict, made: dict, peer_methods=()) -> dict:
    """The report's rows from the stored runs: {"walk", "forearm", "cells", "extra", "peers"}."""
    from .paper import build_rows

    cells = [row for row in build_rows(plan.cells, runs, made) if row.table != "control"] \
        if plan.cells is not None else []
    return {"walk": rows(plan.studied, runs, made, "walk"), "forearm": rows(plan.forearm, runs, made, "forearm"),
            "cells": cells, "extra": rows(plan.extra, runs, made), "peers": rows(list(peer_methods), runs, made, "peers")}


def text(fmt: str, plan: ComparisonPlan, found: dict, runs: dict, jobs: str, figures=None, base=None,
         processes: int = 1, peer_methods=(), seeds: int = 1) -> tuple[str, int]:
    """The report in ``fmt`` (md, csv or json) from its rows ``found`` (``report_rows``), and the
    count of figures written into ``figures`` (linked relative to ``base``)."""
    spec = plan.studied[0].spec if plan.studied else plan.cells.all_specs()[0]
    inverse = spec.reference()
    studied, forearm, cells, extra, peer_rows = (found[k] for k in ("walk", "forearm", "cells", "extra", "peers"))
    fields = inverse_residuals(spec, inverse)
    settings = settings_table(plan, spec, jobs, seeds)
    if fmt == "csv":
        from ..files import csv_text

        return csv_text(list(CSV_COLUMNS), csv_rows(studied + _peer_keyed(peer_rows) + extra, forearm, cells)), 0
    duration, forearm_duration = float(inverse.t[-1]), _duration(forearm)
    claim = claim_lines(studied, forearm, duration, forearm_duration, True, fields)
    if fmt == "json":
        report = json_report(plan, studied + extra, forearm, fields, settings, claim, cells)
        if peer_rows:
            report["peers"] = peers_json(peer_rows, studied)
        return json.dumps(report, indent=2) + "\n", 0
    links = None
    if figures is not None:
        from ..figures import write_model_figures
        from ..files import new_folder

        with new_folder(figures):  # removed again if a figure cannot be written
            links = write_model_figures(spec, inverse, studied, runs, figures, base, processes, SHORT)
    names, kinds = coordinates(spec)
    section = None
    if peer_rows:
        from ..report.peers import peers_markdown

        section = peers_markdown(peer_rows, list(peer_methods), beside(studied))
    return markdown(plan, studied, forearm, inverse, fields, names, kinds, settings,
                    studied + forearm + cells + extra + _peer_keyed(peer_rows), links, section, cells,
                    extra), len(links or {})
