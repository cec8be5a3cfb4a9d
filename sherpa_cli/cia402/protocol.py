"""CiA 402 (IEC 61800-7-201) as this tool uses it: the objects, the modes of operation, the power
state machine (statusword -> State, controlword commands, the next controlword on the way to a
state) and a table of common 0x603F error codes. Pure: no I/O (docs/cia402.md).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

# -- objects (index, sub 0) and their CiA 402 data types ---------------------------------------------
ERROR_REGISTER = 0x1001  # UNSIGNED8: CiA 301's error register (bit 0 generic, bit 4 communication ...)
ERROR_FIELD = 0x1003  # sub 1: UNSIGNED32, the newest error (its code in bits 0-15); optional in CiA 301
ABORT_CONNECTION_OPTION = 0x6007  # INTEGER16: what a lost heartbeat (or other comm loss) does
ERROR_CODE = 0x603F  # UNSIGNED16: the last error (CiA 301 / 402 error code)
CONTROLWORD = 0x6040  # UNSIGNED16
STATUSWORD = 0x6041  # UNSIGNED16
QUICK_STOP_OPTION = 0x605A  # INTEGER16
MODES_OF_OPERATION = 0x6060  # INTEGER8
MODES_DISPLAY = 0x6061  # INTEGER8
POSITION_ACTUAL = 0x6064  # INTEGER32, counts
VELOCITY_ACTUAL = 0x606C  # INTEGER32, counts/s
TARGET_POSITION = 0x607A  # INTEGER32, counts
PROFILE_VELOCITY = 0x6081  # UNSIGNED32, counts/s
PROFILE_ACCELERATION = 0x6083  # UNSIGNED32, counts/s²
PROFILE_DECELERATION = 0x6084  # UNSIGNED32, counts/s² (also what halt decelerates with)
QUICK_STOP_DECELERATION = 0x6085  # UNSIGNED32, counts/s²
TARGET_VELOCITY = 0x60FF  # INTEGER32, counts/s

# struct formats of each object's value (little endian, as SDO carries them)
FORMATS: dict[int, str] = {
    ERROR_REGISTER: "<B", ERROR_FIELD: "<I",
    ABORT_CONNECTION_OPTION: "<h", ERROR_CODE: "<H", CONTROLWORD: "<H", STATUSWORD: "<H",
    QUICK_STOP_OPTION: "<h", MODES_OF_OPERATION: "<b", MODES_DISPLAY: "<b", POSITION_ACTUAL: "<i",
    VELOCITY_ACTUAL: "<i", TARGET_POSITION: "<i", PROFILE_VELOCITY: "<I", PROFILE_ACCELERATION: "<I",
    PROFILE_DECELERATION: "<I", QUICK_STOP_DECELERATION: "<I", TARGET_VELOCITY: "<i",
}
NAMES: dict[int, str] = {
    ERROR_REGISTER: "error register", ERROR_FIELD: "pre-defined error field",
    ABORT_CONNECTION_OPTION: "abort connection option code", ERROR_CODE: "error code", CONTROLWORD: "controlword",
    STATUSWORD: "statusword", QUICK_STOP_OPTION: "quick stop option code", MODES_OF_OPERATION: "modes of operation",
    MODES_DISPLAY: "modes of operation display", POSITION_ACTUAL: "position actual value",
    VELOCITY_ACTUAL: "velocity actual value", TARGET_POSITION: "target position", PROFILE_VELOCITY: "profile velocity",
    PROFILE_ACCELERATION: "profile acceleration", PROFILE_DECELERATION: "profile deceleration",
    QUICK_STOP_DECELERATION: "quick stop deceleration", TARGET_VELOCITY: "target velocity",
}


def encode(index: int, value: int) -> bytes:
    """``value`` as object ``index`` carries it; struct.error (a ValueError) if it does not fit."""
    return struct.pack(FORMATS[index], value)


def decode(index: int, data: bytes) -> int:
    """Object ``index``'s value from its bytes; ValueError if the length is not the object's."""
    fmt = FORMATS[index]
    if len(data) != struct.calcsize(fmt):
        raise ValueError(f"0x{index:04X} ({NAMES[index]}): {len(data)} bytes, expected {struct.calcsize(fmt)}")
    value: int = struct.unpack(fmt, data)[0]
    return value


class OpMode(enum.IntEnum):
    """0x6060 / 0x6061."""

    PROFILE_POSITION = 1
    PROFILE_VELOCITY = 3
    PROFILE_TORQUE = 4
    HOMING = 6
    INTERPOLATED_POSITION = 7
    CYCLIC_SYNC_POSITION = 8


# -- the power state machine ----------------------------------------------------------------------------

class State(enum.Enum):
    NOT_READY_TO_SWITCH_ON = "Not ready to switch on"
    SWITCH_ON_DISABLED = "Switch on disabled"
    READY_TO_SWITCH_ON = "Ready to switch on"
    SWITCHED_ON = "Switched on"
    OPERATION_ENABLED = "Operation enabled"
    QUICK_STOP_ACTIVE = "Quick stop active"
    FAULT_REACTION_ACTIVE = "Fault reaction active"
    FAULT = "Fault"


# statusword bits 0-3, 5, 6: ready to switch on, switched on, operation enabled, fault, quick stop
# (active low), switch on disabled. Each state is (mask, value), the standard's table.
STATE_BITS: dict[State, tuple[int, int]] = {
    State.NOT_READY_TO_SWITCH_ON: (0x4F, 0x00),
    State.SWITCH_ON_DISABLED: (0x4F, 0x40),
    State.READY_TO_SWITCH_ON: (0x6F, 0x21),
    State.SWITCHED_ON: (0x6F, 0x23),
    State.OPERATION_ENABLED: (0x6F, 0x27),
    State.QUICK_STOP_ACTIVE: (0x6F, 0x07),
    State.FAULT_REACTION_ACTIVE: (0x4F, 0x0F),
    State.FAULT: (0x4F, 0x08),
}
# the states whose power stage is on: a quick stop and a fault reaction still drive the motor to
# standstill on the drive's own ramp (the standard's table of the states' functions)
POWERED = (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)
SW_VOLTAGE_ENABLED = 1 << 4
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
SW_SET_POINT_ACK = 1 << 12  # PP: the new set-point was taken; PV: speed 0
SW_FOLLOWING_ERROR = 1 << 13

# controlword bits
CW_SWITCH_ON, CW_ENABLE_VOLTAGE, CW_QUICK_STOP, CW_ENABLE_OPERATION = 1, 1 << 1, 1 << 2, 1 << 3
CW_NEW_SET_POINT = 1 << 4  # PP: a rising edge starts the target given
CW_CHANGE_SET_IMMEDIATELY = 1 << 5  # PP: the new set-point replaces the running one at once
CW_RELATIVE = 1 << 6  # PP: the target is relative (not used: targets are absolute)
CW_FAULT_RESET = 1 << 7  # acts on its rising edge
CW_HALT = 1 << 8


class Command(enum.IntEnum):
    """The device control commands (controlword bits 0-3 and 7; the others are 0 here)."""

    SHUTDOWN = 0x06
    SWITCH_ON = 0x07  # also "disable operation" from Operation enabled (transition 5)
    DISABLE_VOLTAGE = 0x00
    QUICK_STOP = 0x02
    ENABLE_OPERATION = 0x0F
    FAULT_RESET = 0x80


COMMAND_NAMES = {0x06: "shutdown", 0x07: "switch on", 0x00: "disable voltage", 0x02: "quick stop",
                 0x0F: "enable operation", 0x80: "fault reset"}
# controlword bits 0-3, 7 that decide the command; the rest (4-6, 8, 9 and up) are mode bits
COMMAND_MASK = 0x8F


def state_of(statusword: int) -> State | None:
    """The state a statusword shows; None: a pattern the standard does not define."""
    for state, (mask, value) in STATE_BITS.items():
        if statusword & mask == value:
            return state
    return None


def statusword_of(state: State) -> int:
    """The smallest statusword that shows ``state`` (quick stop bit 5 set where the mask leaves it free
    and the state is not a stop, as a drive shows it)."""
    mask, value = STATE_BITS[state]
    if not mask & 0x20 and state not in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE, State.FAULT):
        value |= 0x20
    return value


def command_of(controlword: int) -> str | None:
    """Which device control command a controlword carries (the standard's table, bits 0-3 and 7 with
    "x" where it says so); None: none (bit 7 set counts as fault reset, acting on its rising edge)."""
    if controlword & CW_FAULT_RESET:
        return "fault reset"
    low = controlword & 0x0F
    if not low & CW_ENABLE_VOLTAGE:
        return "disable voltage"  # 0bxx0x
    if not low & CW_QUICK_STOP:
        return "quick stop"  # 0bx01x
    if low & 0x07 == 0x06:
        return "shutdown"  # 0bx110
    if low == 0x07:
        return "switch on"  # also "disable operation" from Operation enabled
    return "enable operation"  # 0b1111


def transition(state: State, controlword: int, *, fault_reset_edge: bool = True) -> State:
    """Where the standard's transitions take ``state`` on ``controlword`` (the drive's automatic ones,
    0->1 and 13->14, are :func:`settle`'s). ``fault_reset_edge``: bit 7 rose with this word.
    Quick stop active -> Operation enabled (transition 16) is optional in the standard and not taken."""
    cmd = command_of(controlword)
    if state is State.FAULT:
        return State.SWITCH_ON_DISABLED if cmd == "fault reset" and fault_reset_edge else state
    if state in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE):
        return state
    if cmd == "fault reset":
        cmd = command_of(controlword & ~CW_FAULT_RESET)
    if cmd == "disable voltage":
        return State.SWITCH_ON_DISABLED  # 7, 9, 10, 12
    if state is State.QUICK_STOP_ACTIVE:
        return state
    if cmd == "quick stop":
        if state is State.OPERATION_ENABLED:
            return State.QUICK_STOP_ACTIVE  # 11
        return State.SWITCH_ON_DISABLED  # 7, 10
    if cmd == "shutdown":
        return State.READY_TO_SWITCH_ON  # 2, 6, 8
    if state is State.SWITCH_ON_DISABLED:
        return state  # switch on / enable operation need Ready to switch on first
    if cmd == "switch on":
        return State.SWITCHED_ON  # 3, 5 (from Operation enabled: disable operation)
    # enable operation: 4 from Switched on; from Ready to switch on 3 and 4 at once (the standard's
    # "switch on + enable operation")
    return State.OPERATION_ENABLED


def settle(state: State) -> State:
    """The drive's own transitions: 0->1 (Not ready -> Switch on disabled), 13->14 (Fault reaction -> Fault)."""
    return {State.NOT_READY_TO_SWITCH_ON: State.SWITCH_ON_DISABLED,
            State.FAULT_REACTION_ACTIVE: State.FAULT}.get(state, state)


