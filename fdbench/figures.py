"""Figures of the report as PNG files (matplotlib, Agg backend): the paper's Figure 2 (desired
rotation and inverse-dynamics torque), Figures 5 and 6 (rotation, its error and the applied torque
of PD control and of each optimised method) and convergence curves (best objective against
evaluations, PD control's RMSE as a reference line).

Every method keeps one colour and one line style in every figure: the colour comes from the
torque parameterisation, the line style from the optimiser (``method_style``)."""

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
_SPARE_COLOURS = ("tab:orange", "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray")
_SPARE_LINES = ("-", "--", ":", "-.")


def _stable_pick(name: str, choices):
    """The same choice for the same name in every process (``hash`` is salted per process)."""
    return choices[int(hashlib.sha256(name.encode()).hexdigest(), 16) % len(choices)]


def method_style(torque: str | None, optimizer: str | None = None) -> dict:
    """Matplotlib line properties of a method: ``method_style(None)`` is PD control; otherwise the
    colour follows the torque parameterisation and the line style the optimiser (a registered
    plugin gets a stable colour and style of its own)."""
    if torque is None or torque == "id":
        return dict(CONTROL_STYLE)
    colour = TORQUE_COLOURS.get(torque) or _stable_pick(torque, _SPARE_COLOURS)
    line = OPTIMIZER_LINES.get(optimizer) or _stable_pick(str(optimizer), _SPARE_LINES)
    return {"color": colour, "linestyle": line, "linewidth": 1.4}


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
    angle (rad), torque (N m)), arrays of the motion's samples; ``style`` comes from ``method_style``."""
    plt = _pyplot()
    fig, (top, middle, bottom) = plt.subplots(3, 1, figsize=(8, 9), sharex=True,
                                              gridspec_kw={"height_ratios": [3, 2, 2]})
    t, desired = inverse.t, inverse.angles[:, 0]
    for label, style, theta, torque in curves:
        top.plot(t, np.degrees(theta), label=label, **style)
        middle.plot(t, np.degrees(theta - desired), label=label, **style)
        bottom.plot(t, torque, label=label, **style)
    top.plot(t, np.degrees(desired), label="desired rotation", **DESIRED)
    middle.axhline(0.0, color="0.4", linewidth=0.8, zorder=0)  # the desired rotation: no error
    bottom.plot(t, inverse.torque[:, 0], label="inverse-dynamics torque", **INVERSE_TORQUE)
    top.set_ylabel("rotation (deg)")
    top.set_title(title, fontsize=11)
    top.legend(fontsize=7.5, loc="upper left")
    middle.set_ylabel("error (deg)")
    bottom.set_ylabel("applied torque (N m)")
    bottom.set_xlabel("time (s)")
    bottom.legend(handles=bottom.lines[-1:], fontsize=7.5, loc="upper left")
    for ax in (top, middle, bottom):
        ax.grid(alpha=0.3)
    _save(fig, path)
    plt.close(fig)


def joints_tracking_figure(inverse, curves, path: Path, title: str) -> None:
    """Figures 5 and 6 for a model of several joints, a column per joint against time (s): each
    method's angle error (deg) and its applied torque (N m) against the inverse-dynamics torque.
    ``curves`` are (label, style, angles (rad), torques (N m)), arrays of shape (samples, joints)."""
    plt = _pyplot()
    joints = inverse.joints
    fig, axes = plt.subplots(2, len(joints), figsize=(5 * len(joints), 7), sharex=True, squeeze=False)
    t = inverse.t
    for j, joint in enumerate(joints):
        top, bottom = axes[0, j], axes[1, j]
        for label, style, angles, torque in curves:
            top.plot(t, np.degrees(angles[:, j] - inverse.angles[:, j]), label=label, **style)
            bottom.plot(t, torque[:, j], label=label, **style)
        top.axhline(0.0, color="0.4", linewidth=0.8, zorder=0)
        bottom.plot(t, inverse.torque[:, j], label="inverse-dynamics torque", **INVERSE_TORQUE)
        top.set_title(joint, fontsize=10)
        top.set_ylabel("error (deg)")
        bottom.set_ylabel("applied torque (N m)")
        bottom.set_xlabel("time (s)")
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7.5, loc="upper left")
    fig.suptitle(title, fontsize=11)
    _save(fig, path)
    plt.close(fig)


def convergence_figure(series, path: Path, title: str, reference: float | None = None) -> None:
    """Best objective (deg, eq. 18) against evaluations: series are (label, style, [history per
    seed]); the median over seeds is drawn with the interquartile range as a band. ``reference``
    (deg), PD control's RMSE of rotation, is drawn as a horizontal line."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    for label, style, histories in series:
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
    from .experiment import replay, run

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
