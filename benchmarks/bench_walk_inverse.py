"""Inverse dynamics of the recorded walk (examples/opensim: subject01.osim, its IK motion at
60 Hz and its ground reactions) by fdbench and by OpenSim's InverseDynamicsTool, each with its own
derivative estimate at the same cutoff (6 Hz), measured in one run.

fdbench: its default estimate of a recorded motion (``fdbench inverse --model subject01.osim
--motion subject01_walk_IK.mot --loads subject01_walk_grf.xml``): a 2nd-order Butterworth run
forward and backward (4th-order zero lag), its design cutoff corrected so that the whole is -3 dB
at the cutoff, each end point-reflected for as long as the filter takes to settle, then an
interpolating quintic spline.
OpenSim's InverseDynamicsTool (``lowpass_cutoff_frequency_for_coordinates`` 6, the external loads
file, muscles excluded): the coordinates padded by half their count at each end (point-reflected,
Signal::Pad), a 3rd-order Butterworth IIR run forward and backward at the uncorrected design
cutoff (Signal::LowpassIIR: -6 dB at the cutoff, -3 dB lower), then quintic GCV splines of zero
error variance (interpolating) whose derivatives are the rates and accelerations.

Printed per coordinate: the RMS of OpenSim's generalised force, the RMS difference of fdbench's
(whole motion and away from the ends), relative to that RMS; the RMS difference of the two
accelerations; fdbench's estimate with its cutoff set to OpenSim's -3 dB point, against the tool;
and fdbench's inverse dynamics on OpenSim's own filtered kinematics (rebuilt in
OpenSim's process: Storage.pad + lowpassIIR + GCVSplineSet(5)) against the tool's output, which
shows that the whole difference is the derivative estimate, not the dynamics.

Run: python benchmarks/bench_walk_inverse.py [--data FOLDER] [--cutoff HZ]
Without the opensim package (or the data) it prints why and exits 0.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PLACES = (ROOT / "examples" / "opensim", ROOT.parent / "shared" / "data" / "opensim",
          ROOT.parent.parent / "shared" / "data" / "opensim")  # the walk's files: shipped, or beside the source
DATA = next((where for where in PLACES if (where / "subject01_walk_grf.xml").exists()), PLACES[0])
EDGE_S = 0.25  # s: "away from the ends" leaves out this much at each end of the motion

# OpenSim runs in a child process (its bundled CasADi cannot share fdbench's process).
OPENSIM_CHILD = r"""
import json, os, sys
import opensim as osim
osim.Logger.setLevelString("Off")
request = json.loads(sys.stdin.read())
model = osim.Model(request["model"])
model.initSystem()
tool = osim.InverseDynamicsTool()
tool.setModel(model)
tool.setCoordinatesFileName(request["motion"])
tool.setLowpassCutoffFrequency(request["cutoff_hz"])
tool.setExternalLoadsFileName(request["loads"])
excluded = osim.ArrayStr()
excluded.append("Muscles")
tool.setExcludedForces(excluded)
tool.setStartTime(request["t0"])
tool.setEndTime(request["t1"])
tool.setResultsDir(request["folder"])
tool.setOutputGenForceFileName("id.sto")
tool.run()
table = osim.TimeSeriesTable(os.path.join(request["folder"], "id.sto"))
times = list(table.getIndependentColumn())
forces = {label.rsplit("_", 1)[0]: list(table.getDependentColumn(label).to_numpy())
          for label in table.getColumnLabels()}
