"""Injectable time for the simulator: tests drive a ManualClock, `sherpa sim` a RealClock."""

from __future__ import annotations

import time
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
