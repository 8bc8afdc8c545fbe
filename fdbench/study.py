"""Studies: one condition swept over the methods, ``noise`` (the captured motion's white noise, deg,
one realisation per seed) or ``mismatch`` (one plant constant changed by each level, %). A study's
specs (``Sweep``) are run and stored like a report's; its summary has each indicator's median and
interquartile range per method and level.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .report.paper_methods import INDICATORS, Cell, failure_message, outcome_text, succeeded
from .spec import RunSpec, control_spec, gradient_for, optimize_spec

KINDS = ("noise", "mismatch")
MAX_LEVELS = 50
UNITS = {"noise": "deg", "mismatch": "%"}
AXIS = {"noise": "noise on the captured angle (deg)", "mismatch": "plant {param} against the nominal model (%)"}


@dataclass(frozen=True)
class Sweep:
    """The runs of a study: {(method label, level): tuple of RunSpec}, methods in order."""

    kind: str
    param: str | None
    levels: tuple
    methods: tuple  # labels, PD first
    specs: dict

    def all_specs(self) -> list[RunSpec]:
        return [spec for key in self.specs for spec in self.specs[key]]


def parse_levels(text: str, kind: str) -> tuple:
    """'0,0.25,0.5' -> (0.0, 0.25, 0.5): finite, distinct, at most MAX_LEVELS; noise >= 0, mismatch > -100 %."""
    try:
        levels = tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise ValueError(f"--levels: expected numbers separated by commas, got {text!r}") from None
    if not levels or len(levels) > MAX_LEVELS:
        raise ValueError(f"--levels: give 1 to {MAX_LEVELS} levels, got {len(levels)}")
    if not all(math.isfinite(v) for v in levels) or len(set(levels)) != len(levels):
        raise ValueError(f"--levels: levels must be finite and distinct, got {text!r}")
    if kind == "noise" and min(levels) < 0:
        raise ValueError("--levels: noise levels are standard deviations in deg, >= 0")
    if kind == "mismatch" and min(levels) <= -100:
        raise ValueError("--levels: a mismatch in percent must be above -100 (the constant stays positive)")
    return tuple(sorted(levels))


def method_label(cell: Cell | None) -> str:
    if cell is None:
        return "PD + feedforward"
    ff = " + ff" if cell.feedforward else ""
    return f"{cell.torque.upper()} + {cell.optimizer}{ff}"


def make_sweep(kind: str, levels, seeds: int, cells, control: bool, kp: float, kd: float, budget: int,
               torque_options: dict, optimizer_options: dict, penalty_weight: float, param: str | None = None,
               gradient: str = "fd", **common) -> Sweep:
    """The specs of a study: for each level, PD control (one run per seed when the runs differ by
    their noise, else one) and each optimisation cell (seeds 0..seeds-1)."""
    from .models import value_of, with_changes

    if kind not in KINDS:
        from .registry import unknown_name_message

        raise ValueError(unknown_name_message("study", kind, list(KINDS)))
    nominal = with_changes(common.get("model_name", "forearm"), common.get("model", ()))
    specs, methods = {}, []
    for level in levels:
        if kind == "noise":
            condition = {"noise_deg": float(level)}
        else:
            value = value_of(common.get("model_name", "forearm"), nominal, param) * (1 + level / 100)
            condition = {"plant": tuple(common.get("plant", ())) + ((param, value),)}
        base = {**common, **condition}
        noisy = bool(base.get("noise_deg"))
        if control:
            label = method_label(None)
            pd = control_spec(kp, kd, **base)
            runs = tuple(replace(pd, seed=s) for s in range(seeds)) if noisy else (pd,)
            specs[(label, level)] = runs
            methods.append(label)
        for cell in cells:
            label = method_label(cell) + (", exact gradient" if gradient_for(cell.optimizer, gradient) == "exact" else "")
            specs[(label, level)] = tuple(
                optimize_spec(cell.torque, cell.optimizer, cell.feedforward, seed, budget, torque_options,
                              optimizer_options, penalty_weight=penalty_weight, shared_options=True,
                              gradient=gradient_for(cell.optimizer, gradient), **base)
                for seed in range(seeds))
            methods.append(label)
    return Sweep(kind, param, tuple(levels), tuple(dict.fromkeys(methods)), specs)


def summary(sweep: Sweep, runs: dict) -> list[dict]:
    """One row per method and level: median and IQR of each indicator over the runs, the number
    of successful runs and of runs that reached the end, why the others stopped (``status``:
    '3 singular, 2 no-better-than-start'), the median ``t_end`` (s) and the first failure's
    ``message``."""
    rows = []
    for method in sweep.methods:
        for level in sweep.levels:
            records = [runs[s.hash()]["record"] for s in sweep.specs[(method, level)]]
            ends = [r["t_end"] for r in records if isinstance(r.get("t_end"), (int, float))]
            row = {"method": method, "level": level, "runs": len(records),
                   "successes": sum(succeeded(r) for r in records),
                   "reached_end": sum(r.get("status") == "success" for r in records),
                   "status": outcome_text(records, codes=True), "why": outcome_text(records),
                   "t_end": float(np.median(ends)) if ends else math.nan, "message": failure_message(records)}
            for name in INDICATORS:
                values = np.array([r.get(name) if r.get(name) is not None else np.nan for r in records], dtype=float)
                values = values[np.isfinite(values)]
                q1, median, q3 = np.percentile(values, [25, 50, 75]) if values.size else (np.nan,) * 3
                row[f"{name}_median"], row[f"{name}_q1"], row[f"{name}_q3"] = float(median), float(q1), float(q3)
            rows.append(row)
    return rows


INDICATOR_COLUMNS = tuple(f"{name}_{stat}" for name in INDICATORS for stat in ("median", "q1", "q3"))
# the conditions every row shares (see ``conditions``)
CONDITION_COLUMNS = ("model", "model_options", "plant", "motion", "motion_sha256", "derivatives", "noise_deg")
# the first columns keep their places; the later ones were added after them
CSV_COLUMNS = (("study", "param", "method", "level", "unit", "runs", "successes") + INDICATOR_COLUMNS
               + ("reached_end", "status", "t_end", "message") + CONDITION_COLUMNS)


def conditions(sweep: Sweep) -> dict:
    """What every run of the study tracked and simulated apart from the swept condition: the
    model and its changes, the plant's changes (a mismatch study adds its own), the motion (a
    file's SHA-256) and the derivative estimate."""
    spec = sweep.all_specs()[0]
    described = spec.describe()
    _, truth = spec.motions()
    plant = described.get("plant")
    if sweep.kind == "mismatch":  # the swept constant is the level; other changes stay
        plant = " ".join(f"{k}={v}" for k, v in spec.plant if k != sweep.param) or None
    return {"model": spec.model_name, "model_options": described.get("model_options"), "plant": plant,
            "motion": truth.name, "motion_sha256": dict(spec.inputs).get("--motion"),
            "derivatives": described.get("derivatives"), "noise_deg": None if sweep.kind == "noise" else spec.noise_deg}


