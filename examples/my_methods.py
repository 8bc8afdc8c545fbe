"""A plugin module: a torque parameterisation and an optimiser of its own, registered by name.

Named in FDBENCH_PLUGINS and importable (here through PYTHONPATH), it reaches the command line:

    PYTHONPATH=examples FDBENCH_PLUGINS=my_methods fdbench optimize --torque linear --opt random --budget 50
"""

import numpy as np
from fdbench.torques import TORQUES, TorqueParameterisation
from fdbench.optimizers import OPTIMIZERS, Optimizer

@TORQUES.register("linear")
class LinearTorque(TorqueParameterisation):
    summary = "straight line a + b t"
    def __init__(self):
        self.n_params = 2
    def prepare(self, t, target, feedforward):
        return np.zeros(2) if feedforward else np.polyfit(t, target, 1)[::-1]
    def evaluate(self, p, t):
        return p[0] + p[1] * np.asarray(t)

@OPTIMIZERS.register("random")
class RandomSearch(Optimizer):
    summary = "random search around x0, steps of --opt 'random[scale=...]'"
    def __init__(self, scale: float = 0.1):  # its options: the command line passes them by name
        self.scale = scale
    def run(self, f, x0, seed):
        rng = np.random.default_rng(seed)
        while True:                      # the budget wrapper stops it
            f(x0 + self.scale * rng.standard_normal(len(x0)))
