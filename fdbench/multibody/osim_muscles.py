"""An OpenSim model's muscles as fdbench's (``fdbench.multibody.muscles``), for the import of
``fdbench.multibody.osim``; run in its child process, with the ``opensim`` module handed in.

* Every muscle becomes a De Groote-Fregly (2016) muscle as OpenSim's
  ``DeGrooteFregly2016Muscle::replaceMuscles`` maps it: the five parameters every OpenSim muscle
  has (max isometric force, optimal fibre length, tendon slack length, pennation angle at the
  optimal length, max contraction velocity) and the tendon (rigid where it ignores tendon
  compliance); of a ``Millard2012EquilibriumMuscle`` also its activation and deactivation time
  constants, fibre damping, passive fibre strain (fibre force-length curve) and tendon strain
  (tendon force-length curve); of a ``Thelen2003Muscle`` its time constants, ``FmaxMuscleStrain``
  and ``FmaxTendonStrain`` (no damping); of a ``DeGrooteFregly2016Muscle`` its own. Another kind of
  muscle keeps the five and takes the defaults for the rest (a note says so). Disabled muscles
  (``appliesForce`` false) are left out.
* A path of plain path points (no wrapping, no conditional or moving points) that lie in one plane
  z = constant becomes a path of points, each moved into the frame of the body that keeps it (a
  body welded into another one or into ground gives its points to it).
* Any other path becomes its length as a polynomial (all monomials up to a total degree) in the
  coordinates it spans (those whose change changes its length), fitted by least squares to
  OpenSim's lengths and slopes dl/dq (central differences of its lengths) on a grid over the
  coordinates' ranges, Huber-weighted (a kink of OpenSim's path weighs less); the degree is the
  lowest whose errors (their ROBUST_PERCENTILE) between the grid's points are within FIT_TARGET
  or a tenth of the tolerance and at its points within SLOPE_TARGET (or the best one). Where OpenSim's length jumps (its
  wrapping switching: arm26's TRIlong by 8 mm), each side of the jump is fitted with its own level,
  the path keeps the largest side's, and the check counts a state's error from its side's level.
* Every muscle's path, as fdbench computes it (``muscle_paths``), is checked against OpenSim's
  ``getLength`` and ``computeMomentArm`` at CHECK_STATES random states within the ranges; a note
  gives each muscle's worst errors. A worst length error above ``max_path_error`` stops the import
  naming the muscle (a path of points beyond it is fitted instead).
"""

from __future__ import annotations

import math
from itertools import combinations_with_replacement

import numpy as np

from ..files import quoted, shown
from .model import ModelError, model_from_dict, to_dict
from .muscle_paths import muscle_geometry

MAX_PATH_ERROR = 3e-3  # m: the default tolerance of a path against OpenSim's lengths (arm26's TRIlong: 2.2 mm)
FIT_TARGET = 1e-4  # m: the fit's degree rises until its length errors between the grid's points are below this
SLOPE_TARGET = 2e-4  # m/rad: ... and its slope errors at the grid's points below this (ROBUST_PERCENTILE)
CHECK_STATES = 200  # random states at which each path is checked against OpenSim
CHECK_SEED = 20160101
SLOPE_STEP = 1e-5  # rad or m: the central difference's half step for OpenSim's slopes
SPAN_SLOPE = 1e-7  # m/rad: a coordinate whose slope stays below this at every probe is not spanned
SPAN_PROBES = 24
GRID = {1: 81, 2: 25, 3: 13, 4: 7, 5: 5, 6: 4}  # grid points per coordinate, by the number spanned
MAX_DEGREE = 14
MAX_TERMS = 1000
JUMP = 1e-3  # m: a step of OpenSim's length this far off its slopes' is a jump (of its wrapping)
SMALL_SEGMENT = 0.02  # of the grid's samples: a segment between jumps smaller than this has no level of its own
HUBER_LENGTH, HUBER_SLOPE = 2e-4, 1e-3  # m, m/rad: misfits beyond these weigh less (Huber), as at a kink
HUBER_STEPS = 4
ROBUST_PERCENTILE = 98  # the degree's errors: a percentile of the misfits, not their worst (a kink)
SAME_Z = 1e-9  # m: path points this close to one plane z = constant are planar
DEFAULT_RANGE = (-math.pi, math.pi)


