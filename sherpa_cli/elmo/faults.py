"""Decoding of SR, MF, EC, IP, IL and EMCY frames into technician text (elmo-protocol.md 2.4-2.5, 3.6).

Pure and total: unknown codes and bits decode to "unknown ..." text; only malformed input
(wrong type, wrong frame length, value wider than 32 bits) raises CodecError.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from sherpa_cli.errors import CodecError

EMCY_FRAME = struct.Struct("<HBBHH")  # code, error register, Elmo code, field 1, field 2


def _u32(value: object, what: str) -> int:
    """A register value as unsigned 32 bits; int32 replies arrive negative when bit 31 is set."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise CodecError(f"{what} must be an integer, got {value!r}")
    if not -(2**31) <= value <= 0xFFFFFFFF:
        raise CodecError(f"{what} value {value} does not fit 32 bits")
    return value & 0xFFFFFFFF


# -- EC: Elmo error codes -------------------------------------------------------------------------

@dataclass(frozen=True)
class ErrorCode:
    code: int
    text: str
    bliss_only: bool = False  # single source ([BLISS] SimplIQ list), not corroborated
    check: str | None = None  # what a technician looks at next, where there is an obvious step

    def line(self) -> str:
        return f"{self.text} - check {self.check}" if self.check else self.text


_CHECK_MOTOR_OFF = "MO: send MO=0 first (limits, UM, IL, PX and SV need the motor off)"
_CHECK_FLASH = "MO=0, no user program running, then CD for why the save failed"
_CHECK_BUS = "CAN wiring, termination and bit rate"

# What to check per EC code; kept apart from the texts so the table of texts stays one line per code.
EC_CHECKS: Mapping[int, str] = MappingProxyType({
    2: "the command letters (upper case, a SimplIQ command)", 3: "the index range of the command",
    7: "the unit mode's set-up (UM, PM and the motion parameters)",
    9: "bus load: keep one interpreter request in flight per drive", 10: "use a query or SDO instead of a PDO",
    11: _CHECK_FLASH, 12: "UM: the command needs another unit mode", 13: "retry after the UART traffic ends",
    14: "the NMT state of the drive", 15: "the host heartbeat / life guarding (0x1016, 0x1029)",
    16: "the command needs an index, e.g. LL[3]", 19: "the command's syntax",
    21: "the value against the command's range (CL[1] <= MC/2, PL[1] <= MC)",
    22: "the divisor parameters (e.g. CA[18], gear ratios)", 23: "the command is read-only or execute-only",
    25: "stop the motion first (ST, wait for MS)", 26: "PM against UM", 28: "VL/VH/LL/HL against the value",
    33: "CA[] feedback / sensor settings", 34: "the other command named in the manual (e.g. UM against CA)",
    43: "NMT reset communication, then the bus", 47: "the user program (download and compile it)",
    48: "CD for the reason, MF, and the commutation settings", 51: "IP and IL[n] (inhibit / abort wiring)",
    54: "CD for the inconsistent parameter", 57: _CHECK_MOTOR_OFF, 58: "MO: send MO=1 first (and read MF if it drops)",
    60: "UM (1 torque, 2 speed, 5 position)", 61: "all parameters: the database was reset to defaults",
    67: "wait for the recorder or stop it", 68: "PM against UM", 71: "wait for HM[1] to read 0 or disarm it",
    72: "XM[1]/XM[2] (their difference must be even)", 82: "stop the user program first",
    83: "the user program", 90: "NMT start the drive", 92: "the PDO mapping (0x1600/0x1A00 ...)",
    122: "UM and the motion mode requested", 166: "XM[1]/XM[2] against the target",
    168: "VH[2]/VL[2] and the speed command", 172: _CHECK_FLASH, 178: _CHECK_BUS,
    179: "the host heartbeat and 0x1016 (consumer heartbeat time)",
})


