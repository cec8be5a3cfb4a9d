"""Record joint motion: TPDOs sent on SYNC (or polling through the interpreter), in counts and
joint units. The API other commands use (``diffdrive move``, ``log step``)::

    with Recorder(session, refs, rate=1000) as rec:
        ...                      # move something
    recording = rec.recording()  # log/recording.py: time_s + joint and motor columns

What the recorder changes on the drives is RAM only and restored on every exit path, never
saved: TPDO1 (0x1800/0x1A00) is mapped to position 0x6064 and velocity 0x6069, transmission
type 1 (every SYNC), and with current TPDO3 (0x1802/0x1A02) to 0x6078 on every 2nd SYNC. The
old COB-IDs, transmission types and mappings are read first and written back at the end.

SYNC comes from python-can's ``send_periodic`` on SocketCAN (the kernel's broadcast manager),
elsewhere from a counted thread of the tool (:class:`ThreadSync`) that sends the SYNCs already due
before it stops; tests inject their own (``sync_factory``) and a clock.
"""

from __future__ import annotations

import bisect
import contextlib
import functools
import math
import struct
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from sherpa_cli.bus import journal, syncgate
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.devices import encoder
from sherpa_cli.devices.ft_sensor import FtReader, FtTrack, Wrench, open_reader
from sherpa_cli.elmo.protocol import SYNC_ID
from sherpa_cli.errors import CommunicationError, SdoError, SherpaError, UsageError
from sherpa_cli.joints.jointmap import JointMap, joint_map, joint_maps
from sherpa_cli.joints.units import counts_per_s_to_rad_per_s, counts_to_rad
from sherpa_cli.log.capture import frame_bits
from sherpa_cli.log.recording import Recording
from sherpa_cli.words import plural

if TYPE_CHECKING:
    import can

    from sherpa_cli.bus.session import ArmSession

MAX_LOAD = 0.90  # share of the bit rate the recording may take (worst-case stuffing counted)
DEFAULT_BITRATE = 1_000_000  # when the config does not say
TPDO_POS = 0  # TPDO1: PX + VX (TPDO2 is the binary interpreter's)
TPDO_CUR = 2  # TPDO3: current
POSITION_ENTRY = 0x60640020  # 0x6064:0, 32 bits
VELOCITY_ENTRY = 0x60690020  # 0x6069:0, 32 bits
# Current actual value. UNCONFIRMED for the Whistle: DS402 scales 0x6078 in per mille of the
# rated current; the simulator sends mA. One place to change when a drive tells otherwise.
CURRENT_ENTRY = 0x60780010  # 0x6078:0, 16 bits
CURRENT_SCALE_A = 0.001  # A per unit of 0x6078
CURRENT_DIVIDER = 2  # current on every 2nd SYNC
DRAIN_LIMIT_S = 1.0  # longest wait for the answers to the last SYNCs after SYNC stopped
RESTORE_ATTEMPTS = 30  # SDO tries per object when putting the PDO settings back (a backlog may delay answers)
RESTORE_WINDOW_S = 3.0  # ... but a drive silent this long is dead: its other objects are not tried
#: with a sink (``log record``): rows stay in memory this long after the newest sample, for frames that
#: arrive late (a loaded receive thread) and for latest(); older rows go to the sink and are dropped
LATE_WINDOW_S = 0.2
LATE_WINDOW_MIN = 50  # ... and at least this many SYNCs (latest() looks back 50)
#: a frame's receive timestamp further than this from the host's wall time is on another clock (an
#: interface's own): the frame is then placed by when the recorder heard it
STAMP_PLAUSIBLE_S = 10.0