def imported_muscles(osim, model, state, description, hosts: dict, source: str,
                     max_path_error: float = MAX_PATH_ERROR) -> tuple[list[dict], list[str]]:
    """([muscle tables of a model file], notes) of the OpenSim ``model``'s muscles, for its planar
    ``description`` (a Model, without muscles); ``hosts``: {OpenSim body: (kept body or 'ground',
    R, p) its frame in the kept one's}. ModelError naming the muscle whose path is off OpenSim's by
    more than ``max_path_error`` (m)."""
    muscles = [m for m in model.getMuscles() if m.get_appliesForce()]
    if not muscles:
        return [], []
    sampler = _Sampler(model, state, description)
    spans = sampler.spans(len(muscles), SPAN_PROBES)
    entries, notes, jumps = [], [], [None] * len(muscles)
    for muscle in muscles:
        entry, note = _parameters(osim, muscle)
        notes += [note] if note else []
        entry["path"] = _points(osim, muscle, state, hosts)
        entries.append(entry)
    fitted = {}
    for k, entry in enumerate(entries):
        if entry["path"] is None:
            fitted.setdefault(spans[k], []).append(k)
    for columns, members in fitted.items():
        for k, (path, found) in zip(members, _fit(sampler, columns, members, max_path_error, muscles, source)):
            entries[k]["path"], jumps[k] = path, found
    checks = _check(sampler, model_from_dict(_data(description, entries), source), spans, jumps)
    off = [k for k, check in enumerate(checks) if check[0] > max_path_error and "points" in entries[k]["path"]]
    if off:  # points out of the plane after all (a tilted axis): fit them
        for k in off:
            entries[k]["path"], jumps[k] = _fit(sampler, spans[k], [k], max_path_error, muscles, source)[0]
        checks = _check(sampler, model_from_dict(_data(description, entries), source), spans, jumps)
    for k, (length, _, _) in enumerate(checks):
        if length > max_path_error:
            raise ModelError(source, "", f"muscle {quoted(muscles[k].getName())}: its path is off OpenSim's lengths by "
                                         f"{length * 1e3:.3g} mm, more than --max-path-error {max_path_error * 1e3:g} mm; "
                                         "raise it or leave the muscle out")
    notes.append(_check_note(entries, checks, muscles))
    notes += [_jump_note(muscles[k], sampler, found, checks[k][2]) for k, found in enumerate(jumps) if found]
    return entries, notes


def _data(description, entries: list) -> dict:
    """The description's data with the muscles ``entries``."""
    return to_dict(description) | {"muscles": entries}


# ---------------------------------------------------------------------------------------- parameters


def _parameters(osim, muscle) -> tuple[dict, str]:
    """(the muscle's table without its path, a note or '') as replaceMuscles maps it."""
    kind = muscle.getConcreteClassName()
    entry = {"name": muscle.getName(), "max_isometric_force": muscle.getMaxIsometricForce(),
             "optimal_fiber_length": muscle.getOptimalFiberLength(),
             "tendon_slack_length": muscle.getTendonSlackLength(),
             "pennation_angle": muscle.getPennationAngleAtOptimalFiberLength(),
             "max_contraction_velocity": muscle.getMaxContractionVelocity(),
             "tendon": "rigid" if muscle.get_ignore_tendon_compliance() else "compliant"}
    note = ""
    millard = osim.Millard2012EquilibriumMuscle.safeDownCast(muscle)
    thelen = osim.Thelen2003Muscle.safeDownCast(muscle)
    degroote = osim.DeGrooteFregly2016Muscle.safeDownCast(muscle)
    if millard is not None:
        entry |= {"activation_time": millard.get_activation_time_constant(),
                  "deactivation_time": millard.get_deactivation_time_constant(),
                  "tendon_strain": millard.get_TendonForceLengthCurve().get_strain_at_one_norm_force(),
                  "passive_strain": millard.get_FiberForceLengthCurve().get_strain_at_one_norm_force(),
                  "fiber_damping": millard.get_fiber_damping()}
    elif thelen is not None:
        entry |= {"activation_time": thelen.get_activation_time_constant(),
                  "deactivation_time": thelen.get_deactivation_time_constant(),
                  "tendon_strain": thelen.get_FmaxTendonStrain(), "passive_strain": thelen.get_FmaxMuscleStrain(),
                  "fiber_damping": 0.0}
    elif degroote is not None:
        entry |= {"activation_time": degroote.get_activation_time_constant(),
                  "deactivation_time": degroote.get_deactivation_time_constant(),
                  "tendon_strain": degroote.get_tendon_strain_at_one_norm_force(),
                  "passive_strain": degroote.get_passive_fiber_strain_at_one_norm_force(),
                  "fiber_damping": degroote.get_fiber_damping()}
        if degroote.get_active_force_width_scale() != 1:
            note = (f"muscle {quoted(muscle.getName())}: its active_force_width_scale "
                    f"{degroote.get_active_force_width_scale():g} is not kept (fdbench's is 1)")
    else:
        note = (f"muscle {quoted(muscle.getName())} ({shown(kind)}): a De Groote muscle of its five parameters; its "
                "time constants, strains and damping are De Groote's defaults")
    return entry, note


