"""The conditions of a run, declared once: the motion's options (its file's units, the derivative
estimate, noise, sampling) and the model's (--model, --plant, --model-file, --loads), added to a
command by ``with_conditions``, which hands them over as one dict ``conditions`` of RunSpec
fields; and the RunSpec fields every command that simulates shares (``run_fields``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .app import BadInput, bad_input

MOTION_PANEL = "Motion and model"


CONDITIONS = {
    "radians": (bool, False, typer.Option("--radians", rich_help_panel=MOTION_PANEL, help="The motion file's angles (and derivatives) are in radians, not degrees; also reads an older fdbench's files, whose <joint>_dot and <joint>_ddot columns are then the rates (rad/s, rad/s^2).")),
    "cutoff_hz": (float, 6.0, typer.Option("--cutoff", rich_help_panel=MOTION_PANEL, help="Derivative estimate: -3 dB frequency (Hz) of the zero-lag 4th-order Butterworth low-pass (Winter's), applied to a recorded or noisy angle before an interpolating spline is differentiated.")),
    "smoothing": (str, "butterworth", typer.Option("--smoothing", rich_help_panel=MOTION_PANEL, help="Derivative estimate: 'butterworth' (low-pass, then spline) or 'spline' (a smoothing spline, factor by generalised cross-validation or --spline-lambda).")),
    "spline_lambda": (Optional[float], None, typer.Option("--spline-lambda", rich_help_panel=MOTION_PANEL, help="Smoothing factor of --smoothing spline (> 0; default: chosen by generalised cross-validation).", show_default=False)),
    "sample_dt": (Optional[float], None, typer.Option("--sample-dt", rich_help_panel=MOTION_PANEL, help="Report the histories and indicators every SAMPLE_DT s (default: the motion's own samples; eq. 5: 1 ms).", show_default=False)),
    "noise_deg": (float, 0.0, typer.Option("--noise-deg", rich_help_panel=MOTION_PANEL, help="White Gaussian noise (deg, in [0, 45], seeded by --seed) added to the captured angles (a free joint's translations stay noise-free) before the derivative estimate; indicators stay measured against the noise-free motion.")),
    "capture_hz": (float, 100.0, typer.Option("--capture-hz", rich_help_panel=MOTION_PANEL, help="Capture rate (Hz) of the noisy samples of 'paper' or 'exact' (a file keeps its own samples).")),
    "plant": (Optional[list[str]], None, typer.Option("--plant", metavar="KEY=VALUE", rich_help_panel=MOTION_PANEL, help="KEY=VALUE (repeatable): change the simulated body only (keys L12, L1G, m, I1, F_ext, g; arm2 also L01, L0G, m0, I0; any model: a path such as thigh.mass; SI units); inverse dynamics and model-based controllers keep the nominal model.", show_default=False)),
    "model": (Optional[list[str]], None, typer.Option("--model", metavar="NAME|FILE|KEY=VALUE", rich_help_panel=MOTION_PANEL, help="The model: forearm (Table 1, default), a library model (arm2: shoulder + elbow; leg3: hip, knee, ankle; see 'fdbench models') or your own model file (.toml or .json, see 'fdbench models show FILE'), whose motions are its named ones or a CSV file t,<joint>...; and KEY=VALUE (repeatable) changes of its constants for the nominal model and the simulated body (forearm: keys as --plant; arm2: L01, L0G, m0, I0 and the forearm's; any model: a path such as thigh.mass or knee.at_parent.x).", show_default=False)),
    "loads": (Optional[Path], None, typer.Option("--loads", metavar="FILE.xml", rich_help_panel=MOTION_PANEL, help="External loads from data, e.g. a walk's measured ground reactions: OpenSim's ExternalLoads file (the body each force acts on, the frames of its force and point, the columns of its data file, a .mot or .sto), applied at every stage of the simulation and in inverse dynamics; its content and its data file's are part of the run's identity.", show_default=False)),
    "model_file": (Optional[Path], None, typer.Option("--model-file", rich_help_panel=MOTION_PANEL, help="TOML or JSON file of KEY = VALUE pairs setting the nominal model (--model applies on top).", show_default=False)),
}


_SAID: set = set()  # the warnings of ``warn_opensim`` said during the current command


def with_conditions(command):
    """Add the CONDITIONS options to a command; it receives them as ``conditions`` (a dict of
    RunSpec fields, the model's name among them), the motion and model files among
    ``conditions['_inputs']``, and ``kinematics`` set to the model's default motion if not given."""
    import functools
    import inspect

    signature = inspect.signature(command, eval_str=True)  # the annotations as objects, as typer reads them
    added = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default,
                               annotation=Annotated[kind, option])
             for name, (kind, default, option) in CONDITIONS.items()]
    kept = [p for p in signature.parameters.values() if p.name != "conditions"]

    @functools.wraps(command)
    def wrapper(**kwargs):
        values = {name: kwargs.pop(name) for name in CONDITIONS}
        _SAID.clear()
        conditions = _conditions(**values)
        _warn_implausible(conditions, kwargs.get("quiet", False))
        if kwargs.get("kinematics") is None:
            from ..models import default_motion

            with bad_input():
                kwargs["kinematics"] = default_motion(conditions["model_name"])
        returned = command(conditions=conditions, **kwargs)
        warn_opensim(conditions["model_name"], kwargs.get("kinematics"), kwargs.get("quiet", False))
        return returned

    wrapper.__signature__ = signature.replace(parameters=kept + added)
    wrapper.__annotations__ = {p.name: p.annotation for p in kept + added}
    return wrapper


