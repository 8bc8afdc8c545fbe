"""Figures of the report as PNG files (matplotlib, Agg backend): the paper's Figure 2 (desired
rotation and inverse-dynamics torque), Figures 5 and 6 (desired rotation against PD control and
the optimised methods) and convergence curves (best objective against evaluations)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# every file the report's --figures writes, checked before the work starts
FIGURE_FILES = ("figure2_inverse_dynamics.png", "figure5_tracking.png", "figure6_tracking.png",
                "convergence_table2.png", "convergence_table3.png")


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


def inverse_figure(inverse, path: Path) -> None:
    """Figure 2: desired rotation (deg) and inverse-dynamics torque (N m) against time (s)."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    top.plot(inverse.t, np.degrees(inverse.theta), color="k")
    top.set_ylabel("rotation (deg)")
    top.set_title(f"Desired rotation and inverse-dynamics torque ({inverse.kinematics} kinematics)")
    bottom.plot(inverse.t, inverse.torque, color="tab:red")
    bottom.set_ylabel("elbow torque (N m)")
    bottom.set_xlabel("time (s)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    _save(fig, path)
    plt.close(fig)


def tracking_figure(inverse, curves, path: Path, title: str) -> None:
    """Figures 5 and 6: desired rotation and simulated ones; curves are (label, theta (rad))
    on the 1001 samples. A lower panel shows each error against the desired rotation."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    top.plot(inverse.t, np.degrees(inverse.theta), color="k", lw=2.5, label="desired")
    for label, theta in curves:
        top.plot(inverse.t, np.degrees(theta), lw=1.2, label=label)
        bottom.plot(inverse.t, np.degrees(theta - inverse.theta), lw=1.2, label=label)
    top.set_ylabel("rotation (deg)")
    top.set_title(title)
    top.legend(fontsize=8)
    bottom.set_ylabel("error (deg)")
    bottom.set_xlabel("time (s)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    _save(fig, path)
    plt.close(fig)


def convergence_figure(series, path: Path, title: str) -> None:
    """Best objective against evaluations: series are (label, [history per seed]); the median
    over seeds is drawn with the interquartile range as a band."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    for label, histories in series:
        length = max(len(h) for h in histories)
        padded = np.array([np.pad(h, (0, length - len(h)), mode="edge") for h in histories], dtype=float)
        q1, med, q3 = np.percentile(padded, [25, 50, 75], axis=0)
        x = np.arange(1, length + 1)
        (line,) = ax.plot(x, med, label=label)
        ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.2)
    ax.set_yscale("log")
    ax.set_xlabel("objective evaluations")
    ax.set_ylabel("best objective f* (eq. 18)")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    _save(fig, path)
    plt.close(fig)
