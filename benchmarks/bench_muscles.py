"""Muscle-driven forward simulation of OpenSim's arm26 (six muscles): fdbench against OpenSim's own
forward simulation of examples/opensim/arm26.osim, measured in the same run.

The model: the library's arm26 (its muscle paths polynomials fitted to OpenSim's) with rigid
tendons; OpenSim's arm26.osim after ``DeGrooteFregly2016Muscle.replaceMuscles`` with
ignore_tendon_compliance, a PrescribedController of the same excitations (piecewise linear, EXCITATIONS),
from the same start (Z0, at rest, each activation at its excitation). OpenSim runs in a child
process (one Manager, one integrate, as its users run it); fdbench runs the compiled RK4 kernel
(``Engine.simulate`` with the excitations on its half-step grid), warmed up before its clock.

Printed:
1. Agreement over 0.5 s (OpenSim at integrator accuracy 1e-7, fdbench RK4 dt 1e-4 s): the largest
   coordinate difference (deg) and, to tell where it comes from, (a) the same for the bare
   mechanics (muscles removed, the arm falling from Z0 for 0.5 s), (b) the fitted paths' length
   (mm) and moment-arm (mm) errors at OpenSim's states along its run, (c) the tendon forces' difference.
2. Speed: one second of simulation, fdbench's kernel (dt 1 ms: 1000 RK4 steps) and its
   ``simulate`` (the CLI's call: excitations sampled, forces after) against OpenSim's integrate
   (accuracy 1e-7 and its default 1e-5; the integrate alone timed, best of ROUNDS); goal: 50x.
   Also at matched accuracy: OpenSim's error at 1 s (its coordinates against its own run at accuracy
   1e-10) and fdbench's (against its run at dt 1e-5 s); fdbench timed at the largest of DTS whose
   error is at most OpenSim's.
3. The cost of one RK4 step of arm26 with muscles against arm26 without them (torque-driven, zero
   torque) and against arm2 (the library's two-link arm), kernel alone, best of ROUNDS x CALLS.

Run: python benchmarks/bench_muscles.py  (needs the opensim package for 1 and 2's OpenSim side)
"""

from __future__ import annotations

import importlib.util
import json
import pathlib
import subprocess
import sys

import numpy as np

from fdbench.models import find_model
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.muscle_paths import muscle_geometry
from fdbench.multibody.simulation import muscle_start
from timing import best_of

ROUNDS, CALLS = 5, 10
OSIM = pathlib.Path(__file__).resolve().parents[1] / "examples" / "opensim" / "arm26.osim"
COORDINATES = ("r_shoulder_elev", "r_elbow_flex")
Z0 = np.array([0.2, 1.2])  # rad: the shoulder raised, the elbow flexed; at rest
TIMES = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]  # s: the excitations' samples, linear between them
TRICEPS, FLEXORS = [0.03, 0.06, 0.02, 0.06, 0.03, 0.06], [0.09, 0.13, 0.09, 0.13, 0.09, 0.13]
EXCITATIONS = {"TRIlong": TRICEPS, "TRIlat": TRICEPS, "TRImed": TRICEPS,  # the joints kept in their ranges
               "BIClong": FLEXORS, "BICshort": FLEXORS, "BRA": FLEXORS}
SAMPLES = [round(0.01 * k, 10) for k in range(51)]  # s: the compared samples (0.5 s)
DTS = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2)  # s: fdbench's candidate steps at matched accuracy
REFERENCE_DT, REFERENCE_ACCURACY = 1e-5, 1e-10  # the two sides' own reference runs (OpenSim at 1e-9 ends 0.01 deg
# off its runs at 1e-5 to 1e-10, which agree within 2e-4 deg: its run at 1e-9 is the odd one)

