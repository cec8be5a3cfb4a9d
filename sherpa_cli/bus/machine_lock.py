"""Locks every sherpa process of this machine sees, whatever its user or state directory (the
dead-man host ids of a bus, motion/lock.py HostIdLock)."""

from __future__ import annotations

import contextlib
import logging
import os
import re
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from sherpa_cli import paths
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    import filelock

log = logging.getLogger(__name__)

_PROCESS_HELD: set[str] = set()  # machine locks of buses private to this process (python-can virtual)
_PROCESS_HELD_LOCK = threading.Lock()


def wire_key(interface: str | None, channel: str | None) -> str:
    """A bus as every process of this machine names it: interface and channel (after the bus map),
    not the config's bus name, which two users may spell differently."""
    return f"{interface or 'config'}:{channel or '-'}"


class MachineLock:
    """A lock every sherpa process of this machine sees, whatever its user or state directory: an
    flock on ``<paths.lock_dir()>/<name>.lock`` (the directory sticky and world-writable, the file
    0666), dropped by the kernel when its process ends, even by SIGKILL. The holder's pid is written
    into the file for the other command's message. Written with fcntl rather than filelock: filelock
    4 may fall back to a soft lock (a file whose existence is the lock, left behind by a SIGKILL) on
    group- or world-writable files, which is what a lock shared by users needs. A bus private to this
    process (python-can ``virtual``: the in-process simulated arm) is locked in this process alone."""

    def __init__(self, key: str, name: str) -> None:
        self.key = key
        self.private = key.startswith("virtual:")
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", key)
        self.path = paths.lock_dir() / f"{safe}-{name}.lock"
        self._fd: int | None = None
        self._private_held = False
        self._fallback: filelock.BaseFileLock | None = None  # no flock here (Windows)

    def try_acquire(self) -> bool:
        """True once held; False if another process (or another lock of this one) holds it."""
        if self.private:
            with _PROCESS_HELD_LOCK:
                if str(self.path) in _PROCESS_HELD:
                    return False
                _PROCESS_HELD.add(str(self.path))
            self._private_held = True
            return True
        try:
            import fcntl
        except ImportError:  # no flock (Windows): filelock's lock, shared by this user's commands
            import filelock

            self._fallback = filelock.FileLock(str(self.path), timeout=0, thread_local=False)
            _make_lock_dir(self.path.parent)
            try:
                self._fallback.acquire(timeout=0)
            except filelock.Timeout:
                return False
            return True
        _make_lock_dir(self.path.parent)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            with contextlib.suppress(OSError):  # another user's file keeps its mode
                os.fchmod(fd, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                return False
            with contextlib.suppress(OSError):  # the pid is only for a message
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except BaseException:
            with contextlib.suppress(OSError):
                os.close(fd)
            raise
        self._fd = fd
        return True

    def release(self) -> None:
        if self._fallback is not None:
            self._fallback.release(force=True)
            self._fallback = None
        if self._private_held:
            with _PROCESS_HELD_LOCK:
                _PROCESS_HELD.discard(str(self.path))
            self._private_held = False
        if self._fd is not None:
            fd, self._fd = self._fd, None
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            os.close(fd)  # closing the only descriptor drops the flock

    def held_here(self) -> bool:
        return self._fd is not None or self._private_held or self._fallback is not None

    def holder(self) -> int | None:
        """The pid of the sherpa process of this machine holding it; None when nobody holds it (probed
        with a non-blocking flock of its own, released at once; the pid a SIGKILLed holder left in the
        file does not count). 0: held, by a pid it did not write yet."""
        if self.held_here():
            return os.getpid()
        if self.private:
            with _PROCESS_HELD_LOCK:
                return os.getpid() if str(self.path) in _PROCESS_HELD else None
        try:
            import fcntl
        except ImportError:
            return None
        try:
            fd = os.open(self.path, os.O_RDONLY)
        except OSError:
            return None  # never made: never held
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
                return int(text) if text.isdigit() else 0
            return None
        finally:
            os.close(fd)  # drops the probe's own flock


def _make_lock_dir(path: Path) -> None:
    """The shared lock directory: made sticky and world-writable by whoever makes it first."""
    if path.is_dir():
        return
    try:
        path.mkdir(parents=True, exist_ok=True)
        if os.environ.get(paths.LOCK_DIR_ENV) is None:
            with contextlib.suppress(OSError):
                os.chmod(path, 0o1777)
    except OSError as exc:
        raise UsageError(f"cannot make the lock directory {path}: {exc.strerror or exc}",
                         hint=paths.LOCK_DIR_HINT) from None


class TransferLock:
    """One drive's SDO channel across the processes of this machine: a blocking flock on
    ``<lock_dir>/<bus>-node<N>-sdo.lock`` held for one transfer. A drive has one SDO
    server channel (0x600 + node / 0x580 + node): two processes that talk to it at once take each
    other's answers ("Node returned a value for 0x1A00:02 instead"). A bus private to this process
    needs none (the drive's client serializes its own threads). Where the lock directory cannot be
    used the transfer goes on unlocked, logged once: a collision then ends in a clear SDO error."""

    POLL = 0.001  # s between two tries while another process holds it

    def __init__(self, key: str, node: int) -> None:
        self.private = key.startswith("virtual:")
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", key)
        self.path = paths.lock_dir() / f"{safe}-node{int(node)}-sdo.lock"
        self._fd: int | None = None
        self._unusable = False

    def _open(self) -> int | None:
        if self._fd is None and not self._unusable:
            try:
                import fcntl  # noqa: F401 - no flock (Windows): unlocked

                _make_lock_dir(self.path.parent)
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
                with contextlib.suppress(OSError):
                    os.fchmod(fd, 0o666)
                self._fd = fd
            except (ImportError, OSError, UsageError) as exc:
                self._unusable = True
                log.warning("SDO lock %s unusable (%s): transfers go on without it", self.path, exc)
        return self._fd

    @contextlib.contextmanager
    def held(self, timeout: float, clock: Callable[[], float] = time.monotonic) -> Iterator[None]:
        """Held for the ``with`` block; TimeoutError when another process kept it ``timeout`` s."""
        fd = None if self.private else self._open()
        if fd is None:
            yield
            return
        import fcntl

        deadline = clock() + timeout
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if clock() >= deadline:
                    raise TimeoutError(f"another sherpa process kept the drive's SDO channel for {timeout:g} s") \
                        from None
                time.sleep(self.POLL)
        try:
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)
