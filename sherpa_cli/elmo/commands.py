"""Declarative table of the SimplIQ interpreter commands the tool uses.

Facts come from docs elmo-protocol.md section 2; entries the sources leave open are
marked UNCONFIRMED in their description so the CLI can show it.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Literal

from sherpa_cli.errors import CodecError

ValueType = Literal["int", "float"]
Access = Literal["rw", "ro", "x"]

INDEX_MAX = 0x3FFF  # 14-bit index field of the binary interpreter
INT32_MIN = -(2**31)
INT32_MAX = 2**31 - 1


@dataclass(frozen=True)
class Override:
    """Per-index differences of an array command; None keeps the command's own value."""

    value_type: ValueType | None = None
    units: str | None = None
    motor_off: bool | None = None
    zero_disables: bool | None = None
    description: str | None = None
    disable_below: float | None = None


_NO_OVERRIDES: Mapping[int, Override] = MappingProxyType({})


@dataclass(frozen=True)
class CommandSpec:
    """One interpreter command. ``index_max == 0`` means scalar (index always 0)."""

    letters: str
    index_min: int
    index_max: int
    value_type: ValueType | None
    access: Access
    motor_off: bool
    units: str
    zero_disables: bool
    description: str
    # Some protections switch off below a threshold rather than at exactly 0 (CL[2] < 2).
    disable_below: float | None = None
    overrides: Mapping[int, Override] = field(default_factory=lambda: _NO_OVERRIDES, hash=False)

    @property
    def is_array(self) -> bool:
        return self.index_max > 0

    def check_index(self, index: int) -> int:
        """Return ``index`` if this command accepts it, else raise CodecError."""
        if isinstance(index, bool) or not isinstance(index, int):
            raise CodecError(f"{self.letters}: index must be an integer, got {index!r}")
        if not 0 <= index <= INDEX_MAX:
            raise CodecError(f"{self.letters}[{index}]: index must be 0..{INDEX_MAX} (14 bits)")
        if not self.is_array:
            if index != 0:
                raise CodecError(f"{self.letters} is not an array command; {self.letters}[{index}] is invalid",
                                 hint=f"write just {self.letters}")
        elif not self.index_min <= index <= self.index_max:
            raise CodecError(f"{self.letters}[{index}]: index outside {self.index_min}..{self.index_max}")
        return index

    def at(self, index: int) -> CommandSpec:
        """The spec as it applies to one index, with that index's override folded in."""
        self.check_index(index)
        ov = self.overrides.get(index)
        if ov is None:
            return self
        changes = {name: getattr(ov, name) for name in
                   ("value_type", "units", "motor_off", "zero_disables", "description", "disable_below")
                   if getattr(ov, name) is not None}
        return replace(self, overrides=_NO_OVERRIDES, **changes)

    def disables_protection(self, index: int, value: float) -> bool:
        """True if writing ``value`` at ``index`` switches a protection off."""
        spec = self.at(index)
        if spec.disable_below is not None:
            return value < spec.disable_below
        return spec.zero_disables and value == 0


def _cmd(letters: str, value_type: ValueType | None, access: Access, description: str, *,
         index: tuple[int, int] = (0, 0), units: str = "", motor_off: bool = False,
         zero_disables: bool = False, overrides: Mapping[int, Override] | None = None) -> CommandSpec:
    return CommandSpec(letters, index[0], index[1], value_type, access, motor_off, units, zero_disables,
                       description, overrides=MappingProxyType(dict(overrides or {})))


_LIMIT_PAIR_NOTE = "1 = current-related (UNCONFIRMED), 2 = speed, 3 = position"

