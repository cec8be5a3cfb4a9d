"""Elmo PVT (position-velocity-time) streaming over CAN: the record frame, the set-up as data and the
PVT emergencies as named events. Pure: no bus, no client.

A PVT record is one RPDO of 8 bytes, INT32 position (counts) then INT32 velocity (counts/s), little-endian
(MAN-CAN301IG p. 2-6, the PV object). The drive keeps the records in a queue (the PVT table, rows
MP[1]..MP[2], at most 64: [IG] 13-28) and plays one per period, interpolating between rows.

Which RPDO carries the record, the object it maps, which interpreter commands set the mode up and how the
motion starts are not in the sources read: each is a field of :class:`PvtSettings` with the documented or
most likely value as its default, UNCONFIRMED (docs/pvt.md).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from sherpa_cli.elmo.faults import EMCY_PVT, Emcy
from sherpa_cli.elmo.protocol import COB_INVALID, RPDO1_BASE, RPDO_COMM, RPDO_MAP
from sherpa_cli.errors import CodecError

RECORD = struct.Struct("<ii")
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
PHYSICAL_ROWS = 64  # [IG] 13-28: the write pointer's physical range is 1..64
RPDO_COB_STEP = 0x100  # RPDO n's predefined COB-ID is 0x200 + 0x100 (n - 1) + node (CiA 301)


@dataclass(frozen=True)
class PvtRecord:
    """One row of the PVT table: where the motor is to be at the end of its period, and how fast."""

    position: int  # counts
    velocity: int  # counts/s


def encode_record(position: int, velocity: int) -> bytes:
    """The 8 data bytes of one PVT record; CodecError for a value that is no int32."""
    for what, value in (("position", position), ("velocity", velocity)):
        if isinstance(value, bool) or not isinstance(value, int):
            raise CodecError(f"PVT {what} must be an integer, got {value!r}")
        if not INT32_MIN <= value <= INT32_MAX:
            raise CodecError(f"PVT {what} {value} is outside the int32 range")
    return RECORD.pack(position, velocity)


def decode_record(data: bytes) -> PvtRecord:
    if len(data) != RECORD.size:
        raise CodecError(f"a PVT record is {RECORD.size} bytes, got {len(data)}: {bytes(data).hex(' ')}")
    return PvtRecord(*RECORD.unpack(bytes(data)))


@dataclass(frozen=True)
class PvtSettings:
    """The PVT CAN path. Every default is UNCONFIRMED unless its comment names a source (docs/pvt.md)."""

    rpdo: int = 3  # the RPDO that carries the records (RPDO2 is the interpreter's)
    data_object: int = 0x2001  # the object the RPDO maps (motion-and-recording.md: "PVT via 0x2001")
    data_sub: int = 0
    transmission_type: int = 255  # asynchronous: the drive queues a record when it arrives
    unit_mode: int = 5  # position mode; [CR] 3-116: table motion in UM 3..5
    first_row: int = 1  # MP[1]: the first row of the queue
    queue_size: int = 64  # rows MP[1]..MP[2]; at most 64 ([IG] 13-28)
    cyclic: int = 1  # MP[3]: 1 = the queue wraps round (streaming), 0 = one pass through the table
    low_threshold: int = 16  # MP[4]: EMCY "queue low" below this many unplayed rows ([IG] 13-28)
    period_ms: int = 10  # the time of every row
    period_command: tuple[str, int] = ("QT", 1)  # where the period is written (real-arm.md: QT[n] in ms)
    write_pointer_command: tuple[str, int] = ("MP", 6)  # the first row written ([IG] 13-28 names MP[6])
    start_command: tuple[str, int] = ("PV", 0)  # set to the first row: PVT motion from there
    begin_with_bg: bool = True  # BG after the start command begins the motion

    def __post_init__(self) -> None:
        ints = {"rpdo": (1, 4), "data_object": (0x2000, 0x5FFF), "data_sub": (0, 255),
                "transmission_type": (0, 255), "unit_mode": (1, 5), "first_row": (1, PHYSICAL_ROWS),
                "queue_size": (2, PHYSICAL_ROWS), "cyclic": (0, 1), "low_threshold": (0, PHYSICAL_ROWS),
                "period_ms": (1, 255)}
        for name, (lo, hi) in ints.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                raise ValueError(f"PvtSettings.{name} must be an integer {lo}..{hi}, got {value!r}")
        if self.rpdo == 2:
            raise ValueError("PvtSettings.rpdo: RPDO2 is the binary interpreter's")
        if self.last_row > PHYSICAL_ROWS:
            raise ValueError(f"PvtSettings: rows {self.first_row}..{self.last_row} pass row {PHYSICAL_ROWS}")
        if self.low_threshold >= self.queue_size:
            raise ValueError("PvtSettings.low_threshold must be below queue_size")

    @property
    def last_row(self) -> int:
        return self.first_row + self.queue_size - 1

    @property
    def period_s(self) -> float:
        return self.period_ms / 1000

    @property
    def comm_index(self) -> int:
        return RPDO_COMM + self.rpdo - 1

    @property
    def map_index(self) -> int:
        return RPDO_MAP + self.rpdo - 1

    @property
    def mapping_entry(self) -> int:
        """The mapping value: object index << 16 | sub-index << 8 | 64 bits."""
        return self.data_object << 16 | self.data_sub << 8 | RECORD.size * 8

    def cob_id(self, node: int) -> int:
        return RPDO1_BASE + RPDO_COB_STEP * (self.rpdo - 1) + node


@dataclass(frozen=True)
class InterpSet:
    """One interpreter set of the set-up (``MP[4]=16``); the motor must be off for it when ``motor_off``."""

    letters: str
    index: int
    value: int

    @property
    def name(self) -> str:
        return f"{self.letters}[{self.index}]" if self.index else self.letters


@dataclass(frozen=True)
class SdoSet:
    """One SDO write of the set-up (the PDO mapping); ``size`` in bytes."""

    index: int
    sub: int
    size: int
    value: int

    @property
    def name(self) -> str:
        return f"0x{self.index:04X}:{self.sub}"


def interpreter_setup(s: PvtSettings) -> tuple[InterpSet, ...]:
    """The interpreter sets that put a drive into PVT mode, in order; the motor is off for the first
    (UM) and every MP[] ([IG] 13-28 ties bad set-up data to EMCY 0x07 at the start)."""
    return (
        InterpSet("UM", 0, s.unit_mode),
        InterpSet("MP", 1, s.first_row),
        InterpSet("MP", 2, s.last_row),
        InterpSet("MP", 3, s.cyclic),
        InterpSet("MP", 4, s.low_threshold),
        InterpSet(*s.write_pointer_command, s.first_row),
        InterpSet(*s.period_command, s.period_ms),
    )


def pdo_setup(s: PvtSettings, node: int) -> tuple[SdoSet, ...]:
    """The SDO writes that map the record RPDO, in CiA 301's order: the PDO off, its mapping emptied,
    the entry written, the count set, the transmission type, the PDO on."""
    cob = s.cob_id(node)
    return (
        SdoSet(s.comm_index, 1, 4, cob | COB_INVALID),
        SdoSet(s.map_index, 0, 1, 0),
        SdoSet(s.map_index, 1, 4, s.mapping_entry),
        SdoSet(s.map_index, 0, 1, 1),
        SdoSet(s.comm_index, 2, 1, s.transmission_type),
        SdoSet(s.comm_index, 1, 4, cob),
    )


def pdo_restore(s: PvtSettings, old: dict[tuple[int, int], int]) -> tuple[SdoSet, ...]:
    """The SDO writes that put the record RPDO back as ``old`` held it (keys (index, sub) of every object
    :func:`pdo_setup` writes), in the same safe order: off, mapping, type, then its old COB-ID."""
    comm, mapping = s.comm_index, s.map_index
    return (
        SdoSet(comm, 1, 4, old[(comm, 1)] | COB_INVALID),
        SdoSet(mapping, 0, 1, 0),
        SdoSet(mapping, 1, 4, old[(mapping, 1)]),
        SdoSet(mapping, 0, 1, old[(mapping, 0)]),
        SdoSet(comm, 2, 1, old[(comm, 2)]),
        SdoSet(comm, 1, 4, old[(comm, 1)]),
    )


def start_steps(s: PvtSettings) -> tuple[InterpSet, ...]:
    """The interpreter set that starts PVT motion at the first row (BG follows if ``begin_with_bg``)."""
    return (InterpSet(*s.start_command, s.first_row),)


# -- the PVT emergencies -------------------------------------------------------------------------

class PvtEventKind(enum.Enum):
    QUEUE_LOW = 0x56
    QUEUE_FULL = 0x34
    BAD_HEAD_POINTER = 0x5B
    NOT_MAPPED = 0x5C
    BAD_SETUP = 0x07
    MOTION_TERMINATED = 0x08
    MESSAGE_LOST = 0x09
    OUT_OF_MODULO = 0xA6
    # real-arm.md lists 0x8A "underflow" beside these (PyLabRobot KX2, DS402 interpolation); [IG] 13-28 has
    # no 0x8A: an underflow there is 0x08 with field 2 = 3. Both are read as the stream ending.
    UNDERFLOW = 0x8A


class TerminationCause(enum.IntEnum):
    """Data field 2 of 0x08 "motion terminated" ([IG] 13-28)."""

    END_OF_TRAJECTORY = 1  # the end of the table in non-cyclic mode
    BAD_TIME = 2  # a zero or negative time for a row
    UNDERFLOW = 3  # the read pointer reached the write pointer: the queue ran empty


@dataclass(frozen=True)
class PvtEvent:
    kind: PvtEventKind
    field1: int
    field2: int

    @property
    def ends_stream(self) -> bool:
        """Everything but "queue low" means the drive stopped or lost a record: the stream cannot go on."""
        return self.kind is not PvtEventKind.QUEUE_LOW

    @property
    def underflow(self) -> bool:
        return self.kind is PvtEventKind.UNDERFLOW or (
            self.kind is PvtEventKind.MOTION_TERMINATED and self.field2 == TerminationCause.UNDERFLOW)

    @property
    def text(self) -> str:
        words = {
            PvtEventKind.QUEUE_LOW: f"PVT queue low (write pointer {self.field1}, read pointer {self.field2})",
            PvtEventKind.QUEUE_FULL: f"PVT queue full: row {self.field1} could not be written",
            PvtEventKind.BAD_HEAD_POINTER: f"PVT write pointer out of range (MP[6]={self.field1})",
            PvtEventKind.NOT_MAPPED: "PVT: the record PDO is not mapped",
            PvtEventKind.BAD_SETUP: "PVT: bad set-up data (write pointer outside MP[1]..MP[2])",
            PvtEventKind.MOTION_TERMINATED: "PVT motion terminated, motor stopped: " + _cause(self.field2),
            PvtEventKind.MESSAGE_LOST: "PVT: a CAN message was lost",
            PvtEventKind.OUT_OF_MODULO: "PVT position out of the modulo range",
            PvtEventKind.UNDERFLOW: "PVT queue underflow",
        }
        return words[self.kind]


def _cause(field2: int) -> str:
    try:
        cause = TerminationCause(field2)
    except ValueError:
        return f"cause {field2}"
    return {TerminationCause.END_OF_TRAJECTORY: "end of the table",
            TerminationCause.BAD_TIME: "a zero or negative row time",
            TerminationCause.UNDERFLOW: "the queue ran empty (underflow)"}[cause]


def pvt_event(emcy: Emcy) -> PvtEvent | None:
    """The PVT event an EMCY carries (code 0xFF00, the Elmo code in byte 3), or None for any other."""
    if emcy.code != EMCY_PVT:
        return None
    try:
        kind = PvtEventKind(emcy.elmo_code)
    except ValueError:
        return None
    return PvtEvent(kind, emcy.field1, emcy.field2)
