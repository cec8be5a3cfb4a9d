"""A simulator that gets to the bus late (a starved process: a loaded machine, the vcan guest) hears
each frame at the time it arrived, not when its pump got to it (sim/arm.py LATE_FRAME_S). A real
drive hears a host heartbeat when it is on the bus: a backlog must not look like a lost heartbeat
(in the guest, `diffdrive move` was stopped by the drives' consumers while it sent every beat)."""

from __future__ import annotations

import time
import uuid

import can
from test_motion_guard import cfg  # noqa: F401 - fixture

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.sim.arm import LATE_FRAME_S, SimArm

HOST = 100
CONSUMER_MS = 1000
BEAT_S = 0.2
HELD_S = 2.0  # the pump held up twice the consumer time, with a beat every 0.2 s on the bus meanwhile


def _lost(session) -> list[str]:
    with session.sim.lock:
        return [text for _, text in session.sim.drives["drive1"].events if text.startswith("heartbeat lost")]


def _heartbeat(bus: can.BusABC, at: float | None = None) -> None:
    msg = can.Message(arbitration_id=0x700 + HOST, data=[5], is_extended_id=False)
    if at is not None:
        msg.timestamp = at
    bus.send(msg)


def test_heartbeats_queued_behind_a_held_up_pump_are_heard_when_they_arrived(cfg):  # noqa: F811
    ref = resolve_target(cfg, "drive1")
    channels = {"can0": f"late-frames-{uuid.uuid4().hex[:8]}"}
    with ArmSession.open(cfg, sim=SimArm.for_session(cfg, channels)) as s:
        s.sdo(ref).download(0x1016, 1, (HOST << 16 | CONSUMER_MS).to_bytes(4, "little"))
        # the host's side of the bus: a second virtual bus on the simulator's channel, whose frames
        # keep the timestamps given (python-can VirtualBus preserve_timestamps): when they were sent
        with can.Bus(interface="virtual", channel=channels["can0"], preserve_timestamps=True) as host:
            _heartbeat(host, time.time())
            deadline = time.monotonic() + 5
            while s.sim.drives["drive1"]._hb_last is None:  # the consumer watches from the first beat
                assert time.monotonic() < deadline, "the simulated drive never heard the first heartbeat"
                time.sleep(0.005)
            with s.sim.lock:  # the pump is held up (as by a starved process) ...
                held_from = time.time()
                time.sleep(HELD_S)
                # ... while the host's beats went out on time: they wait in the pump's queue
                for k in range(1, int(HELD_S / BEAT_S) + 1):
                    _heartbeat(host, held_from + k * BEAT_S)
            beats = int(HELD_S / BEAT_S)
            deadline = time.monotonic() + 5
            while s.sim.late_frames < beats - 1 and time.monotonic() < deadline:  # the pump works off the backlog
                time.sleep(LATE_FRAME_S / 5)
            assert _lost(s) == [], "a heartbeat that was on the bus in time was taken as lost"
            assert s.sim.late_frames >= beats - 1  # (the last one may reach the pump in time)
            # and a consumer still trips when the beats really stop
            time.sleep(CONSUMER_MS / 1000 + 0.5)
            assert len(_lost(s)) == 1, _lost(s)
