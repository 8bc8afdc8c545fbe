"""The figures' layout, checked on matplotlib's own objects rather than on pixels: the tracking
figures' axes against the reference's range when one run is wild, distinct (colour, dash) pairs
for every line of a figure, the walk's legends beside (not over) its panels with its reference line
drawn on top, and the animation's tick labels against its frames' pixel size.

The figures are drawn from synthetic data (a minimum-jerk motion and a made-up torque; stick
figures of two segments), so no kernel runs; each drawing function's figure is caught where it is
saved."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from PIL import Image

from fdbench import figures, study

T = np.linspace(0.0, 1.0, 201)


@pytest.fixture
def drawn(monkeypatch):
    """The figures passed to ``figures.save_png`` (the one place a PNG is written), in order."""
    caught = []
    monkeypatch.setattr(figures, "save_png", lambda fig, path: caught.append(fig))
    return caught


def _inverse(joints=("elbow",)):
    """A made-up inverse dynamics: minimum-jerk angles from 0 to 60 deg (rad) and torques of about
    2 to 8 N m, one column per joint."""
    s = 10 * T**3 - 15 * T**4 + 6 * T**5
    angles = np.column_stack([np.radians(60.0 * s * (j + 1)) for j in range(len(joints))])
    torque = np.column_stack([5.0 + 3.0 * np.sin(2 * np.pi * T + j) for j in range(len(joints))])
    return SimpleNamespace(t=T, angles=angles, torque=torque, joints=tuple(joints), motion="minimum jerk")


def _dash(line) -> tuple:
    offset, dashes = line._unscaled_dash_pattern
    return to_rgba(line.get_color()), (offset, tuple(dashes) if dashes else None)


def _method_lines(ax) -> list:
    """The lines of ``ax`` that carry a label of their own (no markers, no zero line)."""
    return [line for line in ax.get_lines() if not line.get_label().startswith("_") and len(line.get_xdata()) > 1]


# ---- Figures 5 and 6: one wild run does not set the scale ------------------------------------------


def test_a_wild_run_leaves_the_tracking_figure_scaled_to_the_reference_and_is_marked(drawn, tmp_path):
    inverse = _inverse()
    desired, reference = np.degrees(inverse.angles[:, 0]), inverse.torque[:, 0]
    good_error = 0.2 * np.sin(6 * T)  # deg
    wild = np.linspace(0, -2300.0, len(T))  # N m: a failed run's torque, and its angle running away
    curves = [("PD control + feedforward", figures.method_style(None), np.radians(desired + good_error),
               reference + 0.5 * np.cos(3 * T)),
              ("ANN + cmaes", figures.method_style("ann", "cmaes"), np.radians(desired + 40 * T**2 * 1e3), wild)]
    figures.tracking_figure(inverse, curves, tmp_path / "f5.png", "Figure 5")
    top, middle, bottom = drawn[0].axes
    span = np.ptp(desired)
    low, high = top.get_ylim()
    assert low <= desired.min() and high >= desired.max()  # the desired rotation is within the axes ...
    assert low >= desired.min() - 0.5 * span and high <= desired.max() + 0.5 * span  # ... and sets their scale
    low, high = bottom.get_ylim()
    assert low <= reference.min() and high >= reference.max()
    assert low >= reference.min() - 0.5 * np.ptp(reference) and high <= reference.max() + 0.5 * np.ptp(reference)
    low, high = middle.get_ylim()  # the error axis: the working run's error, not the wild one's
    assert high >= np.abs(good_error).max() and high <= 2 * np.abs(good_error).max() and low == -high
    labels = [text.get_text() for text in top.get_legend().get_texts()]
    assert "ANN + cmaes (off scale)" in labels and "PD control + feedforward" in labels


def test_a_wild_run_on_a_model_of_several_joints_is_marked_and_its_torque_axes_follow_the_reference(drawn, tmp_path):
    inverse = _inverse(("shoulder", "elbow"))
    good = ("PD control + feedforward", figures.method_style(None), inverse.angles + 1e-3, inverse.torque + 0.1)
    wild = ("CS + cmaes", figures.method_style("cs", "cmaes"), inverse.angles, inverse.torque - 2300.0 * T[:, None])
    figures.joints_tracking_figure(inverse, [good, wild], tmp_path / "f5.png", "Figure 5")
    axes = np.array(drawn[0].axes).reshape(2, 2)
    for j in range(2):
        low, high = axes[1, j].get_ylim()
        torque = inverse.torque[:, j]
        assert torque.min() - np.ptp(torque) <= low <= torque.min() and torque.max() <= high <= torque.max() + np.ptp(torque)
    labels = [text.get_text() for text in axes[0, -1].get_legend().get_texts()]
    assert "CS + cmaes (off scale)" in labels and "PD control + feedforward" in labels


# ---- every line of a figure has its own colour and dash ---------------------------------------------


def _study_sweep():
    """The methods of the README's noise study, PD and each optimisation with and without feedforward."""
    cells = [("PD + feedforward", "control", None, None, True)]
    cells += [(f"{torque.upper()} + {opt}{' + ff' if ff else ''}", "optimize", torque, opt, ff)
              for ff in (False, True) for torque in ("ann", "cs", "pf") for opt in ("cmaes", "bfgs")]
    specs = {(name, 0.0): [SimpleNamespace(command=command, torque=torque, optimizer=opt, feedforward=ff)]
             for name, command, torque, opt, ff in cells}
    return SimpleNamespace(methods=[c[0] for c in cells], specs=specs, levels=(0.0, 1.0), kind="noise", param=None)


