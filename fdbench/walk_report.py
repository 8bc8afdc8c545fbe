"""The text of the walk's report (``fdbench.walk``): its tables (every method's indicators, the
error per coordinate, the residual means beside OpenSim RRA's), the forearm's table, and the
paper's claim tested, every sentence built from the runs' numbers; as Markdown, CSV or JSON."""

from __future__ import annotations

import math

from . import __version__
from .walk import BFGS, CMAES, COLLOCATION, COMPUTED_TORQUE, LQR, OPEN_LOOP, PD, RRA_MEANS, WalkRow

MAIN_COLUMNS = ("method", "status / t_end", "RMSE_rot (deg)", "RMSE_trans (cm)", "RMSE_torque (N m)",
                "RMSE_force (N)", "residual force RMS (N)", "residual moment RMS (N m)", "runtime (s)")
MAIN_FIELDS = ("rmse_rot_deg", "rmse_trans_cm", "rmse_torque_nm", "rmse_force_n", "residual_force_rms_n",
               "residual_moment_rms_nm", "runtime_s")
CSV_COLUMNS = ("model", "method", "key", "command", "controller", "status", "t_end", *MAIN_FIELDS,
               "residual_fx_mean_n", "residual_fy_mean_n", "residual_mz_mean_nm", "evaluations", "budget", "n_params",
               "spec_hash", "run_id")
RESIDUAL_MEANS = (("residual_fx_mean_n", "FX (N)"), ("residual_fy_mean_n", "FY (N)"), ("residual_mz_mean_nm", "MZ (N m)"))


def number(value) -> str:
    """Three significant digits ('-' for a missing or non-finite value)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.3g}"


def ended(row: WalkRow, duration: float) -> str:
    """'reached 2.5 s' or 'constraint at 0.441 s'."""
    t_end = row.get("t_end", math.nan)
    if row.reached_end:
        return f"reached {duration:g} s"
    return f"{row.get('status', 'not run')} at {number(t_end)} s"


# ---- tables ------------------------------------------------------------------------------------


def main_table(rows: list[WalkRow], duration: float) -> list[str]:
    """Every method's status and indicators, one line each (Markdown)."""
    lines = ["| " + " | ".join(MAIN_COLUMNS) + " |", "|---|---|" + "---:|" * len(MAIN_FIELDS)]
    for row in rows:
        values = " | ".join(number(row.record.get(name)) for name in MAIN_FIELDS)
        lines.append(f"| {row.name} | {ended(row, duration)} | {values} |")
    return lines


def collocation_own_lines(rows: list[WalkRow]) -> list[str]:
    """A sentence on the collocation's own solution at its points (the table gives its torque's
    forward replay), or nothing when no collocation row ran."""
    for row in rows:
        own = row.record.get("collocation_rmse_rot_deg")
        if row.key == COLLOCATION and own is not None:
            get = row.record.get
            return ["", f"Collocation's own solution, at its points (the row above is its torque replayed open loop "
                        f"through fdbench's simulation): RMSE_rot {number(own)} deg, RMSE_trans "
                        f"{number(get('collocation_rmse_trans_cm'))} cm, residual force RMS "
                        f"{number(get('collocation_residual_force_rms_n'))} N, moment RMS "
                        f"{number(get('collocation_residual_moment_rms_nm'))} N m."]
    return []


def coordinate_table(rows: list[WalkRow], names: tuple, kinds: tuple) -> list[str]:
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


def forearm_table(rows: list[WalkRow], duration: float) -> list[str]:
    """The forearm's runs of the same methods: status, RMSE_rot, RMSE_torque, runtime (Markdown)."""
    lines = ["| method | status / t_end | RMSE_rot (deg) | RMSE_torque (N m) | runtime (s) |", "|---|---|---:|---:|---:|"]
    for row in rows:
        lines.append(f"| {row.name} | {ended(row, duration)} | {number(row.record.get('rmse_rot_deg'))} "
                     f"| {number(row.record.get('rmse_torque_nm'))} | {number(row.record.get('runtime_s'))} |")
    return lines


