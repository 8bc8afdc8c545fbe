"""The De Groote–Fregly (2016) muscle as OpenSim defines it (``DeGrooteFregly2016Muscle``, Moco's
default muscle; OpenSim 4.6): its curves and their derivatives, its activation dynamics, and its
force along the path with a rigid tendon or with a compliant tendon in explicit form (normalised
tendon force as state). Scalar compiled functions, for the engine's kernels.

Normalised quantities: fibre length l = l_M / l_opt, fibre velocity v = v_M / (v_max l_opt) (-1 is
the fastest shortening), tendon length l_T / l_s, forces / F0. Lengths in m, velocities in m/s,
forces in N, angles in rad, time constants in s.

The fibre keeps its height, l_M sin(alpha) = l_opt sin(alpha_opt), and lies along the path at
length l_MT - l_T (the tendon's), so l_M = sqrt((l_MT - l_T)^2 + h^2) and cos(alpha) = (l_MT - l_T) / l_M.
Fibre force F0 (a f_L(l) f_V(v) + f_PE(l) + d v); along the path it is times cos(alpha).
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit

# Active force-length: three Gaussian-like terms (b1, b2, b3, b4); OpenSim's values (b11 set so
# that f_L(1) = 1).
B1 = (0.8150671134243542, 1.055033428970575, 0.162384573599574, 0.063303448465465)
B2 = (0.433004984392647, 0.716775413397760, -0.029947116970696, 0.200356847296188)
B3 = (0.1, 1.0, 0.353553390593274, 0.0)
# Force-velocity: d1 asinh(d2 v + d3) + d4, through (-1, 0) and (0, 1) (OpenSim's d1 and d4).
D1, D2, D3, D4 = -0.3211346127989808, -8.149, -0.374, 0.8825327733249912
KPE = 4.0  # passive force-length: exponential shape factor
MIN_FIBER_LENGTH = 0.2  # normalised; the passive curve is 0 there (negative below)
C1, C2, C3 = 0.2, 1.0, 0.2  # tendon force-length: c1 exp(kT (l - c2)) - c3, 0 at l = 1
# The activation a compliant tendon's fibre velocity divides by is at least this: the explicit form
# (f_V's inverse at (f_T / cos(alpha) - f_PE) / (a f_L)) is singular at a = 0, where OpenSim's
# DeGrooteFregly2016Muscle gives NaN; OpenSim's Millard2012EquilibriumMuscle demands the same floor
# (its minimum_activation, at least 0.01 with a compliant tendon and no fibre damping).
MIN_ACTIVATION = 0.01

# The parameters of one muscle, in this order in the array the path functions take
# (``parameters`` builds it; OpenSim's property names and defaults).
PARAMETERS = ("max_isometric_force", "optimal_fiber_length", "tendon_slack_length", "pennation_angle_at_optimal",
              "max_contraction_velocity", "passive_fiber_strain_at_one_norm_force", "tendon_strain_at_one_norm_force",
              "fiber_damping", "active_force_width_scale", "activation_time_constant", "deactivation_time_constant",
              "activation_dynamics_smoothing")
(F0, L_OPT, L_SLACK, ALPHA_OPT, V_MAX, PASSIVE_STRAIN, TENDON_STRAIN, DAMPING, WIDTH, TAU_ACT, TAU_DEACT,
 SMOOTHING) = range(len(PARAMETERS))
DEFAULTS = {"pennation_angle_at_optimal": 0.0, "max_contraction_velocity": 10.0,
            "passive_fiber_strain_at_one_norm_force": 0.6, "tendon_strain_at_one_norm_force": 0.049,
            "fiber_damping": 0.0, "active_force_width_scale": 1.0, "activation_time_constant": 0.015,
            "deactivation_time_constant": 0.060, "activation_dynamics_smoothing": 0.1}


def parameters(max_isometric_force: float, optimal_fiber_length: float, tendon_slack_length: float,
               **others: float) -> np.ndarray:
    """One muscle's parameters, shape (len(PARAMETERS),), in PARAMETERS' order: F0 (N), l_opt and
    l_s (m) and any of DEFAULTS' names (max_contraction_velocity in l_opt/s). ValueError (one line)
    for an unknown name or a value out of OpenSim's bounds."""
    unknown = sorted(set(others) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"unknown muscle parameter(s) {', '.join(unknown)}; known: {', '.join(PARAMETERS)}")
    values = {"max_isometric_force": max_isometric_force, "optimal_fiber_length": optimal_fiber_length,
              "tendon_slack_length": tendon_slack_length, **DEFAULTS, **others}
    values = {name: float(value) for name, value in values.items()}
    for name, value in values.items():
        low, strict = {"pennation_angle_at_optimal": (0.0, False), "fiber_damping": (0.0, False),
                       "active_force_width_scale": (1.0, False)}.get(name, (0.0, True))
        if not math.isfinite(value) or value < low or (strict and value == low):
            raise ValueError(f"muscle parameter {name} must be a finite number {'>' if strict else '>='} {low:g}, "
                             f"not {value:g}")
    if values["pennation_angle_at_optimal"] >= math.pi / 2:
        raise ValueError(f"muscle parameter pennation_angle_at_optimal must be below pi/2 rad, "
                         f"not {values['pennation_angle_at_optimal']:g}")
    return np.array([values[name] for name in PARAMETERS])


