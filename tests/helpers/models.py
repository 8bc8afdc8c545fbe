"""Small models the tests share: the hopper (a free pelvis, a hip, a knee on a path) and loads on
it; arm26's muscles through OpenSim's path points."""

from __future__ import annotations

import numpy as np

from fdbench.multibody import model as d
from fdbench.multibody.loads import ExternalLoad, ExternalLoads


def hopper_model():
    """A free pelvis (tilt, x, y), a thigh on a pin and a shank on a knee path (y with its own angles)."""
    knee = d.JointPath((-2.0, -1.0, 0.0, 0.5), (0.0, 0.01, 0.02, 0.015), (-0.01, 0.0, 0.005), (-1.5, 0.0, 1.0))
    return d.Model(name="hopper", gravity=(0.0, -9.81),
                   bodies=(d.Body("pelvis", 10.0, (0.0, -0.05), 0.2), d.Body("thigh", 5.0, (0.02, -0.2), 0.08),
                           d.Body("shank", 3.0, (0.0, -0.2), 0.05)),
                   joints=(d.Joint("base", "free", "ground", "pelvis", (0.0, 1.0), (0.0, 0.0),
                                   coordinates=("tilt", "tx", "ty")),
                           d.Joint("hip", "pin", "pelvis", "thigh", (0.0, -0.1), (0.0, 0.0), offset=-1.5),
                           d.Joint("knee", "pin", "thigh", "shank", (0.0, -0.4), (0.0, 0.0), path=knee)))


def hopper_loads(seed):
    """Three loads on the hopper, sampled at 50 times over [-0.1, 1] s: on the shank in ground's
    axes, on the thigh with its force in the thigh's frame and its point in the shank's, on the
    pelvis at a point of the thigh."""
    rng, n = np.random.default_rng(seed), 50
    loads = (ExternalLoad("a", "shank"), ExternalLoad("b", "thigh", "thigh", "shank"),
             ExternalLoad("c", "pelvis", "ground", "thigh"))
    return ExternalLoads(loads, np.linspace(-0.1, 1.0, n), rng.normal(0, 50, (n, 3, 2)), rng.normal(0, 0.2, (n, 3, 2)),
                         rng.normal(0, 5, (n, 3)))


# three of arm26's muscles through the path points of OpenSim's arm26.osim (its wrapping left out; x, y in m,
# the base's points in ground: the base sits at (0, 0.8))
ARM26_POINTS = {
    "TRIlong": [("ground", -0.05365, 0.78627), ("r_humerus", -0.02714, -0.11441), ("r_humerus", -0.03184, -0.22637),
                ("r_humerus", -0.01743, -0.26757), ("r_ulna_radius_hand", -0.0219, 0.01046)],
    "BIClong": [("ground", -0.039235, 0.80347), ("ground", -0.028945, 0.81391), ("r_humerus", 0.02131, 0.01793),
                ("r_humerus", 0.02378, -0.00511), ("r_humerus", 0.01345, -0.02827), ("r_humerus", 0.01068, -0.07736),
                ("r_humerus", 0.01703, -0.12125), ("r_humerus", 0.0228, -0.1754),
                ("r_ulna_radius_hand", 0.00751, -0.04839)],
    "BRA": [("r_humerus", 0.0068, -0.1739), ("r_ulna_radius_hand", -0.0032, -0.0239)],
}


def with_arm26_points(data: dict) -> dict:
    """arm26's model dictionary (``to_dict``) with the muscles of ARM26_POINTS through their points
    (changed in place, returned); the others keep their polynomial paths."""
    for muscle in data["muscles"]:
        if muscle["name"] in ARM26_POINTS:
            muscle["path"] = {"points": [{"body": b, "at": [x, y]} for b, x, y in ARM26_POINTS[muscle["name"]]]}
    return data