def _warn_implausible(conditions: dict, quiet: bool) -> None:
    """A warning on stderr for each constant a human arm cannot have (the run goes on); constants
    that are refused outright (a negative mass) are left to the error that follows."""
    from ..plausible import implausible
    from ..models import with_changes

    try:
        with_changes(conditions["model_name"], conditions["model"] + conditions["plant"])
    except ValueError:
        return

    import sys

    for option, pairs in (("--model", conditions["model"]), ("--plant", conditions["plant"])):
        for text in [] if quiet else implausible(pairs):
            sys.stderr.write(f"fdbench: warning: {option}: {text}\n")


def warn_opensim(model_name: str, kinematics: str, quiet: bool) -> None:
    """Warnings on stderr once a command has run (a refused one says one line only): the notes of
    an OpenSim model's import (--model X.osim) and the columns of an OpenSim motion file (.mot,
    .sto) that the model lacks. Each is said once per command: a long command says them before its
    work, once its input is checked (the walk's report), and not again at its end."""
    import sys

    from ..models import import_notes, joints
    from ..multibody.osim import storage_note

    notes = [f"--model: {note}" for note in import_notes(model_name)]
    notes += [f"--motion: {note}" for note in [storage_note(kinematics, joints(model_name))] if note]
    for note in [] if quiet else notes:
        if note not in _SAID:
            _SAID.add(note)
            sys.stderr.write(f"fdbench: warning: {note}\n")


def _conditions(plant, model, loads, model_file, **motion) -> dict:
    """RunSpec fields from the CONDITIONS options (KEY=VALUE pairs parsed, the model file read)."""
    from ..models import is_file

    names = [item.strip() for item in model or [] if "=" not in item]
    pairs = _model_file(model_file) if model_file is not None else []
    pairs += _key_values("--model", [item for item in model or [] if "=" in item])
    name, plant = _model_name(names), tuple(_key_values("--plant", plant or []))
    inputs = {"--model-file": model_file, **({"--model": Path(name)} if is_file(name) else {}), **_loads_inputs(loads)}
    return dict(motion, plant=plant, model=tuple(pairs), _inputs=inputs, model_name=name,
                **({"loads": str(loads)} if loads is not None else {}))


def _loads_inputs(loads) -> dict:
    """{'--loads': the file, '--loads data': its data file}: inputs the outputs must not overwrite."""
    if loads is None:
        return {}
    from ..multibody.loads import data_file

    return {"--loads": Path(loads), "--loads (its data file)": data_file(loads)}