# ---------------------------------------------------------------------------------------- paths of points


def _points(osim, muscle, state, hosts: dict):
    """{'points': [...]} of a path of plain path points in one plane z = constant, else None."""
    path = osim.GeometryPath.safeDownCast(muscle.updPath())
    if path is None or path.getWrapSet().getSize() > 0:
        return None
    points, heights = [], []
    found = path.getPathPointSet()
    for i in range(found.getSize()):
        point = osim.PathPoint.safeDownCast(found.get(i))
        if point is None or found.get(i).getConcreteClassName() != "PathPoint":
            return None
        frame = point.getParentFrame()
        host, R, p = hosts[frame.findBaseFrame().getName()]
        X = frame.findTransformInBaseFrame()
        location = np.array([point.get_location().get(k) for k in range(3)])
        R_bf = np.array([[X.R().get(r, c) for c in range(3)] for r in range(3)])
        p_bf = np.array([X.p().get(k) for k in range(3)])
        at = R @ (R_bf @ location + p_bf) + p
        points.append({"body": host, "at": [float(at[0]), float(at[1])]})
        ground = point.getLocationInGround(state)
        heights.append(ground.get(2))
    if max(heights) - min(heights) > SAME_Z:
        return None
    return {"points": points}


# ---------------------------------------------------------------------------------------- OpenSim's lengths


class _Sampler:
    """OpenSim's muscle lengths at coordinates q (the description's coordinates, in its order)."""

    def __init__(self, model, state, description):
        self.model, self.state = model, state
        found = model.getCoordinateSet()
        self.coordinates = [found.get(name) for name in description.coordinates]
        self.muscles = [m for m in model.getMuscles() if m.get_appliesForce()]
        self.default = np.array([c.getValue(state) for c in self.coordinates])
        self.ranges = np.array([_range(c) for c in self.coordinates])

    def lengths(self, q: np.ndarray, members) -> np.ndarray:
        """(n, len(members)) lengths (m) of the muscles ``members`` (indices) at q (n, J)."""
        out = np.empty((len(q), len(members)))
        for i, row in enumerate(q):
            self._set(row)
            out[i] = [self.muscles[k].getLength(self.state) for k in members]
        return out

    def slopes(self, q: np.ndarray, members, columns) -> np.ndarray:
        """(n, len(members), len(columns)) dl/dq by central differences of OpenSim's lengths."""
        out = np.empty((len(q), len(members), len(columns)))
        for c, j in enumerate(columns):
            step = np.zeros(q.shape[1])
            step[j] = SLOPE_STEP
            out[:, :, c] = (self.lengths(q + step, members) - self.lengths(q - step, members)) / (2 * SLOPE_STEP)
        return out

    def moment_arms(self, q: np.ndarray, k: int, columns) -> np.ndarray:
        """(n, len(columns)) OpenSim's computeMomentArm of muscle k."""
        out = np.empty((len(q), len(columns)))
        for i, row in enumerate(q):
            self._set(row)
            out[i] = [self.muscles[k].computeMomentArm(self.state, self.coordinates[j]) for j in columns]
        return out

    def random(self, count: int, seed: int) -> np.ndarray:
        """(count, J) states uniform within the coordinates' ranges."""
        rng = np.random.default_rng(seed)
        return self.ranges[:, 0] + rng.random((count, len(self.coordinates))) * np.diff(self.ranges, axis=1)[:, 0]

    def spans(self, count: int, probes: int) -> list[tuple]:
        """Per muscle, the columns of the coordinates its length changes with."""
        q = self.random(probes, CHECK_SEED + 1)
        members = list(range(count))
        slopes = self.slopes(q, members, range(len(self.coordinates)))
        return [tuple(j for j in range(len(self.coordinates)) if np.max(np.abs(slopes[:, k, j])) > SPAN_SLOPE)
                for k in members]

    def _set(self, row) -> None:
        for coordinate, value in zip(self.coordinates, row):
            coordinate.setValue(self.state, float(value), False)
        self.model.realizePosition(self.state)