# ---------------------------------------------------------------------- the curves (normalised)


@njit(error_model="numpy", inline="always")
def _gaussian_like(x, b):
    return b[0] * math.exp(-0.5 * (x - b[1]) ** 2 / (b[2] + b[3] * x) ** 2)


@njit(error_model="numpy", inline="always")
def _gaussian_like_derivative(x, b):
    return _gaussian_like(x, b) * (b[1] - x) * (b[2] + b[1] * b[3]) / (b[2] + b[3] * x) ** 3


@njit(error_model="numpy")
def active_force_length(length, width_scale):
    """Active force-length multiplier f_L of the normalised fibre length; 1 at 1 (its peak);
    ``width_scale`` >= 1 widens the curve about 1 (default 1)."""
    x = (length - 1.0) / width_scale + 1.0
    return _gaussian_like(x, B1) + _gaussian_like(x, B2) + _gaussian_like(x, B3)


@njit(error_model="numpy")
def active_force_length_derivative(length, width_scale):
    """d f_L / d l (per normalised length)."""
    x = (length - 1.0) / width_scale + 1.0
    return (_gaussian_like_derivative(x, B1) + _gaussian_like_derivative(x, B2)
            + _gaussian_like_derivative(x, B3)) / width_scale


@njit(error_model="numpy")
def force_velocity(velocity):
    """Force-velocity multiplier f_V of the normalised fibre velocity (lengthening positive): 0 at
    -1, 1 at 0, 1.794 at 1 (its domain)."""
    t = D2 * velocity + D3
    return D1 * math.log(t + math.sqrt(t * t + 1.0)) + D4


@njit(error_model="numpy")
def force_velocity_derivative(velocity):
    """d f_V / d v."""
    t = D2 * velocity + D3
    return D1 * D2 / math.sqrt(t * t + 1.0)


@njit(error_model="numpy")
def force_velocity_inverse(multiplier):
    """The normalised fibre velocity at which f_V is ``multiplier``."""
    return (math.sinh((multiplier - D4) / D1) - D3) / D2


@njit(error_model="numpy")
def passive_force_length(length, strain):
    """Passive force-length multiplier f_PE of the normalised fibre length: exponential (shape
    KPE = 4), 0 at MIN_FIBER_LENGTH (0.2, negative below), 1 at 1 + ``strain`` (the passive fibre
    strain at one normalised force, default 0.6)."""
    offset = math.exp(KPE * (MIN_FIBER_LENGTH - 1.0) / strain)
    return (math.exp(KPE * (length - 1.0) / strain) - offset) / (math.exp(KPE) - offset)


@njit(error_model="numpy")
def passive_force_length_derivative(length, strain):
    """d f_PE / d l."""
    offset = math.exp(KPE * (MIN_FIBER_LENGTH - 1.0) / strain)
    return KPE / strain * math.exp(KPE * (length - 1.0) / strain) / (math.exp(KPE) - offset)


@njit(error_model="numpy")
def tendon_stiffness(strain):
    """The tendon curve's exponent kT for a tendon strain at one normalised force ``strain``
    (default 0.049: kT = 36.6)."""
    return math.log((1.0 + C3) / C1) / (1.0 + strain - C2)


@njit(error_model="numpy")
def tendon_force_length(length, strain):
    """Normalised tendon force f_T of the normalised tendon length: c1 exp(kT (l - c2)) - c3, 0 at
    the slack length (1), 1 at 1 + ``strain``."""
    return C1 * math.exp(tendon_stiffness(strain) * (length - C2)) - C3


@njit(error_model="numpy")
def tendon_force_length_derivative(length, strain):
    """d f_T / d l."""
    k = tendon_stiffness(strain)
    return C1 * k * math.exp(k * (length - C2))


