"""Numerical checks the tests share."""

import numpy as np


def richardson(f, x, h=1e-3):
    """Central differences with one Richardson extrapolation (error O(h^4)), shape (n,)."""
    def cd(step):
        return np.array([(f(x + step * e) - f(x - step * e)) / (2 * step) for e in np.eye(len(x))])
    return (4 * cd(h / 2) - cd(h)) / 3