def residual_means_table(inverse_fields: dict, rows: list[WalkRow]) -> list[str]:
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
         COLLOCATION: "collocation", CMAES: "CMA-ES", BFGS: "BFGS"}
TIE_FACTOR = 1.25  # two methods that both reach the end (or both stop) within this factor of RMSE_rot: a tie
SAME_RESIDUALS = 0.01  # residual force RMS within 1 % of each other: the same


def short(row: WalkRow) -> str:
    """The method's short name in the claim's sentences."""
    return SHORT.get(row.key, row.name)


def _rank_key(row: WalkRow):
    """Methods that reach the end first, then by RMSE_rot (missing last)."""
    rmse = row.record.get("rmse_rot_deg")
    rmse = rmse if rmse is not None and math.isfinite(rmse) else math.inf
    return (not row.reached_end, rmse)


def ranking(rows: list[WalkRow]) -> list[str]:
    """The keys of the rows from best to worst: reaching the end first, then RMSE_rot."""
    return [row.key for row in sorted(rows, key=_rank_key)]


def order(a: WalkRow, b: WalkRow) -> int:
    """-1 when a ranks above b (it reaches the end and b does not, or its RMSE_rot is lower by more
    than TIE_FACTOR), 1 when below, 0 for a tie."""
    if a.reached_end != b.reached_end:
        return -1 if a.reached_end else 1
    x, y = (row.record.get("rmse_rot_deg") for row in (a, b))
    x, y = (v if v is not None and math.isfinite(v) else math.inf for v in (x, y))
    if x == y or (math.isfinite(x) and math.isfinite(y) and max(x, y) <= TIE_FACTOR * min(x, y)):
        return 0
    return -1 if x < y else 1


def _names(rows: list[WalkRow]) -> str:
    names = [short(row) for row in rows]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _order_text(rows: list[WalkRow]) -> str:
    return ", ".join(f"{short(row)} ({number(row.record.get('rmse_rot_deg'))} deg"
                     + ("" if row.reached_end else f", stops at {number(row.record.get('t_end'))} s") + ")"
                     for row in sorted(rows, key=_rank_key))


def claim_lines(walk: list[WalkRow], forearm: list[WalkRow], walk_duration: float, forearm_duration: float,
                floating_base: bool = True, inverse_fields: dict | None = None) -> list[str]:
    """The paper's claim ("the forearm generates the same problems as more complex models") tested
    on these runs: where the walk's ranking of the methods (reaching the end, then RMSE_rot) agrees
    with the forearm's, where not, and why; every sentence from the rows' numbers (and the inverse
    dynamics' residual fields, ``inverse_fields``)."""
    on_forearm = {row.key: row for row in forearm}
    pairs = [(w, on_forearm[w.key]) for w in walk if w.key in on_forearm]
    if not pairs:
        return ["No method ran on both models; nothing to compare."]
    out = _reaching_lines(pairs, walk_duration, forearm_duration, floating_base)
    out += _ranking_lines(pairs)
    out += _open_loop_lines(pairs)
    out += _residual_lines([w for w, _ in pairs], floating_base, inverse_fields or {})
    out += _cost_lines(pairs)
    return out