# the kinematics the tool differentiates: its own filter and splines, rebuilt
storage = osim.Storage(request["motion"])
storage.pad(storage.getSize() // 2)
storage.lowpassIIR(request["cutoff_hz"])
fresh = osim.Model(request["model"])
fresh.initSystem()
if storage.isInDegrees():
    fresh.getSimbodyEngine().convertDegreesToRadians(storage)
splines = osim.GCVSplineSet(5, storage)
kinematics = {}
for name in request["coordinates"]:
    spline = splines.get(name)
    rows = []
    for t in times:
        at = osim.Vector(1, t)
        rows.append([spline.calcValue(at)] + [spline.calcDerivative(osim.StdVectorInt([0] * k), at) for k in (1, 2)])
    kinematics[name] = rows
print(json.dumps({"t": times, "forces": forces, "kinematics": kinematics}))
"""


def opensim_inverse(data: Path, coordinates, cutoff_hz: float, t0: float, t1: float) -> dict:
    """OpenSim's InverseDynamicsTool on the walk and its filtered kinematics: {'t': (n,), 'forces':
    {coordinate: (n,)} (N m or N), 'kinematics': {coordinate: (n, 3) value, rate, acceleration}}."""
    with tempfile.TemporaryDirectory(prefix="fdbench-bench-") as folder:
        request = {"model": str(data / "subject01.osim"), "motion": str(data / "subject01_walk_IK.mot"),
                   "loads": str(data / "subject01_walk_grf.xml"), "cutoff_hz": cutoff_hz, "t0": t0, "t1": t1,
                   "folder": folder, "coordinates": list(coordinates)}
        done = subprocess.run([sys.executable, "-c", OPENSIM_CHILD], input=json.dumps(request), capture_output=True,
                              text=True, cwd=folder, timeout=600)
    if done.returncode != 0:
        sys.exit(f"OpenSim's process failed: {(done.stderr.strip().splitlines() or ['no output'])[-1]}")
    answer = json.loads(done.stdout.strip().splitlines()[-1])
    return {"t": np.array(answer["t"]), "forces": {k: np.array(v) for k, v in answer["forces"].items()},
            "kinematics": {k: np.array(v) for k, v in answer["kinematics"].items()}}


def opensim_minus_3db_hz(cutoff_hz: float, rate_hz: float, order: int = 3, passes: int = 2) -> float:
    """The -3 dB point (Hz) of a digital Butterworth of ``order`` designed at ``cutoff_hz`` (bilinear,
    uncorrected) and run ``passes`` times: (1 + x^(2 order))^passes = 2 with x the warped ratio."""
    x = (2 ** (1 / passes) - 1) ** (1 / (2 * order))
    return rate_hz / math.pi * math.atan(x * math.tan(math.pi * cutoff_hz / rate_hz))


def rms(values, axis=0):
    return np.sqrt(np.mean(np.asarray(values) ** 2, axis=axis))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--data", type=Path, default=DATA, help=f"folder of the walk's files (default {DATA})")
    parser.add_argument("--cutoff", type=float, default=6.0, help="cutoff (Hz) of both estimates (default 6)")
    args = parser.parse_args(argv)
    if not (args.data / "subject01_walk_grf.xml").exists():
        print(f"skipped: the walk's files are not in {args.data}")
        return 0
    from fdbench.peers.child import PeerUnavailable, opensim_version

    try:
        opensim_version()  # OpenSim where it runs: a child process
    except PeerUnavailable:
        print("skipped: the opensim package is not installed (pip install '.[opensim]')")
        return 0

    from fdbench.multibody.engine import Engine
    from fdbench.multibody.loads import read_external_loads
    from fdbench.multibody.motions import joint_motion
    from fdbench.multibody.osim import import_osim

    model, _ = import_osim(args.data / "subject01.osim")
    loads = read_external_loads(args.data / "subject01_walk_grf.xml", model)
    engine = Engine(model, loads=loads)
    motion = joint_motion(str(args.data / "subject01_walk_IK.mot"), model, cutoff_hz=args.cutoff)
    names, kinds = model.coordinates, model.coordinate_kinds
    theirs = opensim_inverse(args.data, names, args.cutoff, motion.start_s, motion.start_s + motion.duration)
    start, end = motion.start_s, motion.start_s + motion.duration
    # the recording's clock: the tool's padded storage rebuilds the times with a drift of up to 5e-7 s
    keep = (theirs["t"] >= start - 1e-6) & (theirs["t"] <= end + 1e-6)
    t = np.clip(theirs["t"][keep], start, end)
    z, zd, zdd = motion(t - motion.start_s)
    ours = engine.inverse_dynamics(z, zd, zdd, t)
    tool = np.column_stack([theirs["forces"][name][keep] for name in names])
    filtered = np.stack([theirs["kinematics"][name][keep] for name in names], axis=1)  # (n, J, 3)
    on_theirs = engine.inverse_dynamics(filtered[:, :, 0], filtered[:, :, 1], filtered[:, :, 2], t)
    inside = (t >= t[0] + EDGE_S) & (t <= t[-1] - EDGE_S)
    rate = 1.0 / np.median(np.diff(t))
    matched_hz = opensim_minus_3db_hz(args.cutoff, rate)  # fdbench's filter with OpenSim's -3 dB point
    matched = joint_motion(str(args.data / "subject01_walk_IK.mot"), model, cutoff_hz=matched_hz)
    ours_matched = engine.inverse_dynamics(*matched(t - motion.start_s), t)

    print(f"fdbench {__import__('fdbench').__version__}: the walk's inverse dynamics, fdbench's estimate against "
          f"OpenSim's InverseDynamicsTool, {len(t)} samples at {rate:.0f} Hz, cutoff {args.cutoff:g} Hz")
    print(f"filters' -3 dB points: fdbench {args.cutoff:.2f} Hz (corrected), OpenSim {matched_hz:.2f} Hz "
          f"(3rd order twice, uncorrected: -6 dB at {args.cutoff:g} Hz)")
    header = (f"{'coordinate':18s} {'unit':4s} {'RMS OpenSim':>11s} {'RMS diff':>9s} {'rel %':>6s} {'inner diff':>10s} "
              f"{'rel %':>6s} {'RMS acc diff':>13s} {'same kin. rel':>13s} {f'rel % {matched_hz:.2f} Hz':>14s}")
    print(header)
    print("-" * len(header))
    diff, inner = rms(ours - tool), rms((ours - tool)[inside])
    scale, same = rms(tool), rms(on_theirs - tool)
    acc = rms(zdd - filtered[:, :, 2])
    diff_matched = rms(ours_matched - tool)
    for j, name in enumerate(names):
        unit, acc_unit = ("N", "m/s2") if kinds[j] == "translation" else ("N m", "r/s2")
        print(f"{name:18s} {unit:4s} {scale[j]:11.2f} {diff[j]:9.2f} {100 * diff[j] / scale[j]:6.1f} {inner[j]:10.2f} "
              f"{100 * inner[j] / scale[j]:6.1f} {acc[j]:8.3f} {acc_unit:4s} {same[j] / scale[j]:13.1e} "
              f"{100 * diff_matched[j] / scale[j]:14.1f}")
    base = [names.index(name) for name in ("pelvis_tx", "pelvis_ty", "pelvis_tilt") if name in names]
    if len(base) == 3:
        means = lambda forces: ", ".join(f"{v:.1f}" for v in forces[:, base].mean(axis=0))  # noqa: E731
        print(f"mean residuals FX (N), FY (N), MZ (N m): fdbench {means(ours)}; OpenSim's tool {means(tool)}")
    worst = int(np.argmax(diff / scale))
    print(f"largest relative difference: {names[worst]} ({100 * diff[worst] / scale[worst]:.1f} % of its RMS); "
          f"the pelvis carries the whole body's mass ({sum(b.mass for b in model.bodies):.1f} kg): "
          f"pelvis_tx/ty differ by {diff[1]:.1f} N, {diff[2]:.1f} N RMS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
