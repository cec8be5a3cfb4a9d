"""What the motion guard did on the way out: one :class:`DriveStop` per drive, in a :class:`GuardReport`,
and the bus faults that ended or troubled the motion (:class:`BusFault`, motion/bus_watch.py)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.errors import SherpaError

RESET_DURING_STOP = "reset during its stop"  # booted again (another node's NMT reset, power) mid-exit
# how these read without --verbose; any other stop (ST, JV=0 + BG, TC=0 + ST, ...) reads "stopped" (the
# method is a detail), and "not stopped" / "-" always as they are
NOT_MOVED = "not moved by this guard"  # refused or ended before it switched the motor on
STOPPED_TEXT = {"motor was off": "motor was off", NOT_MOVED: "not moved",
                RESET_DURING_STOP: "reset during its stop (motor off, RAM from flash)"}
UNSTOPPED = ("not stopped", "not reached", "-")


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
        elif self.stopped_by == "not reached":  # a dead or silent drive, a dead bus: nothing confirmed it
            stopped = "NOT reached"
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


@dataclass(frozen=True)
class BusFault:
    """A bus of the command that left ERROR-ACTIVE/-WARNING during the motion (motion/bus_watch.py)."""

    bus: str
    state: str  # BUS-OFF | ERROR-PASSIVE | STOPPED | down | missing
    seen_in: str  # "an error frame" | "the link state" (netlink, python-can's state)
    action: str  # "stopped the command" | "warned" (motion.bus_error_passive: warn)
    tec: int | None = None
    rec: int | None = None

    def line(self) -> str:
        """``bus can1: BUS-OFF (TEC 255, REC 0; seen in an error frame): stopped the command``."""
        counters = f"TEC {self.tec}, REC {self.rec}; " if self.tec is not None else ""
        return f"bus {self.bus}: {self.state} ({counters}seen in {self.seen_in}): {self.action}"

    def as_json(self) -> dict[str, Any]:
        return {"bus": self.bus, "state": self.state, "seen_in": self.seen_in, "action": self.action,
                "tec": self.tec, "rec": self.rec}


@dataclass
class GuardReport:
    drives: list[DriveStop] = field(default_factory=list)
    reason: str = "end"  # end | error | interrupted | SIGTERM | SIGHUP
    bus_faults: list[BusFault] = field(default_factory=list)  # in the order they were seen
    # what the technician must know of how the guard watched (a force watch that began past its limit)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(not d.problems for d in self.drives)

    def lines(self, verbose: bool = False) -> list[str]:
        return self.notes + [f.line() for f in self.bus_faults] + [d.line(verbose) for d in self.drives]

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> GuardReport:
        """The report back from :meth:`as_json` (a result that kept only that, rendered again)."""
        return cls([DriveStop(**d) for d in data.get("drives", [])], data.get("reason", "end"),
                   [BusFault(**f) for f in data.get("bus_faults", [])], list(data.get("notes", [])))

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"reason": self.reason, "drives": [d.as_json() for d in self.drives]}
        if self.bus_faults:  # only when there were any: a clean run's JSON stays as it was
            out["bus_faults"] = [f.as_json() for f in self.bus_faults]
        if self.notes:
            out["notes"] = list(self.notes)
        return out


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
