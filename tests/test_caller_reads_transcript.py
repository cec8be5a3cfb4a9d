"""Byte-exact transcripts of the caller-read path (bus/reader.py): a DriveClient
waiting for its reply reads the bus itself and dispatches every other frame it reads in bus order.

The bus is scripted: each ``send`` must be the next ``tx`` step byte for byte; ``recv`` returns the
``rx`` steps that follow a matched ``tx``. With nothing to return, ``recv`` moves an injected clock
on by its timeout (single-caller tests: no wall time) or blocks on a condition (two callers).
"""

from __future__ import annotations

import threading

import can
import pytest

from sherpa_cli.bus.links import _paced_network_class
from sherpa_cli.bus.reader import CallerReadNotifier
from sherpa_cli.elmo.client import DriveClient
from sherpa_cli.elmo.transport import NetworkTransport, frame_text
from sherpa_cli.errors import DriveTimeoutError


def _reply(letters: str, value: int) -> bytes:
    return letters.encode() + b"\x00\x00" + value.to_bytes(4, "little", signed=True)


class ScriptedBus:
    """A python-can bus playing a script; ``log`` is what went over it, in order."""

    channel_info = "scripted"

    def __init__(self, script: list[tuple[str, int, bytes]], now: list[float] | None = None) -> None:
        # now None: a real bus for a background reader (recv blocks until the script has a frame)
        self.script, self.pos, self.now = script, 0, now
        self.log: list[str] = []
        self.cond = threading.Condition()
        self.mismatch: list[str] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        with self.cond:
            got = frame_text("tx", msg.arbitration_id, bytes(msg.data))
            want = frame_text(*self.script[self.pos]) if self.pos < len(self.script) else "(script ended)"
            if got != want:
                self.mismatch.append(f"step {self.pos + 1}: expected {want}, got {got}")
            assert got == want, self.mismatch[-1]
            self.pos += 1
            self.log.append(got)
            self.cond.notify_all()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        with self.cond:
            if self.now is None and not self._rx_next():
                self.cond.wait(timeout)
            if self._rx_next():
                _, can_id, data = self.script[self.pos]
                self.pos += 1
                self.log.append(frame_text("rx", can_id, data))
                return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)
            if self.now is not None:
                self.now[0] += timeout or 0.0  # a silent bus: the receive waits its whole timeout
            return None

    def _rx_next(self) -> bool:
        return self.pos < len(self.script) and self.script[self.pos][0] == "rx"

    def fileno(self) -> int:
        raise NotImplementedError

    def shutdown(self) -> None:
        pass


def _network(bus, now: list[float], *, background: bool = False):
    net = _paced_network_class()(bus)  # unpaced: the transcript is about who reads, not when
    net.notifier = CallerReadNotifier(bus, net.listeners, 0.02, clock=lambda: now[0], background=background)
    return net


def _dispatch_log(notifier: CallerReadNotifier) -> list[tuple[str, str]]:
    seen: list[tuple[str, str]] = []
    notifier.add_listener(lambda msg: seen.append((threading.current_thread().name,
                                                   frame_text("rx", msg.arbitration_id, bytes(msg.data)))))
    return seen


def test_frames_for_another_drive_arriving_while_a_caller_waits_reach_their_listeners_in_bus_order():
    now = [0.0]
    bus = ScriptedBus([
        ("tx", 0x30A, b"PX\x00\x00"),
        ("rx", 0x28B, _reply("PX", 7)),  # drive 11's reply to someone else's request
        ("rx", 0x70B, b"\x05"),  # drive 11's heartbeat
        ("rx", 0x18A, bytes(8)),  # drive 10's TPDO1
        ("rx", 0x28A, _reply("PX", 1234)),
    ], now)
    net = _network(bus, now)
    dispatched = _dispatch_log(net.notifier)
    client = DriveClient(NetworkTransport(net), 10, name="a", timeout=0.1, retries=0)
    other: list[bytes] = []
    for can_id in (0x28B, 0x70B, 0x18A):
        net.subscribe(can_id, lambda _id, data, _ts: other.append(bytes(data)))

    assert client.get("PX") == 1234
    assert bus.log == [
        "tx 0x30A 50 58 00 00",
        "rx 0x28B 50 58 00 00 07 00 00 00",
        "rx 0x70B 05",
        "rx 0x18A 00 00 00 00 00 00 00 00",
        "rx 0x28A 50 58 00 00 D2 04 00 00",
    ]
    # every frame was read and dispatched by the caller itself, in bus order
    caller = threading.current_thread().name
    assert dispatched == [(caller, line) for line in bus.log if line.startswith("rx")]
    assert other == [_reply("PX", 7), b"\x05", bytes(8)]
    assert (net.notifier.caller_reads, net.notifier.background_reads) == (4, 0)


