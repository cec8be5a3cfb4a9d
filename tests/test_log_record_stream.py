"""`log record` in constant memory: each completed SYNC row goes to the CSV as it
comes, only a short window stays in memory; what is reported is what is in the file."""

from __future__ import annotations

import math
import tracemalloc
from pathlib import Path

from test_log_record import Lockstep, _arm

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.log.record import Recorder
from sherpa_cli.log.recording import CsvWriter, read_csv, write_csv
from sherpa_cli.sim.clock import ManualClock
from sherpa_cli.sim.drive import FrameRecord

ROOT = Path(__file__).resolve().parent.parent
LOG_CODE = ROOT / "sherpa_cli" / "log" / "*"


def _record(tmp_path: Path, syncs: int, *, name: str, targets=None, rate: float = 1000) -> tuple[int, Recorder, Path]:
    """Memory (bytes) the recorder's code holds at the end of a streaming recording of ``syncs`` SYNCs on a ManualClock."""
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    clock = ManualClock()
    lock = Lockstep(clock)
    out = tmp_path / f"{name}.csv"
    with ArmSession.open(cfg, sim=_arm(cfg, clock)) as session:
        refs = drive_refs(cfg, targets)
        rec = Recorder(session, refs, rate, clock=clock.now, sync_factory=lock.factory)
        with CsvWriter(out, rec.columns()) as sink:
            rec.sink = sink
            with rec:
                tracemalloc.start()
                lock.run(rec, syncs)
                # what the recorder's own code still holds at the end of the recording, not the
                # process's peak: the simulated bus's queues and a late receive thread (CI load) are
                # neither the recorder's memory nor deterministic
                held = tracemalloc.take_snapshot().filter_traces([tracemalloc.Filter(True, str(LOG_CODE))])
                tracemalloc.stop()
    return sum(stat.size for stat in held.statistics("filename")), rec, out


def test_held_memory_does_not_grow_with_the_duration(tmp_path, monkeypatch):
    # the simulated drives log every frame they receive (bounded at 100 000, sim/drive.py FrameRecord):
    # the simulator's memory, not the recorder's; bounded far lower here so it does not count
    monkeypatch.setattr(FrameRecord, "limit", 200)
    joints = ["shoulder_1a", "shoulder_1b", "elbow_1a"]
    short, _, _ = _record(tmp_path, 1000, name="short", targets=joints)
    long, rec, out = _record(tmp_path, 3000, name="long", targets=joints)
    # 3x the samples; kept in memory: only the late-frame window. Where the last flush fell is up to
    # the receive threads (one per bus), so at the end the window holds between `window` and
    # 2 x `window` rows per drive (~105 B a row: a PX/VX tuple in a dict), whatever the duration:
    # that much either recording may hold more than the other. Kept in memory as before (no sink),
    # 2000 more rows of 3 drives would add ~0.6 MB
    window_spread = rec.window * len(joints) * 160
    assert long <= short + window_spread + 32 * 1024, (short, long, window_spread)
    assert rec.rows_written == 3000 and len(read_csv(out).times) == 3000


def test_the_streamed_csv_is_byte_for_byte_the_in_memory_one(tmp_path):
    _, rec, out = _record(tmp_path, 700, name="streamed", targets=["elbow_1a", "elbow_1b", "wrist_1a"], rate=500)
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    clock = ManualClock()
    lock = Lockstep(clock)
    with ArmSession.open(cfg, sim=_arm(cfg, clock)) as session:
        whole = Recorder(session, drive_refs(cfg, ["elbow_1a", "elbow_1b", "wrist_1a"]), 500, clock=clock.now, sync_factory=lock.factory)
        with whole:
            lock.run(whole, 700)
    write_csv(whole.recording(), tmp_path / "whole.csv")
    assert out.read_bytes() == (tmp_path / "whole.csv").read_bytes()
    assert rec.counts() == whole.counts() and set(rec.counts().values()) == {700}


def test_rows_are_in_the_file_while_recording(tmp_path):
    """What a kill -9 would leave: every row older than the late window is already in the file."""
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    clock = ManualClock()
    lock = Lockstep(clock)
    out = tmp_path / "live.csv"
    with ArmSession.open(cfg, sim=_arm(cfg, clock)) as session:
        rec = Recorder(session, drive_refs(cfg, ["elbow_1a"]), 1000, clock=clock.now, sync_factory=lock.factory)
        with CsvWriter(out, rec.columns()) as sink:
            rec.sink = sink
            with rec:
                lock.run(rec, 1000)
                on_disk = read_csv(out)  # the recording still runs
                assert 1000 - 2 * rec.window <= len(on_disk.times) < 1000
                assert all(abs(t - k / 1000) < 1e-9 for k, t in enumerate(on_disk.times))
                assert not any(math.isnan(v) for v in on_disk.columns["elbow_1a.px"])


def test_the_report_counts_gaps_and_never_rounds_up_to_100(cli, tmp_path):
    from sherpa_cli.cli import log_cmd

    assert log_cmd._percent(4999, 5000) == "99.98 %"
    assert log_cmd._percent(99999, 100000) == "99.99 %"
    assert log_cmd._percent(5000, 5000) == "100.00 %"

    class Out:
        def __init__(self):
            self.lines, self.warns = [], []

        def line(self, text):
            self.lines.append(text)

        def warn(self, text):
            self.warns.append(text)

    class St:
        json_mode = False
        out = Out()

    log_cmd._render_record(St, [tmp_path / "r.csv"], {"a": 90}, 100, 95, 3)
    assert St.out.lines[0] == "a: 90 samples of 100 (90.00 %)"
    assert St.out.warns == ["5 of 100 SYNCs have no row: no drive's sample arrived for them",
                            "3 frames came after their row was written: not in the file"]
