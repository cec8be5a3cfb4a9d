"""The recorder's end drain (log/record.py Recorder._drain): after SYNC stops, the answers to the
last SYNCs may still be on their way (a loaded receive thread works off a backlog); the recorder
keeps listening until no new sample came for a few periods, bounded by DRAIN_LIMIT_S, instead of
cutting the end of the recording off.

The drive side is a fake here: its TPDO answers arrive only after SYNC stopped, one every 2 ms
from a thread (the worst case: the whole recording is backlog). The recorder's quiet window at
10 Hz is 0.5 s, so the test does not depend on this machine's speed unless a 2 ms sleep takes
half a second; the drain's bound keeps the test under about 1.5 s.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.log.record import DRAIN_LIMIT_S, Recorder

ROOT = Path(__file__).resolve().parent.parent
RATE = 10.0
GAP_S = 0.002  # between two late answers


class FakeSdo:
    def __init__(self) -> None:
        self.od: dict[tuple[int, int], int] = {}

    def upload(self, index: int, sub: int) -> bytes:
        return self.od.get((index, sub), 0).to_bytes(4, "little")

    def download(self, index: int, sub: int, data: bytes) -> None:
        self.od[(index, sub)] = int.from_bytes(data, "little")


class FakeNetwork:
    def __init__(self) -> None:
        self.subs: dict[int, object] = {}
        self.lock = threading.Lock()

    def subscribe(self, cob: int, callback) -> None:
        with self.lock:
            self.subs[cob] = callback

    def unsubscribe(self, cob: int, callback) -> None:
        with self.lock:
            self.subs.pop(cob, None)

    def deliver(self, cob: int, data: bytes, timestamp: float) -> None:
        with self.lock:
            callback = self.subs.get(cob)
        if callback is not None:  # after unsubscribe a frame is simply not heard
            callback(cob, data, timestamp)


class LateSync:
    """A SYNC source whose drive answers nothing while SYNC runs; at stop() the answers to every
    SYNC sent so far start arriving, one every GAP_S, with the timestamps they were sent at."""

    def __init__(self, network: FakeNetwork, cob: int, period: float) -> None:
        self.network, self.cob, self.period = network, cob, period
        self.t0 = time.time()
        self.sent = 0
        self.running = True
        self.thread: threading.Thread | None = None

    def stop(self) -> None:
        self.sent = math.floor((time.time() - self.t0) / self.period) + 1

        def backlog() -> None:
            for k in range(self.sent):
                time.sleep(GAP_S)
                self.network.deliver(self.cob, struct.pack("<ii", 100 * k, 7), self.t0 + k * self.period + 0.001)

        self.thread = threading.Thread(target=backlog, name="late-tpdos", daemon=True)
        self.thread.start()


@pytest.fixture
def fake():
    cfg = load_config(ROOT / "tests/data/step-arm.yaml")
    (ref,) = drive_refs(cfg, ["elbow"])
    network, sdo = FakeNetwork(), FakeSdo()
    session = SimpleNamespace(cfg=cfg, links={ref.bus: SimpleNamespace(network=network, bus=None)},
                              client=lambda r: SimpleNamespace(nmt_start=lambda: None, silent=False), sdo=lambda r: sdo)
    sources: list[LateSync] = []

    def factory(name, bus, period):
        sources.append(LateSync(network, 0x180 + ref.node, period))
        return sources[-1]

    yield session, ref, factory, sources, sdo
    for s in sources:
        s.running = False
        if s.thread is not None:
            s.thread.join(timeout=5)


def test_answers_that_arrive_after_sync_stopped_are_kept(fake):
    session, ref, factory, sources, sdo = fake
    with Recorder(session, [ref], RATE, sync_factory=factory) as rec:
        time.sleep(0.35)  # SYNCs 0..3 at 10 Hz
    (source,) = sources
    assert source.sent >= 4
    # every answer was heard, in order, on its own SYNC's sample
    assert rec.counts() == {ref.name: source.sent}
    recording = rec.recording()
    assert recording.columns[f"{ref.name}.px"] == [100.0 * k for k in range(source.sent)]
    assert recording.times == pytest.approx([k / RATE for k in range(source.sent)])
    assert sdo.od[(0x1800, 1)] == 0  # and then the PDO's old COB-ID went back


def test_the_drain_is_bounded(fake, monkeypatch):
    """A drive that never stops answering cannot keep the recorder listening past DRAIN_LIMIT_S."""
    session, ref, factory, _sources, _sdo = fake
    monkeypatch.setattr(LateSync, "stop", _endless_stop)
    t = time.monotonic()
    with Recorder(session, [ref], RATE, sync_factory=factory) as rec:
        pass
    took = time.monotonic() - t
    assert DRAIN_LIMIT_S <= took < DRAIN_LIMIT_S + 2.0
    # it kept the recorder busy; only the SYNCs that were sent hold a sample, the rest answer none
    assert rec.counts()[ref.name] == rec.expected() and rec.unplaced() > 10


def _endless_stop(self: LateSync) -> None:
    def forever() -> None:
        k = 0
        while self.running:
            time.sleep(GAP_S)
            self.network.deliver(self.cob, struct.pack("<ii", k, 0), self.t0 + k * self.period)
            k += 1

    self.thread = threading.Thread(target=forever, name="endless-tpdos", daemon=True)
    self.thread.start()


def test_the_sync_thread_sends_every_sync_already_due_when_stopped():
    # A SYNC thread that is behind (a busy interpreter) must not drop the SYNCs already due at the
    # stop: those are the samples of the recording's last milliseconds.
    import uuid as _uuid

    import can as _can

    from sherpa_cli.log.record import ThreadSync

    channel = f"sync-{_uuid.uuid4().hex[:8]}"
    with _can.Bus(interface="virtual", channel=channel) as tx, _can.Bus(interface="virtual", channel=channel) as rx:
        sync = ThreadSync(tx, 0.001)
        sync.start -= 0.05  # 50 SYNCs behind at once, as if the thread had been starved
        time.sleep(0.02)
        sync.stop()
        frames = 0
        while rx.recv(timeout=0.05) is not None:
            frames += 1
    assert sync._due_total is not None and sync._due_total >= 70
    assert sync.sent == sync._due_total == frames