def csv_rows(sweep: Sweep, rows: list[dict]) -> list[list]:
    shared = list(conditions(sweep).values())
    return [[sweep.kind, sweep.param or "", r["method"], r["level"], UNITS[sweep.kind], r["runs"], r["successes"]]
            + [r[c] for c in INDICATOR_COLUMNS + ("reached_end", "status", "t_end", "message")] + shared for r in rows]


def _cell(row: dict, name: str) -> str:
    """'median [Q1, Q3]' with three significant digits, or the one value of a single or repeated run."""
    median, q1, q3 = row[f"{name}_median"], row[f"{name}_q1"], row[f"{name}_q3"]
    if not math.isfinite(median):
        return "-"
    if row["runs"] == 1 or q3 - q1 == 0:
        return f"{median:.3g}"
    return f"{median:.3g} [{q1:.3g}, {q3:.3g}]"


def markdown(sweep: Sweep, rows: list[dict], settings: dict, figures: dict | None = None) -> str:
    """The study as Markdown: settings, one table per indicator (methods by level), figures."""
    unit = UNITS[sweep.kind]
    what = ("white noise on the captured angle" if sweep.kind == "noise"
            else f"the simulated body's {sweep.param} off the nominal model")
    out = [f"# fdbench study: {sweep.kind}" + (f" of {sweep.param}" if sweep.param else ""), "",
           f"Each method tracks the desired motion with {what}, at each level; every figure is the median over "
           "the runs with the interquartile range [Q1, Q3] (one value: a single run, or identical runs). "
           f"RMSE_rot is measured against {_reference(sweep)}, RMSE_torque against the inverse-dynamics "
           "torque of the nominal model on it.", "", "## Settings", "", "| setting | value |", "|---|---|"]
    out += [f"| {k} | {v} |" for k, v in settings.items()]
    titles = {"rmse_rot_deg": "RMSE of rotation (deg)", "rmse_torque_nm": "RMSE of torque (N m)",
              "runtime_s": "Runtime (s)"}
    by_key = {(r["method"], r["level"]): r for r in rows}
    for name in INDICATORS:
        out += ["", f"## {titles[name]}", "",
                "| method | " + " | ".join(f"{level:g} {unit}" for level in sweep.levels) + " | successes |",
                "|---|" + "---:|" * len(sweep.levels) + "---:|"]
        for method in sweep.methods:
            cells = [by_key[(method, level)] for level in sweep.levels]
            done = sum(c["successes"] for c in cells)
            total = sum(c["runs"] for c in cells)
            out.append(f"| {method} | " + " | ".join(_cell(c, name) for c in cells) + f" | {done}/{total} |")
    failures = [f"- {r['method']} at {r['level']:g} {unit}: {r['reached_end']} of {r['runs']} reached the end; "
                f"{r['why']}" + (f". First failure: {r['message'].rstrip('.')}." if r["message"] else ".")
                for r in rows if r["successes"] < r["runs"]]
    if failures:
        out += ["", "## Runs that did not succeed", "",
                "Success: the run reached the end of the motion and (an optimisation) ended below its initial "
                "guess's objective. The others, by why they stopped:", ""] + failures
    out += ["", "## Reading it", ""] + _reading(sweep, rows)
    if figures:
        out += ["", "## Figures", ""] + [f"![{title}]({path})" for title, path in figures.items()]
    return "\n".join(out).rstrip() + "\n"


