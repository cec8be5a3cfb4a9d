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

import pytest
from conftest import ROOT
from killed_helpers import arm as arm
from killed_helpers import shared_arm as shared_arm
from test_record_stall import RATE, STALL, SYNCS, StalledReceive, check_stalled_recording

from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.log.record import Recorder
from sherpa_cli.sim.stepped import SteppedTime

pytestmark = pytest.mark.crossprocess

DRIVE = "elbow_1a"


def test_a_stalled_receive_path_on_the_served_simulator_marks_gaps_and_relabels_nothing(arm, tmp_path):
    pytest.importorskip("mcap_ros2")
    cfg = apply_bus_map(load_config(ROOT / arm.config), parse_bus_map([arm.bus_map]))
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
    check_stalled_recording(recording, cfg, ref.name, stall.answers, counts, expected, gaps, tmp_path)