def _ec(*rows: tuple[int, str], bliss_only: bool = False) -> dict[int, ErrorCode]:
    return {code: ErrorCode(code, text, bliss_only, EC_CHECKS.get(code)) for code, text in rows}


EC_CODES: Mapping[int, ErrorCode] = MappingProxyType({
    **_ec((2, "bad command"), (3, "bad index"), (7, "mode cannot be started - bad initialisation data"),
          (9, "CAN message lost"), (10, "cannot be used by PDO"), (11, "cannot write to flash"),
          (13, "cannot reset communication - UART busy"), (16, "array '[]' expected"),
          (19, "command syntax error"), (21, "operand out of range"), (23, "command cannot be assigned"),
          (26, "profiler mode not supported in this unit mode"), (28, "out of limit range"),
          (33, "bad sensor setting"), (34, "conflict with another command"),
          (47, "program does not exist / not compiled"), (48, "motor could not start - reason in CD"),
          (51, "inhibit or abort input active, cannot start motor"), (54, "bad database"),
          (57, "motor must be off"), (58, "motor must be on"), (60, "bad unit mode"),
          (61, "database reset"), (67, "recorder busy"), (68, "required profiler mode not supported"),
          (71, "homing is busy"), (72, "modulo range must be even"), (82, "program is running"),
          (83, "command not permitted in a program"), (122, "motion mode not supported / init conflict"),
          (166, "out of modulo range"), (168, "speed too large to start motor"),
          (172, "cannot write to flash"), (178, "CAN bus off"), (179, "consumer heartbeat event")),
    **_ec((12, "command not available in this unit mode"), (14, "cannot perform CAN NMT service"),
          (15, "CAN life time exceeded - motor shut down"), (22, "zero division"),
          (25, "command not valid while moving"), (43, "CAN state machine in fault"),
          (90, "CAN state machine not ready"), (92, "PDO not configured"), bliss_only=True),
})


def ec_text(code: int) -> str:
    """``"operand out of range"`` for 21; ``"unknown error code 200"`` for codes not in the table."""
    entry = EC_CODES.get(code)
    return entry.text if entry else f"unknown error code {code}"


def describe_ec(code: int) -> str:
    """The text and, where there is one, what to check: ``"motor must be off - check MO: ..."``."""
    entry = EC_CODES.get(code)
    return entry.line() if entry else f"unknown error code {code}"


# -- SR: status register --------------------------------------------------------------------------

SERVO_STATUS = MappingProxyType({1: "under-voltage", 2: "over-voltage", 5: "short circuit", 6: "over-temperature"})
UNIT_MODES = MappingProxyType({1: "torque", 2: "speed", 3: "stepper", 4: "dual-feedback position",
                               5: "single-feedback position"})
MOTION_STATUS = MappingProxyType({0: "stabilized at target", 1: "reference stationary or motor off",
                                  2: "profiler active", 3: "reserved"})
RECORDER_STATUS = MappingProxyType({0: "inactive", 1: "waiting for trigger", 2: "data ready", 3: "recording"})


def _servo_text(field: int) -> str:
    return SERVO_STATUS.get(field, f"unknown servo status {field}")


@dataclass(frozen=True)
class StatusRegister:
    raw: int
    problem: bool
    servo_status: int  # bits 1..3; 0 = no drive problem
    motor_on: bool
    reference_mode: bool
    motor_failure: bool
    unit_mode: int
    gain_scheduling: bool
    homing: bool
    program_running: bool
    current_limit: bool
    motion_status: int
    recorder: int
    halls: int  # bits 24..26 = Hall A, B, C
    cpu_fault: bool
    stopped_by_limit: bool
    program_error: bool

    @property
    def servo_text(self) -> str | None:
        return _servo_text(self.servo_status) if self.servo_status else None


