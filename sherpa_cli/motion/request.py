"""The one move request: what a command asks one axis (motion/axis.py) to do, in counts.

It is parsed once, where the values come in (the CLI: ``--to 10deg``, ``--velocity 300counts/s``,
``--torque 800mA``; a recipe or a test: numbers in the joint's units, rad, rad/s, A), with the
axis's cpr; every mover then works in counts (position), counts/s (velocity) or A (torque) only.
What is refused here needs no axis limit: a value that is not a finite number, a position move
with both or neither of --to and --by, a bad --for. The limits of the axis are checked by the
move's plan (its normal range, speed limit, current limit; the same rules for every kind of axis).

`diffdrive move` keeps its own pair target (ops/diffdrive.PairTarget): it sets Σ and Δ at once, two
targets of two axes with one timing, which this one-axis request does not describe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from sherpa_cli.errors import UsageError
from sherpa_cli.joints import units
from sherpa_cli.motion.axis import Axis

Mode = Literal["position", "velocity", "torque"]
MODES: tuple[Mode, ...] = ("position", "velocity", "torque")

Value = str | float | int | None  # text with a unit (the CLI), or a number in the joint's unit


@dataclass(frozen=True)
class MoveRequest:
    """One axis's move, in counts: parsed once (:func:`parse_request`)."""

    mode: Mode
    target: float | None = None  # position: counts (whole); velocity: counts/s; torque: A
    relative: bool = False  # position: ``target`` is a distance from where the axis stands (--by)
    speed: int | None = None  # position: counts/s of the move (None: the axis's speed limit)
    duration: float | None = None  # s; velocity: None = until Ctrl-C (plain joints); torque: required
    uncalibrated: bool = False  # allow a position move of a joint not homed since power-up
    hold: bool = False  # after the move the motor stays on holding where it ended (Ctrl-C / sherpa stop)

    @property
    def counts(self) -> int:
        """A position target (or distance) in counts."""
        assert self.mode == "position" and self.target is not None  # parse_request: a position has one
        return int(self.target)

    @property
    def velocity(self) -> int:
        """A velocity jog's speed in counts/s."""
        assert self.mode == "velocity" and self.target is not None  # parse_request: a velocity has one
        return int(self.target)

    @property
    def amps(self) -> float:
        assert self.mode == "torque" and self.target is not None  # parse_request: a torque has one
        return float(self.target)

    def goal(self, start: int) -> int:
        """Where a position move ends, from where the axis stands at ``start``."""
        return start + self.counts if self.relative else self.counts


def _finite(option: str, value: Value) -> None:
    if isinstance(value, int | float) and not math.isfinite(value):
        raise UsageError(f"{option} {value}: expected a finite number")


def _position(axis: Axis, value: Value, option: str) -> int:
    if isinstance(value, str):
        return units.parse_position(value, axis.joint_cpr, what=option)
    assert value is not None
    return units.rad_to_counts(float(value), axis.joint_cpr)


def _velocity(axis: Axis, value: Value, option: str) -> int:
    if isinstance(value, str):
        return units.parse_velocity(value, axis.joint_cpr, what=option)
    assert value is not None
    return units.rad_per_s_to_counts_per_s(float(value), axis.joint_cpr)


def _current(value: Value, option: str) -> float:
    if isinstance(value, str):
        return units.parse_current(value, what=option)
    assert value is not None
    return float(value)


def parse_request(axis: Axis, mode: str, *, to: Value = None, by: Value = None, velocity: Value = None,
                  torque: Value = None, duration: float | None = None, uncalibrated: bool = False,
                  hold: bool = False) -> MoveRequest:
    """The request for ``axis`` from the values as given (text with units, or numbers in rad, rad/s,
    A). In position mode ``velocity`` is the speed of the move."""
    if mode not in MODES:
        raise UsageError(f"jog mode '{mode}': expected one of {', '.join(MODES)}")
    for option, value in (("--to", to), ("--by", by), ("--velocity", velocity), ("--torque", torque),
                          ("--for", duration)):
        _finite(option, value)
    if duration is not None and not duration > 0:
        raise UsageError(f"--for {duration}: expected a time > 0 s")
    m: Mode = mode  # checked against MODES above
    if m == "position":
        if (to is None) == (by is None):
            raise UsageError("a position jog needs exactly one of --to or --by")
        if duration is not None:
            raise UsageError("--for applies to --velocity and --torque jogs; a position move ends at its target")
        target = _position(axis, to, "--to") if to is not None else _position(axis, by, "--by")
        speed = abs(_velocity(axis, velocity, "--velocity")) if velocity is not None else None
        return MoveRequest(m, target, relative=to is None, speed=speed, uncalibrated=uncalibrated, hold=hold)
    if m == "velocity":
        if velocity is None:
            raise UsageError("a velocity jog needs --velocity")
        return MoveRequest(m, _velocity(axis, velocity, "--velocity"), duration=duration, uncalibrated=uncalibrated,
                           hold=hold)
    if torque is None:
        raise UsageError("a torque jog needs --torque")
    return MoveRequest(m, _current(torque, "--torque"), duration=duration, uncalibrated=uncalibrated, hold=hold)
