"""A model's muscles (``fdbench.multibody.muscles``) as OpenSim model XML, for ``osim.to_osim``: each
a ``DeGrooteFregly2016Muscle`` with the same constants (the inverse of ``osim_muscles._parameters``'
mapping), a path of points as a ``GeometryPath`` of ``PathPoint``s on the bodies (ground included;
a named frame's point carried into its body's frame), a polynomial path as a ``FunctionBasedPath``
whose length is a ``MultivariatePolynomialFunction`` of its coordinates (its moment arms OpenSim's
derivatives of it). No OpenSim needed.

OpenSim's MultivariatePolynomialFunction of dimension D and order N (the largest total degree) has
one coefficient per monomial of total degree <= N, ordered by the first coordinate's power, then
the second's, ..., the last's innermost, each ascending from 0: for D = 2, N = 2 the monomials
1, y, y^2, x, x y, x^2. fdbench's terms go to their places; the others are 0.
"""

from __future__ import annotations

from math import comb

from .model import GROUND, ModelError
from .muscles import PointPath

MAX_COEFFICIENTS = 100_000  # a polynomial path's dense coefficients in the file (arm26's largest: 120)


def numbers(*values) -> str:
    """Floats as OpenSim reads them back exactly (shortest round-trip digits)."""
    return " ".join(repr(float(value)) for value in values)


def frame_path(body: str) -> str:
    """OpenSim's path of a body's frame or ground's."""
    return "/ground" if body == GROUND else f"/bodyset/{body}"


def coordinate_path(coordinate: str) -> str:
    """The exported pin's coordinate (``osim._osim_joint``: joint '<name>_joint', coordinate '<name>')."""
    return f"/jointset/{coordinate}_joint/{coordinate}"


def check_muscles(model) -> None:
    """ModelError (one line) for a polynomial path whose OpenSim form would have more than
    MAX_COEFFICIENTS coefficients."""
    for muscle in model.muscles:
        if not isinstance(muscle.path, PointPath):
            count = comb(_order(muscle.path) + len(muscle.path.coordinates), len(muscle.path.coordinates))
            if count > MAX_COEFFICIENTS:
                raise ModelError(model.name, "", f"muscle {muscle.name}: its polynomial path of total degree "
                                                 f"{_order(muscle.path)} in {len(muscle.path.coordinates)} coordinates "
                                                 f"takes {count} coefficients in OpenSim's MultivariatePolynomialFunction, "
                                                 f"more than export-osim writes ({MAX_COEFFICIENTS})")


def osim_muscle(muscle, model) -> str:
    """The muscle of ``model`` as a DeGrooteFregly2016Muscle element."""
    path = _points(muscle, model) if isinstance(muscle.path, PointPath) else _polynomial(muscle.path)
    values = {"max_isometric_force": muscle.max_isometric_force, "optimal_fiber_length": muscle.optimal_fiber_length,
              "tendon_slack_length": muscle.tendon_slack_length, "pennation_angle_at_optimal": muscle.pennation_angle,
              "max_contraction_velocity": muscle.max_contraction_velocity,
              "activation_time_constant": muscle.activation_time, "deactivation_time_constant": muscle.deactivation_time,
              "tendon_strain_at_one_norm_force": muscle.tendon_strain,
              "passive_fiber_strain_at_one_norm_force": muscle.passive_strain, "fiber_damping": muscle.fiber_damping,
              "active_force_width_scale": 1.0}
    properties = "".join(f"<{key}>{numbers(value)}</{key}>" for key, value in values.items())
    rigid = "true" if muscle.tendon == "rigid" else "false"
    return (f'<DeGrooteFregly2016Muscle name="{muscle.name}"><min_control>0</min_control><max_control>1</max_control>'
            f"{path}{properties}<ignore_tendon_compliance>{rigid}</ignore_tendon_compliance>"
            "<tendon_compliance_dynamics_mode>explicit</tendon_compliance_dynamics_mode></DeGrooteFregly2016Muscle>")


def _points(muscle, model) -> str:
    """A GeometryPath of the path's points, each in its body's frame (or ground's)."""
    import math

    points = []
    for k, point in enumerate(muscle.path.points):
        body, origin, angle = (GROUND, (0.0, 0.0), 0.0) if point.body == GROUND else model.frame(point.body)
        c, s = math.cos(angle), math.sin(angle)
        x = origin[0] + c * point.at[0] - s * point.at[1]
        y = origin[1] + s * point.at[0] + c * point.at[1]
        points.append(f'<PathPoint name="{muscle.name}-P{k + 1}"><socket_parent_frame>{frame_path(body)}'
                      f"</socket_parent_frame><location>{numbers(x, y, 0.0)}</location></PathPoint>")
    return f'<GeometryPath name="path"><PathPointSet><objects>{"".join(points)}</objects></PathPointSet></GeometryPath>'


def _order(path) -> int:
    return max(sum(term.powers) for term in path.terms)


def _polynomial(path) -> str:
    """A FunctionBasedPath whose length is the polynomial, in OpenSim's coefficient order."""
    order, dimension = _order(path), len(path.coordinates)
    given = {term.powers: term.coefficient for term in path.terms}
    coefficients = [given.get(powers, 0.0) for powers in exponents(dimension, order)]
    return (f'<FunctionBasedPath name="path"><coordinate_paths>'
            f"{' '.join(coordinate_path(name) for name in path.coordinates)}</coordinate_paths>"
            f"<length_function><MultivariatePolynomialFunction><coefficients>{numbers(*coefficients)}</coefficients>"
            f"<dimension>{dimension}</dimension><order>{order}</order></MultivariatePolynomialFunction>"
            "</length_function></FunctionBasedPath>")


def exponents(dimension: int, order: int) -> list[tuple[int, ...]]:
    """The powers of each coefficient of OpenSim's MultivariatePolynomialFunction, in its order:
    every tuple of ``dimension`` powers of total <= ``order``, the first coordinate's outermost."""
    if dimension == 1:
        return [(p,) for p in range(order + 1)]
    return [(p,) + rest for p in range(order + 1) for rest in exponents(dimension - 1, order - p)]
