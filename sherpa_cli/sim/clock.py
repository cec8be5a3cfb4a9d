"""Injectable time for the simulator: tests drive a ManualClock, `sherpa sim` a RealClock."""

from __future__ import annotations

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

    def read(self) -> float:
        """The stalled seconds so far (never decreasing); a reading also ends a stretch."""
        with self._lock:
            wall = self._wall()
            if self._last is not None and wall - self._last > self.max_gap:
                self.stalled += wall - self._last - self.max_gap
            self._last = max(wall, self._last if self._last is not None else wall)
            return self.stalled

    def keep_time(self, stop: threading.Event, every: float = 0.01) -> None:
        """Read the meter every ``every`` s until ``stop`` is set (a thread of the simulator): a gap
        then means the process did not run, not that nothing happened on the bus."""
        while not stop.wait(every):
            self.read()
