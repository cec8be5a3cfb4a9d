"""One simulated CiA 402 servo drive at CAN-frame level: NMT, heartbeat producer and consumer, EMCY and
SDO as a Whistle's (sim/drive.py, whose node it reuses), with the CiA 402 device profile in place of
Elmo's binary interpreter: the power state machine driven by the controlword (0x6040), profile
position (PP, a trapezoid on sim/motor.py) and profile velocity (PV), halt, quick stop (0x605A),
fault and fault reset, and the heartbeat loss acting per 0x6007 (docs/cia402.md).

Like SimDrive it has no bus and no threads: the owner feeds frames (receive), advances its clock
(tick / advance_to), drains pop_frames and serves SDO through od_read / od_write. A frame on RPDO2
(the Whistle's interpreter channel) is a PDO nobody mapped here: it is ignored.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Unpack

from sherpa_cli.cia402 import protocol as p
from sherpa_cli.cia402.protocol import State
from sherpa_cli.sim.drive import (
    EMCY_HEARTBEAT,
    EMCY_POSITION_LIMIT,
    EMCY_SPEED_LIMIT,
    ERR_REG_COMMUNICATION,
    ERR_REG_GENERIC,
    MF_HEARTBEAT,
    MF_POSITION_LIMIT,
    MF_SPEED_LIMIT,
    OPERATIONAL,
    PRE_OPERATIONAL,
    STOPPED,
    SimDrive,
)
from sherpa_cli.sim.encoder import DriveOptions
from sherpa_cli.sim.od import ABORT_RANGE, ABORT_READ_ONLY, ODError, OdValue
from sherpa_cli.sim.pdo import COB_INVALID, TPDO_BASES, TpdoDefault, TpdoTable

# CiA 301 data types (canopen.objectdictionary's numbers; this module loads without canopen)
I8, I16, I32, U8, U16, U32 = 0x0002, 0x0003, 0x0004, 0x0005, 0x0006, 0x0007
# (index, sub or None, name, data type, access): what sim/sdo.py serves for a CiA 402 drive, beside
# the communication objects every simulated node has (0x1000, 0x1016, 0x1017, 0x1018, 0x1029, 0x6007 ...)
CIA402_OBJECTS = (
    (0x100B, None, "Node-ID", U8, "ro"),
    (0x1014, None, "COB-ID EMCY", U32, "rw"),
    (p.ERROR_CODE, None, "Error code", U16, "ro"),
    (p.CONTROLWORD, None, "Controlword", U16, "rw"),
    (p.STATUSWORD, None, "Statusword", U16, "ro"),
    (p.QUICK_STOP_OPTION, None, "Quick stop option code", I16, "rw"),
    (p.MODES_OF_OPERATION, None, "Modes of operation", I8, "rw"),
    (p.MODES_DISPLAY, None, "Modes of operation display", I8, "ro"),
    (p.POSITION_ACTUAL, None, "Position actual value", I32, "ro"),
    (p.VELOCITY_ACTUAL, None, "Velocity actual value", I32, "ro"),
    (p.TARGET_POSITION, None, "Target position", I32, "rw"),
    (p.PROFILE_VELOCITY, None, "Profile velocity", U32, "rw"),
    (p.PROFILE_ACCELERATION, None, "Profile acceleration", U32, "rw"),
    (p.PROFILE_DECELERATION, None, "Profile deceleration", U32, "rw"),
    (p.QUICK_STOP_DECELERATION, None, "Quick stop deceleration", U32, "rw"),
    (p.TARGET_VELOCITY, None, "Target velocity", I32, "rw"),
)
MAPPABLE = {(p.STATUSWORD, 0): 16, (p.MODES_DISPLAY, 0): 8, (p.POSITION_ACTUAL, 0): 32, (p.VELOCITY_ACTUAL, 0): 32}
# the writable profile objects: their value after a boot (RAM only here) and their range
PROFILE_DEFAULTS: dict[int, int] = {
    p.MODES_OF_OPERATION: 0,  # no mode until the host picks one (UNCONFIRMED: makers differ)
    p.TARGET_POSITION: 0, p.TARGET_VELOCITY: 0,
    p.PROFILE_VELOCITY: 100_000, p.PROFILE_ACCELERATION: 100_000, p.PROFILE_DECELERATION: 100_000,
    p.QUICK_STOP_DECELERATION: 1_000_000,
    p.QUICK_STOP_OPTION: 2,  # CiA 402's default: slow down on the quick stop ramp, then Switch on disabled
}
RANGES: dict[int, tuple[int, int]] = {
    p.MODES_OF_OPERATION: (-128, 127), p.TARGET_POSITION: (-2**31, 2**31 - 1), p.TARGET_VELOCITY: (-2**31, 2**31 - 1),
    p.PROFILE_VELOCITY: (0, 2**32 - 1), p.PROFILE_ACCELERATION: (1, 2**32 - 1), p.PROFILE_DECELERATION: (1, 2**32 - 1),
    p.QUICK_STOP_DECELERATION: (1, 2**32 - 1), p.QUICK_STOP_OPTION: (0, 8),
}
# what this simulator plays; any other mode (CSP, homing ...) is taken and shown, and holds the motor
# still: a drive is found in it, and it is put back
PLAYED_MODES = (p.OpMode.PROFILE_POSITION, p.OpMode.PROFILE_VELOCITY)
# the Whistle's own shut-downs (an injected trip, sim/drive.py) as CiA 402 faults: 0x603F and the EMCY
FAULT_OF_MF = {MF_POSITION_LIMIT: 0x8612, MF_SPEED_LIMIT: 0x8400, MF_HEARTBEAT: 0x8130}
EMCY_OF_ELMO = {EMCY_POSITION_LIMIT: 0x8612, EMCY_SPEED_LIMIT: 0x8400}
POWERED = (State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE)


class SimCia402Drive(SimDrive):
    """A CiA 402 drive on ``node``; takes SimDrive's keyword arguments (clock, settings, serial, flash,
    position, on_step, on_event, stalled ...). Test controls: :meth:`fault`, :attr:`state`."""

    sdo_extra = CIA402_OBJECTS
    sdo_more = ()  # no Elmo recorder (0x2030)
    sdo_tpdos = (0, 1, 2, 3)
    sdo_fixed_tpdos: frozenset[int] = frozenset()
    sdo_rpdo2 = False
    sdo_rpdos: tuple[int, ...] = ()  # its RPDOs carry no PVT records

    def __init__(self, node: int, *, position: int = 0, stalled: Callable[[], float] | None = None,
                 **kwargs: Unpack[DriveOptions]) -> None:
        self.state = State.SWITCH_ON_DISABLED
        self.objects: dict[int, int] = dict(PROFILE_DEFAULTS)
        self.controlword = 0
        self.error_code = 0  # 0x603F
        self._ack = False  # statusword bit 12 in PP: the new set-point was taken
        self._pending: int | None = None  # PP: a set-point waiting for the running one to end (bit 5 off)
        super().__init__(node, position=position, stalled=stalled, **kwargs)

    def _make_tpdo_table(self, node: int) -> TpdoTable:
        return TpdoTable(node, {n: TpdoDefault(COB_INVALID | (base + node)) for n, base in TPDO_BASES.items()},
                         mappable=MAPPABLE, fixed=frozenset())

    # -- boot ------------------------------------------------------------------------------------

    def _boot(self) -> None:
        super()._boot()
        # Not ready to switch on -> Switch on disabled is the drive's own transition at power-up
        self.state = State.SWITCH_ON_DISABLED
        self.objects = dict(PROFILE_DEFAULTS)
        self.controlword = 0
        self.error_code = 0
        self._ack = False
        self._pending = None

    def _interpreter_frame(self, data: bytes) -> None:
        """No binary interpreter on a CiA 402 drive: RPDO2 is not mapped here."""

    def _check_limits(self) -> None:
        """Software position limits (0x607D) are not modelled; the Whistle's LL/HL do not exist here."""

    # -- the objects ---------------------------------------------------------------------------------

    @property
    def mode(self) -> int:
        """0x6061 (the mode in effect; this drive takes a new mode at once)."""
        return self.objects[p.MODES_OF_OPERATION]

    def statusword(self) -> int:
        sw = p.statusword_of(self.state) | p.SW_REMOTE
        if self.state in POWERED:
            sw |= p.SW_VOLTAGE_ENABLED
        m = self.motor
        halted = bool(self.controlword & p.CW_HALT)
        still = m.v == 0 and m.mode in ("idle", "stop")
        if self.mode == p.OpMode.PROFILE_VELOCITY and self.state is State.OPERATION_ENABLED:
            reached = still if halted else (m.mode == "velocity" and m.v == m.v_target)
            if m.v == 0:
                sw |= p.SW_SET_POINT_ACK  # PV: bit 12 is "speed 0"
        else:
            reached = still and self._pending is None
            if self._ack:
                sw |= p.SW_SET_POINT_ACK
        if reached:
            sw |= p.SW_TARGET_REACHED
        return sw

    def od_read(self, index: int, sub: int) -> OdValue | bytes:
        if sub == 0:
            if index == p.STATUSWORD:
                return self.statusword()
            if index == p.CONTROLWORD:
                return self.controlword
            if index == p.MODES_DISPLAY:
                return self.mode
            if index == p.ERROR_CODE:
                return self.error_code
            if index == p.POSITION_ACTUAL:
                return self.px
            if index == p.VELOCITY_ACTUAL:
                return self._vx()
            if index in self.objects:
                return self.objects[index]
        return super().od_read(index, sub)

    def od_write(self, index: int, sub: int, value: int) -> None:
        if sub != 0 or index not in (*self.objects, p.CONTROLWORD, p.STATUSWORD, p.MODES_DISPLAY, p.ERROR_CODE,
                                     p.POSITION_ACTUAL, p.VELOCITY_ACTUAL):
            return super().od_write(index, sub, value)
        if index not in self.objects and index != p.CONTROLWORD:
            raise ODError(f"0x{index:04X} is read-only", ABORT_READ_ONLY)
        self.advance_to(self.clock.now())
        if index == p.CONTROLWORD:
            if not 0 <= value <= 0xFFFF:
                raise ODError(f"0x6040: {value} outside 0..65535", ABORT_RANGE)
            self.od_writes.append((self._t, index, sub, value))
            self._controlword(value)
            return None
        lo, hi = RANGES[index]
        if not lo <= value <= hi:
            raise ODError(f"0x{index:04X}: {value} outside {lo}..{hi}", ABORT_RANGE)
        self.od_writes.append((self._t, index, sub, value))
        changed = self.objects[index] != value
        self.objects[index] = value
        if index == p.MODES_OF_OPERATION and changed and self.state is State.OPERATION_ENABLED:
            # the new mode acts at once, on its own set-point, as a drive's does: PV runs to 0x60FF
            # unless halted; PP (and a mode not played) holds until a new set-point
            self._pending, self._ack = None, False
            if self._pv_running():
                self._record(f"PV: mode change while enabled, running to 0x60FF = {self.objects[p.TARGET_VELOCITY]}")
                self._run_velocity()
            else:
                self._halt_motion()
        elif index == p.TARGET_VELOCITY and self._pv_running():
            self._run_velocity()  # PV follows its target velocity while running
        return None

    def _pdo_values(self) -> dict[int, Callable[[], int]]:
        return {p.STATUSWORD: self.statusword, p.MODES_DISPLAY: lambda: self.mode, p.POSITION_ACTUAL: lambda: self.px,
                p.VELOCITY_ACTUAL: self._vx}

    # -- the power state machine -------------------------------------------------------------------

    def _controlword(self, cw: int) -> None:
        rose = cw & ~self.controlword
        self.controlword = cw
        before = self.state
        after = p.transition(before, cw, fault_reset_edge=bool(rose & p.CW_FAULT_RESET))
        if before is State.FAULT and after is not State.FAULT:
            self.error_code = 0
            self._record("fault reset")
            self._emcy(0x0000, 0)  # CiA 301: the error is gone
        self._enter(after)
        if self.state is State.OPERATION_ENABLED:
            self._operate(rose)

    def _enter(self, state: State) -> None:
        before, self.state = self.state, state
        if state is before:
            return
        self._record(f"CiA 402: {before.value} -> {state.value}")
        if state is State.OPERATION_ENABLED:
            self._ack, self._pending = False, None
            self._set_motor(True)  # holds where it stands (the dead-man invariant is checked there too)
        elif state is State.QUICK_STOP_ACTIVE:
            option = self.objects[p.QUICK_STOP_OPTION]
            if option == 0:
                self._off("quick stop (0x605A=0: disable drive function)")
                self.state = State.SWITCH_ON_DISABLED
            else:
                decel = self.objects[p.PROFILE_DECELERATION if option in (1, 5) else p.QUICK_STOP_DECELERATION]
                self.motor.stop(decel * self.speed_gain)
        elif before in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE):
            # disable operation / shutdown / disable voltage: the power stage off at once (a drive's
            # 0x605C disable operation option may ramp first: not modelled)
            self._off(f"CiA 402: {state.value}")

    def _off(self, why: str) -> None:
        super()._shut_down(0, why)

    def _operate(self, rose: int) -> None:
        """What a controlword does in Operation enabled, by mode: halt, a PP set-point, PV running."""
        cw = self.controlword
        if cw & p.CW_HALT:
            self._halt_motion()
            return
        if self.mode == p.OpMode.PROFILE_VELOCITY:
            self._run_velocity()
        elif self.mode == p.OpMode.PROFILE_POSITION and rose & p.CW_NEW_SET_POINT:
            self._ack = True
            target = self.objects[p.TARGET_POSITION]
            m = self.motor
            if cw & p.CW_CHANGE_SET_IMMEDIATELY or (m.mode in ("idle", "stop") and m.v == 0):
                self._pending = None
                self._move(target)
            else:
                self._pending = target  # starts when the running profile ends

    def _move(self, target: int) -> None:
        o, g = self.objects, self.speed_gain
        self._record(f"PP: target {target}")
        self.motor.move_to(target - self._px_offset, o[p.PROFILE_VELOCITY] * g, o[p.PROFILE_ACCELERATION] * g,
                           o[p.PROFILE_DECELERATION] * g)

    def _pv_running(self) -> bool:
        return (self.state is State.OPERATION_ENABLED and self.mode == p.OpMode.PROFILE_VELOCITY
                and not self.controlword & p.CW_HALT)

    def _run_velocity(self) -> None:
        o, g = self.objects, self.speed_gain
        self.motor.jog(o[p.TARGET_VELOCITY] * g, o[p.PROFILE_ACCELERATION] * g, o[p.PROFILE_DECELERATION] * g)

    def _halt_motion(self) -> None:
        self._pending = None
        self.motor.stop(self.objects[p.PROFILE_DECELERATION] * self.speed_gain)

    def _model_step(self, dt: float) -> None:
        super()._model_step(dt)
        m = self.motor
        if self._ack and not self.controlword & p.CW_NEW_SET_POINT:
            # bit 12 falls after bit 4 did, on the drive's next cycle (not with the write)
            self._ack = False
        still = m.v == 0 and m.mode in ("idle", "stop")
        if self.state is State.QUICK_STOP_ACTIVE and still and self.objects[p.QUICK_STOP_OPTION] not in (5, 6, 7, 8):
            self._off("quick stop done")
            self.state = State.SWITCH_ON_DISABLED
        elif self._pending is not None and still and self.state is State.OPERATION_ENABLED:
            target, self._pending = self._pending, None
            self._move(target)

    # -- faults -------------------------------------------------------------------------------------

    def fault(self, code: int = 0x1000) -> None:
        """A drive fault now (a test control): Fault reaction active -> Fault, the power stage off,
        0x603F = ``code``, an EMCY with it."""
        self.advance_to(self.clock.now())
        self._fault(code)
        self._emcy(code, ERR_REG_GENERIC)

    def _fault(self, code: int) -> None:
        self.error_code = code
        self.state = State.FAULT_REACTION_ACTIVE
        self._off(f"fault 0x{code:04X}")
        self._pending, self._ack = None, False
        self.state = State.FAULT  # the reaction here is the power stage off at once
        self._record(f"CiA 402: Fault 0x{code:04X}")

    def _shut_down(self, mf_bit: int, why: str) -> None:
        """The Whistle's own shut-downs (an injected trip) are CiA 402 faults here."""
        super()._shut_down(mf_bit, why)
        if self.state is not State.FAULT:
            self._fault(FAULT_OF_MF.get(mf_bit, 0x1000))

    def _emcy(self, code: int, register: int, elmo_code: int = 0, field1: int = 0, field2: int = 0) -> None:
        super()._emcy(EMCY_OF_ELMO.get(code, code), register, elmo_code, field1, field2)

    def _heartbeat_lost(self) -> None:
        """The consumer timed out: EMCY 0x8130, then 0x6007 acts on a drive in Operation enabled
        (1 fault, 2 disable voltage, 3 quick stop; 0 nothing), then 0x1029:1 on the NMT state."""
        self._hb_last = None  # re-armed by the host's next heartbeat
        self._emcy(EMCY_HEARTBEAT, ERR_REG_COMMUNICATION)
        action = self._od.values[(p.ABORT_CONNECTION_OPTION, 0)]
        self._record(f"heartbeat lost (0x6007={action})")
        if self.state is State.OPERATION_ENABLED:
            if action == 1:
                self._fault(EMCY_HEARTBEAT)
            elif action == 2:
                self._enter(State.SWITCH_ON_DISABLED)
            elif action == 3:
                self._enter(State.QUICK_STOP_ACTIVE)
        behaviour = self._od.values[(0x1029, 1)]
        if behaviour == 0 and self._nmt_state == OPERATIONAL:
            self._nmt_state = PRE_OPERATIONAL
        elif behaviour == 2:
            self._nmt_state = STOPPED

    # -- RAM between `--sim` commands ---------------------------------------------------------------

    def ram_snapshot(self, advance: bool = True) -> dict[str, object]:
        saved = super().ram_snapshot(advance)
        saved["cia402"] = {"state": self.state.name, "controlword": self.controlword, "error_code": self.error_code,
                           "objects": {f"0x{k:04X}": v for k, v in self.objects.items()}}
        return saved

    def restore_ram(self, saved: Mapping[str, object]) -> None:
        item = saved.get("cia402")
        if not isinstance(item, dict) or not isinstance(item.get("objects"), dict):
            raise ValueError("CiA 402 state missing")
        state = State[str(item["state"])]
        objects = {int(k, 16): v for k, v in item["objects"].items()}
        if set(objects) != set(PROFILE_DEFAULTS) or not all(isinstance(v, int) for v in objects.values()):
            raise ValueError("CiA 402 objects damaged")
        cw, code = item.get("controlword"), item.get("error_code")
        if not isinstance(cw, int) or not isinstance(code, int):
            raise ValueError("CiA 402 controlword / error code damaged")
        # set before the base restores: a consumer that was watching acts on this state (0x6007)
        self.state, self.objects, self.controlword, self.error_code = state, objects, cw, code
        self._pending, self._ack = None, False
        super().restore_ram(saved)
        if self.motor_on != (self.state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE)) \
                and self.state is not State.FAULT:
            raise ValueError(f"CiA 402 state {self.state.value} with the motor {'on' if self.motor_on else 'off'}")
