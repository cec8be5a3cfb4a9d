"""Every file the tool writes for the user (`dump-params -o`, `--report`, `--junit`, ...) goes through here.

Rules, the same for every writer:

- ``-`` means standard output.
- A symlink is followed: its target is what gets written (atomically replaced), the link stays.
- A regular file (or a new name) is written atomically: a temporary file in the same directory,
  fsync, rename -- a crash or an error never leaves half a file, and an existing file keeps its
  permission bits.
- An existing path that is not a regular file is never replaced by one: a FIFO, a character
  device (``/dev/null``, a terminal) or a block device is written in place; a directory or a
  socket is refused with a message naming the option and the path.

Errors are :class:`~sherpa_cli.errors.UsageError` (exit 2) naming the option and the path.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from pathlib import Path

from sherpa_cli.errors import UsageError
from sherpa_cli.paths import write_atomic

STDOUT = "-"


def is_stdout(path: str | os.PathLike[str] | None) -> bool:
    return path is not None and os.fspath(path) == STDOUT


def _target(path: str | os.PathLike[str]) -> Path:
    """The path a write lands on: a symlink (chain) resolved to its final target, which may not exist yet."""
    return Path(os.path.realpath(os.fspath(path)))


def check_output_path(path: str | os.PathLike[str] | None, option: str, what: str = "the file") -> None:
    """Refuse, before any work is done, a path that can never take the output (UsageError)."""
    if path is None or is_stdout(path):
        return
    target = _target(path)
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        # a new file (its missing directories are created when written): where it would land must
        # take a file, or the command would fail with a traceback after the work (/dev/full/x.csv,
        # /proc/self/x.csv)
        check_output_dir(target.parent, option, what, path=path)
        return
    except OSError as exc:
        raise UsageError(f"{option} {path}: cannot write {what}: {exc.strerror or exc}",
                         hint="choose a writable file name") from None
    if stat.S_ISDIR(mode):
        raise UsageError(f"{option} {path}: is a directory, expected a file name",
                         hint=f"name a file, e.g. {option} {Path(path) / 'out'}")
    if stat.S_ISSOCK(mode):
        raise UsageError(f"{option} {path}: is a socket, expected a file name")


def check_output_dir(directory: str | os.PathLike[str], option: str, what: str = "the files", *,
                     path: str | os.PathLike[str] | None = None) -> None:
    """Refuse, before any work is done, a directory that can never take the output: an existing
    non-directory on the way, or a place where no file can be created (tried: a probe file made and
    removed in the nearest directory that exists). Missing directories below it are fine (created)."""
    shown = os.fspath(path if path is not None else directory)
    here = Path(os.path.realpath(os.fspath(directory)))
    while not os.path.lexists(here) and here != here.parent:
        here = here.parent
    if not here.is_dir():
        raise UsageError(f"{option} {shown}: {here} is not a directory, so {what} cannot go there",
                         hint="choose a writable file name")
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(dir=here, prefix=".sherpa-write-probe-")
        try:
            os.close(fd)
        finally:
            os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"{option} {shown}: cannot write {what} in {here}: {exc.strerror or exc}",
                         hint="choose a writable file name") from None


def write_output(path: str | os.PathLike[str], text: str, option: str, *, what: str = "the file",
                 stdout: Callable[[str], None] | None = None) -> str:
    """Write ``text`` to ``path`` by the rules above; returns how it was written ("stdout", "in place",
    "atomically"). ``stdout`` writes to standard output (default: ``sys.stdout``)."""
    if is_stdout(path):
        if stdout is None:
            import sys

            sys.stdout.write(text)
            sys.stdout.flush()
        else:
            stdout(text)
        return "stdout"
    check_output_path(path, option, what)
    target = _target(path)
    try:
        try:
            mode = os.stat(target).st_mode
        except FileNotFoundError:
            mode = None
        if mode is not None and not stat.S_ISREG(mode):
            # FIFO or device: never replaced by a regular file, written where it is
            with open(target, "w", encoding="utf-8") as handle:
                handle.write(text)
            return "in place"
        _replace_atomically(target, text, None if mode is None else stat.S_IMODE(mode))
        return "atomically"
    except OSError as exc:
        raise UsageError(f"{option} {path}: cannot write {what}: {exc.strerror or exc}; nothing was written",
                         hint="choose a writable file name") from None


def _replace_atomically(target: Path, text: str, mode: int | None) -> None:
    if mode is None:  # a new file: what open() would give it (0666 less the umask), not mkstemp's 0600
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    write_atomic(target, text, mode)