@njit(error_model="numpy")
def tendon_force_length_inverse(force, strain):
    """The normalised tendon length at which f_T is ``force`` (> -c3)."""
    return math.log((force + C3) / C1) / tendon_stiffness(strain) + C2


# ---------------------------------------------------------------------- activation and the fibre


@njit(error_model="numpy")
def activation_derivative(excitation, activation, tau_act, tau_deact, smoothing):
    """da/dt (1/s), De Groote et al.'s smooth activation dynamics as OpenSim's: (e - a) times
    (f + 1/2) / (tau_act (1/2 + 3a/2)) + (1/2 - f) (1/2 + 3a/2) / tau_deact, f = tanh(b (e - a)) / 2
    with b = ``smoothing`` (default 0.1). Each muscle its own constants (OpenSim 4.6 keeps those
    of the first muscle it computes for every muscle of the process)."""
    z = 0.5 + 1.5 * activation
    f = 0.5 * math.tanh(smoothing * (excitation - activation))
    return ((f + 0.5) / (tau_act * z) + (0.5 - f) * z / tau_deact) * (excitation - activation)


@njit(error_model="numpy")
def fiber_length(along_path, optimal_length, pennation_at_optimal):
    """The fibre length (m) and cos(alpha) of a fibre ``along_path`` m long along the path (the
    muscle-tendon length minus the tendon's), its height l_opt sin(alpha_opt) kept."""
    height = optimal_length * math.sin(pennation_at_optimal)
    length = math.sqrt(along_path * along_path + height * height)
    return length, along_path / length


@njit(error_model="numpy")
def rigid_tendon_force(activation, length, lengthening, p):
    """The force (N, pulling) of a muscle with a rigid tendon along its path, at ``activation``,
    muscle-tendon ``length`` (m) and ``lengthening`` speed (m/s); ``p``: its ``parameters``."""
    l_m, cos_alpha = fiber_length(length - p[L_SLACK], p[L_OPT], p[ALPHA_OPT])
    norm_length = l_m / p[L_OPT]
    velocity = lengthening * cos_alpha / (p[V_MAX] * p[L_OPT])
    force = (activation * active_force_length(norm_length, p[WIDTH]) * force_velocity(velocity)
             + passive_force_length(norm_length, p[PASSIVE_STRAIN]) + p[DAMPING] * velocity)
    return p[F0] * force * cos_alpha


@njit(error_model="numpy")
def compliant_tendon(activation, tendon_force, length, lengthening, p):
    """A muscle with a compliant tendon in explicit form, its state the normalised tendon force
    ``tendon_force``: the tendon's force (N) and d(tendon_force)/dt (1/s), at ``activation``,
    muscle-tendon ``length`` (m) and ``lengthening`` speed (m/s); ``p``: its ``parameters``.
    As OpenSim's: the fibre velocity is f_V's inverse at (tendon_force / cos(alpha) - f_PE) / (a f_L),
    the fibre damping not counted (it is in the fibre force alone); a at least MIN_ACTIVATION there
    (OpenSim divides by 0 at a = 0)."""
    norm_tendon = tendon_force_length_inverse(tendon_force, p[TENDON_STRAIN])
    l_m, cos_alpha = fiber_length(length - p[L_SLACK] * norm_tendon, p[L_OPT], p[ALPHA_OPT])
    norm_length = l_m / p[L_OPT]
    multiplier = ((tendon_force / cos_alpha - passive_force_length(norm_length, p[PASSIVE_STRAIN]))
                  / (max(activation, MIN_ACTIVATION) * active_force_length(norm_length, p[WIDTH])))
    fiber_velocity = force_velocity_inverse(multiplier) * p[V_MAX] * p[L_OPT]  # m/s
    tendon_velocity = lengthening - fiber_velocity / cos_alpha
    return (p[F0] * tendon_force,
            tendon_velocity / p[L_SLACK] * tendon_force_length_derivative(norm_tendon, p[TENDON_STRAIN]))


# ---------------------------------------------------------------------- partial derivatives (exact sensitivities)


@njit(error_model="numpy")
def activation_partials(excitation, activation, tau_act, tau_deact, smoothing):
    """(d/de, d/da) of ``activation_derivative`` (1/s per unit excitation, per unit activation)."""
    z = 0.5 + 1.5 * activation
    w = excitation - activation
    th = math.tanh(smoothing * w)
    f = 0.5 * th
    rate = (f + 0.5) / (tau_act * z) + (0.5 - f) * z / tau_deact
    f_w = 0.5 * smoothing * (1.0 - th * th)
    rate_f = 1.0 / (tau_act * z) - z / tau_deact
    rate_z = -(f + 0.5) / (tau_act * z * z) + (0.5 - f) / tau_deact
    return rate + w * rate_f * f_w, -rate + w * (1.5 * rate_z - rate_f * f_w)