_TABLE: tuple[CommandSpec, ...] = (
    _cmd("MO", "int", "rw", "motor enable (1 on, 0 off)"),
    _cmd("UM", "int", "rw", "unit mode: 1 torque, 2 speed, 3 stepper, 4 dual-feedback pos, 5 single-feedback pos",
         motor_off=True),
    # Sources only ever set PM with the motor off (COB, BLISS); assumed to need it.
    _cmd("PM", "int", "rw", "profiler mode (UM=2)", motor_off=True),
    _cmd("AC", "int", "rw", "acceleration", units="cnt/s^2"),
    _cmd("DC", "int", "rw", "deceleration", units="cnt/s^2"),
    _cmd("SD", "int", "rw", "stop deceleration (ST, stop manager, limit switches)", units="cnt/s^2"),
    _cmd("SP", "int", "rw", "max speed of PTP motion", units="cnt/s"),
    _cmd("JV", "int", "rw", "jog velocity", units="cnt/s"),
    _cmd("PA", "int", "rw", "absolute position target", units="counts"),
    _cmd("PR", "int", "rw", "relative position target", units="counts"),
    _cmd("PX", "int", "rw", "main position counter", units="counts", motor_off=True),
    # PY is the position feedback in UM=4; moving it under a running loop is as bad as PX.
    _cmd("PY", "int", "rw", "auxiliary position counter", units="counts", motor_off=True),
    _cmd("VX", "int", "ro", "main encoder velocity", units="cnt/s"),
    _cmd("VY", "int", "ro", "auxiliary encoder velocity", units="cnt/s"),
    _cmd("PE", "int", "ro", "position error", units="counts"),
    _cmd("VE", "int", "ro", "velocity error", units="cnt/s"),
    _cmd("DV", "int", "ro", "desired (reference) values: 2 speed, 3 position", index=(1, 3),
         overrides={2: Override(units="cnt/s"), 3: Override(units="counts")}),
    _cmd("MS", "int", "ro", "motion status: 0 at target, 1 stationary/MO=0, 2 profiler active"),
    _cmd("BG", None, "x", "begin motion"),
    _cmd("ST", None, "x", "stop motion (decelerate with SD)"),
    _cmd("TC", "float", "rw", "torque (current) command in UM=1", units="A"),
    _cmd("IQ", "float", "ro", "active (torque) current", units="A"),
    _cmd("ID", "float", "ro", "reactive current (type/units UNCONFIRMED)", units="A"),
    _cmd("XM", "int", "rw", "modulo range of main position: 1 low, 2 high (XM[2]-XM[1] even)",
         index=(1, 2), units="counts", motor_off=True),
    _cmd("YM", "int", "rw", "modulo range of auxiliary position: 1 low, 2 high",
         index=(1, 2), units="counts", motor_off=True),
    _cmd("TR", "int", "rw", "target radius (1, counts) and time (2, ms) for MS=0", index=(1, 2),
         overrides={1: Override(units="counts"), 2: Override(units="ms")}),
    _cmd("LL", "int", "rw", f"low feedback limit (trip, motor shut down); {_LIMIT_PAIR_NOTE}",
         index=(1, 3), motor_off=True,
         overrides={2: Override(units="cnt/s", zero_disables=True),
                    3: Override(units="counts", zero_disables=True)}),
    _cmd("HL", "int", "rw", f"high feedback limit (trip, motor shut down); {_LIMIT_PAIR_NOTE}",
         index=(1, 3), motor_off=True,
         overrides={2: Override(units="cnt/s", zero_disables=True),
                    3: Override(units="counts", zero_disables=True)}),
    # "All-zero VH/VL can mean no-limits mode" (field notes, Gold docs): flag [3] so a zero
    # position window is never written by accident.
    _cmd("VL", "int", "rw", f"low command limit (clipped, no fault); {_LIMIT_PAIR_NOTE}",
         index=(1, 3), motor_off=True,
         overrides={2: Override(units="cnt/s"), 3: Override(units="counts", zero_disables=True)}),
    _cmd("VH", "int", "rw", f"high command limit (clipped, no fault); {_LIMIT_PAIR_NOTE}",
         index=(1, 3), motor_off=True,
         overrides={2: Override(units="cnt/s"), 3: Override(units="counts", zero_disables=True)}),
    _cmd("ER", "int", "rw", "max tracking error: 2 speed, 3 position", index=(1, 3),
         overrides={2: Override(units="cnt/s"), 3: Override(units="counts")}),
    _cmd("CL", "float", "rw", "current limits: 1 continuous, 2 stuck-motor torque %, 3 stuck-motor min speed",
         index=(1, 3),
         overrides={1: Override(units="A", description="continuous current limit"),
                    2: Override(units="%", zero_disables=True, disable_below=2.0,
                                description="stuck-motor torque threshold, % of CL[1] (<2 disables)"),
                    3: Override(value_type="int", units="cnt/s", description="stuck-motor minimum speed")}),
    _cmd("PL", "float", "rw", "peak current: 1 limit, 2 duration", index=(1, 2),
         overrides={1: Override(units="A", description="peak current limit"),
                    2: Override(value_type="int", units="s",
                                description="peak current duration (type UNCONFIRMED)")}),
    _cmd("MC", "float", "ro", "max drive current", units="A"),
    _cmd("LC", "int", "ro", "current limit active flag"),
    _cmd("IP", "int", "ro", "input port (flags and raw pins)"),
    _cmd("IL", "int", "rw", "function of digital input N (even active low, odd active high)",
         index=(1, 10), motor_off=True),
    _cmd("IB", "int", "ro", "single input bit (UNCONFIRMED: bit N of IP)", index=(0, 31)),
    _cmd("SR", "int", "ro", "status register"),
    _cmd("MF", "int", "ro", "motor failure mask (latched until next MO=1)"),
    _cmd("EC", "int", "ro", "error code of the last failed interpreter command"),
    _cmd("SV", None, "x", "save parameters to flash (MO=0; comms pause for a few hundred ms)"),
    _cmd("LD", None, "x", "load parameters from flash (semantics UNCONFIRMED)"),
    _cmd("HP", None, "x", "sent before SV by public code (meaning UNCONFIRMED)"),
    _cmd("CA", "int", "rw", "commutation / feedback array (CA[18] counts per rev UNCONFIRMED)",
         index=(1, 63), motor_off=True),
    _cmd("SN", "int", "ro", "identity: 1 vendor, 2 product, 3 revision, 4 serial", index=(1, 4)),
    _cmd("WS", "int", "ro", "drive status words (WS[30] hardware version)", index=(1, 100)),
    _cmd("HM", "int", "rw", "homing: 1 arm, 2 value, 3 event, 4 action, 5 PX update, 6 output", index=(1, 6)),
    _cmd("RM", "int", "rw", "reference mode"),
    _cmd("UI", "int", "rw", "user integers (RAM; whether SV saves them is UNCONFIRMED); "
         "UI[protocol.calibration_flag] marks a drive homed since power-up", index=(1, 24)),
    _cmd("ET", "int", "rw", "ECAM table entries", index=(1, 1024)),
    # real-arm.md section 4 (one public source): elmo/userprog.py reads it before SV and motion
    _cmd("PS", "int", "ro", "user program status: -1 idle, -2 no program, 1 running (values UNCONFIRMED)"),
    # The recorder (real-arm.md 2; MAN-SIMCR, MAN-SIMSW 7.4): RAM settings, elmo/recorder.py drives them.
    _cmd("RV", "int", "rw", "recorder: signal id mapped to logical signal N", index=(1, 16)),
    _cmd("RC", "int", "rw", "recorder: mask of recorded logical signals (at most 8 bits)"),
    _cmd("RG", "int", "rw", "recorder: gap, samples every RG sample times (1..4096)"),
    _cmd("RL", "int", "rw", "recorder: length, samples per signal"),
    _cmd("RP", "int", "rw", "recorder: 3 trigger (0 now, 1 BG, ...), 4/5 levels, 6/7 input, 8/9 upload part",
         index=(0, 9)),
    _cmd("RR", "int", "rw", "recorder: write 0 kill, 1 at next BG, 2 now, 3 per RP; read -1 no data, "
         "0 data ready, 1..3 waiting"),
    # Gains (real-arm.md 3; MAN-SIMSW ch. 15): KP[2]/KI[2] speed loop, KP[3] position loop; the
    # meanings of KP[1]/KI[1]/KI[3] and of every FF[] index are UNCONFIRMED.
    _cmd("KP", "float", "rw", "proportional gain: 2 speed loop, 3 position loop (1 UNCONFIRMED)", index=(1, 3)),
    _cmd("KI", "float", "rw", "integral gain: 2 speed loop (1, 3 UNCONFIRMED)", index=(1, 3)),
    _cmd("FF", "float", "rw", "feed-forward (index meanings UNCONFIRMED)", index=(1, 3)),
    # PVT table motion (real-arm.md 5, [IG] 13-28; elmo/pvt.py, docs/pvt.md): MP[4] and MP[6] are named
    # by [IG] 13-28, the other indexes, QT as the PVT period and PV as the start are UNCONFIRMED.
    _cmd("MP", "int", "rw", "PVT/PT set-up: 1 first row, 2 last row, 3 cyclic, 4 queue-low rows, 6 write pointer "
         "(1, 2, 3 UNCONFIRMED)", index=(1, 6)),
    _cmd("QT", "int", "rw", "PT/PVT row time (UNCONFIRMED for PVT)", index=(1, 64), units="ms"),
    _cmd("PV", "int", "rw", "start PVT motion at this row, then BG (UNCONFIRMED)"),
)

