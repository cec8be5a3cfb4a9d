"""Parameter store of the simulated drive: factory defaults, what SV saves, value ranges.

Keys are the command table's parameter keys (``"AC"``, ``"LL[3]"``) so RAM, flash and the
tool's parameter dumps share one spelling. Status values (PX, VX, SR, ...) are not stored
here; the drive computes them.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping
from types import MappingProxyType

from sherpa_cli.elmo.commands import COMMANDS, INT32_MAX, INT32_MIN, CommandSpec, parse_param_key
from sherpa_cli.errors import CodecError

Value = int | float

WIDE_POSITION = 1_000_000_000  # counts; wide enough that a factory drive never trips on position

# Factory defaults. Elmo's own factory values are not in the sources read: these are wide
# and mutually consistent (VL/VH inside LL/HL, SP below VH[2], CL[1] <= MC/2) so that a fresh
# simulated drive moves, and every value the tool derives (seed Appendix C) differs from them.
_FACTORY: dict[str, Value] = {
    "UM": 5, "PM": 1, "RM": 0,
    "AC": 100_000, "DC": 100_000, "SD": 1_000_000, "SP": 100_000,
    "JV": 0, "PA": 0, "PR": 0, "TC": 0.0, "PY": 0,
    "LL[1]": 0, "HL[1]": 0, "VL[1]": 0, "VH[1]": 0,  # meaning UNCONFIRMED; not modelled
    "LL[2]": -1_000_000, "HL[2]": 1_000_000,
    "VL[2]": -500_000, "VH[2]": 500_000,
    "LL[3]": -WIDE_POSITION, "HL[3]": WIDE_POSITION,
    "VL[3]": -WIDE_POSITION, "VH[3]": WIDE_POSITION,
    "ER[1]": 0, "ER[2]": 100_000, "ER[3]": 10_000,
    "CL[1]": 5.0, "CL[2]": 0.0, "CL[3]": 0,
    "PL[1]": 10.0, "PL[2]": 3,
    "XM[1]": -WIDE_POSITION, "XM[2]": WIDE_POSITION,
    "YM[1]": -WIDE_POSITION, "YM[2]": WIDE_POSITION,
    "TR[1]": 100, "TR[2]": 20,
    "CA[18]": 4096,
    # IL=4 is "ignore, active low" ([ELMOCAN] writes it to disable switches). It differs from
    # both seed codes (21 stop, 5 home), so programming a switch always shows as a change.
    "IL": 4,
    # recorder (RAM only; sim/recorder.py): the manual's default mapping RV[N]=N
    "RC": 0, "RG": 1, "RL": 256, **{f"RP[{n}]": 0 for n in range(10)}, **{f"RV[{n}]": n for n in range(1, 17)},
    # gains: made-up but plausible; the servo model (sim/servo.py) reads KP[2], KI[2], KP[3] relative
    # to these (its REFERENCE_GAINS): a drive's configured loop is the loop at these gains
    "KP[1]": 1.0, "KP[2]": 0.5, "KP[3]": 30.0, "KI[1]": 100.0, "KI[2]": 200.0, "KI[3]": 0.0,
    "FF[1]": 0.0, "FF[2]": 0.0, "FF[3]": 0.0,
}

# What SV writes to flash. Targets, commands and counters (JV, PA, PR, TC, PX, PY, MO, HM)
# are volatile on the real drive too: a reboot must not resume a motion.
PERSISTENT = frozenset({"UM", "PM", "AC", "DC", "SD", "SP", "LL", "HL", "VL", "VH", "ER", "CL", "PL",
                        "XM", "YM", "TR", "IL", "CA", "ET", "KP", "KI", "FF"})


def factory_ram(inputs: int) -> dict[str, Value]:
    ram = {k: v for k, v in _FACTORY.items() if k != "IL"}
    ram.update({f"IL[{n}]": _FACTORY["IL"] for n in range(1, inputs + 1)})
    return ram


def is_persistent(key: str) -> bool:
    return key[:2] in PERSISTENT


def is_float(spec: CommandSpec) -> bool:
    return spec.value_type == "float"


def to_float32(value: float) -> float:
    """The value a float32 register really holds, so an echo or a read-back matches the bus."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def wrap_int32(value: int) -> int:
    """Counters wrap like the drive's 32-bit registers instead of breaking the reply encoder."""
    return (value - INT32_MIN) % 2**32 + INT32_MIN


