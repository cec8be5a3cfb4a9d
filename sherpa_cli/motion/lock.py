"""One drive's motion lock: an OS file lock in the state directory, released by the kernel when its
process ends (even by SIGKILL)."""

from __future__ import annotations

import contextlib
import os
import re

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
    """One drive's motion lock: ``<state dir>/motion/<bus>-node<N>.lock``, an OS file lock (flock), so
    the kernel releases it when its process ends, even by SIGKILL. The holder's pid is written beside
    it (``.pid``) for the refusal's message. Two motion commands on one drive would disarm each other's
    dead-man (both use the host id and put 0x1016:1 back when the first ends). `sherpa stop` takes no
    lock: it is the emergency path."""

    def __init__(self, ref: DriveRef) -> None:
        self.label = drive_label(ref)
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
            pid = self.holder()
            who = "" if pid is None else (" (this process)" if pid == os.getpid() else f" (pid {pid})")
            raise MotionLockedError(
                f"{self.label}: another sherpa command{who} is moving this drive: refused, nothing sent",
                hint="wait until it ends, or stop it (`sherpa stop` needs no lock)") from None
        except OSError as exc:
            raise UsageError(f"{self.label}: cannot take the motion lock {self.path}: {exc}",
                             hint=paths.STATE_DIR_HINT) from None
        with contextlib.suppress(OSError):  # the pid is only for a message
            self.pid_path.write_text(f"{os.getpid()}\n", encoding="utf-8")

    def release(self) -> None:
        if not self._lock.is_locked:
            return
        with contextlib.suppress(OSError):
            self.pid_path.unlink()
        self._lock.release(force=True)

    def holder(self) -> int | None:
        try:
            return int(self.pid_path.read_text(encoding="utf-8").strip())
        except (OSError, ValueError):
            return None