def next_command(state: State, goal: State) -> Command | None:
    """The command that takes ``state`` one standard transition toward ``goal`` (Operation enabled or
    Ready to switch on), one transition at a time so each can be confirmed; None: already there, or
    the drive moves on its own (Not ready to switch on, Fault reaction active). From Fault it is the
    fault reset: whether to send it is the caller's decision (the drive never sends it unasked)."""
    if goal not in (State.OPERATION_ENABLED, State.READY_TO_SWITCH_ON):
        raise ValueError(f"no path to {goal.value}: the goals are Operation enabled and Ready to switch on")
    if state is goal or state in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE):
        return None
    if state is State.FAULT:
        return Command.FAULT_RESET
    if state is State.QUICK_STOP_ACTIVE:
        return Command.DISABLE_VOLTAGE  # 12: the way out of a quick stop (16 is optional)
    if state is State.SWITCH_ON_DISABLED:
        return Command.SHUTDOWN  # 2
    if goal is State.READY_TO_SWITCH_ON:
        return Command.SHUTDOWN  # 6 (Switched on), 8 (Operation enabled)
    if state is State.READY_TO_SWITCH_ON:
        return Command.SWITCH_ON  # 3
    return Command.ENABLE_OPERATION  # 4


# -- 0x603F error codes (CiA 301 Table 21 / CiA 402 generic ranges) ------------------------------------

