"""The speed a drive reports, estimated as a real drive does: from its encoder's whole counts.

    VX(t) = (counts(t) - counts(t - W)) / W          counts: what the encoder shows (PX), W: the window

A joint turning at v counts/s moves v W counts in a window, a whole number of them each time, so the
estimate steps between neighbouring multiples of 1 / W and a constant speed reads with a ripple of
about 1 / (W sqrt(12)) counts/s: more, relative to the speed, the slower the joint turns.
"""

from __future__ import annotations

import bisect
from collections import deque

TIME_EPS = 1e-9  # model steps land on sums of floats: a reading this close to the window's start is at it


class SpeedEstimate:
    def __init__(self, window_s: float) -> None:
        if not window_s > 0:
            raise ValueError("SpeedEstimate: the window must be > 0 s")
        self.window = window_s
        self._times: deque[float] = deque()
        self._counts: deque[int] = deque()

    def sample(self, t: float, counts: int) -> None:
        """The encoder's reading at ``t`` (after each model step; times ascending)."""
        self._times.append(t)
        self._counts.append(counts)
        # keep one sample at or before the window's start: the reading the window begins with
        while len(self._times) > 2 and self._times[1] <= t - self.window + TIME_EPS:
            self._times.popleft()
            self._counts.popleft()

    def reset(self, t: float, counts: int) -> None:
        """The motor switched off or the encoder's origin moved: the window starts afresh."""
        self._times.clear()
        self._counts.clear()
        self.sample(t, counts)

    def value(self, t: float, counts: int) -> float:
        """counts/s over the window that ends at ``t`` with the encoder at ``counts``."""
        if not self._times:
            return 0.0
        start = t - self.window + TIME_EPS
        i = bisect.bisect_right(list(self._times), start) - 1  # the reading held at the window's start
        if i < 0:
            return 0.0  # less than one window since the motor came on: no speed seen yet
        return (counts - self._counts[i]) / self.window
