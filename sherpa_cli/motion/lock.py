"""One drive's motion lock: an OS file lock in the state directory, released by the kernel when its
process ends (even by SIGKILL)."""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable, Sequence
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


class HostIdLock:
    """A dead-man host id of its own for one motion command (issue 21 item 9).

    Every drive a command moves watches the heartbeat ``0x700 + host id`` of that command alone: two
    commands on one bus never share an id, so a killed or hung command's drives stop by their own
    consumer even while another sherpa command goes on sending its heartbeat. The first id of
    ``ids`` that is free on every bus of the command is taken, under an OS file lock per bus and id
    in the state directory (``motion/<bus>-host<id>.lock``), released by the kernel when the process
    ends. This coordinates the sherpa commands of one machine (one state directory); another host on
    the bus must use ids outside the pool."""

    def __init__(self, buses: Iterable[str], ids: Sequence[int]) -> None:
        self.buses = sorted(set(buses))
        self.ids = list(ids)
        self.host_id: int | None = None
        self._held: list[filelock.FileLock] = []

    def _path(self, bus: str, host_id: int) -> Path:
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", str(bus))
        return paths.state_dir() / "motion" / f"{safe}-host{int(host_id)}.lock"

    def acquire(self) -> int:
        for host_id in self.ids:
            taken: list[filelock.FileLock] = []
            try:
                for bus in self.buses:
                    path = self._path(bus, host_id)
                    path.parent.mkdir(parents=True, exist_ok=True)
                    lock = filelock.FileLock(str(path), timeout=0, thread_local=False)
                    lock.acquire(timeout=0)
                    taken.append(lock)
            except filelock.Timeout:
                for lock in taken:
                    lock.release(force=True)
                continue
            except OSError as exc:
                for lock in taken:
                    lock.release(force=True)
                raise UsageError(f"cannot take a dead-man host id lock in {paths.state_dir() / 'motion'}: {exc}",
                                 hint=paths.STATE_DIR_HINT) from None
            self._held = taken
            self.host_id = host_id
            return host_id
        raise MotionLockedError(
            f"every dead-man host id ({', '.join(map(str, self.ids))}) is in use on bus "
            f"{', '.join(self.buses)} by other sherpa commands: refused, nothing sent",
            hint="wait until one ends, or give motion.host_id_pool more ids no device uses")

    def release(self) -> None:
        for lock in self._held:
            lock.release(force=True)
        self._held = []
        self.host_id = None
