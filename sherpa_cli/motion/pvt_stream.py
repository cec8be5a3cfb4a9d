"""Streaming PVT records to Elmo drives inside an entered motion guard (docs/pvt.md).

:func:`stream_pvt` takes, per drive, the records of one trajectory at the period of
``StreamSettings.pvt.period_ms`` (position counts and velocity counts/s at the end of each period) and:

1. refuses what cannot be streamed before anything is sent (unequal lengths, a last row still moving, a
   value outside int32, a guard that would stop on the PVT emergencies, more rows primed than the queue);
2. sets every drive up (elmo/pvt.py: MP[], the period, the record RPDO's mapping by SDO), every RAM value it
   changes noted first in the drive's journal (bus/journal.py, as the guard notes UM) and put back on every
   way out, then UM and the motor through :meth:`MotionGuard.enable`;
3. primes each queue, starts the drives one after the other (PV=n, BG) and measures the skew;
4. keeps every queue filled from a thread of its own on the injected clock/sleep: at each period the
   records due by then go out, ``prime`` periods ahead of the drive's consumption, and counts the
   periods served on time; the command's thread calls ``guard.check()`` while it watches the sender.

A send later than ``StreamSettings.late_bound_s`` (a starved stream), a queue-low while rows are still to be
sent (the sender on time, so rows were lost: it cannot be answered), an underflow or any other PVT
emergency that ends a stream (queue full, a lost message, a bad pointer) before the trajectory's end stops
every drive at once (the guard's stop frames) and raises :class:`StreamStoppedError` naming the drive; the
guard's exit then stops every drive from standstill. A drive is never left to run to the end of its queue.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sherpa_cli.bus import journal
from sherpa_cli.elmo.faults import EMCY_PVT, Emcy
from sherpa_cli.elmo.pvt import (
    InterpSet,
    PvtEvent,
    PvtSettings,
    encode_record,
    interpreter_setup,
    pdo_restore,
    pdo_setup,
    pvt_event,
    start_steps,
)
from sherpa_cli.errors import CodecError, SafetyError, UsageError
from sherpa_cli.motion.stopping import send_stop, why

if TYPE_CHECKING:
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

log = logging.getLogger(__name__)

JOURNAL_OWNER = "pvt stream"
WATCH_POLL_S = 0.005  # wall s between the watch's looks at the sender's deadline
HANG_GUARD_S = 10.0  # wall s to wait for a stopped sender's thread to end
Record = tuple[int, int]  # (position counts, velocity counts/s)


@dataclass(frozen=True)
class StreamSettings:
    """How the stream runs. ``late_bound_s`` None: half the time the primed rows above the queue-low
    threshold cover, so a stream that late stops well before the drive reaches the end of its queue."""

    pvt: PvtSettings = field(default_factory=PvtSettings)
    prime: int = 32  # rows queued before the start and kept ahead of the drive's consumption
    late_bound_s: float | None = None
    end_margin_periods: int = 2  # periods after the last row is played before the stream counts as ended
    # the first row is one period from where the motor stands: farther than its own speed takes it in a
    # period, plus this, and the drive would jump there
    start_tolerance: int = 2  # counts

    def __post_init__(self) -> None:
        # a fed queue holds prime - 2 rows just before a send, minus the periods a late send may lag
        # (half the rows above the threshold): at least 4 above MP[4], or a healthy stream reads queue-low
        lo = self.pvt.low_threshold + 4
        if isinstance(self.prime, bool) or not isinstance(self.prime, int) or not lo <= self.prime <= self.pvt.queue_size:
            raise ValueError(f"StreamSettings.prime must be {lo}..{self.pvt.queue_size} (queue-low threshold "
                             f"{self.pvt.low_threshold} + 4 .. the queue), got {self.prime!r}")
        if self.late_bound_s is not None and not self.late_bound_s > 0:
            raise ValueError(f"StreamSettings.late_bound_s must be > 0, got {self.late_bound_s!r}")

    @property
    def late_bound(self) -> float:
        if self.late_bound_s is not None:
            return self.late_bound_s
        return max(1, self.prime - self.pvt.low_threshold) * self.pvt.period_s / 2


@dataclass
class StreamReport:
    """What the stream did; ``stopped`` says why it ended early (None: it played to the end)."""

    period_s: float
    periods: int = 0  # periods the sender served
    sent: int = 0  # records sent, all drives
    on_time: int = 0
    late: int = 0  # periods served later than one period after their due time
    max_lateness_s: float = 0.0
    skew_s: float = 0.0  # between the first and the last drive's start
    starts: dict[str, float] = field(default_factory=dict)  # drive -> start time (the injected clock)
    last_position: dict[str, int] = field(default_factory=dict)  # drive -> PX at the end
    queue_low: dict[str, int] = field(default_factory=dict)  # drive -> queue-low EMCYs
    events: list[str] = field(default_factory=list)  # PVT emergencies, "drive: text"
    restored: dict[str, list[str]] = field(default_factory=dict)  # drive -> what was put back
    stopped: str | None = None

    @property
    def on_time_pct(self) -> float:
        return 100.0 * self.on_time / self.periods if self.periods else 100.0


class StreamStoppedError(SafetyError):
    """The stream was stopped (starved, an underflow or another PVT emergency): every drive was stopped."""

    def __init__(self, message: str, *, drive: str, report: StreamReport, hint: str | None = None) -> None:
        super().__init__(message, hint=hint)
        self.drive = drive
        self.report = report


def stream_motion_settings(settings: MotionSettings) -> MotionSettings:
    """``settings`` with the PVT emergencies (0xFF00) answered by the streamer, not the guard: a queue-low
    is no fault, an underflow at the end of the trajectory is its normal end, and the streamer stops
    every drive on the ones that end a stream early (its report names them)."""
    if EMCY_PVT in settings.emcy_answered_codes:
        return settings
    return dataclasses.replace(settings, emcy_answered_codes=(*settings.emcy_answered_codes, EMCY_PVT))


@dataclass
class _Stream:
    """One drive's part of the stream."""

    ref: DriveRef
    client: DriveClient
    records: list[bytes]
    pvt: PvtSettings
    interp_old: list[InterpSet] = field(default_factory=list)  # what was there before, in set-up order
    pdo_old: dict[tuple[int, int], int] = field(default_factory=dict)
    noted: bool = False
    started: float | None = None