ERROR_TEXTS: dict[int, str] = {
    0x0000: "no error",
    0x1000: "generic error",
    0x2300: "current, device output side",
    0x2310: "continuous over-current",
    0x2320: "short circuit / earth leakage",
    0x3100: "mains voltage",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x4210: "excess temperature, device",
    0x4310: "excess temperature, drive",
    0x5530: "data storage (EEPROM)",
    0x6100: "internal software",
    0x7300: "sensor",
    0x7305: "incremental sensor 1 fault",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "life guard error or heartbeat error",
    0x8140: "recovered from bus off",
    0x8200: "protocol error",
    0x8311: "excess torque",
    0x8400: "velocity speed controller",
    0x8611: "following error",
    0x8612: "reference limit",
    0x9000: "external error",
}
# 0x1001 bits: generic (set with any error) and communication; a heartbeat loss sets these alone
ERR_REG_GENERIC = 0x01
ERR_REG_COMMUNICATION = 0x10
# what a drive's heartbeat consumer reports when the producer it watches falls silent (0x6007 = 1: Fault)
HEARTBEAT_LOSS_ERROR = 0x8130
ERROR_CLASSES: dict[int, str] = {
    0x1: "generic", 0x2: "current", 0x3: "voltage", 0x4: "temperature", 0x5: "device hardware",
    0x6: "device software", 0x7: "additional modules", 0x8: "monitoring", 0x9: "external error",
    0xF: "additional functions",
}


@dataclass(frozen=True)
class ErrorCode:
    code: int
    text: str

    def __str__(self) -> str:
        return f"0x{self.code:04X} {self.text}"


def decode_error(code: int) -> ErrorCode:
    """0x603F's meaning: the table's text, else the CiA 301 class of its first digit ("voltage error"),
    0xFF00-0xFFFF device specific (the maker's manual says which)."""
    code &= 0xFFFF
    if code in ERROR_TEXTS:
        return ErrorCode(code, ERROR_TEXTS[code])
    if code >= 0xFF00:
        return ErrorCode(code, "device specific (see the drive's manual)")
    cls = ERROR_CLASSES.get(code >> 12)
    return ErrorCode(code, f"{cls} error" if cls else "unknown error")
