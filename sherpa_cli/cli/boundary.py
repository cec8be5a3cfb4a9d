"""The CLI's boundary: run one command line and turn what it raised into a message and an exit code.

The root typer app is handed over by cli/app.py (:func:`install`), so modules that run command lines
in-process (recipe steps, the step checker) import this module instead of cli/app.py, which imports
them: no import cycle. Only this module turns a SherpaError into an exit code (docs/exit-codes.md).
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Sequence

import typer

from sherpa_cli.cli import context
from sherpa_cli.errors import ExitCode, SherpaError

_ROOT: typer.Typer | None = None


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
        code = _root()(args=args, prog_name="sherpa", standalone_mode=False)
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
    except SystemExit as exc:  # shell completion (_SHERPA_COMPLETE, --show-completion) ends with sys.exit
        return exc.code if isinstance(exc.code, int) else int(ExitCode.OK if exc.code is None else ExitCode.USAGE)
    except typer.TyperException as exc:
        # usage errors: the parser's own message already names the option or argument
        show = getattr(exc, "show", None)
        if show is not None:
            show(file=sys.stderr)
        else:
            sys.stderr.write(f"error: {exc.format_message()}\n")
        return int(ExitCode.USAGE)


def _report(message: str, hint: str | None) -> None:
    from sherpa_cli.cli.output import Output

    state = context.CURRENT
    out = state.out if state is not None else Output.create(no_color=True)
    out.error(message, hint)


def main(argv: Sequence[str] | None = None) -> None:
    sys.exit(run(argv))