def decode_sr(value: int) -> StatusRegister:
    v = _u32(value, "SR")
    bit = lambda n: bool(v >> n & 1)  # noqa: E731
    return StatusRegister(
        raw=v, problem=bit(0), servo_status=v >> 1 & 7, motor_on=bit(4), reference_mode=bit(5),
        motor_failure=bit(6), unit_mode=v >> 7 & 7, gain_scheduling=bit(10), homing=bit(11),
        program_running=bit(12), current_limit=bit(13), motion_status=v >> 14 & 3, recorder=v >> 16 & 3,
        halls=v >> 24 & 7, cpu_fault=bit(27), stopped_by_limit=bit(28), program_error=bit(29))


SR_CHECKS = MappingProxyType({
    "servo": "MF for the detail, then the supply voltage, motor phases or cooling it names",
    "motor_failure": "MF (why the motor was switched off)",
    "cpu_fault": "power cycle the drive; if it repeats, the firmware (0x100A)",
    "program_error": "the user program (EC, CD)",
    "stopped_by_limit": "IP for the active switch, and VL[3]/VH[3] against the target",
})


def sr_problems(value: int) -> list[Fault]:
    """Only the SR facts that need attention, each with what to check (empty when SR is healthy)."""
    sr = decode_sr(value)
    found: list[Fault] = []
    if sr.problem or sr.servo_status:
        text = f"drive problem: {_servo_text(sr.servo_status)}" if sr.servo_status else "drive problem flag set"
        found.append(Fault(sr.raw & 0xF, text, SR_CHECKS["servo"]))
    for flag, bit, key, text in ((sr.motor_failure, 6, "motor_failure", "motor failure latched"),
                                 (sr.cpu_fault, 27, "cpu_fault", "CPU fault: stack overflow or CPU exception"),
                                 (sr.program_error, 29, "program_error", "error in user program"),
                                 (sr.stopped_by_limit, 28, "stopped_by_limit",
                                  "stopped by a limit switch, stop switch or VL[3]/VH[3]")):
        if flag:
            found.append(Fault(1 << bit, text, SR_CHECKS[key]))
    return found


def describe_sr(value: int) -> list[str]:
    """One line per fact the SR value states, problems first."""
    sr = decode_sr(value)
    # one wording per SR problem; the checks are left out here, so motor failure at least points at MF
    lines = [f"{f.text} (read MF)" if f.code == 1 << 6 else f.text for f in sr_problems(value)]
    lines.append("motor on" if sr.motor_on else "motor off")
    lines.append(f"unit mode {sr.unit_mode} ({UNIT_MODES.get(sr.unit_mode, 'unknown')})")
    lines.append(f"motion status {sr.motion_status} ({MOTION_STATUS[sr.motion_status]})")
    for flag, text in ((sr.reference_mode, "reference mode (RM) on"), (sr.gain_scheduling, "gain scheduling on"),
                       (sr.homing, "homing in progress"), (sr.program_running, "user program running"),
                       (sr.current_limit, "current limit active (LC)")):
        if flag:
            lines.append(text)
    if sr.recorder:
        lines.append(f"recorder: {RECORDER_STATUS[sr.recorder]}")
    lines.append("Halls A/B/C: " + "".join("1" if sr.halls >> i & 1 else "0" for i in range(3)))
    unused = sr.raw & 0xC0FC0000
    if unused:
        lines.append(f"unknown SR bits set: 0x{unused:08X}")
    return lines


# -- MF: motor failure ----------------------------------------------------------------------------

@dataclass(frozen=True)
class Fault:
    """One decoded fault: ``text`` for the technician, ``check`` an optional next step."""

    code: int
    text: str
    check: str | None = None
    known: bool = True

    def line(self) -> str:
        return f"{self.text} - check {self.check}" if self.check else self.text


_CHECK_POS_LIMIT = "LL[3]/HL[3] and the joint's switches"
_CHECK_SPEED_LIMIT = "LL[2]/HL[2]"
_CHECK_HEARTBEAT = "the host heartbeat and 0x1016 (consumer heartbeat time)"
_CHECK_SUPPLY = "the DC supply voltage"

