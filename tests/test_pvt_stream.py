"""motion/pvt_stream.py against the in-process simulated arm on stepped time (sim/stepped.py):
two joints of tests/data/move-arm.yaml (yaw on can1, elbow on can0) streamed PVT records inside the
motion guard. The simulated drives play them (sim/pvt.py); the sender keeps its period on the
stepped clock, so lateness only comes from what a test injects."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.bus import journal
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.pvt_stream import (
    StreamSettings,
    StreamStoppedError,
    stream_motion_settings,
    stream_pvt,
)
from sherpa_cli.motion.settings import MotionSettings

MOVE_CONFIG = Path(__file__).resolve().parent / "data" / "move-arm.yaml"
PERIOD = 0.01
DRIVES = ("yaw", "elbow")
AMPLITUDE = {"yaw": 1000, "elbow": -600}  # counts over the stream


def x_of(name: str, t: float, duration: float) -> float:
    """A rest-to-rest path: position A (t/T - sin(2 pi t/T) / 2 pi)."""
    a, s = AMPLITUDE[name], min(max(t / duration, 0.0), 1.0)
    return a * (s - math.sin(2 * math.pi * s) / (2 * math.pi))


def v_of(name: str, t: float, duration: float) -> float:
    s = min(max(t / duration, 0.0), 1.0)
    return AMPLITUDE[name] / duration * (1 - math.cos(2 * math.pi * s))


def tracks(duration: float) -> dict[str, list[tuple[int, int]]]:
    n = round(duration / PERIOD)
    return {name: [(round(x_of(name, k * PERIOD, duration)), round(v_of(name, k * PERIOD, duration)))
                   for k in range(1, n + 1)] for name in DRIVES}


@pytest.fixture
def arm():
    cfg = load_config(MOVE_CONFIG)
    with stepped_session(cfg) as (session, st):
        yield session, st


def guard_of(session, st):
    refs = drive_refs(session.cfg, list(DRIVES))
    settings = stream_motion_settings(MotionSettings.from_config(session.cfg))
    return MotionGuard(session, refs, settings=settings, clock=st.now, sleep=st.sleep), refs


def sim_drive(session, name: str):
    return session.sim.drives[name]


def assert_put_back(session, refs) -> None:
    """Every RAM value the stream changed is back (MP[], QT[1] read 0 until written; the RPDO3 mapping
    as at power-up) and the journal holds nothing of the stream's."""
    for ref in refs:
        d = sim_drive(session, ref.name)
        with session.sim.lock:
            for key in ("MP[1]", "MP[2]", "MP[3]", "MP[4]", "MP[6]", "QT[1]"):
                assert d.ram.get(key, 0) == 0, (ref.name, key, d.ram.get(key))
            assert (d.rpdos.read(0x1402, 1), d.rpdos.read(0x1402, 2)) == (0x400 + ref.node, 255), ref.name
            assert (d.rpdos.read(0x1602, 0), d.rpdos.read(0x1602, 1)) == (0, 0), ref.name
        assert [s for s in journal.leftover(ref) if s.owner == "pvt stream"] == []


