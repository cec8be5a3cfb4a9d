"""The lean virtual bus keeps python-can's virtual delivery rules; the paced network's send path.

LeanVirtualBus replaces python-can's deep copy and queue.Queue for speed (benchmark
``roundtrip``); these tests pin what it must still do exactly as VirtualBus does.
"""

from __future__ import annotations

import errno
import time
import uuid

import can
import pytest
from can.interfaces.virtual import VirtualBus, channels

from sherpa_cli.bus.links import _paced_network_class
from sherpa_cli.bus.virtual import LeanVirtualBus, open_can_bus
from sherpa_cli.errors import CommunicationError


@pytest.fixture
def channel():
    name = f"lean-test-{uuid.uuid4().hex[:8]}"
    opened: list[can.BusABC] = []

    def bus(cls=LeanVirtualBus, **kwargs):
        b = cls(name, **kwargs)
        opened.append(b)
        return b

    yield bus
    for b in opened:
        b.shutdown()
    assert name not in channels, "every queue left the channel on shutdown"


def msg(can_id=0x30A, data=b"PX\x00\x00", **kwargs) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False, **kwargs)


@pytest.mark.parametrize(("sender_cls", "receiver_cls"), [(LeanVirtualBus, VirtualBus), (VirtualBus, LeanVirtualBus),
                                                          (LeanVirtualBus, LeanVirtualBus)])
def test_frames_cross_between_lean_and_plain_buses(channel, sender_cls, receiver_cls):
    tx, rx = channel(sender_cls), channel(receiver_cls)
    before = time.time()
    tx.send(msg(timestamp=1.0))
    got = rx.recv(timeout=1)
    assert (got.arbitration_id, bytes(got.data), got.dlc, got.is_extended_id) == (0x30A, b"PX\x00\x00", 4, False)
    assert got.is_rx and got.channel == tx.channel_id
    assert got.timestamp >= before, "stamped with the send time, not the message's own"
    assert rx.recv(timeout=0.01) is None


def test_every_receiver_gets_its_own_copy(channel):
    tx, a, b = channel(), channel(), channel(VirtualBus)
    original = msg()
    tx.send(original)
    got_a, got_b = a.recv(timeout=1), b.recv(timeout=1)
    got_a.data[0] = 0
    assert bytes(got_b.data) == b"PX\x00\x00" and bytes(original.data) == b"PX\x00\x00"
    assert got_a is not original and got_b is not original
    assert tx.recv(timeout=0.01) is None, "no echo without receive_own_messages"


def test_order_is_kept(channel):
    tx, rx = channel(), channel()
    for n in range(200):
        tx.send(msg(data=n.to_bytes(2, "little")))
    assert [int.from_bytes(rx.recv(timeout=1).data, "little") for _ in range(200)] == list(range(200))


def test_own_messages_and_preserved_timestamps(channel):
    tx = channel(receive_own_messages=True, preserve_timestamps=True)
    rx = channel()
    tx.send(msg(timestamp=12.5))
    own, other = tx.recv(timeout=1), rx.recv(timeout=1)
    assert not own.is_rx and other.is_rx
    assert own.timestamp == other.timestamp == 12.5


def test_remote_and_error_flags_survive(channel):
    tx, rx = channel(), channel()
    tx.send(can.Message(arbitration_id=0x70A, is_remote_frame=True, dlc=1, is_extended_id=False))
    got = rx.recv(timeout=1)
    assert got.is_remote_frame and got.dlc == 1 and bytes(got.data) == b""


def test_a_full_bounded_queue_fails_the_send_like_virtual_bus(channel):
    tx, rx = channel(), channel(rx_queue_size=1)
    tx.send(msg(), timeout=0.01)
    with pytest.raises(can.CanOperationError, match="one or more recipients"):
        tx.send(msg(), timeout=0.01)
    assert rx.recv(timeout=1) is not None


def test_a_closed_bus_refuses_to_send(channel):
    tx = channel()
    tx.shutdown()
    with pytest.raises(can.CanOperationError):
        tx.send(msg())


def test_open_can_bus_gives_the_lean_bus_for_virtual_only(channel):
    name = f"lean-open-{uuid.uuid4().hex[:8]}"
    lean = open_can_bus(interface="virtual", channel=name)
    plain = open_can_bus(interface="virtual", channel=name, ignore_config=True)
    try:
        assert type(lean) is LeanVirtualBus
        assert type(plain) is VirtualBus
        lean.send(msg())
        assert plain.recv(timeout=1).arbitration_id == 0x30A
    finally:
        lean.shutdown()
        plain.shutdown()


# -- PacedNetwork.send_message ---------------------------------------------------------------------

class _FlakyBus:
    """A bus whose first ``failures`` sends raise ``CanOperationError(error_code=code)``."""

    def __init__(self, failures: int, code: int = errno.ENOBUFS) -> None:
        self.failures, self.code, self.sent = failures, code, []

    def send(self, message, timeout=None):
        if self.failures:
            self.failures -= 1
            raise can.CanOperationError("No buffer space available", error_code=self.code)
        self.sent.append(message)


def _network(bus):
    net = _paced_network_class()(bus)
    net.sleeps = []
    net.sleep = net.sleeps.append
    net.clock = lambda: pytest.fail("an unpaced network must not read the clock")
    return net


def test_a_full_socket_buffer_is_retried_with_growing_waits():
    bus = _FlakyBus(failures=3)
    net = _network(bus)
    net.send_message(0x30A, b"PX\x00\x00")
    assert len(bus.sent) == 1 and net.sleeps == [0.001, 0.002, 0.003]


def test_a_buffer_that_stays_full_gives_up_after_send_attempts():
    bus = _FlakyBus(failures=99)
    net = _network(bus)
    with pytest.raises(CommunicationError, match="sending 0x30A failed"):
        net.send_message(0x30A, b"PX\x00\x00")
    assert bus.failures == 99 - net.send_attempts and net.sleeps == [0.001, 0.002, 0.003, 0.004]


def test_other_send_errors_are_not_retried():
    bus = _FlakyBus(failures=1, code=errno.ENETDOWN)
    net = _network(bus)
    with pytest.raises(CommunicationError, match="sending 0x30A failed"):
        net.send_message(0x30A, b"PX\x00\x00")
    assert net.sleeps == [] and bus.failures == 0
