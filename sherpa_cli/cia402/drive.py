"""A CiA 402 servo drive over SDO, as motion asks every drive (sherpa_cli.drive.Drive).

Every call is a short sequence of SDO transfers, each state change confirmed by reading the
statusword back, bounded by ``Cia402Settings.confirm_timeout`` on the injected clock. A drive in
Fault is refused with its 0x603F code and never reset on the way to a motion: a fault reset is the
user's decision (:meth:`Cia402Drive.fault_reset`, which `sherpa recover --apply` sends for a
tripped dead-man).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from sherpa_cli.cia402 import protocol as p
from sherpa_cli.cia402.protocol import State
from sherpa_cli.drive import DriveStatus, Mode, ObjectValue, Ramp
from sherpa_cli.errors import SafetyError, SdoError, UsageError

MODES = {Mode.POSITION: p.OpMode.PROFILE_POSITION, Mode.VELOCITY: p.OpMode.PROFILE_VELOCITY}
DISPLAYED: dict[int, Mode] = {p.OpMode.PROFILE_POSITION: Mode.POSITION, p.OpMode.PROFILE_VELOCITY: Mode.VELOCITY,
                              p.OpMode.PROFILE_TORQUE: Mode.TORQUE}
FAULTED = (State.FAULT, State.FAULT_REACTION_ACTIVE)
MAX_STEPS = 6  # transitions an enable or disable may take (4 on the standard's way, with room for automatic ones)


class Sdo(Protocol):
    """An SDO client of one node (bus/sdo.py DriveSdo has this shape)."""

    def upload(self, index: int, sub: int = 0, *, name: str | None = None) -> bytes: ...

    def download(self, index: int, sub: int, data: bytes, *, name: str | None = None) -> None: ...


@dataclass(frozen=True)
class Cia402Settings:
    """How the drive is driven; the values a drive's manual may change (docs/cia402.md)."""

    confirm_timeout: float = 0.5  # s a state change or set-point acknowledge may take
    poll_interval: float = 0.005  # s between statusword reads while waiting
    # PP: the new set-point replaces a running one at once (controlword bit 5); off: it waits for the
    # running one to end (a drive that buffers). UNCONFIRMED which a given drive supports.
    change_set_immediately: bool = True
    # s a drive ramping down on its own (quick stop, halt before a mode change) may take to stand
    # still before its power stage goes off or its mode changes; |0x606C| <= standstill_velocity
    standstill_timeout: float = 2.0
    standstill_velocity: int = 0