OPENSIM_ARM26 = """
import json, sys, time
import opensim as osim
osim.Logger.setLevelString("Off")
request = json.loads(sys.stdin.read())


def arm(muscles):
    model = osim.Model(request["path"])
    if muscles:
        osim.DeGrooteFregly2016Muscle.replaceMuscles(model)
        controller = osim.PrescribedController()
        for k in range(model.getMuscles().getSize()):
            muscle = osim.DeGrooteFregly2016Muscle.safeDownCast(model.getMuscles().get(k))
            muscle.set_ignore_tendon_compliance(True)
            controller.addActuator(muscle)
            history = osim.PiecewiseLinearFunction()
            for t, value in zip(request["times"], request["excitations"][muscle.getName()]):
                history.addPoint(t, value)
            controller.prescribeControlForActuator(muscle.getName(), history)
        model.addController(controller)
    else:
        model.updForceSet().clearAndDestroy()
    state = model.initSystem()
    coordinates = [model.getCoordinateSet().get(name) for name in request["coordinates"]]
    for coordinate, angle in zip(coordinates, request["z0"]):
        coordinate.setValue(state, angle, False)
        coordinate.setSpeedValue(state, 0.0)
    names = list(request["excitations"]) if muscles else []
    found = [osim.DeGrooteFregly2016Muscle.safeDownCast(model.getMuscles().get(name)) for name in names]
    for muscle, name in zip(found, names):
        muscle.setActivation(state, request["excitations"][name][0])
    return model, state, coordinates, found


def run(muscles):
    model, state, coordinates, found = arm(muscles)
    manager = osim.Manager(model)
    manager.setIntegratorAccuracy(1e-7)
    manager.initialize(state)
    out = []
    for t in request["samples"]:
        if t > 0:
            state = manager.integrate(t)
        model.realizeDynamics(state)
        out.append({"z": [c.getValue(state) for c in coordinates],
                    "force": [m.getTendonForce(state) for m in found],
                    "length": [m.getLength(state) for m in found],
                    "arms": [[m.computeMomentArm(state, c) for c in coordinates] for m in found]})
    return out


def seconds(accuracy, rounds):
    best = float("inf")
    for _ in range(rounds):
        model, state, coordinates, _ = arm(True)
        manager = osim.Manager(model)
        manager.setIntegratorAccuracy(accuracy)
        manager.initialize(state)
        began = time.perf_counter()
        state = manager.integrate(1.0)
        best = min(best, time.perf_counter() - began)
    return best, [c.getValue(state) for c in coordinates]


print(json.dumps({"muscles": run(True), "bare": run(False),
                  "seconds": {str(a): seconds(a, request["rounds"]) for a in request["accuracies"]},
                  "reference": seconds(request["reference"], 1)[1]}))
"""


def arm26(muscles: bool = True) -> Engine:
    """The library's arm26 with rigid tendons (muscles) or without its muscles."""
    data = to_dict(find_model("arm26"))
    for muscle in data["muscles"]:
        muscle["tendon"] = "rigid"
    if not muscles:
        del data["muscles"]
    return Engine(model_from_dict(data, "arm26.toml"))


def excitation_half(engine: Engine, dt: float, n: int) -> np.ndarray:
    """The excitations on the half-step grid of n steps of dt (s), shape (2 n + 1, M)."""
    t = np.arange(2 * n + 1) * (0.5 * dt)
    return np.stack([np.interp(t, TIMES, EXCITATIONS[m.name]) for m in engine.model.muscles], axis=-1)


def run_kernel(engine: Engine, dt: float, n: int, muscles: bool = True):
    """A function of no argument: n RK4 steps of dt (s) from Z0 at rest, no torque (the muscles
    excited, or none); the result."""
    zero = np.zeros((2 * n + 1, engine.n_joints))
    y0 = engine.state_from_joints(Z0, np.zeros(engine.n_joints))
    if not muscles:
        return lambda: engine.simulate(y0, dt, n, zero, zero, zero, zero, 0.0, 0.0)
    excited = excitation_half(engine, dt, n)
    y0 = np.concatenate([y0, muscle_start(engine, y0, excited[0])])
    return lambda: engine.simulate(y0, dt, n, zero, zero, zero, zero, 0.0, 0.0, excitation_half=excited)