def test_a_two_joint_stream_tracks_its_path(arm):
    session, st = arm
    duration = 2.0
    samples: dict[str, list[tuple[float, int]]] = {name: [] for name in DRIVES}
    noted: dict[str, list[tuple[str, int]]] = {}

    def sleep(seconds: float) -> None:
        if not noted:  # while streaming, the journal holds what a killed command would leave
            for ref in refs:
                data = json.loads(journal.path_for(ref.bus, ref.node).read_text(encoding="utf-8"))
                noted[ref.name] = [(step["name"], step["old"]) for step in data["steps"] if step["owner"] == "pvt stream"]
        st.sleep(seconds)
        with session.sim.lock:
            for name in DRIVES:
                d = sim_drive(session, name)
                d.advance_to(st.now())
                if d.pvt.active:
                    samples[name].append((st.now(), d.px))

    guard, refs = guard_of(session, st)
    with guard as g:
        report = stream_pvt(g, tracks(duration), clock=st.now, sleep=sleep)
    assert report.stopped is None
    assert report.sent == 2 * round(duration / PERIOD)
    assert report.late == 0 and report.on_time_pct == 100.0
    assert report.max_lateness_s < PERIOD
    assert 0 <= report.skew_s < 0.1  # the second drive's PV and BG are two interpreter round trips later
    for name in DRIVES:
        assert report.last_position[name] == round(x_of(name, duration, duration)), name
        assert len(samples[name]) > 150, name
        start = report.starts[name]
        worst = max(abs(px - x_of(name, t - start, duration)) for t, px in samples[name])
        assert worst <= 3, (name, worst)
        d = sim_drive(session, name)
        assert d.pvt_records == round(duration / PERIOD)
        assert not d.motor_on  # the guard switched it off again
    assert g.report.reason == "end"
    for ref in refs:
        cob = 0x400 + ref.node
        # the interpreter values, then the RPDO's way back last step first: `sherpa recover` replays it
        # backwards (off, mapping emptied, entry, count, type, its old COB-ID)
        assert noted[ref.name] == [("MP[1]", 0), ("MP[2]", 0), ("MP[3]", 0), ("MP[4]", 0), ("MP[6]", 0), ("QT[1]", 0),
                                   ("0x1402:1", cob), ("0x1402:2", 255), ("0x1602:0", 0), ("0x1602:1", 0),
                                   ("0x1602:0", 0), ("0x1402:1", cob | 0x80000000)], noted
    assert_put_back(session, refs)


def test_a_starved_sender_stops_every_drive_before_its_queue_runs_out(arm):
    session, st = arm
    calls = [0]

    def sleep(seconds: float) -> None:
        calls[0] += 1
        st.sleep(seconds)
        if calls[0] == 40:  # the sender's thread stalls for 1 s of the clock, as a starved thread does:
            for _ in range(100):  # time passes while it does not run, longer than its queues last
                st.sleep(0.01)

    guard, refs = guard_of(session, st)
    with pytest.raises(StreamStoppedError) as info, guard as g:
        stream_pvt(g, tracks(2.0), clock=st.now, sleep=sleep)
    err = info.value
    assert "starved" in str(err) and "yaw" in err.drive and "elbow" in err.drive
    assert err.report.stopped is not None and err.report.stopped.startswith("starved")
    # stopped while the sender was still stuck, past the bound and long before its queues' 310 ms ran out
    assert StreamSettings().late_bound < err.report.max_lateness_s < 0.3
    assert g.report.reason == "error"
    for r in g.report.drives:
        assert r.stopped_by != "not stopped", r.line()
    for name in DRIVES:
        d = sim_drive(session, name)
        assert not d.motor_on
        # stopped by the host, never by running out of records
        assert not any("PVT underflow" in text for _, text in d.events), d.events
    assert_put_back(session, refs)


def test_an_underflow_on_one_drive_stops_every_drive(arm):
    session, st = arm
    calls = [0]

    def sleep(seconds: float) -> None:
        calls[0] += 1
        if calls[0] == 30:
            with session.sim.lock:  # the elbow loses its queue: it runs empty at its next row
                d = sim_drive(session, "elbow")
                d.advance_to(st.now())
                d.pvt.queue.clear()
        st.sleep(seconds)

    guard, refs = guard_of(session, st)
    with pytest.raises(StreamStoppedError) as info, guard as g:
        stream_pvt(g, tracks(2.0), clock=st.now, sleep=sleep)
    err = info.value
    assert err.drive == "elbow"
    assert "queue ran empty (underflow)" in str(err)
    assert g.report.reason == "error"
    yaw = sim_drive(session, "yaw")
    assert not yaw.motor_on and not any("PVT underflow" in text for _, text in yaw.events)
    assert err.report.sent < 2 * 200
    assert_put_back(session, refs)


