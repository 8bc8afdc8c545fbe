"""Figures of the walk's report (``fdbench.walk``) as PNG files and a GIF (matplotlib, Agg): every
coordinate against the recording, the floating base's residuals over the gait cycle, a stick figure
of the recorded and the simulated walk at a few instants, and an animation of the recorded walk
and every method's. A run that stopped early shows its last pose reached, marked with its t_end;
collocation shows its own solution (the collocated nodes) beside its torque's replay.

Each figure is drawn from its data, computed by a function of its own (``coordinate_curves``,
``residual_curves``, ``stick_frames``, ``stopped_poses``, ``animation_frames``) from the stored
runs re-simulated with their specs (collocation solved again), so that the data can be checked
apart from the pixels."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# every file the walk's --figures writes, checked before the work starts
FIGURE_FILES = ("walk_coordinates.png", "walk_residuals.png", "walk_stick_figure.png", "walk_animation.gif")
STICK_INSTANTS = 6  # stick figures per method, evenly spread over the motion
ANIMATION_FPS = 20
ANIMATION_PANEL_HEIGHT = 1.9  # in: a panel per method, as wide as the walk's extent needs, at most ...
ANIMATION_WIDTH = 10.0  # in: ... this wide in all
ANIMATION_DPI = 70
ANIMATION_FONT_PX = 11  # px: the animation's tick labels and panel titles (its top line 1 px more), read at its size
RECORDED = {"color": "black", "linewidth": 1.0, "linestyle": "none", "marker": ".", "markersize": 2.5}
# the tracked reference (the filtered recording, inverse dynamics' residuals): dashed, drawn over the methods'
DESIRED = {"color": "black", "linestyle": (0, (4, 2)), "linewidth": 1.4, "zorder": 4}
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
        command, params = row.record.get("command"), runs[row.hash].get("params")
        if command in ("control", "collocate") or (command == "optimize" and params is not None):
            tasks[row.key] = (row.spec, params if command == "optimize" else None)
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
    from .figures import recorded_samples

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


def _pyplot():
    from .figures import _pyplot

    return _pyplot()


def coordinates_figure(curves: dict, names, kinds, labels: dict, path: Path) -> None:
    """A panel per coordinate against time (s): the recorded samples, the filtered motion every
    method tracks (dashed), each method's simulation and collocation's own solution (dotted, at its
    nodes)."""
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
                ax.plot(curves[key][0], curves[key][1][:, j], label=label, color=COLOURS.get(key), **METHOD)
        if OWN_SOLUTION in curves:
            ax.plot(curves[OWN_SOLUTION][0], curves[OWN_SOLUTION][1][:, j], label=OWN_SOLUTION, **OWN_STYLE)
        ax.set_title(name, fontsize=9)
        ax.set_ylabel("m" if kind == "translation" else "deg", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    for ax in axes.flat[len(names):]:
        ax.set_visible(False)
    fig.suptitle("Every coordinate: the recording and each method's simulation", fontsize=11)
    fig.tight_layout()
    _legend_outside(fig, axes[0, 0])
    _save(fig, path)
    plt.close(fig)


def residuals_figure(curves: dict, labels: dict, path: Path) -> None:
    """FX, FY (N) and MZ (N m) of the floating base against time (s) over the gait cycle: the
    inverse dynamics', each method's and collocation's own solution's (dotted, at its nodes)."""
    from .figures import _save

    plt = _pyplot()
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
    _save(fig, path)
    plt.close(fig)


def _legend_outside(fig, ax) -> None:
    """The legend of ``ax``'s lines to the right of the figure's panels, covering none of them (the
    saved PNG's tight bounding box takes it in)."""
    fig.legend(*ax.get_legend_handles_labels(), loc="upper left", bbox_to_anchor=(1.0, 0.95), fontsize=8,
               frameon=False)


def stick_figure(recorded: list, simulated: dict, times, labels: dict, path: Path, stops: dict | None = None) -> None:
    """A panel per method: the recorded walk (grey) and the method's (coloured) at the instants
    ``times`` (s), drawn side by side as a film strip (instant k moved k spacings to the right);
    ``recorded`` and each of ``simulated`` are ``stick_frames``. A method that stopped early
    (``stops``: {row key: StoppedPose}) has its last pose reached (dashed) one more spacing to the
    right, beside the tracked motion's at that sample, marked with its t_end."""
    from .figures import _save

    plt = _pyplot()
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
    _save(fig, path)
    plt.close(fig)


def _draw(ax, frame: np.ndarray, **style) -> list:
    return [ax.plot(segment[:, 0], segment[:, 1], solid_capstyle="round", **style)[0] for segment in frame]


def animation(data: tuple, labels: dict, t: np.ndarray, stops: dict, path: Path) -> None:
    """A GIF with a panel per method: the tracked walk (grey) and the method's (coloured), its last
    pose held (dashed) after it stopped; ``data`` is ``animation_frames``'s, on the samples t (s);
    ``stops``: {row key: StoppedPose}. The axes are drawn once; each frame draws only its poses and
    texts over them (blitting), so a frame costs a few milliseconds."""
    import io

    from PIL import Image

    from .files import write_atomic

    plt = _pyplot()
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


def write_walk_figures(spec, inverse, rows, runs: dict, directory: Path, base: Path, jobs: int = 1) -> dict:
    """Write the walk's figures into ``directory`` (created if missing) from the stored runs of
    ``rows`` (``walk.WalkRow``) re-simulated, ``jobs`` at once; return {title: path relative to
    ``base``}."""
    from .run_inputs import engine, nominal
    from .walk import COLLOCATION, coordinates

    directory.mkdir(exist_ok=True)
    names, kinds = coordinates(spec)
    sims, solutions = trajectories(rows, runs, jobs)
    own = solutions.get(COLLOCATION)
    labels = {row.key: row.name for row in rows if row.key in sims}
    written = {}

    def link(title, name):
        written[title] = os.path.relpath(directory / name, base)

    coordinates_figure(coordinate_curves(inverse, recording(spec), sims, kinds, own), names, kinds, labels,
                       directory / FIGURE_FILES[0])
    link("Every coordinate against the recording", FIGURE_FILES[0])
    residuals = residual_curves(nominal(spec), inverse, sims, own)
    if residuals:
        residuals_figure(residuals, labels, directory / FIGURE_FILES[1])
        link("Residuals over the gait cycle", FIGURE_FILES[1])
    plant = engine(spec)
    indices = instants(inverse.t)
    recorded = stick_frames(plant, inverse.angles, indices)
    stops = stopped_poses(plant, inverse.angles, sims)
    stick_figure(recorded, {key: stick_frames(plant, sims[key].z, indices) for key in labels}, inverse.t[indices],
                 labels, directory / FIGURE_FILES[2], stops)
    link("Stick figures of the recorded and the simulated walk", FIGURE_FILES[2])
    if sims:
        shown = {key: sims[key] for key in labels}
        animation(animation_frames(plant, inverse.angles, shown, inverse.t), _short_labels(labels), inverse.t, stops,
                  directory / FIGURE_FILES[3])
        link("Animation: the recorded walk and every method's", FIGURE_FILES[3])
    return written


def _short_labels(labels: dict) -> dict:
    """The methods' short names (``walk_report.SHORT``) for the animation's narrow panels."""
    from .walk import COLLOCATION
    from .walk_report import SHORT

    return {key: "collocation's torque replayed" if key == COLLOCATION else SHORT.get(key, label)
            for key, label in labels.items()}
