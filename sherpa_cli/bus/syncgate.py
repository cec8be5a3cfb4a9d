"""One gate per bus for every SYNC this tool sends, so a synchronous start is atomic.

``motion.pair_start: sync_rpdo`` sends BG to each drive of a pair (a synchronous RPDO2, buffered
by each drive) and then one SYNC that both execute. A SYNC from another source of this tool -- the
recorder's SYNC thread of `log record`, `log step`, `diffdrive move --record` -- that falls between
the two BG frames starts the first motor one SYNC before the second (it did in 4 of 4 runs under
load). Every SYNC producer of the tool therefore sends through the bus's :class:`SyncGate`, and the
pair start holds it (:meth:`SyncGate.exclusive`) from the first BG to its own SYNC.

A producer that sends from a thread of the tool takes the gate's lock for each SYNC
(:meth:`SyncGate.send`). One the tool cannot lock -- the kernel's broadcast manager on SocketCAN
(python-can ``send_periodic``) -- registers itself (:meth:`SyncGate.register`) and is paused for
the critical section and restarted after it. The stepped simulator's SYNC source (sim/stepped.py)
sends from the command's own thread, inside its sleep, so it cannot fall between two frames the
same thread sends; it needs no gate (and the sim package may not import this one).

The gate is keyed by the python-can bus object (what both the recorder's SYNC source and the
canopen Network send on), held weakly: a closed session's gate goes with its bus.
"""

from __future__ import annotations

import contextlib
import threading
import weakref
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    import can


class Pausable(Protocol):
    """A SYNC producer the gate cannot lock (a kernel periodic task): stopped and restarted."""

    def pause(self) -> None: ...

    def resume(self) -> None: ...


class SyncGate:
    """The lock every SYNC of this tool on one bus is sent under, and the producers it pauses."""

    def __init__(self) -> None:
        # reentrant: the pair start's own SYNC goes out through send() while it holds the gate
        self.lock = threading.RLock()
        self._pausable: list[Pausable] = []
        self._registry_lock = threading.Lock()

    def send(self, send: Callable[[], None]) -> None:
        """Send one SYNC (``send()``) under the gate: never between the frames of a critical section."""
        with self.lock:
            send()

    def register(self, producer: Pausable) -> Callable[[], None]:
        """Register a producer :meth:`exclusive` must pause; returns its unregistration."""
        with self._registry_lock:
            self._pausable.append(producer)

        def unregister() -> None:
            with self._registry_lock, contextlib.suppress(ValueError):
                self._pausable.remove(producer)
        return unregister

    @contextlib.contextmanager
    def exclusive(self) -> Iterator[None]:
        """No SYNC of this tool but the holder's own goes out on the bus until the block ends."""
        with self.lock:
            with self._registry_lock:
                paused = list(self._pausable)
            stopped: list[Pausable] = []
            try:
                for p in paused:
                    p.pause()
                    stopped.append(p)
                yield
            finally:
                for p in stopped:
                    with contextlib.suppress(Exception):  # a producer that cannot restart: its recording shows the gap
                        p.resume()


_gates: weakref.WeakKeyDictionary[object, SyncGate] = weakref.WeakKeyDictionary()
_gates_lock = threading.Lock()


def gate(bus: can.BusABC | object) -> SyncGate:
    """The gate of the python-can bus ``bus`` (one per bus object, made on first use)."""
    with _gates_lock:
        g = _gates.get(bus)
        if g is None:
            g = _gates[bus] = SyncGate()
        return g
