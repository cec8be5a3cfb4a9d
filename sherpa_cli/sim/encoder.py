"""A simulated CANopen absolute encoder (CiA 406, classes C1 and C2) on the bus: identity and the
encoder objects by SDO, and its position value in TPDO1 and TPDO2.

CiA 406 (v3.1, "changes" table) and the encoder manuals read (Kübler, Lika, ASM, BEI, HYDAC):

- TPDO1 (0x1800 / 0x1A00, COB-ID 0x180 + node) is mapped to 0x6004 (32 bits) by default; its event
  timer "shall be hard-wired with the cyclic timer (object 6200h)": 0x1800:5 and 0x6200 are one
  value, so with an asynchronous transmission type (254/255) the encoder sends TPDO1 every 0x6200 ms
  (0 = never). CiA 406 also sends TPDO1 once on entering Operational.
- TPDO2 (0x1801 / 0x1A01, COB-ID 0x280 + node) is synchronous (type 1) and mapped to 0x6004 too.
- Both follow CiA 301's rules for PDO objects (sim/pdo.py); TPDOs only in Operational.
- Objects: 0x6000 operating parameters (UNSIGNED16: bit 0 code sequence, bit 2 scaling), 0x6001
  measuring units per revolution, 0x6002 total measuring range, 0x6003 preset value, 0x6004
  position value (UNSIGNED32, never negative: a position below the encoder's zero counts down from
  2^32, which the tool's INTEGER32 reading of the same four bytes gives back as a negative number),
  0x6200 cyclic timer, 0x6500 operating status, 0x6501 singleturn resolution, 0x6502 number of
  revolutions, 0x6503..0x6506 alarms / warnings and what is supported (none raised), 0x6507
  profile and software version, 0x6508 operating time (0.1 h), 0x6509 offset value (INTEGER32).

0x6200's factory default differs between makers (ASM: 100 ms), so it is ``cyclic_ms`` here;
everything is RAM: a boot puts the defaults back (a real encoder would keep a preset after 0x1010).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Required, TypedDict, Unpack

from sherpa_cli.sim.clock import Clock
from sherpa_cli.sim.drive import OPERATIONAL, SimDrive
from sherpa_cli.sim.od import ABORT_RANGE, ABORT_READ_ONLY, ODError, OdValue
from sherpa_cli.sim.params import Value
from sherpa_cli.sim.pdo import TpdoDefault, TpdoTable
from sherpa_cli.sim.settings import SimSettings

TPDO1_BASE, TPDO2_BASE = 0x180, 0x280
POSITION_ENTRY = 0x60040020  # 0x6004:0, 32 bits
CYCLIC_TIMER = 0x6200
DEFAULT_TTYPE = 254  # asynchronous: the cyclic timer sends it (CiA 406)
OP_CODE_SEQUENCE, OP_SCALING = 0x0001, 0x0004
REVOLUTIONS = 4096  # 0x6502: a 12-bit multi-turn encoder
PROFILE_SW_VERSION = 0x0100_0302  # 0x6507: software 1.00 (high word), CiA 406 profile 3.2 (low word)
SUPPORTED_ALARMS = 0x0001  # 0x6504: position error

# CiA 301 data types (canopen.objectdictionary's numbers; this module loads without canopen)
U16, U32, I32 = 0x0006, 0x0007, 0x0004
# (index, sub or None, name, data type, access): what sim/sdo.py serves for an encoder
ENCODER_OBJECTS = (
    (0x6000, None, "Operating parameters", U16, "rw"),
    (0x6001, None, "Measuring units per revolution", U32, "rw"),
    (0x6002, None, "Total measuring range in measuring units", U32, "rw"),
    (0x6003, None, "Preset value", U32, "rw"),
    (0x6004, None, "Position value", U32, "ro"),
    (CYCLIC_TIMER, None, "Cyclic timer", U16, "rw"),
    (0x6500, None, "Operating status", U16, "ro"),
    (0x6501, None, "Singleturn resolution", U32, "ro"),
    (0x6502, None, "Number of distinguishable revolutions", U16, "ro"),
    (0x6503, None, "Alarms", U16, "ro"),
    (0x6504, None, "Supported alarms", U16, "ro"),
    (0x6505, None, "Warnings", U16, "ro"),
    (0x6506, None, "Supported warnings", U16, "ro"),
    (0x6507, None, "Profile and software version", U32, "ro"),
    (0x6508, None, "Operating time", U32, "ro"),
    (0x6509, None, "Offset value", I32, "ro"),
)
_READ_ONLY = {spec[0] for spec in ENCODER_OBJECTS if spec[4] == "ro"}


class DriveOptions(TypedDict, total=False):
    """SimDrive's keyword arguments that an encoder passes on (its ``position`` is its own)."""

    clock: Required[Clock]
    settings: SimSettings | None
    serial: int
    flash: Mapping[str, Value] | None
    save_count: int
    speed_gain: float
    on_step: Callable[[SimDrive], None] | None
    on_event: Callable[[SimDrive, float, str], None] | None
    od_live: Mapping[tuple[int, int], Callable[[], OdValue]] | None
    stalled_at: Callable[[float], float] | None