MF_BITS: Mapping[int, Fault] = MappingProxyType({f.code: f for f in (
    Fault(0x00000001, "feedback not ready or signal amplitude lost (resolver / analog Hall)", "the feedback cable"),
    Fault(0x00000004, "feedback loss (encoder and Halls disagree)", "the encoder and Hall wiring"),
    Fault(0x00000008, "peak current exceeded", "PL[1]/PL[2] and the motor phases"),
    Fault(0x00000010, "inhibit input active", "IP and IL[n] (inhibit wiring)"),
    Fault(0x00000040, "two digital Hall sensors changed at once", "the Hall wiring and CA[1..6]"),
    Fault(0x00000080, "speed tracking error (DV[2]-VX > ER[2])", "ER[2] and the speed loop tuning"),
    Fault(0x00000100, "position tracking error (DV[3]-PX/PY > ER[3])", "ER[3] and the load"),
    Fault(0x00000200, "cannot start: inconsistent database", "SR and CD"),
    Fault(0x00000400, "ECAM table difference too large", "the ET[] table"),
    Fault(0x00000800, "heartbeat failure, motor shut down", _CHECK_HEARTBEAT),
    Fault(0x00010000, "failed to find electrical zero", "CA[] commutation settings and the load"),
    Fault(0x00020000, "speed limit exceeded (VX outside LL[2]..HL[2])", _CHECK_SPEED_LIMIT),
    Fault(0x00040000, "stack overflow (fatal; power cycle)", "the user program's depth, then the firmware"),
    Fault(0x00080000, "CPU exception (fatal; power cycle)", "the firmware version (0x100A); report it to Elmo"),
    Fault(0x00200000, "motor stuck", "CL[2]/CL[3] and the mechanics"),
    Fault(0x00400000, "position limit exceeded (LL[3]/HL[3])", _CHECK_POS_LIMIT),
    Fault(0x20000000, "cannot start motor", "EC and CD"),
)})

MF_SERVO_FAULT = 0x1000
MF_SERVO_DETAIL = 0xE000  # bits 13..15 qualify bit 12
_SERVO_CHECKS = MappingProxyType({1: _CHECK_SUPPLY, 2: _CHECK_SUPPLY + " and regeneration (braking resistor)",
                                  5: "the motor phases and cabling for a short", 6: "the drive cooling"})


@dataclass(frozen=True)
class MotorFailure:
    raw: int
    faults: tuple[Fault, ...]

    @property
    def ok(self) -> bool:
        return self.raw == 0


def decode_mf(value: int) -> MotorFailure:
    v = _u32(value, "MF")
    faults: list[Fault] = []
    if v & (MF_SERVO_FAULT | MF_SERVO_DETAIL):
        detail = v >> 13 & 7
        name = _servo_text(detail) if v & MF_SERVO_FAULT else f"servo detail bits {detail} without bit 12"
        faults.append(Fault(v & (MF_SERVO_FAULT | MF_SERVO_DETAIL), f"servo drive fault: {name}",
                            _SERVO_CHECKS.get(detail), known=bool(v & MF_SERVO_FAULT) and detail in SERVO_STATUS))
    rest = v & ~(MF_SERVO_FAULT | MF_SERVO_DETAIL)
    for n in range(32):
        mask = 1 << n
        if rest & mask:
            faults.append(MF_BITS.get(mask) or Fault(mask, f"unknown MF bit {n} (0x{mask:08X})", known=False))
    return MotorFailure(v, tuple(faults))


def describe_mf(value: int) -> list[str]:
    """One line per fault; empty for MF=0."""
    return [f.line() for f in decode_mf(value).faults]


# -- EMCY -----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class EmcyCode:
    code: int
    text: str
    check: str | None = None
    single_source: bool = False  # single-source or Gold-line code


