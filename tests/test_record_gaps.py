"""A recording with holes says how many samples are missing and where (a 60 s
recording reported "100.00 %" while its file had empty rows). SYNCs the test leaves out on simulated
time (a ManualClock, SYNC in lockstep) are the holes; the report names their times as the file has
them, streamed (CSV row by row) or kept in memory. And a second SYNC producer, found on the same
simulated time (across processes: tests/test_foreign_sync.py)."""

from __future__ import annotations

import time
from pathlib import Path

import can
import pytest
from test_log_record import Lockstep, _arm

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.cli import log_cmd
from sherpa_cli.config import load_config
from sherpa_cli.log.record import Gaps, Recorder
from sherpa_cli.log.recording import CsvWriter, read_csv
from sherpa_cli.sim.clock import ManualClock

ROOT = Path(__file__).resolve().parent.parent
SKIPPED = [*range(100, 103), 250, *range(400, 410)]
SYNCS = 500


def _record(rec: Recorder, lock: Lockstep, clock: ManualClock) -> None:
    sent = 0
    for k in range(SYNCS):
        if k:
            clock.advance(lock.period)
        if k in SKIPPED:
            continue
        for bus in lock.buses.values():
            bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        sent += 1
        deadline = time.monotonic() + 5
        while min(rec.counts().values()) < sent:
            assert time.monotonic() < deadline, f"SYNC {k}: samples {rec.counts()}"
            time.sleep(0.0001)


@pytest.mark.parametrize("streamed", [True, False], ids=["streamed", "in memory"])
def test_left_out_syncs_are_counted_and_placed(tmp_path, streamed):
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    clock = ManualClock()
    lock = Lockstep(clock)
    out = tmp_path / "r.csv"
    with ArmSession.open(cfg, sim=_arm(cfg, clock)) as session:
        rec = Recorder(session, drive_refs(cfg, ["elbow_1a", "elbow_1b"]), 1000, clock=clock.now,
                       sync_factory=lock.factory)
        if streamed:
            with CsvWriter(out, rec.columns()) as sink:
                rec.sink = sink
                with rec:
                    _record(rec, lock, clock)
        else:
            with rec:
                _record(rec, lock, clock)
    assert rec.expected() == SYNCS
    gaps = rec.gaps()
    for name in ("elbow_1a", "elbow_1b"):
        assert gaps[name] == Gaps(missing=len(SKIPPED), spans=[(100, 3), (250, 1), (400, 10)], last=409), gaps
    times = read_csv(out).times if streamed else rec.recording().times
    assert len(times) == SYNCS - len(SKIPPED)
    assert all(abs(t - k / 1000) > 1e-9 for t in times for k in SKIPPED)  # the holes are where the report says


class _Out:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self.warns: list[str] = []

    def line(self, text: str) -> None:
        self.lines.append(text)

    def warn(self, text: str) -> None:
        self.warns.append(text)


def test_the_report_names_where_the_samples_are_missing(tmp_path):
    class St:
        json_mode = False
        out = _Out()

    many = Gaps()
    for k in [5, 6, 7, 20, 40, 41, 60, 80, 81, 82, 99, 120]:
        many.add(k)
    log_cmd._render_record(St, [tmp_path / "r.csv"], {"a": 488, "b": 500}, 500, 495,
                           gaps={"a": many, "b": Gaps()}, period=0.001)
    assert St.out.lines[0] == "a: 488 samples of 500 (97.60 %)"
    assert St.out.warns == [
        "5 of 500 SYNCs have no row: no drive's sample arrived for them",
        "a: 12 samples missing (empty cells) at time_s 0.005 s (3 SYNCs), 0.020 s (1 SYNC), 0.040 s (2 SYNCs), "
        "0.060 s (1 SYNC), 0.080 s (3 SYNCs) and 2 more gaps"]


def test_the_json_report_lists_the_gaps(tmp_path):
    import json

    class Out(_Out):
        def json(self, obj) -> None:
            self.lines.append(json.dumps(obj))

    class St:
        json_mode = True
        out = Out()

    g = Gaps()
    for k in (3, 4, 9):
        g.add(k)
    log_cmd._render_record(St, [tmp_path / "r.csv"], {"a": 97}, 100, 100, gaps={"a": g}, period=0.01)
    doc = json.loads(St.out.lines[0])
    assert doc["drives"] == [{"drive": "a", "samples": 97, "missing": 3, "more_gaps": 0,
                              "gaps": [{"t_s": 0.03, "syncs": 2}, {"t_s": 0.09, "syncs": 1}]}]


def test_a_second_sync_producer_is_found_on_simulated_time():
    """The same in lockstep: every period a second SYNC (another producer) besides the recorder's own.
    The recorder's check raises within its margin (10 SYNCs), naming the bus and both counts."""
    from sherpa_cli.log.record import ForeignSyncError

    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    clock = ManualClock()
    lock = Lockstep(clock)
    with ArmSession.open(cfg, sim=_arm(cfg, clock)) as session, \
            Recorder(session, drive_refs(cfg, ["elbow_1a"]), 1000, clock=clock.now, sync_factory=lock.factory) as rec:
        lock.run(rec, 5)
        rec.check()  # one producer: nothing found
        found_at = None
        for k in range(5, 40):
            clock.advance(lock.period)
            for _ in range(2):  # ours and the other node's
                for bus in lock.buses.values():
                    bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            deadline = time.monotonic() + 5
            # the second answer of a period answers no SYNC of this tool: heard, but not a sample
            while rec.counts()["elbow_1a"] + rec.unplaced() < 5 + 2 * (k - 4) and rec.problem() is None:
                assert time.monotonic() < deadline, rec.counts()
                time.sleep(0.0001)
            if rec.problem() is not None:
                found_at = k
                break
        assert found_at is not None and found_at <= 5 + 12, found_at
        with pytest.raises(ForeignSyncError, match=r"bus can1: elbow_1a answered \d+ SYNCs in .* but this tool "
                                                    r"sent at most \d+ \(1000 Hz\): another node is sending SYNC"):
            rec.check()
