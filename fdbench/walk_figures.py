"""Figures of the walk's report (``fdbench.walk``) as PNG files and a GIF (matplotlib, Agg): every
coordinate against the recording, the floating base's residuals over the gait cycle, a stick figure
of the recorded and the simulated walk at a few instants, and an animation of the recorded walk
and the best method's.

Each figure is drawn from its data, computed by a function of its own (``coordinate_curves``,
``residual_curves``, ``stick_frames``) from the stored runs re-simulated with their specs, so that
the data can be checked apart from the pixels."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

# every file the walk's --figures writes, checked before the work starts
FIGURE_FILES = ("walk_coordinates.png", "walk_residuals.png", "walk_stick_figure.png", "walk_animation.gif")
STICK_INSTANTS = 6  # stick figures per method, evenly spread over the motion
ANIMATION_FPS = 20
RECORDED = {"color": "black", "linewidth": 1.0, "linestyle": "none", "marker": ".", "markersize": 2.5}
DESIRED = {"color": "black", "linestyle": (0, (4, 2)), "linewidth": 1.4}
COLOURS = {"open-loop": "tab:gray", "pd": "tab:red", "computed-torque": "tab:blue", "lqr": "tab:purple",
           "collocation": "tab:brown", "cs-cmaes": "tab:green", "cs-bfgs": "tab:olive"}


def trajectories(rows, runs: dict, jobs: int = 1) -> dict:
    """{row key: Simulation} of each row's stored run simulated again with its spec (control: the
    run; shooting: its best parameters replayed), ``jobs`` at once in forked processes; collocation,
    whose solution is not stored and takes minutes to find again, is left out."""
    tasks = {}
    for row in rows:
        command, params = row.record.get("command"), runs[row.hash].get("params")
        if command == "control" or (command == "optimize" and params is not None):
            tasks[row.key] = (row.spec, params if command == "optimize" else None)
    if jobs <= 1 or len(tasks) <= 1 or not hasattr(os, "fork"):
        return {key: simulate_again(*task) for key, task in tasks.items()}
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(min(jobs, len(tasks)), mp_context=multiprocessing.get_context("fork")) as pool:
        futures = {key: pool.submit(simulate_again, *task) for key, task in tasks.items()}
        return {key: future.result() for key, future in futures.items()}


def simulate_again(spec, params=None):
    """The Simulation of a stored run: a control run carried out again, or an optimisation's best
    parameters (``params``) replayed."""
    from .experiment import replay, run

    return run(spec).result if params is None else replay(spec, params)


def _display(values: np.ndarray, kinds) -> np.ndarray:
    """Coordinates (rad or m, shape (n, J)) in the figures' units: angles in deg, translations in m."""
    return np.where([kind == "translation" for kind in kinds], values, np.degrees(values))


def recording(spec) -> tuple | None:
    """(t (s), the recorded samples (rad or m), shape (n, J)) of the spec's recorded motion, None
    for a formula's."""
    from .figures import recorded_samples

    return recorded_samples(spec.motions()[0])


def coordinate_curves(inverse, recorded: tuple | None, sims: dict, kinds) -> dict:
    """The data of the coordinates figure, in deg (angles) and m (translations): {'recorded': (t,
    values (n, J)), 'desired': (t, values), <row key>: (t, values)}; a simulation's values are NaN
    after it stopped."""
    out = {"desired": (inverse.t, _display(inverse.angles, kinds))}
    if recorded is not None:
        out["recorded"] = (recorded[0], _display(recorded[1], kinds))
    for key, result in sims.items():
        out[key] = (result.t, _display(result.z, kinds))
    return out


def residual_curves(model, inverse, sims: dict) -> dict:
    """The floating base's residuals over the motion: {'FX'|'FY' (N)|'MZ' (N m): {'inverse
    dynamics': (t, values), <row key>: (t, values)}} (a simulation's: its applied generalised
    forces on the base's coordinates, NaN after it stopped); {} without a floating base."""
    base = model.floating_base
    if base is None:
        return {}
    c = model.coordinates.index(base.coordinate_names[0])
    out = {}
    for offset, name in ((1, "FX"), (2, "FY"), (0, "MZ")):
        curves = {"inverse dynamics": (inverse.t, inverse.torque[:, c + offset])}
        for key, result in sims.items():
            curves[key] = (result.t, result.torque[:, c + offset])
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


