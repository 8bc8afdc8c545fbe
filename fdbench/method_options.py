"""A method's options: those its registered class takes (its keyword arguments), checked by name
so that a misspelt option is an error, not silently dropped."""

from __future__ import annotations


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
