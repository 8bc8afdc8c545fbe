"""``fdbench import-osim`` and ``export-osim``: OpenSim models (.osim) to fdbench's model files (TOML) and back."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .app import BadInput, app, bad_input
from .common import check_outputs, emit, say, wrote
from .options import Output, Quiet

MAX_TILT_HELP = ("Largest angle (deg, in [0, 45]) by which a joint axis, a child frame or gravity may be off the "
                 "plane's normal (z) and still be projected onto it; beyond it the import stops naming the joint.")
MAX_PATH_ERROR_HELP = ("Largest error (mm) of a muscle's path against OpenSim's lengths at 200 random states within the "
                       "coordinates' ranges; beyond it the import stops naming the muscle.")


@app.command("import-osim")
def import_osim_command(
    model: Annotated[Path, typer.Argument(metavar="MODEL.osim", help="An OpenSim model file.", show_default=False)],
    output: Output = None,
    max_tilt: Annotated[float, typer.Option("--max-tilt", help=MAX_TILT_HELP)] = 5.0,
    max_path_error: Annotated[float, typer.Option("--max-path-error", help=MAX_PATH_ERROR_HELP)] = 3.0,
    quiet: Quiet = False,
):
    """Convert an OpenSim model into fdbench's model file (TOML, with the notes of the import as comments at the top): bodies, pin joints named by their coordinates, gravity, ranges as limits; welded bodies merged; muscles as De Groote muscles, their paths as points or as polynomials fitted to OpenSim's lengths (checked against OpenSim, the errors in the notes); markers, contact geometry and other forces dropped. Needs pip install 'fdbench\\[opensim]'. '--model MODEL.osim' on any command converts the model on the fly."""
    check_outputs("toml", ("toml",), inputs={"MODEL.osim": model}, output=output)
    if not 0 <= max_tilt <= 45:
        raise BadInput(f"--max-tilt: must be in [0, 45] deg, got {max_tilt:g}")
    if not 0 < max_path_error <= 1000:
        raise BadInput(f"--max-path-error: must be in (0, 1000] mm, got {max_path_error:g}")
    from ..multibody.osim import import_osim, toml_text

    with bad_input():
        found, notes = import_osim(model, max_tilt, option="MODEL.osim", max_path_error=max_path_error / 1e3)
    emit(toml_text(found, notes, model), output)
    for note in notes:
        say(quiet, f"[yellow]warning:[/] {note}")
    wrote(output, quiet)


@app.command("export-osim")
def export_osim_command(
    model: Annotated[str, typer.Argument(metavar="NAME|FILE", help="A library model's name or a model file (.toml, .json, or OpenSim's .osim).", show_default=False)],
    output: Output = None,
    quiet: Quiet = False,
):
    """Write a model as an OpenSim model file (.osim, OpenSim 4): one Body, PinJoint (its coordinate named as the joint) and CoordinateActuator per body and joint, gravity, each load a constant PrescribedForce. OpenSim's inverse dynamics of the file equals fdbench's; 'fdbench import-osim' reads it back. Needs no OpenSim, except for an .osim input."""
    from ..models import find_model, library

    # a library model's file is an input too: the output may not write over it
    check_outputs("osim", ("osim",), inputs={"NAME|FILE": library().get(model, Path(model))}, output=output)
    from ..multibody.osim import check_exportable, to_osim

    with bad_input():
        found = find_model(model, "NAME|FILE")
        check_exportable(found)
    emit(to_osim(found), output)
    wrote(output, quiet)