def stream_pvt(guard: MotionGuard, tracks: Mapping[str, Sequence[Record]], *, settings: StreamSettings | None = None,
               clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
               watch: Callable[[float], None] | None = None, watch_interval: float = 0.01) -> StreamReport:
    """Stream ``tracks`` (drive name -> records, one per period) to the guard's drives; see the module
    docstring. Returns the report; raises :class:`StreamStoppedError` (every drive stopped) when the stream
    could not be kept up, UsageError for tracks that cannot be streamed (nothing sent).

    ``watch(elapsed)`` (s since the first start, the injected clock) runs on the sender's thread every
    ``watch_interval`` s while the stream plays, after that period's sends (on the stream's own clock,
    so what it sees does not depend on the host): the caller's limit and tracking watch. What it
    raises stops every drive at once and ends the stream with it."""
    s = settings or StreamSettings()
    report = StreamReport(period_s=s.pvt.period_s)
    streams = _prepare(guard, tracks, s)
    try:
        for st in streams:
            _set_up(guard, st, s.pvt, report)
        for st in streams:
            guard.enable(st.ref, s.pvt.unit_mode)
        for st in streams:
            for data in st.records[:s.prime]:
                _send(guard, st, data)
                report.sent += 1
        for st in streams:
            guard.check()
            for step in start_steps(s.pvt):
                st.client.set(step.letters, step.index, step.value)
            if s.pvt.begin_with_bg:
                st.client.execute("BG")
            st.started = clock()
            report.starts[st.ref.name] = st.started
        starts = [st.started for st in streams if st.started is not None]
        report.skew_s = max(starts) - min(starts)
        _run_sender(guard, streams, s, report, clock, sleep, watch=watch, watch_interval=watch_interval)
        for st in streams:
            report.last_position[st.ref.name] = guard.position(st.ref)
    except BaseException as exc:
        if not isinstance(exc, StreamStoppedError):
            _stop_all(guard, streams, report)  # at once: the guard's exit then waits for standstill
        raise
    finally:
        problems = _restore_all(guard, streams, report)
    if problems:
        raise SafetyError("the PVT set-up was not put back: " + "; ".join(problems),
                          hint="`sherpa recover` puts the journaled values back")
    return report


