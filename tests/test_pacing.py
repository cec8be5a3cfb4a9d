"""Per-drive pacing of bus/links.py PacedNetwork (elmo-protocol.md §4.2): frames to
one drive keep the bus's send gap unless that drive answered the previous one; any two frames on
the bus keep the floor; `protocol.pacing: per-bus` keeps today's gap between any two frames.
Time is injected: a clock that only the network's own sleeps move."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from sherpa_cli.bus.links import _paced_network_class, answering, destination

GAP, FLOOR = 0.001, 0.00014


class _Bus:
    def __init__(self, now: list[float]) -> None:
        self.now, self.sent = now, []

    def send(self, message, timeout=None):
        self.sent.append((round(self.now[0] * 1e6), message.arbitration_id, bytes(message.data)))


def _network(pacing: str = "per-drive"):
    now = [0.0]
    bus = _Bus(now)
    net = _paced_network_class()(bus)
    net.gap, net.floor, net.pacing = GAP, FLOOR, pacing
    net.clock = lambda: now[0]
    net.sleep = lambda s: now.__setitem__(0, now[0] + s)
    return net, bus, now


def _reply(net, node: int) -> None:
    net.notify(0x280 + node, bytearray(b"PX\x00\x00\x01\x00\x00\x00"), 0.0)


def test_frames_to_one_drive_keep_the_gap_and_other_drives_go_between():
    net, bus, _ = _network()
    net.send_message(0x301, b"PX\x00\x40")
    net.send_message(0x301, b"VX\x00\x40")  # drive 1 did not answer: waits the gap
    net.send_message(0x302, b"PX\x00\x40")  # drive 2: only the floor after the last frame
    net.send_message(0x302, b"VX\x00\x40")
    assert bus.sent == [
        (0, 0x301, b"PX\x00\x40"),
        (1000, 0x301, b"VX\x00\x40"),
        (1140, 0x302, b"PX\x00\x40"),
        (2140, 0x302, b"VX\x00\x40"),
    ]


def test_an_answered_frame_lets_the_next_one_to_that_drive_go_after_the_floor_only():
    net, bus, _ = _network()
    net.send_message(0x30A, b"PX\x00\x40")
    _reply(net, 10)
    net.send_message(0x30A, b"VX\x00\x40")
    net.notify(0x58A, bytearray(b"\x43\x00\x10\x00\x92\x01\x02\x00"), 0.0)  # an SDO response answers too
    net.send_message(0x60A, b"\x40\x00\x10\x00\x00\x00\x00\x00")
    net.send_message(0x60A, b"\x40\x18\x10\x01\x00\x00\x00\x00")  # no answer yet: the gap
    assert [t for t, _, _ in bus.sent] == [0, 140, 280, 1280]


def test_an_answer_from_another_drive_or_a_heartbeat_is_not_an_answer():
    net, bus, _ = _network()
    net.send_message(0x301, b"PX\x00\x40")
    _reply(net, 2)
    net.notify(0x701, bytearray(b"\x05"), 0.0)  # drive 1's heartbeat
    net.notify(0x181, bytearray(8), 0.0)  # drive 1's TPDO1
    net.send_message(0x301, b"VX\x00\x40")
    assert [t for t, _, _ in bus.sent] == [0, 1000]


def test_nmt_to_every_drive_waits_for_every_unanswered_drive():
    net, bus, _ = _network()
    net.send_message(0x301, b"PX\x00\x40")
    net.send_message(0x302, b"PX\x00\x40")
    _reply(net, 2)
    net.send_message(0x000, b"\x01\x00")  # start all: drive 1 has not answered
    net.send_message(0x302, b"PX\x00\x40")  # the broadcast went to drive 2 too: the gap again
    assert [t for t, _, _ in bus.sent] == [0, 140, 1000, 2000]


def test_per_bus_mode_keeps_the_gap_between_any_two_frames():
    net, bus, _ = _network("per-bus")
    net.send_message(0x301, b"PX\x00\x40")
    _reply(net, 1)
    net.send_message(0x301, b"VX\x00\x40")
    net.send_message(0x302, b"PX\x00\x40")
    assert [t for t, _, _ in bus.sent] == [0, 1000, 2000]


@pytest.mark.parametrize("seed", range(5))
def test_random_traffic_never_sends_to_a_drive_within_the_gap_unless_it_answered(seed):
    rnd = random.Random(seed)
    net, bus, now = _network()
    answered_at: dict[int, list[float]] = {}
    for _ in range(400):
        node = rnd.randint(1, 4)
        if rnd.random() < 0.5:
            net.send_message(0x300 + node, b"PX\x00\x40")
        else:
            net.send_message(0x600 + node, b"\x40\x00\x10\x00\x00\x00\x00\x00")
        if rnd.random() < 0.6:  # the drive answers (after some time on the bus)
            now[0] += rnd.choice([0.0, 0.0002, 0.0004])
            _reply(net, node) if rnd.random() < 0.5 else net.notify(0x580 + node, bytearray(8), 0.0)
            answered_at.setdefault(node, []).append(round(now[0] * 1e6))
    last: dict[int, int] = {}
    prev = None
    for t, can_id, _ in bus.sent:
        node = can_id & 0x7F
        if prev is not None:
            assert t - prev >= 140, "the bus-wide floor"
        if node in last and t - last[node] < 1000:
            assert any(last[node] <= a <= t for a in answered_at.get(node, [])), (node, last[node], t)
        last[node], prev = t, t


def test_destination_and_answer_ids():
    assert destination(0x30A, b"PX\x00\x40") == 10 and destination(0x60A, b"") == 10
    assert destination(0x20A, b"") == 10 and destination(0x000, b"\x01\x0a") == 10
    assert destination(0x000, b"\x01\x00") is None and destination(0x080, b"") is None
    assert answering(0x28A) == 10 and answering(0x58A) == 10
    assert answering(0x18A) is None and answering(0x70A) is None and answering(0x08A) is None


def test_the_config_names_the_mode_and_the_floor(tmp_path):
    from sherpa_cli.config import load_config
    from sherpa_cli.errors import SherpaError

    base = (tmp_path / "a.yaml")
    text = Path("configs/appendix-c/example1.yaml").read_text(encoding="utf-8")
    assert load_config("configs/appendix-c/example1.yaml").protocol.pacing == "per-drive"
    base.write_text(text + "\nprotocol: {pacing: per-bus, pacing_floor_us: 0}\n", encoding="utf-8")
    p = load_config(base).protocol
    assert (p.pacing, p.pacing_floor_us) == ("per-bus", 0)
    base.write_text(text + "\nprotocol: {pacing: sometimes}\n", encoding="utf-8")
    with pytest.raises(SherpaError, match="pacing 'sometimes': expected per-drive or per-bus"):
        load_config(base)
