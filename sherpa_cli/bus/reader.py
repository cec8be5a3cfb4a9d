"""Who reads a bus: the caller that waits for a reply, or a background thread while nobody waits.

With python-can's ``Notifier`` every reply is received on its thread and handed
to the waiting caller through a lock: two thread switches and cold caches per request. Here the
caller that waits for a reply reads the bus itself (leader/follower) and dispatches every frame
it reads to all listeners -- its own reply, and frames for other drives, heartbeats, EMCY, PDOs
-- in bus order. A background thread reads only while no caller waits (after ``idle_after``), or
when a leader leaves while other callers still wait (it hands them over).

:class:`CallerReadNotifier` has the part of ``can.Notifier``'s interface that canopen and this
tool use (``listeners``, ``add_listener``, ``remove_listener``, ``stop``, ``exception``), so
``PacedNetwork.connect`` installs it as ``Network.notifier`` -- canopen's documented attribute --
and nothing of python-can or canopen is patched. Listeners are ``can.Listener`` objects or
callables taking a ``can.Message``, as for ``can.Notifier``.

Rules that keep it correct:

- One reader at a time (``_read``, reentrant: a listener that itself waits for a reply on the
  same thread reads on). Frames are dispatched while the read lock is held, so listeners see
  them in bus order whichever thread read them.
- A waiter is done when its ``arrived`` lock has been released by a listener (the drive client's
  reply callback); the waiter then owns that lock again, exactly as with ``Lock.acquire(timeout)``.
- A follower (someone else reads) waits on its own ``arrived`` in slices of ``follow_slice``,
  then tries to lead; a leader that leaves with followers waiting wakes the background thread, so
  no waiter depends on its slice to be served.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Protocol

from sherpa_cli.errors import SherpaError

if TYPE_CHECKING:
    from typing import TypeAlias

    import can

    #: what a listener may be, as for ``can.Notifier``
    Recipient: TypeAlias = can.Listener | Callable[[can.Message], None]

log = logging.getLogger(__name__)


class _Bus(Protocol):
    def recv(self, timeout: float | None = None) -> can.Message | None: ...


class CallerReadNotifier:
    """A ``can.Notifier`` stand-in whose waiting callers read the bus themselves (see the module)."""

    def __init__(self, bus: _Bus, listeners: Iterable[Recipient], timeout: float = 0.02, *,
                 idle_after: float = 0.002, follow_slice: float = 0.001,
                 clock: Callable[[], float] = time.monotonic, background: bool = True,
                 lost: Callable[[BaseException], BaseException] | None = None) -> None:
        self.bus = bus
        #: what a caller raises when reading the bus fails on its thread (the bus is gone): the
        #: network's error naming the bus (bus/links.py); None: the adapter's own exception
        self.lost = lost
        self.listeners: list[Recipient] = list(listeners)
        #: the background thread's longest receive (it checks whether to stop this often), as can.Notifier's
        self.timeout = timeout
        #: seconds without a waiting caller before the background thread reads again: a caller that
        #: sends its next request within it finds the bus free and reads its reply itself
        self.idle_after = idle_after
        #: how long a follower waits on its own reply before it tries to lead
        self.follow_slice = follow_slice
        #: how often the parked background thread looks whether callers stopped waiting
        self.waiting_park = min(timeout, 0.005)
        self.exception: BaseException | None = None
        self._clock = clock
        self._read = threading.RLock()  # held by whoever is in bus.recv and dispatching what it read
        self._mutex = threading.Lock()  # guards the fields below
        self._cond = threading.Condition(self._mutex)  # the background thread parks on it
        self._waiters = 0
        self._handover = False  # a leader left while others waited: the background thread serves them
        self._idle_since = clock()
        self._stopped = False
        #: frames dispatched by a waiting caller vs by the background thread (the benchmark prints them)
        self.caller_reads = 0
        self.background_reads = 0
        self._thread: threading.Thread | None = None
        if background:
            self._thread = threading.Thread(target=self._background, name="sherpa-bus-reader", daemon=True)
            self._thread.start()

    # -- can.Notifier's interface ---------------------------------------------------------------

    def add_listener(self, listener: Recipient) -> None:
        self.listeners.append(listener)

    def remove_listener(self, listener: Recipient) -> None:
        self.listeners.remove(listener)

    @property
    def stopped(self) -> bool:
        return self._stopped

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the background thread (joined for at most ``timeout``) and the listeners."""
        with self._cond:
            already = self._stopped
            self._stopped = True
            self._cond.notify_all()
        thread = self._thread
        if thread is not None and timeout > 0 and thread is not threading.current_thread():
            thread.join(timeout)
        if already:
            return
        for listener in self.listeners:
            if hasattr(listener, "stop"):
                listener.stop()

    # -- the caller's side ----------------------------------------------------------------------

    def wait_for(self, arrived: threading.Lock, timeout: float) -> bool:
        """Wait until a listener releases ``arrived`` (then it is held again, and True) or ``timeout``
        passes (False), reading and dispatching the bus meanwhile whenever nobody else does."""
        if arrived.acquire(blocking=False):
            return True
        clock = self._clock
        deadline = clock() + timeout
        led = False
        with self._mutex:  # a plain lock: this runs on every round trip
            self._waiters += 1
        try:
            while True:
                remaining = deadline - clock()
                if remaining <= 0:
                    # a thread the host kept off the CPU past its deadline finds its answer waiting
                    # in the socket: read what is there before calling the drive silent
                    return arrived.acquire(blocking=False) or self._drain(arrived)
                if self._read.acquire(blocking=False):
                    led = True
                    try:
                        while True:
                            # at most one receive cycle per recv: a reply lock released from another
                            # thread (abort_pending) is seen within it even on a silent bus
                            msg = self._recv(min(remaining, self.timeout))
                            if msg is not None:
                                self.caller_reads += 1
                                self._dispatch(msg)
                            if arrived.acquire(blocking=False):
                                return True
                            remaining = deadline - clock()
                            if remaining <= 0:
                                break
                    finally:
                        self._read.release()
                elif arrived.acquire(timeout=min(remaining, self.follow_slice)):
                    return True
        finally:
            with self._mutex:
                self._waiters -= 1
                if not self._waiters:
                    self._handover = False
                    self._idle_since = clock()
                elif led and not self._handover:
                    # a leader leaves while others wait: the background thread serves them now
                    self._handover = True
                    self._cond.notify()

    def _drain(self, arrived: threading.Lock, limit: int = 64) -> bool:
        """Read and dispatch what the bus already holds (no wait), if nobody else reads; True once
        ``arrived`` was released."""
        if not self._read.acquire(blocking=False):
            return arrived.acquire(blocking=False)
        try:
            for _ in range(limit):
                msg = self._recv(0.0)
                if msg is None:
                    break
                self.caller_reads += 1
                self._dispatch(msg)
                if arrived.acquire(blocking=False):
                    return True
        finally:
            self._read.release()
        return arrived.acquire(blocking=False)

    # -- reading and dispatching ----------------------------------------------------------------

    def _recv(self, timeout: float) -> can.Message | None:
        try:
            return self.bus.recv(timeout)
        except SherpaError:
            # raised in this thread by the tool's own signal handler (the motion guard's SIGTERM stop)
            # while it waited in recv: the command's end, not the bus's
            raise
        except Exception as exc:  # the adapter went away: canopen's Network.check() raises it later
            self.exception = exc
            if self.lost is not None and threading.current_thread() is not self._thread:
                raise self.lost(exc) from exc  # a caller's read: one error naming the bus
            raise

    def _dispatch(self, msg: can.Message) -> None:
        for listener in list(self.listeners):
            try:
                listener(msg) if callable(listener) else listener.on_message_received(msg)
            except Exception:  # one listener's error must not stop the others or the reader (as can.Notifier)
                log.exception("bus listener %r failed", listener)

    # -- the background thread ------------------------------------------------------------------

    def _should_read(self, now: float) -> float:
        """0: read now; otherwise how long to park before checking again."""
        if self._handover and self._waiters:
            return 0.0
        if self._waiters:
            # nobody tells this thread when the last waiter leaves (that would cost every round trip
            # a wake-up): it looks again this often, so a listener's frame waits at most this long
            # plus idle_after once callers stop
            return self.waiting_park
        left = self._idle_since + self.idle_after - now
        return 0.0 if left <= 0 else left

    def _background(self) -> None:
        while True:
            with self._cond:
                while not self._stopped:
                    park = self._should_read(self._clock())
                    if park <= 0:
                        break
                    self._cond.wait(park)
                if self._stopped:
                    return
            if not self._read.acquire(timeout=self.timeout):
                continue
            try:
                try:
                    msg = self._recv(self.timeout)
                except Exception:  # noqa: BLE001 - kept in self.exception; canopen's Network.check() raises it
                    log.debug("bus reader stopped: %s", self.exception)
                    return
                if msg is not None:
                    self.background_reads += 1
                    self._dispatch(msg)
            finally:
                self._read.release()