class SimEncoder(SimDrive):
    """The encoder node: a SimDrive for NMT, heartbeat and SDO, with its own TPDOs and CiA 406 objects."""

    sdo_extra = ENCODER_OBJECTS
    sdo_more = ()  # an encoder has no drive recorder
    sdo_tpdos = (0, 1)
    sdo_fixed_tpdos: frozenset[int] = frozenset()
    sdo_rpdo2 = False

    def __init__(self, node: int, *, position: Callable[[], int], cyclic_ms: int = 0, ttype: int = DEFAULT_TTYPE,
                 resolution: int = 4096, **kwargs: Unpack[DriveOptions]) -> None:
        self._read_position = position
        self._default_cyclic_ms = int(cyclic_ms)
        self._default_ttype = int(ttype)
        self.resolution = max(1, int(resolution))  # 0x6501: measuring steps per revolution
        self.tpdo_frames = 0  # TPDO1 frames sent, for tests
        # RAM, set afresh by every boot (_boot)
        self.operating = 0  # 0x6000
        self.units_per_rev = self.resolution  # 0x6001
        self.total_range = min(self.resolution * REVOLUTIONS, 0xFFFFFFFF)  # 0x6002
        self.offset = 0  # 0x6509, from the last preset
        super().__init__(node, **kwargs)
        self._power_up_t = self._t

    def _make_tpdo_table(self, node: int) -> TpdoTable:
        return TpdoTable(node, {0: TpdoDefault(TPDO1_BASE + node, self._default_ttype, (POSITION_ENTRY,),
                                               self._default_cyclic_ms),
                                1: TpdoDefault(TPDO2_BASE + node, 1, (POSITION_ENTRY,))},
                         mappable={(0x6004, 0): 32}, fixed=frozenset())

    # -- RAM defaults at every boot --------------------------------------------------------------
    def _boot(self) -> None:
        self.operating = 0
        self.units_per_rev = self.resolution
        self.total_range = min(self.resolution * REVOLUTIONS, 0xFFFFFFFF)
        self.offset = 0
        super()._boot()

    # -- the position value ----------------------------------------------------------------------
    def _unshifted(self) -> int:
        raw = int(self._read_position())
        if self.operating & OP_CODE_SEQUENCE:
            raw = -raw  # counting the other way round
        if self.operating & OP_SCALING:
            raw = raw * self.units_per_rev // self.resolution
        return raw

    def _modulus(self) -> int:
        scaled = self.operating & OP_SCALING and 0 < self.total_range < 0xFFFFFFFF
        return self.total_range if scaled else 1 << 32

    def position_value(self) -> int:
        """0x6004: UNSIGNED32, within the measuring range (never negative)."""
        return (self._unshifted() + self.offset) % self._modulus()

    def _pdo_values(self) -> dict[int, Callable[[], int]]:
        return {0x6004: self.position_value}

    # -- objects -------------------------------------------------------------------------------
    def od_read(self, index: int, sub: int) -> OdValue | bytes:
        if sub == 0:
            hours_10 = int((self._t - self._power_up_t) / 360)
            values = {0x6000: self.operating, 0x6001: self.units_per_rev, 0x6002: self.total_range,
                      0x6003: self.position_value(), 0x6500: self.operating, 0x6501: self.resolution,
                      0x6502: REVOLUTIONS, 0x6503: 0, 0x6504: SUPPORTED_ALARMS, 0x6505: 0, 0x6506: 0,
                      0x6507: PROFILE_SW_VERSION, 0x6508: hours_10 & 0xFFFFFFFF, 0x6509: self.offset}
            if index in values:
                return values[index]
            if index == CYCLIC_TIMER:
                return self.tpdo.read(0x1800, 5)
        return super().od_read(index, sub)

    def od_write(self, index: int, sub: int, value: int) -> None:
        if index == CYCLIC_TIMER and sub == 0:  # TPDO1's event timer is hard-wired to it
            self.advance_to(self.clock.now())
            self.tpdo.write(0x1800, 5, value, now=self._t)
            self.od_writes.append((self._t, index, sub, value))
            return None
        if (not 0x6000 <= index <= 0x6003 and index not in _READ_ONLY) or sub != 0:
            return super().od_write(index, sub, value)
        if index in _READ_ONLY:
            raise ODError(f"0x{index:04X} is read-only", ABORT_READ_ONLY)
        self.advance_to(self.clock.now())
        if index == 0x6000:
            if value & ~(OP_CODE_SEQUENCE | OP_SCALING) or not 0 <= value <= 0xFFFF:
                raise ODError(f"0x6000: 0x{value:04X}: only bit 0 (code sequence) and bit 2 (scaling) exist",
                              ABORT_RANGE)
            self.operating = value
        elif index in (0x6001, 0x6002):
            if not 1 <= value <= 0xFFFFFFFF:
                raise ODError(f"0x{index:04X}: {value} outside 1..4294967295", ABORT_RANGE)
            if index == 0x6001:
                self.units_per_rev = value
            else:
                self.total_range = value
        else:  # 0x6003 preset: the position value reads this from now on
            if not 0 <= value < self._modulus():
                raise ODError(f"0x6003: {value} outside the measuring range 0..{self._modulus() - 1}", ABORT_RANGE)
            offset = value - self._unshifted()
            self.offset = (offset + 2**31) % 2**32 - 2**31  # INTEGER32 (0x6509)
        self.od_writes.append((self._t, index, sub, value))
        return None

    # -- sending -------------------------------------------------------------------------------
    def _send_pdo(self, can_id: int, data: bytes) -> None:
        if can_id == self.tpdo.read(0x1800, 1) & 0x7FF:
            self._send_tpdo(can_id, data)
        else:
            self._send(can_id, data)

    def _send_tpdo(self, can_id: int, data: bytes) -> None:
        """TPDO1 (counted for tests; a test may replace it to silence TPDO1)."""
        self.tpdo_frames += 1
        self._send(can_id, data)

    def _nmt(self, cs: int) -> None:
        before = self._nmt_state
        super()._nmt(cs)
        if self._nmt_state == OPERATIONAL and before != OPERATIONAL and self.tpdo.sending(0) \
                and self.tpdo.read(0x1800, 2) >= 254:
            self._send_pdo(*self.tpdo.frame(0, self._pdo_values()))  # CiA 406: TPDO1 on entering Operational
            self.tpdo.note_sent(0, self._t)  # an event-driven send: the next waits out the inhibit time

    @property
    def cyclic_ms(self) -> int:
        """0x6200 (= 0x1800:5)."""
        return self.tpdo.read(0x1800, 5)

    @cyclic_ms.setter
    def cyclic_ms(self, value: int) -> None:
        self.tpdo.write(0x1800, 5, value, now=self._t)

    @property
    def next_cyclic(self) -> float:
        return self.tpdo.next_due() if self._nmt_state == OPERATIONAL else math.inf

    # -- RAM between `--sim` commands ----------------------------------------------------------
    def ram_snapshot(self, advance: bool = True) -> dict[str, object]:
        saved = super().ram_snapshot(advance)
        saved["encoder"] = {"operating": self.operating, "units_per_rev": self.units_per_rev,
                            "total_range": self.total_range, "offset": self.offset}
        return saved

    def restore_ram(self, saved: Mapping[str, object]) -> None:
        super().restore_ram(saved)
        enc = saved.get("encoder")
        if not isinstance(enc, dict) or not all(isinstance(enc.get(k), int) for k in
                                                ("operating", "units_per_rev", "total_range", "offset")):
            raise ValueError("encoder objects missing")
        self.operating, self.units_per_rev = enc["operating"], enc["units_per_rev"]
        self.total_range, self.offset = enc["total_range"], enc["offset"]
