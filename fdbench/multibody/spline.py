"""The interpolating cubic spline OpenSim evaluates for a ``SimmSpline`` (the knee's path), so that a
joint path read from an OpenSim model moves exactly as OpenSim moves it.

The spline is Forsythe, Malcolm and Moler's (Computer Methods for Mathematical Computations, 1977,
routine SPLINE): a C2 cubic through the samples (x_i, y_i) whose third derivative at each end
equals that of the cubic through the four samples nearest that end (with three samples, zero
third derivative at the ends; with two, a line). Outside [x_0, x_(n-1)] it is continued by the
line of its end slope, as OpenSim's ``SimmSpline.calcValue`` is (so the second derivative is 0
there). Each piece is y_i + b_i u + c_i u^2 + d_i u^3, u = x - x_i.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Spline:
    """Knots x (n,) strictly increasing and the pieces' coefficients y, b, c, d (n,) each."""

    x: np.ndarray
    y: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray

    def evaluate(self, value, order: int = 0):
        """The spline's value (order 0), first (1) or second (2) derivative at ``value`` (any shape)."""
        t = np.asarray(value, dtype=float)
        below, above = t < self.x[0], t > self.x[-1]
        k = np.clip(np.searchsorted(self.x, t, side="right") - 1, 0, len(self.x) - 2)
        u = t - self.x[k]
        y, b, c, d = self.y[k], self.b[k], self.c[k], self.d[k]
        if order == 0:
            inside = y + u * (b + u * (c + u * d))
            return np.where(below, self.y[0] + (t - self.x[0]) * self.b[0],
                            np.where(above, self.y[-1] + (t - self.x[-1]) * self.b[-1], inside))
        if order == 1:
            inside = b + u * (2.0 * c + 3.0 * u * d)
            return np.where(below, self.b[0], np.where(above, self.b[-1], inside))
        if order == 2:
            return np.where(below | above, 0.0, 2.0 * c + 6.0 * u * d)
        raise ValueError(f"order must be 0, 1 or 2, got {order}")

    def at(self, t: float) -> tuple[float, float, float]:
        """(value, first, second derivative) at the number t: ``evaluate``'s three orders, for one
        number at a time (no arrays: the fast path of a simulation's stage)."""
        knots = self._knots()
        x, y, b, c, d = knots
        if t < x[0]:
            return y[0] + (t - x[0]) * b[0], b[0], 0.0
        if t > x[-1]:
            return y[-1] + (t - x[-1]) * b[-1], b[-1], 0.0
        k = min(bisect.bisect_right(x, t) - 1, len(x) - 2)
        u = t - x[k]
        return (y[k] + u * (b[k] + u * (c[k] + u * d[k])), b[k] + u * (2.0 * c[k] + 3.0 * u * d[k]),
                2.0 * c[k] + 6.0 * u * d[k])

    def _knots(self):
        """The arrays as lists of floats, made once."""
        cached = self.__dict__.get("_lists")
        if cached is None:
            cached = tuple(a.tolist() for a in (self.x, self.y, self.b, self.c, self.d))
            object.__setattr__(self, "_lists", cached)
        return cached

    def pieces(self):
        """(x_k, y_k, b_k, c_k, d_k) of the interior pieces, k = 0 .. n-2, as plain floats."""
        return [tuple(float(a[k]) for a in (self.x, self.y, self.b, self.c, self.d)) for k in range(len(self.x) - 1)]


def fit(x, y) -> Spline:
    """The spline through the samples (x, y), x strictly increasing, at least two samples."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = len(x)
    if n < 2 or y.shape != x.shape or not np.all(np.diff(x) > 0):
        raise ValueError("a spline needs at least two samples with strictly increasing x")
    if n == 2:
        slope = (y[1] - y[0]) / (x[1] - x[0])
        return Spline(x, y, np.full(2, slope), np.zeros(2), np.zeros(2))
    h = np.diff(x)  # the intervals
    slopes = np.diff(y) / h
    # the tridiagonal system for sigma_i (a third of the second derivative halved: c_i / 3 below)
    diag, rhs = np.empty(n), np.empty(n)
    diag[1:-1] = 2.0 * (h[:-1] + h[1:])
    rhs[1:-1] = slopes[1:] - slopes[:-1]
    diag[0], diag[-1] = -h[0], -h[-1]
    rhs[0] = rhs[-1] = 0.0
    if n > 3:  # end third derivatives from the divided differences of the four end samples
        rhs[0] = (rhs[2] / (x[3] - x[1]) - rhs[1] / (x[2] - x[0])) * h[0] ** 2 / (x[3] - x[0])
        rhs[-1] = -(rhs[-2] / (x[-1] - x[-3]) - rhs[-3] / (x[-2] - x[-4])) * h[-1] ** 2 / (x[-1] - x[-4])
    for i in range(1, n):  # elimination (off-diagonal h_(i-1))
        t = h[i - 1] / diag[i - 1]
        diag[i] -= t * h[i - 1]
        rhs[i] -= t * rhs[i - 1]
    sigma = np.empty(n)
    sigma[-1] = rhs[-1] / diag[-1]
    for i in range(n - 2, -1, -1):
        sigma[i] = (rhs[i] - h[i] * sigma[i + 1]) / diag[i]
    b, c, d = np.empty(n), 3.0 * sigma, np.empty(n)
    b[:-1] = slopes - h * (sigma[1:] + 2.0 * sigma[:-1])
    b[-1] = slopes[-1] + h[-1] * (sigma[-2] + 2.0 * sigma[-1])
    d[:-1] = (sigma[1:] - sigma[:-1]) / h
    d[-1] = d[-2]
    return Spline(x, y, b, c, d)


def casadi_value(ca, spline: Spline, t):
    """The spline at the CasADi scalar t (SX or MX), with its linear continuation outside the knots."""
    x0, xn = float(spline.x[0]), float(spline.x[-1])
    value = float(spline.y[0]) + (t - x0) * float(spline.b[0])
    for xk, yk, bk, ck, dk in spline.pieces():
        u = t - xk
        value = ca.if_else(t >= xk, yk + u * (bk + u * (ck + u * dk)), value)
    return ca.if_else(t > xn, float(spline.y[-1]) + (t - xn) * float(spline.b[-1]), value)
