"""Runtime of one PD simulation (the controller's gains per joint plus the inverse-dynamics
feedforward, each model's default motion: the forearm's paper motion, arm2's reach) by the
engine's compiled RK4 (dt = 1 ms) against scipy's ``solve_ivp`` (DOP853 and RK45, rtol 1e-6,
atol 1e-9) on the same problem: ``fdbench.multibody.simulation.simulate`` with integrator rk4,
dop853 and rk45 (the adaptive methods call the engine's compiled right-hand side once per
evaluation from Python). Plus ``run(control_spec())`` end to end (inverse dynamics, the
controller's design, the simulation). Each figure is the best of several rounds after a warm-up.

Run: python benchmarks/bench_simulation.py
"""

from __future__ import annotations

import platform
import time

import numpy as np
import scipy

import fdbench
from fdbench.api import run
from fdbench.spec import control_spec
from fdbench.multibody import simulation as sim
from kernel_call import model_and_motion
from timing import best_of

MODELS = ("forearm", "arm2")
INTEGRATORS = (("rk4", 7, 20), ("dop853", 3, 1), ("rk45", 3, 1))  # (integrator, rounds, calls per round)
RTOL, ATOL = 1e-6, 1e-9


def pd_gains(engine, model_name: str, motion):
    """The PD controller's gains per joint (N m/rad, N m s/rad), shape (J,) each: the forearm's
    80 and 0.3, scaled for other models (``controllers.pd.PD``)."""
    from fdbench.controllers.base import Plan
    from fdbench.controllers.pd import PD
    from fdbench.models import description

    return PD().gains(Plan(engine, description(model_name), motion))


def main() -> None:
    start = time.perf_counter()
    print(f"fdbench {fdbench.__version__}, numpy {np.__version__}, scipy {scipy.__version__}, "
          f"python {platform.python_version()}, {platform.machine()}")
    print(f"PD with feedforward, t in [0, duration], adaptive methods at rtol {RTOL:g}, atol {ATOL:g} "
          "(best of several rounds)")
    sim.warm_up(adaptive=True)
    for name in MODELS:
        engine, motion = model_and_motion(name)
        kp, kd = pd_gains(engine, name, motion)
        ff = sim.feedforward(engine, motion)
        desired = sim.inverse_dynamics(None, engine, motion).angles
        print(f"{name} ({motion.name} motion, {engine.n_joints} joint(s), kp {np.round(kp, 3)}, kd {np.round(kd, 4)}):")
        times = {}
        for integrator, rounds, calls in INTEGRATORS:
            def simulate():
                return sim.simulate(ff, engine, motion, kp, kd, integrator=integrator, rtol=RTOL, atol=ATOL)

            result = simulate()
            times[integrator] = best_of(simulate, rounds, calls)
            evaluations = result.rhs_evaluations or 4 * round(motion.duration / 1e-3)
            print(f"  {integrator:<7}{times[integrator] * 1e3:9.3f} ms  {times[integrator] / times['rk4']:7.1f} x rk4"
                  f"   rmse_rot_deg {sim.rmse_deg(result, desired)[0]:.6g}  ({evaluations} rhs evaluations, "
                  f"{result.status.name})")
        spec = control_spec(model_name=name)
        run(spec)
        one_shot = min(run(spec).record["runtime_s"] for _ in range(7))
        print(f"  run(control_spec()) end to end: {one_shot * 1e3:.3f} ms")
    print(f"total benchmark time: {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
