"""The ``fdbench`` application: the typer app, its error handling (the command-line contract:
results on stdout, one-line errors on stderr, exit codes 0/1/2/130/141/143) and --help choices."""

from __future__ import annotations

import os
import sys
import time
from contextlib import contextmanager
from typing import Annotated

import typer
from typer.core import TyperGroup

from .. import __version__
from ..registry import PluginError


STARTED = time.perf_counter()
FORMATS = ("table", "json", "csv")  # of the commands of one run
SWEEP_FORMATS = ("md", "csv", "json")  # of report and study


class BadInput(Exception):
    """Bad usage or input: exit code 2 with this one-line message."""


@contextmanager
def bad_input(errors=ValueError, wording=str):
    """The library's ``errors`` raised inside as bad input, their message worded by ``wording``."""
    try:
        yield
    except errors as exc:
        raise BadInput(wording(exc)) from None


# the library's errors that are bad input wherever a command lets them out (by name: none is imported
# before a command needs it), with the words put before their message
LIBRARY_BAD_INPUT = {"StoreError": "--db: ", "BadFile": "", "BackendError": "", "BadQuery": "", "DesignError": ""}


class HelpGroup(TyperGroup):
    """A group of commands whose --help shows choices (registered names; no type noise on flags)."""

    def resolve_command(self, ctx, args):
        # the command about to run (not each one listed by --help, which stays fast)
        name, command, rest = super().resolve_command(ctx, args)
        if command is not None and getattr(ctx.find_root().command, "help_requested", False):
            _show_choices(command, ctx)
        return name, command, rest


class FdbenchGroup(HelpGroup):
    """Routes every error to one line on stderr with the contract's exit codes."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except BrokenPipeError:  # before click turns it into a silent exit code 1
            raise _StdoutClosed from None

    def main(self, args=None, prog_name=None, **extra):
        extra.pop("standalone_mode", None)
        given = sys.argv[1:] if args is None else args
        self.help_requested = any(a in ("-h", "--help") for a in given)
        if any(a in ("-q", "--quiet") for a in given):
            from ..jit import quiet

            quiet()  # no notice of compilation either
        code = 0
        import warnings

        # numerical trouble (overflow in a torque of 1e308...) is reported by a run's status, once
        warnings.filterwarnings("ignore", category=RuntimeWarning)
        try:
            returned = super().main(args=args, prog_name=prog_name or "fdbench", standalone_mode=False, **extra)
            code = returned if isinstance(returned, int) else 0
            if code == 130:
                error("interrupted")
        except (BadInput, PluginError) as exc:
            code = error(str(exc), 2)
        except KeyboardInterrupt:
            code = error("interrupted", 130)
        except (BrokenPipeError, _StdoutClosed):
            code = _closed_stdout()
        except Exception as exc:  # noqa: BLE001 - the contract: one line, never a traceback
            if hasattr(exc, "exit_code") and hasattr(exc, "format_message"):  # click usage errors
                message = exc.format_message().strip()
                if not message:  # no arguments: the help was shown, nothing more to say
                    sys.exit(exc.exit_code)
                context = getattr(exc, "ctx", None)
                where = f"{context.command_path}: " if context is not None else ""
                code = error(where + message, exc.exit_code)
            elif type(exc).__name__ in LIBRARY_BAD_INPUT:  # e.g. an output found unwritable only when written
                code = error(LIBRARY_BAD_INPUT[type(exc).__name__] + str(exc), 2)
            elif _output_full(exc):  # help text into '> /dev/full': as any full output
                _closed_stdout()
                code = error(f"standard output: cannot write: {exc.strerror}", 2)
            elif os.environ.get("FDBENCH_DEBUG"):
                raise
            else:
                code = error(f"{type(exc).__name__}: {exc}", 1)
        sys.exit(_flush_stdout(code))

    def format_help(self, ctx, formatter):
        _show_choices(self, ctx)
        return super().format_help(ctx, formatter)


def subcommands(name: str, help: str, **settings) -> typer.Typer:
    """A group of subcommands of ``fdbench`` (``fdbench runs ...``)."""
    group = typer.Typer(cls=HelpGroup, help=help, **settings)
    app.add_typer(group, name=name)
    return group


# options whose valid values are registered names: (module, name of its registry), read for --help
REGISTERED = {"torque": ("torques", "TORQUES"), "opt": ("optimizers", "OPTIMIZERS"),
              "integrator": ("integrate", "INTEGRATORS"), "smoothing": ("multibody.motions", "SMOOTHING"),
              "backend": ("execution", "BACKENDS"), "controller": ("controllers", "CONTROLLERS"),
              "scheme": ("collocation", "SCHEMES")}


def _choices(name: str, command: str):
    """The valid values of an option, from the registries (plugins included), for --help."""
    import importlib

    if name in REGISTERED:
        module, registry = REGISTERED[name]
        return list(getattr(importlib.import_module(f"fdbench.{module}"), registry))
    if name == "kinematics":
        from ..models import named_motions, names

        found = [motion for model in names() for motion in named_motions(model)]  # the library's, in order
        return list(dict.fromkeys(found)) + ["FILE"]
    if name == "fmt":  # the --format values the command accepts (its help lists exactly these)
        return list(SWEEP_FORMATS if command in ("report", "study") else FORMATS)
    return None


def _escape_help(command) -> None:
    """Help only: the help texts of ``command``, of its options and of its subcommands as plain
    text under rich markup, so that an example in brackets ('cs[knots=21]', '.[dask]') is shown
    as written instead of read as a style tag (each text once)."""
    from rich.markup import escape

    items = [command, *getattr(command, "params", [])] + list(getattr(command, "commands", {}).values())
    for item in items:
        if getattr(item, "_fdbench_escaped", False):
            continue
        item._fdbench_escaped = True
        for attribute in ("help", "short_help"):
            text = getattr(item, attribute, None)
            if isinstance(text, str):  # a bracket escaped by hand ('\\[opensim]') is escaped once
                setattr(item, attribute, escape(text.replace("\\[", "[")))


def _show_choices(command, ctx) -> None:
    """Help only: show registered names as an option's choices ('[ann|cs|pf]') and no type for
    on/off flags (computed when help is asked for, so plugins appear and other commands stay fast);
    texts in brackets shown as written (``_escape_help``)."""
    params = list(command.get_params(ctx) if hasattr(command, "get_params") else [])  # method options made
    _escape_help(command)
    help_option = command.get_help_option(ctx) if hasattr(command, "get_help_option") else None
    for param in params + ([help_option] if help_option is not None else []):
        if getattr(param, "is_flag", False) and getattr(param, "metavar", None) is None:
            param.metavar = ""
            continue
        if getattr(param, "param_type_name", None) != "option" or param.metavar is not None:
            continue
        try:
            choices = _choices(param.name, command.name)
        except PluginError:
            return  # the command itself reports it
        if choices:
            param.metavar = "[" + "|".join(choices) + "]"


class _StdoutClosed(Exception):
    """Standard output was closed (``>&-``): nothing can be written there."""


SIGPIPE_EXIT = 141  # 128 + SIGPIPE: what a shell tool exits with when its reader went away


def write_stdout(text: str) -> None:
    """Write ``text`` to standard output in full and flush it, or raise BrokenPipeError (the
    reader went away) or _StdoutClosed. The bytes go to the binary layer in a loop: with
    unbuffered output (``PYTHONUNBUFFERED``, ``python -u``) the text layer would drop whatever a
    partial write to a pipe left over, and exit 0 with the output cut."""
    stream = sys.stdout
    if stream is None:
        raise _StdoutClosed
    binary = getattr(stream, "buffer", None)
    if binary is None:  # a plain text stream (an embedding application's)
        stream.write(text)
        stream.flush()
        return
    try:
        stream.flush()
        data = memoryview(text.encode(stream.encoding or "utf-8", stream.errors or "strict"))
        while data:
            written = binary.write(data)
            if written is None:  # a non-blocking stdout that is full: wait until it can take more
                import select

                select.select([], [binary.fileno()], [])
                continue
            data = data[written:]
        binary.flush()
    except BrokenPipeError:
        raise
    except OSError as exc:  # '> /dev/full', a full disk: as for '-o FILE', bad output, exit 2
        _closed_stdout()  # what is left in the buffer is dropped, not written again at exit
        raise BadInput(f"standard output: cannot write the results: {exc.strerror or exc}") from None


def _flush_stdout(code: int) -> int:
    """The exit code once standard output is flushed: 141 if the reader went away, which the
    interpreter's own flush at exit would report as a traceback and exit code 120."""
    if code == SIGPIPE_EXIT or sys.stdout is None:
        return code
    try:
        sys.stdout.flush()
    except (BrokenPipeError, ValueError):  # ValueError: stdout closed by the command itself
        return _closed_stdout()
    except OSError as exc:  # a full disk under '> file': the results are not all there
        _closed_stdout()
        return error(f"standard output: cannot write the results: {exc.strerror or exc}", 2)
    return code