def _reference(sweep: Sweep) -> str:
    """What RMSE_rot is measured against: the noise-free motion, a recording's filtered angle."""
    spec = sweep.all_specs()[0]
    recorded = bool(dict(spec.inputs).get("--motion"))
    noisy = sweep.kind == "noise" or spec.noise_deg
    if recorded:
        return "the recording's filtered angle" + (" (noise-free: the methods are given the noisy capture)" if noisy else "")
    return "the true (noise-free) motion" if noisy else "the desired motion"


def _reading(sweep: Sweep, rows: list[dict]) -> list[str]:
    """A sentence per method from the numbers: how its RMSE_rot changes from the first level to the last."""
    lines = []
    first, last = sweep.levels[0], sweep.levels[-1]
    unit = UNITS[sweep.kind]
    by_key = {(r["method"], r["level"]): r for r in rows}
    for method in sweep.methods:
        a, b = by_key[(method, first)]["rmse_rot_deg_median"], by_key[(method, last)]["rmse_rot_deg_median"]
        if not (math.isfinite(a) and math.isfinite(b)):
            continue
        lines.append(f"- {method}: median RMSE_rot {a:.3g} deg at {first:g} {unit}, {b:.3g} deg at {last:g} {unit}.")
    finite = [r for r in rows if r["level"] == last and math.isfinite(r["rmse_rot_deg_median"])]
    if finite:
        best = min(finite, key=lambda r: r["rmse_rot_deg_median"])
        lines.append(f"- At {last:g} {unit} the most accurate is {best['method']} "
                     f"({best['rmse_rot_deg_median']:.3g} deg).")
    return lines