@njit(error_model="numpy")
def rigid_tendon_partials(activation, length, lengthening, p):
    """(dF/da (N), dF/dl (N/m), dF/dv (N s/m)) of ``rigid_tendon_force`` at the same arguments."""
    along = length - p[L_SLACK]
    l_m, cos_alpha = fiber_length(along, p[L_OPT], p[ALPHA_OPT])
    height = p[L_OPT] * math.sin(p[ALPHA_OPT])
    cos_l = height * height / (l_m * l_m * l_m)  # d cos(alpha) / d length
    norm_length, speed = l_m / p[L_OPT], p[V_MAX] * p[L_OPT]
    norm_l = cos_alpha / p[L_OPT]
    velocity = lengthening * cos_alpha / speed
    velocity_l = lengthening * cos_l / speed
    f_l, f_v = active_force_length(norm_length, p[WIDTH]), force_velocity(velocity)
    f_l1, f_v1 = active_force_length_derivative(norm_length, p[WIDTH]), force_velocity_derivative(velocity)
    inner = activation * f_l * f_v + passive_force_length(norm_length, p[PASSIVE_STRAIN]) + p[DAMPING] * velocity
    inner_l = (activation * f_l1 * f_v * norm_l + activation * f_l * f_v1 * velocity_l
               + passive_force_length_derivative(norm_length, p[PASSIVE_STRAIN]) * norm_l + p[DAMPING] * velocity_l)
    return (p[F0] * cos_alpha * f_l * f_v, p[F0] * (inner_l * cos_alpha + inner * cos_l),
            p[F0] * cos_alpha * (activation * f_l * f_v1 + p[DAMPING]) * cos_alpha / speed)


@njit(error_model="numpy")
def compliant_tendon_partials(activation, tendon_force, length, lengthening, p):
    """(d/da, d/df_T, d/dl (1/m), d/dv (s/m)) of ``compliant_tendon``'s rate of the normalised tendon
    force (1/s) at the same arguments (its force, F0 f_T, has d/df_T = F0 alone). Below
    MIN_ACTIVATION the rate does not depend on the activation."""
    strain, k = p[TENDON_STRAIN], tendon_stiffness(p[TENDON_STRAIN])
    norm_tendon = tendon_force_length_inverse(tendon_force, strain)
    tendon_f = 1.0 / (k * (tendon_force + C3))  # d norm_tendon / d f_T
    l_m, cos_alpha = fiber_length(length - p[L_SLACK] * norm_tendon, p[L_OPT], p[ALPHA_OPT])
    height = p[L_OPT] * math.sin(p[ALPHA_OPT])
    cos_x = height * height / (l_m * l_m * l_m)  # d cos(alpha) / d (the fibre's length along the path)
    norm_length = l_m / p[L_OPT]
    norm_x = cos_alpha / p[L_OPT]
    active = max(activation, MIN_ACTIVATION)
    active_a = 1.0 if activation > MIN_ACTIVATION else 0.0
    f_l = active_force_length(norm_length, p[WIDTH])
    numerator = tendon_force / cos_alpha - passive_force_length(norm_length, p[PASSIVE_STRAIN])
    denominator = active * f_l
    multiplier = numerator / denominator
    numerator_x = (-tendon_force / (cos_alpha * cos_alpha) * cos_x
                   - passive_force_length_derivative(norm_length, p[PASSIVE_STRAIN]) * norm_x)
    denominator_x = active * active_force_length_derivative(norm_length, p[WIDTH]) * norm_x
    multiplier_x = (numerator_x - multiplier * denominator_x) / denominator
    speed = p[V_MAX] * p[L_OPT]
    fiber_velocity = force_velocity_inverse(multiplier) * speed
    velocity_m = math.cosh((multiplier - D4) / D1) / (D1 * D2) * speed  # d fiber_velocity / d multiplier
    tendon_velocity = lengthening - fiber_velocity / cos_alpha
    tv_x = -velocity_m * multiplier_x / cos_alpha + fiber_velocity * cos_x / (cos_alpha * cos_alpha)
    tv_m = -velocity_m / cos_alpha
    slope = tendon_force_length_derivative(norm_tendon, strain) / p[L_SLACK]
    tv_f = tv_x * (-p[L_SLACK] * tendon_f) + tv_m / (cos_alpha * denominator)
    return (slope * tv_m * (-multiplier * active_a * f_l / denominator),
            slope * tv_f + tendon_velocity * slope * k * tendon_f, slope * tv_x, slope)