def test_a_reply_arriving_after_the_timeout_is_not_taken_for_the_next_answer():
    now = [0.0]
    bus = ScriptedBus([
        ("tx", 0x30A, b"PX\x00\x00"),  # no answer within the 0.1 s timeout
        ("tx", 0x30A, b"VX\x00\x00"),
        ("rx", 0x28A, _reply("PX", 5)),  # the late answer to PX
        ("rx", 0x28A, _reply("VX", -3)),
    ], now)
    net = _network(bus, now)
    client = DriveClient(NetworkTransport(net), 10, name="a", timeout=0.1, retries=0)

    with pytest.raises(DriveTimeoutError, match=r"a \(node 10\): no answer to PX within 0.1 s"):
        client.get("PX")
    assert now[0] == pytest.approx(0.1)  # the caller read the silent bus until its deadline, no longer
    assert client.get("VX") == -3
    assert bus.log == [
        "tx 0x30A 50 58 00 00",
        "tx 0x30A 56 58 00 00",
        "rx 0x28A 50 58 00 00 05 00 00 00",
        "rx 0x28A 56 58 00 00 FD FF FF FF",
    ]
    assert bus.pos == len(bus.script)


def test_a_retry_after_a_timeout_sends_the_request_again_and_reads_its_answer():
    now = [0.0]
    bus = ScriptedBus([
        ("tx", 0x30A, b"PX\x00\x00"),
        ("tx", 0x30A, b"PX\x00\x00"),
        ("rx", 0x28A, _reply("PX", 9)),
    ], now)
    net = _network(bus, now)
    client = DriveClient(NetworkTransport(net), 10, name="a", timeout=0.1, retries=1)
    assert client.get("PX") == 9
    assert bus.log[-1] == "rx 0x28A 50 58 00 00 09 00 00 00" and now[0] == pytest.approx(0.1)


class ResponderBus:
    """Answers every interpreter query at once with ``value`` + how many it answered for that drive;
    ``recv`` blocks (a real wait) until a frame is there. ``hold`` delays one drive's answers until
    another drive's request went out (once), so two callers wait at the same time."""

    channel_info = "responder"

    def __init__(self, hold: dict[int, int] | None = None) -> None:
        self.cond = threading.Condition()
        self.queue: list[can.Message] = []
        self.log: list[str] = []
        self.count: dict[int, int] = {}
        self.hold = dict(hold or {})  # node -> node whose request releases its answers
        self.held: dict[int, list[can.Message]] = {}

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        node = msg.arbitration_id - 0x300
        with self.cond:
            self.log.append(frame_text("tx", msg.arbitration_id, bytes(msg.data)))
            self.count[node] = self.count.get(node, 0) + 1
            reply = can.Message(arbitration_id=0x280 + node, is_extended_id=False,
                                data=bytes(msg.data[:4]) + (node * 1000 + self.count[node]).to_bytes(4, "little"))
            waiting_for = self.hold.pop(node, None)  # once: the first answer only
            if waiting_for is not None:
                self.held.setdefault(waiting_for, []).append(reply)
            else:
                self.queue.append(reply)
            self.queue.extend(self.held.pop(node, []))  # this request releases answers held for it
            self.cond.notify_all()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        with self.cond:
            if not self.queue:
                self.cond.wait(timeout)
            if not self.queue:
                return None
            msg = self.queue.pop(0)
            self.log.append(frame_text("rx", msg.arbitration_id, bytes(msg.data)))
            return msg

    def fileno(self) -> int:
        raise NotImplementedError  # as python-can's buses without one: can.Notifier then reads on a thread

    def shutdown(self) -> None:
        pass


