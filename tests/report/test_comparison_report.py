"""The report of a model with a floating base (``fdbench report`` on a recorded walk): its tables,
its figures' data and the paper's claim tested.

Fast checks run on a small model file with a free pelvis (tilt, x, y), a hip and a knee on a path
(``hopper_model``), a recorded motion written as a CSV file and an external load written as
OpenSim's ExternalLoads (XML + .mot); one end-to-end check runs the gait model's walk with a tiny
budget. Independent references: the motion file's columns (the recorded curves), the engine's
``point_positions`` (the stick figures), a hand count of the rows (the tables), the stored records
(the CSV/JSON), and synthetic rows whose numbers are changed (the claim's sentences)."""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import io
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.cli_checks import assert_one_line_error
from helpers.loads_files import push_files
from helpers.paths import ROOT
from fdbench.cli import app
from fdbench.problem import DEFAULT_RESIDUAL_WEIGHT
from fdbench.report import Row
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.model_files import to_toml
from fdbench.report.comparison import claim_facts, claim_lines, make_plan, ranking
from fdbench.report.methods import (BFGS, CMAES, COLLOCATION, COMPUTED_TORQUE, FLOATING_BASE_PENALTY, LQR,
                                    MUSCLE_COLLOCATION, MUSCLE_DRIVEN, OPEN_LOOP, PD, Options)

EXAMPLES = ROOT / "examples" / "opensim"
DURATION = 0.3  # s: the small model's recorded motion
COORDINATES = ("tilt", "tx", "ty", "hip", "knee")


def _hopper_file(folder: Path) -> Path:
    """The hopper model (free pelvis, hip, knee on a path) as a model file, without named motions."""
    from helpers.models import hopper_model

    from fdbench.multibody.model import MotionSpec
    from fdbench.multibody.model_files import to_toml

    model = hopper_model()
    rest = tuple((name, 0.0) for name in model.coordinates)
    path = folder / "hopper.toml"
    path.write_text(to_toml(dataclasses.replace(model, motions=(MotionSpec("still", "minimum-jerk", 0.2, rest, rest),))))
    return path


def _motion(t: np.ndarray) -> np.ndarray:
    """The small model's recorded motion: tilt (deg), tx, ty (m), hip, knee (deg), shape (n, 5)."""
    s = np.sin(2 * np.pi * t / DURATION)
    return np.column_stack([2 * s, 0.3 * t, 0.01 * s, 10 + 15 * s, -20 - 10 * s])


def _motion_file(folder: Path) -> Path:
    t = np.round(np.arange(0, DURATION + 1e-9, 0.01), 6)
    path = folder / "hop.csv"
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(("t",) + COORDINATES)
        writer.writerows(np.column_stack([t, _motion(t)]).tolist())
    return path


def _loads_file(folder: Path) -> Path:
    """An ExternalLoads file: a 20 N push along x and 60 N up on the shank, in ground's axes, at a
    point below the knee, with a free moment of 1 N m; its data in a .mot file."""
    return push_files(folder, np.arange(0, DURATION + 0.0501, 0.05), (20.0, 60.0, 0.0), (0.0, 0.3, 0.0), (0.0, 0.0, 1.0))


@pytest.fixture(scope="module")
def hop(tmp_path_factory):
    """The small model's walk report run once (CSV, JSON, Markdown with figures from the same
    database: the later formats reuse the stored runs)."""
    folder = tmp_path_factory.mktemp("hop")
    files = {"model": _hopper_file(folder), "motion": _motion_file(folder), "loads": _loads_file(folder)}
    base = ["report", "--model", str(files["model"]), "--motion", str(files["motion"]), "--loads", str(files["loads"]),
            "--db", str(folder / "runs.sqlite"), "--budget", "4", "--popsize", "2", "--no-beyond", "--jobs", "1", "-q"]
    runner = CliRunner()
    outputs = {}
    for fmt in ("csv", "json", "md"):
        out = folder / f"report.{fmt}"
        extra = ["--figures", str(folder / "figs")] if fmt == "md" else []
        result = runner.invoke(app, base + ["-f", fmt, "--output", str(out)] + extra)
        assert result.exit_code == 0, result.output
        outputs[fmt] = out.read_text()
    return {"folder": folder, "files": files, "base": base, **outputs}


def _expected_keys(report: dict) -> list:
    """The methods of a report made with --no-beyond: BFGS too once exact gradients take the model."""
    return [OPEN_LOOP, PD, COMPUTED_TORQUE, LQR, CMAES] + ([BFGS] if report["bfgs"] is None else [])


# ---- the report's tables -------------------------------------------------------------------------