def _emcy(code: int, text: str, check: str | None = None, single: bool = False) -> tuple[int, EmcyCode]:
    return code, EmcyCode(code, text, check, single)


EMCY_CODES: Mapping[int, EmcyCode] = MappingProxyType(dict((
    _emcy(0x0000, "error reset / no error"),
    # 0x2F21 events
    _emcy(0x8110, "CAN message lost (corrupted or overrun)", "bus load: keep one RPDO2 in flight per drive"),
    _emcy(0x8200, "protocol error (unrecognised NMT request)", "the NMT frames the host sends (0x000)"),
    _emcy(0x8210, "access to an unconfigured RPDO", "the PDO mapping"),
    _emcy(0x8130, "heartbeat event", _CHECK_HEARTBEAT),
    _emcy(0x6180, "fatal CPU error: stack overflow (power cycle)", "the user program's depth, then the firmware"),
    _emcy(0x6200, "user program aborted by an error", "the user program (EC, CD)"),
    _emcy(0xFF01, "user program emergency (EMCY())", "the user program's EMCY() call and its argument"),
    _emcy(0x6300, "RPDO-mapped object returned an interpretation error / motion failed",
          "the Elmo error code and the object in field 1"),
    _emcy(0xFF02, "DS402 interpolated-position underflow", "the host's set-point rate"),
    # motor shut down by fault (0x2F21 bit 7)
    _emcy(0x2340, "short circuit", "the motor phases and cabling for a short"),
    _emcy(0x3120, "under-voltage", _CHECK_SUPPLY),
    _emcy(0x3310, "over-voltage", _CHECK_SUPPLY + " and regeneration (braking resistor)"),
    _emcy(0x4310, "drive over-temperature", "the drive cooling"),
    _emcy(0x5280, "ECAM table problem", "the ET[] table"),
    _emcy(0x5441, "motor disabled by limit switch, inhibit or abort input", "IP and IL[n] (switch wiring)"),
    _emcy(0x7121, "motor stuck", "CL[2]/CL[3] and the mechanics"),
    _emcy(0x7300, "resolver / analog encoder feedback failed", "the feedback cable"),
    _emcy(0x7381, "two digital Hall sensors changed at once", "the Hall wiring and CA[1..6]"),
    _emcy(0x8311, "peak current exceeded", "PL[1]/PL[2] and the motor phases"),
    _emcy(0x8480, "speed tracking error", "ER[2] and the speed loop tuning"),
    _emcy(0x8481, "speed limit exceeded", _CHECK_SPEED_LIMIT),
    _emcy(0x8611, "position tracking error", "ER[3] and the load"),
    _emcy(0x8680, "position limit exceeded", _CHECK_POS_LIMIT),
    _emcy(0xFF10, "cannot start motor", "EC and CD"),
    # single-source / Gold-line
    _emcy(0x3130, "AC fail", "the mains supply", single=True),
    _emcy(0x5281, "timing error", "the sampling / PWM settings and the firmware", single=True),
    _emcy(0x5400, "cannot start motor", "EC and CD", single=True),
    _emcy(0x6181, "CPU exception (power cycle)", "the firmware version (0x100A)", single=True),
    _emcy(0x6320, "inconsistent database", "SR and CD", single=True),
    _emcy(0x7380, "feedback loss", "the encoder and Hall wiring", single=True),
    _emcy(0x7382, "commutation failed", "CA[] commutation settings", single=True),
    _emcy(0x8140, "recovered from bus-off", "CAN wiring and termination", single=True),
    _emcy(0x8380, "cannot find electrical zero", "CA[] commutation settings and the load", single=True),
    _emcy(0x8381, "cannot tune current offsets", "the motor phases and the current sensors", single=True),
    _emcy(0x5442, "additional abort input active", "IP and IL[n]", single=True),
    _emcy(0xFF20, "safe torque off (STO) active", "the STO / safety circuit", single=True),
    _emcy(0xFF40, "gantry slave disabled", "the gantry partner drive", single=True),
)))