def test_two_callers_on_one_bus_each_get_their_own_answers():
    bus = ResponderBus(hold={10: 11})  # drive 10's answers come only once drive 11 was asked
    net = _paced_network_class()(bus)
    net.connect()  # caller_reads: the CallerReadNotifier with its background thread
    assert isinstance(net.notifier, CallerReadNotifier)
    dispatched = _dispatch_log(net.notifier)
    a = DriveClient(NetworkTransport(net), 10, name="a", timeout=5.0, retries=0)
    b = DriveClient(NetworkTransport(net), 11, name="b", timeout=5.0, retries=0)
    got: dict[str, list[int | float]] = {"a": [], "b": []}
    errors: list[BaseException] = []

    def run(client: DriveClient, name: str, n: int) -> None:
        try:
            for _ in range(n):
                got[name].append(client.get("PX"))
        except BaseException as exc:  # noqa: BLE001 - handed to the test thread
            errors.append(exc)

    t = threading.Thread(target=run, args=(a, "a", 1), name="caller-a")
    t.start()
    t.join(0.05)  # a is waiting (its answer is held until b asks)
    got["b"].append(b.get("PX"))
    t.join(5.0)
    t2 = threading.Thread(target=run, args=(a, "a", 20), name="caller-a2")
    t2.start()
    for _ in range(20):
        got["b"].append(b.get("PX"))
    t2.join(10.0)
    net.notifier.stop(1.0)
    assert not errors and not t.is_alive() and not t2.is_alive()
    assert got["a"] == [10001 + i for i in range(21)]
    assert got["b"] == [11001 + i for i in range(21)]
    # every answer was dispatched exactly once, in the order the bus gave it
    assert [line for _, line in dispatched] == [line for line in bus.log if line.startswith("rx")]
    assert sorted(line for line in bus.log if line.startswith("tx")) == \
        ["tx 0x30A 50 58 00 00"] * 21 + ["tx 0x30B 50 58 00 00"] * 21
    # callers read for themselves (the background thread may have served a handed-over follower)
    assert net.notifier.caller_reads > 0
    assert net.notifier.caller_reads + net.notifier.background_reads == 42


def test_frames_keep_flowing_to_listeners_while_no_caller_waits():
    bus = ResponderBus()
    net = _paced_network_class()(bus)
    net.connect()
    heard = threading.Event()
    net.subscribe(0x70A, lambda *_: heard.set())
    with bus.cond:
        bus.queue.append(can.Message(arbitration_id=0x70A, data=b"\x05", is_extended_id=False))
        bus.cond.notify_all()
    try:
        assert heard.wait(5.0), "the background reader did not deliver a heartbeat while nobody waited"
        assert net.notifier.background_reads == 1 and net.notifier.caller_reads == 0
    finally:
        net.notifier.stop(1.0)


def test_caller_reads_off_keeps_python_cans_notifier():
    bus = ResponderBus()
    net = _paced_network_class()(bus)
    net.caller_reads = False
    net.connect()
    try:
        assert isinstance(net.notifier, can.Notifier)
        client = DriveClient(NetworkTransport(net), 10, name="a", timeout=5.0, retries=0)
        assert client.get("PX") == 10001
    finally:
        net.notifier.stop(1.0)


# -- the expedited-SDO fast path (bus/sdo.py) on the same mechanism -------------------------------

def _sdo(bus, now, timeout: float = 0.3):
    from sherpa_cli.bus.sdo import DriveSdo

    net = _network(bus, now)
    return DriveSdo(net, 10, label="a (node 10)", timeout=timeout), net


def test_an_expedited_upload_is_one_request_and_its_answer_read_by_the_caller():
    now = [0.0]
    bus = ScriptedBus([
        ("tx", 0x60A, bytes.fromhex("40 18 10 01 00 00 00 00")),
        ("rx", 0x70B, b"\x05"),  # another drive's heartbeat first
        ("rx", 0x58A, bytes.fromhex("43 18 10 01 9A 00 00 00")),
        ("tx", 0x60A, bytes.fromhex("40 17 10 00 00 00 00 00")),
        ("rx", 0x58A, bytes.fromhex("4B 17 10 00 E8 03 00 00")),  # 2 bytes announced
    ], now)
    sdo, net = _sdo(bus, now)
    assert sdo.upload(0x1018, 1) == bytes.fromhex("9A 00 00 00")
    assert sdo.upload(0x1017, 0) == bytes.fromhex("E8 03")
    assert bus.pos == len(bus.script) and now[0] == 0.0
    assert (net.notifier.caller_reads, net.notifier.background_reads) == (3, 0)


