"""A busy computer is not a silent drive: a waiting thread the host kept off the CPU past its
deadline reads what is already in the socket before it calls the drive silent (bus/reader.py),
gives a late wait its own length once more, and a timeout that still comes says the computer was
too busy (elmo/client.py). Time is a fake clock the fake bus advances: no test depends on load."""

from __future__ import annotations

import threading

import can

from sherpa_cli.bus.reader import CallerReadNotifier
from sherpa_cli.elmo.client import DriveClient
from sherpa_cli.errors import DriveTimeoutError


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class StarvedBus:
    """The first receive comes back ``stall`` s later than asked (the host ran something else) and
    empty, while the reply reached the socket meanwhile; later receives hand out what is queued."""

    def __init__(self, clock: Clock, stall: float, reply: can.Message | None) -> None:
        self.clock, self.stall, self.reply = clock, stall, reply
        self.queue: list[can.Message] = []
        self.calls: list[float] = []

    def recv(self, timeout: float | None = None) -> can.Message | None:
        self.calls.append(0.0 if timeout is None else timeout)
        if len(self.calls) == 1:
            self.clock.t += (timeout or 0.0) + self.stall
            if self.reply is not None:
                self.queue.append(self.reply)
            return None
        if self.queue:
            return self.queue.pop(0)
        self.clock.t += timeout or 0.0
        return None


def _waiter(bus: StarvedBus, clock: Clock) -> tuple[CallerReadNotifier, threading.Lock, list[can.Message]]:
    got: list[can.Message] = []
    arrived = threading.Lock()
    arrived.acquire()

    def listener(msg: can.Message) -> None:
        got.append(msg)
        arrived.release()

    return CallerReadNotifier(bus, [listener], clock=clock, background=False), arrived, got


def test_a_starved_waiter_reads_the_reply_already_in_the_socket_instead_of_timing_out():
    clock = Clock()
    reply = can.Message(arbitration_id=0x28A, data=b"PX\x00\x00\x01\x00\x00\x00", is_extended_id=False)
    bus = StarvedBus(clock, stall=0.3, reply=reply)
    notifier, arrived, got = _waiter(bus, clock)
    assert notifier.wait_for(arrived, 0.1) is True
    assert got == [reply]
    assert bus.calls[1] == 0.0  # read without waiting: it was there


class LateTransport:
    """A host that keeps the waiting thread ``late`` s past each wait; the drive answers on the
    ``answer_on`` wait (0: never). Every wait and every frame sent is kept."""

    def __init__(self, clock: Clock, late: float, answer_on: int = 0) -> None:
        self.clock, self.late, self.answer_on = clock, late, answer_on
        self.waits: list[float] = []
        self.sent = 0
        self.reply = None

    def send(self, can_id: int, data: bytes) -> None:
        self.sent += 1

    def subscribe(self, can_id: int, callback: object) -> None:
        if can_id == 0x28A:
            self.reply = callback

    def wait(self, arrived: threading.Lock, timeout: float) -> bool:
        self.waits.append(timeout)
        self.clock.t += timeout + self.late
        if len(self.waits) == self.answer_on:
            self.reply(0x28A, b"PX\x00\x00\x07\x00\x00\x00", self.clock.t)
            return arrived.acquire(blocking=False)
        return False


def test_a_late_wait_gets_its_lateness_once_more_before_the_request_is_sent_again():
    """The answer came through a receive thread as late as the waiting thread: found in the wait's
    second chance (its 80 ms once more), with no second request on the bus."""
    clock = Clock()
    transport = LateTransport(clock, 0.08, answer_on=2)
    client = DriveClient(transport, 10, name="shoulder_1a", timeout=0.1, retries=1, clock=clock)
    assert client.get("PX") == 7
    assert transport.sent == 1 and [round(w, 3) for w in transport.waits] == [0.1, 0.08]


def test_a_timeout_on_a_busy_host_says_the_computer_was_too_busy_not_only_the_drive_silent():
    clock = Clock()
    client = DriveClient(LateTransport(clock, 0.08), 10, name="shoulder_1a", timeout=0.1, retries=1, clock=clock)
    try:
        client.get("PX")
    except DriveTimeoutError as exc:
        text, hint = str(exc), exc.hint
    else:
        raise AssertionError("no timeout")
    assert text == ("shoulder_1a (node 10): no answer to PX within 0.1 s (2 attempts); this computer was too "
                    "busy: the tool's own thread came back 80 ms late while it waited, so the drive may well be fine")
    assert hint == "close what loads this computer and try again"
    quiet = DriveClient(LateTransport(clock, 0.0), 10, name="shoulder_1a", timeout=0.1, retries=1, clock=clock)
    try:
        quiet.get("PX")
    except DriveTimeoutError as exc:
        assert "too busy" not in str(exc)