COMMANDS: Mapping[str, CommandSpec] = MappingProxyType({c.letters: c for c in _TABLE})

_LETTERS = re.compile(r"[A-Z]{2}")
_KEY = re.compile(r"^\s*([^\[\]\s]+)\s*(?:\[\s*([^\]]*?)\s*\])?\s*$")


def check_letters(letters: object) -> str:
    """Return ``letters`` if they are two upper-case ASCII letters, else raise CodecError."""
    if not isinstance(letters, str):
        raise CodecError(f"command letters must be a string, got {letters!r}")
    if _LETTERS.fullmatch(letters):
        return letters
    if not letters.isascii():
        raise CodecError(f"command {letters!r} contains non-ASCII characters")
    if len(letters) == 2 and letters.isalpha():
        raise CodecError(f"command {letters!r} must be upper case", hint=f"write {letters.upper()}")
    raise CodecError(f"command {letters!r} must be exactly two letters A-Z")


def lookup(letters: str) -> CommandSpec:
    """The table entry for ``letters``; CodecError names unknown commands and the closest known one."""
    check_letters(letters)
    spec = COMMANDS.get(letters)
    if spec is None:
        close = difflib.get_close_matches(letters, list(COMMANDS), n=1, cutoff=0.5)
        hint = f"did you mean {close[0]}?" if close else None
        suffix = f" (did you mean {close[0]}?)" if close else ""
        raise CodecError(f"unknown command {letters}{suffix}", hint=hint)
    return spec


