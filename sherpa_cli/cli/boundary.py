"""The CLI's boundary: run one command line and turn what it raised into a message and an exit code.

The root typer app is handed over by cli/app.py (:func:`install`), so modules that run command lines
in-process (recipe steps, the step checker) import this module instead of cli/app.py, which imports
them: no import cycle. Only this module turns a SherpaError into an exit code (docs/exit-codes.md).
"""

from __future__ import annotations

import functools
import re
import sys
from collections.abc import Sequence
from typing import Any

import typer
from typer.core import TyperGroup

from sherpa_cli.cli import context
from sherpa_cli.errors import ExitCode, SherpaError, Terminated, UsageError

_ROOT: typer.Typer | None = None


class Interrupted(SherpaError):
    """Ctrl-C that ended a command (exit 130, "interrupted")."""

    exit_code = ExitCode.INTERRUPTED


class RootGroup(TyperGroup):
    """The root command (``typer.Typer(cls=RootGroup)`` in cli/app.py).

    A Ctrl-C while the command line is parsed or a command runs becomes :class:`Interrupted` here,
    before the installed typer sees it: typer 0.29 turns a KeyboardInterrupt into a silent
    ``Exit(130)`` (click raised ``Abort``), and it parses slowly the first time (it imports pydantic
    then), so the one line "interrupted" must not depend on which one is installed.
    """

    def make_context(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().make_context(*args, **kwargs)
        except KeyboardInterrupt as exc:
            raise Interrupted("interrupted") from exc

    def invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as exc:
            raise Interrupted("interrupted") from exc


def install(app: typer.Typer) -> None:
    """Make ``app`` the root that :func:`run` runs (cli/app.py, once, at import)."""
    global _ROOT
    _ROOT = app
    root_command.cache_clear()


def _root() -> typer.Typer:
    if _ROOT is None:  # a programming error: only cli/app.py's import installs the root
        raise RuntimeError("sherpa_cli.cli.boundary: no root app installed (import sherpa_cli.cli.app)")
    return _ROOT


@functools.lru_cache(maxsize=1)
def root_command() -> object:
    """The click command tree of the root app, built once per process (a click.Command of the click
    that the installed typer uses: typer 0.29 vendors its own)."""
    import typer.main

    return typer.main.get_command(_root())


def run(argv: Sequence[str] | None = None) -> int:
    """Run the CLI and return its exit code; tests call this, the console script wraps it."""
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    context.CURRENT = None
    try:
        refuse_non_ascii_numbers(args)
        # the cached click tree, not ``Typer.__call__`` (which rebuilds it on every call: a recipe
        # runs ~10 commands in one process). The app's pretty exceptions are off,
        # so typer's except hook would print the standard traceback anyway.
        command: Any = root_command()
        code = command(args=args, prog_name="sherpa", standalone_mode=False)
        return int(code) if isinstance(code, int) else int(ExitCode.OK)
    except SherpaError as exc:
        if debug:
            raise
        _report(str(exc), exc.hint)
        return int(exc.exit_code)
    except (KeyboardInterrupt, typer.Abort):
        if debug:
            raise
        _report("interrupted", None)
        return int(ExitCode.INTERRUPTED)
    except typer.Exit as exc:
        return int(exc.exit_code)
    except RuntimeError as exc:
        # Ctrl-C during a lazy import that builds a dataclass: Python wraps the KeyboardInterrupt
        # raised in __set_name__ in a RuntimeError; it is still the user's Ctrl-C, and a SIGTERM or
        # SIGHUP there is still that signal (cli/entry.py ends it with its own exit code)
        if not debug and isinstance(exc.__cause__, Terminated):
            raise exc.__cause__ from None
        if debug or not isinstance(exc.__cause__, KeyboardInterrupt):
            raise
        _report("interrupted", None)
        return int(ExitCode.INTERRUPTED)
    except SystemExit as exc:  # shell completion (_SHERPA_COMPLETE, --show-completion) ends with sys.exit
        return exc.code if isinstance(exc.code, int) else int(ExitCode.OK if exc.code is None else ExitCode.USAGE)
    except typer.TyperException as exc:
        # usage errors: the parser's own message already names the option or argument
        show = getattr(exc, "show", None)
        if show is not None:
            show(file=sys.stderr)
        else:
            sys.stderr.write(f"error: {exc.format_message()}\n")
        hint = _global_option_hint(exc, args)
        if hint:
            sys.stderr.write(f"hint: {hint}\n")
        return int(ExitCode.USAGE)


def _global_option_hint(exc: Exception, args: Sequence[str]) -> str | None:
    """For `sherpa scan --sim`: the parser says only "No such option"; a global option goes before
    the command, so say that, with the line as it should be typed."""
    if type(exc).__name__ != "NoSuchOption":  # click's, whichever click typer brings
        return None
    name = getattr(exc, "option_name", None)
    if not isinstance(name, str) or not name.startswith("-"):
        return None
    param = next((p for p in getattr(root_command(), "params", ()) if name in (*p.opts, *p.secondary_opts)), None)
    if param is None or name in ("--help", "-h"):
        return None
    # the last one: the parser read the global options before the command, so a refused one is after it
    at = next((i for i in reversed(range(len(args))) if args[i] == name or args[i].startswith(name + "=")), None)
    if at is None:
        return None
    takes_value = not param.is_flag and not param.count
    moved = args[at:at + (2 if takes_value and "=" not in args[at] else 1)]
    rest = [*args[:at], *args[at + len(moved):]]
    return (f"{name} is a global option: it goes before the command, "
            f"`sherpa {' '.join([*moved, *rest])}`")


# A number as a command line gives it (option values, KEY=VALUE, positional), digits of any script,
# with the unit suffixes sherpa reads: what Python's float()/int() or a str pattern's \d would take.
_NUMBER_SHAPED = re.compile(r"\s*[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\s*"
                            r"(?:rad|deg|counts?|cnt|a|ma|s|hz|ms)?(?:/s)?\s*", re.IGNORECASE)


def refuse_non_ascii_numbers(args: Sequence[str]) -> None:
    """Numbers are ASCII: Python reads a fullwidth 3 (U+FF13) or Arabic-Indic 12 as 3 and 12 (float(),
    int(), typer's options), so `--to` with a fullwidth 3 moved a joint 3 rad. Refused for every
    argument before any option parser sees it (the parsers of units, raw commands, targets and
    config refuse them too). A file or name with such digits is not number-shaped and passes."""
    previous = None
    for arg in args:
        name, eq, value = arg.partition("=")
        if not eq:
            name, value = (previous if previous and previous.startswith("-") else "argument"), arg
        previous = arg
        if value.isascii() or not _number_shaped(value):
            continue
        raise UsageError(f"{name} {value!r}: numbers are written with the ASCII digits 0-9",
                         hint=f"did you mean {_ascii_digits(value)!r}?")


def _number_shaped(text: str) -> bool:
    if _NUMBER_SHAPED.fullmatch(text):
        return True
    for convert in (float, int):
        try:
            convert(text)
        except (ValueError, OverflowError):
            continue
        return True
    return False


def _ascii_digits(text: str) -> str:
    import unicodedata

    return "".join(str(unicodedata.decimal(c)) if not c.isascii() and unicodedata.decimal(c, None) is not None
                   else c for c in text).strip()


def _report(message: str, hint: str | None) -> None:
    from sherpa_cli.cli.output import Output

    state = context.CURRENT
    out = state.out if state is not None else Output.create(no_color=True)
    out.error(message, hint)


def main(argv: Sequence[str] | None = None) -> None:
    sys.exit(run(argv))
