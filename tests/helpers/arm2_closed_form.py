"""The two-segment arm of the library (arm2.toml) in closed form, written by hand from Lagrange's
equations, independent of fdbench's engine: the tests' reference for the arm through the engine.

The upper arm (length L01, mass m0, centre of mass L0G from the shoulder, inertia I0 about the
shoulder) carries Table 1's forearm (L12, m, L1G, I1 about the elbow) with F_ext downwards at the
hand; y up; z = [shoulder, elbow] (rad), the elbow relative to the upper arm:

    M11 = I0 + I1 + m L01^2 + 2 b cos(e),  M12 = M21 = I1 + b cos(e),  M22 = I1,  b = m L01 L1G
    h1 = -b sin(e) (2 s' e' + e'^2) + (m0 g L0G + (m g + F_ext) L01) cos(s) + G cos(s + e)
    h2 =  b sin(e) s'^2 + G cos(s + e),   G = m g L1G + F_ext L12
"""

from __future__ import annotations

import numpy as np

ARM2 = dict(L01=0.30, L0G=0.13, m0=2.0, I0=0.06, L12=0.33, L1G=0.11, m=1.0, I1=0.04, F_ext=15.0, g=9.81)
REACH = (np.radians([-20.0, 30.0]), np.radians([15.0, 55.0]), 1.0)  # start, goal (rad), duration (s)


def joint_torques(z, w, dw, **changes) -> np.ndarray:
    """M(z) z'' + h(z, z') (N m) for z, w, dw of shape (..., 2)."""
    c = {**ARM2, **changes}
    z, w, dw = (np.asarray(v, dtype=float) for v in (z, w, dw))
    s, e, ws, we = z[..., 0], z[..., 1], w[..., 0], w[..., 1]
    b = c["m"] * c["L01"] * c["L1G"]
    G = c["m"] * c["g"] * c["L1G"] + c["F_ext"] * c["L12"]
    upper = c["m0"] * c["g"] * c["L0G"] + (c["m"] * c["g"] + c["F_ext"]) * c["L01"]
    m11 = c["I0"] + c["I1"] + c["m"] * c["L01"] ** 2 + 2 * b * np.cos(e)
    m12 = c["I1"] + b * np.cos(e)
    h1 = -b * np.sin(e) * (2 * ws * we + we**2) + upper * np.cos(s) + G * np.cos(s + e)
    h2 = b * np.sin(e) * ws**2 + G * np.cos(s + e)
    return np.stack([m11 * dw[..., 0] + m12 * dw[..., 1] + h1, m12 * dw[..., 0] + c["I1"] * dw[..., 1] + h2], axis=-1)


def reach(t):
    """The arm's default motion, minimum jerk from REACH's start to its goal: z, z', z'' (rad,
    rad/s, rad/s^2), each of shape t.shape + (2,)."""
    start, goal, T = REACH
    u = np.clip(np.asarray(t, dtype=float) / T, 0.0, 1.0)[..., None]
    span = goal - start
    return (start + span * (10 * u**3 - 15 * u**4 + 6 * u**5), span * (30 * u**2 - 60 * u**3 + 30 * u**4) / T,
            span * (60 * u - 180 * u**2 + 120 * u**3) / T**2)