class Cia402Drive:
    """One CiA 402 drive on SDO ``sdo``; ``label`` names it in messages ("<name> (<bus> node <n>)")."""

    kind = "cia402"

    def __init__(self, sdo: Sdo, label: str, *, settings: Cia402Settings | None = None,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        self.sdo = sdo
        self.label = label
        self.settings = settings or Cia402Settings()
        self._clock = clock
        self._sleep = sleep
        self._halt = 0  # CW_HALT while the drive is held (PV before begin(), after stop())
        self._op_mode: p.OpMode | None = None  # what enable() set

    # -- reading ----------------------------------------------------------------------------------

    def _read(self, index: int) -> int:
        return p.decode(index, self.sdo.upload(index, 0, name=p.NAMES[index]))

    def _write(self, index: int, value: int) -> None:
        self.sdo.download(index, 0, p.encode(index, value), name=p.NAMES[index])

    def _state(self) -> tuple[State | None, int]:
        sw = self._read(p.STATUSWORD)
        return p.state_of(sw), sw

    def _fault_text(self) -> str:
        return str(p.decode_error(self._read(p.ERROR_CODE)))

    def _read_sub(self, index: int, sub: int) -> int:
        return p.decode(index, self.sdo.upload(index, sub, name=p.NAMES[index]))

    def status(self) -> DriveStatus:
        """``enabled``: the power stage is on -- Operation enabled, and Quick stop active and Fault
        reaction active too, whose ramp still drives the motor."""
        state, _ = self._state()
        mode = DISPLAYED.get(self._read(p.MODES_DISPLAY), Mode.OTHER)
        powered = state in p.POWERED
        stopping = state.value if state is State.QUICK_STOP_ACTIVE or state is State.FAULT_REACTION_ACTIVE else None
        if state in FAULTED and state is not None:
            code = p.decode_error(self._read(p.ERROR_CODE))
            if code.code != p.HEARTBEAT_LOSS_ERROR:
                return DriveStatus(enabled=powered, mode=mode, fault=f"{state.value}: {code}", stopping=stopping)
            more = self._besides_heartbeat_loss()
            fault = f"{state.value}: {code}" + (f"; {more}" if more else "")
            return DriveStatus(enabled=powered, mode=mode, fault=fault, heartbeat_lost=more is None, stopping=stopping)
        return DriveStatus(enabled=powered, mode=mode, stopping=stopping)

    def _besides_heartbeat_loss(self) -> str | None:
        """With 0x603F = 0x8130: what else the drive reports as an error (0x1001 bits other than
        generic and communication; the newest 0x1003 entry, where the drive has one, not 0x8130),
        named; None: the heartbeat loss is the only error (what a fault reset may clear)."""
        register = self._read(p.ERROR_REGISTER)
        if register & ~(p.ERR_REG_GENERIC | p.ERR_REG_COMMUNICATION):
            return f"error register (0x1001) 0x{register:02X}: more than a communication error"
        try:
            newest = self._read_sub(p.ERROR_FIELD, 1)
        except SdoError as exc:
            if exc.reason != "abort":
                raise
            return None  # 0x1003 is optional (CiA 301): the error register is all there is
        if newest & 0xFFFF not in (0, p.HEARTBEAT_LOSS_ERROR):
            return f"newest error (0x1003:1) {p.decode_error(newest)}: more than the heartbeat loss"
        return None

    def position(self) -> int:
        return self._read(p.POSITION_ACTUAL)

    def velocity(self) -> int:
        return self._read(p.VELOCITY_ACTUAL)

    # -- the power state machine -----------------------------------------------------------------

    def _refuse_fault(self, state: State | None, sw: int) -> None:
        if state in FAULTED:
            raise SafetyError(f"{self.label}: the drive is in {state.value if state else 'Fault'} "
                              f"({self._fault_text()}; statusword 0x{sw:04X})",
                              hint="find the cause; a fault reset is the user's decision (sherpa does not reset it)")

    def _walk(self, goal: State, state: State | None, sw: int) -> None:
        """From ``state`` to ``goal`` one transition at a time, each confirmed by the statusword."""
        for _ in range(MAX_STEPS):
            if state is None:
                raise SafetyError(f"{self.label}: statusword 0x{sw:04X} shows no CiA 402 state")
            if state is goal:
                return
            self._refuse_fault(state, sw)
            command = p.next_command(state, goal)
            if command is not None:
                self._write(p.CONTROLWORD, int(command) | (self._halt if command is p.Command.ENABLE_OPERATION else 0))
            state, sw = self._wait_state_left(state, p.COMMAND_NAMES[int(command)] if command is not None else None)
        raise SafetyError(f"{self.label}: did not reach {goal.value} in {MAX_STEPS} transitions "
                          f"(now {state.value if state else f'statusword 0x{sw:04X}'})")

    def _wait_state_left(self, state: State, command: str | None) -> tuple[State | None, int]:
        deadline = self._clock() + self.settings.confirm_timeout
        while True:
            now, sw = self._state()
            if now is not state:
                return now, sw
            if self._clock() >= deadline:
                after = f" after '{command}'" if command else ""
                raise SafetyError(f"{self.label}: stuck in {state.value}{after} "
                                  f"for {self.settings.confirm_timeout:g} s (statusword 0x{sw:04X})")
            self._sleep(self.settings.poll_interval)

    def _wait_still(self, why: str) -> None:
        """Until |0x606C| <= standstill_velocity (bounded): a drive ramping down on its own is left
        to do so before its power stage goes off (it would coast) or its mode changes."""
        deadline = self._clock() + self.settings.standstill_timeout
        while True:
            velocity = self.velocity()
            if abs(velocity) <= self.settings.standstill_velocity:
                return
            if self._clock() >= deadline:
                state, sw = self._state()
                raise SafetyError(f"{self.label}: still moving ({velocity} counts/s) "
                                  f"{self.settings.standstill_timeout:g} s {why} "
                                  f"(now {state.value if state else f'statusword 0x{sw:04X}'})",
                                  hint="the drive ramps down on its own; `sherpa stop` switches it off at standstill")
            self._sleep(self.settings.poll_interval)

    def enable(self, mode: Mode) -> None:
        if mode not in MODES:
            raise UsageError(f"{self.label}: {mode.value} mode is not built for CiA 402 drives "
                             "(profile position and profile velocity are)")
        state, sw = self._state()
        self._refuse_fault(state, sw)  # nothing is written to a drive in Fault
        op = MODES[mode]
        if state is State.QUICK_STOP_ACTIVE:
            self._wait_still("into the quick stop")  # left by disable voltage: the power stage goes off
        elif state is State.OPERATION_ENABLED and self._read(p.MODES_DISPLAY) != op:
            # halted first: the new mode acts at once on its own set-point (PV runs the old 0x60FF)
            self._write(p.CONTROLWORD, int(p.Command.ENABLE_OPERATION) | p.CW_HALT)
            self._wait_still("after the halt before the mode change")
        self._write(p.MODES_OF_OPERATION, int(op))
        shown = self._read(p.MODES_DISPLAY)
        if shown != op:
            raise SafetyError(f"{self.label}: modes of operation display (0x6061) shows {shown} after 0x6060 := {int(op)}")
        self._op_mode = op
        # PV holds still until begin(): the target velocity 0x60FF may be one from before
        self._halt = p.CW_HALT if op is p.OpMode.PROFILE_VELOCITY else 0
        if state is State.OPERATION_ENABLED:
            self._write(p.CONTROLWORD, int(p.Command.ENABLE_OPERATION) | self._halt)
            return
        self._walk(State.OPERATION_ENABLED, state, sw)

    def disable(self) -> None:
        """Power stage off: to Ready to switch on. A drive in Fault has its power stage off already and
        is left in Fault (not reset)."""
        state, sw = self._state()
        if state in FAULTED:
            return
        if state is State.QUICK_STOP_ACTIVE:
            self._wait_still("into the quick stop")  # the disable voltage it leaves by cuts the power stage
        self._walk(State.READY_TO_SWITCH_ON, state, sw)

    def fault_reset(self) -> None:
        """Fault -> Switch on disabled: controlword bit 7 on its rising edge (the word without it first),
        confirmed by the statusword; the power stage stays off. Nothing is sent to a drive not in Fault."""
        state, sw = self._state()
        if state is State.FAULT_REACTION_ACTIVE:
            state, sw = self._wait_state_left(state, None)
        if state is not State.FAULT:
            return
        self._write(p.CONTROLWORD, 0)  # disable voltage: a drive in Fault stays there; bit 7 down for the edge
        self._write(p.CONTROLWORD, int(p.Command.FAULT_RESET))
        state, sw = self._wait_state_left(State.FAULT, p.COMMAND_NAMES[int(p.Command.FAULT_RESET)])
        if state in FAULTED or state is None:
            raise SafetyError(f"{self.label}: still in fault after the fault reset (statusword 0x{sw:04X}: "
                              f"{self._fault_text()})", hint="find the cause on the drive")

    # -- the profile ------------------------------------------------------------------------------

    def mode_object(self) -> ObjectValue:
        return ObjectValue(p.MODES_OF_OPERATION, 0, 1, self._read(p.MODES_OF_OPERATION) & 0xFF)

    def put_back(self, obj: ObjectValue) -> None:
        self.sdo.download(obj.index, obj.sub, obj.value.to_bytes(obj.size, "little"),
                          name=p.NAMES.get(obj.index, f"0x{obj.index:04X}"))

    def ramp(self) -> Ramp:
        return Ramp(self._read(p.PROFILE_VELOCITY), self._read(p.PROFILE_ACCELERATION),
                    self._read(p.PROFILE_DECELERATION))

    def ramp_objects(self, ramp: Ramp) -> tuple[ObjectValue, ...]:
        return tuple(ObjectValue(index, 0, 4, value) for index, value in (
            (p.PROFILE_VELOCITY, ramp.speed), (p.PROFILE_ACCELERATION, ramp.accel), (p.PROFILE_DECELERATION, ramp.decel)))

    def set_ramp(self, ramp: Ramp) -> None:
        values = ((p.PROFILE_VELOCITY, ramp.speed), (p.PROFILE_ACCELERATION, ramp.accel),
                  (p.PROFILE_DECELERATION, ramp.decel))
        for index, value in values:  # all checked before the first is written
            if not 0 <= value <= 0xFFFFFFFF:
                raise UsageError(f"{self.label}: {p.NAMES[index]} {value} outside 0..4294967295")
        for index, value in values:
            self._write(index, value)

    def _need(self, op: p.OpMode, what: str) -> None:
        if self._op_mode is not op:
            raise UsageError(f"{self.label}: {what} needs the drive enabled in {op.name.replace('_', ' ').lower()} mode")

    def move_to(self, target: int) -> None:
        self._need(p.OpMode.PROFILE_POSITION, "move_to")
        self._write(p.TARGET_POSITION, target)

    def jog(self, velocity: int) -> None:
        self._need(p.OpMode.PROFILE_VELOCITY, "jog")
        self._write(p.TARGET_VELOCITY, velocity)

    def _require_enabled(self, what: str) -> None:
        """A controlword carrying "enable operation" takes Ready to switch on and Switched on to Operation
        enabled (the standard's transitions 3+4): a begin() or stop() must never power a drive on."""
        state, sw = self._state()
        if state is not State.OPERATION_ENABLED:
            self._refuse_fault(state, sw)
            raise SafetyError(f"{self.label}: {what} refused: the drive is in "
                              f"{state.value if state else f'statusword 0x{sw:04X}'}, not Operation enabled")

    def begin(self) -> None:
        self._require_enabled("begin")
        base = int(p.Command.ENABLE_OPERATION)
        self._halt = 0
        if self._op_mode is p.OpMode.PROFILE_VELOCITY:
            self._write(p.CONTROLWORD, base)  # halt released: the drive runs to 0x60FF
            return
        self._need(p.OpMode.PROFILE_POSITION, "begin")
        edge = p.CW_NEW_SET_POINT | (p.CW_CHANGE_SET_IMMEDIATELY if self.settings.change_set_immediately else 0)
        # a bit 12 still set from the set-point before would pass for this one's acknowledge
        self._wait_ack(False, "before the new set-point")
        self._write(p.CONTROLWORD, base | edge)
        try:
            self._wait_ack(True, "waiting for the set-point acknowledge")
        except SafetyError:
            self._write(p.CONTROLWORD, base)
            raise
        self._write(p.CONTROLWORD, base)  # bit 4 down: the next begin() is a rising edge again
        self._wait_ack(False, "after the set-point was acknowledged")

    def _wait_ack(self, up: bool, when: str) -> None:
        """Until statusword bit 12 (set-point acknowledge) is ``up`` (bounded by confirm_timeout)."""
        deadline = self._clock() + self.settings.confirm_timeout
        while True:
            state, sw = self._state()
            if bool(sw & p.SW_SET_POINT_ACK) is up:
                return
            if state is not State.OPERATION_ENABLED:
                self._refuse_fault(state, sw)
                raise SafetyError(f"{self.label}: left Operation enabled {when} "
                                  f"(now {state.value if state else f'statusword 0x{sw:04X}'})")
            if self._clock() >= deadline:
                if up:
                    raise SafetyError(f"{self.label}: the new set-point was not acknowledged (statusword bit 12) "
                                      f"within {self.settings.confirm_timeout:g} s")
                raise SafetyError(f"{self.label}: the set-point acknowledge (statusword bit 12) still set {when} "
                                  f"for {self.settings.confirm_timeout:g} s ({state.value}, statusword 0x{sw:04X})")
            self._sleep(self.settings.poll_interval)

    def stop(self) -> str:
        """Halt (controlword bit 8): the drive decelerates with its profile deceleration and stays
        enabled ("halt"). A drive in Quick stop active or Fault reaction active ramps down on its
        own and gets nothing ("quick stop", "fault reaction"). A drive in another state is not driving
        its motor and gets nothing either:
        the halt word would power on one in Ready to switch on or Switched on ("off: <state>")."""
        self._halt = p.CW_HALT
        state, sw = self._state()
        if state is State.QUICK_STOP_ACTIVE:
            return "quick stop"  # ramping down on its own; halt + enable operation could take it back (16)
        if state is State.FAULT_REACTION_ACTIVE:
            return "fault reaction"
        if state is not State.OPERATION_ENABLED:
            return f"off: {state.value if state else f'statusword 0x{sw:04X}'}"
        self._write(p.CONTROLWORD, int(p.Command.ENABLE_OPERATION) | p.CW_HALT)
        return "halt"

    def profile_done(self) -> bool:
        if self._op_mode is p.OpMode.PROFILE_VELOCITY:
            return self.velocity() == 0
        return bool(self._read(p.STATUSWORD) & p.SW_TARGET_REACHED)
