"""How a drive client reaches the bus: a two-method seam, a canopen adapter and a scripted fake.

The seam mirrors ``canopen.Network`` (``send_message`` / ``subscribe`` with callbacks
``(can_id, data, timestamp)``) so one Network per bus can carry SDO, NMT and the binary
interpreter at once. Nothing here imports canopen: ``sherpa --help`` must stay light.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from typing import Any, Literal, Protocol

Callback = Callable[[int, bytes, float], None]
Direction = Literal["tx", "rx"]
Step = tuple[Direction, int, bytes]


class Transport(Protocol):
    """Raw CAN frames in and out; callbacks may run on any thread (a real bus's receive thread)."""

    def send(self, can_id: int, data: bytes) -> None: ...

    # optional: ``wait(arrived, timeout) -> bool`` (see waiter())

    def subscribe(self, can_id: int, callback: Callback) -> None: ...


class NetworkTransport:
    """:class:`Transport` over a connected ``canopen.Network`` (or anything with its two methods)."""

    def __init__(self, network: Any) -> None:
        self.network = network
        #: how a caller waits for its reply on this network, resolved once (see :func:`waiter`)
        self.reply_waiter: Waiter = self._waiter()

    def send(self, can_id: int, data: bytes) -> None:
        self.network.send_message(can_id, bytes(data))

    def subscribe(self, can_id: int, callback: Callback) -> None:
        self.network.subscribe(can_id, callback)

    def wait(self, arrived: threading.Lock, timeout: float) -> bool:
        """Wait until a subscriber callback releases ``arrived`` (True, held again) or ``timeout``.

        A network with ``wait_for`` (bus/links.py PacedNetwork) lets the waiting caller read the bus
        itself (bus/reader.py); anything else waits on the lock while its own
        receive thread delivers."""
        return self.reply_waiter(arrived, timeout)

    def _waiter(self) -> Waiter:
        # the notifier's own wait_for when it has one: one call per round trip instead of three
        notifier_wait = getattr(getattr(self.network, "notifier", None), "wait_for", None)
        if callable(notifier_wait):
            return notifier_wait
        network_wait = getattr(self.network, "wait_for", None)
        if callable(network_wait):
            return network_wait
        return _acquire


Waiter = Callable[[threading.Lock, float], bool]


def _acquire(arrived: threading.Lock, timeout: float) -> bool:
    return arrived.acquire(timeout=timeout)


def waiter(transport: object) -> Waiter:
    """How a client waits for a reply on ``transport``: its ``wait`` (the caller may read the bus
    itself) or, for a transport without one (FakeTransport delivers inside ``send``), the lock.
    ``reply_waiter`` (NetworkTransport: the notifier's own ``wait_for``) skips a call per round trip."""
    wait = getattr(transport, "reply_waiter", None) or getattr(transport, "wait", None)
    return wait if callable(wait) else _acquire


def frame_text(direction: str, can_id: int, data: bytes) -> str:
    """``"tx 0x30A 41 43 00 00"``: the one spelling used in transcripts and mismatch messages."""
    return f"{direction} 0x{can_id:03X} {bytes(data).hex(' ').upper()}".rstrip()


def parse_transcript(text: str) -> list[Step]:
    """Steps from text lines ``tx 30A 41 43 00 00`` / ``rx 0x28A ...``; ``#`` starts a comment.

    Lets a transcript live in a golden file and be read by a technician next to a candump log.
    """
    steps: list[Step] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        if len(parts) < 2 or parts[0] not in ("tx", "rx"):
            raise ValueError(f"transcript line {number}: expected 'tx|rx COB-ID bytes...', got {raw!r}")
        try:
            can_id = int(parts[1], 16)
            data = bytes.fromhex("".join(parts[2:]))
        except ValueError:
            raise ValueError(f"transcript line {number}: bad COB-ID or bytes in {raw!r}") from None
        steps.append((parts[0], can_id, data))  # type: ignore[arg-type]
    return steps


def _as_step(step: tuple[str, int, bytes | str]) -> Step:
    direction, can_id, data = step
    if direction not in ("tx", "rx"):
        raise ValueError(f"transcript step direction must be 'tx' or 'rx', got {direction!r}")
    raw = bytes.fromhex(data) if isinstance(data, str) else bytes(data)
    return (direction, can_id, raw)  # type: ignore[return-value]


class FakeTransport:
    """A scripted conversation (habit 12): each send must be the next ``tx`` step, byte for byte.

    After a matching send, every ``rx`` step that follows is delivered to the subscribers
    synchronously, inside ``send``, exactly as a drive that answers instantly would. ``rx`` steps
    at the start of the script (or after the last ``tx``) wait for :meth:`pump`, which stands in
    for frames the drive sends on its own (EMCY, boot-up).
    """

    def __init__(self, script: Iterable[tuple[str, int, bytes | str]],
                 *, clock: Callable[[], float] | None = None) -> None:
        self.script: list[Step] = [_as_step(s) for s in script]
        self.sent: list[tuple[int, bytes]] = []
        self._pos = 0
        self._clock = clock
        self._subscribers: dict[int, list[Callback]] = {}
        # Clients may send from several threads; the script position must advance atomically.
        self._lock = threading.Lock()

    def subscribe(self, can_id: int, callback: Callback) -> None:
        callbacks = self._subscribers.setdefault(can_id, [])
        if callback not in callbacks:
            callbacks.append(callback)

    def send(self, can_id: int, data: bytes) -> None:
        data = bytes(data)
        got = frame_text("tx", can_id, data)
        with self._lock:
            self.sent.append((can_id, data))
            if self._pos >= len(self.script):
                raise AssertionError(f"unexpected {got}: the script has ended")
            want = frame_text(*self.script[self._pos])
            if want != got:
                raise AssertionError(f"transcript step {self._pos + 1}: expected {want}, got {got}")
            self._pos += 1
            replies = self._take_rx()
        self._deliver(replies)

    def pump(self) -> None:
        """Deliver the ``rx`` steps that are next in the script (frames nobody asked for)."""
        with self._lock:
            replies = self._take_rx()
        self._deliver(replies)

    def done(self) -> None:
        """Assert that the whole script was played."""
        left = self.script[self._pos:]
        if left:
            lines = "\n".join(f"  {frame_text(*s)}" for s in left)
            raise AssertionError(f"transcript not finished, {len(left)} step(s) left:\n{lines}")

    def _take_rx(self) -> list[Step]:
        replies: list[Step] = []
        while self._pos < len(self.script) and self.script[self._pos][0] == "rx":
            replies.append(self.script[self._pos])
            self._pos += 1
        return replies

    def _deliver(self, replies: list[Step]) -> None:
        # Outside the lock: a subscriber may legitimately send again from its callback.
        for _, can_id, data in replies:
            timestamp = self._clock() if self._clock else 0.0
            for callback in list(self._subscribers.get(can_id, ())):
                callback(can_id, data, timestamp)
