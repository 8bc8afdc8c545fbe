"""The cost of one RK4 step of the exact sensitivities with muscle states on the library's arm26
(six muscles, polynomial paths, compliant tendons as in the library, and all rigid), against the
same kernel without muscles (arm26's mechanics under torques: the torque-driven gradient), with
the same number of parameters P, and against the plain RK4 (no sensitivities, ``Engine.simulate``)
with and without muscles. Compiled before the clock, best of ROUNDS x CALLS; the ratios are within
one run on the same machine.

Run: python benchmarks/bench_muscle_sensitivity.py [--steps N] [--params P]
"""

from __future__ import annotations

import argparse

import numpy as np

from fdbench.models import find_model
from fdbench.multibody import kernels
from fdbench.multibody.engine import Engine
from fdbench.multibody.model import model_from_dict, to_dict
from fdbench.multibody.simulation import muscle_start
from timing import best_of

ROUNDS, CALLS = 5, 5
Z0, ZD0 = np.array([0.3, 0.8]), np.array([0.2, -0.5])  # rad, rad/s


def arm26(tendon: str | None) -> Engine:
    data = to_dict(find_model("arm26"))
    for m in data["muscles"]:
        m["tendon"] = tendon or m.get("tendon", "rigid")
    return Engine(model_from_dict(data, "arm26.toml"))


def costs(engine: Engine, n: int, P: int, dt: float = 1e-3) -> dict:
    """Seconds per RK4 step: sensitivities with and without muscles, plain RK4 with and without."""
    J, M, rows = engine.n_joints, engine.n_muscles, 2 * n + 1
    t = np.arange(rows) * (0.5 * dt)
    excitation = 0.2 + 0.3 * np.sin(5.0 * np.outer(t, np.arange(1, M + 1))) ** 2
    zero, G = np.zeros((rows, J)), np.cos(np.outer(t, np.arange(1, P + 1)))
    y_mech = engine.state_from_joints(Z0, ZD0)
    y_full = np.concatenate([y_mech, muscle_start(engine, y_mech, excitation[0])])
    muscles = engine.muscles_at(excitation)
    out = {}
    for name, y0, cols, excited in (("without", y_mech, np.arange(P) % J, None),
                                    ("with", y_full, J + np.arange(P) % M, muscles)):
        w = y0.shape[0]
        buffers = (np.empty((n + 1, w)), np.empty((n + 1, w)), np.empty((n + 1, J)), np.empty((n + 1, J, P)))
        cols = cols.astype(np.int64)

        def run(y0=y0, cols=cols, excited=excited, buffers=buffers):
            kernels.rk4_sensitivity(y0, dt, n, zero, zero, zero, G, cols, 1, *engine.kernel_args(), None, *buffers,
                                    excited)
        run()
        out[f"sensitivity {name} muscles"] = best_of(run, ROUNDS, CALLS) / n
    def rk4():  # Engine.simulate: the compiled RK4 as every command calls it
        engine.simulate(y_mech, dt, n, zero, zero, zero, zero, 0.0, 0.0)

    def rk4_muscles():
        engine.simulate(y_full, dt, n, zero, zero, zero, zero, 0.0, 0.0, excitation_half=excitation)
    for name, fn in (("rk4 without muscles", rk4), ("rk4 with muscles", rk4_muscles)):
        fn()
        out[name] = best_of(fn, ROUNDS, CALLS) / n
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=1000, help="RK4 steps per call (dt 1 ms)")
    parser.add_argument("--params", type=int, default=12, help="parameters P (the sensitivities' columns)")
    options = parser.parse_args()
    for tendon in (None, "rigid"):
        c = costs(arm26(tendon), options.steps, options.params)
        label = "compliant (library)" if tendon is None else tendon
        print(f"arm26, {label} tendons, P = {options.params}, per RK4 step:")
        for name, seconds in c.items():
            print(f"  {name:32s} {seconds * 1e6:8.2f} us")
        print(f"  sensitivity with / without muscles: {c['sensitivity with muscles'] / c['sensitivity without muscles']:.2f}x;"
              f" with muscles, sensitivity / rk4: {c['sensitivity with muscles'] / c['rk4 with muscles']:.2f}x;"
              f" rk4 with / without muscles: {c['rk4 with muscles'] / c['rk4 without muscles']:.2f}x")


if __name__ == "__main__":
    main()
