"""What the motion guard did on the way out: one :class:`DriveStop` per drive, in a :class:`GuardReport`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


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

    def line(self) -> str:
        parts = [f"{self.drive} ({self.address}): stopped by {self.stopped_by}"]
        if self.standstill is False:
            parts.append("NOT at standstill")
        if self.motor_off:
            parts.append("motor off")
        if self.restored:
            parts.append("restored " + ", ".join(self.restored))
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

    def lines(self) -> list[str]:
        return [d.line() for d in self.drives]

    def as_json(self) -> dict[str, Any]:
        return {"reason": self.reason, "drives": [d.as_json() for d in self.drives]}
