"""Artificial neural network of Figure 3: one hidden layer of tanh neurons, linear output.

Input t in [0, T] s (T the motion's duration, 1 s in the paper) is mapped to [-1, 1] and the output from [-1, 1] to torque (N m) as MATLAB's
fitnet does (mapminmax on the training target). Parameters, 3 n_h + 1 of them:
[w_1 .. w_nh (input weights), b_1 .. b_nh (hidden biases), v_1 .. v_nh (output weights), c].
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..method_options import MethodOption
from .base import TORQUES, TorqueParameterisation, check_count

PRETRAIN_SEED = 0  # the pre-training's restarts are drawn from this fixed seed
PRETRAIN_RESTARTS = 6
AUTO_MAX_HIDDEN = 10
OUTPUT_SCALE = 0.3  # typical magnitude of the output weights and bias (scaled units), see AnnTorque.scale
AUTO_TOLERANCE = 1e-3  # fit RMSE / torque range that counts as good enough for --hidden auto


def network(p: np.ndarray, x: np.ndarray, n_h: int) -> np.ndarray:
    """Network output in scaled units for scaled inputs x (shape (n,))."""
    w, b, v, c = p[:n_h], p[n_h : 2 * n_h], p[2 * n_h : 3 * n_h], p[3 * n_h]
    return np.tanh(np.outer(x, w) + b) @ v + c


def _residual_jacobian(p, x, n_h):
    w, b, v = p[:n_h], p[n_h : 2 * n_h], p[2 * n_h : 3 * n_h]
    h = np.tanh(np.outer(x, w) + b)
    dh = (1 - h**2) * v
    return np.hstack([dh * x[:, None], dh, h, np.ones((len(x), 1))])


def pretrain(x: np.ndarray, y: np.ndarray, n_h: int) -> tuple[np.ndarray, float]:
    """Least-squares fit of the network to scaled targets y at scaled inputs x.

    Returns the best parameters over a few seeded restarts and their RMSE (scaled units) on
    all points; the fit itself uses at most ~200 of them (the torque is smooth)."""
    from scipy.optimize import least_squares

    every = max(1, len(x) // 200)
    xs, ys = x[::every], y[::every]
    rng = np.random.default_rng(PRETRAIN_SEED)
    best, best_cost = None, np.inf
    for _ in range(PRETRAIN_RESTARTS):
        # Nguyen-Widrow-like start: steep enough neurons spread over the input range
        w = rng.uniform(-1, 1, n_h) * 0.7 * n_h + np.sign(rng.uniform(-1, 1, n_h)) * 1.0
        b = -w * rng.uniform(-1, 1, n_h)
        p0 = np.concatenate([w, b, rng.uniform(-0.5, 0.5, n_h), [0.0]])
        fit = least_squares(lambda p: network(p, xs, n_h) - ys, p0,
                            jac=lambda p: _residual_jacobian(p, xs, n_h), method="lm", max_nfev=300)
        if fit.cost < best_cost:
            best, best_cost = fit.x, fit.cost
    return best, float(np.sqrt(np.mean((network(best, x, n_h) - y) ** 2)))


@lru_cache(maxsize=64)
def _pretrain_cached(key: bytes, n_h: int, n: int):
    data = np.frombuffer(key).reshape(2, n)
    return pretrain(data[0], data[1], n_h)


def select_hidden(t, target, max_hidden=AUTO_MAX_HIDDEN, tolerance=AUTO_TOLERANCE):
    """The smallest neuron count whose pre-trained fit has RMSE / range <= tolerance.

    Returns (n_h, [(n, relative fit RMSE), ...] for every count tried)."""
    tried = []
    for n_h in range(1, max_hidden + 1):
        ann = AnnTorque(hidden=n_h)
        ann.prepare(t, target, feedforward=False)
        tried.append((n_h, ann.fit_rmse / 2))  # scaled outputs span 2
        if tried[-1][1] <= tolerance:
            return n_h, tried
    return max_hidden, tried


@TORQUES.register("ann")
class AnnTorque(TorqueParameterisation):
    name = "ann"
    # CMA-ES in the scaling of ``scale``: steps of 0.2 on the hidden layer, 0.06 on the output
    optimizer_defaults = {"cmaes": {"sigma0": 0.2, "popsize": 8}}
    summary = "neural network, one hidden layer of --hidden tanh neurons (default 4), 3N+1 parameters"

    command_line = {"hidden": MethodOption("hidden neurons in [1, 50], or 'auto' to choose the smallest count that "
                                           "fits the inverse-dynamics torque.", str, "4", metavar="<int>|auto")}

    def __init__(self, hidden: int = 4):
        self.hidden = check_count("--hidden", hidden, 1, 50)
        self.n_params = 3 * self.hidden + 1
        self.offset, self.span = 0.0, 1.0
        self.duration = 1.0  # s, set by prepare from the motion's samples
        self.fit_rmse = float("nan")  # of the pre-training, scaled units

    def _scaling(self, target):
        lo, hi = float(np.min(target)), float(np.max(target))
        return (lo + hi) / 2, max((hi - lo) / 2, 1e-9)

    @classmethod
    def warm_up(cls):
        import scipy.optimize  # noqa: F401  (its import is not part of a run's runtime)

        from .kernels import warm_up  # lazy: numba off the CLI's start-up

        warm_up()

    def prepare(self, t, target, feedforward):
        t, target = np.asarray(t, dtype=float), np.asarray(target, dtype=float)
        offset, self.span = self._scaling(target)
        self.duration = float(t[-1]) if len(t) and t[-1] > 0 else 1.0
        x, y = 2 * t / self.duration - 1, (target - offset) / self.span
        p, self.fit_rmse = _pretrain_cached(np.stack([x, y]).tobytes(), self.hidden, len(t))
        p = p.copy()
        if feedforward:
            # zero additional torque, keeping the trained hidden layer so gradients are informative
            self.offset = 0.0
            p[2 * self.hidden :] = 0.0
        else:
            self.offset = offset
        return p

    def evaluate(self, p, t):
        t = np.asarray(t, dtype=float)
        return self.offset + self.span * network(np.asarray(p, dtype=float), 2 * t / self.duration - 1, self.hidden)

    def on_grid_batch(self, t):
        from .kernels import affine_rows, own_weighted_sums  # lazy: numba off the CLI's start-up

        x = np.ascontiguousarray(2 * np.asarray(t, dtype=float) / self.duration - 1)  # scaled input, shape (n,)
        n_h = self.hidden

        def evaluate(P):
            """The neurons' inputs in a kernel, their tanh by numpy, the output layer in a kernel."""
            P = np.ascontiguousarray(P, dtype=float).reshape(len(P), 3 * n_h + 1)
            hidden = np.empty((len(P), n_h, len(x)))
            affine_rows(x, np.ascontiguousarray(P[:, :n_h]), np.ascontiguousarray(P[:, n_h : 2 * n_h]), hidden)
            np.tanh(hidden, out=hidden)
            out = np.empty((len(P), len(x)))
            output_weights = np.ascontiguousarray(P[:, 2 * n_h : 3 * n_h])
            output_bias = np.ascontiguousarray(P[:, 3 * n_h])
            own_weighted_sums(output_weights, hidden, output_bias, float(self.span), float(self.offset), out)
            return out

        return evaluate

    def scale(self):
        """Typical magnitudes: 1 for the hidden layer's weights and biases (scaled input), 0.3 for
        the output weights and bias (scaled output; a change of 0.3 in one output weight moves the
        torque by up to 30% of its half range, so the output layer gets the finer steps)."""
        return np.concatenate([np.ones(2 * self.hidden), np.full(self.hidden + 1, OUTPUT_SCALE)])

    def on_grid_jacobian(self, t):
        x = 2 * np.asarray(t, dtype=float) / self.duration - 1
        n_h = self.hidden
        return lambda p: self.span * _residual_jacobian(np.asarray(p, dtype=float), x, n_h)
