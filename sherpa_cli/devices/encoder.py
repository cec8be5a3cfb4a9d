"""The CANopen absolute encoder's position (CiA 406 0x6004) from its TPDO1, with SDO as the fallback.

CiA 406 maps 0x6004 (32 bits) into TPDO1 (COB-ID 0x180 + node) and hard-wires TPDO1's event timer
to the cyclic timer 0x6200: with an asynchronous transmission type (254/255) and 0x6200 > 0 the
encoder sends its position every 0x6200 ms. :func:`read_position`:

1. NMT-starts the encoder (PDOs only live in Operational) and reads TPDO1's COB-ID, transmission
   type, mapping and 0x6200 by SDO; a TPDO1 that does not carry 0x6004 first goes to the fallback.
2. If TPDO1 is not already sending on its own, makes it send, in RAM only: ``tpdo_trigger: cyclic``
   writes 0x6200 = ``cyclic_ms`` (and type 254 / a valid COB-ID if needed); ``sync`` writes
   transmission type 1 and sends one SYNC.
3. Takes the first TPDO1 frame that arrives after it started listening.
4. Puts every object it changed back, in reverse order, on every exit path (never saved: no 0x1010).

No frame within the wait, or an SDO refusal of the set-up: the SDO read of 0x6004, and the reading
says why (``via``). ``position_from: sdo`` reads by SDO only.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sherpa_cli.bus import syncgate
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig, DeviceConfig, JointConfig
from sherpa_cli.devices import CanOpenEncoder
from sherpa_cli.elmo.protocol import COB_INVALID, NMT_ID, NMT_START, SYNC_ID, TPDO_COMM, TPDO_MAP
from sherpa_cli.errors import SherpaError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.sdo import DriveSdo
    from sherpa_cli.bus.session import ArmSession

TPDO1_COMM, TPDO1_MAP, CYCLIC_TIMER = TPDO_COMM, TPDO_MAP, 0x6200
POSITION_ENTRY = 0x60040020  # 0x6004:0, 32 bits
ASYNC_TYPES = (254, 255)
WAIT_PERIODS = 5  # cyclic: wait this many timer periods for the first frame (at least MIN_WAIT_S)
MIN_WAIT_S = 0.3


@dataclass
class EncoderReading:
    device: str
    position: int  # raw 0x6004 counts
    via: str  # "TPDO1" or "SDO" (+ why, when the TPDO was tried and did not give it)
    changed: list[tuple[int, int, int, int]] = field(default_factory=list)  # (index, sub, size, old) put back

    @property
    def by_tpdo(self) -> bool:
        return self.via == "TPDO1"


class _Listener:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.value: int | None = None
        self.frames = 0

    def __call__(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) >= 4:
            with self.lock:
                self.value = CanOpenEncoder.position_from_tpdo(bytes(data))
                self.frames += 1


def device_ref(dev: DeviceConfig) -> DriveRef:
    return DriveRef(dev.name, dev.bus, dev.node)


def read_position(session: ArmSession, dev: DeviceConfig, *, clock: Callable[[], float] = time.monotonic,
                  sleep: Callable[[float], None] = time.sleep, wait_s: float | None = None) -> EncoderReading:
    """The encoder's raw position (0x6004): from TPDO1 as the module says, else by SDO."""
    sdo = session.sdo(device_ref(dev))
    encoder = CanOpenEncoder(sdo)
    if dev.position_from == "sdo":
        return EncoderReading(dev.name, int(encoder.position()), "SDO")
    link = session.links[dev.bus]
    changed: list[tuple[int, int, int, int]] = []
    listener = _Listener()
    cob: int | None = None
    why = ""
    try:
        link.network.send_message(NMT_ID, bytes([NMT_START, dev.node]))

        def read(index: int, sub: int, size: int) -> int:
            return int.from_bytes(bytes(sdo.upload(index, sub))[:size].ljust(size, b"\0"), "little")

        def write(index: int, sub: int, size: int, value: int) -> None:
            old = read(index, sub, size)
            changed.append((index, sub, size, old))  # put back even if the write half-happened
            sdo.download(index, sub, value.to_bytes(size, "little"))

        old_cob, ttype, cyclic = read(TPDO1_COMM, 1, 4), read(TPDO1_COMM, 2, 1), read(CYCLIC_TIMER, 0, 2)
        if read(TPDO1_MAP, 0, 1) < 1 or read(TPDO1_MAP, 1, 4) != POSITION_ENTRY:
            why = "TPDO1 does not carry 0x6004 first"
        else:
            cob = old_cob & 0x7FF
            link.network.subscribe(cob, listener)
            sending = not old_cob & COB_INVALID and ttype in ASYNC_TYPES and cyclic > 0
            period = (cyclic if sending else dev.cyclic_ms) / 1000
            if not sending and dev.tpdo_trigger == "cyclic":
                if ttype not in ASYNC_TYPES:
                    write(TPDO1_COMM, 2, 1, 254)
                if cyclic == 0:
                    write(CYCLIC_TIMER, 0, 2, dev.cyclic_ms)
                if old_cob & COB_INVALID:
                    write(TPDO1_COMM, 1, 4, old_cob & ~COB_INVALID & 0xFFFFFFFF)
            elif not sending:  # sync: transmission type 1, then one SYNC
                if ttype != 1:
                    write(TPDO1_COMM, 2, 1, 1)
                if old_cob & COB_INVALID:
                    write(TPDO1_COMM, 1, 4, old_cob & ~COB_INVALID & 0xFFFFFFFF)
                with listener.lock:
                    listener.value, listener.frames = None, 0  # only a frame the SYNC caused counts
                syncgate.gate(link.bus).send(lambda: link.network.send_message(SYNC_ID, b""))
                period = 0.0
            wait = wait_s if wait_s is not None else max(MIN_WAIT_S, WAIT_PERIODS * period,
                                                         session.cfg.protocol.sdo_timeout)
            deadline = clock() + wait
            while True:
                with listener.lock:
                    value = listener.value
                if value is not None:
                    return EncoderReading(dev.name, value, "TPDO1", list(changed))
                if clock() >= deadline:
                    why = f"no TPDO1 within {wait:g} s"
                    break
                sleep(0.005)
    except SherpaError as exc:
        why = f"TPDO1 set-up failed: {exc}"
    finally:
        if cob is not None:
            with contextlib.suppress(Exception):  # unsubscribing must not hide why we stop
                link.network.unsubscribe(cob, listener)
        _restore(sdo, changed)
    return EncoderReading(dev.name, int(encoder.position()), f"SDO ({why})", list(changed))


