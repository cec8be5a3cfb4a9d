"""Listen to the error frames (and count the traffic) of a session's buses while something else runs.

:func:`watching` hooks one listener per bus into the receive thread each bus already has (canopen's
Network keeps a python-can ``Notifier``; ``add_listener`` / ``remove_listener`` are its documented
calls), so nothing competes with the drive clients for frames. :meth:`BusWatch.drain` hands over
the decoded error frames received since the last call (bus/errframes.py); :meth:`BusWatch.traffic`
the frames and data bytes each bus carried to this host, for a load estimate. `sherpa bus watch`
shows them live; the motion guard's bus watch (motion/bus_watch.py) is told of each error frame as it
arrives (``on_error``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.errframes import ErrorFrame, decode_error_frame

if TYPE_CHECKING:
    import can

    from sherpa_cli.bus.session import ArmSession


@dataclass(frozen=True)
class SeenError:
    """One error frame of one bus: when (the frame's receive timestamp, s) and what it says."""

    bus: str
    timestamp: float
    frame: ErrorFrame

    def as_json(self) -> dict[str, Any]:
        return {"bus": self.bus, **self.frame.as_json()}


class BusWatch:
    """What the listeners of :func:`watching` collected; thread-safe. ``on_error``: also called with
    each error frame as it arrives, on the receive thread (the motion guard's bus watch acts at once)."""

    def __init__(self, on_error: Callable[[SeenError], None] | None = None) -> None:
        self._on_error = on_error
        self._lock = threading.Lock()
        self._errors: list[SeenError] = []
        self._frames: dict[str, int] = {}
        self._bytes: dict[str, int] = {}

    def listener(self, bus: str) -> Callable[[can.Message], None]:
        self._frames.setdefault(bus, 0)
        self._bytes.setdefault(bus, 0)

        def on_message(msg: can.Message) -> None:
            self.feed(bus, msg.arbitration_id, bytes(msg.data), is_error=bool(msg.is_error_frame),
                      timestamp=float(msg.timestamp or 0.0))

        return on_message

    def feed(self, bus: str, can_id: int, data: bytes, *, is_error: bool, timestamp: float = 0.0) -> None:
        """One received frame (what a listener does; tests inject frames here)."""
        seen = SeenError(bus, timestamp, decode_error_frame(can_id, data)) if is_error else None
        with self._lock:
            if seen is not None:
                self._errors.append(seen)
            else:
                self._frames[bus] = self._frames.get(bus, 0) + 1
                self._bytes[bus] = self._bytes.get(bus, 0) + len(data)
        if seen is not None and self._on_error is not None:
            self._on_error(seen)

    def drain(self) -> list[SeenError]:
        with self._lock:
            out, self._errors = self._errors, []
        return out

    def traffic(self, bus: str) -> tuple[int, int]:
        """(frames, data bytes) received on ``bus`` so far (error frames not counted)."""
        with self._lock:
            return self._frames.get(bus, 0), self._bytes.get(bus, 0)


@contextmanager
def watching(session: ArmSession, buses: Iterable[str] | None = None,
             on_error: Callable[[SeenError], None] | None = None) -> Iterator[BusWatch]:
    """A :class:`BusWatch` fed by the receive thread of each named bus of an open session (default: all);
    ``on_error``: see :class:`BusWatch`."""
    watch = BusWatch(on_error)
    hooked: list[tuple[Any, Any]] = []
    try:
        for name in buses if buses is not None else list(session.links):
            notifier = getattr(session.links[name].network, "notifier", None)
            if notifier is None:
                continue
            listener = watch.listener(name)
            notifier.add_listener(listener)
            hooked.append((notifier, listener))
        yield watch
    finally:
        for notifier, listener in hooked:
            with suppress(ValueError):  # already gone with its bus
                notifier.remove_listener(listener)
