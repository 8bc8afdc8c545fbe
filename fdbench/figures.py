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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# every file the report's --figures writes, checked before the work starts
FIGURE_FILES = ("figure2_inverse_dynamics.png", "figure5_tracking.png", "figure6_tracking.png",
                "convergence_table2.png", "convergence_table3.png")
ACTIVATIONS_FILE = "activations.png"  # on a model with muscles: each muscle's activation per method
REPORT_FIGURE_FILES = FIGURE_FILES + (ACTIVATIONS_FILE,)  # every file the report's --figures may write

# the reference lines (the desired rotation, the inverse-dynamics torque or residuals): dashed black, on top
DESIRED = {"color": "black", "linestyle": (0, (4, 2)), "linewidth": 1.6, "zorder": 10}
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


def agg_pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path: Path) -> None:
    """Write the figure as a PNG file and close it."""
    import io

    from .files import write_atomic

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    write_atomic(path, buffer.getvalue(), "--figures")
    agg_pyplot().close(fig)


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
    plt = agg_pyplot()
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
    save_png(fig, path)


def tracking_figure(inverse, curves, path: Path, title: str) -> None:
    """Figures 5 and 6 in three panels against time (s): the rotation (deg) with the desired one
    drawn dashed on top, each method's error against it (deg), and the applied elbow torque (N m)
    against the inverse-dynamics torque, for a model of one joint. ``curves`` are (label, style,
    angle (rad), torque (N m)), arrays of the motion's samples; ``style`` comes from ``method_style``.
    The axes span the desired rotation and the inverse-dynamics torque (``reference_limits``) and
    the errors of the runs within them: a run that leaves them is marked off scale."""
    plt = agg_pyplot()
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
    (reference,) = bottom.plot(t, inverse.torque[:, 0], label="inverse-dynamics torque", **DESIRED)
    top.set_ylabel("rotation (deg)")
    top.set_title(title, fontsize=11)
    top.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    middle.set_ylabel("error (deg)")
    bottom.set_ylabel("applied torque (N m)")
    bottom.set_xlabel("time (s)")
    bottom.legend(handles=[reference], fontsize=7.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    for ax in (top, middle, bottom):
        ax.grid(alpha=0.3)
    save_png(fig, path)


def joints_tracking_figure(inverse, curves, path: Path, title: str) -> None:
    """Figures 5 and 6 for a model of several joints, a column per joint against time (s): each
    method's angle error (deg) and its applied torque (N m) against the inverse-dynamics torque.
    ``curves`` are (label, style, angles (rad), torques (N m)), arrays of shape (samples, joints).
    The torque axes span the inverse-dynamics torque and the error axes the errors of the runs
    within every joint's (``reference_limits``): a run that leaves them is marked off scale."""
    plt = agg_pyplot()
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
        bottom.plot(t, inverse.torque[:, j], label="inverse-dynamics torque", **DESIRED)
        top.set_title(joint, fontsize=10)
        top.set_ylabel("error (deg)")
        bottom.set_ylabel("applied torque (N m)")
        bottom.set_xlabel("time (s)")
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
    axes[0, -1].legend(handles=axes[1, -1].get_lines()[-len(curves) - 1:], fontsize=7.5, loc="upper left",
                       bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(title, fontsize=11)
    save_png(fig, path)


def convergence_figure(series, path: Path, title: str, reference: float | None = None) -> None:
    """Best objective (deg, eq. 18) against evaluations: series are (label, style, [history per
    seed]); the median over seeds is drawn with the interquartile range as a band. ``reference``
    (deg), PD control's RMSE of rotation, is drawn as a horizontal line."""
    plt = agg_pyplot()
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
    save_png(fig, path)


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


# ---- figures of any model: its coordinates, a floating base's residuals, stick figures --------------
# Every coordinate against the recording, the floating base's residuals over the motion, a stick
# figure of the recorded and the simulated motion at a few instants, and an animation of the
# recording and every method's. A run that stopped early shows its last pose reached, marked with
# its t_end; collocation shows its own solution (the collocated nodes) beside its torque's replay.
# Each figure is drawn from its data, computed by a function of its own (``coordinate_curves``,
# ``residual_curves``, ``stick_frames``, ``stopped_poses``, ``animation_frames``) from the stored
# runs re-simulated with their specs (collocation solved again), so that the data can be checked
# apart from the pixels.

# every file the figures of a model's coordinates write (--figures on a model with a floating base),
# checked before the work starts
OWN_SUFFIX = ":own"  # a collocation's own solution beside its replay, in a figure's curves
MODEL_FIGURE_FILES = ("coordinates.png", "residuals.png", "stick_figure.png", "animation.gif", ACTIVATIONS_FILE)
COLLOCATION = "collocation"  # the registered method's key (``report.methods``)
STICK_INSTANTS = 6  # stick figures per method, evenly spread over the motion
ANIMATION_FPS = 20
ANIMATION_PANEL_HEIGHT = 1.9  # in: a panel per method, as wide as the motion's extent needs, at most ...
ANIMATION_WIDTH = 10.0  # in: ... this wide in all
ANIMATION_DPI = 70
ANIMATION_FONT_PX = 11  # px: the animation's tick labels and panel titles (its top line 1 px more), read at its size
RECORDED = {"color": "black", "linewidth": 1.0, "linestyle": "none", "marker": ".", "markersize": 2.5}
# the tracked reference (the filtered recording, inverse dynamics' residuals): dashed, drawn over the methods'
TRACKED = {"color": "black", "linestyle": (0, (4, 2)), "linewidth": 1.4, "zorder": 4}
METHOD = {"linewidth": 1.1, "zorder": 2}  # a method's line (its colour from COLOURS)
COLOURS = {"open-loop": "tab:orange", "pd": "tab:red", "computed-torque": "tab:blue", "lqr": "tab:purple",
           "collocation": "tab:brown", "cs-cmaes": "tab:green", "cs-bfgs": "tab:olive"}
OWN_SOLUTION = "collocation (own solution)"  # the key and label of the collocated trajectory in the figures' data
OWN_STYLE = {"color": "tab:brown", "linestyle": (0, (1, 1.5)), "linewidth": 1.6, "marker": "o", "markersize": 1.8}
STOPPED_STYLE = {"linestyle": (0, (3, 1.5)), "linewidth": 1.4}  # the last pose of a run that stopped early


def trajectories(rows, runs: dict, jobs: int = 1) -> tuple[dict, dict]:
    """({row key: Simulation}, {row key: CollocationResult}) of the rows' stored runs simulated again
    with their specs (control: the run; shooting: its best parameters replayed; collocation: solved
    again, deterministically, giving its replay and its own solution at its nodes), ``jobs`` at once
    in forked processes."""
    tasks = {}
    for row in rows:
        command, params = row.record.get("command"), runs[row.hashes[0]].get("params")
        if command in ("control", "collocate") or (command == "optimize" and params is not None):
            tasks[row.key] = (row.specs[0], params if command == "optimize" else None)
    if jobs <= 1 or len(tasks) <= 1 or not hasattr(os, "fork"):
        found = {key: simulate_again(*task) for key, task in tasks.items()}
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(jobs, len(tasks)), mp_context=multiprocessing.get_context("fork")) as pool:
            futures = {key: pool.submit(simulate_again, *task) for key, task in tasks.items()}
            found = {key: future.result() for key, future in futures.items()}
    return ({key: sim for key, (sim, _) in found.items()},
            {key: own for key, (_, own) in found.items() if own is not None})


def simulate_again(spec, params=None) -> tuple:
    """(Simulation, CollocationResult or None) of a stored run: a control run carried out again, an
    optimisation's best parameters (``params``) replayed, or a collocation solved again (its
    torque's replay and its own solution)."""
    from .method_runs import replay, run

    if params is not None:
        return replay(spec, params), None
    outcome = run(spec)
    return outcome.result, outcome.extra.get("collocation")


def _display(values: np.ndarray, kinds) -> np.ndarray:
    """Coordinates (rad or m, shape (n, J)) in the figures' units: angles in deg, translations in m."""
    return np.where([kind == "translation" for kind in kinds], values, np.degrees(values))


def recording(spec) -> tuple | None:
    """(t (s), the recorded samples (rad or m), shape (n, J)) of the spec's recorded motion, None
    for a formula's."""
    return recorded_samples(spec.motions()[0])


def coordinate_curves(inverse, recorded: tuple | None, sims: dict, kinds, own=None) -> dict:
    """The data of the coordinates figure, in deg (angles) and m (translations): {'recorded': (t,
    values (n, J)), 'desired': (t, values), <row key>: (t, values), OWN_SOLUTION: (node times,
    values (N + 1, J))}; a simulation's values are NaN after it stopped; ``own``: collocation's
    ``CollocationResult`` (its nodes' angles), or None."""
    out = {"desired": (inverse.t, _display(inverse.angles, kinds))}
    if recorded is not None:
        out["recorded"] = (recorded[0], _display(recorded[1], kinds))
    for key, result in sims.items():
        out[key] = (result.t, _display(result.z, kinds))
    if own is not None:
        out[OWN_SOLUTION] = (own.t, _display(own.angles, kinds))
    return out


def residual_curves(model, inverse, sims: dict, own=None) -> dict:
    """The floating base's residuals over the motion: {'FX'|'FY' (N)|'MZ' (N m): {'inverse
    dynamics': (t, values), <row key>: (t, values), OWN_SOLUTION: (node times, values)}} (a
    simulation's: its applied generalised forces on the base's coordinates, NaN after it stopped;
    ``own``, collocation's ``CollocationResult`` or None: its generalised forces at its nodes); {}
    without a floating base."""
    base = model.floating_base
    if base is None:
        return {}
    c = model.coordinates.index(base.coordinate_names[0])
    out = {}
    for offset, name in ((1, "FX"), (2, "FY"), (0, "MZ")):
        curves = {"inverse dynamics": (inverse.t, inverse.torque[:, c + offset])}
        for key, result in sims.items():
            curves[key] = (result.t, result.torque[:, c + offset])
        if own is not None:
            curves[OWN_SOLUTION] = (own.t, own.torque[:, c + offset])
        out[name] = curves
    return out


def instants(t: np.ndarray, count: int = STICK_INSTANTS) -> np.ndarray:
    """Indices of ``count`` samples of t evenly spread from its start to its end."""
    return np.unique(np.searchsorted(t, np.linspace(t[0], t[-1], count) - 1e-12))


def stick_frames(engine, z: np.ndarray, indices) -> list:
    """The stick figure of the coordinates z (rad or m, shape (n, J)) at the samples ``indices``:
    per instant an array (B, 2, 2) of each body's segment from its joint point to its end (m), as
    ``Engine.point_positions`` gives them; None for an instant the simulation did not reach."""
    frames = []
    for i in indices:
        if not np.all(np.isfinite(z[i])):
            frames.append(None)
            continue
        points = engine.point_positions(z[i])
        frames.append(np.array([[points[f"{name}.joint"], points[f"{name}.end"]] for name in engine.body_names]))
    return frames


@dataclass(frozen=True)
class StoppedPose:
    """Where a simulation that stopped before the motion's end left the model: its t_end (s) and
    status code ('constraint', ...), the last sample it reached (index, time t in s) and the stick
    figures (B, 2, 2), m, of the simulation and of the tracked motion at that sample."""

    t_end: float
    status: str
    index: int
    t: float
    frame: np.ndarray
    tracked: np.ndarray

    @property
    def label(self) -> str:
        return f"fell at {self.t_end:.3f} s ({self.status})"


def last_reached(result) -> int | None:
    """The index of the last sample (every coordinate finite) of a simulation that stopped before
    the motion's end; None for one that reached the end or no sample at all."""
    if result.success:
        return None
    reached = np.flatnonzero(np.all(np.isfinite(result.z), axis=1))
    return int(reached[-1]) if len(reached) else None


def stopped_poses(engine, tracked_z: np.ndarray, sims: dict) -> dict:
    """{row key: StoppedPose} of the simulations of ``sims`` that stopped early, with the tracked
    motion's pose at the same sample (``tracked_z``: rad or m, shape (n, J), on the simulations'
    samples)."""
    out = {}
    for key, result in sims.items():
        i = last_reached(result)
        if i is not None:
            (frame,), (tracked,) = stick_frames(engine, result.z, [i]), stick_frames(engine, tracked_z, [i])
            out[key] = StoppedPose(float(result.t_end), result.status.code, i, float(result.t[i]), frame, tracked)
    return out


def animation_frames(engine, tracked_z: np.ndarray, sims: dict, t: np.ndarray) -> tuple:
    """The animation's data, ``ANIMATION_FPS`` frames per second of motion time: (indices of the
    samples t (s) shown, the tracked motion's stick figures there, {row key: stick figures, the
    last pose reached held after a simulation stopped}, {row key: whether each frame is held})."""
    step = max(1, int(round(1.0 / (ANIMATION_FPS * float(np.median(np.diff(t)))))))
    indices = np.arange(0, len(t), step)
    stops = stopped_poses(engine, tracked_z, sims)
    frames, held = {}, {}
    for key, result in sims.items():
        drawn = stick_frames(engine, result.z, indices)
        held[key] = [frame is None and key in stops for frame in drawn]
        frames[key] = [stops[key].frame if hold else frame for frame, hold in zip(drawn, held[key])]
    return indices, stick_frames(engine, tracked_z, indices), frames, held


# ---- drawing -------------------------------------------------------------------------------------


def _panels(names, title: str, path: Path, draw) -> None:
    """A panel per name in two columns against time (s), ``draw(ax, j)`` drawing panel j's lines;
    the legend outside, saved to ``path``."""
    plt = agg_pyplot()
    columns = 2
    rows = (len(names) + 1) // columns
    fig, axes = plt.subplots(rows, columns, figsize=(11, 2.2 * rows), sharex=True, squeeze=False)
    for j, name in enumerate(names):
        ax = axes[j // columns, j % columns]
        draw(ax, j)
        ax.set_title(name, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    for ax in axes.flat[len(names):]:
        ax.set_visible(False)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    _legend_outside(fig, axes[0, 0])
    save_png(fig, path)


def coordinates_figure(curves: dict, names, kinds, labels: dict, path: Path) -> None:
    """A panel per coordinate against time (s): the recorded samples, the filtered motion every
    method tracks (dashed), each method's simulation and collocation's own solution (dotted, at its
    nodes)."""

    def draw(ax, j):
        if "recorded" in curves:
            ax.plot(curves["recorded"][0], curves["recorded"][1][:, j], label="recorded", **RECORDED)
        ax.plot(curves["desired"][0], curves["desired"][1][:, j], label="recording, filtered (tracked)", **TRACKED)
        for key, label in labels.items():
            if key in curves:
                ax.plot(curves[key][0], curves[key][1][:, j], label=label, color=COLOURS.get(key), **METHOD)
        if OWN_SOLUTION in curves:
            ax.plot(curves[OWN_SOLUTION][0], curves[OWN_SOLUTION][1][:, j], label=OWN_SOLUTION, **OWN_STYLE)
        ax.set_ylabel("m" if kinds[j] == "translation" else "deg", fontsize=8)

    _panels(names, "Every coordinate: the recording and each method's simulation", path, draw)


def residuals_figure(curves: dict, labels: dict, path: Path) -> None:
    """FX, FY (N) and MZ (N m) of the floating base against time (s) over the gait cycle: the
    inverse dynamics', each method's and collocation's own solution's (dotted, at its nodes)."""

    plt = agg_pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for ax, (name, unit) in zip(axes, (("FX", "N"), ("FY", "N"), ("MZ", "N m"))):
        for key, (t, values) in curves[name].items():
            style = (DESIRED if key == "inverse dynamics" else OWN_STYLE if key == OWN_SOLUTION
                     else {"color": COLOURS.get(key), **METHOD})
            ax.plot(t, values, label=labels.get(key, key), **style)
        ax.axhline(0.0, color="0.4", linewidth=0.8, zorder=0)
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title("Residuals on the floating base over the gait cycle", fontsize=11)
    fig.tight_layout()
    _legend_outside(fig, axes[0])
    save_png(fig, path)


def _legend_outside(fig, ax) -> None:
    """The legend of ``ax``'s lines to the right of the figure's panels, covering none of them (the
    saved PNG's tight bounding box takes it in)."""
    fig.legend(*ax.get_legend_handles_labels(), loc="upper left", bbox_to_anchor=(1.0, 0.95), fontsize=8,
               frameon=False)


def stick_figure(recorded: list, simulated: dict, times, labels: dict, path: Path, stops: dict | None = None) -> None:
    """A panel per method: the recorded motion (grey) and the method's (coloured) at the instants
    ``times`` (s), drawn side by side as a film strip (instant k moved k spacings to the right);
    ``recorded`` and each of ``simulated`` are ``stick_frames``. A method that stopped early
    (``stops``: {row key: StoppedPose}) has its last pose reached (dashed) one more spacing to the
    right, beside the tracked motion's at that sample, marked with its t_end."""

    plt = agg_pyplot()
    stops = stops or {}
    points = np.concatenate([frame.reshape(-1, 2) for frame in recorded])
    spacing = round(float(np.ptp(points[:, 0])) + 0.4, 1)
    slots = len(times) + (1 if stops else 0)
    fig, axes = plt.subplots(len(simulated), 1, figsize=(2.0 + 1.6 * slots, 2.6 * len(simulated)),
                             sharex=True, squeeze=False)
    for ax, (key, frames) in zip(axes[:, 0], simulated.items()):
        colour = COLOURS.get(key, "tab:red")
        for k, (seen, frame) in enumerate(zip(recorded, frames)):
            shift = np.array([k * spacing, 0.0])
            _draw(ax, seen + shift, color="0.6", linewidth=2.2)
            if frame is not None:
                _draw(ax, frame + shift, color=colour, linewidth=1.2)
        title = labels.get(key, key)
        if key in stops:
            stop, shift = stops[key], np.array([len(times) * spacing, 0.0])
            _draw(ax, stop.tracked + shift, color="0.6", linewidth=2.2)
            _draw(ax, stop.frame + shift, color=colour, **STOPPED_STYLE)
            title += f" ({stop.label}; on the right its last pose reached, t = {stop.t:.3f} s, dashed)"
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.set_ylabel("y (m)")
    axes[-1, 0].set_xlabel(f"x (m); the instant k drawn k x {spacing:g} m to the right")
    fig.suptitle("Stick figures at t = " + ", ".join(f"{t:.2f}" for t in times)
                 + " s: recorded (grey) and simulated" + (", then the last pose of a run that fell" if stops else ""),
                 fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    save_png(fig, path)


def _draw(ax, frame: np.ndarray, **style) -> list:
    return [ax.plot(segment[:, 0], segment[:, 1], solid_capstyle="round", **style)[0] for segment in frame]


def animation(data: tuple, labels: dict, t: np.ndarray, stops: dict, path: Path) -> None:
    """A GIF with a panel per method: the tracked motion (grey) and the method's (coloured), its last
    pose held (dashed) after it stopped; ``data`` is ``animation_frames``'s, on the samples t (s);
    ``stops``: {row key: StoppedPose}. The axes are drawn once; each frame draws only its poses and
    texts over them (blitting), so a frame costs a few milliseconds."""
    import io

    from PIL import Image

    from .files import write_atomic

    plt = agg_pyplot()
    indices, recorded, simulated, held = data
    fig, axes = _animation_axes(plt, recorded, simulated)
    fig.canvas.draw()
    background = fig.canvas.copy_from_bbox(fig.bbox)
    images = []
    for k in range(len(indices)):
        fig.canvas.restore_region(background)
        artists = [fig.text(0.5, 0.995, f"recorded (grey) and each method's walk, t = {t[indices[k]]:.2f} s",
                            ha="center", va="top", fontsize=_points(ANIMATION_FONT_PX + 1))]
        for ax, key in zip(axes.flat, simulated):
            artists += _draw(ax, recorded[k], color="0.6", linewidth=2.2)
            pose, colour = simulated[key][k], COLOURS.get(key, "tab:red")
            if pose is not None:
                artists += _draw(ax, pose, color=colour, **(STOPPED_STYLE if held[key][k] else {"linewidth": 1.2}))
            note = f"fell at {stops[key].t_end:.3f} s: last pose held" if held[key][k] else ""
            artists.append(ax.text(0.5, 1.02, f"{labels.get(key, key)}\n{note}", transform=ax.transAxes, ha="center",
                                   va="bottom", fontsize=_points(ANIMATION_FONT_PX)))
        for artist in artists:
            fig.draw_artist(artist)
        images.append(Image.fromarray(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()))
        for artist in artists:
            artist.remove()
    plt.close(fig)
    buffer = io.BytesIO()
    images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:], loop=0,
                   duration=round(1000 / ANIMATION_FPS))
    write_atomic(path, buffer.getvalue(), "--figures")


def _animation_axes(plt, recorded: list, simulated: dict) -> tuple:
    """The animation's figure and its panels (one per method, in rows of as many as fit
    ``ANIMATION_WIDTH``), every panel spanning every pose of ``recorded`` and ``simulated``."""
    every = np.concatenate([f.reshape(-1, 2) for frames in [recorded, *simulated.values()] for f in frames
                            if f is not None])
    panel = ANIMATION_PANEL_HEIGHT * float(np.clip((np.ptp(every[:, 0]) + 0.4) / (np.ptp(every[:, 1]) + 0.2), 1, 5))
    columns = int(np.clip(ANIMATION_WIDTH // panel, 1, min(3, len(simulated))))
    rows = -(-len(simulated) // columns)
    text = 3.5 * ANIMATION_FONT_PX / ANIMATION_DPI  # in: a panel's two lines of title and a row of tick labels
    height = rows * (ANIMATION_PANEL_HEIGHT + text) + 2 * ANIMATION_FONT_PX / ANIMATION_DPI
    fig, axes = plt.subplots(rows, columns, figsize=(columns * panel + 0.6, height), squeeze=False, dpi=ANIMATION_DPI)
    for ax in axes.flat[len(simulated):]:
        ax.set_visible(False)
    from matplotlib.ticker import MaxNLocator

    for ax in axes.flat[:len(simulated)]:
        ax.set_xlim(every[:, 0].min() - 0.2, every[:, 0].max() + 0.2)
        ax.set_ylim(every[:, 1].min() - 0.1, every[:, 1].max() + 0.1)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=_points(ANIMATION_FONT_PX))
        ax.xaxis.set_major_locator(MaxNLocator(max(2, int(panel * ANIMATION_DPI / (6 * ANIMATION_FONT_PX)))))
        ax.yaxis.set_major_locator(MaxNLocator(4))
        ax.set_title("\n", fontsize=_points(ANIMATION_FONT_PX))  # room for each frame's two lines of title
    fig.tight_layout(rect=(0, 0, 1, 1 - 2 * ANIMATION_FONT_PX / ANIMATION_DPI / height))
    return fig, axes


def _points(pixels: float) -> float:
    """A font size in points that is ``pixels`` high in the animation's frames (at ANIMATION_DPI)."""
    return pixels * 72.0 / ANIMATION_DPI


def write_model_figures(spec, inverse, rows, runs: dict, directory: Path, base: Path, jobs: int = 1,
                        short: dict | None = None) -> dict:
    """Write the figures of a model's coordinates into ``directory`` (created if missing) from the
    stored runs of ``rows`` (``report.Row`` of registered methods, by key) re-simulated, ``jobs`` at
    once; ``short``: the methods' short names by key, for the animation; return {title: path
    relative to ``base``}."""
    from .run_inputs import engine, nominal

    model = nominal(spec)
    names, kinds = tuple(model.coordinates), tuple(model.coordinate_kinds)
    directory.mkdir(exist_ok=True)
    sims, solutions = trajectories(rows, runs, jobs)
    own = solutions.get(COLLOCATION)
    labels = {row.key: row.name for row in rows if row.key in sims}
    written = {}

    def link(title, name):
        written[title] = os.path.relpath(directory / name, base)

    coordinates_figure(coordinate_curves(inverse, recording(spec), sims, kinds, own), names, kinds, labels,
                       directory / MODEL_FIGURE_FILES[0])
    link("Every coordinate against the recording", MODEL_FIGURE_FILES[0])
    residuals = residual_curves(model, inverse, sims, own)
    if residuals:
        residuals_figure(residuals, labels, directory / MODEL_FIGURE_FILES[1])
        link("Residuals over the gait cycle", MODEL_FIGURE_FILES[1])
    plant = engine(spec)
    indices = instants(inverse.t)
    recorded = stick_frames(plant, inverse.angles, indices)
    stops = stopped_poses(plant, inverse.angles, sims)
    stick_figure(recorded, {key: stick_frames(plant, sims[key].z, indices) for key in labels}, inverse.t[indices],
                 labels, directory / MODEL_FIGURE_FILES[2], stops)
    link("Stick figures of the recorded and the simulated walk", MODEL_FIGURE_FILES[2])
    if sims:
        shown = {key: sims[key] for key in labels}
        animation(animation_frames(plant, inverse.angles, shown, inverse.t), _short_labels(labels, short or {}), inverse.t, stops,
                  directory / MODEL_FIGURE_FILES[3])
        link("Animation: the recorded walk and every method's", MODEL_FIGURE_FILES[3])
    driven = {key: (sims[key].t, sims[key].activation) for key in labels
              if getattr(sims[key], "activation", None) is not None}
    names = {key: labels[key] for key in driven}
    for key, solution in solutions.items():  # muscle-driven collocation's own activations, at its nodes
        if key in driven and getattr(solution, "activation", None) is not None:
            driven[key + OWN_SUFFIX], names[key + OWN_SUFFIX] = (solution.t, solution.activation), \
                f"{labels[key]} (own solution)"
    if driven:  # the methods that drove the model's muscles
        activations_figure(driven, [m.name for m in model.muscles], names, directory / ACTIVATIONS_FILE)
        link("Each muscle's activation", ACTIVATIONS_FILE)
    return written


def activation_curves(rows, runs: dict, jobs: int = 1) -> dict:
    """{row key: (t (s), activations (n, M))} of ``rows`` (those that drove the model's muscles),
    their stored runs carried out again (``trajectories``)."""
    sims, _ = trajectories(rows, runs, jobs) if rows else ({}, {})
    return {key: (sim.t, sim.activation) for key, sim in sims.items() if getattr(sim, "activation", None) is not None}


def activations_figure(curves: dict, muscles, labels: dict, path: Path) -> None:
    """A panel per muscle: its activation (0 to 1) against time (s), a line per method."""
    spare = iter(_SPARE_COLOURS)
    colours = {key: COLOURS.get(key) or next(spare, None) for key in labels}

    def draw(ax, m):
        for key, label in labels.items():
            if key in curves:
                ax.plot(curves[key][0], curves[key][1][:, m], label=label, color=colours[key], **METHOD)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("activation", fontsize=8)

    _panels(muscles, "Each muscle's activation: the methods that drive the muscles", path, draw)


def write_activations_figure(rows, runs: dict, directory: Path, base: Path, jobs: int = 1) -> dict:
    """Write ``ACTIVATIONS_FILE`` into ``directory`` for the rows whose run drove the model's muscles
    (a record with ``effort``; none: nothing written); return {title: path relative to ``base``}."""
    from .run_inputs import nominal

    driven = [row for row in rows if row.record.get("effort") is not None]
    curves = activation_curves(driven, runs, jobs)
    if not curves:
        return {}
    directory.mkdir(exist_ok=True)
    labels = {row.key: row.name for row in driven if row.key in curves}
    muscles = [m.name for m in nominal(driven[0].specs[0]).muscles]
    activations_figure(curves, muscles, labels, directory / ACTIVATIONS_FILE)
    return {"Each muscle's activation": os.path.relpath(directory / ACTIVATIONS_FILE, base)}


def _short_labels(labels: dict, short: dict) -> dict:
    """The methods' short names for the animation's narrow panels."""
    return {key: "collocation's torque replayed" if key == COLLOCATION else short.get(key, label)
            for key, label in labels.items()}