EMCY_PVT = 0xFF00
PVT_CODES: Mapping[int, EmcyCode] = MappingProxyType(dict((
    _emcy(0x56, "PVT queue low", "the host's PVT feed rate"),
    _emcy(0x5B, "PVT bad head pointer", "the PVT write pointer the host sends"),
    _emcy(0x5C, "PVT: PDO 0x3xx not mapped", "the PDO mapping"),
    _emcy(0x34, "PVT queue full", "the host's PVT feed rate"),
    _emcy(0x07, "PVT bad mode initialisation data", "the PVT set-up (MP[] parameters)"),
    _emcy(0x08, "PVT motion terminated", "MF and EC for why the motion stopped"),
    _emcy(0x09, "PVT CAN message lost", "bus load"),
    _emcy(0xA6, "PVT position out of modulo range", "XM[1]/XM[2]"),
)))


@dataclass(frozen=True)
class Emcy:
    """A decoded EMCY frame; ``text`` is the one-line technician message."""

    code: int
    error_register: int
    elmo_code: int
    field1: int
    field2: int
    meaning: str
    check: str | None
    known: bool

    @property
    def elmo_text(self) -> str | None:
        # PVT frames use byte 3 for their own sub-code, not the EC numbering.
        if not self.elmo_code or self.code == EMCY_PVT:
            return None
        return ec_text(self.elmo_code)

    @property
    def text(self) -> str:
        line = f"EMCY 0x{self.code:04X}: {self.meaning}"
        if self.elmo_text:
            line += f" (error {self.elmo_code}: {self.elmo_text})"
        detail = self._detail()
        if detail:
            line += f"; {detail}"
        if self.check:
            line += f" - check {self.check}"
        return line

    def _detail(self) -> str | None:
        if self.code == 0x8110:
            return "hardware buffer overrun" if self.field2 == 0xFFFF else f"lost COB-ID 0x{self.field2:03X}"
        if self.code == 0x6300:
            return f"object 0x{self.field1:04X}, field 2 0x{self.field2:04X}"
        if self.code == 0xFF01:
            return f"argument {self.field1 | self.field2 << 16}"
        return None


def decode_emcy(data: bytes) -> Emcy:
    """Decode an 8-byte EMCY payload; unknown codes give "unknown code 0x...." and never raise."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise CodecError(f"EMCY frame must be bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) != EMCY_FRAME.size:
        raise CodecError(f"EMCY frame must be {EMCY_FRAME.size} bytes, got {len(data)}: {data.hex(' ')}")
    code, register, elmo, field1, field2 = EMCY_FRAME.unpack(data)
    if code == EMCY_PVT:
        entry = PVT_CODES.get(elmo)
        meaning = entry.text if entry else f"PVT/PT emergency, unknown sub-code 0x{elmo:02X}"
    else:
        entry = EMCY_CODES.get(code)
        meaning = entry.text if entry else f"unknown code 0x{code:04X}"
    return Emcy(code, register, elmo, field1, field2, meaning, entry.check if entry else None, entry is not None)


def encode_error_field(code: int, register: int, elmo_code: int = 0) -> int:
    """The 0x1003 entry a SimplIQ stores for an EMCY: code (bits 0..15), error register (16..23),
    Elmo code (24..31); the frame's data fields are not kept."""
    return code | register << 16 | elmo_code << 24


def decode_error_field(value: int) -> Emcy:
    """A 0x1003 entry (see :func:`encode_error_field`) as the EMCY it records, data fields zero."""
    v = _u32(value, "0x1003 entry")
    return decode_emcy(EMCY_FRAME.pack(v & 0xFFFF, v >> 16 & 0xFF, v >> 24 & 0xFF, 0, 0))


# -- IP: input port; IL: input functions ----------------------------------------------------------