def test_an_unanswered_upload_times_out_and_aborts_as_canopen_does():
    from sherpa_cli.errors import SdoError

    now = [0.0]
    bus = ScriptedBus([
        ("tx", 0x60A, bytes.fromhex("40 00 10 00 00 00 00 00")),
        ("tx", 0x60A, bytes.fromhex("80 00 10 00 00 00 04 05")),  # abort 0x05040000: SDO protocol timed out
        ("tx", 0x60A, bytes.fromhex("40 18 10 01 00 00 00 00")),
        ("rx", 0x58A, bytes.fromhex("43 00 10 00 92 01 02 00")),  # the late answer to 0x1000: not ours, ignored
        ("rx", 0x58A, bytes.fromhex("43 18 10 01 9A 00 00 00")),  # 0x1018:1's own
        ("tx", 0x60A, bytes.fromhex("40 18 10 04 00 00 00 00")),
        ("rx", 0x58A, bytes.fromhex("80 18 10 04 00 00 02 06")),
    ], now)
    sdo, _ = _sdo(bus, now)
    with pytest.raises(SdoError) as info:
        sdo.upload(0x1000, 0)
    assert str(info.value) == "a (node 10): no answer to the SDO upload of 0x1000 within 0.3 s"
    assert info.value.reason == "timeout" and now[0] == pytest.approx(0.3)
    # another transfer's late answer is never taken for this one's (it was "Node returned a value for
    # 0x1000:00 instead"): the upload waits for its own
    assert sdo.upload(0x1018, 1) == bytes.fromhex("9A 00 00 00")
    with pytest.raises(SdoError) as info:
        sdo.upload(0x1018, 4, name="serial number")
    assert (info.value.reason, info.value.abort_code) == ("abort", 0x06020000)
    assert str(info.value) == ("a (node 10): SDO upload of 0x1018:4 (serial number) aborted with 0x06020000 "
                               "(object does not exist in the object dictionary)")
    assert bus.pos == len(bus.script)


def test_a_segmented_answer_hands_the_object_to_canopen_from_then_on():
    from sherpa_cli.bus.sdo import DriveSdo

    init = bytes.fromhex("40 00 20 01 00 00 00 00")
    started = bytes.fromhex("41 00 20 01 07 00 00 00")  # segmented, 7 bytes
    bus = ScriptedBus([
        ("tx", 0x60A, init), ("rx", 0x58A, started),  # the fast path learns: segmented
        ("tx", 0x60A, init), ("rx", 0x58A, started),  # canopen's own transfer
        ("tx", 0x60A, bytes.fromhex("60 00 00 00 00 00 00 00")), ("rx", 0x58A, b"\x01Whistle"),
        ("tx", 0x60A, init), ("rx", 0x58A, started),  # next time straight to canopen
        ("tx", 0x60A, bytes.fromhex("60 00 00 00 00 00 00 00")), ("rx", 0x58A, b"\x01Whistle"),
        ("tx", 0x60A, bytes.fromhex("40 08 10 00 00 00 00 00")),  # the device name: canopen at once
        ("rx", 0x58A, bytes.fromhex("41 08 10 00 02 00 00 00")),
        ("tx", 0x60A, bytes.fromhex("60 00 00 00 00 00 00 00")), ("rx", 0x58A, bytes.fromhex("0B 4F 4B 00 00 00 00 00")),
    ])
    net = _paced_network_class()(bus)
    net.connect()  # canopen's client waits on its queue: the background reader feeds it
    try:
        sdo = DriveSdo(net, 10, label="a (node 10)", timeout=5.0)
        assert sdo.upload(0x2000, 1) == b"Whistle"
        assert sdo.upload(0x2000, 1) == b"Whistle"
        assert sdo.upload(0x1008, 0) == b"OK"
        assert bus.pos == len(bus.script) and not bus.mismatch
        sdo.close()
        assert not net.subscribers.get(0x58A)  # neither the fast path nor canopen still listens
    finally:
        net.notifier.stop(1.0)