def write_figures(sweep: Sweep, rows: list[dict], directory) -> dict:
    """One PNG per indicator: level on x, the median per method with its IQR band; returns
    {title: path}."""
    from pathlib import Path

    from .figures import agg_pyplot, save_png

    plt = agg_pyplot()
    directory = Path(directory)
    directory.mkdir(exist_ok=True)
    labels = {"rmse_rot_deg": "RMSE of rotation (deg)", "rmse_torque_nm": "RMSE of torque (N m)",
              "runtime_s": "runtime (s)"}
    axis = AXIS[sweep.kind].format(param=sweep.param)
    styles = _styles(sweep)
    written = {}
    for name in INDICATORS:
        fig, ax = plt.subplots(figsize=(7.5, 4.8))
        for method in sweep.methods:
            points = [r for r in rows if r["method"] == method]
            x = np.array([r["level"] for r in points])
            median = np.array([r[f"{name}_median"] for r in points])
            (line,) = ax.plot(x, median, marker="o", label=method, **styles[method])
            ax.fill_between(x, [r[f"{name}_q1"] for r in points], [r[f"{name}_q3"] for r in points],
                            color=line.get_color(), alpha=0.15)
        ax.set_xlabel(axis)
        ax.set_ylabel(labels[name])
        if name != "runtime_s" and all(r[f"{name}_median"] > 0 for r in rows if math.isfinite(r[f"{name}_median"])):
            ax.set_yscale("log")
        ax.set_title(f"{labels[name]} against {sweep.kind} (median, IQR band)", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, ncol=2)
        path = directory / f"study_{sweep.kind}_{name}.png"
        save_png(fig, path)
        plt.close(fig)
        written[labels[name]] = str(path)
    return written


def _styles(sweep: Sweep) -> dict:
    """The report's style of each method (PD red; colour by torque, line by optimiser; with
    feedforward the same colour, thicker, its own dashes), no two alike (``distinct_styles``)."""
    from .figures import distinct_styles, method_style

    styles = []
    for method in sweep.methods:
        spec = sweep.specs[(method, sweep.levels[0])][0]
        optimised = spec.command == "optimize"
        styles.append(method_style(spec.torque if optimised else None, spec.optimizer,
                                   feedforward=bool(spec.feedforward) and optimised))
    return dict(zip(sweep.methods, distinct_styles(styles)))


FIGURE_NAMES = tuple(f"study_{kind}_{name}.png" for kind in KINDS for name in INDICATORS)


def json_text(sweep, rows, settings: dict) -> str:
    """The study as one JSON object: its settings and one object per method and level with the
    CSV's columns (null for a statistic no run gave)."""
    import json

    from .files import finite_or_none

    table = [{name: finite_or_none(value.item() if hasattr(value, "item") else value)
              for name, value in zip(CSV_COLUMNS, row)} for row in csv_rows(sweep, rows)]
    return json.dumps({"settings": settings, "rows": table}, indent=2) + "\n"


def settings(sweep, seeds, budget, carried_out: str, kinematics, integrator, dt) -> dict:
    """The study's settings table: what was swept, the conditions every run shares (model, its
    changes, the plant's, the motion and its digest, the estimate, the noise), the run settings."""
    from . import __version__
    from .report import condition_settings
    from .store import machine

    spec = sweep.all_specs()[0]
    described = spec.describe()
    shared = condition_settings(spec, sweep.all_specs())
    shared.pop("RMSE_rot against", None)  # the study's introduction says it
    if sweep.kind == "noise":
        shared.pop("noise", None)  # the levels are the noise; the seeds are below
    else:
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
