"""A recording whose receive path stalls: each sample keeps the SYNC it answers.

The in-process arm runs on stepped time (sim/stepped.py) with the recorder's SYNC source. For 30 ms
of simulated time (30 SYNCs at 1 kHz) the tool's receive path for the drive's TPDO1 stalls: its
queue keeps the first QUEUE frames and drops the rest, as a full socket buffer does, and hands the
kept ones over only when the stall ends -- 30 ms later on the recorder's clock. Every SYNC still
gets its answer from the simulated drive (the test waits for the drive's frame, not the
recorder's sample), so nothing depends on the machine's speed.

Each SYNC's answer carries its own PX (the test moves the drive's PX offset before every SYNC), so a
sample placed on another SYNC's row shows. The frames the queue kept belong to the SYNCs that were
sent before them; the dropped ones are a gap, reported and absent from the CSV and the MCAP alike.
"""

from __future__ import annotations

import math
import struct
import uuid
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.cli import log_cmd
from sherpa_cli.config import load_config
from sherpa_cli.log.record import Recorder
from sherpa_cli.log.recording import read_csv, write_csv
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.stepped import SteppedTime

ROOT = Path(__file__).resolve().parent.parent
RATE = 1000.0
SYNCS = 100
STALL = range(40, 70)  # the SYNCs sent while the receive path stalls: 30 ms
QUEUE = 10  # frames the stalled receive path keeps


class StalledReceive:
    """The tool's receive path for one COB-ID (canopen's Network.notify, which every received frame
    goes through): counts and remembers every answer the drive sent, and while stalled queues up to
    QUEUE of them (the rest are lost) until :meth:`release`."""

    def __init__(self, network, cob: int) -> None:
        self.network, self.cob = network, cob
        self.deliver = network.notify
        self.answers: list[int] = []  # PX of the drive's answer to SYNC n, in order
        self.queue: list[tuple[int, bytes, float]] = []
        self.stalled = False
        network.notify = self.notify

    def notify(self, can_id: int, data: bytes, timestamp: float) -> None:
        if can_id != self.cob:
            self.deliver(can_id, data, timestamp)
            return
        self.answers.append(struct.unpack_from("<i", bytes(data))[0])
        if not self.stalled:
            self.deliver(can_id, data, timestamp)
        elif len(self.queue) < QUEUE:
            self.queue.append((can_id, data, timestamp))

    def release(self) -> None:
        self.stalled = False
        queued, self.queue = self.queue, []
        for frame in queued:
            self.deliver(*frame)


class _Out:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self.warns: list[str] = []

    def line(self, text: str) -> None:
        self.lines.append(text)

    def warn(self, text: str) -> None:
        self.warns.append(text)


def test_a_stalled_receive_path_leaves_a_marked_gap_and_no_relabelled_sample(tmp_path):
    pytest.importorskip("mcap_ros2")
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    stepped = SteppedTime(pace=False)
    tag = uuid.uuid4().hex[:8]
    arm = SimArm(cfg, {b: {"interface": "virtual", "channel": f"stall-{tag}-{b}"} for b in cfg.buses},
                 clock=stepped.clock)
    (ref,) = drive_refs(cfg, ["elbow_1a"])
    period = 1 / RATE
    with ArmSession.open(cfg, sim=arm) as session:
        stall = StalledReceive(session.links[ref.bus].network, 0x180 + ref.node)
        with Recorder(session, [ref], RATE, clock=stepped.now, sync_factory=stepped.sync_factory) as rec:
            # the next SYNC waits for the drive's answer to reach the receive path, not the recorder
            stepped.follow(lambda n: len(stall.answers) >= n)
            k = 0
            while k < SYNCS:
                with arm.lock:
                    arm.drives[ref.name]._px_offset = 1000 * k  # each SYNC's answer its own PX
                if k == STALL.start:
                    stall.stalled = True
                if k == STALL.stop:
                    stall.release()
                stepped.sleep(period)
                k = len(stall.answers)
        recording = rec.recording()
        counts, expected, gaps = rec.counts(), rec.expected(), rec.gaps()

    assert len(stall.answers) == SYNCS
    check_stalled_recording(recording, cfg, ref.name, stall.answers, counts, expected, gaps, tmp_path)


def check_stalled_recording(recording, cfg, drive: str, answers: list[int], counts, expected: int, gaps,
                            tmp_path: Path) -> None:
    """What a recording over the stall must hold, in its CSV and its MCAP alike: every row is the
    SYNC its answer came for (its time that SYNC's, its PX that answer's), the lost span marked as a
    gap, and the summary lines say so."""
    from mcap_ros2.reader import read_ros2_messages

    from sherpa_cli.log.mcap_out import write_recording

    period = 1 / RATE
    lost = len(STALL) - QUEUE
    assert expected == SYNCS
    assert gaps[drive].missing == lost and gaps[drive].spans == [(STALL.start + QUEUE, lost)], gaps
    assert counts[drive] == len(recording.times) == SYNCS - lost
    csv_path, mcap_path = tmp_path / "run.csv", tmp_path / "run.mcap"
    write_csv(recording, csv_path)
    write_recording(mcap_path, recording, cfg, time_zero_ns=0)
    from_csv = read_csv(csv_path)
    assert len(from_csv.times) == SYNCS - lost
    for t, px in zip(from_csv.times, from_csv.columns[f"{drive}.px"], strict=True):
        n = round(t / period)
        assert abs(t - n * period) < 1e-6 and n not in range(STALL.start + QUEUE, STALL.stop), t
        assert px == answers[n], f"the row at {t:.3f} s holds another SYNC's sample ({px})"
    with mcap_path.open("rb") as fh:
        motors = [(m.log_time_ns, m.ros_msg.position[0]) for m in read_ros2_messages(fh, ["/sherpa/motor_counts"])]
    assert [(round(t * 1e9), px) for t, px in zip(from_csv.times, from_csv.columns[f"{drive}.px"],
                                                  strict=True)] == motors

    class St:
        json_mode = False
        out = _Out()

    log_cmd._render_record(St, [csv_path, mcap_path], counts, expected, len(recording.times), gaps=gaps,
                           period=period)
    assert St.out.lines[0] == f"{drive}: {SYNCS - lost} samples of {SYNCS} (80.00 %)"
    assert St.out.lines[1:] == [f"wrote {csv_path} ({SYNCS - lost} rows)", f"wrote {mcap_path} ({SYNCS - lost} rows)"]
    assert any(f"{lost} samples missing" in w and "0.050 s (20 SYNCs)" in w for w in St.out.warns), St.out.warns
    assert math.isclose(from_csv.times[-1], (SYNCS - 1) * period, abs_tol=1e-9)
