"""Model files: a ``Model`` (``fdbench.multibody.model``) read from a TOML or JSON file (the same
keys) and written back as TOML."""

from __future__ import annotations

import json
from pathlib import Path

from ..files import read_input_text
from .model import MAX_FILE_BYTES, Model, ModelError, model_from_dict, to_dict


def load_model(path, option: str = "model file") -> Model:
    """The checked model of a TOML or JSON file (by its suffix; otherwise JSON if it starts with
    '{'). ModelError or BadFile (both ValueError, one line naming the file) if it cannot be used.
    ``fdbench.models.find_model`` also takes library names and OpenSim models (.osim)."""
    source = str(path)
    suffix = Path(source).suffix.lower()
    text = read_input_text(path, option, MAX_FILE_BYTES)
    is_json = suffix == ".json" or (suffix != ".toml" and text.lstrip().startswith("{"))
    data = _parse_json(text, source) if is_json else _parse_toml(text, source)
    return model_from_dict(data, source, default_name=Path(source).stem)


def _parse_toml(text: str, source: str):
    try:
        import tomllib
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib
        except ImportError:
            raise ModelError(source, "", "reading TOML needs Python 3.11 or the tomli package; "
                             "write the model as JSON (the same keys)") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(source, "", f"not valid TOML: {exc}") from None
    except ValueError:  # an integer of thousands of digits, beyond Python's limit for reading one
        raise ModelError(source, "", "not valid TOML: a number too long to read") from None
    except RecursionError:
        raise ModelError(source, "", "not valid TOML: nested too deeply") from None


def _parse_json(text: str, source: str):
    def unique_keys(pairs):
        found = dict(pairs)
        if len(found) < len(pairs):  # linear: a set of the keys seen, not a count per key
            seen = set()
            key = next(key for key, _ in pairs if key in seen or seen.add(key))
            raise ModelError(source, "", f"the key {key!r} appears twice in one object; give it once")
        return found

    try:
        return json.loads(text, parse_int=float, object_pairs_hook=unique_keys)
    except json.JSONDecodeError as exc:
        raise ModelError(source, "", f"not valid JSON: {exc}") from None
    except RecursionError:
        raise ModelError(source, "", "not valid JSON: nested too deeply") from None


def to_toml(model: Model, explicit_ends: bool = False) -> str:
    """The model as a TOML file that load_model reads back to an equal Model."""
    data = to_dict(model, explicit_ends)
    lines = [f"{key} = {_toml_value(data[key])}" for key in ("name", "description", "gravity") if key in data]
    for section in ("bodies", "joints", "loads", "motions", "frames", "muscles", "actuators"):
        for entry in data.get(section, []):
            lines += ["", f"[[{section}]]"] + [f"{key} = {_toml_value(value)}" for key, value in entry.items()]
    if "keys" in data:
        lines += ["", "[keys]"] + [f"{key} = {_toml_value(value)}" for key, value in data["keys"].items()]
    return "\n".join(lines) + "\n"


def _toml_value(value) -> str:
    import json

    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):  # names of joints: bare keys
        return "{ " + ", ".join(f"{key} = {_toml_value(v)}" for key, v in value.items()) + " }"
    if isinstance(value, int) and not isinstance(value, bool):  # a muscle path's powers
        return str(value)
    return repr(float(value))
