"""The models fdbench simulates, by name or file, all on the multibody engine (``fdbench.multibody``),
and the one dispatcher from a name or a file's suffix to its ``Model`` (``find_model``):

* The library (``library/*.toml``): ``forearm`` (Table 1's 1-DOF forearm, the paper's model and the
  default; its named motions are eq. 5's ``paper`` and ``exact``), ``arm2``, ``leg3``;
* any model file, TOML or JSON (``fdbench.multibody.model_files``), with the motions the file
  declares (or a CSV file) and its short keys (``[keys]``) or paths into the model for
  ``--model``/``--plant KEY=VALUE`` (``fdbench.multibody.model_changes``);
* an OpenSim model file (``.osim``): converted on the fly by ``fdbench.multibody.osim`` (cached by
  content), its notes given by ``import_notes``.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

from ..files import read_input_bytes
from ..multibody.model import Model, ModelError
from ..multibody.model_changes import change_paths, path_value, short_key_values, with_short_keys
from ..multibody.model_files import load_model
from ..multibody.osim import import_osim, import_osim_content
from ..registry import unknown_name_message

PAPER = "forearm"
SUFFIXES = (".toml", ".json", ".osim")
LIBRARY = Path(__file__).resolve().parent / "library"


def library() -> dict[str, Path]:
    """The built-in models: name -> its TOML file, sorted by name."""
    return {path.stem: path for path in sorted(LIBRARY.glob("*.toml"))}


def find_model(name_or_path, option: str = "model file") -> Model:
    """A library model by name, or the model of a file by its suffix: OpenSim's .osim
    (``fdbench.multibody.osim``), otherwise TOML or JSON (``model_files.load_model``). ModelError
    (listing the library's names) for a name that is neither."""
    text = str(name_or_path)
    models = library()
    if text in models:
        return load_model(models[text], option)
    if text and (Path(text).exists() or "/" in text or Path(text).suffix.lower() in SUFFIXES):
        if Path(text).suffix.lower() == ".osim":
            return import_osim(text, option=option)[0]
        return load_model(text, option)
    raise ModelError(option, "", unknown_name_message("model", text, list(models))
                     + "; or give a model file (.toml, .json or OpenSim's .osim)")


def names() -> list[str]:
    """The models known by name: the paper's forearm, then the library's other models."""
    return [PAPER] + [name for name in library() if name != PAPER]


def is_file(name: str) -> bool:
    """True when ``name`` is not a library name but a model file's path."""
    return name not in names()


def check_name(name: str) -> str:
    """``name`` if it is a known model or a readable model file; ValueError (one line) otherwise."""
    if name in names():
        return name
    if name and (os.path.exists(name) or name.lower().endswith(SUFFIXES) or "/" in name):
        description(name)  # a ModelError (a ValueError) names the file, the key and what is allowed
        return name
    raise ValueError(unknown_name_message("model", name, names()) + "; or give a model file (.toml, .json or .osim)")


def description(name: str):
    """The ``fdbench.multibody.model.Model`` of a library name or model file (a file is read
    again when its content changed). The forearm's is the library's forearm.toml."""
    if name in library():
        return _described(name, None)
    return _described(name, read_input_bytes(name, "--model"))


@lru_cache(maxsize=32)
def _described(name: str, content: bytes | None):
    if content is not None and is_osim(name):
        return _imported(name, content)[0]
    return find_model(name, "--model")


def is_osim(name: str) -> bool:
    """True for an OpenSim model file's name (.osim)."""
    return name.lower().endswith(".osim") and name not in names()


def import_notes(name: str) -> tuple[str, ...]:
    """The notes of an OpenSim model's import (what was dropped, welded, projected; one line
    each), none for other models."""
    if not is_osim(name):
        return ()
    return _imported(name, read_input_bytes(name, "--model"))[1]


@lru_cache(maxsize=8)
def _imported(name: str, content: bytes):
    """(Model, notes) of an OpenSim model file's content (``name`` names it in messages)."""
    return import_osim_content(content, name)


def summary(name: str) -> str:
    """One line saying what the model ``name`` is."""
    return description(name).description or f"model file {name}"


def joints(name: str) -> tuple[str, ...]:
    """The joints (coordinates) of model ``name``, in the model's order: columns of its files."""
    return tuple(description(name).coordinates)


def n_joints(name: str) -> int:
    return len(joints(name))


def named_motions(name: str) -> tuple:
    """The motions model ``name`` knows by name, its default first (any other is a CSV file)."""
    return tuple(motion.name for motion in description(name).motions)


def default_motion(name: str) -> str:
    """The motion a command of model ``name`` follows when none is given."""
    motions = named_motions(name)
    if not motions:
        raise ValueError(f"--motion: model {name} declares no motion; give a CSV file t,"
                         f"{','.join(joints(name))}")
    return motions[0]


def model_keys(name: str) -> tuple:
    """The constants of model ``name`` that --model and --plant KEY=VALUE may change."""
    model = description(name)
    return tuple(name for name, _ in model.keys) + tuple(change_paths(model))


def with_changes(name: str, pairs=()):
    """The description (``Model``) of model ``name`` with some constants changed ((key, value) pairs of
    short keys or paths); ValueError if out of range."""
    return with_short_keys(description(name), tuple(pairs))


def value_of(name: str, model, key: str) -> float:
    """The value of constant ``key`` (a short key or a path) in ``model`` (from ``with_changes``)."""
    values = short_key_values(model)
    return values[key] if key in values else path_value(model, key)


