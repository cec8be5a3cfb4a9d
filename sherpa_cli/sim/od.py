"""The CANopen objects of a simulated Whistle that are not PDO parameters (sim/pdo.py) or the
recorder's (sim/recorder.py); configs/eds/whistle.eds describes them all, tests/test_eds.py keeps the two equal.

Values are Python ints or str; an SDO layer encodes them. Errors carry the CiA abort code the
SDO server must send, so the simulator and a real drive fail the same way.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.elmo.protocol import EMCY_BASE, SYNC_ID

if TYPE_CHECKING:
    from sherpa_cli.sim.settings import SimSettings

ABORT_NO_OBJECT = 0x06020000
ABORT_NO_SUBINDEX = 0x06090011
ABORT_READ_ONLY = 0x06010002
ABORT_TYPE = 0x06070010
ABORT_RANGE = 0x06090030

# DS402 device type: profile 402, additional info 0x0002 (servo drive). Elmo's printed value
# was not in the pages read (UNCONFIRMED); a tool should log it, not insist on it.
DEVICE_TYPE = 0x00020192

OdValue = int | str


class ODError(LookupError):
    """An SDO access that the drive refuses; ``abort_code`` is the CiA 301 abort code."""

    def __init__(self, message: str, abort_code: int) -> None:
        super().__init__(message)
        self.abort_code = abort_code


def is_restricted(can_id: int) -> bool:
    """CiA 301's restricted CAN-IDs (NMT, SYNC/EMCY, TIME, SDO, LSS, heartbeat, ...): no PDO and no
    SYNC may use them (7.3.5)."""
    return (can_id <= 0x7F or 0x101 <= can_id <= 0x180 or 0x581 <= can_id <= 0x5FF or 0x601 <= can_id <= 0x67F
            or 0x6E0 <= can_id <= 0x6FF or can_id >= 0x701)


# 0x1005 COB-ID SYNC (CiA 301 7.5.2.5): bits 0..10 the CAN-ID, 29 frame (29-bit ids), 30 gen (this node
# produces SYNC), 31 "do not care". The node is a SYNC consumer with 11-bit ids only, so bits 11..30 are
# refused (CiA 301 names 0x06090030 for the frame bit; CANopenNode's OD_write_1005 uses it for all of them).
SYNC_CAN_ID = 0x7FF
SYNC_REFUSED_BITS = 0x7FFFF800


@dataclass(frozen=True)
class Entry:
    writable: bool
    lo: int = 0
    hi: int = 0xFFFFFFFF
    reserved: int = 0  # bits that must stay 0 (a COB-ID's)


COB_INVALID = 0x80000000  # bit 31 of a COB-ID object: the service is off


# Entries a host may write and SV saves (section 3.5: "Persist with SV if wanted").
WRITABLE: Mapping[tuple[int, int], Entry] = {
    (0x1014, 0): Entry(True, reserved=0x7FFFF800),  # EMCY COB-ID ([IG] 12-11): bit 31 off, 11-bit CAN-ID only
    (0x1016, 1): Entry(True, 0, 0x00FFFFFF),  # bits 31..24 must be 0 ([IG 12-12])
    (0x1017, 0): Entry(True, 0, 0xFFFF),
    (0x1029, 1): Entry(True, 0, 2),
    (0x6007, 0): Entry(True, 0, 3),
    (0x1005, 0): Entry(True, 0, 0xFFFFFFFF),  # COB-ID SYNC: checked in check_value
    (0x2040, 0): Entry(True, 0, 127),  # group id ([IG] 13-10): 0 none; a frame to 0x300+id reaches the group
}


def flash_key(index: int, sub: int) -> str:
    return f"0x{index:04X}:{sub}"


class ObjectDictionary:
    def __init__(self, constants: Mapping[tuple[int, int], OdValue],
                 live: Mapping[tuple[int, int], Callable[[], OdValue]],
                 writable: Mapping[tuple[int, int], int]) -> None:
        self._constants = dict(constants)
        self._live = dict(live)
        self.values = {key: writable[key] for key in WRITABLE}

    def _known(self, index: int, sub: int) -> None:
        keys = {*self._constants, *self._live, *self.values}
        if (index, sub) in keys:
            return
        if any(i == index for i, _ in keys):
            raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)
        raise ODError(f"object 0x{index:04X} does not exist", ABORT_NO_OBJECT)

    def read(self, index: int, sub: int) -> OdValue:
        self._known(index, sub)
        key = (index, sub)
        if key in self._live:
            return self._live[key]()
        if key in self.values:
            return self.values[key]
        return self._constants[key]

    def check_write(self, index: int, sub: int, value: object) -> int:
        """The value to store, or ODError with the abort code a real drive would give."""
        self._known(index, sub)
        return check_value(index, sub, value)

    def check_change(self, index: int, sub: int, value: int) -> None:
        """CiA 301's rule for a COB-ID object: the CAN-ID of a valid service does not change in one
        write (a master sets bit 31 first), so no frame ever goes out on a half-changed id."""
        if (index, sub) != (0x1014, 0):
            return
        old = self.values[(index, sub)]
        if not old & COB_INVALID and not value & COB_INVALID and (old ^ value) & 0x7FF:
            raise ODError(f"0x{index:04X}: the CAN-ID of a valid EMCY cannot change; set bit 31 first", ABORT_RANGE)


def check_value(index: int, sub: int, value: object) -> int:
    entry = WRITABLE.get((index, sub))
    if entry is None:
        raise ODError(f"object 0x{index:04X}:{sub} is read-only", ABORT_READ_ONLY)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ODError(f"object 0x{index:04X}:{sub} takes an integer, got {value!r}", ABORT_TYPE)
    if not entry.lo <= value <= entry.hi:
        raise ODError(f"object 0x{index:04X}:{sub}: {value} outside {entry.lo}..{entry.hi}", ABORT_RANGE)
    if value & entry.reserved:
        raise ODError(f"object 0x{index:04X}:{sub}: 0x{value:08X} sets reserved bits", ABORT_RANGE)
    if (index, sub) == (0x1005, 0):
        if value & SYNC_REFUSED_BITS:
            raise ODError(f"0x1005: 0x{value:08X}: the node consumes SYNC on an 11-bit id only (bits 11..30 must be 0)",
                          ABORT_RANGE)
        if is_restricted(value & SYNC_CAN_ID):
            raise ODError(f"0x1005: CAN-ID 0x{value & SYNC_CAN_ID:03X} is restricted (CiA 301)", ABORT_RANGE)
    return value


def build_od(settings: SimSettings, serial: int, flash: Mapping[str, object],
             live: Mapping[tuple[int, int], Callable[[], OdValue]], node: int = 0) -> ObjectDictionary:
    """The dictionary after a boot: constants from settings, writable entries from flash."""
    defaults = {key: 0 for key in WRITABLE}
    defaults[(0x1014, 0)] = EMCY_BASE + node  # the predefined connection set's id
    defaults[(0x1017, 0)] = settings.heartbeat_ms
    # DS402 default 1 ("fault"): any non-zero value makes heartbeat loss shut the motor down.
    defaults[(0x6007, 0)] = 1
    defaults[(0x1005, 0)] = SYNC_ID  # CiA 301's default COB-ID SYNC
    writable = {}
    for key, default in defaults.items():
        value = flash.get(flash_key(*key), default)
        try:
            writable[key] = check_value(*key, value)
        except ODError as exc:
            raise ValueError(f"flash key {flash_key(*key)!r}: {exc}") from None
    constants: dict[tuple[int, int], OdValue] = {
        (0x1000, 0): DEVICE_TYPE, (0x1008, 0): settings.device_name, (0x1009, 0): f"0x{settings.hw_version:X}",
        (0x100A, 0): settings.sw_version, (0x100B, 0): node, (0x1016, 0): 1, (0x1018, 0): 4, (0x1018, 1): settings.vendor_id,
        (0x1018, 2): settings.product_code, (0x1018, 3): settings.revision, (0x1018, 4): serial, (0x1029, 0): 1,
    }
    return ObjectDictionary(constants, live, writable)
