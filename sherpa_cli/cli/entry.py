"""The process entry (console script ``sherpa`` and ``python -m sherpa_cli``): signals from the first instruction.

Importing the CLI takes a tenth of a second or more (typer, the command modules). A SIGINT in that
window printed a ``KeyboardInterrupt`` traceback and a SIGTERM or SIGHUP killed the process without a
word. So this module imports nothing heavy and installs its handlers first:

- while the CLI is imported (nothing was opened, nothing sent): one line and exit 128 + signal number
  at once (SIGINT 130, SIGTERM 143, SIGHUP 129);
- while a command runs: SIGINT is Python's ``KeyboardInterrupt`` as before (the boundary reports
  "interrupted", 130), SIGTERM and SIGHUP raise :class:`sherpa_cli.errors.Terminated`, which unwinds the command through
  its ``finally`` blocks (buses closed, files and drives put back) to one line here and 143 / 129.
  The motion guard installs its own handlers while motors may move and puts these back after
  (motion/guard.py); so do ``log record`` and ``sim``.

Only the process entry installs handlers: code that runs commands in-process (tests, recipe steps)
keeps the handlers it has. docs/exit-codes.md lists the codes.
"""

from __future__ import annotations

import os
import signal  # enum is loaded at start-up already; typing and collections.abc are not: not imported here
import sys

SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None)


def exit_code(signum: int) -> int:
    return 128 + int(signum)


def message(signum: int) -> str:
    """The line a signal ends a command with: a Ctrl-C says what it always said."""
    return "interrupted" if signum == signal.SIGINT else f"interrupted by {signal.Signals(signum).name}"


def _say(text: str) -> None:
    try:
        os.write(2, f"error: {text}\n".encode())
    except OSError:  # SIGHUP: the terminal may be gone
        return


def _at_once(signum: int, frame: object) -> None:
    """Before the CLI runs (and after it returned): nothing to stop or put back."""
    _say(message(signum))
    os._exit(exit_code(signum))


def _unwind(signum: int, frame: object) -> None:
    """While a command runs: SIGTERM/SIGHUP end it like Ctrl-C does, through its clean-up."""
    from sherpa_cli import errors  # loaded with the CLI before this handler is installed

    if errors.signal_received() is not None:
        return  # the first one is unwinding the command already: let the clean-up finish
    errors.note_signal(signum)  # first: the raise below can be lost (errors.py)
    raise errors.Terminated(signum)


def _thread_ended(args: object) -> None:
    """A background thread's exception (a library's receive thread meeting a bus closed under it,
    typically while the command unwinds after a signal): one line on stderr, never a traceback.
    After a signal nothing is said: the command's own line says why it ended. --debug keeps
    Python's own report."""
    from sherpa_cli.errors import signal_received

    exc_type = getattr(args, "exc_type", None)
    if exc_type is None or issubclass(exc_type, SystemExit) or signal_received() is not None:
        return
    thread = getattr(args, "thread", None)
    name = getattr(thread, "name", "?")
    try:
        os.write(2, f"warning: background thread {name} ended: {exc_type.__name__}: "
                    f"{getattr(args, 'exc_value', '')}\n".encode(errors="replace"))
    except OSError:
        return


def install_at_once() -> None:
    for signum in SIGNALS:
        signal.signal(signum, _at_once)


def install_while_running() -> None:
    signal.signal(signal.SIGINT, signal.default_int_handler)
    for signum in SIGNALS:
        if signum != signal.SIGINT:
            signal.signal(signum, _unwind)


def main(argv: list[str] | None = None) -> None:
    install_at_once()  # first: the imports below take a while
    args = list(sys.argv[1:] if argv is None else argv)
    from sherpa_cli.cli.app import run  # the whole CLI
    from sherpa_cli.errors import Terminated, note_signal, signal_received

    code: int | None = None
    note_signal(None)
    if "--debug" not in args:
        import threading  # loaded with the CLI already

        threading.excepthook = _thread_ended
    try:
        install_while_running()
        code = run(args)
        lost = signal_received()
        if lost is not None:  # its Terminated never arrived (errors.py): the command still ends with it
            _say(message(lost))
            code = exit_code(lost)
    except Terminated as exc:
        if "--debug" in args:
            raise
        _say(message(exc.signum))
        code = exit_code(exc.signum)
    except KeyboardInterrupt:  # a Ctrl-C that reached past the boundary (during its own report)
        if "--debug" in args:
            raise
        _say(message(signal.SIGINT))
        code = exit_code(signal.SIGINT)
    finally:
        install_at_once()
    sys.exit(code)
