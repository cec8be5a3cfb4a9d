"""PVT mode of a simulated Whistle: the receive PDOs that can carry PVT records, and the PVT queue.

RPDO1/3/4 (0x1400 + n / 0x1600 + n; RPDO2 is the interpreter's) keep CiA 301's rules as the TPDOs do
(sim/pdo.py): a mapping changes only while the PDO is off (COB-ID bit 31), an entry only while the count is
0, a valid PDO's CAN-ID does not change; a write that leaves a value as it is is accepted. Unlike a TPDO, an
RPDO that maps nothing may be valid: it is so at power-up (configs/eds/whistle.eds), and is put back so. The one object
an RPDO can map is the PVT record (``SimSettings.pvt_object``, 64 bits: INT32 position + INT32 velocity).

The queue ([IG] 13-28): rows MP[1]..MP[2] (at most ``SimSettings.pvt_rows``), a write pointer that starts
at MP[6] and wraps in cyclic mode (MP[3]=1), a read pointer. PV=n then BG starts the motion at row n; from
then on one row is played per period (``QT[1]`` ms) on the drive's own clock: the motor goes from where it
was to the row's position and velocity along the cubic that meets both ends' positions and velocities
(Hermite), as Elmo's PVT interpolates. EMCY 0xFF00 with the Elmo code in byte 3: 0x56 when fewer than MP[4]
rows are left unplayed (once until the queue fills past it again), 0x34 for a record with no free row,
0x08 field 2 = 3 when the queue runs empty while moving: the motor then stops with DC. Which commands and
objects these are is UNCONFIRMED (docs/pvt.md); the simulator plays what elmo/pvt.py's defaults send.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.elmo.pvt import RECORD, PvtRecord
from sherpa_cli.sim.od import ABORT_NO_SUBINDEX, ABORT_RANGE, ODError

ABORT_UNSUPPORTED = 0x06010000
ABORT_NOT_MAPPABLE = 0x06040041
COB_INVALID = 0x80000000
COB_RESERVED = 0x3FFFF800
RPDO_BASES = {0: 0x200, 2: 0x400, 3: 0x500}  # RPDO number - 1 -> function code; RPDO2 is the interpreter's
MAX_ENTRIES = 8

QUEUE_LOW, QUEUE_FULL, TERMINATED = 0x56, 0x34, 0x08
CAUSE_UNDERFLOW = 3


@dataclass
class Rpdo:
    cob: int
    ttype: int = 255
    count: int = 0
    entries: list[int] = field(default_factory=lambda: [0] * MAX_ENTRIES)

    @property
    def valid(self) -> bool:
        return not self.cob & COB_INVALID


class RpdoTable:
    """RPDO1/3/4 of one node: communication and mapping parameters, and which CAN-ID carries records."""

    def __init__(self, node: int, record_entry: int) -> None:
        self.node = node
        self.record_entry = record_entry  # the mapping value of the PVT record (index << 16 | sub << 8 | 64)
        self.pdos: dict[int, Rpdo] = {}
        self._record_cobs: frozenset[int] = frozenset()  # kept with every write: each frame on the bus asks
        self.reset()

    def reset(self) -> None:
        self.pdos = {n: Rpdo(base + self.node) for n, base in RPDO_BASES.items()}
        self._update()

    def _update(self) -> None:
        self._record_cobs = frozenset(p.cob & 0x7FF for p in self.pdos.values()
                                      if p.valid and p.count == 1 and p.entries[0] == self.record_entry)

    @staticmethod
    def serves(index: int) -> bool:
        return index - 0x1400 in RPDO_BASES or index - 0x1600 in RPDO_BASES

    def read(self, index: int, sub: int) -> int:
        comm = index < 0x1600
        pdo = self.pdos[index - (0x1400 if comm else 0x1600)]
        if comm:
            values = {0: 2, 1: pdo.cob, 2: pdo.ttype}
            if sub in values:
                return values[sub]
        elif sub == 0:
            return pdo.count
        elif 1 <= sub <= MAX_ENTRIES:
            return pdo.entries[sub - 1]
        raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)

    def write(self, index: int, sub: int, value: int) -> None:
        self._write(index, sub, value)
        self._update()

    def _write(self, index: int, sub: int, value: int) -> None:
        if self.read(index, sub) == value:
            return  # nothing changes: accepted in any state
        comm = index < 0x1600
        pdo = self.pdos[index - (0x1400 if comm else 0x1600)]
        if comm:
            if sub == 1:
                if value & COB_RESERVED:
                    raise ODError(f"0x{index:04X}:1: bits 11..29 must be 0", ABORT_RANGE)
                if pdo.valid and not value & COB_INVALID and value != pdo.cob:
                    raise ODError(f"0x{index:04X}:1: the CAN-ID of a valid PDO cannot change", ABORT_RANGE)
                pdo.cob = value
            elif sub == 2:
                if 241 <= value <= 253 or not 0 <= value <= 255:
                    raise ODError(f"0x{index:04X}:2: {value} is no transmission type", ABORT_RANGE)
                pdo.ttype = value
            else:
                raise ODError(f"0x{index:04X}:{sub} is read-only", ABORT_UNSUPPORTED)
            return
        if pdo.valid:
            raise ODError(f"0x{index:04X}: the mapping of a valid PDO cannot change; set bit 31 first",
                          ABORT_UNSUPPORTED)
        if sub == 0:
            if not 0 <= value <= MAX_ENTRIES:
                raise ODError(f"0x{index:04X}:0: at most {MAX_ENTRIES} entries", ABORT_RANGE)
            if value and any(e != self.record_entry for e in pdo.entries[:value]):
                raise ODError(f"0x{index:04X}:0: the entries cannot be mapped", ABORT_NOT_MAPPABLE)
            if value > 1:
                raise ODError(f"0x{index:04X}:0: more than 8 bytes mapped", 0x06040042)
            pdo.count = value
            return
        if pdo.count:
            raise ODError(f"0x{index:04X}:{sub}: set the count to 0 first", ABORT_UNSUPPORTED)
        if value not in (0, self.record_entry):
            raise ODError(f"0x{index:04X}:{sub}: 0x{value:08X} cannot be mapped to an RPDO", ABORT_NOT_MAPPABLE)
        pdo.entries[sub - 1] = value

    def record_cob(self, can_id: int) -> bool:
        """Whether ``can_id`` is a valid RPDO that maps the PVT record."""
        return can_id in self._record_cobs

    def snapshot(self) -> dict[str, Any]:
        return {str(n): {"cob": p.cob, "ttype": p.ttype, "count": p.count, "entries": list(p.entries)}
                for n, p in self.pdos.items()}

    def restore(self, saved: dict[str, Any]) -> None:
        for key, raw in saved.items():
            n = int(key)
            if n in self.pdos:
                entries = [int(e) for e in raw["entries"]][:MAX_ENTRIES]
                self.pdos[n] = Rpdo(int(raw["cob"]), int(raw["ttype"]), int(raw["count"]),
                                    entries + [0] * (MAX_ENTRIES - len(entries)))
        self._update()


@dataclass(frozen=True)
class PvtEmcy:
    """An emergency the queue raises: the drive sends it as 0xFF00, register 0x81, ``code`` in byte 3."""

    code: int
    field1: int = 0
    field2: int = 0


@dataclass
class Segment:
    t0: float
    x0: float
    v0: float
    x1: float
    v1: float
    period: float

    def at(self, t: float) -> tuple[float, float]:
        """Position and velocity at ``t`` on the cubic Hermite through both ends."""
        h = self.period
        s = min(max((t - self.t0) / h, 0.0), 1.0)
        s2, s3 = s * s, s * s * s
        x = ((2 * s3 - 3 * s2 + 1) * self.x0 + (s3 - 2 * s2 + s) * h * self.v0
             + (-2 * s3 + 3 * s2) * self.x1 + (s3 - s2) * h * self.v1)
        v = ((6 * s2 - 6 * s) * self.x0 + (3 * s2 - 4 * s + 1) * h * self.v0
             + (-6 * s2 + 6 * s) * self.x1 + (3 * s2 - 2 * s) * h * self.v1) / h
        return x, v


class PvtQueue:
    """The PVT table of one drive; positions here are PX counts (the drive converts)."""

    def __init__(self, rows: int) -> None:
        self.rows = rows
        self.queue: deque[PvtRecord] = deque()
        self.first = 1
        self.last = rows
        self.cyclic = True
        self.low = 0
        self.write_pointer = 1
        self.read_pointer = 1
        self.segment: Segment | None = None  # the row being played; None: not moving in PVT
        self.low_sent = False
        self.played = 0  # rows played since the start
        self.bad: PvtEmcy | None = None  # set-up data the start refuses

    @property
    def capacity(self) -> int:
        return self.last - self.first + 1

    @property
    def active(self) -> bool:
        return self.segment is not None

    def configure(self, first: int, last: int, cyclic: int, low: int, write_pointer: int) -> None:
        """MP[1..4, 6] written: a new, empty table. Set-up data the drive refuses is kept and answered at
        the start (:attr:`bad`): EMCY 0x5B for rows outside the physical table, 0x07 for a write pointer
        outside MP[1]..MP[2] ([IG] 13-28)."""
        self.stop()
        self.bad = None
        if not 1 <= first <= last <= self.rows:
            self.bad = PvtEmcy(0x5B, write_pointer)
        elif not first <= write_pointer <= last:
            self.bad = PvtEmcy(0x07, write_pointer)
        else:
            self.first, self.last = first, last
            self.write_pointer = self.read_pointer = write_pointer
        self.cyclic, self.low = bool(cyclic), low
        self.low_sent = False
        self.played = 0

    def push(self, data: bytes) -> PvtEmcy | None:
        """A record arrived: it goes into the next free row, or EMCY queue full."""
        if len(data) != RECORD.size:
            return None  # a PDO shorter than its mapping is not taken (CiA 301); not modelled further
        if len(self.queue) >= self.capacity:
            return PvtEmcy(QUEUE_FULL, self.write_pointer)
        self.queue.append(PvtRecord(*RECORD.unpack(data)))
        self.write_pointer = self._next(self.write_pointer)
        if len(self.queue) >= self.low:
            self.low_sent = False
        return None

    def start(self, t: float, x: float, period: float) -> PvtEmcy | None:
        """PV=n, BG: the first row becomes the end of the first period, from where the motor stands."""
        if self.bad is not None:
            return self.bad
        if period <= 0:
            return PvtEmcy(TERMINATED, self.write_pointer, 2)
        self.played = 0
        return self._next_segment(t, x, 0.0, period)

    def next_due(self) -> float:
        return self.segment.t0 + self.segment.period if self.segment is not None else math.inf

    def boundary(self, t: float, period: float) -> PvtEmcy | None:
        """The playing row is done at ``t``: the next one starts, or the queue ran empty (underflow)."""
        seg = self.segment
        assert seg is not None
        return self._next_segment(t, seg.x1, seg.v1, period)

    def _next_segment(self, t: float, x: float, v: float, period: float) -> PvtEmcy | None:
        if not self.queue:
            self.segment = None
            return PvtEmcy(TERMINATED, self.write_pointer, CAUSE_UNDERFLOW)
        row = self.queue.popleft()
        self.read_pointer = self._next(self.read_pointer)
        self.played += 1
        self.segment = Segment(t, x, v, row.position, row.velocity, period)
        if len(self.queue) < self.low and not self.low_sent:
            self.low_sent = True
            return PvtEmcy(QUEUE_LOW, self.write_pointer, self.read_pointer)
        return None

    def stop(self) -> None:
        self.segment = None
        self.queue.clear()

    def _next(self, pointer: int) -> int:
        return self.first if pointer >= self.last else pointer + 1