def test_a_queue_low_while_rows_are_still_sent_stops_every_drive(arm):
    session, st = arm
    calls = [0]

    def sleep(seconds: float) -> None:
        calls[0] += 1
        if calls[0] == 30:
            with session.sim.lock:  # the yaw loses 20 queued rows (as if lost on the bus): it runs low
                d = sim_drive(session, "yaw")
                d.advance_to(st.now())
                for _ in range(20):
                    d.pvt.queue.pop()
        st.sleep(seconds)

    guard, refs = guard_of(session, st)
    with pytest.raises(StreamStoppedError) as info, guard as g:
        stream_pvt(g, tracks(2.0), clock=st.now, sleep=sleep)
    err = info.value
    assert err.drive == "yaw" and "PVT queue low" in str(err)
    assert err.report.queue_low == {"yaw": 1}
    assert g.report.reason == "error"
    for name in DRIVES:
        d = sim_drive(session, name)
        assert not d.motor_on and not any("PVT underflow" in text for _, text in d.events), name
    assert_put_back(session, refs)


def test_tracks_that_cannot_be_streamed_are_refused_before_anything_is_sent(arm):
    session, st = arm
    guard, refs = guard_of(session, st)
    good = tracks(0.5)
    with guard as g:
        for bad, words in (({"yaw": good["yaw"], "elbow": good["elbow"][:-1]}, "same number"),
                           ({"yaw": [*good["yaw"][:-1], (1000, 5)], "elbow": good["elbow"]}, "last PVT record"),
                           ({"yaw": [(2**31, 0)], "elbow": [(0, 0)]}, "int32"),
                           ({"yaw": [(500, 0)], "elbow": [(0, 0)]}, "the first PVT record is at 500"),
                           ({"wrist": good["yaw"]}, "not a drive of this motion guard"),
                           ({}, "at least one")):
            with pytest.raises(UsageError, match=words):
                stream_pvt(g, bad, clock=st.now, sleep=st.sleep)
        for ref in refs:
            assert sim_drive(session, ref.name).pvt_records == 0
            assert not sim_drive(session, ref.name).motor_on


def test_a_guard_that_would_stop_on_pvt_emergencies_is_refused(arm):
    session, st = arm
    refs = drive_refs(session.cfg, list(DRIVES))
    with MotionGuard(session, refs, settings=MotionSettings.from_config(session.cfg), clock=st.now,
                     sleep=st.sleep) as g, pytest.raises(UsageError, match="0xFF00"):
        stream_pvt(g, tracks(0.5), clock=st.now, sleep=st.sleep)


def test_stream_settings_bounds():
    assert StreamSettings().late_bound == pytest.approx((32 - 16) * PERIOD / 2)
    with pytest.raises(ValueError):
        StreamSettings(prime=65)
    with pytest.raises(ValueError):
        StreamSettings(prime=19)  # a fed queue would read low
    with pytest.raises(ValueError):
        StreamSettings(late_bound_s=0)


def test_sherpa_recover_puts_back_what_a_killed_stream_left(arm, monkeypatch):
    """A stream killed before its restore leaves its set-up on the drives and its notes in the journal:
    the journal's replay (`sherpa recover`, backwards) puts every value back without a refusal."""
    from sherpa_cli.motion import pvt_stream

    session, st = arm
    monkeypatch.setattr(pvt_stream, "_restore_all", lambda guard, streams, report: [])  # killed: no restore
    guard, refs = guard_of(session, st)
    with guard as g:
        stream_pvt(g, tracks(0.5), clock=st.now, sleep=st.sleep)
    for ref in refs:
        with session.sim.lock:
            assert sim_drive(session, ref.name).rpdos.record_cob(0x400 + ref.node)  # still set up
        path = journal.path_for(ref.bus, ref.node)
        data = json.loads(path.read_text(encoding="utf-8"))
        for step in data["steps"]:
            step["proc"] = "a process that has ended"  # as after a kill: the note's process is gone
        path.write_text(json.dumps(data), encoding="utf-8")
        result = journal.restore(session, ref, apply=True)
        assert result.problems == [], result.problems
    assert_put_back(session, refs)