def test_csv_has_one_row_per_method_and_model_with_the_stored_records(hop):
    """Every method once on the walk and once on the forearm (collocation left out by
    --no-beyond), and the CSV's numbers are the JSON's stored records'."""
    rows = list(csv.DictReader(io.StringIO(hop["csv"])))
    report = json.loads(hop["json"])
    keys = _expected_keys(report)
    assert [r["key"] for r in rows if r["model"] == "walk"] == keys
    assert [r["key"] for r in rows if r["model"] == "forearm"] == keys
    records = {("walk", e["key"]): e["record"] for e in report["walk"]} | {("forearm", e["key"]): e["record"]
                                                                           for e in report["forearm"]}
    for row in rows:
        record = records[(row["model"], row["key"])]
        for name in ("rmse_rot_deg", "rmse_trans_cm", "residual_force_rms_n", "t_end"):
            if record.get(name) is None:
                assert row[name] == ""
            else:
                assert float(row[name]) == pytest.approx(record[name], rel=1e-12)
    walk_cma = records[("walk", CMAES)]
    assert walk_cma["budget"] == 4 and walk_cma["optimizer"] == "cmaes" and walk_cma["feedforward"]
    assert walk_cma["n_params"] == len(COORDINATES) * 4  # knots every 0.1 s over 0.3 s: 4 per coordinate
    assert records[("forearm", CMAES)]["budget"] == 4  # the same budget on the forearm


def test_open_loop_is_pd_with_zero_gains_and_residuals_only_on_the_free_base(hop):
    """Open loop applies the inverse-dynamics torques with Kp = Kd = 0; the residual fields exist on
    the model with a floating base and not on the forearm; the inverse dynamics' residual means sit
    beside OpenSim RRA's published ones."""
    report = json.loads(hop["json"])
    walk = {e["key"]: e["record"] for e in report["walk"]}
    forearm = {e["key"]: e["record"] for e in report["forearm"]}
    assert all(walk[OPEN_LOOP][f"kp_{name}"] == 0.0 and walk[OPEN_LOOP][f"kd_{name}"] == 0.0 for name in COORDINATES)
    assert forearm[OPEN_LOOP]["kp"] == 0.0 and forearm[OPEN_LOOP]["kd"] == 0.0
    assert all(walk[key]["residual_force_rms_n"] is not None for key in walk)
    assert all("residual_force_rms_n" not in forearm[key] for key in forearm)
    assert report["rra_published_means"] == {"residual_fx_mean_n": -3.8, "residual_fy_mean_n": -2.8,
                                             "residual_mz_mean_nm": -3.4}
    assert set(report["inverse_residuals"]) >= {"residual_fx_mean_n", "residual_fy_mean_n", "residual_mz_mean_nm"}
    assert report["bfgs"] is None  # exact gradients on a free base, its step fitted to the recording's samples
    assert walk[BFGS]["gradient"] == "exact" and walk[BFGS]["optimizer"] == "bfgs" and walk[BFGS]["feedforward"]
    # eq. 18 on the walk: a fall penalised by FLOATING_BASE_PENALTY, the residuals weighted (loads given); the paper's on the forearm
    for key in (CMAES, BFGS):
        assert walk[key]["penalty_weight"] == FLOATING_BASE_PENALTY and walk[key]["residual_weight"] == DEFAULT_RESIDUAL_WEIGHT
        assert forearm[key]["penalty_weight"] == 1.0 and "residual_weight" not in forearm[key]


def test_markdown_tables_carry_every_method_and_coordinate(hop):
    """The main table has a line per method with its status; the per-coordinate table a column per
    coordinate, angles in deg and translations in cm, with each record's value."""
    text = hop["md"]
    report = json.loads(hop["json"])
    main = text.split("## Results on the walk")[1].split("### Error per coordinate")[0]
    for entry in report["walk"]:
        line = next(l for l in main.splitlines() if l.startswith(f"| {entry['method']} |"))
        assert f"{entry['record']['rmse_rot_deg']:.3g}" in line
    per = text.split("### Error per coordinate")[1].split("##")[0]
    header = next(l for l in per.splitlines() if l.startswith("| method"))
    assert header == "| method | tilt (deg) | tx (cm) | ty (cm) | hip (deg) | knee (deg) |"
    pd = next(e for e in report["walk"] if e["key"] == PD)
    line = next(l for l in per.splitlines() if l.startswith(f"| {pd['method']} |"))
    assert f"{pd['record']['rmse_trans_cm_tx']:.3g}" in line and f"{pd['record']['rmse_rot_deg_knee']:.3g}" in line
    for heading in ("## Inverse dynamics and its residuals", "## The same methods on the forearm",
                    "## The paper's claim tested", "## When and where the runs were made", "## Figures"):
        assert heading in text
    assert "OpenSim RRA" in text and "Table 2" not in text


# ---- the figures' data ---------------------------------------------------------------------------


def test_figures_are_written_and_linked(hop):
    """Every figure of a model without muscles (no activations figure) is written and linked."""
    from fdbench.figures import ACTIVATIONS_FILE, MODEL_FIGURE_FILES

    figs = hop["folder"] / "figs"
    written = set(MODEL_FIGURE_FILES) - {ACTIVATIONS_FILE}
    assert {p.name for p in figs.iterdir()} == written
    for name in written:
        assert (figs / name).stat().st_size > 1000 and f"](figs/{name})" in hop["md"]
    assert (figs / "animation.gif").read_bytes()[:6] in (b"GIF87a", b"GIF89a")


