"""An fdbench plugin ($FDBENCH_PLUGINS=option_plugin) with an option of its own: the optimiser
``coordinate-search`` steps each parameter by +-``step`` in turn, halving the step when no move
helps. It exists to show that a plugin is one file and receives its options from the command line
(``--opt 'coordinate-search[step=0.5]'``)."""

import math

from fdbench.optimizers import OPTIMIZERS
from fdbench.optimizers.base import Optimizer


@OPTIMIZERS.register("coordinate-search")
class CoordinateSearch(Optimizer):
    name = "coordinate-search"
    summary = "coordinate search with a halving step (tests); option step"

    def __init__(self, step: float = 0.1):
        if not (math.isfinite(step) and step > 0):
            raise ValueError(f"step must be a positive finite number, got {step}")
        self.step = step

    def run(self, f, x0, seed):
        x, best, step = x0.copy(), f(x0), self.step
        while True:
            moved = False
            for i in range(len(x)):
                for sign in (1.0, -1.0):
                    trial = x.copy()
                    trial[i] += sign * step
                    value = f(trial)
                    if value < best:
                        x, best, moved = trial, value, True
                        break
            if not moved:
                step /= 2