def sampled(result, dt: float, engine: Engine) -> np.ndarray:
    """The coordinates (rad) at SAMPLES of a run of step dt, shape (51, J)."""
    rows = np.rint(np.array(SAMPLES) / dt).astype(int)
    return np.array([engine.joints_from_state(result.states[k, :engine.n_state])[0] for k in rows])


def opensim(accuracies=(1e-7, 1e-5)) -> dict | None:
    """OpenSim's runs and timings (the child's answer), or None without the opensim package."""
    if importlib.util.find_spec("opensim") is None:
        return None
    request = {"path": str(OSIM), "coordinates": COORDINATES, "z0": Z0.tolist(), "times": TIMES,
               "excitations": EXCITATIONS, "samples": SAMPLES, "rounds": ROUNDS, "accuracies": list(accuracies),
               "reference": REFERENCE_ACCURACY}
    done = subprocess.run([sys.executable, "-c", OPENSIM_ARM26], input=json.dumps(request), capture_output=True,
                          text=True, timeout=1800)
    if done.returncode != 0:
        raise RuntimeError(done.stderr.strip().splitlines()[-1] if done.stderr.strip() else "OpenSim failed")
    return json.loads(done.stdout.strip().splitlines()[-1])


def agreement(theirs: dict) -> None:
    muscled, bare = arm26(), arm26(muscles=False)
    dt, n = 1e-4, 5000
    ours = run_kernel(muscled, dt, n)()
    z = sampled(ours, dt, muscled)
    their_z = np.array([s["z"] for s in theirs["muscles"]])
    moved = np.degrees(np.abs(their_z - Z0).max())
    print(f"arm26 over 0.5 s (OpenSim accuracy 1e-7, fdbench RK4 dt 1e-4 s): OpenSim moves the joints by up to "
          f"{moved:.1f} deg")
    for j, name in enumerate(COORDINATES):
        print(f"  {name}: largest difference {np.degrees(np.abs(z[:, j] - their_z[:, j]).max()):.3g} deg, "
              f"at 0.5 s {np.degrees(z[-1, j] - their_z[-1, j]):+.3g} deg")
    for dt_coarse in (1e-3,):
        coarse = sampled(run_kernel(muscled, dt_coarse, round(0.5 / dt_coarse))(), dt_coarse, muscled)
        print(f"  fdbench dt {dt_coarse:g} s against dt 1e-4 s: {np.degrees(np.abs(coarse - z).max()):.2g} deg")
    bare_z = sampled(run_kernel(bare, dt, n, muscles=False)(), dt, bare)
    their_bare = np.array([s["z"] for s in theirs["bare"]])
    print(f"  (a) the bare mechanics (muscles removed, falling from Z0): largest difference "
          f"{np.degrees(np.abs(bare_z - their_bare).max()):.3g} deg of a {np.degrees(np.abs(their_bare - Z0).max()):.0f}"
          f" deg fall")
    lengths, arms = muscle_geometry(muscled.model, their_z)
    their_lengths = np.array([s["length"] for s in theirs["muscles"]])
    their_arms = np.array([s["arms"] for s in theirs["muscles"]])
    names = [m.name for m in muscled.model.muscles]
    length_error = np.abs(lengths - their_lengths).max(axis=0) * 1e3
    arm_error = np.abs(arms - their_arms).max(axis=(0, 2)) * 1e3
    print("  (b) fitted paths at OpenSim's states along its run, worst length error (mm) / moment-arm error (mm): "
          + ", ".join(f"{name} {le:.3g}/{ae:.3g}" for name, le, ae in zip(names, length_error, arm_error)))
    force = np.array([s["force"] for s in theirs["muscles"]])
    rows = np.rint(np.array(SAMPLES) / dt).astype(int)
    from fdbench.multibody.simulation import muscle_forces  # after the runs: numpy paths

    states = ours.states[rows]
    zs = np.array([muscled.joints_from_state(s[:muscled.n_state]) for s in states])
    our_force = muscle_forces(muscled, zs[:, 0], zs[:, 1], states[:, muscled.n_state:])
    print(f"  (c) tendon forces: largest difference {np.abs(our_force - force).max():.3g} N of up to "
          f"{np.abs(force).max():.0f} N")


