"""`sherpa bus watch`: the buses' state and their error frames, decoded, with what to check.

:func:`watch` runs until ``duration`` has passed on the injected clock (None: until Ctrl-C): every
``interval`` it reads each bus's link (bus/linkstate.py) and drains the error frames the session's
receive threads collected (bus/errwatch.py), and hands a :class:`WatchState` to ``on_update``. Tests
drive it with a fake clock and frames fed into the BusWatch; the CLI renders it live with rich.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.errframes import HINTS
from sherpa_cli.bus.errwatch import BusWatch, SeenError, watching
from sherpa_cli.bus.linkstate import LinkStatus, read_link
from sherpa_cli.errors import raise_if_signalled

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession

DEFAULT_INTERVAL = 0.5


@dataclass
class WatchState:
    """Everything seen so far: the last link reading per bus, every error frame, counts per kind."""

    buses: list[str]
    links: dict[str, LinkStatus] = field(default_factory=dict)
    errors: list[SeenError] = field(default_factory=list)
    counts: dict[str, Counter[str]] = field(default_factory=dict)
    new: list[SeenError] = field(default_factory=list)  # the error frames of the last update
    elapsed: float = 0.0
    max_kept: int = 1000  # error frames kept for the JSON (the counts go on)

    def add(self, seen: Sequence[SeenError]) -> None:
        self.new = list(seen)
        for e in seen:
            self.counts.setdefault(e.bus, Counter()).update(e.frame.kinds)
        self.errors.extend(seen)
        del self.errors[:-self.max_kept]

    def hints(self, bus: str) -> list[str]:
        """One hint per kind seen on ``bus``, most frequent kind first."""
        out: list[str] = []
        for kind, _n in self.counts.get(bus, Counter()).most_common():
            hint = HINTS.get(kind)
            if hint is not None and hint not in out:
                out.append(hint)
        return out

    def as_json(self) -> dict[str, Any]:
        return {"elapsed_s": round(self.elapsed, 3),
                "buses": [{**self.links[b].as_json(), "error_frames": dict(self.counts.get(b, Counter())),
                           "hints": self.hints(b)} for b in self.buses if b in self.links],
                "errors": [e.as_json() for e in self.errors]}


def watch(session: ArmSession, buses: Sequence[str], *, duration: float | None, interval: float = DEFAULT_INTERVAL,
          clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
          on_update: Callable[[WatchState], None] | None = None, bus_watch: BusWatch | None = None) -> WatchState:
    """Watch ``buses`` of an open session; ``bus_watch``: an existing collector (tests feed it), else
    one hooked into the session's receive threads for the time of the watch."""
    state = WatchState(list(buses))
    if bus_watch is not None:
        _loop(session, state, bus_watch, duration, interval, clock, sleep, on_update)
        return state
    with watching(session, buses) as w:
        _loop(session, state, w, duration, interval, clock, sleep, on_update)
    return state


def _loop(session: ArmSession, state: WatchState, w: BusWatch, duration: float | None, interval: float,
          clock: Callable[[], float], sleep: Callable[[float], None],
          on_update: Callable[[WatchState], None] | None) -> None:
    start = clock()
    while True:
        raise_if_signalled()  # a SIGTERM whose exception was lost (errors.py): no other ear for it
        now = clock()
        state.elapsed = now - start
        state.links = {b: read_link(session, b) for b in state.buses}
        state.add(w.drain())
        if on_update is not None:
            on_update(state)
        if duration is not None and state.elapsed >= duration:
            return
        wait = interval if duration is None else min(interval, max(0.0, duration - state.elapsed))
        sleep(wait)
