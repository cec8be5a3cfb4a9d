"""The drive seam: what moving a motor needs of a servo drive, whatever its protocol (docs/architecture.md).

A :class:`Drive` speaks in counts, counts/s and counts/s², and in a few states: whether the power
stage is on, in which :class:`Mode`, whether a fault forbids motion (decoded to a sentence), and
whether the profile it was given has ended. Each drive type implements it over its own protocol --
the Elmo binary interpreter (elmo/drive.py: MO, UM, PX, SP, PA, BG, ST ...) and the CiA 402 state
machine over SDO (cia402/drive.py: controlword, statusword, 0x607A ...) -- and devices.REGISTRY maps
the config's drive type to the class. The motion layer asks a drive only through this Protocol.

What is not here is not portable: Elmo's group BG, its recorder, user programs and gains stay
behind the Elmo client; a command that needs them refuses another drive type by name.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Protocol, runtime_checkable


class Mode(enum.Enum):
    """How the drive follows its set point (Elmo UM 5/2/1; CiA 402 0x6060 = 1/3/4)."""

    POSITION = "position"
    VELOCITY = "velocity"
    TORQUE = "torque"
    OTHER = "other"  # a mode motion does not use (Elmo UM=4 dual feedback, CiA 402 homing ...)


@dataclass(frozen=True)
class Ramp:
    """A trapezoid profile: cruise speed (counts/s), acceleration and deceleration (counts/s²)."""

    speed: int
    accel: int
    decel: int


@dataclass(frozen=True)
class DriveStatus:
    """One read of a drive's state."""

    enabled: bool  # the power stage is on: the motor is held or driven
    mode: Mode
    fault: str | None = None  # why it must not move, decoded; None: nothing forbids it
    # the fault is its heartbeat consumer's alone (the tool's heartbeat ended: a killed command), what
    # `sherpa recover --apply` may reset; any other fault is the user's to find
    heartbeat_lost: bool = False
    # powered but ramping down on its own, deaf to set-points (CiA 402 Quick stop active, Fault
    # reaction active): the state's name; None: following its set-points or off
    stopping: str | None = None


@runtime_checkable
class Drive(Protocol):
    """One servo drive as motion uses it. Every call is one exchange (or a short confirmed
    sequence) with the drive; a drive that does not answer raises DriveTimeoutError, a refusal
    DriveRefusedError (sherpa_cli.errors)."""

    @property
    def kind(self) -> str:
        """The config's drive type: "elmo", "cia402"."""
        ...

    @property
    def label(self) -> str:
        """The drive for messages: "<name> (<bus> node <n>)"."""
        ...

    def status(self) -> DriveStatus: ...

    def position(self) -> int:
        """The actual position, counts."""
        ...

    def velocity(self) -> int:
        """The actual velocity, counts/s."""
        ...

    def enable(self, mode: Mode) -> None:
        """Into ``mode`` (the power stage off first where a mode change needs it), then power on,
        confirmed by reading the state back."""
        ...

    def disable(self) -> None:
        """Power stage off, confirmed."""
        ...

    def ramp(self) -> Ramp:
        """The profile the drive holds now (to be put back)."""
        ...

    def set_ramp(self, ramp: Ramp) -> None: ...

    def move_to(self, target: int) -> None:
        """An absolute position target (counts); the motion starts at :meth:`begin`."""
        ...

    def jog(self, velocity: int) -> None:
        """A velocity set point (counts/s); the motion starts at :meth:`begin`."""
        ...

    def begin(self) -> None:
        """Start the set point given last (Elmo BG; CiA 402 new set-point / halt released)."""
        ...

    def stop(self) -> str:
        """Decelerate to standstill with the drive's own ramp; does not wait. Returns how, for
        the report ("ST", "halt")."""
        ...

    def profile_done(self) -> bool:
        """The last profile has ended (Elmo MS=0; CiA 402 target reached)."""
        ...


@runtime_checkable
class FaultResettable(Protocol):
    """A drive whose latched fault the tool resets on the user's word (`sherpa recover --apply`, after
    its dead-man tripped), under a dead-man of its own. The reset leaves the power stage off."""

    def fault_reset(self) -> None:
        """Out of the fault, confirmed; raises SafetyError when the drive stays in it."""
        ...


@dataclass(frozen=True)
class ObjectValue:
    """One object of the drive's dictionary and the value it holds (to be put back by SDO)."""

    index: int
    sub: int
    size: int  # bytes
    value: int


@runtime_checkable
class RampObjects(Protocol):
    """A drive whose profile lives in dictionary objects: the guard journals them before it changes
    the profile, so `sherpa recover` can put them back after a killed command."""

    def ramp_objects(self, ramp: Ramp) -> tuple[ObjectValue, ...]:
        """The objects that hold ``ramp`` on this drive, with its values."""
        ...


@runtime_checkable
class ModeObject(Protocol):
    """A drive whose mode lives in a dictionary object (CiA 402 0x6060): the guard journals the mode
    found before it changes it and puts it back once the power stage is off, as Elmo's UM."""

    def mode_object(self) -> ObjectValue:
        """The object that selects the mode, with the value it holds now (unsigned, ``size`` bytes)."""
        ...

    def put_back(self, obj: ObjectValue) -> None:
        """Write ``obj``'s value back (with the power stage off)."""
        ...
