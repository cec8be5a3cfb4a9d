"""Stepped time for the in-process simulated arm: `sherpa --sim log step` (docs/log.md).

The arm runs on a :class:`ManualClock` that moves only when the tool waits. Every wait of the
command (its own, the motion guard's, the drive clients' MO polls) goes through :meth:`sleep`;
while a recording is on, the clock moves one SYNC period at a time: SYNC goes out on the bus,
then the wait lasts until the recorder has every TPDO that SYNC asked for, and only then does
the clock move on. So what is recorded, and every figure computed from it, depends on the
simulated drive and the commands sent, not on how fast or loaded the host is.

Two bounds keep the rest of the protocol honest:

- simulated time never runs faster than wall time: a :meth:`sleep` moves the clock in slices of
  at most ``PACED_SLICE_S`` (or SYNC periods), each only once the wall has caught up with the one
  before, so it is never more than a slice ahead: the motion guard's host heartbeat comes from a
  thread in wall time, and the drive's heartbeat consumer counts simulated time;
- while recording, the clock stops only on SYNC instants (a wait is rounded up to whole
  periods), so the simulated drives are always stepped to the same instants.

The drive clients (:meth:`client_overrides`) wait on this clock too. A request that a drive in
its MO settle window does not hear costs the host, on a real bus, its wait for the reply: until
the window ends (the client knows ``protocol.mo_settle``), at most one reply timeout. The
simulated drives count such requests and the settle time each had left (``SimDrive.unheard``,
``unheard_s``), and the clients' next wait is charged that much simulated time, while their real
wait for a reply that will not come stays short (``STEPPED_REPLY_S``: the in-process simulator
answers within milliseconds; retries cover a loaded machine).
"""

from __future__ import annotations

import bisect
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from sherpa_cli.elmo.protocol import SYNC_ID
from sherpa_cli.errors import CommunicationError
from sherpa_cli.sim.clock import ManualClock

if TYPE_CHECKING:
    import can  # imported where a SYNC is sent: the simulator's modules load without python-can

ANSWER_TIMEOUT_S = 5.0  # wall time to wait for the TPDOs of one SYNC (a loaded machine)
STEPPED_REPLY_S = 0.3  # wall time a client waits for one reply from the stepped in-process arm (a deaf
# poll costs this much wall time; an answerable one later than this on a loaded machine would cost
# one more charged wait, so it is generous)
PACED_SLICE_S = 0.02  # the longest step simulated time takes at once in a paced wait (heartbeats: 10-100 ms)
STEPPED_RETRIES = 4  # at least this many resends (a late reply on a loaded machine; sim time stands still)
_EPS = 1e-9


class SyncBus(Protocol):
    """What the SYNC source needs of a bus (a python-can bus is one)."""

    def send(self, msg: can.Message) -> None: ...