def _reaching_lines(pairs, walk_duration, forearm_duration, floating_base) -> list[str]:
    both = [w for w, f in pairs if w.reached_end and f.reached_end]
    neither = [(w, f) for w, f in pairs if not w.reached_end and not f.reached_end]
    walk_only = [(w, f) for w, f in pairs if not w.reached_end and f.reached_end]
    forearm_only = [(w, f) for w, f in pairs if w.reached_end and not f.reached_end]
    agree = len(both) + len(neither)
    out = [f"- **Reaching the end**: {agree} of {len(pairs)} methods behave alike on both models."
           + (f" {_names(both)} reach the end of both motions." if both else "")]
    for w, f in neither:
        out.append(f"- {short(w)} stops on both: the forearm at t = {number(f.get('t_end'))} s of {forearm_duration:g} s "
                   f"({f.get('status')}), the walk at t = {number(w.get('t_end'))} s of {walk_duration:g} s "
                   f"({w.get('status')}).")
    for w, f in walk_only:
        why = ""
        if w.key == OPEN_LOOP and floating_base:
            why = (" Without feedback nothing holds the walk's floating base: the pelvis's three coordinates are "
                   "driven by the inverse-dynamics residuals alone, so the error that open loop accumulates is never "
                   "corrected and the model falls, whereas the forearm's elbow is pinned to the ground.")
        out.append(f"- **Disagrees**: {short(w)} reaches the end of the forearm's motion ({forearm_duration:g} s) but "
                   f"stops on the walk at t = {number(w.get('t_end'))} s of {walk_duration:g} s ({w.get('status')})."
                   + why + _shooting_start(w))
    for w, f in forearm_only:
        out.append(f"- **Disagrees**: {short(w)} reaches the end of the walk ({walk_duration:g} s) but stops on the "
                   f"forearm at t = {number(f.get('t_end'))} s of {forearm_duration:g} s ({f.get('status')}).")
    return out


def _shooting_start(row: WalkRow) -> str:
    """For an optimisation that ended worse than its initial guess: says so, with both objectives."""
    best, initial = row.record.get("best_objective"), row.record.get("initial_objective")
    if best is None or initial is None or not best > initial:
        return ""
    return (f" Its best objective (eq. 18: {number(best)}) is worse than that of its initial guess ({number(initial)}, "
            f"the inverse-dynamics torques alone): none of the {row.get('evaluations')} candidates it evaluated "
            "around that guess did better.")


def _ranking_lines(pairs) -> list[str]:
    walk_rows, forearm_rows = [w for w, _ in pairs], [f for _, f in pairs]
    both = [(pairs[i], pairs[k]) for i in range(len(pairs)) for k in range(i + 1, len(pairs))]
    agree, ties, by_end, by_error = [], [], [], []
    for (wa, fa), (wb, fb) in both:
        on_walk, on_forearm = order(wa, wb), order(fa, fb)
        if 0 in (on_walk, on_forearm):
            ties.append((wa, wb))
        elif on_walk == on_forearm:
            agree.append((wa, wb))
        elif wa.reached_end != wb.reached_end or fa.reached_end != fb.reached_end:
            by_end.append((wa, wb))
        else:
            by_error.append((wa, wb, on_forearm))
    out = [f"- **Ranking** (reaching the end first, then RMSE_rot; best first): forearm {_order_text(forearm_rows)}; "
           f"walk {_order_text(walk_rows)}."]
    best_w, best_f = (min(rows, key=_rank_key) for rows in (walk_rows, forearm_rows))
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


def _swap_text(a: WalkRow, b: WalkRow, on_forearm: int) -> str:
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