def _range(coordinate) -> tuple[float, float]:
    low, high = coordinate.getRangeMin(), coordinate.getRangeMax()
    return (low, high) if math.isfinite(low) and math.isfinite(high) and low < high else DEFAULT_RANGE


# ---------------------------------------------------------------------------------------- polynomials


def _powers(count: int, degree: int) -> list[tuple]:
    """Every tuple of ``count`` powers of total degree <= ``degree``, low degrees first."""
    out = []
    for total in range(degree + 1):
        for combination in combinations_with_replacement(range(count), total):
            out.append(tuple(combination.count(k) for k in range(count)))
    return out


def _basis(x: np.ndarray, powers: list) -> tuple[np.ndarray, np.ndarray]:
    """Monomials (n, T) at x (n, K) and their derivatives (n, K, T)."""
    values = np.stack([np.prod(x ** np.array(p), axis=1) for p in powers], axis=1)
    slopes = np.zeros((x.shape[0], x.shape[1], len(powers)))
    for t, p in enumerate(powers):
        for k, power in enumerate(p):
            if power:
                lowered = np.array(p)
                lowered[k] -= 1
                slopes[:, k, t] = power * np.prod(x ** lowered, axis=1)
    return values, slopes


def _fit(sampler: _Sampler, columns: tuple, members: list, max_path_error: float, muscles, source: str) -> list:
    """[(path, jumps)] of the muscles ``members`` that span the coordinates ``columns``: the length
    polynomial and ``_Jumps`` (where OpenSim's length jumps on the grid, or None)."""
    if not columns:  # a length that no coordinate changes: a constant in the first coordinate
        lengths = sampler.lengths(sampler.default[None, :], members)[0]
        return [(_polynomial(sampler, (0,), [(0,)], [value]), None) for value in lengths]
    if len(columns) > 6:
        names = ", ".join(muscles[k].getName() for k in members)
        raise ModelError(source, "", f"muscles {shown(names)} span {len(columns)} coordinates; fdbench's polynomial paths "
                                     "take at most 6")
    size = GRID[len(columns)]
    axes = [np.linspace(*sampler.ranges[j], size) for j in columns]
    between = [(a[1:] + a[:-1]) / 2 for a in axes]
    grid, middle = _states(sampler, columns, axes), _states(sampler, columns, between)
    lengths, slopes = sampler.lengths(grid, members), sampler.slopes(grid, members, columns)
    middle_lengths = sampler.lengths(middle, members)
    x, x_middle = grid[:, list(columns)], middle[:, list(columns)]
    target = min(max_path_error / 10, FIT_TARGET)
    out = []
    for m in range(len(members)):
        segments = _segments(axes, lengths[:, m], slopes[:, m, :])
        best = None
        for degree in range(1, MAX_DEGREE + 1):
            powers = _powers(len(columns), degree)
            if len(powers) > MAX_TERMS or len(powers) * 2 > len(x) * (1 + len(columns)):
                break
            coefficients, levels, slope_error = _segmented_fit(x, lengths[:, m], slopes[:, m, :], powers, segments)
            jumps = _Jumps(columns, axes, levels)
            off = middle_lengths[:, m] - _basis(x_middle, powers)[0] @ coefficients
            error = max(np.percentile(jumps.error(x_middle, off), ROBUST_PERCENTILE), slope_error * FIT_TARGET / SLOPE_TARGET)
            if best is None or error < best[0]:
                best = (error, powers, coefficients, jumps)
            if error <= target:
                break
        out.append((_polynomial(sampler, columns, best[1], best[2]), best[3] if best[3].size else None))
    return out


