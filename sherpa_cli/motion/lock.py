"""The motion locks, released by the kernel when their process ends (even by SIGKILL): one drive's
lock (an OS file lock in the state directory) and the dead-man host ids of a bus (machine-wide, in
:func:`sherpa_cli.paths.lock_dir`)."""

from __future__ import annotations

import contextlib
import os
import re
import threading
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import filelock

from sherpa_cli import paths
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.errors import ExitCode, SherpaError, UsageError


def drive_label(ref: DriveRef) -> str:
    return f"{ref.name} ({ref.bus}:{ref.node})"


class MotionLockedError(SherpaError):
    """Another sherpa command holds the drive's motion lock: refused before anything was sent (exit 5)."""

    exit_code = ExitCode.BUSY


class DriveLock:
    """One drive's lock, taken by every command that moves it or writes its parameters (motion
    commands, program-limits, params restore): ``<state dir>/motion/<bus>-node<N>.lock``, an OS file lock (flock), so
    the kernel releases it when its process ends, even by SIGKILL. The holder's pid is written beside
    it (``.pid``) for the refusal's message. Two motion commands on one drive would disarm each other's
    dead-man (both use the host id and put 0x1016:1 back when the first ends). `sherpa stop` takes no
    lock: it is the emergency path."""

    def __init__(self, ref: DriveRef, purpose: str = "moving") -> None:
        self.label = drive_label(ref)
        self.purpose = purpose  # what the holder does with the drive, for the other command's refusal
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", str(ref.bus))
        self.path = paths.state_dir() / "motion" / f"{safe}-node{int(ref.node)}.lock"
        self.pid_path = self.path.with_suffix(".pid")
        # thread_local=False: the interactive view takes it in the main thread and may hand it over
        # (release) from its homing worker
        self._lock = filelock.FileLock(str(self.path), timeout=0, thread_local=False)

    def acquire(self) -> None:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._lock.acquire(timeout=0)
        except filelock.Timeout:
            pid, purpose = self.holder_and_purpose()
            who = "" if pid is None else (" (this process)" if pid == os.getpid() else f" (pid {pid})")
            raise MotionLockedError(
                f"{self.label}: another sherpa command{who} is {purpose} this drive: refused, nothing sent",
                hint="wait until it ends, or stop it (`sherpa stop` needs no lock)") from None
        except OSError as exc:
            raise UsageError(f"{self.label}: cannot take the motion lock {self.path}: {exc}",
                             hint=paths.STATE_DIR_HINT) from None
        with contextlib.suppress(OSError):  # the pid is only for a message
            self.pid_path.write_text(f"{os.getpid()} {self.purpose}\n", encoding="utf-8")

    def release(self) -> None:
        if not self._lock.is_locked:
            return
        with contextlib.suppress(OSError):
            self.pid_path.unlink()
        self._lock.release(force=True)

    def holder(self) -> int | None:
        return self.holder_and_purpose()[0]

    def holder_and_purpose(self) -> tuple[int | None, str]:
        """The holder's pid (None: unknown) and what it does ("moving", "writing parameters to")."""
        try:
            pid, _, purpose = self.pid_path.read_text(encoding="utf-8").strip().partition(" ")
            return int(pid), purpose or "moving"
        except (OSError, ValueError):
            return None, "using"


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
        self._fallback: filelock.BaseFileLock | None = None

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


class HostIdLock:
    """A dead-man host id of its own for one motion command (issue 21 item 9, issue 34 R1).

    Every drive a command moves watches the heartbeat ``0x700 + host id`` of that command alone: two
    commands on one bus never share an id, so a killed or hung command's drives stop by their own
    consumer even while another command goes on sending its heartbeat. The first id of ``ids`` that
    nobody was heard sending (motion/host_ids.py listens first) and whose machine lock is free on
    every bus of the command is taken (:class:`MachineLock` ``<bus>-host<id>``): the sherpa commands
    of every user of this machine coordinate by the lock, those of other hosts by the listening."""

    def __init__(self, buses: Mapping[str, str], ids: Sequence[int]) -> None:
        self.buses = dict(sorted(buses.items()))  # bus name -> wire_key
        self.ids = list(ids)
        self.host_id: int | None = None
        self._held: list[MachineLock] = []

    def lock_for(self, bus: str, host_id: int) -> MachineLock:
        return MachineLock(self.buses[bus], f"host{int(host_id)}")

    def acquire(self, heard: Mapping[str, Iterable[int]] | None = None) -> int:
        """Take the first free id. ``heard``: per bus, the ids another node was heard sending."""
        heard_on = {bus: set(ids) for bus, ids in (heard or {}).items()}
        busy: list[str] = []
        for host_id in self.ids:
            senders = [bus for bus in self.buses if host_id in heard_on.get(bus, set())]
            if senders:
                busy.append(f"{host_id}: heard on {', '.join(senders)} (another host or tool)")
                continue
            taken: list[MachineLock] = []
            try:
                for bus in self.buses:
                    lock = self.lock_for(bus, host_id)
                    if not lock.try_acquire():
                        pid = lock.holder()
                        busy.append(f"{host_id}: taken by sherpa" + (f" pid {pid}" if pid else "") + f" on {bus}")
                        break
                    taken.append(lock)
                else:
                    self._held = taken
                    self.host_id = host_id
                    return host_id
            except OSError as exc:
                for lock in taken:
                    lock.release()
                raise UsageError(f"cannot take a dead-man host id lock in {paths.lock_dir()}: {exc.strerror or exc}",
                                 hint=paths.LOCK_DIR_HINT) from None
            for lock in taken:
                lock.release()
        raise MotionLockedError(
            f"every dead-man host id is in use on bus {', '.join(self.buses)} ({'; '.join(busy)}): "
            "refused, nothing sent",
            hint="wait until one ends, or give motion.host_id_pool more ids no device or other host uses "
                 "(docs/motion.md \"Heartbeat ids\")")

    def release(self) -> None:
        for lock in self._held:
            lock.release()
        self._held = []
        self.host_id = None