def _output_full(exc: BaseException) -> bool:
    """An OSError of a full output (no space, quota, file size limit) raised by click's or
    typer's own writes of the help to standard output."""
    import errno
    import traceback

    if not isinstance(exc, OSError) or exc.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        return False
    return any(frame.name in ("echo", "format_help") and ("click" in frame.filename or "typer" in frame.filename)
               for frame in traceback.extract_tb(exc.__traceback__))


def _closed_stdout() -> int:
    """A reader that stopped reading (``| head``) or a closed stdout is a normal end: no message,
    and no second failure when Python flushes stdout at exit."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
    except OSError:
        pass
    return SIGPIPE_EXIT


def error(message: str, code: int = 1) -> int:
    message = " ".join(message.split())  # one line, whatever a path or a library put in it
    sys.stderr.write(f"fdbench: error: {message}\n")
    sys.stderr.flush()
    return code


app = typer.Typer(
    cls=FdbenchGroup,
    help="Benchmark of trajectory-tracking methods for the forward dynamic simulation of the paper's 1-DOF forearm "
    "and any planar tree of bodies (--model arm2, leg3 or your own model file): feedback control (PD with computed feedforward, computed-torque, LQR), "
    "optimised torque histories (ANN, cubic spline, parametric function by CMA-ES, BFGS and more) and direct "
    "collocation, on eq. 5's motion or your own recording. Results as a table, JSON or CSV "
    "(--format table|json|csv); 'fdbench report' runs the paper's whole comparison and 'fdbench study' sweeps "
    "noise or model mismatch (--format md|csv|json), stored in a results database and resumed.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool):
    if value:
        write_stdout(f"fdbench {__version__}\n")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")] = False,
):
    """fdbench: trajectory tracking in forward dynamics, benchmarked."""


def _compile_spinner(notice):
    """rich's live status line for the kernels' compilation notice (``fdbench.jit``)."""
    from rich.console import Console  # lazy: off the start-up path

    return Console(stderr=True).status(notice)


def main() -> None:
    """Console-script entry point."""
    from ..execution import interrupts_end_compiling
    from ..jit import spin_with

    interrupts_end_compiling()  # this process is the command's: Ctrl-C while kernels compile ends it
    spin_with(_compile_spinner)
    typer.main.get_command(app).main(prog_name="fdbench")
