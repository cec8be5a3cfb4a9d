"""What the motion guard did on the way out: one :class:`DriveStop` per drive, in a :class:`GuardReport`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.errors import SherpaError

# how these read without --verbose; any other stop (ST, JV=0 + BG, TC=0 + ST, ...) reads "stopped" (the
# method is a detail), and "not stopped" / "-" always as they are
STOPPED_TEXT = {"motor was off": "motor was off", "not moved by this guard": "not moved"}
UNSTOPPED = ("not stopped", "-")


@dataclass
class DriveStop:
    """What the guard did to one drive on the way out."""

    drive: str
    address: str
    stopped_by: str = "-"  # "ST", "JV=0 + BG", "TC=0 + ST", "motor was off", "not stopped"
    standstill: bool | None = None  # None: not checked (motor off)
    motor_off: bool = False  # the guard switched the motor off (it had switched it on)
    position: int | None = None  # PX once stopped (None: could not be read)
    restored: list[str] = field(default_factory=list)
    kept: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    def line(self, verbose: bool = False) -> str:
        """``elbow (can0:6): stopped; motor off; settings put back`` -- a normal end reads as one.
        ``verbose`` names the stop (``stopped by ST``) and the objects put back (``restored
        0x1016:1, ...``); what was kept and every problem are always shown. Rendering only: the
        report's data (as_json) is the same either way."""
        if self.stopped_by == "not stopped":
            stopped = "NOT stopped"
        elif verbose or self.stopped_by in UNSTOPPED:
            stopped = f"stopped by {self.stopped_by}"
        else:
            stopped = STOPPED_TEXT.get(self.stopped_by, "stopped")
        parts = [f"{self.drive} ({self.address}): {stopped}"]
        if self.standstill is False:
            parts.append("NOT at standstill")
        if self.motor_off:
            parts.append("motor off")
        if self.restored:
            parts.append("restored " + ", ".join(self.restored) if verbose else "settings put back")
        if self.kept:
            parts.append("kept " + ", ".join(self.kept))
        text = "; ".join(parts)
        if self.problems:
            text += " -- " + "; ".join(self.problems)
        return text

    def as_json(self) -> dict[str, Any]:
        return {"drive": self.drive, "address": self.address, "stopped_by": self.stopped_by,
                "standstill": self.standstill, "motor_off": self.motor_off, "position": self.position,
                "restored": list(self.restored),
                "kept": list(self.kept), "problems": list(self.problems)}


@dataclass
class GuardReport:
    drives: list[DriveStop] = field(default_factory=list)
    reason: str = "end"  # end | error | interrupted | SIGTERM | SIGHUP

    @property
    def ok(self) -> bool:
        return all(not d.problems for d in self.drives)

    def lines(self, verbose: bool = False) -> list[str]:
        return [d.line(verbose) for d in self.drives]

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> GuardReport:
        """The report back from :meth:`as_json` (a result that kept only that, rendered again)."""
        return cls([DriveStop(**d) for d in data.get("drives", [])], data.get("reason", "end"))

    def as_json(self) -> dict[str, Any]:
        return {"reason": self.reason, "drives": [d.as_json() for d in self.drives]}


class MotionInterrupted(KeyboardInterrupt):
    """Ctrl-C during a motion, with how the guard stopped it (still a KeyboardInterrupt: exit 130)."""

    def __init__(self, motion_report: GuardReport) -> None:
        super().__init__()
        self.motion_report = motion_report


def with_report(exc: BaseException, report: GuardReport) -> BaseException:
    """What a mover raises when its guarded motion ended with ``exc``: a SherpaError with the guard's
    report in its typed ``motion_report`` field, Ctrl-C as :class:`MotionInterrupted` (raise it
    ``from exc``); anything else (a bug) as it is."""
    if isinstance(exc, SherpaError):
        if exc.motion_report is None:
            exc.motion_report = report
        return exc
    if isinstance(exc, KeyboardInterrupt) and not isinstance(exc, MotionInterrupted):
        return MotionInterrupted(report)
    return exc


def report_of(exc: BaseException) -> GuardReport | None:
    """The guard's report an error carries (:func:`with_report`), typed; None if it has none."""
    report = exc.motion_report if isinstance(exc, SherpaError | MotionInterrupted) else None
    return report if isinstance(report, GuardReport) else None
