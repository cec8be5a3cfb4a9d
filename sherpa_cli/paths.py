"""Where sherpa-cli keeps state between runs, and the lock that keeps two commands' updates apart.

The directory is platformdirs' user state directory: ``$XDG_STATE_HOME/sherpa-cli`` (default
``~/.local/state/sherpa-cli``) on Linux, ``~/Library/Application Support/sherpa-cli`` on macOS,
``%LOCALAPPDATA%\\sherpa-cli`` on Windows.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

# filelock and platformdirs are imported where used: the CLI's root callback reaches this module on
# every command, `--help` included, and they cost ~40 ms of start-up
if TYPE_CHECKING:
    import filelock

APP_NAME = "sherpa-cli"
LOCK_TIMEOUT = 10.0  # s a command waits for another one's update of a state file



def state_dir() -> Path:
    """The user's state directory for sherpa-cli (on Linux ``$XDG_STATE_HOME/sherpa-cli``)."""
    import platformdirs

    return Path(platformdirs.user_state_dir(APP_NAME, appauthor=False))


LOCK_DIR_ENV = "SHERPA_LOCK_DIR"


def lock_dir() -> Path:
    """Where the machine-wide locks live: every user's and every state directory's sherpa commands
    meet there (the dead-man host ids of a bus). ``$SHERPA_LOCK_DIR`` if set (tests, a system that
    mounts its own), else ``/run/lock/sherpa-cli`` (``/var/lock``, then the temporary directory, where
    there is no /run/lock). A lock is an flock the kernel drops when its process ends."""
    env = os.environ.get(LOCK_DIR_ENV)
    if env:
        return Path(env)
    for base in ("/run/lock", "/var/lock"):
        if os.path.isdir(base) and os.access(base, os.W_OK | os.X_OK):
            return Path(base) / APP_NAME
    return Path(tempfile.gettempdir()) / f"{APP_NAME}-locks"


LOCK_DIR_HINT = f"check that {LOCK_DIR_ENV} (default /run/lock/sherpa-cli) is a directory every sherpa user can write"


def file_lock(path: Path, timeout: float = LOCK_TIMEOUT) -> filelock.BaseFileLock:
    """An inter-process lock for a read-modify-write of ``path`` (held in ``<path>.lock``).

    Use it as a context manager; it raises ``filelock.Timeout`` (a ``TimeoutError``, so an
    ``OSError``) when another command holds it for longer than ``timeout`` seconds.
    """
    import filelock

    path.parent.mkdir(parents=True, exist_ok=True)
    return filelock.FileLock(str(path) + ".lock", timeout=timeout)


def write_atomic(path: Path, text: str, mode: int | None = None, durable: bool = True) -> None:
    """Write via a temporary file and rename, so a crash never leaves half a file. ``mode``: the
    permission bits to give it (an output file keeps its old ones); None leaves mkstemp's 0600.
    ``durable`` False skips the fsync: the file still survives the writer's death (the kernel has it),
    not a power cut; for a file rewritten many times a second."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            if durable:
                os.fsync(handle.fileno())
        if mode is not None:
            os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


MAX_STATE_BYTES = 16 * 1024 * 1024  # a state file holds counts and a few flash images


def read_json(path: Path, default: object) -> object:
    """The file's JSON, ``default`` if it does not exist; ValueError says what is wrong with it
    (not JSON, not UTF-8, too large, nested too deeply), OSError that it cannot be read."""
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_STATE_BYTES + 1)
    except (FileNotFoundError, NotADirectoryError):  # a parent that is a file: no such file either
        return default
    if len(data) > MAX_STATE_BYTES:
        raise ValueError(f"larger than {MAX_STATE_BYTES // (1024 * 1024)} MiB")
    try:
        return json.loads(data.decode("utf-8"))
    except RecursionError:
        raise ValueError("nested too deeply") from None


STATE_DIR_HINT = "check that the state directory ($XDG_STATE_HOME/sherpa-cli, default ~/.local/state/sherpa-cli) " \
                 "is a writable directory and the disk is not full"


def move_aside_hint(path: Path, consequence: str) -> str:
    """The way out of a damaged state file: keep it for a look, let the tool start a new one."""
    return f"move it aside (mv '{path}' '{path}.damaged') and run again; {consequence}"
