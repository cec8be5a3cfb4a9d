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


class PausingClock(RealClock):
    """Wall time for a simulator that runs inside the process it serves (``--sim``, the tests' arms):
    it stands still while that process does not run.

    In one process the simulated drives and the tool's heartbeat thread starve together (a loaded
    machine deschedules the whole process). A real drive runs on its own CPU and keeps counting, but
    this one cannot tell a starved tool from a starved simulator: on wall time its heartbeat consumer
    saw a gap the tool never made, and stopped a command that sent every beat. So a stretch of more
    than ``max_gap`` s between two readings counts as ``max_gap`` only. The simulator reads it often
    while it runs (:meth:`keep_time`, and every bus pump), so only a process that did not run makes
    such a gap; a heartbeat thread that alone stops sending still trips the consumer. ``max_gap``
    stays well below ``consumer_time_ms`` minus one heartbeat period (375 ms by default)."""

    def __init__(self, max_gap: float = 0.1, *, wall: Callable[[], float] = time.monotonic) -> None:
        if max_gap <= 0:
            raise ValueError(f"max_gap must be positive, not {max_gap}")
        self.max_gap = max_gap
        self.paused = 0.0  # s of wall time this clock stood still
        self._wall = wall
        self._last: float | None = None
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            wall = self._wall()
            if self._last is not None and wall - self._last > self.max_gap:
                self.paused += wall - self._last - self.max_gap
            self._last = wall
            return wall - self.paused

    def received_at(self, timestamp: float) -> float:
        return self.now() - (time.time() - timestamp)

    def keep_time(self, stop: threading.Event, every: float = 0.01) -> None:
        """Read the clock every ``every`` s until ``stop`` is set (a thread of the simulator): a
        gap then means the process did not run, not that no frame came."""
        while not stop.wait(every):
            self.now()
