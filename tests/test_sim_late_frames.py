"""A simulator that gets to the bus late (a starved process: a loaded machine, the vcan guest) hears
each frame at the time it arrived, not when its pump got to it (sim/arm.py LATE_FRAME_S). A real
drive hears a host heartbeat when it is on the bus: a backlog must not look like a lost heartbeat
(in the guest, `diffdrive move` was stopped by the drives' consumers while it sent every beat).

On a manual clock that places frames by their timestamps (sim/clock.py FrameClock), as RealClock
does with wall time: the simulated time moves only when the test moves it."""

from __future__ import annotations

import time
import uuid

import can
from test_motion_guard import cfg  # noqa: F401 - fixture

from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.clock import ManualClock

EPOCH = 1_000_000.0  # the frames' timestamp of simulated time 0
NODE = 5  # drive1 of test_motion_guard's config
HOST = 100
CONSUMER_MS = 1000
BEAT_S = 0.2
HELD_S = 2.0  # the pump held up twice the consumer time, with a beat every 0.2 s on the bus meanwhile
PATIENCE_S = 10.0  # how long the test waits for the pump's thread; a bound, not a measurement


class StampedClock(ManualClock):
    """A manual clock whose frames carry ``EPOCH + t`` (python-can VirtualBus preserve_timestamps)."""

    def received_at(self, timestamp: float) -> float:
        return timestamp - EPOCH


def _send(bus: can.BusABC, can_id: int, data: bytes, t: float) -> None:
    msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=False)
    msg.timestamp = EPOCH + t
    bus.send(msg)


def _until(condition) -> None:
    deadline = time.monotonic() + PATIENCE_S
    while not condition():
        assert time.monotonic() < deadline, "the simulator's pump did not get there"
        time.sleep(0.002)


def test_heartbeats_queued_behind_a_held_up_pump_are_heard_when_they_arrived(cfg):  # noqa: F811
    clock = StampedClock()
    channel = f"late-frames-{uuid.uuid4().hex[:8]}"
    sim = SimArm(cfg, {"can0": {"interface": "virtual", "channel": channel}}, clock=clock).start()
    drive = sim.drives["drive1"]

    def lost() -> list[str]:
        with sim.lock:
            return [text for _, text in drive.events if text.startswith("heartbeat lost")]

    try:
        with can.Bus(interface="virtual", channel=channel, preserve_timestamps=True) as host:
            entry = (HOST << 16 | CONSUMER_MS).to_bytes(4, "little")
            _send(host, 0x000, bytes([0x01, NODE]), 0.0)  # NMT start
            _send(host, 0x600 + NODE, bytes([0x23, 0x16, 0x10, 0x01]) + entry, 0.0)  # 0x1016:1 = the consumer
            _send(host, 0x700 + HOST, bytes([5]), 0.0)  # the first beat: the consumer watches from here
            _until(lambda: drive._hb_last is not None)
            with sim.lock:  # the pump is held up (as by a starved process) while 2 s pass ...
                clock.advance(HELD_S)
                # ... and the host's beats went out on time: they wait in the pump's queue
                beats = int(HELD_S / BEAT_S)
                for k in range(1, beats + 1):
                    _send(host, 0x700 + HOST, bytes([5]), k * BEAT_S)
            _until(lambda: drive._hb_last == HELD_S)  # the pump worked off its backlog
            assert lost() == [], "a heartbeat that was on the bus in time was taken as lost"
            assert sim.late_frames == beats - 1  # the last beat is on time (now), the others were late
            # and a consumer still trips when the beats really stop
            clock.advance(CONSUMER_MS / 1000 + 0.1)
            _until(lambda: lost() != [])
            assert lost() == ["heartbeat lost (0x6007=1)"]
    finally:
        sim.stop()
    assert sim.errors == []
