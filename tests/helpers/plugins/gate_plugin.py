"""An fdbench plugin ($FDBENCH_PLUGINS=gate_plugin) for the tests that watch or stop a command
midway.

The optimiser ``gated-bfgs`` is BFGS, except that it waits until the file $FDBENCH_GATE exists:
before a run whose seed is at least $FDBENCH_GATE_FROM, or, when $FDBENCH_GATE_AFTER is set,
before that many evaluations into every run. A command started with the gate closed does some
work and then holds still, so a test can look at it or signal it in a known state without timing
anything; creating the file lets everything through. Only subprocesses import this module (the
test process's registry stays as fdbench ships it).
"""

import os
import time

from fdbench.optimizers import OPTIMIZERS
from fdbench.optimizers.scipy_methods import BFGS


def _wait_for_gate() -> None:
    gate = os.environ["FDBENCH_GATE"]
    while not os.path.exists(gate):
        time.sleep(0.01)


class _PausedObjective:
    """The budgeted objective ``f``, waiting for the gate before evaluation number ``after``."""

    def __init__(self, f, after: int):
        self.f, self.after, self.calls = f, after, 0

    def __call__(self, x):
        if self.calls == self.after:
            _wait_for_gate()
        self.calls += 1
        return self.f(x)

    def __getattr__(self, name):
        return getattr(self.f, name)


@OPTIMIZERS.register("gated-bfgs")
class GatedBFGS(BFGS):
    name = "gated-bfgs"
    summary = "BFGS that waits for the file $FDBENCH_GATE (tests)"

    def run(self, f, x0, seed):
        if not os.environ.get("FDBENCH_GATE"):
            return super().run(f, x0, seed)
        if os.environ.get("FDBENCH_GATE_AFTER"):
            return super().run(_PausedObjective(f, int(os.environ["FDBENCH_GATE_AFTER"])), x0, seed)
        if seed >= int(os.environ.get("FDBENCH_GATE_FROM", "0")):
            _wait_for_gate()
        return super().run(f, x0, seed)


from fdbench.controllers import CONTROLLERS  # noqa: E402
from fdbench.controllers.pd import PD  # noqa: E402


@CONTROLLERS.register("marked-pd")
class MarkedPD(PD):
    """PD that creates the file $FDBENCH_MARK once its design is done, just before the simulation:
    a test then knows that the command has reached its long part."""

    name = "marked-pd"
    summary = "PD that creates the file $FDBENCH_MARK before simulating (tests)"

    def design(self, plan):
        design = super().design(plan)
        open(os.environ["FDBENCH_MARK"], "w").close()
        return design


if os.environ.get("FDBENCH_MARK_POPULATION"):
    from fdbench.population import Population  # noqa: E402

    _evaluate = Population.__call__

    def _marked(self, count, args):
        """Population evaluation that first creates the file $FDBENCH_MARK_POPULATION when a
        population of more than one candidate begins (not the warm-up's, of two steps): a test then
        knows that CMA-ES's simulations are under way."""
        if count > 1 and self.n_steps > 2:
            open(os.environ["FDBENCH_MARK_POPULATION"], "w").close()
        return _evaluate(self, count, args)

    Population.__call__ = _marked
