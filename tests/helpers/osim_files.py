"""Small OpenSim model files (.osim) written from a few lines: bodies, joints with their offset
frames, and a free planar pelvis with a knee whose shank follows a spline (``path_knee_model``)."""

from __future__ import annotations

from pathlib import Path


def frame(name: str, owner: str, at=(0, 0, 0), rotation=(0, 0, 0)) -> str:
    return (f'<PhysicalOffsetFrame name="{name}"><socket_parent>{owner}</socket_parent>'
            f"<translation>{' '.join(map(repr, map(float, at)))}</translation>"
            f"<orientation>{' '.join(map(repr, map(float, rotation)))}</orientation></PhysicalOffsetFrame>")


def body(name: str, mass: float, com, inertia) -> str:
    return (f'<Body name="{name}"><mass>{mass!r}</mass><mass_center>{" ".join(map(repr, map(float, com)))}'
            f'</mass_center><inertia>{" ".join(map(repr, map(float, inertia)))}</inertia></Body>')


def joint(kind: str, name: str, parent: str, child: str, coordinates=(), parent_at=(0, 0, 0), parent_rotation=(0, 0, 0),
          child_at=(0, 0, 0), child_rotation=(0, 0, 0)) -> str:
    """A joint of ``kind`` (PinJoint, WeldJoint, BallJoint...); coordinates: (name, default, locked)."""
    owner = lambda b: "/ground" if b == "ground" else f"/bodyset/{b}"  # noqa: E731
    coords = "".join(f'<Coordinate name="{c}"><default_value>{v!r}</default_value><range>-3 3</range>'
                     f"<locked>{'true' if locked else 'false'}</locked></Coordinate>" for c, v, locked in coordinates)
    return (f'<{kind} name="{name}"><socket_parent_frame>{name}_p</socket_parent_frame>'
            f"<socket_child_frame>{name}_c</socket_child_frame>"
            + (f"<coordinates>{coords}</coordinates>" if coordinates else "")
            + f"<frames>{frame(name + '_p', owner(parent), parent_at, parent_rotation)}"
            f"{frame(name + '_c', owner(child), child_at, child_rotation)}</frames></{kind}>")


def osim_file(path: Path, bodies, joints, gravity=(0, -9.81, 0), extra: str = "") -> Path:
    path.write_text('<?xml version="1.0" encoding="UTF-8" ?>\n<OpenSimDocument Version="40000"><Model name="written">'
                    f"<credits>written by fdbench's tests</credits><gravity>{' '.join(map(repr, map(float, gravity)))}"
                    f'</gravity><BodySet name="bodyset"><objects>{"".join(bodies)}</objects></BodySet>'
                    f'<JointSet name="jointset"><objects>{"".join(joints)}</objects></JointSet>{extra}'
                    "</Model></OpenSimDocument>\n")
    return path




def path_knee_model(path: Path, spline: str = "<SimmSpline><x> -2 -1 0 1</x><y> -0.01 -0.005 0 0.001</y></SimmSpline>",
                    knee_y: str = "<Constant><value>0</value></Constant>") -> Path:
    """A free planar pelvis and a knee whose shank follows a spline of the angle, as in OpenSim's gait
    models: ``spline`` the knee's translation along x, ``knee_y`` along y (functions of knee_angle)."""
    axes = "".join(
        f'<TransformAxis name="{name}"><coordinates>{coordinate}</coordinates><axis>{axis}</axis>{function}</TransformAxis>'
        for name, coordinate, axis, function in [
            ("rotation1", "knee_angle", "0 0 1", "<LinearFunction><coefficients> 1 0</coefficients></LinearFunction>"),
            ("rotation2", "", "0 1 0", "<Constant><value>0</value></Constant>"),
            ("rotation3", "", "1 0 0", "<Constant><value>0</value></Constant>"),
            ("translation1", "knee_angle", "1 0 0", spline),
            ("translation2", "knee_angle" if "Constant" not in knee_y else "", "0 1 0", knee_y),
            ("translation3", "", "0 0 1", "<Constant><value>0</value></Constant>")])
    knee = joint("CustomJoint", "knee", "thigh", "shank", [("knee_angle", 0.0, False)], (0, -0.4, 0))
    knee = knee.replace("</frames>", f"</frames><SpatialTransform>{axes}</SpatialTransform>")
    return osim_file(path, [body("thigh", 8.0, (0, -0.2, 0), (0.1, 0.02, 0.1, 0, 0, 0)),
                            body("shank", 3.5, (0, -0.2, 0), (0.05, 0.005, 0.05, 0, 0, 0))],
                     [joint("PlanarJoint", "hip", "ground", "thigh", [("pelvis_tilt", 0, False), ("pelvis_tx", 0, False),
                                                                      ("pelvis_ty", 1, False)]), knee])