def coerce(spec: CommandSpec, value: Value) -> Value | None:
    """``value`` in the parameter's own type, or None if it cannot be represented.

    A mismatched type bit is converted as the ASCII interpreter does ([SW] 4-8: float to an
    integer parameter is rounded); whether the binary interpreter does the same is UNCONFIRMED.
    """
    if is_float(spec):
        value = float(value)
        if not math.isfinite(value):
            return None
        return to_float32(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return None
        value = round(value)
    return value if INT32_MIN <= value <= INT32_MAX else None


def _between(lo: float, hi: float) -> Callable[[Value], bool]:
    return lambda v: lo <= v <= hi


# Ranges that give EC 21 (operand out of range). Units 3 and 4 exist on the drive but the
# model has no stepper or dual-loop, so refusing them is more honest than ignoring them.
_RANGES: Mapping[str, Callable[[Value], bool]] = MappingProxyType({
    "MO": _between(0, 1), "UM": lambda v: v in (1, 2, 5), "PM": _between(0, 1), "RM": _between(0, 1),
    "AC": _between(1, INT32_MAX), "DC": _between(1, INT32_MAX), "SD": _between(1, INT32_MAX),
    "SP": _between(0, INT32_MAX), "IL": _between(0, 23),
    "TR": _between(0, INT32_MAX), "ER": _between(0, INT32_MAX),
    # [IG] 9-4's worked error example: `CA[1]=4` is answered EC 21. The guide gives no range for CA[1]
    # ([TUM]'s EC texts make CA[1..6] the Hall sensor mapping, so 1..3 are believed to name Hall inputs);
    # only CA[1] is checked, as narrowly as the example allows: above 3 (or negative) is refused, and 0,
    # what CA[1] reads until written, stays accepted.
    "CA[1]": _between(0, 3),
    "CL[2]": _between(0.0, 100.0), "CL[3]": _between(0, INT32_MAX), "PL[2]": _between(0, 60),
})
_CURRENT_RANGES = {"CL[1]": 0.5, "PL[1]": 1.0, "TC": 1.0}  # fraction of MC


def in_range(key: str, value: Value, max_current: float) -> bool:
    if key in _CURRENT_RANGES:
        limit = max_current * _CURRENT_RANGES[key]
        return (-limit if key == "TC" else 0.0) <= value <= limit
    check = _RANGES.get(key) or _RANGES.get(key[:2])
    return check(value) if check else True


def parse_flash(flash: Mapping[str, Value] | None) -> dict[str, Value]:
    """Validate a caller's flash image: interpreter keys must be persistent parameters."""
    out: dict[str, Value] = {}
    for key, value in (flash or {}).items():
        if isinstance(key, str) and key.startswith("0x"):
            out[key] = value  # object-dictionary entries; the drive validates them on load
            continue
        try:
            letters, index = parse_param_key(key)
        except CodecError as exc:
            raise ValueError(f"flash key {key!r}: {exc.message}") from None
        canon = f"{letters}[{index}]" if COMMANDS[letters].is_array else letters
        if not is_persistent(canon):
            raise ValueError(f"flash key {key!r}: {letters} is not saved by SV")
        spec = COMMANDS[letters].at(index)
        coerced = coerce(spec, value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None
        if coerced is None:
            raise ValueError(f"flash key {key!r}: bad value {value!r}")
        out[canon] = coerced
    return out