# -- the bus budget ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class BusBudget:
    bus: str
    drives: int
    bitrate: int
    bitrate_assumed: bool
    bits_per_sync: float
    rate: float
    current: bool

    @property
    def load(self) -> float:
        return self.bits_per_sync * self.rate / self.bitrate

    @property
    def max_rate(self) -> int:
        return int(MAX_LOAD * self.bitrate // self.bits_per_sync)

    @property
    def fits(self) -> bool:
        return self.load <= MAX_LOAD + 1e-12


def bus_budget(cfg: ArmConfig, refs: Sequence[DriveRef], rate: float, *, current: bool,
               encoders: Sequence[Any] = (), ft_sensors: Sequence[Any] = ()) -> list[BusBudget]:
    """Per bus: SYNC + one 8-byte TPDO per drive per SYNC (+ a 2-byte current TPDO every 2nd)
    (+ a 4-byte TPDO per recorded encoder, ``encoders``: DeviceConfig, devices/encoder.py)
    (+ a 1-byte request and two 8-byte replies per recorded F/T sensor, ``ft_sensors``)."""
    out = []
    for bus in dict.fromkeys([*(r.bus for r in refs), *(e.bus for e in encoders)]):
        n = sum(1 for r in refs if r.bus == bus)
        configured = cfg.buses[bus].bitrate if bus in cfg.buses else None
        bits = frame_bits(0) + n * frame_bits(8) + (n * frame_bits(2) / CURRENT_DIVIDER if current else 0)
        bits += sum(frame_bits(4) for e in encoders if e.bus == bus)
        bits += sum(frame_bits(1) + 2 * frame_bits(8) for f in ft_sensors if f.bus == bus)
        out.append(BusBudget(bus, n, configured or DEFAULT_BITRATE, not configured, bits, rate, current))
    return out


# -- SYNC -----------------------------------------------------------------------------------------

def wall_time() -> float:
    """The clock of the frames' receive timestamps (SocketCAN's kernel stamps, python-can's virtual
    and remote interfaces): the host's wall time."""
    return time.time()


class SyncLog:
    """The SYNCs this tool sent on one bus, in order: SYNC n's send time on the recorder's clock
    (``at``) and on the clock of the frames' receive timestamps (``stamp``, taken just before the
    send, so an answer is never stamped before its SYNC). A recorded TPDO is matched to the SYNC it
    answers through it, and a sample is placed at its SYNC's ``at``.

    A source that notes every SYNC it sends (:meth:`sent`: the tool's thread, stepped time) gives
    the exact log. The kernel's broadcast manager sends on its own, as exactly as the kernel's
    timer: its log is the schedule (:meth:`scheduled`: SYNC n at the start + n periods, none while
    paused), and so is that of a source that keeps no log (a test's)."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.at: list[float] = []
        self.stamps: list[float] = []
        self._lock = threading.Lock()
        # a schedule: segments (start on the recorder's clock, start stamp or None, first index)
        self._segments: list[tuple[float, float | None, int]] | None = None
        self._end: float | None = None  # the schedule's pause or stop on the recorder's clock
        self._now: Callable[[], float] = wall_time

    @classmethod
    def scheduled(cls, period: float, start: float, *, now: Callable[[], float] = wall_time,
                  stamped: bool = True) -> SyncLog:
        """SYNC n at ``start`` + n periods (``start`` on ``now``'s clock); ``stamped``: that clock is
        the frames' timestamps' (wall time), else frames are placed by when the recorder heard them."""
        log = cls(period)
        log._segments, log._now = [(start, start if stamped else None, 0)], now
        return log

    @property
    def stamped(self) -> bool:
        return self._segments is None or self._segments[-1][1] is not None

    def sent(self, at: float, stamp: float) -> None:
        """One SYNC about to go out (called by its source just before the send)."""
        with self._lock:
            self.at.append(at)
            self.stamps.append(stamp)

    def retract(self) -> None:
        """The SYNC just noted did not go out (its send failed): the log holds only what was sent."""
        with self._lock:
            self.at.pop()
            self.stamps.pop()

    def pause(self) -> None:
        """A scheduled source stopped (the SYNC gate, its end): no SYNC after now."""
        if self._segments is not None and self._end is None:
            self._end = self._now()

    def resume(self) -> None:
        """A paused scheduled source started again: its first SYNC goes out now."""
        if self._segments is not None and self._end is not None:
            first = self.count()
            now = self._now()
            self._segments.append((now, now if self._segments[-1][1] is not None else None, first))
            self._end = None

    def count(self) -> int:
        """SYNCs sent so far."""
        if self._segments is None:
            return len(self.at)
        start, _, first = self._segments[-1]
        until = self._now() if self._end is None else self._end
        return first + max(0, math.floor((until - start) / self.period + 1e-6) + 1)

    def time_of(self, n: int) -> float:
        """SYNC ``n``'s send time on the recorder's clock."""
        if self._segments is None:
            return self.at[n]
        for start, _, first in reversed(self._segments):
            if n >= first:
                return start + (n - first) * self.period
        raise IndexError(n)

    def sent_by(self, stamp: float | None) -> int:
        """How many SYNCs had been sent when a frame stamped ``stamp`` arrived (None: now)."""
        if stamp is None:
            return self.count()
        if self._segments is None:
            with self._lock:
                return bisect.bisect_right(self.stamps, stamp)
        count = self.count()
        for _start, start_stamp, first in reversed(self._segments):
            if start_stamp is not None and stamp >= start_stamp:
                return min(count, first + math.floor((stamp - start_stamp) / self.period + 1e-6) + 1)
        return 0


class PeriodicSync:
    """SYNC every ``period`` s through python-can's send_periodic (kernel BCM on SocketCAN). The
    kernel sends without the bus's SYNC gate, so the gate pauses it (stop, then start again) while
    a synchronous pair start sends its BG frames (bus/syncgate.py); its log is the kernel's
    schedule, paused likewise."""

    def __init__(self, bus: can.BusABC, period: float) -> None:
        import can

        self.log = SyncLog.scheduled(period, wall_time())
        self.task = bus.send_periodic(can.Message(arbitration_id=SYNC_ID, data=b"", is_extended_id=False), period)
        self._unregister = syncgate.gate(bus).register(self)

    def pause(self) -> None:
        self.task.stop()
        self.log.pause()

    def resume(self) -> None:
        start = getattr(self.task, "start", None)  # RestartableCyclicTaskABC (SocketCAN's is one)
        if start is not None:
            self.log.resume()
            start()

    def stop(self) -> None:
        self._unregister()
        self.task.stop()
        self.log.pause()


class ThreadSync:
    """SYNC every ``period`` s from a thread of the tool, for interfaces without a kernel periodic
    task (python-can would use a thread there too). One thread serves every such bus of a
    recording, sending each SYNC on all of them back to back, so a row's SYNCs go out together
    however late a loaded interpreter runs the thread. It notes each SYNC in its bus's log
    (``logs``) just before sending it, and on :meth:`stop` first sends the SYNCs already due (a
    thread behind on a busy interpreter would otherwise drop them, and with them the samples of the
    recording's last milliseconds)."""

    CATCH_UP_LIMIT_S = 0.2  # longest wait at stop for the SYNCs already due

    def __init__(self, bus: can.BusABC | Sequence[can.BusABC], period: float) -> None:
        import can

        self.buses = list(bus) if isinstance(bus, Sequence) else [bus]
        self.period = period
        self.message = can.Message(arbitration_id=SYNC_ID, data=b"", is_extended_id=False)
        # never between the two BG frames of a synchronous pair start
        self.gates = [syncgate.gate(b) for b in self.buses]
        self.logs = [SyncLog(period) for _ in self.buses]
        self.sent = 0
        self.start = time.perf_counter()
        self._due_total: int | None = None  # set by stop(): send up to this many, then end
        self._wake = threading.Event()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="sherpa-sync", daemon=True)
        self._thread.start()

    @property
    def log(self) -> SyncLog:
        """The log of the first bus (a source made for one bus has only that)."""
        return self.logs[0]

    def _run(self) -> None:
        try:
            while True:
                limit = self._due_total
                if limit is not None and self.sent >= limit:
                    return
                ahead = self.start + self.sent * self.period - time.perf_counter()
                if ahead > 0 and limit is None:
                    self._wake.wait(ahead)
                    continue
                for bus, gate, log in zip(self.buses, self.gates, self.logs, strict=True):
                    gate.send(functools.partial(self._send_one, bus, log))
                self.sent += 1
        except BaseException as exc:  # noqa: BLE001  a dead bus ends the SYNC; the recording shows the gap
            self.error = exc

    def _send_one(self, bus: can.BusABC, log: SyncLog) -> None:
        now = wall_time()
        log.sent(now, now)
        try:
            bus.send(self.message)
        except BaseException:
            log.retract()
            raise

    def request_stop(self) -> None:
        """From now on send only the SYNCs already due, then end (:meth:`stop` waits for that)."""
        if self._due_total is None:
            self._due_total = math.floor((time.perf_counter() - self.start) / self.period + 1e-6) + 1
            self._wake.set()

    def stop(self) -> None:
        self.request_stop()
        self._thread.join(timeout=self.CATCH_UP_LIMIT_S)
        if self._thread.is_alive():  # still behind after the limit: end it where it is
            self._due_total = 0
            self._thread.join(timeout=1.0)


class SyncSource(Protocol):
    """A running SYNC source (PeriodicSync, ThreadSync, the simulator's stepped source): stop() ends it;
    one with ``request_stop()`` is first told to send only the SYNCs already due. One with a ``log``
    (:class:`SyncLog`, or anything with its ``count``/``time_of``/``sent_by``/``stamped``) says which
    SYNCs it sent; without one the recorder takes the schedule for them."""

    def stop(self) -> None: ...


def default_sync(bus: can.BusABC, period: float) -> PeriodicSync | ThreadSync:
    """The kernel's broadcast manager on SocketCAN, else a counted thread of the tool."""
    if _has_bcm(bus):
        return PeriodicSync(bus, period)
    return ThreadSync(bus, period)


def _has_bcm(bus: can.BusABC) -> bool:
    return type(bus).__name__ == "SocketcanBus"


SyncFactory = Callable[[str, "can.BusABC", float], SyncSource]  # (bus name, python-can bus, period)


# -- the recorder ---------------------------------------------------------------------------------

@dataclass
class _Drive:
    ref: DriveRef
    cobs: dict[int, int] = field(default_factory=dict)  # TPDO -> COB-ID in use
    saved: list[tuple[int, int, int, int]] = field(default_factory=list)  # (index, sub, size, value) to restore
    pos: dict[int, tuple[int, int]] = field(default_factory=dict)  # sample -> (px, vx)
    cur: dict[int, float] = field(default_factory=dict)  # current frame j (rows j*2, j*2 + 1) -> A
    last: dict[int, int] = field(default_factory=dict)  # TPDO -> newest SYNC (current: frame) index answered
    written: int = 0  # position samples already handed to the sink (and dropped from pos)
    cur_written: int = 0  # current samples likewise
    late: int = 0  # frames that came after their row was written: not in the file
    unplaced: int = 0  # frames that answer no SYNC this tool sent (another SYNC producer): not in the file
    frames: int = 0  # position TPDOs received: one per SYNC on the bus, whoever sent it
    gaps: Gaps = field(default_factory=lambda: Gaps())  # SYNCs written without this drive's sample


MAX_GAP_SPANS = 5  # gaps a report names by place; the rest are counted


@dataclass
class Gaps:
    """SYNC indexes with no sample of one drive: how many, and the first few runs of them
    (first index, length), so a report says where a recording has holes."""

    missing: int = 0
    spans: list[tuple[int, int]] = field(default_factory=list)
    more_spans: int = 0  # runs after the first MAX_GAP_SPANS, counted only
    last: int = -2  # the newest missing index (a run goes on from it)

    def add(self, k: int) -> None:
        self.missing += 1
        if k == self.last + 1 and not self.more_spans and self.spans:
            self.spans[-1] = (self.spans[-1][0], self.spans[-1][1] + 1)
        elif k != self.last + 1:
            if len(self.spans) < MAX_GAP_SPANS:
                self.spans.append((k, 1))
            else:
                self.more_spans += 1
        self.last = k

    def copy(self) -> Gaps:
        return Gaps(self.missing, list(self.spans), self.more_spans, self.last)


FOREIGN_SYNC_SLACK = 10  # TPDOs beyond the SYNCs this tool can have sent before it calls that a foreign SYNC
FOREIGN_SYNC_SHARE = 0.05  # ... or this share of them, whichever is more (jitter at the edges of a span)


class ForeignSyncError(CommunicationError):
    """Another node sends SYNC on a recorded bus: the drives answer both producers, the samples
    can no longer be placed on this tool's time grid (exit 3)."""


class RowSink(Protocol):
    """Where a streaming recorder's completed rows go (log/recording.py CsvWriter)."""

    def write(self, rec: Recording) -> None: ...


def answer_slot(taken: dict[int, Any], prev: int, newest: int, lowest: int) -> int | None:
    """The SYNC (the slot of ``taken``: SYNC index -> sample) a drive's next answer belongs to.
    ``prev``: the newest SYNC it answered before; ``newest``: the newest SYNC sent before the
    answer arrived; ``lowest``: the first SYNC whose row is not written yet.

    A drive answers each SYNC once, in order, so the answer belongs to ``newest`` unless that one
    is answered already: then answers bunched up (a drive or simulator that answered late), and by
    their order the ones since the last free SYNC answered the SYNCs before -- that run moves back
    by one (into ``taken``) and this answer takes ``prev``. None: no SYNC sent and not written is
    free for it (a frame of another SYNC producer, or one whose row is in the file). Never a SYNC
    that was not sent, never one of a later sample."""
    if newest > prev:
        return newest if newest >= lowest else None
    free = prev
    while free in taken:
        free -= 1
    if free < lowest or free == prev:
        return None
    for k in range(free, prev):
        taken[k] = taken.pop(k + 1)
    return prev


class Recorder:
    """Sample PX, VX (and current) of ``refs`` at ``rate`` Hz; a context manager."""

    def __init__(self, session: ArmSession, refs: Iterable[DriveRef], rate: float, *, current: bool = False,
                 clock: Callable[[], float] | None = None, sync_factory: SyncFactory | None = None,
                 enforce_budget: bool = True, sink: RowSink | None = None) -> None:
        self.session = session
        self.cfg: ArmConfig = session.cfg
        self.refs = list(refs)
        if not self.refs:
            raise UsageError("nothing to record: no drives")
        if not (math.isfinite(rate) and rate > 0):
            raise UsageError(f"--rate {rate}: expected a rate in Hz > 0")
        self.rate = float(rate)
        self.period = 1.0 / self.rate
        self.current = current
        # CANopen encoders of the recorded joints, recorded beside them (devices/encoder.py)
        self.encoders = encoder.recorded_encoders(self.cfg, (r.name for r in self.refs))
        # F/T sensors on the recorded buses, asked once per period beside the SYNCs (a real-time
        # recording only: the sensor answers requests, not SYNC, so an injected clock cannot pace it)
        recorded_buses = {r.bus for r in self.refs}
        self.ft_tracks = [FtTrack(d) for d in self.cfg.ft_sensors() if d.bus in recorded_buses] \
            if clock is None else []
        self._ft_stop = threading.Event()
        self._ft_threads: list[threading.Thread] = []
        self._ft_ports = contextlib.ExitStack()
        self.budget = bus_budget(self.cfg, self.refs, self.rate, current=current,
                                 encoders=[t.dev for t in self.encoders], ft_sensors=[t.dev for t in self.ft_tracks])
        if enforce_budget:
            check_budget(self.budget)
        self.clock = clock
        self.sync_factory = sync_factory
        self._drives = {r.key: _Drive(r) for r in self.refs}
        self._subscribed: list[tuple[Any, int, Callable]] = []
        self._syncs: list[SyncSource] = []
        self._lock = threading.Lock()
        self.t0: float | None = None
        self.t_end: float | None = None
        self._logs: dict[str, Any] = {}  # bus -> the SYNCs sent on it (SyncLog or a source's own log)
        self._schedules: list[SyncLog] = []  # the logs the recorder keeps for sources without one
        # streaming (``sink``): each completed row is handed to the sink as the recording goes, only a
        # short window stays in memory (constant memory whatever the duration)
        self.sink = sink
        self.window = max(LATE_WINDOW_MIN, math.ceil(LATE_WINDOW_S * self.rate))
        self._flushed = 0  # rows (SYNC indexes) below this one are written
        self._newest = -1  # newest SYNC index any drive answered
        self._write_lock = threading.Lock()  # keeps batches in order when two receive threads flush
        self.rows_written = 0  # rows handed to the sink (SYNCs with at least one drive's sample)
        self.failure: SherpaError | None = None  # set by the receive thread: a second SYNC producer
        # while the SYNC sources start: a source sends its first SYNC before its constructor returns, and
        # an answer the receive thread hears before the source's log is noted here would be taken for
        # a frame from before the recording; such frames wait (in order) for the log
        self._starting = False
        self._early: list[Callable[[], None]] = []
        self._start_lock = threading.Lock()

    # -- lifetime -------------------------------------------------------------------------------
    def __enter__(self) -> Recorder:
        try:
            for d in self._drives.values():
                self._configure(d)
            for track in self.encoders:
                track.configure(self.session)
            self._listen()
            self.t0 = self._now()
            self._start_syncs(list(dict.fromkeys([*(r.bus for r in self.refs), *(t.dev.bus for t in self.encoders)])))
            self._start_ft()
        except BaseException:
            self._finish()
            raise
        return self

    def _start_ft(self) -> None:
        """One thread per recorded F/T sensor: a request per period, its sample placed on the newest
        SYNC sent before the request (its row), unless that row has a sample or is written already."""
        for track in self.ft_tracks:
            reader = self._ft_ports.enter_context(open_reader(self.session, track.dev))
            thread = threading.Thread(target=self._poll_ft, args=(track, reader), daemon=True,
                                      name=f"log-record-ft-{track.dev.name}")
            self._ft_threads.append(thread)
            thread.start()

    def _poll_ft(self, track: FtTrack, reader: FtReader) -> None:
        due = time.monotonic()
        while not self._ft_stop.is_set():
            sent = self._answered_by(track.dev.bus, wall_time())
            if sent:
                try:
                    sample: Wrench | None = reader.read()
                except CommunicationError:
                    sample = None
                with self._lock:
                    if sample is None:
                        track.misses += 1
                    elif sent - 1 >= self._flushed and sent - 1 not in track.samples:
                        track.add(sent - 1, sample)
            due = max(due + self.period, time.monotonic() - self.period)  # behind: no burst to catch up
            self._ft_stop.wait(max(0.0, due - time.monotonic()))

    def _stop_ft(self) -> None:
        self._ft_stop.set()
        for thread in self._ft_threads:
            thread.join(timeout=5)
        self._ft_threads.clear()
        self._ft_ports.close()

    def _start_syncs(self, buses: list[str]) -> None:
        """Start a SYNC source per bus and note its log; the answers heard meanwhile are handled
        once every log is noted, in the order they came, before any later frame (:meth:`_defer`)."""
        with self._start_lock:
            self._starting = True
        try:
            self._start_sources(buses)
        finally:
            while True:
                with self._start_lock:
                    early, self._early = self._early, []
                    if not early:
                        self._starting = False
                        break
                for handle in early:
                    handle()

    def _defer(self, handle: Callable[[], None]) -> bool:
        """True: a frame heard while the SYNC sources start is kept (``handle`` runs it later)."""
        if not self._starting:
            return False
        with self._start_lock:
            if not self._starting:
                return False
            self._early.append(handle)
            return True

    def _deferring(self, handle: Callable[[int, bytes, float], None]) -> Callable[[int, bytes, float], None]:
        """A receive callback that runs ``handle`` now, or once the SYNC sources' logs are noted."""
        def on_frame(can_id: int, data: bytes, timestamp: float) -> None:
            if not self._defer(functools.partial(handle, can_id, data, timestamp)):
                handle(can_id, data, timestamp)
        return on_frame

    def _start_sources(self, buses: list[str]) -> None:
        links = self.session.links
        if self.sync_factory is None:
            threaded = [b for b in buses if not _has_bcm(links[b].bus)]
            for bus in buses:
                if bus not in threaded:
                    source = PeriodicSync(links[bus].bus, self.period)
                    self._syncs.append(source)
                    self._logs[bus] = source.log
            if threaded:
                thread = ThreadSync([links[b].bus for b in threaded], self.period)
                self._syncs.append(thread)
                self._logs.update(zip(threaded, thread.logs, strict=True))
            return
        for bus in buses:
            started = self._now()
            made = self.sync_factory(bus, links[bus].bus, self.period)
            self._syncs.append(made)
            log = getattr(made, "log", None)
            if log is None:  # the source says nothing of what it sent: its schedule stands for it
                log = SyncLog.scheduled(self.period, started, now=self._now, stamped=self.clock is None)
                self._schedules.append(log)
            self._logs[bus] = log

    def __exit__(self, *exc: object) -> None:
        self._finish(quiet=exc[0] is not None)

    def _now(self) -> float:
        return self.clock() if self.clock is not None else time.time()

    def now(self) -> float:
        """The recorder's time (its clock, else wall time like the frames' timestamps)."""
        return self._now()

    def _finish(self, quiet: bool = False) -> None:
        self._stop_ft()  # before the SYNCs end: no request whose row no SYNC stands for
        # every source's end first (the SYNCs due until then are expected; a ThreadSync still sends
        # them), then the stops, so one bus's catching up does not lengthen another's span
        for log in self._schedules:
            log.pause()
        for sync in self._syncs:
            request = getattr(sync, "request_stop", None)
            if request is not None:
                with contextlib.suppress(Exception):
                    request()
        for sync in self._syncs:
            with contextlib.suppress(Exception):  # stopping must not hide why we stop
                sync.stop()
        self._syncs.clear()
        if self.t0 is not None and self.t_end is None:
            self.t_end = self._now()
        self._drain()
        for network, cob, callback in self._subscribed:
            with contextlib.suppress(Exception):
                network.unsubscribe(cob, callback)
        self._subscribed.clear()
        if self.sink is not None:
            self._flush(final=True)  # every row still held: the file ends with the recording's last sample
        failures: list[SherpaError] = []
        for d in self._drives.values():
            sdo = self.session.sdo(d.ref)
            # a drive that answered nothing to its last interpreter request gets one try, not the window
            window = 0.0 if self.session.client(d.ref).silent else RESTORE_WINDOW_S
            deaf = False
            for index, sub, size, value in reversed(d.saved):
                if deaf:
                    failures.append(CommunicationError(f"{d.ref.name}: 0x{index:04X}:{sub} not put back: the drive "
                                                       "did not answer (dead or silent)"))
                    continue
                # patient: right after a fast recording the drive may still be working off a backlog;
                # but bounded in time per drive (RESTORE_WINDOW_S of no answer), so a dead drive costs
                # that window once, not 30 timeouts per object (it held a command's exit for good)
                silent_since: float | None = None
                for attempt in range(RESTORE_ATTEMPTS):
                    try:
                        sdo.download(index, sub, value.to_bytes(size, "little"))
                        break
                    except SherpaError as exc:
                        timed_out = isinstance(exc, SdoError) and exc.reason == "timeout"
                        now = time.monotonic()
                        silent_since = (silent_since or now - sdo.timeout) if timed_out else None
                        deaf = silent_since is not None and now - silent_since >= window
                        if deaf or attempt == RESTORE_ATTEMPTS - 1:
                            failures.append(exc)
                            break
            if not failures:
                journal.forget(d.ref, "log record")
            d.saved.clear()
        for track in self.encoders:
            try:
                track.restore(self.session)
            except SherpaError as exc:
                failures.append(exc)
        if failures and not quiet:
            raise failures[0]

    def _drain(self) -> None:
        """Answers to the last SYNCs may still wait in a loaded receive thread: keep listening until
        no new sample came for a few periods (bounded), so the end of a recording is not cut off."""
        if not self._subscribed or self.clock is not None or self.problem() is not None:
            return  # (another SYNC producer keeps the answers coming: nothing to wait for)
        quiet_for = max(0.02, 5 * self.period)
        deadline = time.monotonic() + DRAIN_LIMIT_S
        last = self._received()
        last_change = time.monotonic()
        while time.monotonic() < deadline:
            time.sleep(quiet_for / 4)
            now_received = self._received()
            if now_received != last:
                last, last_change = now_received, time.monotonic()
            elif time.monotonic() - last_change >= quiet_for:
                return

    def _received(self) -> int:
        with self._lock:
            return sum(d.written + len(d.pos) + d.late + d.unplaced + d.cur_written + len(d.cur)
                       for d in self._drives.values())

    def answered(self, syncs: int) -> bool:
        """Whether every TPDO the first ``syncs`` SYNCs ask for has arrived (position of every
        drive for each, current for every 2nd): a SYNC source in lockstep with a simulated clock
        waits for this before it moves the clock on."""
        with self._lock:
            return all(d.written + len(d.pos) >= syncs and (not self.current or d.cur_written + len(d.cur)
                                                             >= syncs // CURRENT_DIVIDER)
                       for d in self._drives.values())

    # -- PDO set-up (RAM only) ------------------------------------------------------------------
    def _configure(self, d: _Drive) -> None:
        client = self.session.client(d.ref)
        client.nmt_start()  # PDOs only live in Operational
        self._map(d, TPDO_POS, [POSITION_ENTRY, VELOCITY_ENTRY], 1)
        if self.current:
            self._map(d, TPDO_CUR, [CURRENT_ENTRY], CURRENT_DIVIDER)

    def _map(self, d: _Drive, n: int, entries: list[int], ttype: int) -> None:
        sdo = self.session.sdo(d.ref)
        comm, mapping = 0x1800 + n, 0x1A00 + n

        def read(index: int, sub: int, size: int) -> int:
            return int.from_bytes(sdo.upload(index, sub)[:size].ljust(size, b"\0"), "little")

        def write(index: int, sub: int, size: int, value: int) -> None:
            sdo.download(index, sub, value.to_bytes(size, "little"))

        old_cob, old_type, old_count = read(comm, 1, 4), read(comm, 2, 1), read(mapping, 0, 1)
        old_entries = [read(mapping, sub, 4) for sub in range(1, len(entries) + 1)]
        # restored in reverse: PDO off, count 0, entries, count, transmission type, COB-ID last
        d.saved.append((comm, 1, 4, old_cob))
        journal.note(d.ref, *(journal.sdo("log record", i, s, n, v) for i, s, n, v in  # before any change
                              [(comm, 1, 4, old_cob), (comm, 2, 1, old_type), (mapping, 0, 1, old_count),
                               *((mapping, sub, 4, v) for sub, v in enumerate(old_entries, 1)),
                               (mapping, 0, 1, 0), (comm, 1, 4, old_cob | 0x80000000)]))
        write(comm, 1, 4, old_cob | 0x80000000)  # PDO off while it is changed (CiA 301)
        d.saved.append((comm, 2, 1, old_type))
        d.saved.append((mapping, 0, 1, old_count))
        for sub, value in enumerate(old_entries, 1):
            d.saved.append((mapping, sub, 4, value))
        d.saved.append((mapping, 0, 1, 0))  # the count goes to 0 before the entries go back
        d.saved.append((comm, 1, 4, old_cob | 0x80000000))  # first of all: PDO off again (CiA 301)
        write(mapping, 0, 1, 0)
        for sub, entry in enumerate(entries, 1):
            write(mapping, sub, 4, entry)
        write(mapping, 0, 1, len(entries))
        write(comm, 2, 1, ttype)
        cob = (0x180 + 0x100 * n if n != 1 else 0x280) + d.ref.node
        write(comm, 1, 4, cob)
        d.cobs[n] = cob

    # -- receiving ------------------------------------------------------------------------------
    def _listen(self) -> None:
        for d in self._drives.values():
            network = self.session.links[d.ref.bus].network
            for n, cob in d.cobs.items():
                callback = self._callback(d, n)
                network.subscribe(cob, callback)
                self._subscribed.append((network, cob, callback))
        for track in self.encoders:
            assert track.cob is not None  # configured in __enter__
            network, callback = self.session.links[track.dev.bus].network, self._encoder_callback(track)
            network.subscribe(track.cob, callback)
            self._subscribed.append((network, track.cob, callback))

    def _answered_by(self, bus: str, timestamp: float) -> int:
        """How many of this tool's SYNCs on ``bus`` had been sent when a frame stamped ``timestamp``
        arrived: its receive timestamp against the SYNC log's send stamps, so a frame that waited in
        a loaded receive thread still counts from when it was on the bus. A log on another clock
        than the frames' (an injected clock with a schedule), or a timestamp from another clock,
        counts from when the recorder hears the frame."""
        log = self._logs.get(bus)
        if log is None:
            return 0
        plausible = log.stamped and abs(timestamp - wall_time()) < STAMP_PLAUSIBLE_S
        return int(log.sent_by(timestamp if plausible else None))

    def _encoder_callback(self, track: encoder.EncoderTrack) -> Callable[[int, bytes, float], None]:
        def handle(can_id: int, data: bytes, timestamp: float) -> None:
            sent = self._answered_by(track.dev.bus, timestamp)
            if sent == 0 or len(data) < 4:
                return
            with self._lock:
                k = answer_slot(track.samples, track.last, sent - 1, self._flushed)
                if k is not None:  # else: its row is written already, or it answers no SYNC of ours
                    track.add(k, data)
        return self._deferring(handle)

    def _callback(self, d: _Drive, n: int) -> Callable[[int, bytes, float], None]:
        unpack_pos, unpack_cur = struct.Struct("<ii").unpack_from, struct.Struct("<h").unpack_from
        divider = CURRENT_DIVIDER if n == TPDO_CUR else 1

        def handle(can_id: int, data: bytes, timestamp: float) -> None:
            sent = self._answered_by(d.ref.bus, timestamp)
            if sent == 0:
                return  # before this tool's first SYNC: no answer to it
            # the newest SYNC sent before the frame arrived (current: the frame of every 2nd SYNC)
            newest = (sent - 1) // divider
            with self._lock:
                taken: dict[int, Any] = d.pos if n == TPDO_POS else d.cur
                lowest = -(-self._flushed // divider)  # the first slot whose rows are not written yet
                prev = d.last.get(n, -1)
                if n == TPDO_POS and len(data) >= 8:
                    d.frames += 1
                    if self.failure is None and d.frames > self._sync_bound(d.ref.bus):
                        self._foreign_sync(d)
                k = answer_slot(taken, prev, newest, lowest)
                if k is None:
                    if max(newest, prev) < lowest:
                        d.late += 1  # streaming: its row is in the file already
                    else:
                        d.unplaced += 1
                    return
                d.last[n] = max(prev, k)
                if n == TPDO_POS and len(data) >= 8:
                    d.pos[k] = unpack_pos(data)
                    if k > self._newest:
                        self._newest = k
                elif n == TPDO_CUR and len(data) >= 2:
                    d.cur[k] = unpack_cur(data)[0] * CURRENT_SCALE_A
                due = self.sink is not None and self._newest - self._flushed >= 2 * self.window
            if due:
                self._flush()
        return self._deferring(handle)

    @staticmethod
    def _current_rows(cur: Mapping[int, float], rows: Iterable[int]) -> dict[int, float]:
        """Current frames (one per CURRENT_DIVIDER SYNCs) as the rows they fill."""
        return {r: cur[r // CURRENT_DIVIDER] for r in rows if r // CURRENT_DIVIDER in cur}

    def _flush(self, *, final: bool = False) -> None:
        """Hand the rows older than the late-frame window (``final``: all) to the sink and forget
        them: taken out under the lock, converted and written outside it (the receive threads go on)."""
        sink = self.sink
        if sink is None:
            return
        with self._write_lock:
            with self._lock:
                cut = (max(self._newest, *(t.last for t in self.encoders), *(t.last for t in self.ft_tracks), -1) + 1
                       if final else self._newest - self.window + 1)
                if cut <= self._flushed:
                    return
                taken: dict[str, tuple[dict[int, tuple[int, int]], dict[int, float]]] = {}
                keys_set: set[int] = set()
                for d in self._drives.values():
                    pos = {k: v for k, v in d.pos.items() if k < cut}
                    cur = self._current_rows(d.cur, range(self._flushed, cut))
                    for k in range(self._flushed, cut):
                        if k not in pos:
                            d.gaps.add(k)
                    for k in pos:
                        del d.pos[k]
                    done = [j for j in d.cur if CURRENT_DIVIDER * (j + 1) <= cut]
                    for j in done:
                        del d.cur[j]
                    d.written += len(pos)
                    d.cur_written += len(done)
                    keys_set.update(pos)
                    taken[d.ref.name] = (pos, cur)
                keys = sorted(keys_set)
                encoder_columns: dict[str, list[float]] = {}
                for track in self.encoders:
                    encoder_columns.update(track.columns(keys))
                    for k in [k for k in track.samples if k < cut]:
                        del track.samples[k]
                for ft_track in self.ft_tracks:
                    encoder_columns.update(ft_track.columns(keys))
                    ft_track.written += sum(1 for k in keys if k in ft_track.samples)
                    for k in [k for k in ft_track.samples if k < cut]:
                        del ft_track.samples[k]
                self._flushed = cut
            rec = self._build(keys, taken, None)
            rec.columns.update(encoder_columns)
            sink.write(rec)
            self.rows_written += len(keys)

    # -- another SYNC producer ------------------------------------------------------------------
    def _sync_bound(self, bus: str) -> float:
        """The SYNCs this tool's source on ``bus`` has sent by now (its log), with a margin; a drive
        answering more SYNCs than that answers someone else's."""
        log = self._logs.get(bus)
        if log is None:  # a frame between the PDO set-up and the source's start: nothing to count yet
            return math.inf
        mine = int(log.count())
        return mine + max(FOREIGN_SYNC_SLACK, math.ceil(FOREIGN_SYNC_SHARE * mine))

    def _foreign_sync(self, d: _Drive) -> None:
        log = self._logs[d.ref.bus]
        mine = int(log.count())
        took = self._now() - log.time_of(0) if mine else 0.0
        self.failure = ForeignSyncError(
            f"bus {d.ref.bus}: {d.ref.name} answered {d.frames} SYNCs in {took:.2f} s but this tool "
            f"sent at most {mine} ({self.rate:g} Hz): another node is sending SYNC (0x080) on this bus; the "
            "samples cannot be placed in time, the recording is stopped",
            hint="stop the other SYNC producer (another `sherpa log record`, a master's SYNC) and record again")

    def problem(self) -> SherpaError | None:
        """What ended the recording early: another SYNC producer (found by the receive thread), or a
        recorded bus whose connection went away (its network's receive thread ended)."""
        if self.failure is None:
            for bus in self._logs:
                lost = getattr(self.session.links[bus].network, "lost_error", None)
                error = lost() if lost is not None else None
                if error is not None:
                    self.failure = error
                    break
        return self.failure

    def check(self) -> None:
        """Raise :meth:`problem`; a loop calls this beside its guard's check."""
        problem = self.problem()
        if problem is not None:
            raise problem

    # -- results --------------------------------------------------------------------------------
    def counts(self) -> dict[str, int]:
        """Samples per drive (and recorded encoder) so far, each placed on a SYNC this tool sent:
        what the file holds (a late or unplaced frame is not counted)."""
        with self._lock:
            return {**{d.ref.name: d.written + len(d.pos) for d in self._drives.values()},
                    **{t.dev.name: len(t.samples) for t in self.encoders},
                    **{t.dev.name: t.written + len(t.samples) for t in self.ft_tracks}}

    def latest(self) -> tuple[float, dict[str, tuple[int, int]]] | None:
        """The newest SYNC every drive has answered: (its time on the recorder's clock, drive ->
        (PX, VX)), or None before the first. For a loop that acts on the recording while it runs
        (`diffdrive move --feedback`): all drives sampled at the same SYNC."""
        with self._lock:
            drives = list(self._drives.values())
            newest = min(d.last.get(TPDO_POS, -1) for d in drives)
            for k in range(newest, max(newest - 50, -1), -1):  # a lost frame: the SYNC before it
                if all(k in d.pos for d in drives):
                    return (self._row_time(k),
                            {d.ref.name: (int(d.pos[k][0]), int(d.pos[k][1])) for d in drives})
        return None

    def gaps(self) -> dict[str, Gaps]:
        """Per drive: the SYNCs of the recording (0 .. expected() - 1) with no sample of it, after the
        recording (streaming: what went to the file; else what :meth:`recording` holds)."""
        expected = self.expected()
        out: dict[str, Gaps] = {}
        with self._lock:
            for d in self._drives.values():
                if self.sink is not None:
                    gaps, start = d.gaps.copy(), self._flushed
                else:
                    gaps, start = Gaps(), 0
                for k in range(start, expected):
                    if k not in d.pos:
                        gaps.add(k)
                out[d.ref.name] = gaps
        return out

    def late(self) -> int:
        """Frames that came after their row was written (streaming only): not in the file."""
        with self._lock:
            return sum(d.late for d in self._drives.values())

    def unplaced(self) -> int:
        """Frames that answered no SYNC this tool sent (more answers than SYNCs): not in the file."""
        with self._lock:
            return sum(d.unplaced for d in self._drives.values())

    def expected(self) -> int:
        """SYNCs (samples per drive) this tool sent, on the bus whose source sent the most (each
        bus's SYNC log: sent, not merely due)."""
        return max((int(log.count()) for log in self._logs.values()), default=0)

    def _row_time(self, k: int) -> float:
        """When SYNC ``k`` went out, on the recorder's clock: on the first bus that sent it (a
        recording's buses get their k-th SYNCs together: one thread sends them back to back, the
        kernel's timers start together, stepped time sends them at one instant)."""
        for log in self._logs.values():
            if log.count() > k:
                return float(log.time_of(k))
        return (self.t0 or 0.0) + k * self.period  # not sent: no sample is ever placed there

    def time_zero(self) -> float:
        """The recording's time 0 on the recorder's clock: its first SYNC (before it, the start)."""
        return self._row_time(0) if self.expected() else (self.t0 or 0.0)

    def sync_times(self, *, t_zero: float | None = None) -> list[float]:
        """The times of every SYNC sent (a row each when a drive answered it), as :meth:`recording`
        gives them."""
        zero = self.time_zero() if t_zero is None else t_zero
        return [self._row_time(k) - zero for k in range(self.expected())]

    def recording(self, *, t_zero: float | None = None) -> Recording:
        """Samples in joint units; ``t_zero`` (same clock as the recorder) becomes time 0."""
        with self._lock:
            keys = sorted({k for d in self._drives.values() for k in d.pos})
            by_name = {d.ref.name: (dict(d.pos), self._current_rows(d.cur, keys)) for d in self._drives.values()}
        rec = self._build(keys, by_name, t_zero)
        with self._lock:
            for track in self.encoders:
                rec.columns.update(track.columns(keys))
            for ft_track in self.ft_tracks:
                rec.columns.update(ft_track.columns(keys))
        return rec

    def columns(self) -> list[str]:
        """The recording's column names (without ``time_s``), in the order :meth:`recording` gives them."""
        rec = self._build([], {d.ref.name: ({}, {}) for d in self._drives.values()}, None)
        for track in self.encoders:
            rec.columns.update(track.columns([]))
        for ft_track in self.ft_tracks:
            rec.columns.update(ft_track.columns([]))
        return list(rec.columns)

    def _build(self, keys: list[int], by_name: dict[str, tuple[dict[int, tuple[int, int]], dict[int, float]]],
               t_zero: float | None) -> Recording:
        """Rows ``keys`` (SYNC indexes) in joint units, from each drive's (positions, currents)."""
        zero = self.time_zero() if t_zero is None else t_zero
        rec = Recording(times=[self._row_time(k) - zero for k in keys])
        nan = math.nan

        def motor(name: str, which: int) -> list[float]:
            pos = by_name[name][0]
            return [float(pos[k][which]) if k in pos else nan for k in keys]

        def amps(name: str) -> list[float]:
            cur = by_name[name][1]
            return [cur.get(k, nan) for k in keys]

        for m in joint_maps(self.cfg):
            if not all(d in by_name for d in m.drives):
                continue
            for col, which, conv in (("pos_rad", 0, counts_to_rad), ("vel_rad_s", 1, counts_per_s_to_rad_per_s)):
                if m.b is None:
                    rec.columns[f"{m.joint}.{col}"] = [conv(v, m.cpr) if v == v else nan for v in motor(m.a, which)]
                else:
                    a, b = motor(m.a, which), motor(m.b, which)
                    rec.columns[f"{m.joint}.{col}"] = [conv(m.value(x, y), m.cpr) if x == x and y == y else nan
                                                       for x, y in zip(a, b, strict=True)]  # a sample one drive missed
            if self.current and m.b is None:
                rec.columns[f"{m.joint}.cur_a"] = amps(m.a)
        for ref in self.refs:
            rec.columns[f"{ref.name}.px"] = motor(ref.name, 0)
            rec.columns[f"{ref.name}.vx"] = motor(ref.name, 1)
            if self.current:
                rec.columns[f"{ref.name}.iq_a"] = amps(ref.name)
        return rec


def check_budget(budget: Sequence[BusBudget]) -> None:
    for b in budget:
        if not b.fits:
            what = "PX+VX" + (" and current" if b.current else "")
            raise UsageError(
                f"--rate {b.rate:g}: {what} of {plural(b.drives, 'drive')} on bus {b.bus} needs {100 * b.load:.0f} % of "
                f"{b.bitrate / 1e6:g} Mbit/s (at most {100 * MAX_LOAD:.0f} %); the highest rate it can carry is "
                f"{b.max_rate} Hz", hint=f"use --rate {min(x.max_rate for x in budget)}"
                + ("" if not b.current else " or --no-current"))


# -- polling fallback -----------------------------------------------------------------------------

class Poller:
    """``--poll``: PX and VX (and IQ) through the binary interpreter, each bus every its
    ``poll_interval_ms`` (the seed's ``scheduler_interval``); slower and jittery, but changes nothing."""

    def __init__(self, session: ArmSession, refs: Iterable[DriveRef], *, current: bool = False,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        self.session, self.refs, self.current = session, list(refs), current
        self.clock, self.sleep = clock, sleep
        self.rows: list[tuple[float, str, int, int, float | None]] = []
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.t0: float | None = None
        self.errors: list[BaseException] = []

    def __enter__(self) -> Poller:
        self.t0 = self.clock()
        for bus in dict.fromkeys(r.bus for r in self.refs):
            interval = self.session.cfg.buses[bus].poll_interval_ms / 1000
            refs = [r for r in self.refs if r.bus == bus]
            for r in refs:
                self.session.client(r).nmt_start()
            t = threading.Thread(target=self._run, args=(refs, interval), daemon=True, name=f"poll-{bus}")
            self._threads.append(t)
            t.start()
        return self

    def _run(self, refs: list[DriveRef], interval: float) -> None:
        try:
            while not self._stop.is_set():
                start = self.clock()
                for r in refs:
                    client = self.session.client(r)
                    px, vx = int(client.get("PX")), int(client.get("VX"))
                    iq = float(client.get("IQ")) if self.current else None
                    self.rows.append((self.clock(), r.name, px, vx, iq))
                rest = interval - (self.clock() - start)
                if rest > 0:
                    self.sleep(rest)
        except BaseException as exc:  # noqa: BLE001  raised again by __exit__ on the caller's thread
            self.errors.append(exc)

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=5)
        if self.errors and exc[0] is None:
            raise self.errors[0]

    def counts(self) -> dict[str, int]:
        return {r.name: sum(1 for row in self.rows if row[1] == r.name) for r in self.refs}

    def recording(self, cfg: ArmConfig, *, t_zero: float | None = None) -> Recording:
        """One row per drive reading, at its own poll time (its cells of other drives' rows are
        empty). A pair's Σ/Δ joint is on the row of the pair's motor read second in a round, from
        both motors' readings of that round (one bus, read back to back), as the TPDO recorder's."""
        zero = t_zero if t_zero is not None else (self.t0 or 0.0)
        rec = Recording(times=[row[0] - zero for row in self.rows])
        nan = math.nan
        for r in self.refs:
            mine = [row if row[1] == r.name else None for row in self.rows]
            rec.columns[f"{r.name}.px"] = [float(m[2]) if m else nan for m in mine]
            rec.columns[f"{r.name}.vx"] = [float(m[3]) if m else nan for m in mine]
            if self.current:
                rec.columns[f"{r.name}.iq_a"] = [m[4] if m and m[4] is not None else nan for m in mine]
        for joint in cfg.joints.values():
            if joint.drive is not None and f"{joint.drive}.px" in rec.columns:
                rec.columns[f"{joint.name}.pos_rad"] = [counts_to_rad(v, joint.cpr) if v == v else nan
                                                        for v in rec.columns[f"{joint.drive}.px"]]
                rec.columns[f"{joint.name}.vel_rad_s"] = [counts_per_s_to_rad_per_s(v, joint.cpr) if v == v else nan
                                                          for v in rec.columns[f"{joint.drive}.vx"]]
            elif (m := joint_map(cfg, joint)) is not None and m.b is not None \
                    and f"{m.a}.px" in rec.columns and f"{m.b}.px" in rec.columns:
                rec.columns[f"{joint.name}.pos_rad"], rec.columns[f"{joint.name}.vel_rad_s"] = self._pair_columns(m)
        return rec

    def _pair_columns(self, m: JointMap) -> tuple[list[float], list[float]]:
        """A bus's poll thread reads its drives in the same order every round, so the pair's rows
        alternate: each second reading completes a round with the other motor's reading before it."""
        a, b = m.a, m.b
        assert b is not None  # a pair joint's map
        pos, vel = [math.nan] * len(self.rows), [math.nan] * len(self.rows)
        first: dict[str, tuple[int, int]] = {}
        for i, (_, name, px, vx, _iq) in enumerate(self.rows):
            if name not in (a, b):
                continue
            other = b if name == a else a
            if other not in first:
                first = {name: (px, vx)}
                continue
            (pa, va), (pb, vb) = ((px, vx), first[b]) if name == a else (first[a], (px, vx))
            pos[i] = counts_to_rad(m.value(pa, pb), m.cpr)
            vel[i] = counts_per_s_to_rad_per_s(m.value(va, vb), m.cpr)
            first = {}
        return pos, vel
