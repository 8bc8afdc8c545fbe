"""An fdbench plugin ($FDBENCH_PLUGINS=gate_plugin) for the tests that stop a sweep midway.

The optimiser ``gated-bfgs`` is BFGS, except that a run whose seed is at least
$FDBENCH_GATE_FROM first waits until the file $FDBENCH_GATE exists. A sweep started with the gate
closed stores its first runs and then holds still with its workers busy, so a test can signal it
in a known state without timing anything; creating the file lets every run through. Only
subprocesses import this module (the test process's registry stays as fdbench ships it).
"""

import os
import time

from fdbench.optimizers import OPTIMIZERS
from fdbench.optimizers.scipy_methods import BFGS


@OPTIMIZERS.register("gated-bfgs")
class GatedBFGS(BFGS):
    name = "gated-bfgs"
    summary = "BFGS whose runs from seed $FDBENCH_GATE_FROM on wait for the file $FDBENCH_GATE (tests)"

    def run(self, f, x0, seed):
        gate = os.environ.get("FDBENCH_GATE")
        if gate and seed >= int(os.environ.get("FDBENCH_GATE_FROM", "0")):
            while not os.path.exists(gate):
                time.sleep(0.01)
        return super().run(f, x0, seed)
