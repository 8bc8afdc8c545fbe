"""Figures of the report as PNG files (matplotlib, Agg backend): the paper's Figure 2 (desired
rotation and inverse-dynamics torque), Figures 5 and 6 (rotation, its error and the applied torque
of PD control and of each optimised method) and convergence curves (best objective against
evaluations, PD control's RMSE as a reference line).

Every method keeps one colour and one line style in every figure: the colour comes from the
torque parameterisation, the line style from the optimiser (``method_style``); no two lines of a
figure share both (``distinct_styles``). The tracking figures' axes span the reference (the desired
rotation, the inverse-dynamics torque) with a margin: a run that leaves them is clipped, marked at
the edge where it leaves and called "off scale" in the legend (``off_scale``)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

# every file the report's --figures writes, checked before the work starts
FIGURE_FILES = ("figure2_inverse_dynamics.png", "figure5_tracking.png", "figure6_tracking.png",
                "convergence_table2.png", "convergence_table3.png")

DESIRED = {"color": "black", "linestyle": (0, (4, 2)), "linewidth": 1.6, "zorder": 10}
INVERSE_TORQUE = {"color": "black", "linestyle": (0, (4, 2)), "linewidth": 1.6, "zorder": 10}
CONTROL_STYLE = {"color": "tab:red", "linestyle": "-", "linewidth": 2.0}
TORQUE_COLOURS = {"ann": "tab:blue", "cs": "tab:green", "pf": "tab:purple"}
OPTIMIZER_LINES = {"cmaes": "-", "bfgs": "--", "nelder-mead": ":", "lbfgsb": "-."}
# with feedforward (the study draws both): the same colour, thicker, a dash pattern of its own
FEEDFORWARD_LINES = {"cmaes": (0, (7, 2)), "bfgs": (0, (2, 1.2)), "nelder-mead": (0, (1, 3)),
                     "lbfgsb": (0, (7, 2, 1, 2))}
_SPARE_COLOURS = ("tab:orange", "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray")
_SPARE_LINES = ("-", "--", ":", "-.")
# the dash patterns a repeated (colour, dash) pair falls back to, in order (``distinct_styles``)
_FALLBACK_LINES = (*_SPARE_LINES, *FEEDFORWARD_LINES.values(), (0, (4, 1, 1, 1, 1, 1)), (0, (10, 3)), (0, (1, 1)))
OFF_SCALE_MARGIN = 0.25  # the tracking figures' axes: the reference's range widened by this fraction of it each side


def _stable_pick(name: str, choices):
    """The same choice for the same name in every process (``hash`` is salted per process)."""
    return choices[int(hashlib.sha256(name.encode()).hexdigest(), 16) % len(choices)]


def method_style(torque: str | None, optimizer: str | None = None, feedforward: bool = False) -> dict:
    """Matplotlib line properties of a method: ``method_style(None)`` is PD control; otherwise the
    colour follows the torque parameterisation and the line style the optimiser (a registered
    plugin gets a stable colour and style of its own); ``feedforward``: the optimiser's dash
    pattern with feedforward, drawn thicker (for a figure that shows a method with and without)."""
    if torque is None or torque == "id":
        return dict(CONTROL_STYLE)
    colour = TORQUE_COLOURS.get(torque) or _stable_pick(torque, _SPARE_COLOURS)
    if feedforward:
        line = FEEDFORWARD_LINES.get(optimizer) or _stable_pick(str(optimizer), tuple(FEEDFORWARD_LINES.values()))
        return {"color": colour, "linestyle": line, "linewidth": 2.2}
    line = OPTIMIZER_LINES.get(optimizer) or _stable_pick(str(optimizer), _SPARE_LINES)
    return {"color": colour, "linestyle": line, "linewidth": 1.4}


def line_key(style: dict) -> tuple:
    """(RGBA colour, dash pattern) of a style: what tells two lines apart (linewidth aside)."""
    from matplotlib.colors import to_rgba
    from matplotlib.lines import Line2D

    line = Line2D([], [], color=style.get("color"), linestyle=style.get("linestyle", "-"))
    offset, dashes = line._unscaled_dash_pattern
    return to_rgba(line.get_color()), (offset, tuple(dashes) if dashes else None)


def distinct_styles(styles: list) -> list:
    """The styles of a figure's lines, in order, with every (colour, dash pattern) pair distinct:
    a style repeating an earlier one's takes the first dash pattern not yet drawn in its colour
    (then a spare colour)."""
    used, out = set(), []
    for style in styles:
        style = dict(style)
        if line_key(style) in used:
            colours = (style.get("color"), *_SPARE_COLOURS)
            style.update(next({"color": c, "linestyle": d} for c in colours for d in _FALLBACK_LINES
                              if line_key({"color": c, "linestyle": d}) not in used))
        used.add(line_key(style))
        out.append(style)
    return out


def reference_limits(*references, margin: float = OFF_SCALE_MARGIN) -> tuple[float, float]:
    """(low, high) of an axis: the finite range of the reference arrays widened by ``margin`` of
    its span on each side (a constant reference: by ``margin`` of its magnitude, or of 1)."""
    values = np.concatenate([np.ravel(r) for r in references])
    values = values[np.isfinite(values)]
    low, high = (float(values.min()), float(values.max())) if len(values) else (-1.0, 1.0)
    span = high - low or max(abs(high), 1.0)
    return low - margin * span, high + margin * span


def off_scale(values, limits: tuple) -> int | None:
    """The index of the first sample of ``values`` outside ``limits`` (an infinite one too), None
    if every sample is within (NaN, after a simulation stopped, is not drawn)."""
    values = np.asarray(values, dtype=float)
    outside = np.flatnonzero((values < limits[0]) | (values > limits[1]))
    return int(outside[0]) if len(outside) else None


def _scaled(ax, t, curves, limits: tuple) -> set:
    """Set the y limits of ``ax`` and mark, at the edge, where each of its ``curves`` ((label, style,
    values) drawn against t) leaves them; return the labels of those that leave."""
    ax.set_ylim(*limits)
    left = set()
    for label, style, values in curves:
        i = off_scale(values, limits)
        if i is not None:
            high = values[i] > limits[1]
            ax.plot(t[i], limits[1] if high else limits[0], marker="^" if high else "v", markersize=7,
                    color=style["color"], clip_on=False, zorder=11, linestyle="none")
            left.add(label)
    return left


def _error_limits(errors: list, reference: tuple) -> tuple:
    """Symmetric limits of an error panel: the largest error of the runs on scale, with the margin;
    ``reference`` (low, high): the limits of the panel of the quantity itself, the widest allowed."""
    largest = max((float(np.nanmax(np.abs(e))) for e in errors if np.any(np.isfinite(e))), default=0.0)
    widest = reference[1] - reference[0]
    bound = min(largest * (1 + OFF_SCALE_MARGIN), widest) or widest * 0.01
    return -bound, bound


def _marked(label: str, left: set) -> str:
    return f"{label} (off scale)" if label in left else label


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    import io

    from .files import write_atomic

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    write_atomic(path, buffer.getvalue(), "--figures")


def recorded_samples(motion) -> tuple | None:
    """The raw samples of a recorded or noisy motion (a ``SampledMotion``, per joint for a larger
    model, or one resampled): (t (s), angles (rad), shape (n, joints)); None for a formula."""
    motion = getattr(motion, "base", motion)
    parts = getattr(motion, "parts", [motion])
    if not parts or not all(hasattr(part, "recorded") for part in parts):
        return None
    return np.asarray(parts[0]._t), np.column_stack([part.recorded for part in parts])


def inverse_figure(inverse, path: Path, samples: tuple | None = None, note: str = "", reference: str = "") -> None:
    """Figure 2: the desired angle (deg) and inverse-dynamics torque (N m) of every joint (the
    forearm's elbow, or each joint of a larger model) against time (s). ``samples``: the raw
    samples of a recorded or noisy motion (see ``recorded_samples``), drawn as dots under the
    angle; ``note``: a line under the title (what the indicators are measured against); ``reference``:
    what the drawn angle is (e.g. 'filtered')."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    one_joint = len(inverse.joints) == 1
    angles, torques, joints = inverse.angles, inverse.torque, inverse.joints
    for j, joint in enumerate(joints):
        line = ("-", "--", ":", "-.")[j % 4]
        top.plot(inverse.t, np.degrees(angles[:, j]), color="k", linestyle=line,
                 label=f"{joint}: {reference}" if reference else joint)
        bottom.plot(inverse.t, torques[:, j], color="k", linestyle=line, label=joint)
        if samples is not None:
            top.plot(samples[0], np.degrees(samples[1][:, j]), linestyle="none", marker=".", markersize=2.5,
                     color="tab:orange", alpha=0.7, zorder=0, label=f"{joint}: raw samples")
    where = f"motion {inverse.motion}"
    top.set_title(f"Figure 2: desired rotation and inverse-dynamics torque\n({where})" + (f"\n{note}" if note else ""),
                  fontsize=11 if not note else 9)
    top.set_ylabel("rotation (deg)" if one_joint else "joint angle (deg)")
    bottom.set_ylabel(f"{joints[0]} torque (N m)" if one_joint else "joint torque (N m)")
    bottom.set_xlabel("time (s)")
    if not one_joint or reference:
        top.legend(fontsize=7.5)
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    _save(fig, path)
    plt.close(fig)


def tracking_figure(inverse, curves, path: Path, title: str) -> None:
    """Figures 5 and 6 in three panels against time (s): the rotation (deg) with the desired one
    drawn dashed on top, each method's error against it (deg), and the applied elbow torque (N m)
    against the inverse-dynamics torque, for a model of one joint. ``curves`` are (label, style,
    angle (rad), torque (N m)), arrays of the motion's samples; ``style`` comes from ``method_style``.
    The axes span the desired rotation and the inverse-dynamics torque (``reference_limits``) and
    the errors of the runs within them: a run that leaves them is marked off scale."""
    plt = _pyplot()
    fig, (top, middle, bottom) = plt.subplots(3, 1, figsize=(8, 9), sharex=True,
                                              gridspec_kw={"height_ratios": [3, 2, 2]})
    t, desired = inverse.t, np.degrees(inverse.angles[:, 0])
    styles = distinct_styles([style for _, style, _, _ in curves])
    rotation = [(label, style, np.degrees(theta)) for (label, _, theta, _), style in zip(curves, styles)]
    error = [(label, style, values - desired) for label, style, values in rotation]
    torque = [(label, style, np.asarray(values)) for (label, _, _, values), style in zip(curves, styles)]
    limits = reference_limits(desired), reference_limits(inverse.torque[:, 0])
    left = _scaled(top, t, rotation, limits[0]) | _scaled(bottom, t, torque, limits[1])
    left |= _scaled(middle, t, error, _error_limits([e for label, _, e in error if label not in left], limits[0]))
    for ax, drawn in ((top, rotation), (middle, error), (bottom, torque)):
        for label, style, values in drawn:
            ax.plot(t, values, label=_marked(label, left), **style)
    top.plot(t, desired, label="desired rotation", **DESIRED)
    middle.axhline(0.0, color="0.4", linewidth=0.8, zorder=0)  # the desired rotation: no error
    (reference,) = bottom.plot(t, inverse.torque[:, 0], label="inverse-dynamics torque", **INVERSE_TORQUE)
    top.set_ylabel("rotation (deg)")
    top.set_title(title, fontsize=11)
    top.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    middle.set_ylabel("error (deg)")
    bottom.set_ylabel("applied torque (N m)")
    bottom.set_xlabel("time (s)")
    bottom.legend(handles=[reference], fontsize=7.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    for ax in (top, middle, bottom):
        ax.grid(alpha=0.3)
    _save(fig, path)
    plt.close(fig)


def joints_tracking_figure(inverse, curves, path: Path, title: str) -> None:
    """Figures 5 and 6 for a model of several joints, a column per joint against time (s): each
    method's angle error (deg) and its applied torque (N m) against the inverse-dynamics torque.
    ``curves`` are (label, style, angles (rad), torques (N m)), arrays of shape (samples, joints).
    The torque axes span the inverse-dynamics torque and the error axes the errors of the runs
    within every joint's (``reference_limits``): a run that leaves them is marked off scale."""
    plt = _pyplot()
    joints = inverse.joints
    fig, axes = plt.subplots(2, len(joints), figsize=(5 * len(joints), 7), sharex=True, squeeze=False)
    t = inverse.t
    styles = distinct_styles([style for _, style, _, _ in curves])
    errors, torques, left = [], [], set()
    for j in range(len(joints)):
        desired = np.degrees(inverse.angles[:, j])
        errors.append([(label, style, np.degrees(angles[:, j]) - desired)
                       for (label, _, angles, _), style in zip(curves, styles)])
        torques.append([(label, style, np.asarray(values)[:, j]) for (label, _, _, values), style in zip(curves, styles)])
        left |= _scaled(axes[1, j], t, torques[j], reference_limits(inverse.torque[:, j]))
        left |= {label for label, _, error in errors[j] if off_scale(error + desired, reference_limits(desired)) is not None}
    for j in range(len(joints)):
        limits = reference_limits(np.degrees(inverse.angles[:, j]))
        left |= _scaled(axes[0, j], t, errors[j], _error_limits([e for label, _, e in errors[j] if label not in left],
                                                                limits))
    for j, joint in enumerate(joints):
        top, bottom = axes[0, j], axes[1, j]
        for ax, drawn in ((top, errors[j]), (bottom, torques[j])):
            for label, style, values in drawn:
                ax.plot(t, values, label=_marked(label, left), **style)
        top.axhline(0.0, color="0.4", linewidth=0.8, zorder=0)
        bottom.plot(t, inverse.torque[:, j], label="inverse-dynamics torque", **INVERSE_TORQUE)
        top.set_title(joint, fontsize=10)
        top.set_ylabel("error (deg)")
        bottom.set_ylabel("applied torque (N m)")
        bottom.set_xlabel("time (s)")
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
    axes[0, -1].legend(handles=axes[1, -1].get_lines()[-len(curves) - 1:], fontsize=7.5, loc="upper left",
                       bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(title, fontsize=11)
    _save(fig, path)
    plt.close(fig)


def convergence_figure(series, path: Path, title: str, reference: float | None = None) -> None:
    """Best objective (deg, eq. 18) against evaluations: series are (label, style, [history per
    seed]); the median over seeds is drawn with the interquartile range as a band. ``reference``
    (deg), PD control's RMSE of rotation, is drawn as a horizontal line."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    for (label, _, histories), style in zip(series, distinct_styles([style for _, style, _ in series])):
        length = max(len(h) for h in histories)
        padded = np.array([np.pad(h, (0, length - len(h)), mode="edge") for h in histories], dtype=float)
        q1, med, q3 = np.percentile(padded, [25, 50, 75], axis=0)
        x = np.arange(1, length + 1)
        ax.plot(x, med, label=label, **style)
        ax.fill_between(x, q1, q3, color=style["color"], alpha=0.15)
    if reference is not None and np.isfinite(reference) and reference > 0:
        ax.axhline(reference, label=f"PD control + feedforward ({reference:.3f} deg)",
                   **{**CONTROL_STYLE, "linewidth": 1.2, "linestyle": (0, (1, 1))})
    ax.set_yscale("log")
    ax.set_xlabel("objective evaluations (forward simulations)")
    ax.set_ylabel("best objective f* (deg, eq. 18)")
    ax.set_title(title, fontsize=11)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7.5)
    _save(fig, path)
    plt.close(fig)


def figure2_samples(spec) -> tuple:
    """(raw samples, note, line label) of Figure 2 for the motion of ``spec``: the samples a method
    is given (a recording's, or the noisy capture of seed ``spec.seed or 0``) and what RMSE_rot is
    measured against; (None, "", "") for a formula's motion or derivatives given in the file."""
    desired, _ = spec.motions()
    samples = recorded_samples(desired)
    if samples is None or getattr(desired, "given_derivatives", False):
        return None, "", ""
    if spec.noise_deg:
        return samples, (f"dots: the noisy capture ({spec.noise_deg:g} deg, seed {spec.seed or 0}); "
                         "RMSE_rot is measured against the noise-free motion (the line)"), "noise-free"
    return samples, "dots: the recorded samples; RMSE_rot is measured against the filtered angle (the line)", "filtered"


def write_report_figures(plan, runs: dict, rows, inverse, directory: Path, base: Path) -> dict:
    """Write the report's figures into ``directory`` (created if missing) for the plan's stored
    runs ({hash: stored run}) and report rows; return {title: path relative to ``base``}, the
    directory of the report. Each tracking figure shows the run of median RMSE_rot of each cell; a
    model of several joints has a column per joint."""
    from .method_runs import replay, run

    directory.mkdir(exist_ok=True)
    written = {}

    def link(name, path):
        written[name] = os.path.relpath(path, base)

    one_joint = len(inverse.joints) == 1
    path = directory / "figure2_inverse_dynamics.png"
    spec = plan.control or plan.all_specs()[0]
    samples, note, reference = figure2_samples(spec)
    inverse_figure(inverse, path, samples, note, reference)
    desired = f"\n(desired: the {reference} angle, which RMSE_rot is measured against)" if reference else ""
    link("Figure 2: desired rotation and inverse-dynamics torque", path)

    def angles(result):
        return result.angles[:, 0] if one_joint else result.angles

    def torques(result):
        return result.torque[:, 0] if one_joint else result.torque

    control_curves, reference = [], None
    if plan.control is not None:
        result = run(plan.control).result
        control_curves = [("PD control + feedforward", method_style(None), angles(result), torques(result))]
        reference = runs[plan.control.hash()]["record"].get("rmse_rot_deg")
    for table, name in ((2, "Figure 5: without feedforward"), (3, "Figure 6: with feedforward")):
        curves = list(control_curves)
        series = []
        for row in rows:
            if row.table != table:
                continue
            specs = plan.specs[row.cell]
            stored = [runs[s.hash()] for s in specs]
            style = method_style(row.cell.torque, row.cell.optimizer)
            values = np.array([r["record"]["rmse_rot_deg"] if r["record"]["rmse_rot_deg"] is not None else np.inf
                               for r in stored])
            median_seed = int(np.argsort(values)[len(values) // 2])
            if stored[median_seed]["params"] is not None:
                result = replay(specs[median_seed], stored[median_seed]["params"])
                curves.append((row.name, style, angles(result), torques(result)))
            histories = [r["history"] for r in stored if r["history"]]
            if histories:
                series.append((row.name, style, histories))
        if len(curves) > len(control_curves):
            path = directory / f"figure{5 if table == 2 else 6}_tracking.png"
            (tracking_figure if one_joint else joints_tracking_figure)(inverse, curves, path,
                                                                       f"{name}: the median run of each method"
                                                                       + desired)
            link(name, path)
        if series:
            path = directory / f"convergence_table{table}.png"
            convergence_figure(series, path, f"Convergence, Table {table}: median over seeds, IQR band", reference)
            link(f"Convergence, Table {table}", path)
    return written