def _restore(sdo: DriveSdo, changed: list[tuple[int, int, int, int]]) -> None:
    """Every changed object back to its old value, last change first; every one is tried."""
    first: SherpaError | None = None
    for index, sub, size, old in reversed(changed):
        try:
            sdo.download(index, sub, old.to_bytes(size, "little"))
        except SherpaError as exc:
            first = first or exc
    if first is not None:
        raise first


# -- recording (log/record.py Recorder) ---------------------------------------------------------------

def recorded_encoders(cfg: ArmConfig, drives: Iterable[str]) -> list[EncoderTrack]:
    """The CANopen encoders of the joints whose drives are all recorded (``abs_encoder.source`` names
    a device), one track per device, in config order."""
    recorded = set(drives)
    tracks: dict[str, EncoderTrack] = {}
    for joint in cfg.joints.values():
        enc = joint.abs_encoder
        dev = cfg.device_by_source(enc.source) if enc is not None else None
        if dev is None or dev.type != "canopen-encoder":
            continue
        if joint.drive is not None:
            mine = {joint.drive}
        else:
            assert joint.pair is not None  # a joint has a drive or a pair (config/validate.py)
            pair = cfg.pairs[joint.pair]
            mine = {pair.drive_a, pair.drive_b}
        if mine <= recorded:
            tracks.setdefault(dev.name, EncoderTrack(dev)).joints.append(joint)
    return list(tracks.values())


