"""The ATI Net F/T force/torque sensor on CAN: frames, the two-frame short reply, the wrench in SI
units, and a reader that asks for one sample and waits a bounded time for it.

The protocol (docs/devices.md, ATI's Net F/T manual, section "CAN Bus Operation"):

- a one-byte frame ``0x02`` to the base id asks for the current data in short format (16 bits);
- the sensor answers with two 8-byte frames: base+5 carries Fx, Tx, Fy, Ty and base+6 carries Fz,
  Tz, the system status word and the sample number, each INT16, little endian, two's complement;
- a one-byte frame ``0x04`` to the base id biases the sensor (zeroes it at the present load);
- a new request during a transmission ends the old one.

Values are counts: the counts per force and per torque unit come from the sensor's calibration
sheet and are config settings here (over CAN they cannot be read; UNCONFIRMED that a given sensor
was calibrated in N and N·m, which is what the tool assumes when it divides).

The codec is pure; :class:`FtReader` is the one part that talks to a bus, through the
:class:`FramePort` Protocol, with its clock injected.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import queue
import struct
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Protocol

from sherpa_cli.config.model import ArmConfig, DeviceConfig
from sherpa_cli.errors import DriveTimeoutError, ProtocolError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession

REQUEST_SHORT = 0x02  # opcode: send the present data in short (16-bit) format
BIAS = 0x04  # opcode: zero the readings at the present load
FORCES_OFFSET = 5  # base+5: Fx, Tx, Fy, Ty
STATUS_OFFSET = 6  # base+6: Fz, Tz, status word, sample number
REPLY_LEN = 8
INT16_MIN, INT16_MAX = -0x8000, 0x7FFF
MAX_BASE_ID = 0x7FF - STATUS_OFFSET  # the base and both reply ids are 11-bit ids
_REPLY = struct.Struct("<hhhh")
AXES = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")


@dataclass(frozen=True)
class Frame:
    """One CAN frame (11-bit id)."""

    can_id: int
    data: bytes

    def __str__(self) -> str:
        return f"{self.can_id:03X}#{self.data.hex().upper()}"


def _check_base(base_id: int) -> None:
    if not 0 <= base_id <= MAX_BASE_ID:
        raise ValueError(f"base id 0x{base_id:X} out of range 0..0x{MAX_BASE_ID:X}")


def request_frame(base_id: int) -> Frame:
    """The one-byte request for short data."""
    _check_base(base_id)
    return Frame(base_id, bytes([REQUEST_SHORT]))


def bias_frame(base_id: int) -> Frame:
    """The one-byte bias command."""
    _check_base(base_id)
    return Frame(base_id, bytes([BIAS]))


def reply_ids(base_id: int) -> tuple[int, int]:
    _check_base(base_id)
    return base_id + FORCES_OFFSET, base_id + STATUS_OFFSET


def sensor_ids(base_id: int) -> tuple[int, int, int]:
    """Every id the sensor listens or answers on: base, base+5, base+6."""
    return (base_id, *reply_ids(base_id))


@dataclass(frozen=True)
class StatusWord:
    """The reply's system status word: the upper 16 bits of the Net F/T's 32-bit status code.

    0 is healthy; any set bit means the sensor needs attention. Which bit means what is in the
    manual's "System Status Code" table; that the CAN word is exactly its upper half is UNCONFIRMED,
    so the bits are shown as numbers, not names.
    """

    raw: int

    @property
    def ok(self) -> bool:
        return self.raw == 0

    @property
    def bits(self) -> tuple[int, ...]:
        return tuple(b for b in range(16) if self.raw >> b & 1)

    def __str__(self) -> str:
        return "ok" if self.ok else f"0x{self.raw:04X} (bits {','.join(map(str, self.bits))})"


@dataclass(frozen=True)
class RawSample:
    """One short-format sample in counts, as the two reply frames carry it."""

    fx: int
    tx: int
    fy: int
    ty: int
    fz: int
    tz: int
    status: int  # the 16-bit status word, as an unsigned number
    sample: int  # the sample number, as an unsigned number (it wraps)


def _int16(name: str, value: int) -> int:
    if not INT16_MIN <= value <= INT16_MAX:
        raise ValueError(f"{name} {value} does not fit INT16")
    return value


def encode_reply(base_id: int, raw: RawSample) -> tuple[Frame, Frame]:
    """The two frames a sensor sends for ``raw`` (the simulator's side, and the tests')."""
    forces_id, status_id = reply_ids(base_id)
    first = _REPLY.pack(*(_int16(n, getattr(raw, n)) for n in ("fx", "tx", "fy", "ty")))
    for name in ("fz", "tz"):
        _int16(name, getattr(raw, name))
    if not 0 <= raw.status <= 0xFFFF or not 0 <= raw.sample <= 0xFFFF:
        raise ValueError("status and sample number are 16-bit words")
    second = struct.pack("<hhHH", raw.fz, raw.tz, raw.status, raw.sample)
    return Frame(forces_id, first), Frame(status_id, second)


def _check_frame(base_id: int, frame: Frame, offset: int, what: str) -> None:
    want = base_id + offset
    if frame.can_id != want:
        raise ProtocolError(f"F/T sensor at base 0x{base_id:03X}: {what} frame (base+{offset}) expected on id "
                            f"0x{want:03X}, got id 0x{frame.can_id:03X}")
    if len(frame.data) != REPLY_LEN:
        raise ProtocolError(f"F/T sensor at base 0x{base_id:03X}: {what} frame 0x{want:03X} (base+{offset}) has "
                            f"{len(frame.data)} data bytes, expected {REPLY_LEN}")


def decode_reply(base_id: int, forces: Frame, status: Frame) -> RawSample:
    """The sample in the two reply frames; a frame on the wrong id or of the wrong length raises
    :class:`ProtocolError` naming that frame."""
    _check_frame(base_id, forces, FORCES_OFFSET, "Fx/Tx/Fy/Ty")
    _check_frame(base_id, status, STATUS_OFFSET, "Fz/Tz/status")
    fx, tx, fy, ty = _REPLY.unpack(forces.data)
    fz, tz, word, sample = struct.unpack("<hhHH", status.data)
    return RawSample(fx, tx, fy, ty, fz, tz, word, sample)


@dataclass(frozen=True)
class Calibration:
    """Counts per N and counts per N·m (the sensor's calibration sheet)."""

    counts_per_force: float
    counts_per_torque: float

    def __post_init__(self) -> None:
        if not (self.counts_per_force > 0 and self.counts_per_torque > 0):
            raise ValueError("counts per force and per torque must be > 0")


@dataclass(frozen=True)
class Wrench:
    """A force (N) and torque (N·m) in the sensor frame, with the sample's status and number."""

    fx: float
    fy: float
    fz: float
    tx: float
    ty: float
    tz: float
    status: StatusWord = StatusWord(0)
    sample: int = 0
    frame: str = ""  # the sensor frame's name (config)
    # axes whose count sits at an end of INT16: the real value may be anywhere beyond it
    saturated: tuple[str, ...] = ()

    @property
    def force(self) -> float:
        """|F| in N."""
        return math.sqrt(self.fx ** 2 + self.fy ** 2 + self.fz ** 2)

    @property
    def torque(self) -> float:
        """|T| in N·m."""
        return math.sqrt(self.tx ** 2 + self.ty ** 2 + self.tz ** 2)

    def axes(self) -> dict[str, float]:
        return {"Fx": self.fx, "Fy": self.fy, "Fz": self.fz, "Tx": self.tx, "Ty": self.ty, "Tz": self.tz}


def to_wrench(raw: RawSample, cal: Calibration, *, frame: str = "") -> Wrench:
    f, t = cal.counts_per_force, cal.counts_per_torque
    counts = {"Fx": raw.fx, "Fy": raw.fy, "Fz": raw.fz, "Tx": raw.tx, "Ty": raw.ty, "Tz": raw.tz}
    return Wrench(raw.fx / f, raw.fy / f, raw.fz / f, raw.tx / t, raw.ty / t, raw.tz / t,
                  StatusWord(raw.status), raw.sample, frame,
                  saturated=tuple(n for n, c in counts.items() if c in (INT16_MIN, INT16_MAX)))


def _counts(value: float, per_unit: float) -> int:
    return max(INT16_MIN, min(INT16_MAX, round(value * per_unit)))


def to_raw(wrench: Wrench, cal: Calibration) -> RawSample:
    """Counts for a wrench, saturated at INT16 as the sensor's short format is (the simulator's side)."""
    f, t = cal.counts_per_force, cal.counts_per_torque
    return RawSample(_counts(wrench.fx, f), _counts(wrench.tx, t), _counts(wrench.fy, f), _counts(wrench.ty, t),
                     _counts(wrench.fz, f), _counts(wrench.tz, t), wrench.status.raw & 0xFFFF, wrench.sample & 0xFFFF)


# -- reading one sample --------------------------------------------------------------------------------

class FramePort(Protocol):
    """What the reader needs of a bus: send a frame, and take the next frame received on one of the
    given ids within ``timeout`` s (None when nothing came)."""

    def send(self, frame: Frame) -> None: ...

    def receive(self, ids: frozenset[int], timeout: float) -> Frame | None: ...


class FtReader:
    """Asks the sensor for one sample and waits at most ``wait_s`` for both reply frames.

    A base+6 frame without a base+5 frame before it (a reply the sensor cut short for a newer
    request, or one that began before we asked) is dropped and the wait goes on.
    """

    type = "ft_sensor"
    profile = None  # no CANopen device profile

    def __init__(self, port: FramePort, base_id: int, cal: Calibration, *, frame: str = "", wait_s: float = 0.1,
                 clock: Callable[[], float] = time.monotonic, name: str = "F/T sensor") -> None:
        self.port, self.base_id, self.cal, self.frame = port, base_id, cal, frame
        self.wait_s, self.clock, self.name = wait_s, clock, name
        self.ids = frozenset(reply_ids(base_id))

    def request(self) -> None:
        self.port.send(request_frame(self.base_id))

    def bias(self) -> None:
        self.port.send(bias_frame(self.base_id))

    def read(self) -> Wrench:
        """One sample: request, then both frames within ``wait_s``; else :class:`DriveTimeoutError`."""
        self.request()
        deadline = self.clock() + self.wait_s
        forces: Frame | None = None
        forces_id = self.base_id + FORCES_OFFSET
        while True:
            left = deadline - self.clock()
            if left <= 0:
                got = "only the base+5 frame" if forces is not None else "no reply"
                raise DriveTimeoutError(f"{self.name} (base 0x{self.base_id:03X}): {got} within "
                                        f"{self.wait_s * 1000:g} ms of the request",
                                        hint="check the sensor's power, its CAN base address switches and "
                                             "that CAN is selected on its Communications page")
            got_frame = self.port.receive(self.ids, left)
            if got_frame is None:
                continue
            if got_frame.can_id == forces_id:
                forces = got_frame
            elif forces is not None:
                return to_wrench(decode_reply(self.base_id, forces, got_frame), self.cal, frame=self.frame)



class Network(Protocol):
    """What :class:`NetworkPort` needs of a bus link's canopen Network (bus/links.py)."""

    def subscribe(self, can_id: int, callback: Callable[[int, bytes, float], None]) -> None: ...

    def unsubscribe(self, can_id: int, callback: Callable[[int, bytes, float], None] | None = None) -> None: ...

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None: ...


class NetworkPort:
    """A :class:`FramePort` on a session's bus: it listens on the sensor's reply ids from the moment it
    is opened (a context manager) and sends through the network's pacing."""

    def __init__(self, network: Network, ids: tuple[int, ...]) -> None:
        self.network, self.listen = network, ids
        self.frames: queue.Queue[Frame] = queue.Queue()

    def _heard(self, can_id: int, data: bytes, timestamp: float) -> None:
        self.frames.put(Frame(can_id, bytes(data)))

    def __enter__(self) -> NetworkPort:
        for can_id in self.listen:
            self.network.subscribe(can_id, self._heard)
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        for can_id in self.listen:
            with contextlib.suppress(Exception):  # unsubscribing must not hide why we stop
                self.network.unsubscribe(can_id, self._heard)

    def send(self, frame: Frame) -> None:
        # what was heard before this frame answers an older request: never taken for its answer
        with contextlib.suppress(queue.Empty):
            while True:
                self.frames.get_nowait()
        self.network.send_message(frame.can_id, frame.data)

    def receive(self, ids: frozenset[int], timeout: float) -> Frame | None:
        deadline = time.monotonic() + max(0.0, timeout)
        while True:
            try:
                frame = self.frames.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                return None
            if frame.can_id in ids:
                return frame


def calibration(dev: DeviceConfig) -> Calibration:
    ft = dev.ft
    if ft is None or ft.counts_per_force is None or ft.counts_per_torque is None:
        raise UsageError(f"{dev.name} is no F/T sensor with its calibration (counts_per_force, counts_per_torque)")
    return Calibration(ft.counts_per_force, ft.counts_per_torque)


@contextlib.contextmanager
def open_reader(session: ArmSession, dev: DeviceConfig, *, clock: Callable[[], float] = time.monotonic,
                wait_s: float | None = None) -> Iterator[FtReader]:
    """A reader of sensor ``dev`` on its bus of ``session``, listening while the block runs."""
    cal = calibration(dev)
    assert dev.ft is not None
    if wait_s is None:
        wait_s = dev.ft.reply_ms / 1000
        if session.sim is not None:  # an in-process simulator on a possibly loaded machine: its patient timeout
            wait_s = max(wait_s, session.cfg.sim_reply_timeout)
    link = session.links.get(dev.bus)
    if link is None:
        raise UsageError(f"F/T sensor {dev.name}: bus {dev.bus} is not open in this session")
    with NetworkPort(link.network, reply_ids(dev.ft.base_id)) as port:
        yield FtReader(port, dev.ft.base_id, cal, frame=dev.ft.frame, clock=clock, name=f"F/T sensor {dev.name}",
                       wait_s=wait_s)


def sensor_named(cfg: ArmConfig, name: str | None) -> DeviceConfig:
    """The F/T sensor ``name`` (None: the only one); a clear error when there is none or it is ambiguous."""
    sensors = cfg.ft_sensors()
    if name is None:
        if len(sensors) == 1:
            return sensors[0]
        if not sensors:
            raise UsageError("this arm has no F/T sensor (no device of type ft_sensor in the config)",
                             hint="add one under devices: (docs/devices.md)")
        raise UsageError(f"this arm has {len(sensors)} F/T sensors: name one of {', '.join(d.name for d in sensors)}")
    dev = cfg.devices.get(name)
    if dev is None or dev.ft is None:
        raise UsageError(f"'{name}' is no F/T sensor; F/T sensors: {', '.join(d.name for d in sensors) or 'none'}")
    return dev


# -- recording (log/record.py Recorder) ---------------------------------------------------------------

FT_COLUMNS = (("fx", "fx_n"), ("fy", "fy_n"), ("fz", "fz_n"), ("tx", "tx_nm"), ("ty", "ty_nm"), ("tz", "tz_nm"))


@dataclass
class FtTrack:
    """An F/T sensor in a recording: one sample per SYNC slot at most, placed on the newest SYNC sent
    before its request. Columns ``<device>.fx_n`` ... ``<device>.tz_nm`` (N, N·m; NaN: no sample)."""

    dev: DeviceConfig
    samples: dict[int, Wrench] = dataclasses.field(default_factory=dict)
    last: int = -1
    misses: int = 0  # requests without an answer in time
    written: int = 0  # samples handed to a streaming sink (and forgotten)

    def add(self, k: int, wrench: Wrench) -> None:
        self.last = max(self.last, k)
        self.samples[k] = wrench

    def columns(self, keys: list[int]) -> dict[str, list[float]]:
        return {f"{self.dev.name}.{column}": [float(getattr(self.samples[k], attr)) if k in self.samples else math.nan
                                              for k in keys]
                for attr, column in FT_COLUMNS}