# -- before anything is sent ------------------------------------------------------------------------

def _prepare(guard: MotionGuard, tracks: Mapping[str, Sequence[Record]], s: StreamSettings) -> list[_Stream]:
    if not tracks:
        raise UsageError("a PVT stream needs at least one drive's records")
    if EMCY_PVT not in guard.settings.emcy_answered_codes and EMCY_PVT not in guard.settings.emcy_warning_codes:
        raise UsageError("the motion guard would stop on the PVT emergencies (EMCY 0xFF00)",
                         hint="enter the guard with stream_motion_settings(settings)")
    by_name = {ref.name: ref for ref in guard.refs}
    lengths = {name: len(records) for name, records in tracks.items()}
    if len(set(lengths.values())) != 1:
        raise UsageError("every drive of a PVT stream needs the same number of records: "
                         + ", ".join(f"{n} {k}" for n, k in lengths.items()))
    out: list[_Stream] = []
    for name, records in tracks.items():
        ref = by_name.get(name)
        if ref is None:
            raise UsageError(f"{name}: not a drive of this motion guard ({', '.join(by_name) or 'none'})")
        if not records:
            raise UsageError(f"{name}: no PVT records")
        if records[-1][1] != 0:
            raise UsageError(f"{name}: the last PVT record moves at {records[-1][1]} counts/s",
                             hint="end a trajectory at rest: the drive would run on past it")
        try:
            frames = [encode_record(p, v) for p, v in records]
        except CodecError as exc:
            raise UsageError(f"{name}: {exc.message}") from None
        out.append(_Stream(ref, guard.client(ref), frames, s.pvt))
    for st in out:
        position, velocity = tracks[st.ref.name][0]
        here = guard.position(st.ref)
        reach = abs(velocity) * s.pvt.period_s + s.start_tolerance
        if abs(position - here) > reach:
            raise UsageError(f"{st.ref.name}: the first PVT record is at {position}, the motor at {here}: "
                             f"more than {reach:.0f} counts for the first {s.pvt.period_ms} ms",
                             hint="a trajectory starts where the motor stands")
    return out


# -- set-up and restore ------------------------------------------------------------------------------

def _set_up(guard: MotionGuard, st: _Stream, p: PvtSettings, report: StreamReport) -> None:
    """Read what is there, note it in the journal, then write: MP[] and the period, the RPDO mapping.
    UM is the guard's (enable notes and restores it)."""
    guard.check()
    c, sdo = st.client, guard.session.sdo(st.ref)
    sets = [step for step in interpreter_setup(p) if step.letters != "UM"]
    writes = pdo_setup(p, st.ref.node)
    old_interp = [InterpSet(step.letters, step.index, int(c.get(step.letters, step.index))) for step in sets]
    old_pdo: dict[tuple[int, int], int] = {}
    for w in writes:
        if (w.index, w.sub) not in old_pdo:
            old_pdo[(w.index, w.sub)] = int.from_bytes(sdo.upload(w.index, w.sub)[:w.size], "little")
    guard.check()
    # `sherpa recover` replays a journal backwards: the PDO's safe way back (off, mapping, type, its old
    # COB-ID last) is noted last step first
    back = reversed(pdo_restore(p, old_pdo))
    journal.note(st.ref, *(journal.interp(JOURNAL_OWNER, o.letters, o.index, o.value) for o in old_interp),
                 *(journal.sdo(JOURNAL_OWNER, w.index, w.sub, w.size, w.value) for w in back))
    st.noted = True
    st.interp_old, st.pdo_old = old_interp, old_pdo
    for step in sets:
        c.set(step.letters, step.index, step.value)
    for w in writes:
        guard.check()
        sdo.download(w.index, w.sub, w.value.to_bytes(w.size, "little"))
    report.restored.setdefault(st.ref.name, [])