class SteppedTime:
    """``now``/``sleep`` for the tool, and a SYNC source (``sync_factory``) for its Recorder."""

    def __init__(self, clock: ManualClock | None = None, *, pace: bool = True,
                 answer_timeout: float = ANSWER_TIMEOUT_S, wall: Callable[[], float] = time.monotonic,
                 wall_sleep: Callable[[float], None] = time.sleep) -> None:
        self.clock = clock or ManualClock()
        self._wall, self._wall_sleep = wall, wall_sleep  # what pacing waits on (tests: a fake wall)
        self.pace = pace
        self.answer_timeout = answer_timeout
        self._buses: dict[str, SyncBus] = {}
        self._period: float | None = None
        self._t0 = 0.0
        self._syncs = 0  # SYNCs sent since the SYNC source started
        self._answered: Callable[[int], bool] = lambda n: True
        self._sources: dict[str, _Source] = {}
        self._lock = threading.Lock()  # one sleeper at a time (the command's thread)

    def now(self) -> float:
        return self.clock.now()

    def client_overrides(self, reply_timeout: float, retries: int,
                         unheard: Callable[[], tuple[int, float]] = lambda: (0, 0.0)) -> dict[str, Any]:
        """DriveClient options (ArmSession.client_overrides) for clients of the stepped arm.
        ``reply_timeout``: the real bus's; ``unheard()``: (requests the simulated drives did not
        hear, the settle time they had left in total) so far; a wait is charged what was lost
        since the last one, at most one ``reply_timeout`` per request."""
        charged = [unheard()]

        def sleep(seconds: float) -> None:
            (n, s), (n0, s0) = unheard(), charged[0]
            charged[0] = (n, s)
            self.sleep(seconds + max(0.0, min(s - s0, (n - n0) * reply_timeout)))

        return {"clock": self.now, "sleep": sleep, "timeout": STEPPED_REPLY_S,
                "retries": max(retries, STEPPED_RETRIES)}

    # -- the SYNC source ------------------------------------------------------------------------
    def sync_factory(self, name: str, bus: SyncBus, period: float) -> _Source:
        """Recorder's ``sync_factory``: SYNC on ``bus`` every ``period`` of simulated time; the
        first SYNC is at the present instant (the recorder's t = 0), sent by the next sleep."""
        if not self._buses:
            self._t0, self._syncs, self._period = self.clock.now(), 0, period
        elif self._period is not None and abs(period - self._period) > _EPS:
            raise ValueError(f"SteppedTime: one SYNC period for all buses ({self._period} s, asked {period} s)")
        self._buses[name] = bus
        self._sources[name] = _Source(self, name, period)
        return self._sources[name]

    def follow(self, answered: Callable[[int], bool]) -> None:
        """``answered(n)``: whether every answer to the first n SYNCs has arrived (Recorder.answered)."""
        self._answered = answered

    def _stop(self, name: str) -> None:
        self._buses.pop(name, None)
        self._sources.pop(name, None)
        if not self._buses:
            self._period, self._answered = None, (lambda n: True)

    # -- waiting --------------------------------------------------------------------------------
    def sleep(self, seconds: float) -> None:
        if not seconds > 0:
            return
        with self._lock:
            start = self._wall()
            if self._period is not None:
                self._sync_for(seconds, start)
            elif not self.pace:
                self.clock.advance(seconds)
            else:
                # in slices, each paced: one long wait (a charged one, a settle) moved in a single jump
                # would put simulated time a whole wait ahead of the wall-time heartbeat, and a drive's
                # consumer, counting simulated time, would trip in the jump though no beat was missed
                # (each slice ends at an instant reckoned from the start, so the wait ends at exactly
                # begin + seconds, as one step would: no sum of slices drifts off it)
                begin = self.clock.now()
                end = begin + seconds
                while True:  # at least once: a wait shorter than _EPS still moves the clock
                    now = self.clock.now()
                    self.clock.advance(min(now + PACED_SLICE_S, end) - now)
                    self._pace(start, self.clock.now() - begin)
                    if self.clock.now() >= end:
                        break

    def _pace(self, start: float, ahead: float) -> None:
        """Wait until ``ahead`` s of wall time have passed since ``start`` (with ``pace``)."""
        if self.pace:
            rest = ahead - (self._wall() - start)
            if rest > 0:
                self._wall_sleep(rest)

    def _sync_for(self, seconds: float, start: float) -> None:
        """Whole SYNC periods covering ``seconds``, each SYNC answered before the clock moves on, and
        paced (from ``start``, wall time) at each SYNC instant, as :meth:`sleep` paces its slices."""
        import can

        period = self._period
        assert period is not None
        begin = self.clock.now()
        end = begin + seconds
        ahead = 0.0
        while True:
            due = self._t0 + self._syncs * period
            if due > end + _EPS and self.clock.now() + _EPS >= end:
                break
            if due > self.clock.now():
                ahead += due - self.clock.now()
                self.clock.advance(due - self.clock.now())
                self._pace(start, ahead)
            for name, bus in list(self._buses.items()):
                # noted before the send: its answer's receive timestamp is never earlier
                self._sources[name].log.sent(self.clock.now(), time.time())
                bus.send(can.Message(arbitration_id=SYNC_ID, data=b"", is_extended_id=False))
            self._syncs += 1
            deadline = time.monotonic() + self.answer_timeout
            while not self._answered(self._syncs):
                if time.monotonic() > deadline:
                    raise CommunicationError(f"simulated SYNC {self._syncs}: not every TPDO it asks for came within "
                                             f"{self.answer_timeout:g} s", hint="a simulated drive left Operational "
                                             "or died during the recording")
                time.sleep(0.0002)


class SentSyncs:
    """The SYNCs a stepped source sent (the Recorder's SYNC log, log/record.py SyncLog, which the
    simulator cannot import): each one's simulated time and the wall time (the frames' receive
    timestamps' clock) just before it went out."""

    stamped = True

    def __init__(self) -> None:
        self.at: list[float] = []
        self.stamps: list[float] = []
        self._lock = threading.Lock()

    def sent(self, at: float, stamp: float) -> None:
        with self._lock:
            self.at.append(at)
            self.stamps.append(stamp)

    def count(self) -> int:
        return len(self.at)

    def time_of(self, n: int) -> float:
        return self.at[n]

    def sent_by(self, stamp: float | None) -> int:
        if stamp is None:
            return len(self.at)
        with self._lock:
            return bisect.bisect_right(self.stamps, stamp)


class _Source:
    def __init__(self, owner: SteppedTime, name: str, period: float) -> None:
        self.owner, self.name = owner, name
        self.log = SentSyncs()

    def stop(self) -> None:
        self.owner._stop(self.name)

