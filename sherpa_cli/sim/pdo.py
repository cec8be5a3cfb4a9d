"""TPDOs of a simulated Whistle: communication (0x1800..0x1803) and mapping (0x1A00..0x1A03)
objects in RAM, and the frames a SYNC makes them send (transmission type 1..240: every n-th SYNC).

TPDO2 (0x1801/0x1A01) is the binary interpreter's reply channel and is not served here. The
objects live in RAM only: a boot (power-up or NMT reset) restores the defaults, and SV does not
save them (a real drive would; the tool never saves them).

Mappable objects: 0x6064 position actual value (PX, int32), 0x6069 and 0x606C velocity (VX,
int32, counts/s), 0x6078 current actual value (IQ as int16 mA -- UNCONFIRMED: DS402 says per
mille of the rated current; the tool's log/record.py names the same scale).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from sherpa_cli.sim.od import ABORT_NO_OBJECT, ABORT_NO_SUBINDEX, ABORT_RANGE, ODError

MAPPABLE = {(0x6064, 0, 32), (0x6069, 0, 32), (0x606C, 0, 32), (0x6078, 0, 16)}
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_LENGTH = 0x06040042
ABORT_DEVICE_STATE = 0x08000022  # data cannot be transferred in the present device state
TPDO_BASES = {0: 0x180, 2: 0x380, 3: 0x480}  # TPDO number - 1 -> function code (TPDO2 is the interpreter)


def is_pdo_object(index: int) -> bool:
    return (0x1800 <= index <= 0x1803 or 0x1A00 <= index <= 0x1A03) and (index & 0xFF) != 1


class TpdoTable:
    def __init__(self, node: int) -> None:
        self.node = node
        self.reset()

    def reset(self) -> None:
        # defaults: TPDO1/3/4 not valid (COB-ID bit 31), asynchronous, nothing mapped
        self.cob = {n: 0x80000000 | (base + self.node) for n, base in TPDO_BASES.items()}
        self.ttype = {n: 254 for n in TPDO_BASES}
        self.count = {n: 0 for n in TPDO_BASES}
        self.entries: dict[int, list[int]] = {n: [0] * 8 for n in TPDO_BASES}
        self._syncs = {n: 0 for n in TPDO_BASES}

    def read(self, index: int, sub: int) -> int:
        n, comm = self._which(index)
        if comm:
            if sub == 0:
                return 2
            if sub == 1:
                return self.cob[n]
            if sub == 2:
                return self.ttype[n]
            raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)
        if sub == 0:
            return self.count[n]
        if 1 <= sub <= 8:
            return self.entries[n][sub - 1]
        raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)

    def write(self, index: int, sub: int, value: int) -> None:
        n, comm = self._which(index)
        if comm:
            if sub == 1:
                self.cob[n] = value & 0xFFFFFFFF
            elif sub == 2:
                if not 0 <= value <= 255:
                    raise ODError(f"0x{index:04X}:2: {value} outside 0..255", ABORT_RANGE)
                self.ttype[n] = value
                self._syncs[n] = 0
            else:
                raise ODError(f"object 0x{index:04X}:{sub} is read-only", ABORT_NO_SUBINDEX)
            return
        if not self.cob[n] & 0x80000000:
            # CiA 301: a mapping changes only while its PDO is invalid (COB-ID bit 31 set)
            raise ODError(f"0x{index:04X}:{sub}: the PDO is valid; set bit 31 of 0x{0x1800 + n:04X}:1 first",
                          ABORT_DEVICE_STATE)
        if sub == 0:
            if not 0 <= value <= 8:
                raise ODError(f"0x{index:04X}:0: {value} outside 0..8", ABORT_RANGE)
            if sum(e & 0xFF for e in self.entries[n][:value]) > 64:
                raise ODError(f"0x{index:04X}: mapping longer than 8 bytes", ABORT_PDO_LENGTH)
            self.count[n] = value
            return
        if not 1 <= sub <= 8:
            raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)
        if value and (value >> 16, value >> 8 & 0xFF, value & 0xFF) not in MAPPABLE:
            raise ODError(f"0x{value:08X} cannot be mapped", ABORT_NOT_MAPPABLE)
        self.entries[n][sub - 1] = value

    def _which(self, index: int) -> tuple[int, bool]:
        n = index & 0xFF
        if n not in TPDO_BASES:
            raise ODError(f"object 0x{index:04X} does not exist", ABORT_NO_OBJECT)
        return n, index < 0x1A00

    def on_sync(self, values: Mapping[int, Callable[[], int]]) -> list[tuple[int, bytes]]:
        """Frames due at this SYNC: each valid synchronous TPDO whose SYNC count came round."""
        frames = []
        for n in TPDO_BASES:
            ttype, cob = self.ttype[n], self.cob[n]
            if cob & 0x80000000 or not 1 <= ttype <= 240 or not self.count[n]:
                continue
            self._syncs[n] += 1
            if self._syncs[n] < ttype:
                continue
            self._syncs[n] = 0
            payload, bits = 0, 0
            for entry in self.entries[n][:self.count[n]]:
                length = entry & 0xFF
                raw = int(values[entry >> 16]()) & ((1 << length) - 1)
                payload |= raw << bits
                bits += length
            frames.append((cob & 0x7FF, payload.to_bytes((bits + 7) // 8, "little")))
        return frames
