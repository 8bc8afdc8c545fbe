"""Small models the tests share: the hopper (a free pelvis, a hip, a knee on a path) and loads on
it; the forearm with a flexor and an extensor; arm26 with rigid tendons on a 50-ms motion; the leg's
description (a free base, a knee on a path, an offset ankle and a frame), without muscles; arm26's
muscles through OpenSim's path points."""

from __future__ import annotations

import dataclasses

import numpy as np

from fdbench.models import find_model
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


H, D = 0.3, 0.05  # m: the muscles' origins at (0, +-H) on ground, their insertion (D, 0) on the forearm
SWING = {"name": "swing", "type": "minimum-jerk", "duration": 0.5, "start": {"theta": -0.6}, "goal": {"theta": -0.1}}


def forearm_with_muscles_data() -> dict:
    """The library's forearm (a model file's dict) with a flexor and an extensor (rigid tendons, a
    straight path from ground to the forearm each) and the motion ``swing`` (0.5 s)."""
    data = d.to_dict(find_model("forearm"))
    data["muscles"] = [{"name": name, "max_isometric_force": 600.0, "optimal_fiber_length": 0.1,
                        "tendon_slack_length": slack,
                        "path": {"points": [{"body": "ground", "at": [0.0, y]}, {"body": "forearm", "at": [D, 0.0]}]}}
                       for name, y, slack in (("flexor", H, 0.2), ("extensor", -H, 0.21))]
    data["motions"] = [SWING]
    return data


def short_arm26(points: bool = False):
    """The library's arm26 with every tendon rigid and one motion, 'short': 50 ms of minimum jerk
    from (0.3, 0.8) to (0.32, 0.9) rad; ``points``: the muscles of ARM26_POINTS through their points."""
    data = d.to_dict(find_model("arm26"))
    for m in data["muscles"]:
        m["tendon"] = "rigid"
    model = d.model_from_dict(with_arm26_points(data) if points else data, "arm26.toml")
    start = tuple(zip(model.coordinates, (0.3, 0.8)))
    goal = tuple(zip(model.coordinates, (0.32, 0.9)))
    return dataclasses.replace(model, motions=(d.MotionSpec("short", "minimum-jerk", 0.05, start, goal),))


LEG = {  # the leg: a free base, a knee on a path, an offset ankle and a frame
    "name": "leg",
    "bodies": [{"name": "thigh", "mass": 8.0, "com": [0.0, -0.2], "inertia": 0.1},
               {"name": "shank", "mass": 3.5, "com": [0.0, -0.2], "inertia": 0.05},
               {"name": "foot", "mass": 1.0, "com": [0.05, 0.0], "inertia": 0.01}],
    "joints": [{"name": "hip", "type": "free", "coordinates": ["pelvis_tilt", "pelvis_tx", "pelvis_ty"],
                "parent": "ground", "child": "thigh", "at_parent": [0.0, 0.0]},
               {"name": "knee_angle", "parent": "thigh", "child": "shank", "at_parent": [0.0, -0.4],
                "path": {"angles": [-2.0, -1.0, 0.0, 1.0], "x": [-0.01, -0.005, 0.0, 0.001], "y": [0.0] * 4}},
               {"name": "ankle_angle", "parent": "shank", "child": "foot", "at_parent": [0.01, -0.42],
                "at_child": [-0.02, 0.01], "offset": 0.3}],
    "frames": [{"name": "heel", "body": "foot", "at": [-0.05, 0.02], "angle": 0.7}],
}


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
