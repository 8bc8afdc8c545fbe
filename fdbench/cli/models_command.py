"""``fdbench models``: the library of model descriptions, and one model checked and shown (a library
name or the user's own TOML or JSON file)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .app import FORMATS, bad_input, subcommands
from .common import check_outputs, emit, render, say, text_table
from .options import Output, format_option

models_app = subcommands("models", "The library of models (bodies, joints, loads as TOML files); 'fdbench models show "
                         "NAME|FILE' checks and shows one, your own file included.", invoke_without_command=True)
SHOW_FORMATS = ("table", "json", "toml")


@models_app.callback()
def list_models(
    ctx: typer.Context,
    fmt: Annotated[str, format_option(FORMATS, "Output: table (for a person), json or csv.")] = "table",
    output: Output = None,
):
    """One line per library model: its name, bodies, joints (its coordinates), total mass and what it is."""
    if ctx.invoked_subcommand is not None:
        return
    from ..models import library

    check_outputs(fmt, FORMATS, output=output)
    rows = [_summary(_checked(name)) for name in library()]
    if fmt == "json":
        text = json.dumps(rows, indent=2) + "\n"
    elif fmt == "csv":
        from ..files import csv_text

        text = csv_text(list(rows[0]), [[" ".join(v) if isinstance(v, list) else v for v in row.values()] for row in rows])
    else:
        columns = ("name", "bodies", "coordinates", "mass_kg", "description")
        shown = [{k: ", ".join(v) if isinstance(v, list) else v for k, v in row.items()} | {"mass_kg": f"{row['mass_kg']:.6g}"}
                 for row in rows]
        text = text_table(f"{len(rows)} models in the library ('fdbench models show NAME' for one)", shown, columns,
                          {"mass_kg": "mass (kg)", "coordinates": "joints (coordinates)"})
    emit(text, output)


@models_app.command("show")
def show_model(
    model: Annotated[str, typer.Argument(metavar="NAME|FILE", help="A library model's name or a model file (.toml, .json, or OpenSim's .osim).", show_default=False)],
    fmt: Annotated[str, format_option(SHOW_FORMATS, "Output: table (for a person), json (the checked model and what follows from it) or toml (a model file to start from, every end point explicit).")] = "table",
    output: Output = None,
):
    """Check a model and show it: bodies (with each end point of natural coordinates resolved), joints, loads, named motions, short keys, the paths --model PATH=VALUE takes with their values, and the total mass. A file that cannot be used is refused in one line naming the key."""
    from ..models import library

    # a library model's file is an input too: an output may not write over it
    check_outputs(fmt, SHOW_FORMATS, inputs={"NAME|FILE": library().get(model, Path(model))}, output=output)
    found = _checked(model)
    if fmt == "toml":
        from ..multibody.model_files import to_toml

        emit(to_toml(found, explicit_ends=True), output)
    elif fmt == "json":
        emit(json.dumps(_shown(found, model), indent=2) + "\n", output)
    else:
        emit(_show_text(found, model), output)


def _checked(name_or_path: str):
    from ..models import find_model, is_osim

    with bad_input():
        if is_osim(name_or_path):  # an OpenSim model: its import's notes as warnings
            from ..multibody.osim import import_osim

            found, notes = import_osim(name_or_path, option="NAME|FILE")
            for note in notes:
                say(False, f"[yellow]warning:[/] {note}")
            return found
        return find_model(name_or_path, "NAME|FILE")


def _summary(model) -> dict:
    return {"name": model.name, "bodies": [b.name for b in model.bodies], "coordinates": list(model.coordinates),
            "mass_kg": model.total_mass, "description": model.description}


def _shown(model, source: str) -> dict:
    """The checked model (a model file's keys, end points explicit) and what follows from it."""
    from ..multibody.model import to_dict
    from ..multibody.model_changes import short_key_values

    return {"source": source, "total_mass_kg": model.total_mass, "coordinates": list(model.coordinates),
            "short_key_values": short_key_values(model), "paths": _path_values(model),
            "model": to_dict(model, explicit_ends=True)}


def _point(point) -> str:
    return f"({point[0]:.6g}, {point[1]:.6g})"


def _table(title: str, rows: list[dict], columns=None) -> str:
    """A person's table of ``rows`` (columns: the first row's keys); nothing without rows or columns."""
    return text_table(title, rows, columns or list(rows[0])) if rows or columns else ""


def _show_text(model, source: str) -> str:
    from ..multibody.model import end_of
    from ..multibody.model_changes import short_key_values

    header = {"name": model.name, "description": model.description, "source": source,
              "gravity (m/s^2)": _point(model.gravity), "total mass (kg)": f"{model.total_mass:.6g}",
              "coordinates": ", ".join(model.coordinates)}
    bodies = []
    for body in model.bodies:
        end, given_by = end_of(model, body.name)
        bodies.append({"name": body.name, "mass": f"{body.mass:.6g}", "com": _point(body.com),
                       "inertia": f"{body.inertia:.6g}", "joint": model.parent_joint(body.name).name,
                       "end": _point(end) + ("" if given_by == "end" else f" ({_END_ORIGIN[given_by.split()[0]]})")})
    joints = [{"#": str(k), "name": j.name, "type": _joint_type(j), "parent": j.parent, "child": j.child,
               "at_parent": _point(j.at_parent), "at_child": _point(j.at_child), "offset": f"{j.offset:.6g}",
               "limits": "" if j.limits is None else _point(j.limits)} for k, j in enumerate(model.joints)]
    loads = [{"#": str(i), "body": load.body, "at": _point(load.at), "force": _point(load.force)}
             for i, load in enumerate(model.loads)]
    values = short_key_values(model)
    keys = [{"key": name, "path": target, "value": f"{values[name]:.6g}"} for name, target in model.keys]
    paths = [{"path": path, "value": f"{value:.6g}"} for path, value in _path_values(model).items()]
    return (render(header, "table", f"model {model.name}")
            + _table("bodies (kg, m, kg m^2 about the centre of mass; end: second point of natural coordinates)", bodies)
            + _table("joints in order (m, rad)", joints)
            + _table("loads (m in the body's frame, N in world axes)", loads) + _muscles_text(model) + _actuators_text(model)
            + _motions_text(model)
            + _table("short keys (--model KEY=VALUE)", keys) + _table("paths (--model PATH=VALUE)", paths, ["path", "value"]))


def _muscles_text(model) -> str:
    """The muscles: constants and path (the bodies of its points, or the coordinates of its polynomial)."""
    rows = [{"name": m.name, "F_max (N)": f"{m.max_isometric_force:.6g}",
             "l_opt (m)": f"{m.optimal_fiber_length:.6g}", "l_slack (m)": f"{m.tendon_slack_length:.6g}",
             "tendon": m.tendon, "path": (f"points on {', '.join(p.body for p in m.path.points)}"
                                          if hasattr(m.path, "points") else
                                          f"polynomial in {', '.join(m.path.coordinates)} ({len(m.path.terms)} terms)")}
            for m in model.muscles]
    return _table("muscles (max isometric force, optimal fibre length, tendon slack length)", rows)


def _actuators_text(model) -> str:
    """The torque actuators ([[actuators]]): name, coordinate and optimal force."""
    kinds = dict(zip(model.coordinates, model.coordinate_kinds))
    rows = [{"name": a.name, "coordinate": a.coordinate,
             "optimal force": f"{a.optimal_force:.6g} {'N' if kinds[a.coordinate] == 'translation' else 'N m'}"}
            for a in model.actuators]
    return _table("torque actuators (optimal force per unit control; the other coordinates have none beside the "
                  "muscles)", rows)


def _joint_type(joint) -> str:
    """'pin', 'pin on a path (n samples)' or 'free (angle, x, y)'."""
    if joint.type == "free":
        return f"free ({', '.join(joint.coordinates)})"
    return joint.type + (f" on a path ({len(joint.path.angles)} samples)" if joint.path is not None else "")


def _motions_text(model) -> str:
    """The named motions (the first the default): each coordinate's start -> goal in degrees (an
    angle) or metres (a translation)."""
    import math

    kinds = dict(zip(model.coordinates, model.coordinate_kinds))

    def span(joint, a, b):
        if kinds.get(joint) == "translation":
            return {f"{joint} (m)": f"{a:.4g} -> {b:.4g}"}
        return {f"{joint} (deg)": f"{math.degrees(a):.4g} -> {math.degrees(b):.4g}"}

    rows = [{"name": m.name + (" (default)" if i == 0 else ""), "type": m.type, "duration (s)": f"{m.duration:.6g}"}
            | {key: value for (joint, a), (_, b) in zip(m.start, m.goal) for key, value in span(joint, a, b).items()}
            for i, m in enumerate(model.motions)]
    return _table("motions (--motion NAME; from rest to rest)", rows)


def _path_values(model) -> dict:
    """{path: its value in this model (SI units, rad)}: every path --model PATH=VALUE, --plant and
    study mismatch --param take."""
    from ..multibody.model import change_paths
    from ..multibody.model_changes import path_value

    return {path: path_value(model, path) for path in change_paths(model)}


_END_ORIGIN = {"joint": "first child joint", "load": "farthest load", "com": "centre of mass",
               "default": "1 m along x"}