def end_error(engine: Engine, dt: float, reference: np.ndarray) -> float:
    """The largest difference (deg) of the coordinates at 1 s of a run of step dt from reference (rad);
    inf if the run fails."""
    result = run_kernel(engine, dt, round(1.0 / dt))()
    if result.status != 0:
        return np.inf
    return float(np.degrees(np.abs(engine.joints_from_state(result.states[-1, :engine.n_state])[0] - reference)).max())


def speed(theirs: dict | None) -> None:
    from fdbench.multibody.simulation import simulate

    muscled = arm26()
    one_second = run_kernel(muscled, 1e-3, 1000)
    one_second()  # warmed up: compiled (or loaded) before the clock
    kernel = best_of(one_second, ROUNDS, CALLS)

    class Rest:
        name, duration, joints, samples = "rest", 1.0, COORDINATES, np.linspace(0.0, 1.0, 101)

        def __call__(self, t):
            shape = np.shape(t) + (2,)
            return np.broadcast_to(Z0, shape).copy(), np.zeros(shape), np.zeros(shape)

    def excitation(t):
        return np.stack([np.interp(t, TIMES, EXCITATIONS[m.name]) for m in muscled.model.muscles], axis=-1)

    def whole():
        return simulate(None, muscled, Rest(), dt=1e-3, excitation=excitation)

    whole()
    call = best_of(whole, ROUNDS, CALLS)
    print(f"one second of arm26 driven by its six muscles: fdbench's kernel (RK4, dt 1 ms) {kernel * 1e3:.2f} ms, "
          f"its simulate (the CLI's call) {call * 1e3:.2f} ms")
    fine = run_kernel(muscled, REFERENCE_DT, round(1.0 / REFERENCE_DT))().states[-1, :muscled.n_state]
    errors = {dt: end_error(muscled, dt, muscled.joints_from_state(fine)[0]) for dt in DTS}
    print(f"  fdbench's error at 1 s (against dt {REFERENCE_DT:g} s), deg: "
          + ", ".join(f"dt {dt:g} s {error:.2g}" for dt, error in errors.items()))
    if theirs is not None:
        reference = np.array(theirs["reference"])
        for accuracy, (seconds, end) in sorted(theirs["seconds"].items(), key=lambda item: -float(item[0])):
            their_error = float(np.degrees(np.abs(np.array(end) - reference)).max())
            matched = max([dt for dt, error in errors.items() if error <= their_error], default=min(DTS))
            run = run_kernel(muscled, matched, round(1.0 / matched))
            run()
            at_matched = best_of(run, ROUNDS, CALLS)
            print(f"  OpenSim's integrate (accuracy {float(accuracy):g}) {seconds * 1e3:.1f} ms, error at 1 s "
                  f"{their_error:.2g} deg (against accuracy {REFERENCE_ACCURACY:g}); fdbench's kernel at dt 1 ms "
                  f"{seconds / kernel:.0f}x faster (its simulate {seconds / call:.0f}x); at matched accuracy (dt "
                  f"{matched:g} s, error {errors[matched]:.2g} deg) {at_matched * 1e3:.2f} ms, "
                  f"{seconds / at_matched:.0f}x faster (goal: 50x)")
    per_step = {}
    for label, engine, muscles in (("arm26 with its six muscles", muscled, True),
                                   ("arm26 without muscles (torque-driven)", arm26(False), False),
                                   ("arm2", Engine(find_model("arm2")), False)):
        fn = run_kernel(engine, 1e-3, 1000, muscles)
        fn()
        per_step[label] = best_of(fn, ROUNDS, CALLS) / 1000
    base = per_step["arm26 with its six muscles"]
    for label, seconds in per_step.items():
        print(f"  one RK4 step, {label}: {seconds * 1e6:.2f} us" + (
            "" if seconds == base else f" (the muscles' step {base / seconds:.1f}x)"))


def main() -> None:
    theirs = opensim()
    if theirs is None:
        print("OpenSim is not installed: fdbench's side only")
    else:
        agreement(theirs)
    speed(theirs)


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
