"""The motion locks, released by the kernel when their process ends (even by SIGKILL): one drive's
lock (an OS file lock in the state directory) and the dead-man host ids of a bus (machine-wide locks,
bus/machine_lock.py)."""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable, Mapping, Sequence

import filelock

from sherpa_cli import paths
from sherpa_cli.bus.machine_lock import MachineLock
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
    lock: it is the emergency path.

    With ``key`` (the bus as every process names it, bus/machine_lock.py wire_key) the drive is also
    locked machine-wide (:class:`MachineLock` ``<bus>-node<N>``): a command of another user or state
    directory (sudo, a second login) on the same drive is refused too, not only this state
    directory's."""

    def __init__(self, ref: DriveRef, purpose: str = "moving", key: str | None = None) -> None:
        self.label = drive_label(ref)
        self.purpose = purpose  # what the holder does with the drive, for the other command's refusal
        self._machine = MachineLock(key, f"node{int(ref.node)}") if key is not None else None
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
        if self._machine is not None:
            try:
                taken = self._machine.try_acquire()
            except OSError as exc:
                self._lock.release(force=True)
                raise UsageError(f"{self.label}: cannot take the machine-wide drive lock {self._machine.path}: "
                                 f"{exc.strerror or exc}", hint=paths.LOCK_DIR_HINT) from None
            if not taken:
                self._lock.release(force=True)
                pid = self._machine.holder()
                who = f" (pid {pid}, another user or state directory)" if pid else " (another user or state directory)"
                raise MotionLockedError(
                    f"{self.label}: another sherpa command{who} is using this drive: refused, nothing sent",
                    hint="wait until it ends, or stop it (`sherpa stop` needs no lock)")
        with contextlib.suppress(OSError):  # the pid is only for a message
            self.pid_path.write_text(f"{os.getpid()} {self.purpose}\n", encoding="utf-8")

    def release(self) -> None:
        if self._machine is not None:
            self._machine.release()
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
    """A dead-man host id of its own for one motion command.

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

    @property
    def private(self) -> bool:
        """Every bus of the command is private to this process (the in-process simulated arm's)."""
        return all(key.startswith("virtual:") for key in self.buses.values())

    def lock_for(self, bus: str, host_id: int) -> MachineLock:
        return MachineLock(self.buses[bus], f"host{int(host_id)}")

    def acquire(self, heard: Mapping[str, Iterable[int]] | None = None,
                watched: Mapping[str, Mapping[int, Sequence[str]]] | None = None) -> int:
        """Take the first free id. ``heard``: per bus, the ids another node was heard sending;
        ``watched``: per bus, the ids drives the command does not arm watch (0x1016:1), with their names."""
        heard_on = {bus: set(ids) for bus, ids in (heard or {}).items()}
        busy: list[str] = []
        for host_id in self.ids:
            senders = [bus for bus in self.buses if host_id in heard_on.get(bus, set())]
            if senders:
                busy.append(f"{host_id}: heard on {', '.join(senders)} (another host or tool)")
                continue
            watchers = [name for bus in self.buses for name in (watched or {}).get(bus, {}).get(host_id, ())]
            if watchers:
                busy.append(f"{host_id}: watched by {', '.join(watchers)} (0x1016:1 of a drive this command "
                            "does not arm: a tool that armed it and did not finish, or another host)")
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
