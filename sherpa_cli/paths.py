"""Where sherpa-cli keeps state between runs, and the lock that keeps two commands' updates apart.

The directory is platformdirs' user state directory: ``$XDG_STATE_HOME/sherpa-cli`` (default
``~/.local/state/sherpa-cli``) on Linux, ``~/Library/Application Support/sherpa-cli`` on macOS,
``%LOCALAPPDATA%\\sherpa-cli`` on Windows.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import filelock
import platformdirs

APP_NAME = "sherpa-cli"
LOCK_TIMEOUT = 10.0  # s a command waits for another one's update of a state file



def state_dir() -> Path:
    """The user's state directory for sherpa-cli (on Linux ``$XDG_STATE_HOME/sherpa-cli``)."""
    return Path(platformdirs.user_state_dir(APP_NAME, appauthor=False))


def file_lock(path: Path, timeout: float = LOCK_TIMEOUT) -> filelock.BaseFileLock:
    """An inter-process lock for a read-modify-write of ``path`` (held in ``<path>.lock``).

    Use it as a context manager; it raises ``filelock.Timeout`` (a ``TimeoutError``, so an
    ``OSError``) when another command holds it for longer than ``timeout`` seconds.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    return filelock.FileLock(str(path) + ".lock", timeout=timeout)


def write_atomic(path: Path, text: str) -> None:
    """Write via a temporary file and rename, so a crash never leaves half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def read_json(path: Path, default: Any) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return default