# ---- drawing -------------------------------------------------------------------------------------


def _pyplot():
    from .figures import _pyplot

    return _pyplot()


def coordinates_figure(curves: dict, names, kinds, labels: dict, path: Path) -> None:
    """A panel per coordinate against time (s): the recorded samples, the filtered motion every
    method tracks (dashed) and each method's simulation."""
    from .figures import _save

    plt = _pyplot()
    columns = 2
    rows = (len(names) + 1) // columns
    fig, axes = plt.subplots(rows, columns, figsize=(11, 2.2 * rows), sharex=True, squeeze=False)
    for j, (name, kind) in enumerate(zip(names, kinds)):
        ax = axes[j // columns, j % columns]
        if "recorded" in curves:
            ax.plot(curves["recorded"][0], curves["recorded"][1][:, j], label="recorded", **RECORDED)
        ax.plot(curves["desired"][0], curves["desired"][1][:, j], label="recording, filtered (tracked)", **DESIRED)
        for key, label in labels.items():
            if key in curves:
                ax.plot(curves[key][0], curves[key][1][:, j], label=label, color=COLOURS.get(key), linewidth=1.1)
        ax.set_title(name, fontsize=9)
        ax.set_ylabel("m" if kind == "translation" else "deg", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    for ax in axes.flat[len(names):]:
        ax.set_visible(False)
    axes[0, 0].legend(fontsize=6.5, loc="best")
    fig.suptitle("Every coordinate: the recording and each method's simulation", fontsize=11)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def residuals_figure(curves: dict, labels: dict, path: Path) -> None:
    """FX, FY (N) and MZ (N m) of the floating base against time (s) over the gait cycle: the
    inverse dynamics' and each method's."""
    from .figures import _save

    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for ax, (name, unit) in zip(axes, (("FX", "N"), ("FY", "N"), ("MZ", "N m"))):
        for key, (t, values) in curves[name].items():
            style = DESIRED if key == "inverse dynamics" else {"color": COLOURS.get(key), "linewidth": 1.1}
            ax.plot(t, values, label=labels.get(key, key), **style)
        ax.axhline(0.0, color="0.4", linewidth=0.8, zorder=0)
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].legend(fontsize=7)
    axes[0].set_title("Residuals on the floating base over the gait cycle", fontsize=11)
    _save(fig, path)
    plt.close(fig)


def stick_figure(recorded: list, simulated: dict, times, labels: dict, path: Path) -> None:
    """A panel per method: the recorded walk (grey) and the method's (coloured) at the instants
    ``times`` (s), drawn side by side as a film strip (instant k moved k spacings to the right);
    ``recorded`` and each of ``simulated`` are ``stick_frames``."""
    from .figures import _save

    plt = _pyplot()
    points = np.concatenate([frame.reshape(-1, 2) for frame in recorded])
    spacing = round(float(np.ptp(points[:, 0])) + 0.4, 1)
    fig, axes = plt.subplots(len(simulated), 1, figsize=(2.0 + 1.6 * len(times), 2.6 * len(simulated)),
                             sharex=True, squeeze=False)
    for ax, (key, frames) in zip(axes[:, 0], simulated.items()):
        for k, (seen, frame) in enumerate(zip(recorded, frames)):
            shift = np.array([k * spacing, 0.0])
            _draw(ax, seen + shift, color="0.6", linewidth=2.2)
            if frame is not None:
                _draw(ax, frame + shift, color=COLOURS.get(key, "tab:red"), linewidth=1.2)
        missing = [f"{t:.2f}" for t, frame in zip(times, frames) if frame is None]
        ax.set_title(labels.get(key, key) + (f" (stopped before t = {', '.join(missing)} s)" if missing else ""),
                     fontsize=9)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.set_ylabel("y (m)")
    axes[-1, 0].set_xlabel(f"x (m); the instant k drawn k x {spacing:g} m to the right")
    fig.suptitle("Stick figures at t = " + ", ".join(f"{t:.2f}" for t in times)
                 + " s: recorded (grey) and simulated", fontsize=11)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _draw(ax, frame: np.ndarray, **style) -> list:
    return [ax.plot(segment[:, 0], segment[:, 1], solid_capstyle="round", **style)[0] for segment in frame]


def animation(engine, recorded_z: np.ndarray, simulated_z: np.ndarray, t: np.ndarray, label: str, path: Path) -> None:
    """A GIF of the recorded walk (grey) and ``label``'s (red), ``ANIMATION_FPS`` frames per second
    of motion time (coordinates of shape (n, J) on the samples t)."""
    import tempfile

    from matplotlib.animation import FuncAnimation, PillowWriter

    from .files import write_atomic

    plt = _pyplot()
    step = max(1, int(round(1.0 / (ANIMATION_FPS * float(np.median(np.diff(t)))))))
    indices = np.arange(0, len(t), step)
    recorded, simulated = stick_frames(engine, recorded_z, indices), stick_frames(engine, simulated_z, indices)
    every = np.concatenate([f.reshape(-1, 2) for f in recorded + simulated if f is not None])
    fig, ax = plt.subplots(figsize=(9, 3.2))
    ax.set_xlim(every[:, 0].min() - 0.2, every[:, 0].max() + 0.2)
    ax.set_ylim(every[:, 1].min() - 0.1, every[:, 1].max() + 0.1)
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    drawn = []

    def frame(k):
        for line in drawn:
            line.remove()
        drawn.clear()
        drawn.extend(_draw(ax, recorded[k], color="0.6", linewidth=2.2))
        if simulated[k] is not None:
            drawn.extend(_draw(ax, simulated[k], color="tab:red", linewidth=1.2))
        ax.set_title(f"recorded (grey) and {label} (red), t = {t[indices[k]]:.2f} s", fontsize=9)
        return drawn

    movie = FuncAnimation(fig, frame, frames=len(indices), blit=False)
    with tempfile.TemporaryDirectory() as folder:
        temporary = Path(folder) / "walk.gif"
        movie.save(temporary, writer=PillowWriter(fps=ANIMATION_FPS), dpi=70)
        write_atomic(path, temporary.read_bytes(), "--figures")
    plt.close(fig)


def write_walk_figures(spec, inverse, rows, runs: dict, directory: Path, base: Path, jobs: int = 1) -> dict:
    """Write the walk's figures into ``directory`` (created if missing) from the stored runs of
    ``rows`` (``walk.WalkRow``) re-simulated, ``jobs`` at once; return {title: path relative to
    ``base``}."""
    from .multibody.runs import engine, nominal
    from .walk import PD, coordinates

    directory.mkdir(exist_ok=True)
    names, kinds = coordinates(spec)
    sims = trajectories(rows, runs, jobs)
    labels = {row.key: row.name for row in rows if row.key in sims}
    written = {}

    def link(title, name):
        written[title] = os.path.relpath(directory / name, base)

    coordinates_figure(coordinate_curves(inverse, recording(spec), sims, kinds), names, kinds, labels,
                       directory / FIGURE_FILES[0])
    link("Every coordinate against the recording", FIGURE_FILES[0])
    residuals = residual_curves(nominal(spec), inverse, sims)
    if residuals:
        residuals_figure(residuals, labels, directory / FIGURE_FILES[1])
        link("Residuals over the gait cycle", FIGURE_FILES[1])
    plant = engine(spec)
    indices = instants(inverse.t)
    recorded = stick_frames(plant, inverse.angles, indices)
    stick_figure(recorded, {key: stick_frames(plant, sims[key].z, indices) for key in labels}, inverse.t[indices],
                 labels, directory / FIGURE_FILES[2])
    link("Stick figures of the recorded and the simulated walk", FIGURE_FILES[2])
    shown = PD if PD in sims else next(iter(sims), None)
    if shown is not None:
        animation(plant, inverse.angles, sims[shown].z, inverse.t, labels[shown], directory / FIGURE_FILES[3])
        link(f"Animation: the recorded walk and {labels[shown]}", FIGURE_FILES[3])
    return written
