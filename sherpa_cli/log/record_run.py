"""One recording of joint motion, start to end: the engine of `sherpa log record` and `Arm.record`
(docs/log.md, docs/api.md).

:func:`plan_record` decides from the config alone what is recorded (the drives, their encoders'
buses, current or not, the bus budget), so a command can show the budget and refuse a rate the
bus cannot carry before any bus is opened. :func:`run_record` then records on an open session --
TPDOs on SYNC (log/record.py ``Recorder``) or, with ``poll``, interpreter queries (``Poller``) --
for ``duration`` through an injected ``wait``, and returns a :class:`RecordResult`: the samples
with their timestamps, what arrived per drive, the gaps, and the writers to CSV and MCAP.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from sherpa_cli.errors import SherpaError, UsageError
from sherpa_cli.log.recording import Recording, write_csv

if TYPE_CHECKING:
    import can

    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.log.foxglove_live import LiveView
    from sherpa_cli.log.mcap_out import TimedEmcy, TimedStatus
    from sherpa_cli.log.record import BusBudget, Gaps, SyncSource
    from sherpa_cli.log.record_extras import RecordExtras

MAX_RECORD_S = 3600.0
# the lowest rate of a recording (the wait notices Ctrl-C and its end once a SYNC period)
MIN_RECORD_RATE = 1.0
MAX_RECORD_RATE = 10000.0

#: ``wait(duration, failed)``: block while the recording runs; True when it was interrupted (Ctrl-C,
#: SIGTERM), False at its end or as soon as ``failed()`` (the recorder found another SYNC producer)
Wait = Callable[[float, Callable[[], bool]], bool]


class RecordTime(Protocol):
    """Where a recording's time comes from when it is not wall time (sim/stepped.py ``SteppedTime``):
    the recorder's clock, the wait's sleep and the SYNC source, and which SYNCs were answered."""

    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...

    def sync_factory(self, name: str, bus: can.BusABC, period: float) -> SyncSource: ...

    def follow(self, answered: Callable[[int], bool]) -> None: ...


def check_record_values(duration: float, rate: float) -> None:
    """The bounds of a recording's length and rate, worded as the command's options."""
    if not (math.isfinite(duration) and 0 < duration <= MAX_RECORD_S):
        raise UsageError(f"--for {duration}: expected seconds > 0 and <= {MAX_RECORD_S:g}")
    if not (math.isfinite(rate) and MIN_RECORD_RATE <= rate <= MAX_RECORD_RATE):
        raise UsageError(f"--rate {rate:g}: expected Hz >= {MIN_RECORD_RATE:g} (the recording notices Ctrl-C and "
                         f"its end once a SYNC period) and <= {MAX_RECORD_RATE:g}")


@dataclass(frozen=True)
class RecordPlan:
    """What a recording samples, decided from the config before any bus opens."""

    refs: tuple[DriveRef, ...]
    buses: tuple[str, ...]  # the drives' buses and their joints' encoders' buses, config order of first use
    rate: float
    current: bool
    poll: bool
    budget: tuple[BusBudget, ...]  # per bus (empty with ``poll``: the interpreter has no budget)

    def loads(self) -> dict[str, float]:
        """bus -> the share of its bit rate the recording takes (the MCAP's metadata)."""
        return {b.bus: round(b.load, 6) for b in self.budget}


def plan_record(cfg: ArmConfig, targets: Sequence[str] | None, rate: float, *, current: bool | None = None,
                poll: bool = False) -> RecordPlan:
    """The drives ``targets`` mean (joints, pairs, drives, an encoder device for the joint it measures;
    none: every configured drive), and for TPDO recording the bus budget. ``current`` None: sampled
    when every bus's budget allows it. Nothing is checked against the budget here (:func:`check_budget`)."""
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.devices import encoder
    from sherpa_cli.log.record import bus_budget

    # an encoder device stands for the joint it measures (recorded beside it: devices/encoder.py)
    refs = drive_refs(cfg, encoder.targets_with_encoders(cfg, targets), configured_only=True,
                      elmo_only="log record")
    tracks = encoder.recorded_encoders(cfg, (r.name for r in refs))
    budget: tuple[BusBudget, ...] = ()
    if not poll:
        encoders = [t.dev for t in tracks]
        if current is None:
            current = all(b.fits for b in bus_budget(cfg, refs, rate, current=True, encoders=encoders))
        budget = tuple(bus_budget(cfg, refs, rate, current=current, encoders=encoders))
    buses = tuple(dict.fromkeys([*(r.bus for r in refs), *(t.dev.bus for t in tracks)]))
    return RecordPlan(tuple(refs), buses, float(rate), bool(current), poll, budget)


def check_budget(plan: RecordPlan) -> None:
    """Refuse a rate a bus cannot carry, naming the highest it can (UsageError)."""
    from sherpa_cli.log.record import check_budget as check

    if not plan.poll:
        check(plan.budget)


def wait_on(clock: Callable[[], float], sleep: Callable[[float], None], *, wake_every: float = 0.1) -> Wait:
    """A :data:`Wait` on ``clock``/``sleep``, looking every ``wake_every`` s whether the recorder
    failed; Ctrl-C (KeyboardInterrupt) ends it as an interruption, the samples so far kept."""
    def wait(duration: float, failed: Callable[[], bool]) -> bool:
        try:
            end = clock() + duration
            while (rest := end - clock()) > 0 and not failed():
                sleep(min(rest, wake_every))
        except KeyboardInterrupt:
            return True
        return False
    return wait


@dataclass
class RecordResult:
    """A finished recording: its samples with their timestamps (``recording``: ``time_s`` from the
    first SYNC, each joint in rad, rad/s and A, each drive's motor in counts and counts/s beside it;
    ``recording.joint(name)`` and ``recording.drive(name)`` give them typed), and what arrived.

    ``samples``: per drive, the samples it delivered; ``expected``: the SYNCs sent (None when polled);
    ``rows``: rows recorded; ``gaps``: per drive where its samples are missing; ``late``: frames that
    came after their row was written; ``unplaced``: frames that answered no SYNC this tool sent.
    ``interrupted``: the wait was cut short (Ctrl-C); ``failure``: what ended it early (another SYNC
    producer), raised by :meth:`check`. ``streamed``: the rows went to a CSV file as they came, and
    ``recording`` holds none of them.
    """

    cfg: ArmConfig = field(repr=False)
    plan: RecordPlan
    recording: Recording
    samples: dict[str, int]
    rows: int
    time_zero_ns: int  # wall time of time_s 0 (ns since the epoch), the MCAP's log times
    expected: int | None = None
    late: int = 0
    unplaced: int = 0
    gaps: dict[str, Gaps] = field(default_factory=dict)
    period: float = 0.0
    interrupted: bool = False
    failure: SherpaError | None = None
    streamed: Path | None = None
    status: list[TimedStatus] = field(default_factory=list)  # the drives' MO/UM/SR/MF before and after
    emcy: list[TimedEmcy] = field(default_factory=list)  # EMCYs heard meanwhile

    @property
    def ok(self) -> bool:
        return self.failure is None and not self.interrupted

    def check(self) -> None:
        """Raise the failure that ended the recording early, if any."""
        if self.failure is not None:
            raise self.failure

    def write_csv(self, path: str | Path) -> None:
        """The samples as the CSV `sherpa log record -o FILE.csv` writes (log/recording.py)."""
        if self.streamed is not None:
            raise UsageError(f"{path}: this recording was streamed to {self.streamed}; it holds no rows")
        write_csv(self.recording, Path(path))

    def write_mcap(self, path: str | Path, *, info: Mapping[str, str] | None = None, config_file: str = "") -> None:
        """The samples as a ROS 2 MCAP (docs/log.md "MCAP"; the robotics extra): joint states, motor
        counts, the drives' status and the EMCYs heard. ``info``: the file's metadata (default: how
        it was recorded)."""
        from sherpa_cli.log.mcap_out import write_recording

        if self.streamed is not None:
            raise UsageError(f"{path}: this recording was streamed to {self.streamed}; it holds no rows")
        if info is None:
            info = {"source": "poll" if self.plan.poll else "TPDO on SYNC",
                    "rate_hz": "" if self.plan.poll else f"{self.plan.rate:g}",
                    "current": str(self.plan.current).lower()}
        write_recording(Path(path), self.recording, self.cfg, time_zero_ns=self.time_zero_ns, info=info,
                        status=self.status, emcy=self.emcy, config_file=config_file)


def run_record(session: ArmSession, plan: RecordPlan, duration: float, *, wait: Wait | None = None,
               stream_to: Path | None = None, status: bool = False, view: LiveView | None = None,
               timebase: RecordTime | None = None) -> RecordResult:
    """Record ``plan`` on ``session`` for ``duration`` s. The drives' PDO settings are RAM only, read
    first and put back on every way out; nothing is saved.

    ``wait``: how the caller waits (default: :func:`wait_on` the timebase's clock, else wall time);
    ``stream_to``: a CSV file the rows go to as they come (constant memory; TPDO recording only);
    ``status``: read the drives' status before and after and listen for EMCY (for an MCAP);
    ``view``: a Foxglove live view fed the newest sample; ``timebase``: the clock, sleep and SYNC
    source (default wall time; tests and `--sim` step it, sim/stepped.py).
    """
    from sherpa_cli.log.record_extras import RecordExtras

    check_record_values(duration, plan.rate)
    if stream_to is not None and plan.poll:
        raise UsageError("a polled recording is written at its end: stream_to takes a TPDO recording")
    if wait is None:
        wait = wait_on(timebase.now, timebase.sleep) if timebase is not None else wait_on(time.monotonic, time.sleep)
    extras = RecordExtras(session, list(plan.refs), mcap=status, view=view, budget=plan.loads())
    try:
        return _run(session, plan, duration, extras, wait, timebase, stream_to)
    finally:
        extras.stop()


def _run(session: ArmSession, plan: RecordPlan, duration: float, extras: RecordExtras, wait: Wait,
         timebase: RecordTime | None, stream_to: Path | None) -> RecordResult:
    from sherpa_cli.log.record import Poller, Recorder
    from sherpa_cli.log.record_extras import poller_sample, recorder_sample
    from sherpa_cli.log.recording import CsvWriter

    cfg = session.cfg
    extras.start()
    if plan.poll:
        poller = Poller(session, plan.refs, current=plan.current) if timebase is None else \
            Poller(session, plan.refs, current=plan.current, clock=timebase.now, sleep=timebase.sleep)
        zero_ns = time.time_ns()
        with poller, extras.feed(cfg, poller_sample(poller)):
            interrupted = wait(duration, lambda: False)
        rec = poller.recording(cfg)
        extras.read_status()
        return RecordResult(cfg, plan, rec, poller.counts(), len(rec.times), zero_ns, interrupted=interrupted,
                            status=extras.status, emcy=extras.emcy)
    recorder = Recorder(session, plan.refs, plan.rate, current=plan.current) if timebase is None else \
        Recorder(session, plan.refs, plan.rate, current=plan.current, clock=timebase.now,
                 sync_factory=timebase.sync_factory)
    wall_ns = time.time_ns()
    streamed: CsvWriter | None = None
    # a streamed recording goes to the file row by row as it comes (constant memory; a killed
    # recording leaves its rows so far)
    if stream_to is not None:
        recorder.sink = streamed = CsvWriter(stream_to, recorder.columns())
    try:
        with recorder, extras.feed(cfg, recorder_sample(recorder)):
            if timebase is not None:
                timebase.follow(recorder.answered)
            interrupted = wait(duration, lambda: recorder.problem() is not None)
    finally:
        if streamed is not None:
            streamed.close()
    extras.read_status()
    rec = recorder.recording() if streamed is None else Recording()
    return RecordResult(cfg, plan, rec, recorder.counts(), streamed.rows if streamed is not None else len(rec.times),
                        # the first SYNC's wall time is time_s 0 of the rows (a stepped clock is no wall time)
                        round(recorder.time_zero() * 1e9) if timebase is None else wall_ns,
                        expected=recorder.expected(), late=recorder.late(), unplaced=recorder.unplaced(),
                        gaps=recorder.gaps(), period=recorder.period, interrupted=interrupted,
                        failure=recorder.problem(), streamed=stream_to, status=extras.status, emcy=extras.emcy)