IP_FLAGS: Mapping[int, str] = MappingProxyType({
    **{n: f"input {n + 1} function flag" for n in range(6)},
    6: "main home switch", 7: "auxiliary home switch", 8: "soft stop", 9: "hard stop",
    10: "forward limit switch (FLS)", 11: "reverse limit switch (RLS)", 12: "inhibit",
    13: "begin-motion input", 14: "abort",
})
IP_PIN_SHIFT = 16
IP_PIN_COUNT = 10


@dataclass(frozen=True)
class InputPort:
    raw: int
    flags: tuple[str, ...]  # active function flags, bit order
    pins: tuple[int, ...]  # raw digital input pins (1-based) that read active
    unknown_bits: int

    def lines(self) -> list[str]:
        out = [f"active: {', '.join(self.flags)}" if self.flags else "no input function active"]
        out.append(f"pins high: {', '.join(map(str, self.pins))}" if self.pins else "no input pin active")
        if self.unknown_bits:
            out.append(f"unknown IP bits set: 0x{self.unknown_bits:08X}")
        return out


def decode_ip(value: int) -> InputPort:
    v = _u32(value, "IP")
    flags = tuple(name for bit, name in IP_FLAGS.items() if v >> bit & 1)
    pins = tuple(n + 1 for n in range(IP_PIN_COUNT) if v >> (IP_PIN_SHIFT + n) & 1)
    known = sum(1 << b for b in IP_FLAGS) | ((1 << IP_PIN_COUNT) - 1) << IP_PIN_SHIFT
    return InputPort(v, flags, pins, v & ~known)


def describe_ip(value: int) -> list[str]:
    return decode_ip(value).lines()


# Indexed by IL value // 2; even values are active low, odd active high ([MBARI] table).
IL_FUNCTIONS: tuple[str, ...] = (
    "inhibit", "hard stop", "ignore", "general purpose", "reverse limit switch (RLS)",
    "forward limit switch (FLS)", "begin motion", "soft stop", "main home", "auxiliary home",
    "both stop (UNCONFIRMED)", "abort",
)


@dataclass(frozen=True)
class InputFunction:
    value: int
    function: str | None  # None for values outside the table
    active_high: bool

    def text(self) -> str:
        if self.function is None:
            return f"unknown input function {self.value}"
        return f"{self.function}, active {'high' if self.active_high else 'low'}"


def decode_il(value: int) -> InputFunction:
    if isinstance(value, bool) or not isinstance(value, int):
        raise CodecError(f"IL value must be an integer, got {value!r}")
    function = IL_FUNCTIONS[value // 2] if 0 <= value < 2 * len(IL_FUNCTIONS) else None
    return InputFunction(value, function, value % 2 == 1)


def describe_il(value: int, roles: Mapping[int, str] | None = None) -> str:
    """What the drive does with an input whose IL is ``value`` (the [MBARI] table, elmo-protocol.md
    IL[N]): ``"forward limit switch (FLS), active high"`` for 11. ``roles`` maps the config's
    il_codes to what the tool uses the input for (``joints.limits.il_roles``); a value found there
    gets it added: 5 reads ``"ignore, active high (config: home switch)"`` -- the drive
    itself does nothing with a home switch's input, the tool reads the pin (IP) while homing.
    The one decoder of IL values: `cmd DRIVE "IL[1]"` and `limits show` both use it."""
    text = decode_il(value).text()
    role = (roles or {}).get(value)
    return f"{text} (config: {role})" if role else text


def fault_reason(mf: int, sr: int) -> str | None:
    """Why a drive must not move, decoded; None when MF and SR show no fault."""
    reasons = describe_mf(mf) if mf else []
    for fault in sr_problems(sr):
        if fault.code == 1 << 6 and mf:  # "motor failure latched": MF already says which
            continue
        if fault.code == 1 << 28:  # stopped by a limit: a state, not a fault (moving away is allowed)
            continue
        reasons.append(fault.line())
    return "; ".join(reasons) if reasons else None
