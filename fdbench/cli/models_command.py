"""``fdbench models``: the library of model descriptions, and one model checked and shown (a library
name or the user's own TOML or JSON file)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .app import BadInput, SubcommandGroup, app
from .common import check_outputs, emit, say
from .options import Output, format_option


models_app = typer.Typer(
    cls=SubcommandGroup,
    help="The library of models (bodies, joints, loads as TOML files); 'fdbench models show NAME|FILE' checks and "
    "shows one, your own file included.",
    invoke_without_command=True,
)
app.add_typer(models_app, name="models")

LIST_FORMATS = ("table", "json", "csv")
SHOW_FORMATS = ("table", "json", "toml")


@models_app.callback()
def list_models(
    ctx: typer.Context,
    fmt: Annotated[str, format_option(LIST_FORMATS, "Output: table (for a person), json or csv.")] = "table",
    output: Output = None,
):
    """One line per library model: its name, bodies, joints (its coordinates), total mass and what it is."""
    if ctx.invoked_subcommand is not None:
        return
    from ..models import library

    check_outputs(fmt, LIST_FORMATS, output=output)
    rows = [_summary(_checked(name)) for name in library()]
    if fmt == "json":
        text = json.dumps(rows, indent=2) + "\n"
    elif fmt == "csv":
        from ..files import csv_text

        text = csv_text(list(rows[0]), [[" ".join(v) if isinstance(v, list) else v for v in row.values()] for row in rows])
    else:
        from .store_commands import text_table

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
    from ..models import is_osim
    from ..models import find_model

    try:
        if is_osim(name_or_path):  # an OpenSim model: its import's notes as warnings
            from ..multibody.osim import import_osim

            found, notes = import_osim(name_or_path, option="NAME|FILE")
            for note in notes:
                say(False, f"[yellow]warning:[/] {note}")
            return found
        return find_model(name_or_path, "NAME|FILE")
    except ValueError as exc:
        raise BadInput(str(exc)) from None


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


def _show_text(model, source: str) -> str:
    from ..multibody.model import end_of
    from .common import render
    from .store_commands import text_table

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
    text = render(header, "table", f"model {model.name}")
    text += text_table("bodies (kg, m, kg m^2 about the centre of mass; end: second point of natural coordinates)",
                   bodies, list(bodies[0]))
    text += text_table("joints in order (m, rad)", joints, list(joints[0]))
    if loads:
        text += text_table("loads (m in the body's frame, N in world axes)", loads, list(loads[0]))
    return text + _muscles_text(model) + _motions_text(model) + _keys_text(model) + _paths_text(model)


def _muscles_text(model) -> str:
    """The muscles: constants and path (the bodies of its points, or the coordinates of its polynomial)."""
    from .store_commands import text_table

    rows = [{"name": m.name, "F_max (N)": f"{m.max_isometric_force:.6g}",
             "l_opt (m)": f"{m.optimal_fiber_length:.6g}", "l_slack (m)": f"{m.tendon_slack_length:.6g}",
             "tendon": m.tendon, "path": (f"points on {', '.join(p.body for p in m.path.points)}"
                                          if hasattr(m.path, "points") else
                                          f"polynomial in {', '.join(m.path.coordinates)} ({len(m.path.terms)} terms)")}
            for m in model.muscles]
    if not rows:
        return ""
    return text_table("muscles (max isometric force, optimal fibre length, tendon slack length)", rows, list(rows[0]))


def _joint_type(joint) -> str:
    """'pin', 'pin on a path (n samples)' or 'free (angle, x, y)'."""
    if joint.type == "free":
        return f"free ({', '.join(joint.coordinates)})"
    return joint.type + (f" on a path ({len(joint.path.angles)} samples)" if joint.path is not None else "")


def _motions_text(model) -> str:
    """The named motions (the first the default): each coordinate's start -> goal in degrees (an
    angle) or metres (a translation)."""
    import math

    from .store_commands import text_table

    kinds = dict(zip(model.coordinates, model.coordinate_kinds))

    def span(joint, a, b):
        if kinds.get(joint) == "translation":
            return {f"{joint} (m)": f"{a:.4g} -> {b:.4g}"}
        return {f"{joint} (deg)": f"{math.degrees(a):.4g} -> {math.degrees(b):.4g}"}

    rows = [{"name": m.name + (" (default)" if i == 0 else ""), "type": m.type, "duration (s)": f"{m.duration:.6g}"}
            | {key: value for (joint, a), (_, b) in zip(m.start, m.goal) for key, value in span(joint, a, b).items()}
            for i, m in enumerate(model.motions)]
    return text_table("motions (--motion NAME; from rest to rest)", rows, list(rows[0])) if rows else ""


def _path_values(model) -> dict:
    """{path: its value in this model (SI units, rad)}: every path --model PATH=VALUE, --plant and
    study mismatch --param take."""
    from ..multibody.model import change_paths
    from ..multibody.model_changes import path_value

    return {path: path_value(model, path) for path in change_paths(model)}


def _paths_text(model) -> str:
    from .store_commands import text_table

    rows = [{"path": path, "value": f"{value:.6g}"} for path, value in _path_values(model).items()]
    return text_table("paths (--model PATH=VALUE)", rows, ["path", "value"])


def _keys_text(model) -> str:
    """The short keys of --model KEY=VALUE: the path each sets and its value in this model."""
    from ..multibody.model_changes import short_key_values
    from .store_commands import text_table

    values = short_key_values(model)
    rows = [{"key": name, "path": target, "value": f"{values[name]:.6g}"} for name, target in model.keys]
    return text_table("short keys (--model KEY=VALUE)", rows, list(rows[0])) if rows else ""


_END_ORIGIN = {"joint": "first child joint", "load": "farthest load", "com": "centre of mass",
               "default": "1 m along x"}
