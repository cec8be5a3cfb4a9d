"""A simulated CANopen absolute encoder (CiA 406) on the bus: identity and 0x6004 by SDO, and its
TPDO1 carrying the position value.

CiA 406 (v3.1, "changes" table) and the encoder manuals read (Kübler, Lika, ASM, BEI): TPDO1
(0x1800 / 0x1A00, COB-ID 0x180 + node) is mapped to 0x6004 (32 bits) by default; its event timer
"shall be hard-wired with the cyclic timer (object 6200h)", so with an asynchronous transmission
type (254/255) the encoder sends TPDO1 every 0x6200 ms (0 = never); transmission types 1..240
send it on every n-th SYNC (Lika: "synchronous transmission at each SYNC"). TPDOs only in
Operational; CiA 406 also sends TPDO1 once on entering Operational. 0x6200's factory default
differs between makers (ASM: 100 ms), so it is ``cyclic_ms`` here; everything is RAM: a boot puts
the defaults back.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping
from typing import Required, TypedDict, Unpack

from sherpa_cli.sim.clock import Clock
from sherpa_cli.sim.drive import OPERATIONAL, TIME_EPS, SimDrive
from sherpa_cli.sim.od import ABORT_NO_SUBINDEX, ABORT_RANGE, ODError, OdValue
from sherpa_cli.sim.params import Value
from sherpa_cli.sim.settings import SimSettings

TPDO1_BASE = 0x180
POSITION_ENTRY = 0x60040020  # 0x6004:0, 32 bits
CYCLIC_TIMER = 0x6200
DEFAULT_TTYPE = 254  # asynchronous: the cyclic timer sends it (CiA 406)


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


class SimEncoder(SimDrive):
    """The encoder node: a SimDrive for NMT, heartbeat and SDO, with its own TPDO1 and 0x6200."""

    sdo_extra = ((CYCLIC_TIMER, None, "Cyclic timer", 0x0006, "rw"),)  # UNSIGNED16, ms

    def __init__(self, node: int, *, position: Callable[[], int], cyclic_ms: int = 0, ttype: int = DEFAULT_TTYPE,
                 **kwargs: Unpack[DriveOptions]) -> None:
        self._read_position = position
        self._default_cyclic_ms = int(cyclic_ms)
        self._default_ttype = int(ttype)
        self.tpdo_frames = 0  # TPDO1 frames sent, for tests
        # RAM, set afresh by every boot (_boot); the COB-ID once SimDrive has checked the node id
        self.enc_cob: int  # 0x1800:1
        self.enc_ttype = self._default_ttype  # 0x1800:2
        self.enc_map_count = 1  # 0x1A00:0
        self.enc_entry = POSITION_ENTRY  # 0x1A00:1
        self.cyclic_ms = self._default_cyclic_ms  # 0x6200
        self._enc_syncs = 0  # SYNCs counted toward the next synchronous TPDO1
        self._next_cyclic = math.inf
        super().__init__(node, **kwargs)

    # -- RAM defaults at every boot --------------------------------------------------------------
    def _boot(self) -> None:
        self.enc_cob = TPDO1_BASE + self.node  # valid (bit 31 clear): an encoder's TPDO1 is on by default
        self.enc_ttype = self._default_ttype
        self.enc_map_count = 1
        self.enc_entry = POSITION_ENTRY
        self.cyclic_ms = self._default_cyclic_ms
        self._enc_syncs = 0
        self._next_cyclic = math.inf
        super()._boot()

    # -- objects -------------------------------------------------------------------------------
    def od_read(self, index: int, sub: int) -> OdValue | bytes:
        objects = {(0x1800, 0): 2, (0x1800, 1): self.enc_cob, (0x1800, 2): self.enc_ttype, (0x1A00, 0): self.enc_map_count, (0x1A00, 1): self.enc_entry,
                   (CYCLIC_TIMER, 0): self.cyclic_ms}
        if (index, sub) in objects:
            return objects[(index, sub)]
        if index in (0x1800, 0x1A00, CYCLIC_TIMER):
            return self._no_sub(index, sub)
        return super().od_read(index, sub)

    def od_write(self, index: int, sub: int, value: int) -> None:
        if index not in (0x1800, 0x1A00, CYCLIC_TIMER):
            return super().od_write(index, sub, value)
        self.advance_to(self.clock.now())
        if (index, sub) == (CYCLIC_TIMER, 0):  # TPDO1's event timer is hard-wired to it
            if not 0 <= value <= 0xFFFF:
                raise ODError(f"0x{index:04X}:{sub}: {value} outside 0..65535 ms", ABORT_RANGE)
            self.cyclic_ms = value
            self._schedule_cyclic(restart=True)
        elif (index, sub) == (0x1800, 1):
            self.enc_cob = value & 0xFFFFFFFF
            self._schedule_cyclic(restart=True)
        elif (index, sub) == (0x1800, 2):
            if not 0 <= value <= 255:
                raise ODError(f"0x1800:2: {value} outside 0..255", ABORT_RANGE)
            self.enc_ttype, self._enc_syncs = value, 0
            self._schedule_cyclic(restart=True)
        elif index == 0x1A00 and not self.enc_cob & 0x80000000:
            # CiA 301: a mapping changes only while its PDO is invalid (COB-ID bit 31 set)
            raise ODError("0x1A00: TPDO1 is valid; set bit 31 of 0x1800:1 first", 0x08000022)
        elif (index, sub) == (0x1A00, 0):
            if value not in (0, 1):
                raise ODError(f"0x1A00:0: {value}: TPDO1 maps one object", ABORT_RANGE)
            self.enc_map_count = value
        elif (index, sub) == (0x1A00, 1):
            if value != POSITION_ENTRY:
                raise ODError(f"0x{value:08X} cannot be mapped (only 0x6004, 32 bits)", 0x06040041)
            self.enc_entry = value
        else:
            self._no_sub(index, sub)
        self.od_writes.append((self._t, index, sub, value))

    @staticmethod
    def _no_sub(index: int, sub: int) -> OdValue:
        raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)

    # -- sending -------------------------------------------------------------------------------
    @property
    def _tpdo_on(self) -> bool:
        return self._nmt_state == OPERATIONAL and not self.enc_cob & 0x80000000 and self.enc_map_count >= 1

    def _send_tpdo(self) -> None:
        self.tpdo_frames += 1
        self._send(self.enc_cob & 0x7FF, struct.pack("<i", int(self._read_position())))

    def _schedule_cyclic(self, restart: bool = False) -> None:
        if self._tpdo_on and self.enc_ttype in (254, 255) and self.cyclic_ms > 0:
            if restart or self._next_cyclic == math.inf:
                self._next_cyclic = self._t + self.cyclic_ms / 1000
        else:
            self._next_cyclic = math.inf

    def _nmt(self, cs: int) -> None:
        before = self._nmt_state
        super()._nmt(cs)
        if self._nmt_state == OPERATIONAL and before != OPERATIONAL and self._tpdo_on and self.enc_ttype in (254, 255):
            self._send_tpdo()  # CiA 406: TPDO1 on entering Operational
        self._schedule_cyclic(restart=True)

    def _sync(self) -> None:
        super()._sync()
        if self._tpdo_on and 1 <= self.enc_ttype <= 240:
            self._enc_syncs += 1
            if self._enc_syncs >= self.enc_ttype:
                self._enc_syncs = 0
                self._send_tpdo()

    def _next_event(self) -> float:
        return min(super()._next_event(), self._next_cyclic)

    def _fire_events(self) -> None:
        super()._fire_events()
        while self._t + TIME_EPS >= self._next_cyclic:
            if self._dead or not self._tpdo_on:
                self._next_cyclic = math.inf
                break
            self._send_tpdo()
            self._next_cyclic += self.cyclic_ms / 1000
