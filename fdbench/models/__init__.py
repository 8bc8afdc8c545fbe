"""The models fdbench simulates, by name or file, all on the multibody engine (``fdbench.multibody``).

* The library (``library/*.toml``): ``forearm`` (Table 1's 1-DOF forearm, the paper's model and the
  default; its motions are eq. 5's ``paper`` and ``exact``, which serve any one-joint model),
  ``arm2``, ``leg3``; and any model file (TOML or JSON, ``fdbench.multibody.description``), with the
  motions the file declares (or a CSV file) and its short keys (``[keys]``) or paths into the
  description for ``--model``/``--plant KEY=VALUE``.
* An OpenSim model file (``.osim``): converted on the fly by ``fdbench.multibody.osim`` (cached by
  content), its notes given by ``import_notes``.
"""

from __future__ import annotations

import os
from functools import lru_cache

PAPER = "forearm"
SUFFIXES = (".toml", ".json", ".osim")


def names() -> list[str]:
    """The models known by name: the paper's forearm, then the library's other models."""
    from ..multibody.description import library

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
    from ..registry import unknown_name_message

    raise ValueError(unknown_name_message("model", name, names()) + "; or give a model file (.toml, .json or .osim)")


def description(name: str):
    """The ``fdbench.multibody.description.Model`` of a library name or model file (a file is read
    again when its content changed). The forearm's is the library's forearm.toml."""
    from ..multibody.description import library

    if name in library():
        return _described(name, None)
    from ..files import read_input_bytes

    return _described(name, read_input_bytes(name, "--model"))


@lru_cache(maxsize=32)
def _described(name: str, content: bytes | None):
    if content is not None and is_osim(name):
        return _imported(name, content)[0]
    from ..multibody.description import find_model

    return find_model(name, "--model")


def is_osim(name: str) -> bool:
    """True for an OpenSim model file's name (.osim)."""
    return name.lower().endswith(".osim") and name not in names()


def import_notes(name: str) -> tuple[str, ...]:
    """The notes of an OpenSim model's import (what was dropped, welded, projected; one line
    each), none for other models."""
    if not is_osim(name):
        return ()
    from ..files import read_input_bytes

    return _imported(name, read_input_bytes(name, "--model"))[1]


@lru_cache(maxsize=8)
def _imported(name: str, content: bytes):
    """(Model, notes) of an OpenSim model file's content (``name`` names it in messages)."""
    from ..multibody.osim import import_osim_content

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
    from ..motion import KINEMATICS

    model = description(name)
    own = tuple(motion.name for motion in model.motions)
    return own + (tuple(KINEMATICS) if len(model.coordinates) == 1 else ())  # eq. 5's serve any one joint


def default_motion(name: str) -> str:
    """The motion a command of model ``name`` follows when none is given."""
    motions = named_motions(name)
    if not motions:
        raise ValueError(f"--motion: model {name} declares no motion; give a CSV file t,"
                         f"{','.join(joints(name))}")
    return motions[0]


def model_keys(name: str) -> tuple:
    """The constants of model ``name`` that --model and --plant KEY=VALUE may change."""
    from ..multibody.description import change_paths

    model = description(name)
    return tuple(name for name, _ in model.keys) + tuple(change_paths(model))


def with_changes(name: str, pairs=()):
    """The description (``Model``) of model ``name`` with some constants changed ((key, value) pairs of
    short keys or paths); ValueError if out of range."""
    from ..multibody.description import with_short_keys

    return with_short_keys(description(name), tuple(pairs))


def value_of(name: str, model, key: str) -> float:
    """The value of constant ``key`` (a short key or a path) in ``model`` (from ``with_changes``)."""
    from ..multibody.description import path_value, short_key_values

    values = short_key_values(model)
    return values[key] if key in values else path_value(model, key)


