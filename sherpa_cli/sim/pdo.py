"""TPDOs of a simulated node, kept as strictly as CiA 301 asks (CANopenNode's CO_PDO.c is the
reference implementation the rules and abort codes follow).

Communication parameter 0x1800 + n: sub 0 highest sub-index (5), 1 COB-ID, 2 transmission type,
3 inhibit time (100 us), 5 event timer (ms). Mapping parameter 0x1A00 + n: sub 0 number of mapped
objects, 1..8 entries (index << 16 | sub << 8 | bits).

Refused, with CANopenNode's abort codes:

- COB-ID: bits 11..29 set, a restricted CAN-ID (CiA 301 7.3.5: 0x000-0x07F, 0x101-0x180,
  0x581-0x5FF, 0x601-0x67F, 0x6E0-0x6FF, 0x701-0x7FF), a new CAN-ID while the PDO is valid, or
  making a PDO valid that maps nothing: 0x06090030.
- Transmission type 241..253 (reserved, or RTR-only, which the node does not offer): 0x06090030.
- Inhibit time while the PDO is valid: 0x06090030.
- Mapping while the PDO is valid, or an entry while the count is not 0: 0x06010000.
- A count over 8 or mapped objects longer than 8 bytes: 0x06040042; an object that cannot be
  mapped (not mappable, length not whole bytes or longer than the object) or a count covering an
  empty entry: 0x06040041. Dummy entries (index 0x0001..0x001F, sub 0) map zeros.

A ``fixed`` PDO (the Whistle's TPDO2, the binary interpreter's reply channel) reads like any other
and refuses every write with 0x06010002; the table never sends it. Everything is RAM: a boot puts
the defaults back; :meth:`TpdoTable.snapshot` / :meth:`TpdoTable.restore` carry it between commands.

Transmission types: 0 (acyclic synchronous: at a SYNC if the mapped values changed since the last
one sent), 1..240 (every n-th SYNC), 254/255 (event-driven: every event timer period, if the timer
is not 0), only while the node is Operational (its owner asks). The inhibit time (sub 3, 100 us)
holds an event-driven TPDO back until that long after its last send (CiA 301 applies it to types
254/255 only); a timer that came due meanwhile sends once when it ends, as CANopenNode does.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.sim.od import ABORT_NO_OBJECT, ABORT_NO_SUBINDEX, ABORT_RANGE, ABORT_READ_ONLY, ODError, is_restricted

ABORT_UNSUPPORTED = 0x06010000  # unsupported access to an object
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_LENGTH = 0x06040042
ABORT_INVALID = ABORT_RANGE  # 0x06090030: invalid value for parameter (CANopenNode ODR_INVALID_VALUE)
ABORT_DEVICE_STATE = 0x08000022  # data cannot be transferred in the present device state
COB_INVALID = 0x80000000
COB_NO_RTR = 0x40000000
COB_RESERVED = 0x3FFFF800  # bits 11..29 must be 0 (no 29-bit ids)
MAX_ENTRIES, MAX_BITS = 8, 64
COMM_SUBS = (1, 2, 3, 5)
HIGHEST_COMM_SUB = 5

# the drive's mappable objects: (index, sub) -> bits
DRIVE_MAPPABLE: Mapping[tuple[int, int], int] = {(0x6064, 0): 32, (0x6069, 0): 32, (0x606C, 0): 32, (0x6078, 0): 16}
MAPPABLE = {(i, s, bits) for (i, s), bits in DRIVE_MAPPABLE.items()}  # the drive's, as (index, sub, bits)
TPDO_BASES = {0: 0x180, 1: 0x280, 2: 0x380, 3: 0x480}  # TPDO number - 1 -> function code


def is_pdo_object(index: int) -> bool:
    """TPDO communication / mapping objects a simulated Whistle serves (TPDO1..4)."""
    return 0x1800 <= index <= 0x1803 or 0x1A00 <= index <= 0x1A03


@dataclass(frozen=True)
class TpdoDefault:
    """One TPDO at boot."""

    cob: int  # 0x18xx:1
    ttype: int = 254
    entries: tuple[int, ...] = ()
    event_ms: int = 0


@dataclass
class _Tpdo:
    default: TpdoDefault
    cob: int = 0
    ttype: int = 254
    inhibit: int = 0
    event_ms: int = 0
    count: int = 0
    entries: list[int] = field(default_factory=lambda: [0] * MAX_ENTRIES)
    syncs: int = 0  # SYNCs counted toward the next synchronous send
    next_event: float = math.inf  # the event timer's next send
    last: bytes | None = None  # the last payload sent (type 0 sends only a change)
    sent_at: float = -math.inf  # when it was last sent event-driven (the inhibit time counts from it)

    @property
    def inhibit_s(self) -> float:
        return self.inhibit / 10_000  # 0x1800+n:3 counts 100 us

    def reset(self) -> None:
        d = self.default
        self.cob, self.ttype, self.inhibit, self.event_ms = d.cob, d.ttype, 0, d.event_ms
        self.count = len(d.entries)
        self.entries = [*d.entries, *[0] * (MAX_ENTRIES - len(d.entries))]
        self.syncs, self.next_event, self.last, self.sent_at = 0, math.inf, None, -math.inf

    @property
    def valid(self) -> bool:
        return not self.cob & COB_INVALID


def drive_defaults(node: int) -> dict[int, TpdoDefault]:
    """A Whistle's TPDOs at boot: TPDO1/3/4 not valid and empty; TPDO2 the interpreter's reply
    channel ([IG]: COB-ID 0x280 + node with RTR not allowed, type 254, mapped to 0x2013, 64 bits)."""
    out = {n: TpdoDefault(COB_INVALID | (base + node)) for n, base in TPDO_BASES.items() if n != 1}
    out[1] = TpdoDefault(COB_NO_RTR | (0x280 + node), 254, (0x20130040,))
    return dict(sorted(out.items()))


class TpdoTable:
    """The TPDOs of one node: ``defaults`` (PDO number - 1 -> boot state), ``mappable``
    ((index, sub) -> bits), ``fixed`` PDO numbers - 1 that refuse writes and are never sent here."""

    @property
    def cob(self) -> dict[int, int]:
        """COB-ID (0x18xx:1) per TPDO number - 1."""
        return {n: p.cob for n, p in self.pdos.items()}

    def __init__(self, node: int, defaults: Mapping[int, TpdoDefault] | None = None,
                 mappable: Mapping[tuple[int, int], int] = DRIVE_MAPPABLE, fixed: frozenset[int] = frozenset({1})) -> None:
        self.node = node
        self.mappable = dict(mappable)
        self.fixed = fixed
        self.pdos = {n: _Tpdo(d) for n, d in (defaults if defaults is not None else drive_defaults(node)).items()}
        self.reset()

    def reset(self) -> None:
        for pdo in self.pdos.values():
            pdo.reset()

    # -- objects ------------------------------------------------------------------------------
    def serves(self, index: int) -> bool:
        return (0x1800 <= index < 0x1A00 or 0x1A00 <= index < 0x1C00) and (index & 0x1FF) in self.pdos

    def _which(self, index: int) -> tuple[_Tpdo, int, bool]:
        n = index & 0x1FF
        if not self.serves(index):
            raise ODError(f"object 0x{index:04X} does not exist", ABORT_NO_OBJECT)
        return self.pdos[n], n, index < 0x1A00

    def read(self, index: int, sub: int) -> int:
        pdo, _, comm = self._which(index)
        if comm:
            values = {0: HIGHEST_COMM_SUB, 1: pdo.cob, 2: pdo.ttype, 3: pdo.inhibit, 5: pdo.event_ms}
            if sub in values:
                return values[sub]
        elif sub == 0:
            return pdo.count
        elif 1 <= sub <= MAX_ENTRIES:
            return pdo.entries[sub - 1]
        raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)

    def write(self, index: int, sub: int, value: int, now: float = 0.0) -> None:
        """Store a value or raise ODError with CiA 301's abort code; ``now`` starts an event timer."""
        pdo, n, comm = self._which(index)
        if (comm and sub not in COMM_SUBS and sub != 0) or (not comm and not 0 <= sub <= MAX_ENTRIES):
            raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)
        if n in self.fixed or (sub == 0 and comm):
            raise ODError(f"0x{index:04X}:{sub} is read-only", ABORT_READ_ONLY)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFFFFFF:
            raise ODError(f"0x{index:04X}:{sub}: {value!r} is no UNSIGNED32", ABORT_INVALID)
        if comm:
            self._write_comm(pdo, index, sub, value, now)
        else:
            self._write_map(pdo, index, sub, value)

    def _write_comm(self, pdo: _Tpdo, index: int, sub: int, value: int, now: float) -> None:
        where = f"0x{index:04X}:{sub}"
        if sub == 1:
            can_id, valid = value & 0x7FF, not value & COB_INVALID
            if value & COB_RESERVED:
                raise ODError(f"{where}: 0x{value:08X}: bits 11..29 must be 0", ABORT_INVALID)
            if valid and pdo.valid and can_id != pdo.cob & 0x7FF:
                raise ODError(f"{where}: the CAN-ID of a valid PDO cannot change; set bit 31 first", ABORT_INVALID)
            if valid and is_restricted(can_id):
                raise ODError(f"{where}: CAN-ID 0x{can_id:03X} is restricted (CiA 301)", ABORT_INVALID)
            if valid and pdo.count == 0:
                raise ODError(f"{where}: the PDO maps nothing; map it before making it valid", ABORT_INVALID)
            was = pdo.valid
            pdo.cob = value
            if valid and not was:
                pdo.syncs, pdo.last, pdo.sent_at = 0, None, -math.inf
                self._arm_timer(pdo, now)
            elif not valid:
                pdo.next_event = math.inf
        elif sub == 2:
            if not 0 <= value <= 240 and value not in (254, 255):
                raise ODError(f"{where}: transmission type {value} is reserved (0..240, 254, 255)", ABORT_INVALID)
            pdo.ttype, pdo.syncs, pdo.last = value, 0, None
            self._arm_timer(pdo, now)
        elif sub == 3:
            if pdo.valid:
                raise ODError(f"{where}: the inhibit time of a valid PDO cannot change; set bit 31 first",
                              ABORT_INVALID)
            if value > 0xFFFF:
                raise ODError(f"{where}: {value} outside 0..65535", ABORT_INVALID)
            pdo.inhibit = value
        else:  # 5: event timer
            if value > 0xFFFF:
                raise ODError(f"{where}: {value} outside 0..65535 ms", ABORT_INVALID)
            pdo.event_ms = value
            self._arm_timer(pdo, now)

    def _write_map(self, pdo: _Tpdo, index: int, sub: int, value: int) -> None:
        where = f"0x{index:04X}:{sub}"
        if pdo.valid:
            raise ODError(f"{where}: the PDO is valid; set bit 31 of 0x{index - 0x200:04X}:1 first", ABORT_UNSUPPORTED)
        if sub > 0 and pdo.count:
            raise ODError(f"{where}: set the number of mapped objects (sub 0) to 0 first", ABORT_UNSUPPORTED)
        if sub == 0:
            if value > MAX_ENTRIES:
                raise ODError(f"{where}: {value} entries; a PDO maps at most {MAX_ENTRIES}", ABORT_PDO_LENGTH)
            entries = pdo.entries[:value]
            if any(e == 0 for e in entries):
                raise ODError(f"{where}: {value} entries cover an empty one", ABORT_NOT_MAPPABLE)
            if sum(e & 0xFF for e in entries) > MAX_BITS:
                raise ODError(f"{where}: the mapped objects are longer than 8 bytes", ABORT_PDO_LENGTH)
            pdo.count = value
            return
        if value:
            bits, key = value & 0xFF, (value >> 16, value >> 8 & 0xFF)
            if bits > MAX_BITS:
                raise ODError(f"{where}: 0x{value:08X} is longer than a PDO", ABORT_PDO_LENGTH)
            dummy = 1 <= key[0] <= 0x1F and key[1] == 0
            if not bits or bits % 8 or not (dummy or bits <= self.mappable.get(key, 0)):
                raise ODError(f"{where}: 0x{value:08X} cannot be mapped", ABORT_NOT_MAPPABLE)
        pdo.entries[sub - 1] = value

    @staticmethod
    def _arm_timer(pdo: _Tpdo, now: float) -> None:
        timed = pdo.valid and pdo.ttype >= 254 and pdo.event_ms > 0
        pdo.next_event = now + pdo.event_ms / 1000 if timed else math.inf

    # -- sending ------------------------------------------------------------------------------
    def _frame(self, pdo: _Tpdo, values: Mapping[int, Callable[[], int]]) -> tuple[int, bytes]:
        payload, bits = 0, 0
        for entry in pdo.entries[:pdo.count]:
            length = entry & 0xFF
            source = values.get(entry >> 16)  # a dummy entry (or an object without a source) maps zeros
            raw = int(source()) & ((1 << length) - 1) if source is not None else 0
            payload |= raw << bits
            bits += length
        return pdo.cob & 0x7FF, payload.to_bytes((bits + 7) // 8, "little")

    def frame(self, n: int, values: Mapping[int, Callable[[], int]]) -> tuple[int, bytes]:
        """TPDO ``n``'s frame now (COB-ID, payload)."""
        return self._frame(self.pdos[n], values)

    def _sendable(self, n: int, pdo: _Tpdo) -> bool:
        return n not in self.fixed and pdo.valid and pdo.count > 0

    def on_sync(self, values: Mapping[int, Callable[[], int]]) -> list[tuple[int, bytes]]:
        """Frames due at this SYNC: each valid synchronous TPDO whose SYNC count came round."""
        frames = []
        for n, pdo in self.pdos.items():
            if not self._sendable(n, pdo) or pdo.ttype > 240:
                continue
            if pdo.ttype == 0:
                frame = self._frame(pdo, values)
                if frame[1] != pdo.last:
                    pdo.last = frame[1]
                    frames.append(frame)
                continue
            pdo.syncs += 1
            if pdo.syncs < pdo.ttype:
                continue
            pdo.syncs = 0
            frames.append(self._frame(pdo, values))
        return frames

    def next_due(self) -> float:
        """When an event timer sends next (inf: none running)."""
        return min((p.next_event for n, p in self.pdos.items() if self._sendable(n, p)), default=math.inf)

    def on_timers(self, now: float, values: Mapping[int, Callable[[], int]], eps: float = 1e-9) -> list[tuple[int, bytes]]:
        """Frames of the event timers due by ``now`` (each timer sends once and re-arms). A timer due
        within its PDO's inhibit time waits for its end: the node wakes then (:meth:`next_due`)."""
        frames = []
        for n, pdo in self.pdos.items():
            if self._sendable(n, pdo) and pdo.next_event <= now + eps:
                free = pdo.sent_at + pdo.inhibit_s
                if now + eps < free:
                    pdo.next_event = free  # due, but held back: one send when the inhibit time ends
                    continue
                frames.append(self._frame(pdo, values))
                pdo.sent_at = now
                period = pdo.event_ms / 1000
                while pdo.next_event <= now + eps:
                    pdo.next_event += period
        return frames

    def note_sent(self, n: int, now: float) -> None:
        """TPDO ``n`` (number - 1) went out event-driven outside the timer (the CiA 406 encoder's send on
        entering Operational): its inhibit time counts from ``now``."""
        self.pdos[n].sent_at = now

    def start_timers(self, now: float) -> None:
        """The node entered Operational: event timers count from now."""
        for pdo in self.pdos.values():
            self._arm_timer(pdo, now)

    def stop_timers(self) -> None:
        for pdo in self.pdos.values():
            pdo.next_event = math.inf

    def sending(self, n: int) -> bool:
        """TPDO ``n`` (number - 1) is valid, maps something and is not fixed."""
        pdo = self.pdos.get(n)
        return pdo is not None and self._sendable(n, pdo)

    # -- RAM between commands ---------------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        return {str(n): {"cob": p.cob, "ttype": p.ttype, "inhibit": p.inhibit, "event_ms": p.event_ms,
                         "count": p.count, "entries": list(p.entries)} for n, p in self.pdos.items()}

    def restore(self, saved: Mapping[str, Any]) -> None:
        """What :meth:`snapshot` gave; a value that no write could have stored raises ValueError."""
        for key, item in saved.items():
            pdo = self.pdos.get(int(key))
            if pdo is None or not isinstance(item, Mapping):
                raise ValueError(f"TPDO {key}: not a TPDO of this node")
            entries = item.get("entries")
            numbers = [item.get(k) for k in ("cob", "ttype", "inhibit", "event_ms", "count")]
            if not isinstance(entries, list) or len(entries) != MAX_ENTRIES or not all(
                    isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 0xFFFFFFFF for v in [*numbers, *entries]):
                raise ValueError(f"TPDO {key}: damaged")
            cob, ttype, inhibit, event_ms, count = (int(v or 0) for v in numbers)
            if count > MAX_ENTRIES or (not 0 <= ttype <= 240 and ttype not in (254, 255)) or any(
                    e == 0 for e in entries[:count]):
                raise ValueError(f"TPDO {key}: damaged")
            pdo.cob, pdo.ttype, pdo.inhibit, pdo.event_ms, pdo.count = cob, ttype, inhibit, event_ms, count
            pdo.entries = [int(e) for e in entries]
            pdo.syncs, pdo.last, pdo.next_event, pdo.sent_at = 0, None, math.inf, -math.inf