def _model_name(names: list) -> str:
    """The one model named by --model (default: forearm): a library name or a model file."""
    from ..models import check_name, names as library_names

    if len(set(names)) > 1:
        raise BadInput(f"--model: name one model, got {', '.join(names)}")
    name = names[0] if names else "forearm"
    try:
        return check_name(name)
    except ValueError as exc:
        known = name in library_names() or not name or not any(c in name for c in "./")
        message = str(exc) if str(exc).startswith("--model") else f"--model: {exc}"
        raise BadInput(message + (" (or KEY=VALUE)" if known else "")) from None


def _key_values(option: str, items) -> list:
    pairs = []
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise BadInput(f"{option}: expected KEY=VALUE (keys L12, L1G, m, I1, F_ext, g; arm2 also L01, L0G, m0, I0; "
                           f"any model: a path such as thigh.mass, see 'fdbench models show'), got {item!r}")
        try:
            pairs.append((key.strip(), float(value)))
        except ValueError:
            raise BadInput(f"{option}: {key.strip()} must be a number, got {value!r}") from None
    return pairs


def _model_file(path: Path) -> list:
    """(key, value) pairs of a TOML or JSON model file (a table of numbers, or one table of them)."""
    from ..files import parse_json, read_input_text

    text = read_input_text(path, "--model-file", 2**20)
    try:
        if path.suffix.lower() == ".json":
            data = parse_json(text)
        else:
            import tomllib

            data = tomllib.loads(text)
    except (ValueError, RecursionError) as exc:
        raise BadInput(f"--model-file: cannot read {path} as {'JSON' if path.suffix.lower() == '.json' else 'TOML'}: "
                       f"{' '.join(str(exc).split())[:200]}") from None
    if isinstance(data, dict) and len(data) == 1 and isinstance(next(iter(data.values())), dict):
        data = next(iter(data.values()))  # [forearm] L12 = 0.3 ...
    if not isinstance(data, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                             for v in data.values()):
        raise BadInput(f"--model-file: {path} must hold KEY = number pairs (the constants of the model, e.g. I1 = 0.045)")
    return [(str(k), v if isinstance(v, float) else _float(k, v)) for k, v in data.items()]


def _float(key, value: int) -> float:
    """An integer of a model file as a float; one too large for a float is infinite (refused as such)."""
    try:
        return float(value)
    except OverflowError:
        return float("inf") if value > 0 else float("-inf")


def spec_inputs(conditions: dict, kinematics: str, **others) -> dict:
    """The input files of a command (for the output checks): the motion file, the model file, others."""
    from ..models import named_motions

    inputs = dict(conditions.get("_inputs", {}))
    if kinematics not in named_motions(conditions.get("model_name", "forearm")):
        inputs["--motion"] = Path(kinematics)
    return {**inputs, **others}


def run_fields(kinematics, integrator, dt, rtol, atol, alpha, xi, omega, conditions: dict | None = None) -> dict:
    """RunSpec fields shared by every command that simulates (a motion file, a model file and a
    loads file enter by their digests)."""
    import os

    from ..models import is_file, named_motions
    from ..run_inputs import model_digest, motion_digest

    fields = dict(kinematics=kinematics, integrator=integrator, dt=dt, rtol=rtol, atol=atol, alpha=alpha, xi=xi,
                  omega=omega, **{k: v for k, v in (conditions or {}).items() if not k.startswith("_")})
    model = fields.get("model_name", "forearm")
    files = []  # (option, digest of its file, the file)
    if kinematics not in named_motions(model):
        if model != "forearm" and not os.path.exists(kinematics):
            from ..registry import unknown_name_message

            raise BadInput(f"--motion: {unknown_name_message(f'{model} motion', kinematics, list(named_motions(model)))}"
                           f", and no file {kinematics} exists")
        files.append(("--motion", motion_digest, kinematics))
    if is_file(model):
        files.append(("--model", model_digest, model))
    if fields.get("loads") is not None:
        from ..multibody.loads import loads_digest  # only with loads: it imports the engine

        files.append(("--loads", loads_digest, fields["loads"]))
    if files:  # a file that cannot be read: BadFile, bad input
        fields["inputs"] = tuple(sorted((option, digest(path)) for option, digest, path in files))
    return fields


def noise_seed(conditions: dict, seed: int) -> dict:
    """The seed field of a command whose only randomness is the motion's noise (none without it)."""
    return {"seed": seed} if conditions.get("noise_deg") else {}