def targets_with_encoders(cfg: ArmConfig, names: Sequence[str] | None) -> list[str] | None:
    """`log record` targets where an encoder device (name or BUS:NODE) stands for the joint it
    measures: that joint's drives are recorded and the encoder with them."""
    if not names:
        return names  # type: ignore[return-value]
    out: list[str] = []
    for text in names:
        dev = cfg.device_by_source(text)
        if dev is None:
            out.append(text)
            continue
        joints = [j.name for j in cfg.joints.values()
                  if j.abs_encoder is not None and cfg.device_by_source(j.abs_encoder.source) is dev]
        if not joints:
            raise UsageError(f"{text}: device {dev.name} measures no joint (no abs_encoder names it), nothing "
                             "to record it beside", hint="name it in a joint's abs_encoder.source")
        out.extend(joints)
    return out


@dataclass
class EncoderTrack:
    """A CANopen encoder in a recording: its TPDO1 (0x6004) on every SYNC -- transmission type 1 and
    a valid COB-ID, RAM only, put back by :meth:`restore` -- and its columns: ``<device>.pos``
    (raw counts) and ``<joint>.ext_pos_rad`` (reading + the joint's abs_encoder offset, in rad)."""

    dev: DeviceConfig
    joints: list[JointConfig] = field(default_factory=list)
    cob: int | None = None
    saved: list[tuple[int, int, int, int]] = field(default_factory=list)
    samples: dict[int, int] = field(default_factory=dict)
    last: int = -1

    def configure(self, session: ArmSession) -> None:
        sdo = session.sdo(device_ref(self.dev))
        session.links[self.dev.bus].network.send_message(NMT_ID, bytes([NMT_START, self.dev.node]))

        def read(index: int, sub: int, size: int) -> int:
            return int.from_bytes(bytes(sdo.upload(index, sub))[:size].ljust(size, b"\0"), "little")

        if read(TPDO1_MAP, 0, 1) < 1 or read(TPDO1_MAP, 1, 4) != POSITION_ENTRY:
            raise UsageError(f"{self.dev.name}: its TPDO1 does not carry the position value 0x6004 first; "
                             "cannot record it", hint="check the encoder's 0x1A00 mapping")
        old_cob, old_type = read(TPDO1_COMM, 1, 4), read(TPDO1_COMM, 2, 1)
        for sub, size, old, new in ((2, 1, old_type, 1), (1, 4, old_cob, old_cob & ~COB_INVALID & 0xFFFFFFFF)):
            if new != old:
                self.saved.append((TPDO1_COMM, sub, size, old))
                sdo.download(TPDO1_COMM, sub, new.to_bytes(size, "little"))
        self.cob = old_cob & 0x7FF

    def restore(self, session: ArmSession) -> None:
        saved, self.saved = self.saved, []
        _restore(session.sdo(device_ref(self.dev)), saved)

    def add(self, k: int, data: bytes) -> None:
        """One TPDO1 frame answering SYNC number ``k``, as the recorder matched it (it holds its lock)."""
        if len(data) >= 4:
            self.last = max(self.last, k)
            self.samples[k] = CanOpenEncoder.position_from_tpdo(bytes(data))

    def columns(self, keys: Sequence[int]) -> dict[str, list[float]]:
        from sherpa_cli.joints.units import counts_to_rad

        raw = [float(self.samples[k]) if k in self.samples else math.nan for k in keys]
        out = {f"{self.dev.name}.pos": raw}
        for joint in self.joints:
            assert joint.abs_encoder is not None  # recorded_encoders adds only joints with one
            off = joint.abs_encoder.offset
            out[f"{joint.name}.ext_pos_rad"] = [counts_to_rad(v + off, joint.cpr) if v == v else math.nan
                                                for v in raw]
        return out
