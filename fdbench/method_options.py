"""A method's options: those its registered class takes (its keyword arguments), checked by name
so that a misspelt option is an error, not silently dropped."""

from __future__ import annotations

from dataclasses import dataclass


def accepted_options(registry, name, options, kind: str) -> tuple:
    """The options given (not None) as sorted (name, value) pairs, checked by ``check_method_options``."""
    options = {k: v for k, v in (options or {}).items() if v is not None}
    check_method_options(registry, name, options, kind)
    return tuple(sorted(options.items()))


def taken_options(registry, name) -> list:
    """The option names the class registered as ``name`` takes (none for an unknown name)."""
    import inspect

    return list(inspect.signature(registry[name]).parameters) if name in registry else []


def check_method_options(registry, name, options, kind: str) -> None:
    """ValueError naming an option the class registered as ``name`` does not take, and those it
    takes (a misspelt ``knot`` is not silently dropped). An unknown ``name`` is left to
    ``RunSpec.validate``."""
    if name not in registry:
        return
    taken = taken_options(registry, name)
    unknown = [key for key in options if key not in taken]
    if unknown:
        raise ValueError(f"{kind} {name!r} takes no option {unknown[0]!r}; it takes "
                         f"{', '.join(taken) if taken else 'none'}")


def options_for(registry, name, options) -> dict:
    """Of one set of options shared by several methods (a sweep's), those the class registered
    as ``name`` takes."""
    taken = taken_options(registry, name)
    return {k: v for k, v in (options or {}).items() if k in taken}


def options_text(pairs) -> str:
    """(name, value) pairs as text: 'hidden=4 knots=11'."""
    return " ".join(f"{k}={v}" for k, v in pairs)


@dataclass(frozen=True)
class MethodOption:
    """How the command line offers one option of a registered method as a flag of its own,
    ``--<name>`` (underscores as dashes): its help (the method's name is put before it), the type
    of its value, the command's default (None: the method's own default; not shown unless
    ``show_default``), and a metavar where the type says too little. A method declares them in
    its class attribute ``command_line`` ({option: MethodOption}); any option its class takes is
    also given in brackets, ``NAME[KEY=VALUE,...]``."""

    help: str
    type: type = float
    default: object = None
    show_default: bool = True
    metavar: str | None = None


def command_line_options(registry, only=None) -> dict:
    """{option: (MethodOption, names of the methods declaring it)} of the registered methods
    (those named in ``only``, if given), in the registry's order; the first declaration of an
    option shared by several methods gives its help."""
    found: dict = {}
    for name, cls in registry.items():
        if only is not None and name not in only:
            continue
        for option, declared in getattr(cls, "command_line", {}).items():
            first, names = found.get(option, (declared, []))
            found[option] = (first, [*names, name])
    return found
