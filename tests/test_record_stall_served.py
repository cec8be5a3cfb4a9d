"""A recording through `sherpa sim --serve` whose receive path stalls: gaps marked, no sample relabelled.

The served simulator runs in its own process on its own (wall) clock, so it cannot be stepped. What
the test fixes instead is the order of events, which is all the samples' labels depend on:

- the recorder's SYNC source is the stepped source of sim/stepped.py (``pace=False``) on the test's
  own clock: SYNC n goes out only once the drive's answer to SYNC n-1 has reached the tool's receive
  path, and the recorder places each sample at its SYNC's time on that clock;
- before SYNC n the test writes PX = 1000 n through the drive's interpreter and waits for its echo, so
  the drive's answer to SYNC n carries n and a sample placed on another SYNC's row shows (the first
  wait sends SYNCs 0 and 1 together: both carry 0);
- the receive path for the drive's TPDO1 stalls over SYNCs 40..69 (30 ms of the recording at 1 kHz):
  it keeps the first QUEUE frames with their receive timestamps and loses the rest, as a full socket
  buffer does, and hands the kept ones over when the stall ends.

How fast the machine runs changes none of this; a wall-time bound is only a hang guard (the stepped
source's answer timeout). The CSV and the MCAP of the run are checked alike.
"""

from __future__ import annotations

import math

import pytest
from arm_harness import ArmProcess, TestBus
from conftest import ROOT, _patient_config
from test_record_stall import QUEUE, RATE, STALL, SYNCS, StalledReceive, _Out

from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.cli import log_cmd
from sherpa_cli.config import load_config
from sherpa_cli.log.record import Recorder
from sherpa_cli.log.recording import read_csv, write_csv
from sherpa_cli.sim.stepped import SteppedTime

pytestmark = pytest.mark.crossprocess

DRIVE = "elbow_1a"


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """A `sherpa sim --serve` of the module's own (python-can-remote on 127.0.0.1)."""
    work = tmp_path_factory.mktemp("served")
    proc = ArmProcess(TestBus("remote"), ROOT, _patient_config(work), work)
    try:
        proc.start()
    except RuntimeError as exc:
        pytest.skip(f"the served simulator did not start: {exc}")
    try:
        yield proc
    finally:
        proc.stop()


def test_a_stalled_receive_path_on_the_served_simulator_marks_gaps_and_relabels_nothing(served, tmp_path):
    pytest.importorskip("mcap_ros2")
    from mcap_ros2.reader import read_ros2_messages

    from sherpa_cli.log.mcap_out import write_recording

    served.new_test()
    served.before_command()
    cfg = apply_bus_map(load_config(served.config), parse_bus_map([served.bus_map]))
    (ref,) = drive_refs(cfg, [DRIVE])
    stepped = SteppedTime(pace=False)
    period = 1 / RATE
    with ArmSession.open(cfg, buses=[ref.bus]) as session:
        client = session.client(ref)
        stall = StalledReceive(session.links[ref.bus].network, 0x180 + ref.node)
        with Recorder(session, [ref], RATE, clock=stepped.now, sync_factory=stepped.sync_factory) as rec:
            # the next SYNC waits for the drive's answer to reach the receive path, not the recorder
            stepped.follow(lambda n: len(stall.answers) >= n)
            k = 0
            while k < SYNCS:
                client.set("PX", 0, 1000 * k)  # the drive's answer to SYNC k carries k (echo awaited)
                if k == STALL.start:
                    stall.stalled = True
                if k == STALL.stop:
                    stall.release()
                stepped.sleep(period)
                k = len(stall.answers)
        recording = rec.recording()
        counts, expected, gaps = rec.counts(), rec.expected(), rec.gaps()

    # one answer per SYNC, each its own PX (the first wait sends SYNCs 0 and 1, both before PX moves)
    assert stall.answers == [0, 0, *(1000 * n for n in range(2, SYNCS))]
    assert expected == SYNCS
    lost = len(STALL) - QUEUE
    assert gaps[ref.name].missing == lost and gaps[ref.name].spans == [(STALL.start + QUEUE, lost)], gaps
    assert counts[ref.name] == len(recording.times) == SYNCS - lost

    csv_path, mcap_path = tmp_path / "run.csv", tmp_path / "run.mcap"
    write_csv(recording, csv_path)
    write_recording(mcap_path, recording, cfg, time_zero_ns=0)
    from_csv = read_csv(csv_path)
    assert len(from_csv.times) == SYNCS - lost
    for t, px in zip(from_csv.times, from_csv.columns[f"{ref.name}.px"], strict=True):
        n = round(t / period)
        assert abs(t - n * period) < 1e-6 and n not in range(STALL.start + QUEUE, STALL.stop), t
        assert px == stall.answers[n], f"the row at {t:.3f} s holds another SYNC's sample ({px})"
    with mcap_path.open("rb") as fh:
        motors = [(m.log_time_ns, m.ros_msg.position[0]) for m in read_ros2_messages(fh, ["/sherpa/motor_counts"])]
    assert [(round(t * 1e9), px) for t, px in zip(from_csv.times, from_csv.columns[f"{ref.name}.px"],
                                                  strict=True)] == motors

    class St:
        json_mode = False
        out = _Out()

    log_cmd._render_record(St, [csv_path, mcap_path], counts, expected, len(recording.times), gaps=gaps,
                           period=period)
    assert St.out.lines[0] == f"{ref.name}: {SYNCS - lost} samples of {SYNCS} (80.00 %)"
    assert St.out.lines[1:] == [f"wrote {csv_path} ({SYNCS - lost} rows)", f"wrote {mcap_path} ({SYNCS - lost} rows)"]
    assert any(f"{lost} samples missing" in w and "0.050 s (20 SYNCs)" in w for w in St.out.warns), St.out.warns
    assert math.isclose(from_csv.times[-1], (SYNCS - 1) * period, abs_tol=1e-9)