def _restore_all(guard: MotionGuard, streams: list[_Stream], report: StreamReport) -> list[str]:
    """Put back every drive's PVT set-up: the mapping first (no record reaches the drive any more), then
    MP[] and the period. Never raises; returns the problems."""
    problems: list[str] = []
    for st in streams:
        if not st.noted:
            continue
        done = report.restored.setdefault(st.ref.name, [])
        failed = False
        try:
            sdo = guard.session.sdo(st.ref)
            if st.pdo_old:
                for w in pdo_restore(st.pvt, st.pdo_old):
                    sdo.download(w.index, w.sub, w.value.to_bytes(w.size, "little"))
                done.append(f"RPDO{st.pvt.rpdo} mapping")
            for old in st.interp_old:
                st.client.set(old.letters, old.index, old.value)
                done.append(f"{old.name}={old.value}")
        except Exception as exc:  # noqa: BLE001 - reported; this runs in a finally and must not mask the cause
            failed = True
            problems.append(f"{st.ref.name}: {why(exc)}")
        if not failed:
            journal.forget(st.ref, JOURNAL_OWNER)
    return problems


# -- sending ------------------------------------------------------------------------------------------

def _send(guard: MotionGuard, st: _Stream, data: bytes) -> None:
    guard.session.links[st.ref.bus].network.send_message(st.pvt.cob_id(st.ref.node), data)


def _stop_all(guard: MotionGuard, streams: list[_Stream], report: StreamReport) -> None:
    """The guard's stop frames to every drive that may move, one right after the other. Never raises."""
    for st in streams:
        if st.started is None:
            continue
        try:
            _how, problems = send_stop(st.client, unit_mode=None)
        except Exception as exc:  # noqa: BLE001 - the guard's exit stops it again and reports
            problems = [why(exc)]
        for problem in problems:
            report.events.append(f"{st.ref.name}: stop: {problem}")


