"""What one jog did, for every kind of axis: the one :class:`JogResult`.

A plain joint, a drive, the Σ or Δ joint of a differential pair and one motor of a pair
(motion/axis.py names the kinds) all end in this type, so a caller reads ``start_rad``/``end_rad``,
``ok`` and ``stop`` without asking which mover ran. Positions are kept in counts, as the drives
count them, and given in joint units (rad, rad/s) beside them where the axis has a cpr.

``--json`` keeps the two shapes users already parse: a plain joint or a drive prints the one-drive
shape (``target``, ``drive``, ``start: {counts, rad}``, ...), a Σ/Δ joint or a pair motor the pair
shape (``axis``, ``kind``, ``joints_start``, ``motor_commands``, ...). The kind chooses.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.joints.units import counts_per_s_to_rad_per_s, counts_to_rad
from sherpa_cli.motion.axis import DRIVE, PLAIN, AxisKind
from sherpa_cli.motion.calibration import Calibration
from sherpa_cli.motion.limit_watch import Breach, BreachOutcome
from sherpa_cli.motion.report import GuardReport
from sherpa_cli.motion.request import Mode

#: per motor, the letters sent to start the motion and their values (``{"left": {"PA": 24, "SP": 4000}}``)
MotorCommands = dict[str, dict[str, int | float]]


def letters(commands: Mapping[str, Mapping[str, int | float]]) -> str:
    """``left PA=24 SP=4000; right PA=24 SP=4000``: motor commands as a technician types them."""
    return "; ".join(f"{d} " + " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in c.items())
                     for d, c in commands.items())


@dataclass
class JogProgress:
    """A jog under way: s since its start, where the axis is (counts, and rad where it has a cpr)."""

    elapsed: float
    counts: int
    rad: float | None


@dataclass
class JogResult(BreachOutcome):
    """One jog of one axis: where it started and ended, what was sent, how it ended, how the guard
    stopped the motors. ``ok`` is False when a joint left its full range (``breaches``; the joint
    was brought back, ``recovered_to`` says where)."""

    axis: str  # the name the jog was given: a joint, a drive or BUS:NODE
    kind: AxisKind  # plain | drive | sigma | delta | motor
    mode: Mode
    drives: tuple[str, ...]  # the motors commanded (a, b of a Σ/Δ joint)
    addresses: tuple[str, ...]  # BUS:NODE of each drive, in the same order
    cpr: int | None  # counts per joint revolution of the axis; None: a bare drive (no joint units)
    start_counts: int  # the axis position before the motion
    end_counts: int | None  # after the guard's stop; None: PX could not be read
    target_counts: int | None = None  # position moves: where the axis was sent
    speed: int | None = None  # counts/s of the axis: a move's profile speed, or the velocity commanded
    current: float | None = None  # A: the torque jog's motor current
    for_s: float | None = None  # the time limit asked for (velocity, torque)
    command: str = ""  # what was sent to start it, in drive letters ("PA=286", "left JV=-3000; right JV=-3000")
    ended_by: str = ""  # "target reached", "time up", "Ctrl-C", "left its full range, ...", a hold's end
    duration: float = 0.0  # s from the start command until the motion (and any hold) ended
    breaches: list[Breach] = field(default_factory=list)  # a plain jog stops at its first
    recovered_to: dict[str, int] = field(default_factory=dict)  # joint -> counts after the limit recovery
    calibrations: list[Calibration] = field(default_factory=list)  # read for a position move
    stop: GuardReport = field(default_factory=GuardReport)  # how the guard stopped every motor
    joints_start: dict[str, int] = field(default_factory=dict)  # every joint the motors move (counts)
    joints_end: dict[str, int] = field(default_factory=dict)
    joint_cpr: dict[str, int] = field(default_factory=dict)  # cpr of each of those joints
    motors_start: dict[str, int] = field(default_factory=dict)  # drive -> PX
    motors_end: dict[str, int] = field(default_factory=dict)
    motor_commands: MotorCommands = field(default_factory=dict)
    held_at: dict[str, int] | None = None  # --hold: the PA each motor held (None: not held)
    held_until: str = ""  # --hold: how the hold ended (motion/hold.py)
    # a Σ/Δ jog: the other joint of the pair put back after start/stop skew, {joint: {"from", "to"}}
    held_correction: dict[str, dict[str, int]] = field(default_factory=dict)

    @property
    def error_counts(self) -> int | None:
        """End minus target of a position move (None otherwise, or when the end is unknown)."""
        if self.target_counts is None or self.end_counts is None:
            return None
        return self.end_counts - self.target_counts

    def rad(self, counts: int | None) -> float | None:
        """Axis counts in rad (None without a cpr or without counts)."""
        return None if counts is None or self.cpr is None else counts_to_rad(counts, self.cpr)

    @property
    def start_rad(self) -> float | None:
        return self.rad(self.start_counts)

    @property
    def end_rad(self) -> float | None:
        return self.rad(self.end_counts)

    @property
    def target_rad(self) -> float | None:
        return self.rad(self.target_counts)

    @property
    def error_rad(self) -> float | None:
        return self.rad(self.error_counts)

    @property
    def speed_rad_s(self) -> float | None:
        """The commanded speed in rad/s (the torque is already in A: ``current``)."""
        return None if self.speed is None or self.cpr is None else counts_per_s_to_rad_per_s(self.speed, self.cpr)

    def as_json(self) -> dict[str, Any]:
        """What `sherpa jog --json` prints: the one-drive shape for a plain joint or a drive, the pair
        shape for a Σ/Δ joint or a pair motor (each as it always was)."""
        return self._one_drive_json() if self.kind in (PLAIN, DRIVE) else self._pair_json()

    def _one_drive_json(self) -> dict[str, Any]:
        breach = self.breaches[0] if self.breaches else None
        return {"target": self.axis, "drive": self.drives[0], "address": self.addresses[0], "mode": self.mode,
                "command": self.command, "ended_by": self.ended_by,
                "start": {"counts": self.start_counts, "rad": self.start_rad},
                "end": {"counts": self.end_counts, "rad": self.end_rad},
                "target_position": None if self.target_counts is None else
                {"counts": self.target_counts, "rad": self.target_rad},
                "error": None if self.error_counts is None else {"counts": self.error_counts, "rad": self.error_rad},
                "duration_s": round(self.duration, 3), "stop": self.stop.as_json(), "ok": self.ok,
                "limit": None if breach is None else
                {**breach.as_dict(), "recovered_to": self.recovered_to.get(breach.joint)},
                "calibration": self.calibrations[0].as_dict() if self.calibrations else None}

    def _pair_json(self) -> dict[str, Any]:
        return {
            "axis": self.axis, "kind": self.kind, "mode": self.mode, "drives": list(self.drives),
            "ok": self.ok, "outcome": self.outcome, "start": self.start_counts, "end": self.end_counts,
            "target": self.target_counts, "speed": self.speed, "current": self.current, "for_s": self.for_s,
            "joints_start": dict(self.joints_start), "joints_end": dict(self.joints_end),
            "motors_start": dict(self.motors_start), "motors_end": dict(self.motors_end),
            "motor_commands": dict(self.motor_commands),
            "calibration": [c.as_dict() for c in self.calibrations],
            "limit": [b.as_dict() for b in self.breaches], "recovered_to": dict(self.recovered_to),
            "held_correction": dict(self.held_correction), "stop": self.stop.as_json(),
            **({"hold": {"at": dict(self.held_at), "ended_by": self.held_until}} if self.held_at is not None else {}),
        }