def _common(hop) -> dict:
    """The RunSpec fields of the small model's motion and loads."""
    from fdbench.multibody.loads import loads_digest
    from fdbench.spec import model_digest, motion_digest

    files = hop["files"]
    inputs = (("--loads", loads_digest(files["loads"])), ("--model", model_digest(files["model"])),
              ("--motion", motion_digest(files["motion"])))
    return dict(kinematics=str(files["motion"]), model_name=str(files["model"]), loads=str(files["loads"]),
                inputs=inputs)


def _spec(hop, **more):
    from fdbench.spec import control_spec

    return control_spec(**_common(hop), **more)


def test_recorded_curves_are_the_motion_files_columns(hop):
    """The coordinates figure's recorded curve of each coordinate is the file's column (deg for
    angles, m for translations); each simulated curve is the simulation's coordinates in those units."""
    from fdbench.api import run
    from fdbench.report.comparison import coordinates
    from fdbench.figures import coordinate_curves, recording

    spec = _spec(hop)
    names, kinds = coordinates(spec)
    assert names == COORDINATES and kinds == ("angle", "translation", "translation", "angle", "angle")
    result = run(spec).result
    curves = coordinate_curves(spec.reference(), recording(spec), {PD: result}, kinds)
    table = np.loadtxt(hop["files"]["motion"], delimiter=",", skiprows=1)
    np.testing.assert_allclose(curves["recorded"][0], table[:, 0], atol=1e-12)
    np.testing.assert_allclose(curves["recorded"][1], table[:, 1:], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(curves[PD][1][:, 1], result.z[:, 1], rtol=0, atol=0)  # tx in m
    np.testing.assert_allclose(curves[PD][1][:, 4], np.degrees(result.z[:, 4]), rtol=1e-14)


def test_stick_figure_points_are_the_engines_point_positions(hop):
    """At each instant, the stick figure's segments run from each body's joint point to its end as
    ``Engine.point_positions`` gives them; an instant a simulation did not reach has none."""
    from fdbench.run_inputs import engine
    from fdbench.figures import instants, stick_frames

    spec = _spec(hop)
    plant = engine(spec)
    inverse = spec.reference()
    indices = instants(inverse.t, 4)
    assert list(inverse.t[indices]) == pytest.approx([0.0, 0.1, 0.2, 0.3])
    frames = stick_frames(plant, inverse.angles, indices)
    for i, frame in zip(indices, frames):
        points = plant.point_positions(inverse.angles[i])
        for b, body in enumerate(("pelvis", "thigh", "shank")):
            np.testing.assert_array_equal(frame[b, 0], points[f"{body}.joint"])
            np.testing.assert_array_equal(frame[b, 1], points[f"{body}.end"])
    # the pelvis's joint point follows the (filtered) recorded x, y of the free joint (the base sits at (0, 1))
    np.testing.assert_allclose(frames[-1][0, 0], [0.3 * 0.3, 1.0 + 0.0], atol=1e-5)
    fallen = inverse.angles.copy()
    fallen[indices[-1]:] = np.nan
    assert stick_frames(plant, fallen, indices)[-1] is None


def _fallen(result, last: int):
    """The simulation ``result`` as if it had stopped on a constraint violation just after the
    sample ``last``: NaN on every later sample, as a simulation that stops leaves them."""
    from fdbench.integrate import Status

    z, torque = result.z.copy(), result.torque.copy()
    z[last + 1:], torque[last + 1:] = np.nan, np.nan
    t_end = float(result.t[last] + 0.4 * (result.t[last + 1] - result.t[last]))
    return dataclasses.replace(result, z=z, torque=torque, t_end=t_end, status=Status.CONSTRAINT)


def test_a_fallen_runs_last_pose_is_shown_marked_and_held(hop):
    """A run that stopped early: the stick figure's last pose is ``Engine.point_positions`` at the
    last sample it reached, beside the tracked motion's there, marked with its t_end; the animation
    shows its poses until then and holds that last pose after; a run that reached the end has none."""
    from fdbench.api import run
    from fdbench.run_inputs import engine
    from fdbench.figures import ANIMATION_FPS, animation_frames, stopped_poses

    spec = _spec(hop)
    plant, inverse, result = engine(spec), spec.reference(), run(spec).result
    assert result.success
    last = 13  # t = 0.13 s of the 0.01 s samples
    fallen = _fallen(result, last)
    stops = stopped_poses(plant, inverse.angles, {PD: result, OPEN_LOOP: fallen})
    assert list(stops) == [OPEN_LOOP]
    stop = stops[OPEN_LOOP]
    assert (stop.index, stop.t, stop.status) == (last, pytest.approx(0.13), "constraint")
    assert stop.label == f"fell at {fallen.t_end:.3f} s (constraint)" == "fell at 0.134 s (constraint)"
    reached, tracked = plant.point_positions(result.z[last]), plant.point_positions(inverse.angles[last])
    for b, body in enumerate(("pelvis", "thigh", "shank")):
        for end, point in enumerate(("joint", "end")):
            np.testing.assert_array_equal(stop.frame[b, end], reached[f"{body}.{point}"])
            np.testing.assert_array_equal(stop.tracked[b, end], tracked[f"{body}.{point}"])
    indices, recorded, frames, held = animation_frames(plant, inverse.angles, {PD: result, OPEN_LOOP: fallen}, inverse.t)
    assert np.diff(inverse.t[indices]) == pytest.approx(np.full(len(indices) - 1, 1 / ANIMATION_FPS))
    assert held[PD] == [False] * len(indices)
    assert held[OPEN_LOOP] == [i > last for i in indices] and any(held[OPEN_LOOP])
    for k, i in enumerate(indices):
        shown = plant.point_positions(result.z[min(i, last)])
        np.testing.assert_array_equal(frames[OPEN_LOOP][k][2], [shown["shank.joint"], shown["shank.end"]])
        np.testing.assert_array_equal(frames[PD][k][2], [plant.point_positions(result.z[i])[f"shank.{p}"]
                                                         for p in ("joint", "end")])
        np.testing.assert_array_equal(recorded[k][1], [plant.point_positions(inverse.angles[i])[f"thigh.{p}"]
                                                       for p in ("joint", "end")])


def test_collocations_own_solution_is_drawn_at_its_nodes(hop, tmp_path):
    """The collocation row gives its replay (a Simulation on the motion's samples) and its own
    solution: the coordinates figure's 'collocation (own solution)' curve is the angles (deg) and
    translations (m) at the nodes of ``collocation.collocate`` called directly on the same model,
    motion and loads; the residuals figure's, the generalised forces on the base there; both
    figures are written with it."""
    from fdbench.collocation import collocate
    from fdbench.spec import collocate_spec
    from fdbench.run_inputs import loads, motions, nominal
    from fdbench.report.comparison import coordinates
    from fdbench.figures import (OWN_SOLUTION, coordinate_curves, coordinates_figure, recording,
                                      residual_curves, residuals_figure, trajectories)

    spec = collocate_spec(10, "hermite-simpson", **_common(hop))
    row = _row(COLLOCATION, "collocation + replay", {"command": "collocate"}, spec)
    sims, own = trajectories([row], {spec.hash(): {"params": None}})
    assert list(sims) == list(own) == [COLLOCATION]
    inverse = spec.reference()
    np.testing.assert_array_equal(sims[COLLOCATION].t, inverse.t)
    direct = collocate(nominal(spec), motions(spec)[0], 10, "hermite-simpson", loads=loads(spec))
    assert direct.t.shape == (11,)  # the nodes of 10 intervals
    _, kinds = coordinates(spec)
    curves = coordinate_curves(inverse, recording(spec), sims, kinds, own[COLLOCATION])
    t, values = curves[OWN_SOLUTION]
    np.testing.assert_allclose(t, direct.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(values[:, [1, 2]], direct.angles[:, [1, 2]], rtol=1e-6, atol=1e-9)  # tx, ty in m
    np.testing.assert_allclose(values[:, [0, 3, 4]], np.degrees(direct.angles[:, [0, 3, 4]]), rtol=1e-6, atol=1e-7)
    residuals = residual_curves(nominal(spec), inverse, sims, own[COLLOCATION])
    for name, column in (("FX", 1), ("FY", 2), ("MZ", 0)):
        np.testing.assert_allclose(residuals[name][OWN_SOLUTION][1], direct.torque[:, column], rtol=1e-6, atol=1e-6)
    labels = {COLLOCATION: row.name}
    coordinates_figure(curves, COORDINATES, kinds, labels, tmp_path / "c.png")
    residuals_figure(residuals, labels, tmp_path / "r.png")
    assert (tmp_path / "c.png").stat().st_size > 1000 and (tmp_path / "r.png").stat().st_size > 1000


def test_residual_curves_are_the_base_coordinates_generalised_forces(hop):
    """FX, FY, MZ of the inverse dynamics are its forces on tx, ty and tilt; a simulation's are its
    applied forces on them; a model without a floating base has none."""
    from fdbench.api import run
    from fdbench.spec import control_spec
    from fdbench.models import with_changes
    from fdbench.run_inputs import nominal
    from fdbench.figures import residual_curves

    spec = _spec(hop)
    inverse = spec.reference()
    result = run(spec).result
    curves = residual_curves(nominal(spec), inverse, {PD: result})
    for name, column in (("FX", 1), ("FY", 2), ("MZ", 0)):
        np.testing.assert_array_equal(curves[name]["inverse dynamics"][1], inverse.torque[:, column])
        np.testing.assert_array_equal(curves[name][PD][1], result.torque[:, column])
    forearm = control_spec()
    assert residual_curves(with_changes("forearm"), forearm.reference(), {}) == {}


# ---- the claim tested, from synthetic rows -------------------------------------------------------


def _row(key: str, name: str, record: dict, spec=None) -> Row:
    """A report row of one run of the registered method ``key``."""
    return Row(name, "walk", None, {}, None, [record], hashes=[spec.hash()] if spec else [],
               specs=[spec] if spec else [], key=key)


def _rows(values: dict) -> list[Row]:
    """Rows of methods {key: (status, t_end, rmse_rot_deg, residual force RMS or None)}."""
    return [_row(key, key.replace("-", " ").title(), {"status": status, "t_end": t_end, "rmse_rot_deg": rot,
                                                         "runtime_s": 1.0, "residual_force_rms_n": residual})
            for key, (status, t_end, rot, residual) in values.items()]


FOREARM = {OPEN_LOOP: ("success", 1.0, 5.0, None), PD: ("success", 1.0, 0.1, None),
           COMPUTED_TORQUE: ("success", 1.0, 0.01, None), LQR: ("success", 1.0, 0.05, None)}
WALK = {OPEN_LOOP: ("constraint", 0.44, 30.0, 40.0), PD: ("success", 2.5, 0.02, 34.0),
        COMPUTED_TORQUE: ("success", 2.5, 0.06, 33.8), LQR: ("success", 2.5, 0.03, 33.9)}


def test_claim_says_where_reaching_the_end_disagrees_and_why():
    facts = claim_facts(_rows(WALK), _rows(FOREARM))
    reach = facts["reach_the_end"]
    assert reach["both"] == [PD, COMPUTED_TORQUE, LQR] and reach["forearm_only"] == [OPEN_LOOP]
    assert reach["neither"] == reach["walk_only"] == []
    # open loop last on both, 50 times PD's error on the forearm (5 / 0.1) and 1,500 times on the walk (30 / 0.02)
    assert facts["ranking"]["forearm"][-1] == facts["ranking"]["walk"][-1] == OPEN_LOOP
    assert facts["open_loop_over_pd"] == {"forearm": pytest.approx(50), "walk": pytest.approx(1500)}
    text = "\n".join(claim_lines(_rows(WALK), _rows(FOREARM), 2.5, 1.0))
    assert "nothing holds the walk's floating base" in text  # the reason, where open loop falls on the walk only
    assert "drift from the motion, 50 times (forearm) and 1,500 times (walk) PD's error" in text
    # the same numbers but open loop reaching the walk's end: the disagreement and its reason go
    walk = dict(WALK, **{OPEN_LOOP: ("success", 2.5, 30.0, 40.0)})
    assert claim_facts(_rows(walk), _rows(FOREARM))["reach_the_end"]["both"] == list(WALK)
    text = "\n".join(claim_lines(_rows(walk), _rows(FOREARM), 2.5, 1.0))
    assert "floating base:" not in text and "Disagrees" not in text
    # open loop as close to PD as a tie on the walk: no claim that it drifts on both
    walk = dict(WALK, **{OPEN_LOOP: ("success", 2.5, 0.021, 40.0)})
    assert claim_facts(_rows(walk), _rows(FOREARM))["open_loop_over_pd"]["walk"] == pytest.approx(1.05)
    assert "drift from the motion" not in "\n".join(claim_lines(_rows(walk), _rows(FOREARM), 2.5, 1.0))


def test_claim_ranking_follows_the_numbers():
    """The rankings' agreement is counted over pairs of methods and names the pairs ordered
    differently; swapping RMSE values on the walk changes it; close values tie."""
    assert ranking(_rows(WALK)) == [PD, LQR, COMPUTED_TORQUE, OPEN_LOOP]  # reaching the end first, then RMSE_rot
    assert ranking(_rows(FOREARM)) == [COMPUTED_TORQUE, LQR, PD, OPEN_LOOP]
    # forearm CT < LQR < PD; walk PD < LQR < CT: all three pairs among them swap, the three with open loop agree
    facts = claim_facts(_rows(WALK), _rows(FOREARM))["ranking"]
    assert (facts["pairs"], facts["alike"], facts["ties"], facts["other_way_by_reaching_the_end"]) == (6, 3, 0, 0)
    assert sorted(map(tuple, facts["other_way_by_rmse_rot"])) == [(COMPUTED_TORQUE, LQR), (COMPUTED_TORQUE, PD),
                                                                  (LQR, PD)]  # (above on the forearm, below)
    assert (facts["forearm"][0], facts["walk"][0]) == (COMPUTED_TORQUE, PD)
    assert "The best is computed torque on the forearm and PD on the walk." in "\n".join(
        claim_lines(_rows(WALK), _rows(FOREARM), 2.5, 1.0))
    same = dict(WALK, **{PD: ("success", 2.5, 0.5, 34.0), COMPUTED_TORQUE: ("success", 2.5, 0.01, 33.8),
                         LQR: ("success", 2.5, 0.05, 33.9)})
    facts = claim_facts(_rows(same), _rows(FOREARM))["ranking"]
    assert facts["alike"] == 6 and facts["other_way_by_rmse_rot"] == [] and facts["walk"][0] == COMPUTED_TORQUE
    # PD and LQR within a factor 1.25 on the walk: a tie, neither agreeing nor swapped
    close = dict(WALK, **{PD: ("success", 2.5, 0.025, 34.0)})
    facts = claim_facts(_rows(close), _rows(FOREARM))["ranking"]
    assert (facts["alike"], facts["ties"], len(facts["other_way_by_rmse_rot"])) == (3, 1, 2)
    # a swap caused by reaching the end is counted apart from those by RMSE_rot
    falls = dict(WALK, **{COMPUTED_TORQUE: ("constraint", 1.0, 0.06, 33.8)})
    facts = claim_facts(_rows(falls), _rows(FOREARM))["ranking"]
    assert facts["other_way_by_reaching_the_end"] == 2 and facts["other_way_by_rmse_rot"] == [[LQR, PD]]


def test_claim_residual_sentence_follows_the_methods_that_reach_the_end():
    facts = claim_facts(_rows(WALK), _rows(FOREARM), {"residual_force_rms_n": 33.7})
    # 33.8, 33.9 and 34 N: within 1 %; open loop's 40 N is not a whole walk
    assert facts["residual_force_rms_n"] == {COMPUTED_TORQUE: 33.8, LQR: 33.9, PD: 34.0}
    assert facts["residual_force_rms_n_inverse"] == 33.7
    text = "\n".join(claim_lines(_rows(WALK), _rows(FOREARM), 2.5, 1.0, inverse_fields={"residual_force_rms_n": 33.7}))
    assert "leave the same residual force RMS to within 1 %" in text
    walk = dict(WALK, **{PD: ("success", 2.5, 0.02, 40.0)})
    assert "goes from 33.8 N (computed torque) to 40 N (PD)" in "\n".join(claim_lines(_rows(walk), _rows(FOREARM),
                                                                                       2.5, 1.0))
    walk = {key: (status if key == PD else "constraint", t_end, rot, res) for key, (status, t_end, rot, res) in WALK.items()}
    assert claim_facts(_rows(walk), _rows(FOREARM))["residual_force_rms_n"] == {PD: 34.0}


def test_claim_says_when_an_optimisation_ended_worse_than_its_start():
    rows = _rows({**WALK, CMAES: ("constraint", 0.08, 28.9, 80.0)})
    rows[-1].record.update(best_objective=29.9, initial_objective=31.4, evaluations=48, budget=48, n_params=260)
    forearm = _rows({**FOREARM, CMAES: ("success", 1.0, 1.0, None)})
    forearm[-1].record.update(n_params=11, budget=48)
    assert claim_facts(rows, forearm)["worse_than_start"] == []
    assert "spread over 260 spline parameters on the walk against 11" in "\n".join(claim_lines(rows, forearm, 2.5, 1.0))
    rows[-1].record.update(best_objective=38.0)
    assert claim_facts(rows, forearm)["worse_than_start"] == [CMAES]
    text = "\n".join(claim_lines(rows, forearm, 2.5, 1.0))
    assert "Its best objective (eq. 18: 38) is worse than that of its initial guess (31.4" in text


# ---- bad input -----------------------------------------------------------------------------------


@pytest.mark.parametrize("extra, word", [(["--seeds", "0"], "--seeds"), (["--kp", "nan"], "--kp"),
                                         (["--jobs", "0"], "--jobs"), (["--budget", "0"], "--budget"),
                                         (["--torque", "xyz"], "--torque")])
def test_bad_options_are_refused_in_one_line_before_any_work(tmp_path, extra, word):
    files = [_hopper_file(tmp_path), _motion_file(tmp_path), _loads_file(tmp_path)]
    before = set(tmp_path.iterdir())
    result = CliRunner().invoke(app, ["report", "--model", str(files[0]), "--motion", str(files[1]), "--loads",
                                      str(files[2]), "--db", str(tmp_path / "runs.sqlite"), "--no-beyond",
                                      "--output", str(tmp_path / "out.md"), "-q"] + extra)
    assert_one_line_error(result, word)
    assert set(tmp_path.iterdir()) == before  # no database, no report


def test_the_paper_reports_options_shape_the_runs_on_a_floating_base(hop):
    """The options of the paper's report work on a floating base too: --torque/--opt/--feedforward
    select the paper's cells, run on the model with --seeds each; --kp/--kd set PD's gains on both
    models; --penalty-weight, --sigma0 and --knots the shooting methods'; --gradient exact adds the
    cells' exact-gradient rows; --no-control leaves PD out. Checked on the stored records."""
    out = hop["folder"] / "options.json"
    base = [arg for arg in hop["base"] if arg != "--no-beyond"]
    result = CliRunner().invoke(app, base + ["--no-beyond", "--torque", "cs", "--opt", "cmaes", "--opt", "bfgs", "--feedforward",
                                             "--seeds", "2", "--kp", "50", "--kd", "0.5", "--penalty-weight", "7",
                                             "--sigma0", "0.3", "--knots", "5", "--gradient", "exact", "-f", "json",
                                             "--output", str(out)])
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    walk = {e["key"]: e["record"] for e in report["walk"]}
    forearm = {e["key"]: e["record"] for e in report["forearm"]}
    assert walk[PD]["kp"] == 50.0 and walk[PD]["kd"] == 0.5 and forearm[PD]["kp"] == 50.0
    assert walk[CMAES]["penalty_weight"] == 7.0 and forearm[CMAES]["penalty_weight"] == 1.0
    assert "sigma0" in str(walk[CMAES]["optimizer_options"]) and "0.3" in str(walk[CMAES]["optimizer_options"])
    assert walk[CMAES]["n_params"] == len(COORDINATES) * 5  # --knots 5 on every coordinate
    cells = report["cells"]
    assert sorted((c["torque"], c["optimizer"], c["table"]) for c in cells) == [("cs", "bfgs", 3), ("cs", "cmaes", 3)]
    assert all(c["seeds"] == 2 and c["model"] == str(hop["files"]["model"]) for c in cells)
    assert any(key.endswith("-exact") and walk[key]["gradient"] == "exact" for key in walk)
    rows = list(csv.DictReader(io.StringIO(CliRunner().invoke(app, base + [
        "--no-beyond", "--torque", "cs", "--opt", "cmaes", "--opt", "bfgs", "--feedforward", "--seeds", "2", "--kp", "50", "--kd",
        "0.5", "--penalty-weight", "7", "--sigma0", "0.3", "--knots", "5", "--gradient", "exact", "-f", "csv"]).stdout)))
    assert sum(r["key"].startswith("table3-seed") for r in rows) == 4  # two cells, two seeds each
    result = CliRunner().invoke(app, base + ["--no-beyond", "--no-control", "-f", "json", "--output", str(out)])
    assert result.exit_code == 0, result.output
    assert PD not in {e["key"] for e in json.loads(out.read_text())["walk"]}


# ---- the recorded walk, end to end ---------------------------------------------------------------


def _first_of_the_walk(folder: Path, seconds: float) -> tuple[Path, Path]:
    """The recorded walk's first ``seconds`` as a .mot file, and its loads file pointing at the
    ground reactions' data by an absolute path."""
    lines = (EXAMPLES / "subject01_walk_IK.mot").read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip() == "endheader") + 2  # the column labels too
    kept = [line for line in lines[end:] if line.strip() and float(line.split()[0]) <= seconds + 1e-9]
    motion = folder / "walk_start.mot"
    motion.write_text("\n".join(lines[:end] + kept) + "\n")
    loads = folder / "grf.xml"
    loads.write_text((EXAMPLES / "subject01_walk_grf.xml").read_text().replace(
        "<datafile>subject01_walk_grf.mot", f"<datafile>{EXAMPLES / 'subject01_walk_grf.mot'}"))
    return motion, loads


@pytest.mark.skipif(not (EXAMPLES / "subject01.osim").exists(), reason="the gait model is not in examples/opensim")
def test_walk_report_end_to_end_on_the_gait_model(tmp_path):
    """The first 0.3 s of subject01's walk with a tiny budget and no collocation: every method on
    both models; PD tracks every angle within 1 deg and the pelvis within 1 cm; the inverse
    dynamics' residual means are those of ``fdbench inverse`` on the same files."""
    if importlib.util.find_spec("opensim") is None:  # not imported here: its CasADi would break LQR's in this process
        pytest.skip("the opensim package is not installed")
    motion, loads = _first_of_the_walk(tmp_path, 0.3)
    common = ["--model", str(EXAMPLES / "subject01.osim"), "--motion", str(motion), "--loads", str(loads), "-q"]
    out = tmp_path / "walk.json"
    runner = CliRunner()
    result = runner.invoke(app, ["report", *common, "--db", str(tmp_path / "runs.sqlite"), "--budget", "2",
                                 "--popsize", "2", "--no-beyond", "--jobs", "2", "-f", "json", "--output", str(out)])
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    walk = {e["key"]: e["record"] for e in report["walk"]}
    assert list(walk) == _expected_keys(report)
    pd = walk[PD]
    assert pd["status"] == "success" and pd["t_end"] == pytest.approx(0.3)
    angles = [k for k in pd if k.startswith("rmse_rot_deg_")]
    assert len(angles) == 8 and all(pd[k] < 1.0 for k in angles)  # 10 coordinates, 2 translations
    assert all(pd[f"rmse_trans_cm_pelvis_{axis}"] < 1.0 for axis in ("tx", "ty"))
    assert all(walk[key].get("residual_force_rms_n", 0) > 0 for key in walk), {k: (r["status"], r.get("message")) for k, r in walk.items()}
    assert any(line.startswith("Residuals exist only on the walk") for line in report["claim"])
    inverse = json.loads(runner.invoke(app, ["inverse", *common, "-f", "json"]).stdout)
    for name in ("residual_fx_mean_n", "residual_fy_mean_n", "residual_mz_mean_nm"):
        assert report["inverse_residuals"][name] == pytest.approx(inverse[name], rel=1e-9)


def test_collocations_own_solution_is_named_beside_its_replay():
    """The sentence under the main table gives the collocation's own numbers from its record, and
    is left out without a collocation row."""
    from fdbench.report.comparison import collocation_own_lines

    record = {"status": "constraint", "t_end": 0.3, "collocation_rmse_rot_deg": 0.0421, "collocation_rmse_trans_cm": 0.128,
              "collocation_residual_force_rms_n": 8.61, "collocation_residual_moment_rms_nm": 9.52}
    (text,) = [line for line in collocation_own_lines([_row(COLLOCATION, "collocation", record)]) if line]
    assert all(f"{value:.3g}" in text for key, value in record.items() if key.startswith("collocation_"))
    assert collocation_own_lines([_row(PD, "PD", {"status": "success"})]) == []
    both = [line for line in collocation_own_lines([_row(COLLOCATION, "collocation", record),
                                                    _row(MUSCLE_COLLOCATION, "muscles", record)]) if line]
    assert len(both) == 2 and "its torque replayed" in both[0] and "its excitations and reserves replayed" in both[1]


# ---- the import's warnings: once, before the work ---------------------------------------------------


def test_an_imported_models_warnings_are_said_once_before_the_work(tmp_path):
    """A free pelvis and a knee on a path written as an OpenSim model with one marker (which the
    import drops, saying so): its report says that warning once, before the line saying what it
    wrote."""
    if importlib.util.find_spec("opensim") is None:
        pytest.skip("the opensim package is not installed")
    from helpers.osim_files import path_knee_model

    model = path_knee_model(tmp_path / "knee.osim")
    marker = ('<MarkerSet name="markerset"><objects><Marker name="m1"><socket_parent_frame>/bodyset/thigh'
              "</socket_parent_frame><location>0 0 0</location></Marker></objects></MarkerSet>")
    model.write_text(model.read_text().replace("</Model>", marker + "</Model>"))
    t = np.round(np.arange(0, DURATION + 1e-9, 0.01), 6)
    s = np.sin(2 * np.pi * t / DURATION)
    motion = tmp_path / "hop.csv"
    with motion.open("w", newline="") as handle:
        csv.writer(handle).writerows([("t", "pelvis_tilt", "pelvis_tx", "pelvis_ty", "knee_angle")]
                                     + np.column_stack([t, 2 * s, 0.3 * t, 1 + 0.01 * s, -20 - 10 * s]).tolist())
    out = tmp_path / "walk.md"
    result = CliRunner().invoke(app, ["report", "--model", str(model), "--motion", str(motion), "--loads",
                                      str(_loads_file(tmp_path)), "--db", str(tmp_path / "runs.sqlite"), "--budget",
                                      "4", "--popsize", "2", "--no-beyond", "--jobs", "1", "--output", str(out)])
    assert result.exit_code == 0, result.output
    lines = result.stderr.splitlines()
    warnings = [i for i, line in enumerate(lines) if line.startswith("fdbench: warning: --model: ")]
    assert len(warnings) == 1 and "dropped 1 marker" in lines[warnings[0]], lines
    (wrote,) = [i for i, line in enumerate(lines) if line.startswith(f"wrote {out}")]
    assert warnings[0] < wrote, lines


def test_a_floating_base_with_muscles_gets_the_muscle_driven_methods_the_forearm_does_not(tmp_path):
    """The hopper with a hip flexor and extensor (rigid tendons): the report plans every
    muscle-driven method on it and none on the forearm (which has no muscles), the forearm keeping
    every other method of the hopper's; --no-beyond leaves them out with collocation."""
    from helpers.models import hopper_model

    data = to_dict(hopper_model())
    data["motions"] = [{"name": "still", "type": "minimum-jerk", "duration": 0.2,
                        "start": {name: 0.0 for name in hopper_model().coordinates},
                        "goal": {name: 0.0 for name in hopper_model().coordinates}}]
    data["muscles"] = [{"name": name, "max_isometric_force": 800.0, "optimal_fiber_length": 0.1,
                        "tendon_slack_length": 0.15, "tendon": "rigid",
                        "path": {"points": [{"body": "pelvis", "at": [x, 0.0]}, {"body": "thigh", "at": [x, -0.2]}]}}
                       for name, x in (("flexor", 0.05), ("extensor", -0.05))]
    path = tmp_path / "hopper.toml"
    path.write_text(to_toml(model_from_dict(data, "hopper.toml")))
    plan = make_plan({"model_name": str(path), "motion": "still"}, {}, Options(budget=4, popsize=2))
    studied, forearm = [m.key for m in plan.studied], [m.key for m in plan.forearm]
    assert set(MUSCLE_DRIVEN) <= set(studied) and not set(MUSCLE_DRIVEN) & set(forearm)
    assert forearm == [key for key in studied if key not in MUSCLE_DRIVEN]
    assert all(m.spec.model_name == str(path) for m in plan.studied if m.key in MUSCLE_DRIVEN)
    without = make_plan({"model_name": str(path), "motion": "still"}, {}, Options(budget=4, popsize=2),
                        collocation=False)
    assert not set(MUSCLE_DRIVEN) & {m.key for m in without.studied}