def param_key(letters: str, index: int = 0) -> str:
    """``"AC"`` for scalar commands, ``"LL[3]"`` for array commands; validates the index."""
    spec = lookup(letters)
    spec.check_index(index)
    return f"{letters}[{index}]" if spec.is_array else letters


def parse_param_key(key: str) -> tuple[str, int]:
    """Inverse of :func:`param_key`: ``"LL[3]"`` -> ``("LL", 3)``, ``"AC"`` -> ``("AC", 0)``."""
    if not isinstance(key, str):
        raise CodecError(f"parameter key must be a string, got {key!r}")
    m = _KEY.match(key)
    if m is None:
        raise CodecError(f"bad parameter key {key!r}", hint="write e.g. AC or LL[3]")
    letters, raw_index = m.group(1), m.group(2)
    spec = lookup(letters)
    if raw_index is None:
        if spec.is_array:
            raise CodecError(f"{letters} is an array command; {key!r} needs an index",
                             hint=f"write e.g. {letters}[{spec.index_min}]")
        return letters, 0
    if not raw_index.isdigit() or not raw_index.isascii():
        raise CodecError(f"bad index {raw_index!r} in {key!r}: must be a decimal number")
    return letters, spec.check_index(int(raw_index))


def format_value(value: object, digits: int = 6) -> str:
    """A parameter value as a technician types it: ints plain, floats to ``digits`` significant
    digits, which hides float32 noise."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, float):
        text = f"{value:.{digits}g}"
        return text if any(c in text for c in ".en") else text + ".0"
    return str(value)
