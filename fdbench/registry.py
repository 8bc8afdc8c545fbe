"""A name -> factory mapping that registers by decorator and refuses a name collision."""

from __future__ import annotations

import difflib
import re
from typing import Callable, Generic, Iterator, TypeVar

T = TypeVar("T")


class UnknownName(ValueError):
    """A name that is not registered; the message lists the valid names."""


class Registry(Generic[T]):
    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, T] = {}

    def register(self, name: str) -> Callable[[T], T]:
        """Decorator: ``@TORQUES.register("cs")`` above a class."""

        def add(entry: T) -> T:
            if name in self._entries:
                raise ValueError(f"{self.kind} {name!r} is already registered")
            self._entries[name] = entry
            return entry

        return add

    def unregister(self, name: str) -> None:
        self._entries.pop(name, None)

    def __getitem__(self, name: str) -> T:
        try:
            return self._entries[name]
        except KeyError:
            raise UnknownName(unknown_name_message(self.kind, name, list(self._entries))) from None

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def items(self):
        return self._entries.items()


def parse_method(text: str, option: str) -> tuple[str, dict]:
    """A method named with its options, as benchopt writes them: ``cmaes[sigma0=0.1,popsize=12]`` ->
    ('cmaes', {'sigma0': 0.1, 'popsize': 12}); a bare name has none. Values are integers, numbers,
    true/false or text. ValueError (one line naming ``option``) for anything else."""
    match = re.fullmatch(r"\s*([^\[\]\s]+)\s*(?:\[(.*)\])?\s*", str(text), re.S)
    if match is None:
        raise ValueError(f"{option}: expected NAME or NAME[KEY=VALUE,...], got {text!r}")
    name, body = match.groups()
    options = {}
    for item in [] if body is None or not body.strip() else body.split(","):
        key, sep, value = (part.strip() for part in item.partition("="))
        if not sep or not key.isidentifier() or not value:
            raise ValueError(f"{option}: expected KEY=VALUE inside {name}[...], got {item.strip()!r}")
        if key in options:
            raise ValueError(f"{option}: {name}[...] gives {key} twice")
        options[key] = option_value(value)
    return name, options


def option_value(text: str):
    """A method option's value from its text: an integer, a number, true/false, or the text itself."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def unknown_name_message(kind: str, name: str, valid: list[str]) -> str:
    """'unknown torque 'cx'; valid: ann, cs, pf (did you mean 'cs'?)'."""
    text = f"unknown {kind} {name!r}; valid: {', '.join(valid)}"
    close = difflib.get_close_matches(str(name), valid, n=1)
    return text + (f" (did you mean {close[0]!r}?)" if close else "")


PLUGINS_VARIABLE = "FDBENCH_PLUGINS"
ENTRY_POINT_GROUP = "fdbench.plugins"
_plugins_loaded = False


class PluginError(ImportError):
    """A plugin module that cannot be imported; the message names it."""


def load_plugins() -> None:
    """Import, once, the modules that register extra torques or optimisers: those named in
    $FDBENCH_PLUGINS (comma-separated module names) and the entry points of the group
    ``fdbench.plugins`` of installed packages."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    import contextlib
    import importlib
    import os
    import sys

    names = [n.strip() for n in os.environ.get(PLUGINS_VARIABLE, "").split(",") if n.strip()]
    for name in names:
        try:
            with contextlib.redirect_stdout(sys.stderr):  # a plugin's prints never mix with results
                importlib.import_module(name)
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - any failure of a plugin, sys.exit included
            raise PluginError(f"{PLUGINS_VARIABLE}: cannot import {name!r}: {_failure(exc)}") from None
    from importlib.metadata import entry_points

    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            with contextlib.redirect_stdout(sys.stderr):
                entry.load()
        except (Exception, SystemExit) as exc:  # noqa: BLE001
            raise PluginError(f"plugin {entry.name!r} ({entry.value}): cannot load: {_failure(exc)}") from None


def _failure(exc: BaseException) -> str:
    if isinstance(exc, SystemExit):
        return f"it called sys.exit({exc.code!r}) while being imported"
    return f"{type(exc).__name__}: {exc}" if not str(exc) else str(exc)