def test_no_two_lines_of_a_study_figure_share_colour_and_dash(drawn, tmp_path):
    sweep = _study_sweep()
    rows = [{"method": method, "level": level, **{f"{name}_{stat}": 0.1 + level + i / 10
                                                  for name in study.INDICATORS for stat in ("median", "q1", "q3")}}
            for i, method in enumerate(sweep.methods) for level in sweep.levels]
    study.write_figures(sweep, rows, tmp_path)
    assert len(drawn) == len(study.INDICATORS)
    for fig in drawn:
        lines = _method_lines(fig.axes[0])
        assert [line.get_label() for line in lines] == sweep.methods
        keys = [_dash(line) for line in lines]
        assert len(set(keys)) == len(keys), [line.get_label() for line in lines]
        by_label = dict(zip(sweep.methods, lines))
        # with feedforward: the same colour as without, another dash
        assert by_label["CS + bfgs"].get_color() == by_label["CS + bfgs + ff"].get_color()


def test_styles_that_collide_are_made_distinct_keeping_the_first():
    plugin = {"color": "tab:green", "linestyle": "--", "linewidth": 1.4}
    styles = figures.distinct_styles([figures.method_style("cs", "bfgs"), plugin, dict(plugin), dict(plugin)])
    assert styles[0] == figures.method_style("cs", "bfgs")
    keys = [figures.line_key(style) for style in styles]
    assert len(set(keys)) == 4


def test_convergence_lines_are_distinct_when_two_methods_share_a_style(drawn, tmp_path):
    same = figures.method_style("cs", "bfgs")
    series = [("CS + bfgs", same, [np.geomspace(10, 1, 20)]), ("CS + plugin", dict(same), [np.geomspace(9, 2, 20)])]
    figures.convergence_figure(series, tmp_path / "c.png", "Convergence", reference=0.5)
    keys = [_dash(line) for line in _method_lines(drawn[0].axes[0])]
    assert len(keys) == 3 and len(set(keys)) == 3


# ---- the figures of a model's coordinates: legends beside the panels, the reference on top ----------------------------


def _coordinate_curves():
    recorded = np.column_stack([np.degrees(np.sin(2 * np.pi * T)), 0.8 * T])
    curves = {"recorded": (T, recorded), "desired": (T, recorded)}
    for k, key in enumerate(("open-loop", "pd", "lqr")):
        curves[key] = (T, recorded + 0.01 * k)
    return curves


def _assert_legends_beside_the_panels(fig) -> None:
    fig.canvas.draw()
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert legends
    for legend in legends:
        box = legend.get_window_extent()
        for ax in fig.axes:
            if ax.get_visible():
                assert not box.overlaps(ax.get_window_extent()), (legend, ax.get_title())


def test_coordinates_legend_covers_no_panel_and_the_tracked_motion_is_drawn_on_top(drawn, tmp_path):
    labels = {"open-loop": "open loop", "pd": "PD", "lqr": "LQR"}
    figures.coordinates_figure(_coordinate_curves(), ("pelvis_tilt", "pelvis_tx"), ("rotation", "translation"),
                                    labels, tmp_path / "c.png")
    fig = drawn[0]
    _assert_legends_beside_the_panels(fig)
    for ax in fig.axes[:2]:
        lines = {line.get_label(): line for line in ax.get_lines()}
        tracked = lines["recording, filtered (tracked)"]
        assert all(tracked.get_zorder() > lines[name].get_zorder() for name in labels.values())


def test_residuals_legend_covers_no_panel_and_inverse_dynamics_is_drawn_on_top(drawn, tmp_path):
    base = 50 * np.sin(2 * np.pi * T)
    curves = {name: {"inverse dynamics": (T, base), "pd": (T, base + 1), "lqr": (T, base - 1)}
              for name in ("FX", "FY", "MZ")}
    figures.residuals_figure(curves, {"pd": "PD", "lqr": "LQR"}, tmp_path / "r.png")
    fig = drawn[0]
    _assert_legends_beside_the_panels(fig)
    for ax in fig.axes:
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert lines["inverse dynamics"].get_zorder() > max(lines["PD"].get_zorder(), lines["LQR"].get_zorder())


# ---- the animation's tick labels are readable at its size ------------------------------------------


def _stick_frames(phase: float, count: int = 8) -> list:
    frames = []
    for k in range(count):
        a = 0.4 * np.sin(2 * np.pi * (k / count + phase))
        hip = np.array([0.1 * k, 1.0])
        knee = hip + [0.45 * np.sin(a), -0.45 * np.cos(a)]
        frames.append(np.array([[hip, knee], [knee, knee + [0.0, -0.45]]]))
    return frames


def test_animation_tick_labels_are_at_least_ten_pixels_high_in_its_frames(tmp_path):
    recorded, simulated = _stick_frames(0.0), {"pd": _stick_frames(0.05), "lqr": _stick_frames(0.1)}
    held = {key: [False] * len(recorded) for key in simulated}
    path = tmp_path / "walk.gif"
    figures.animation((np.arange(len(recorded)), recorded, simulated, held), {"pd": "PD", "lqr": "LQR"},
                           np.linspace(0, 0.35, len(recorded)), {}, path)
    plt = figures.agg_pyplot()
    fig, axes = figures._animation_axes(plt, recorded, simulated)
    width, height = Image.open(path).size
    dpi = fig.get_dpi()
    # the frames are the figure at its dpi, not rescaled: a point is dpi / 72 of the frame's pixels
    assert np.allclose((width, height), fig.get_size_inches() * dpi, atol=1.0)
    fig.canvas.draw()
    for ax in axes.flat:
        for label in ax.get_xticklabels() + ax.get_yticklabels():
            assert label.get_fontsize() * dpi / 72 >= 10  # the font's size in the frame's pixels
            if label.get_text():
                assert label.get_window_extent().height >= 9  # the drawn text: a digit's height and more
    plt.close(fig)
