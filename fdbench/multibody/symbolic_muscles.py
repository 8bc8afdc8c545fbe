"""The muscles' equations as CasADi SX expressions, for direct collocation: each muscle's length
(m) along its path as a function of the coordinates z, its moment arms -dl/dz, its lengthening
speed dl/dt = (dl/dz) z' (m/s), its force along the path with a rigid tendon (N) and the
muscles' generalised forces sum_m arm_m F_m (N m; N on a translation), and De Groote's activation
dynamics a' = f(e, a) (1/s).

The curves, the rigid-tendon force and the activation dynamics are written once, in
``fdbench.multibody.muscle``: each compiled function's Python source (numba's ``py_func``) is
called here on CasADi symbols, its module's ``math`` swapped for ``SHIM`` (exp, log, sqrt, tanh,
sin, cos, sinh, asinh on numbers or SX) and every compiled function of that module it calls
swapped likewise. A data-dependent ``if`` or ``max`` would raise on a symbol (none of the
functions used here has one). The paths are written here from the model's description: a
polynomial path term by term, a path of points through the bodies' frames of
``symbolic._poses`` (independent of ``muscle_paths``' compiled kernel, which tests compare them
to). ``casadi`` is imported only when a function here is called.
"""

from __future__ import annotations

import functools
import math
import numbers
import sys
import types

import numpy as np

from .model import GROUND, Model
from .muscle import SMOOTHING, TAU_ACT, TAU_DEACT, activation_derivative, rigid_tendon_force
from .muscles import PointPath
from .symbolic import _poses, _rotate


def _casadi():
    from ..casadi_loader import casadi

    return casadi()


def _unary(name: str):
    """math's ``name`` on a number, CasADi's on a symbol."""
    def function(x):
        return getattr(math, name)(x) if isinstance(x, numbers.Real) else getattr(_casadi(), name)(x)
    function.__name__ = name
    return function


SHIM = types.SimpleNamespace(**{name: _unary(name) for name in ("exp", "log", "sqrt", "tanh", "sin", "cos", "sinh",
                                                                "asinh")})


@functools.lru_cache(maxsize=None)
def _module_globals(module_name: str) -> dict:
    """The globals of module ``module_name`` with ``math`` as SHIM and each of its own compiled
    functions as its Python source bound to these globals."""
    source = sys.modules[module_name].__dict__
    swapped = dict(source, math=SHIM)
    for name, value in source.items():
        py = getattr(value, "py_func", None)
        if py is not None and py.__module__ == module_name:
            swapped[name] = types.FunctionType(py.__code__, swapped, py.__name__, py.__defaults__, py.__closure__)
    return swapped


def symbolic(compiled):
    """The compiled (numba) function ``compiled`` as a Python function of CasADi symbols (or numbers)."""
    return _module_globals(compiled.py_func.__module__)[compiled.py_func.__name__]


def path_lengths(ca, model: Model, z):
    """The muscle-tendon lengths (m) of ``model.muscles``, an SX column (M, 1), of the coordinates z
    (SX column (J, 1))."""
    poses = None
    lengths = []
    for muscle in model.muscles:
        path = muscle.path
        if isinstance(path, PointPath):
            if poses is None:
                poses = _poses(ca, model, z)
            points = [_point(ca, model, poses, point) for point in path.points]
            lengths.append(sum((ca.norm_2(b - a) for a, b in zip(points, points[1:])), 0))
        else:
            columns = [model.coordinates.index(name) for name in path.coordinates]
            lengths.append(sum((term.coefficient * _monomial(z, columns, term.powers) for term in path.terms), 0))
    return ca.vertcat(*lengths)


def _monomial(z, columns, powers):
    value = 1
    for column, power in zip(columns, powers):
        if power:
            value = value * z[column] ** power
    return value


def _point(ca, model: Model, poses, point):
    """A path point's position (m, SX column (2, 1)) in ground."""
    if point.body == GROUND:
        return ca.DM(list(point.at))
    body, origin, angle = model.frame(point.body)
    c, s = math.cos(angle), math.sin(angle)
    local = (origin[0] + c * point.at[0] - s * point.at[1], origin[1] + s * point.at[0] + c * point.at[1])
    angles, origins = poses
    k = [joint.child for joint in model.joints].index(body)
    return origins[k] + _rotate(ca, angles[k], local)


@functools.lru_cache(maxsize=16)
def _muscle_functions(model: Model, params_bytes: bytes):
    ca = _casadi()
    J, M = model.n_joints, len(model.muscles)
    params = np.frombuffer(params_bytes).reshape(M, -1)
    z, zd, a, e = ca.SX.sym("z", J), ca.SX.sym("zd", J), ca.SX.sym("a", M), ca.SX.sym("e", M)
    lengths = path_lengths(ca, model, z)
    arms = -ca.jacobian(lengths, z)
    lengthening = ca.jtimes(lengths, z, zd)
    force_of, rate_of = symbolic(rigid_tendon_force), symbolic(activation_derivative)
    force = ca.vertcat(*(force_of(a[m], lengths[m], lengthening[m], params[m]) for m in range(M)))
    rate = ca.vertcat(*(rate_of(e[m], a[m], params[m][TAU_ACT], params[m][TAU_DEACT], params[m][SMOOTHING])
                        for m in range(M)))
    geometry = ca.Function("muscle_geometry", [z, zd], [lengths, arms, lengthening])
    forces = ca.Function("muscle_forces", [z, zd, a], [ca.cse(force), ca.cse(arms.T @ force)])
    return geometry, forces, ca.Function("activation_rate", [e, a], [rate])


def muscle_functions(model: Model, params: np.ndarray):
    """CasADi Functions of ``model``'s muscles with ``params`` (M, len(muscle.PARAMETERS)), the
    engine's ``muscle_params``, built once per model: ``muscle_geometry`` (z, z') -> lengths (M)
    (m), moment arms (M, J) (-dl/dz), lengthening speeds (M) (m/s); ``muscle_forces`` (z, z', a) ->
    forces along the paths with rigid tendons (M) (N), generalised forces arms^T F (J) (N m);
    ``activation_rate`` (e, a) -> a' (M) (1/s)."""
    return _muscle_functions(model, np.ascontiguousarray(params, dtype=float).tobytes())
