"""CMA-ES (Hansen and Ostermeier 2001) through the ``cma`` package, in an ask/tell loop."""

from __future__ import annotations

import math
import threading

import numpy as np

from ..method_options import MethodOption
from .base import OPTIMIZERS, Budgeted, Optimizer

MAX_POPSIZE = 10_000  # candidates per generation: more than any budget here can feed
# parameters from which cma's own work runs in a thread of its own (``_interruptible``): its single
# numpy operations on the N x N covariance take seconds at 11,000 (a 1000-body model's), ~1 ms at 1000
IN_THREAD_FROM = 1000


def _interruptible(call, *args):
    """call(*args), run in a daemon thread while this one waits: Python acts on Ctrl-C in the main
    thread only, between two operations, so a long numpy operation of cma's would hold it for
    seconds; the abandoned call ends with the process."""
    outcome = {}

    def target():
        try:
            outcome["value"] = call(*args)
        except BaseException as exc:  # noqa: BLE001 - raised again in the caller's thread
            outcome["error"] = exc

    thread = threading.Thread(target=target, name="cma", daemon=True)
    thread.start()
    thread.join()
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]


@OPTIMIZERS.register("cmaes")
class CMAES(Optimizer):
    name = "cmaes"
    summary = "CMA-ES evolution strategy (cma package); --sigma0 initial step, --popsize population"

    command_line = {
        "sigma0": MethodOption("initial step size, in scaled parameter units (default: per torque, cs 0.05, ann 0.2, "
                               "pf 0.03).", show_default=False),
        "popsize": MethodOption("population size, in [2, 10000] (default: per torque, cs and ann 8, pf cma's 4 + 3 ln "
                                "n).", int),
    }

    def __init__(self, sigma0: float = 0.1, popsize: int | None = None):
        if not (math.isfinite(sigma0) and sigma0 > 0):
            raise ValueError(f"--sigma0 must be a positive finite number, got {sigma0}")
        if popsize is not None and not 2 <= popsize <= MAX_POPSIZE:
            raise ValueError(f"--popsize must be an integer in [2, {MAX_POPSIZE}], got {popsize}")
        self.sigma0, self.popsize = sigma0, popsize

    def warm_up(self):
        import cma  # noqa: F401

    def run(self, f: Budgeted, x0, seed):
        import cma  # ~2 s to import: only here

        # no signals file: cma would otherwise look for one in the working folder every generation
        options = {"seed": seed + 1, "verbose": -9, "verb_log": 0, "verb_disp": 0, "maxfevals": f.budget,
                   "signals_filename": ""}
        if self.popsize:
            options["popsize"] = self.popsize
            if self.popsize == 2:  # two-point step-size adaptation needs room for its own two samples
                options["AdaptSigma"] = cma.sigma_adaptation.CMAAdaptSigmaCSA

        def cma_work(call, *args):
            return _interruptible(call, *args) if len(x0) >= IN_THREAD_FROM else call(*args)

        es = cma_work(cma.CMAEvolutionStrategy, np.asarray(x0, dtype=float), self.sigma0, options)
        try:
            while not cma_work(es.stop):
                candidates = cma_work(es.ask)
                if f.remaining < len(candidates):
                    f.many(candidates)  # the budget's last evaluations
                    break
                cma_work(es.tell, candidates, f.many(candidates))  # one generation, in one call where batched
        except ValueError as exc:  # cma refusing its own state: the best point so far is the result
            return f"cma stopped: {' '.join(str(exc).split())}"
        stop = cma_work(es.stop)
        return ", ".join(f"{k} {v}" for k, v in stop.items()) if stop else "budget spent"