def _segments(axes: list, lengths: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """(n,) the segment of each grid sample: neighbours along a coordinate are in one segment
    unless OpenSim's length between them differs from the trapezoid of its slopes by more than
    JUMP (a jump of its wrapping); the largest segment is 0."""
    shape = [len(a) for a in axes]
    L, S = lengths.reshape(shape), slopes.reshape(shape + [len(axes)])
    label = np.full(shape, -1)
    count = 0
    for start in np.ndindex(*shape):
        if label[start] >= 0:
            continue
        label[start], pending = count, [start]
        while pending:
            node = pending.pop()
            for k, a in enumerate(axes):
                for step in (-1, 1):
                    other = node[:k] + (node[k] + step,) + node[k + 1:]
                    if not 0 <= other[k] < len(a) or label[other] >= 0:
                        continue
                    rise = (S[node][k] + S[other][k]) / 2 * (a[other[k]] - a[node[k]])
                    if abs(L[other] - L[node] - rise) <= JUMP:
                        label[other] = count
                        pending.append(other)
        count += 1
    sizes = np.bincount(label.ravel())
    order = np.argsort(-sizes, kind="stable")
    return np.argsort(order)[label.ravel()]


class _Jumps:
    """The levels (m) of OpenSim's length on the grid off the fitted path's (0 on its largest
    segment; the jumps of its wrapping): ``error`` of a state counts from the level that explains it
    best among the grid corners around it."""

    def __init__(self, columns: tuple, axes: list, levels: np.ndarray):
        self.columns, self.axes = columns, axes
        self.levels = levels.reshape([len(a) for a in axes])
        self.size = int(np.count_nonzero(self.levels))
        self.largest = float(np.max(np.abs(self.levels)))

    def error(self, x: np.ndarray, residuals: np.ndarray) -> np.ndarray:
        """|residual| (m) at states x (n, K) of the spanned coordinates, less the level of the grid
        corner around each state that explains it best (none where the grid has no jump)."""
        if not self.size:
            return np.abs(residuals)
        below = [np.clip(np.searchsorted(a, x[:, k]) - 1, 0, len(a) - 2) for k, a in enumerate(self.axes)]
        best = np.abs(residuals)
        for corner in np.ndindex(*([2] * len(self.axes))):
            level = self.levels[tuple(b + c for b, c in zip(below, corner))]
            best = np.minimum(best, np.abs(residuals - level))
        return best

    def explained(self, x: np.ndarray, residuals: np.ndarray) -> int:
        """How many states' errors a jump explains (beyond JUMP without it)."""
        return int(np.count_nonzero((np.abs(residuals) > JUMP) & (self.error(x, residuals) <= JUMP)))


def _segmented_fit(x, lengths, slopes, powers, segments) -> tuple[np.ndarray, np.ndarray, float]:
    """(coefficients, levels (n,), the ROBUST_PERCENTILE of the slope misfits m/rad) of the monomials ``powers`` fitted to OpenSim's lengths and
    slopes, each segment but the largest with its own level (the jump's); slopes far off the others'
    fit (differences across a jump) are left out."""
    values, derivatives = _basis(x, powers)
    sizes = np.bincount(segments)
    large = np.flatnonzero(sizes >= max(SMALL_SEGMENT * len(x), 4))  # 0 first: the largest
    small = ~np.isin(segments, large)  # a few samples between jumps: their lengths are left out
    indicators = (segments[:, None] == large[None, 1:]).astype(float)
    count = len(large)
    A_slopes = np.hstack([derivatives.transpose(1, 0, 2).reshape(-1, len(powers)),
                          np.zeros((derivatives.shape[1] * len(x), count - 1))])
    b_slopes = slopes.T.ravel()
    A = np.vstack([np.hstack([values, indicators]), A_slopes])
    b = np.concatenate([lengths, b_slopes])
    tolerance = np.concatenate([np.full(len(x), HUBER_LENGTH), np.full(len(b) - len(x), HUBER_SLOPE)])
    weights = np.ones(len(b))
    for _ in range(HUBER_STEPS):  # Huber's weights: a kink of OpenSim's path weighs less than the rest
        weights[:len(x)][small] = 0.0
        root = np.sqrt(weights)
        solution = _solve(A * root[:, None], b * root)
        weights = np.minimum(1.0, tolerance / np.maximum(np.abs(A @ solution - b), 1e-300))
    levels = indicators @ solution[len(powers):]
    levels[small] = lengths[small] - values[small] @ solution[:len(powers)]
    slope_error = float(np.percentile(np.abs(A[len(x):] @ solution - b[len(x):]), ROBUST_PERCENTILE))
    return solution[:len(powers)], levels, slope_error


def _solve(A, b) -> np.ndarray:
    """Least squares with the columns scaled to unit norm."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    return np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale


def _states(sampler: _Sampler, columns: tuple, axes: list) -> np.ndarray:
    """(n, J) the default state with the coordinates ``columns`` on the grid of ``axes``."""
    mesh = np.meshgrid(*axes, indexing="ij")
    q = np.tile(sampler.default, (mesh[0].size, 1))
    for j, values in zip(columns, mesh):
        q[:, j] = values.ravel()
    return q


def _polynomial(sampler: _Sampler, columns: tuple, powers: list, coefficients) -> dict:
    names = [sampler.coordinates[j].getName() for j in columns]
    return {"length": {"coordinates": names, "terms": [{"coefficient": float(c), "powers": list(p)}
                                                       for p, c in zip(powers, coefficients)]}}


# ---------------------------------------------------------------------------------------- the check


def _check(sampler: _Sampler, model, spans: list, jumps: list) -> list[tuple[float, float, int]]:
    """Per muscle, (worst length error m, worst moment-arm error m, states off by a jump) of
    fdbench's path against OpenSim's getLength and computeMomentArm (of the coordinates it spans)
    at CHECK_STATES states; a length's error beside a jump of OpenSim's is taken from that jump's
    level (``_Jumps``)."""
    q = sampler.random(CHECK_STATES, CHECK_SEED)
    lengths, arms = muscle_geometry(model, q)
    theirs = sampler.lengths(q, range(len(sampler.muscles)))
    out = []
    for k, (columns, found) in enumerate(zip(spans, jumps)):
        residuals = theirs[:, k] - lengths[:, k]
        explained = 0
        if found is not None:
            x = q[:, list(found.columns)]
            length, explained = float(np.max(found.error(x, residuals))), found.explained(x, residuals)
        else:
            length = float(np.max(np.abs(residuals)))
        arm = 0.0
        if columns:
            arm = float(np.nanmax(np.abs(arms[:, k, list(columns)] - sampler.moment_arms(q, k, columns))))
        out.append((length, arm, explained))
    return out


def _check_note(entries: list, checks: list, muscles) -> str:
    parts = []
    for entry, muscle, (length, arm, _) in zip(entries, muscles, checks):
        path = entry["path"]
        form = "points" if "points" in path else (f"polynomial in {', '.join(path['length']['coordinates'])}, "
                                                  f"{len(path['length']['terms'])} terms")
        parts.append(f"{muscle.getName()} ({muscle.getConcreteClassName()}, {form}) {length * 1e3:.3g} mm, "
                     f"{arm * 1e3:.3g} mm")
    return (f"muscles as De Groote muscles, their paths against OpenSim at {CHECK_STATES} states within the "
            f"coordinates' ranges (worst length error, worst moment-arm error): {'; '.join(parts)}")


def _jump_note(muscle, sampler: _Sampler, jumps: _Jumps, explained: int) -> str:
    names = ", ".join(sampler.coordinates[j].getName() for j in jumps.columns)
    return (f"muscle {quoted(muscle.getName())}: OpenSim's length jumps (its wrapping) by up to {jumps.largest * 1e3:.3g} mm "
            f"over {names} ({jumps.size} of {jumps.levels.size} samples); the fitted path is smooth, on the level of "
            f"most samples; {explained} of {CHECK_STATES} states are off by the jump, their error counted from it")