def _residual_lines(walk_rows: list[WalkRow], floating_base: bool, inverse_fields: dict) -> list[str]:
    if not floating_base:
        return []
    found = sorted(((row.get("residual_force_rms_n"), row) for row in walk_rows if row.reached_end
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


def markdown(plan, walk: list[WalkRow], forearm: list[WalkRow], inverse, inverse_fields: dict, names: tuple,
             kinds: tuple, settings: dict, provenance: list[str], figures: dict | None = None,
             peers: list[str] | None = None) -> str:
    """The walk's report as Markdown; ``peers``: the lines of its section "Peers" (``--peers``)."""
    duration, forearm_duration = float(inverse.t[-1]), _duration(forearm)
    out = ["# fdbench report: a recorded walk", "",
           f"Trajectory tracking of a recorded motion of {len(names)} coordinates ({', '.join(names)}) on a model with "
           "a floating base, driven by its measured external loads: which method keeps the recording, how closely, "
           "how fast and with how much residual force; then the same methods on the paper's forearm, to test its claim "
           "that the forearm \"generates the same problems as more complex models\".", "",
           "## Settings", "", "| setting | value |", "|---|---|"]
    out += [f"| {key} | {value} |" for key, value in settings.items()]
    out += ["", "## Inverse dynamics and its residuals", "",
            "The inverse dynamics of the recording (its derivatives estimated as the settings say) with the measured "
            "loads leaves residual forces and a moment on the floating base: what the recorded kinematics, the model "
            "and the loads do not agree on. Their means over the walk, beside OpenSim RRA's published averages for "
            "OpenSim's example walk (subject01, the trial in examples/opensim: a reference point for another "
            "recording, not its own); RRA's come after it adjusted the model's masses and the kinematics to shrink them, which "
            "fdbench does not do, so larger means here are expected:", ""]
    out += residual_means_table(inverse_fields, walk)
    out += ["", "## Methods", ""] + [f"- **{m.name}**: {m.description}." for m in plan.walk]
    if plan.bfgs_note:
        out += [f"- {plan.bfgs_note}"]
    out += ["", "## Results on the walk", "",
            "RMSE_rot over the angles (deg) and RMSE_trans over the pelvis's translations (cm), never pooled; "
            "RMSE_torque (N m) and RMSE_force (N) of the applied generalised forces against the inverse dynamics'; "
            "the residual force's and moment's RMS on the floating base (the fourth indicator: the smaller, the more "
            "dynamically consistent the tracked walk); all over the samples reached, one run each.", ""]
    out += main_table(walk, duration)
    out += collocation_own_lines(walk)
    out += ["", "### Error per coordinate", ""] + coordinate_table(walk, names, kinds)
    out += ["", "## The same methods on the forearm", "",
            "The paper's forearm and motion (eq. 5), the same methods, budget and population:", ""]
    out += forearm_table(forearm, forearm_duration)
    out += ["", "## The paper's claim tested", "",
            "The paper offers the forearm as a stand-in that \"generates the same problems as more complex models\". "
            "From the runs above:", ""]
    out += claim_lines(walk, forearm, duration, forearm_duration, True, inverse_fields)
    if peers:
        out += [""] + peers
    out += ["", "## When and where the runs were made", ""] + provenance
    if figures:
        out += ["", "## Figures", ""] + [f"![{name}]({path})" for name, path in figures.items()]
    return "\n".join(out).rstrip() + "\n"


def _duration(rows: list[WalkRow]) -> float:
    """The motion's duration of the rows' runs, from their specs (1 s for eq. 5)."""
    for row in rows:
        if row.spec is not None:
            return float(row.spec.motions()[1].duration)
    return 1.0


def csv_rows(walk: list[WalkRow], forearm: list[WalkRow]) -> list[list]:
    """One row per method and model (the columns of ``CSV_COLUMNS``)."""
    return [[("" if value is None else value) for value in _flat(row, model).values()]
            for model, rows in (("walk", walk), ("forearm", forearm)) for row in rows]


def _flat(row: WalkRow, model: str) -> dict:
    rec = row.record
    values = {"model": model, "method": row.name, "key": row.key, "command": rec.get("command"),
              "controller": rec.get("controller"), "status": rec.get("status"), "t_end": rec.get("t_end"),
              **{name: rec.get(name) for name in CSV_COLUMNS[7:-2]}, "spec_hash": row.hash,
              "run_id": row.provenance.get("id")}
    return {name: values.get(name) for name in CSV_COLUMNS}


def json_report(plan, walk: list[WalkRow], forearm: list[WalkRow], inverse_fields: dict, settings: dict,
                claim: list[str]) -> dict:
    """The report as one JSON-ready object: settings, the inverse dynamics' residuals beside RRA's,
    every run's record per model, the BFGS note and the claim's sentences."""
    from .files import finite_or_none

    def entry(row):
        return {"method": row.name, "key": row.key, "spec_hash": row.hash, "run_id": row.provenance.get("id"),
                "record": {k: finite_or_none(v) for k, v in row.record.items()}}

    return {"command": "report", "kind": "walk", "fdbench_version": __version__, "settings": settings,
            "inverse_residuals": {k: finite_or_none(v) for k, v in inverse_fields.items()},
            "rra_published_means": dict(RRA_MEANS), "bfgs": plan.bfgs_note,
            "walk": [entry(row) for row in walk], "forearm": [entry(row) for row in forearm],
            "claim": [line.removeprefix("- ").replace("**", "") for line in claim]}
