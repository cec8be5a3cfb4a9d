"""Injectable time for the simulator: tests drive a ManualClock, `sherpa sim` a RealClock."""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    def now(self) -> float:
        """Seconds on a monotonic scale; only differences matter."""
        ...


class ManualClock:
    """A clock that moves only when told to, so timing tests are exact and instant."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)

    def now(self) -> float:
        return self._now

    def advance(self, dt: float) -> float:
        """Move time forward by ``dt`` seconds and return the new time."""
        if dt < 0:
            raise ValueError(f"a clock cannot go backwards (dt={dt})")
        self._now += dt
        return self._now


@runtime_checkable
class FrameClock(Clock, Protocol):
    """A clock that can place a received frame on its own scale: a bus pump that got to a frame late
    hands it to the drives at the time it arrived (sim/arm.py LATE_FRAME_S)."""

    def received_at(self, timestamp: float) -> float:
        """``timestamp`` (a received can.Message's) on this clock's scale."""
        ...


class RealClock:
    """Wall time; monotonic so a system clock change cannot make the simulated drive jump."""

    def now(self) -> float:
        return time.monotonic()

    def received_at(self, timestamp: float) -> float:
        # python-can stamps received frames with wall time (time.time() based)
        return time.monotonic() - (time.time() - timestamp)


STRETCHES_KEPT = 1024  # stretches stalled_at looks back over (each one at least max_gap long)


class StallMeter:
    """How long the process that runs an in-process simulator (``--sim``, the tests' arms) did not run.

    In one process the simulated drives and the tool's heartbeat thread starve together (a loaded
    machine deschedules the whole process). A real drive runs on its own CPU and keeps counting, but
    this one cannot tell a starved tool from a starved simulator: on wall time its heartbeat consumer
    saw a gap the tool never made, and stopped a command that sent every beat. The simulated drive's
    consumer leaves out what this meter counts; its motor keeps wall time (a real motor moves on
    while the tool is held up, and the tool must see that progress).

    A stretch of more than ``max_gap`` s between two readings counts ``max_gap`` less as stalled. The
    simulator reads it every few ms while it runs (:meth:`keep_time`, and every drive step), so only
    a process that did not run makes such a gap; a heartbeat thread that alone stops sending still
    trips the consumer. ``max_gap`` stays well below ``consumer_time_ms`` minus one heartbeat period
    (375 ms by default)."""

    def __init__(self, max_gap: float = 0.1, *, wall: Callable[[], float] = time.monotonic) -> None:
        if max_gap <= 0:
            raise ValueError(f"max_gap must be positive, not {max_gap}")
        self.max_gap = max_gap
        self.stalled = 0.0  # s the process did not run, beyond max_gap per stretch
        self._wall = wall
        self._last: float | None = None
        self._lock = threading.Lock()
        # the recent stretches: (wall time it ended, s counted), for stalled_at
        self._stretches: collections.deque[tuple[float, float]] = collections.deque(maxlen=STRETCHES_KEPT)

    def read(self) -> float:
        """The stalled seconds so far (never decreasing); a reading also ends a stretch."""
        with self._lock:
            return self._read_locked()

    def _read_locked(self) -> float:
        wall = self._wall()
        if self._last is not None and wall - self._last > self.max_gap:
            counted = wall - self._last - self.max_gap
            self.stalled += counted
            self._stretches.append((wall, counted))
        self._last = max(wall, self._last if self._last is not None else wall)
        return self.stalled

    def stalled_at(self, when: float) -> float:
        """The stalled seconds as of wall instant ``when`` (at most :meth:`read`'s): what a stretch
        counted after ``when`` is left out, a stretch's count taken as its last seconds.

        A frame the simulator handles late carries the instant it arrived. Paired with the meter
        read when it is handled, a heartbeat that came before a stall would be charged that stall:
        its consumer's window, counted from the arrival, would lose the very time the process did
        not run, and a busy machine's late pump tripped a dead-man the host had kept."""
        with self._lock:  # one reading and the stretches it saw: none added in between
            now = self._read_locked()
            return now - sum(min(counted, end - when) for end, counted in self._stretches if end > when)

    def keep_time(self, stop: threading.Event, every: float = 0.01) -> None:
        """Read the meter every ``every`` s until ``stop`` is set (a thread of the simulator): a gap
        then means the process did not run, not that nothing happened on the bus."""
        while not stop.wait(every):
            self.read()