@dataclass
class _Pace:
    """What the sender and the watch of it share, under ``lock``: the send due now and by when it must
    have gone out (inf: nothing left to send)."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    stop: threading.Event = field(default_factory=threading.Event)
    due: float = math.inf
    deadline: float = math.inf


def _run_sender(guard: MotionGuard, streams: list[_Stream], s: StreamSettings, report: StreamReport,
                clock: Callable[[], float], sleep: Callable[[float], None], *,
                watch: Callable[[float], None] | None = None, watch_interval: float = 0.01) -> None:
    """The sender's thread, and this thread watching it: a send not out by its deadline stops every drive
    now, while the sender is still stuck (a sleep that overran, a hung request), not when it wakes."""
    events: collections.deque[tuple[float, str, PvtEvent]] = collections.deque()
    callbacks = []
    for st in streams:
        def on_emcy(emcy: Emcy, name: str = st.ref.name) -> None:
            event = pvt_event(emcy)
            if event is not None:
                events.append((clock(), name, event))
        st.client.on_emcy(on_emcy)
        callbacks.append((st.client, on_emcy))
    pace = _Pace()
    failure: list[BaseException] = []

    def run() -> None:
        try:
            _sender(guard, streams, s, report, clock, sleep, events, pace, watch, watch_interval)
        except BaseException as exc:  # noqa: BLE001 - handed to the command's thread, which raises it
            failure.append(exc)

    thread = threading.Thread(target=run, name="pvt-stream", daemon=True)
    try:
        thread.start()
        while thread.is_alive():
            thread.join(WATCH_POLL_S)  # wall time: how often the watch looks; the deadline is the clock's
            # the guard's sign of life and its checks (signals, the dead-man's read-back of every drive
            # now and then) from this thread: on the sender's they held its period past the late bound
            guard.check()
            now = clock()
            if now <= pace.deadline:
                continue
            # the sender may be between its sleep and its sends: let it finish those first (bounded)
            got = pace.lock.acquire(timeout=s.late_bound)
            try:
                starved = not pace.stop.is_set() and clock() > pace.deadline
                if starved:
                    pace.stop.set()
            finally:
                if got:
                    pace.lock.release()
            if starved:
                late = clock() - pace.due
                report.max_lateness_s = max(report.max_lateness_s, late)
                raise _starved(guard, streams, s, report, late)
    except BaseException:
        pace.stop.set()
        thread.join(HANG_GUARD_S)  # the sender ends at its next wake-up; a hung one is a daemon thread
        raise
    finally:
        for client, callback in callbacks:
            client.remove_emcy(callback)
    if failure:
        raise failure[0]


def _starved(guard: MotionGuard, streams: list[_Stream], s: StreamSettings, report: StreamReport,
             late: float) -> StreamStoppedError:
    """Every drive stopped now; the error to raise."""
    name = ", ".join(st.ref.name for st in streams)  # one sender feeds them all: all starve
    report.stopped = f"starved: a send {late * 1000:.0f} ms late (bound {s.late_bound * 1000:.0f} ms)"
    _stop_all(guard, streams, report)
    return StreamStoppedError(f"PVT stream starved ({name}): the records were {late * 1000:.0f} ms late, "
                              f"more than {s.late_bound * 1000:.0f} ms; every drive stopped",
                              drive=name, report=report,
                              hint="the host could not keep the stream's period: lower the load or "
                                   "raise StreamSettings.prime")


def _sender(guard: MotionGuard, streams: list[_Stream], s: StreamSettings, report: StreamReport,
            clock: Callable[[], float], sleep: Callable[[float], None],
            events: collections.deque[tuple[float, str, PvtEvent]], pace: _Pace,
            watch: Callable[[float], None] | None = None, watch_interval: float = 0.01) -> None:
    period = s.pvt.period_s
    total = len(streams[0].records)
    t0 = min(st.started for st in streams if st.started is not None)
    # row k (from 0) is taken by the drive at t0 + k T and played until t0 + (k + 1) T; the last row ends then
    end = t0 + total * period
    sending_until = t0 + (total - s.prime) * period  # the last row goes out then; the queue drains after
    next_row = s.prime
    next_watch = t0
    # the drives were started one after the other: the periods that passed meanwhile are not the
    # sender's lateness (their rows go out at its first wake-up; the primed queue covered them, and a
    # queue that ran low meanwhile says so with its EMCY)
    k = max(0, math.floor((clock() - t0) / period))
    while not pace.stop.is_set():
        k += 1
        due = t0 + k * period
        with pace.lock:
            pace.due = due
            pace.deadline = due + s.late_bound if next_row < total else math.inf
        wait = due - clock()
        if wait > 0:
            sleep(wait)
        with pace.lock:
            if pace.stop.is_set():
                return  # the watch stopped the stream (or the command is ending)
            now = clock()
            late = now - due
            report.periods += 1
            report.max_lateness_s = max(report.max_lateness_s, late)
            if late <= period:
                report.on_time += 1
            else:
                report.late += 1
            if late > s.late_bound and next_row < total:
                pace.stop.set()
                raise _starved(guard, streams, s, report, late)
            # after the lateness: a late host also makes the queues run low, and lateness is the cause to name
            _answer_events(guard, streams, events, report, end, period, sending_until)
            # every row due by now: the drives take row j at t0 + j T, it goes out prime periods before
            due_rows = min(total, s.prime + int((now - t0) / period + 1e-9))
            while next_row < due_rows:
                for st in streams:
                    _send(guard, st, st.records[next_row])
                    report.sent += 1
                next_row += 1
            if watch is not None and now >= next_watch:
                next_watch = now + watch_interval
                watch(now - t0)
            if now >= end + s.end_margin_periods * period:
                _answer_events(guard, streams, events, report, end, period, sending_until)
                return


def _answer_events(guard: MotionGuard, streams: list[_Stream], events: collections.deque[tuple[float, str, PvtEvent]],
                   report: StreamReport, end: float, period: float, sending_until: float) -> None:
    """Count queue-lows; stop everything on an emergency that ends a stream before the trajectory's end
    (an underflow when the last row has played out is the stream's normal end), and on a queue-low while
    rows are still to be sent: the drive has fewer rows than were sent, so some were lost."""
    while events:
        at, name, event = events.popleft()
        report.events.append(f"{name}: {event.text}")
        if not event.ends_stream:
            report.queue_low[name] = report.queue_low.get(name, 0) + 1
            if at >= sending_until:
                continue  # the queue drains after the last row: expected
        elif event.underflow and at >= end - period / 2:
            continue
        report.stopped = f"{name}: {event.text}"
        _stop_all(guard, streams, report)
        raise StreamStoppedError(f"PVT stream stopped: {name}: {event.text}; every drive stopped",
                                 drive=name, report=report,
                                 hint="an underflow means the drive ran out of records: the host was late or "
                                      "records were lost (`sherpa bus watch` shows the bus)")
