"""Compiled kernels of the torque parameterisations' population evaluators.

Each row of a population is computed by the same scalar code whatever the number of rows, so a
population's torque histories equal, to the last bit, those of its candidates one by one. The
transcendental functions (exp, tanh) stay with numpy, whose vectorised versions are several times
faster than the scalar ones a kernel calls; the kernels do the arithmetic around them in one pass.
"""

from __future__ import annotations

from ..jit import njit


@njit(nogil=True)
def weighted_sums(weights, rows, out):
    """out[c, i] = sum_k weights[c, k] rows[k, i], summed over k = 0, 1, ... in that order.

    weights: shape (lam, K); rows: shape (K, n), shared by every candidate; out: shape (lam, n),
    filled. (The cubic spline: weights the knot values (N m), rows the basis functions.)"""
    for c in range(weights.shape[0]):
        w = weights[c, 0]
        for i in range(rows.shape[1]):
            out[c, i] = w * rows[0, i]
        for k in range(1, weights.shape[1]):
            w = weights[c, k]
            for i in range(rows.shape[1]):
                out[c, i] += w * rows[k, i]


@njit(nogil=True)
def own_weighted_sums(weights, rows, bias, scale, shift, out):
    """out[c, i] = shift + scale (bias[c] + sum_k weights[c, k] rows[c, k, i]), the sum taken over
    k = 0, 1, ... in that order.

    weights: shape (lam, K); rows: shape (lam, K, n), each candidate's own; bias: shape (lam,);
    scale, shift: numbers; out: shape (lam, n), filled. (Gaussian bumps: the amplitudes (N m)
    times the bumps, bias 0, scale 1, shift 0; the network: the output weights times the hidden
    neurons' outputs, bias the output bias, scale and shift the output's mapping to N m.)"""
    for c in range(weights.shape[0]):
        w = weights[c, 0]
        for i in range(rows.shape[2]):
            out[c, i] = bias[c] + w * rows[c, 0, i]
        for k in range(1, weights.shape[1]):
            w = weights[c, k]
            for i in range(rows.shape[2]):
                out[c, i] += w * rows[c, k, i]
        for i in range(rows.shape[2]):
            out[c, i] = shift + scale * out[c, i]


@njit(nogil=True)
def gaussian_exponents(t, amplitude_sharpness_centre, out):
    """out[c, k, i] = -C (t_i - T)^2 for the sharpness C (1/s^2) and centre T (s) of bump k of
    candidate c: parameters of shape (lam, K, 3) ([A, C, T] per bump), times t (s) of shape (n,),
    out of shape (lam, K, n), filled."""
    P = amplitude_sharpness_centre
    for c in range(P.shape[0]):
        for k in range(P.shape[1]):
            sharpness, centre = P[c, k, 1], P[c, k, 2]
            for i in range(t.shape[0]):
                d = t[i] - centre
                out[c, k, i] = -sharpness * (d * d)


@njit(nogil=True)
def affine_rows(x, weights, biases, out):
    """out[c, k, i] = weights[c, k] x[i] + biases[c, k]: the input x (shape (n,)) of every
    neuron k (weights and biases of shape (lam, K)); out of shape (lam, K, n), filled."""
    for c in range(weights.shape[0]):
        for k in range(weights.shape[1]):
            w, b = weights[c, k], biases[c, k]
            for i in range(x.shape[0]):
                out[c, k, i] = w * x[i] + b


def warm_up() -> None:
    """Load (or compile) the kernels, so that later timings exclude it."""
    import numpy as np

    out = np.empty((1, 3))
    weighted_sums(np.ones((1, 2)), np.ones((2, 3)), out)
    rows = np.empty((1, 2, 3))
    gaussian_exponents(np.ones(3), np.ones((1, 2, 3)), rows)
    affine_rows(np.ones(3), np.ones((1, 2)), np.ones((1, 2)), rows)
    own_weighted_sums(np.ones((1, 2)), rows, np.zeros(1), 1.0, 0.0, out)
