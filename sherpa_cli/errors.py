"""One exception root for the whole package, and the documented exit codes.

Every error a user can cause or meet carries what they must know to act on it
(file and line, drive and node, Elmo error code). The CLI turns a SherpaError
into one line on stderr and its exit code; only ``--debug`` shows a traceback.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum


class ExitCode(IntEnum):
    """Process exit codes; docs/exit-codes.md is the user-facing copy of this table."""

    OK = 0
    PROBLEM = 1  # the operation ran and found a problem (missing drive, diff, verify mismatch)
    USAGE = 2  # bad arguments or bad configuration
    BUS = 3  # bus or communication error (timeout, adapter missing)
    REFUSED = 4  # a drive refused a command (Elmo error reply)
    BUSY = 5  # another sherpa command is moving the drive (its motion lock is held)
    PRIVILEGE = 6  # the command needs a privilege this process lacks (CAP_NET_ADMIN for `bus up`)
    INTERRUPTED = 130  # Ctrl-C


@dataclass(frozen=True)
class Location:
    """Where in an input a problem sits: file, 1-based line, and key path like ``joints.elbow.pos_min``."""

    file: str | None = None
    line: int | None = None
    path: str | None = None

    def __str__(self) -> str:
        where = self.file or "<input>"
        if self.line is not None:
            where += f":{self.line}"
        if self.path:
            where += f": {self.path}"
        return where


class SherpaError(Exception):
    """Root of every error sherpa-cli raises on purpose."""

    exit_code: ExitCode = ExitCode.PROBLEM
    motion_report: object | None = None  # also for subclasses that set up their own __init__

    def __init__(self, message: str, *, hint: str | None = None, motion_report: object | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint
        # how the motion guard stopped the motors when this error ended a motion (motion/report.py
        # GuardReport; read it typed with motion.report.report_of); None outside a motion
        self.motion_report = motion_report

    def __str__(self) -> str:
        return self.message


class UsageError(SherpaError):
    """Bad command-line arguments or values (exit 2)."""

    exit_code = ExitCode.USAGE


class ConfigError(SherpaError):
    """A configuration file is wrong; the message names file, line and key path (exit 2)."""

    exit_code = ExitCode.USAGE

    def __init__(self, message: str, location: Location | None = None, *, hint: str | None = None) -> None:
        self.location = location or Location()
        self.problem = message
        text = f"{self.location}: {message}"
        super().__init__(text, hint=hint)


class CodecError(SherpaError, ValueError):
    """A frame or command could not be encoded or decoded (bad letters, index, value, length)."""

    exit_code = ExitCode.USAGE


class CommunicationError(SherpaError):
    """The bus or a drive did not answer as it must (exit 3)."""

    exit_code = ExitCode.BUS


class DriveTimeoutError(CommunicationError, TimeoutError):
    """A drive did not answer in time; names the drive and what was asked."""


class ProtocolError(CommunicationError):
    """A device answered, but with a frame the protocol does not allow (wrong length, NaN/Inf,
    bad command byte); the message names the drive and the frame in hex (exit 3)."""


class SdoError(CommunicationError):
    """An SDO transfer failed (exit 3): ``reason`` is "timeout", "abort" (``abort_code`` set),
    "malformed" (an answer that is not a valid SDO reply), "bus" (the request could not be sent) or
    "busy" (another process of this machine kept the drive's SDO channel, bus/machine_lock.py).

    ``detail`` is the message without the drive's label, for a note in a row that names the drive.
    """

    def __init__(self, message: str, *, detail: str, reason: str, drive: str | None = None,
                 node: int | None = None, index: int | None = None, sub: int | None = None,
                 abort_code: int | None = None, hint: str | None = None) -> None:
        super().__init__(message, hint=hint)
        self.detail = detail
        self.reason = reason
        self.drive = drive
        self.node = node
        self.index = index
        self.sub = sub
        self.abort_code = abort_code


class DriveRefusedError(SherpaError):
    """A drive answered with an Elmo error code (exit 4)."""

    exit_code = ExitCode.REFUSED

    def __init__(self, message: str, *, drive: str | None = None, command: str | None = None,
                 code: int | None = None, hint: str | None = None) -> None:
        super().__init__(message, hint=hint)
        self.drive = drive
        self.command = command
        self.code = code


class SafetyError(SherpaError):
    """An operation was refused by a safety rule (motor on, outside limits, unconfirmed save)."""

    exit_code = ExitCode.PROBLEM


class PrivilegeError(SherpaError):
    """The operation needs a privilege this process lacks (CAP_NET_ADMIN); nothing was changed (exit 6)."""

    exit_code = ExitCode.PRIVILEGE


class Terminated(BaseException):
    """SIGTERM or SIGHUP while a command runs outside the motion guard (cli/entry.py); BaseException,
    like KeyboardInterrupt, so no ``except Exception`` swallows it and no recipe step turns it into a result."""

    def __init__(self, signum: int) -> None:
        import signal

        super().__init__(signal.Signals(signum).name)
        self.signum = signum


# The signal the process entry turned into Terminated. A signal handler's exception can be lost:
# CPython drops it when the handler runs inside C code that does not pass the signal check's error
# on (seen: a SIGHUP while the compiler of a module being imported ran; `sherpa --sim scan` then
# ran to the end and exited 0). The record lets the entry end with the signal's code anyway, and a
# motion guard refuse to start after a signal that was lost on the way.
_signal_received: int | None = None


def note_signal(signum: int | None) -> None:
    """The entry's record (None: forget it, for a new command in the same process)."""
    global _signal_received
    _signal_received = signum


def signal_received() -> int | None:
    return _signal_received


def raise_if_signalled() -> None:
    """Terminated if the entry received SIGTERM or SIGHUP during this command (before anything moves)."""
    if _signal_received is not None:
        raise Terminated(_signal_received)
