"""The simulated Whistle's PVT mode (sim/pvt.py) at frame level on a ManualClock: set up the way
elmo/pvt.py's settings describe, a queue played one row per period, the PVT emergencies."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.elmo.codec import decode_reply, encode_execute, encode_set
from sherpa_cli.elmo.faults import decode_emcy
from sherpa_cli.elmo.pvt import (
    PvtEventKind,
    PvtSettings,
    encode_record,
    interpreter_setup,
    pdo_setup,
    pvt_event,
    start_steps,
)
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.od import ODError
from sherpa_cli.sim.pvt import Segment

NODE = 3
RPDO2, TPDO2, EMCY = 0x300 + NODE, 0x280 + NODE, 0x80 + NODE
PERIOD = 0.01


def interp(drive: SimDrive, frame: bytes) -> None:
    drive.receive(RPDO2, frame)
    replies = [decode_reply(data) for can_id, data in drive.pop_frames() if can_id == TPDO2]
    assert replies and replies[-1].ok, replies


def pvt_drive(clock: ManualClock, settings: PvtSettings | None = None, sim: SimSettings | None = None) -> SimDrive:
    s = settings or PvtSettings()
    drive = SimDrive(NODE, clock=clock, settings=sim or SimSettings(mo_settle_s=0.0))
    drive.receive(0x000, bytes([0x01, NODE]))
    for step in interpreter_setup(s):
        interp(drive, encode_set(step.letters, step.index, step.value))
    for w in pdo_setup(s, NODE):
        drive.od_write(w.index, w.sub, w.value)
    drive.pop_frames()
    return drive


def start(drive: SimDrive, settings: PvtSettings | None = None) -> None:
    s = settings or PvtSettings()
    interp(drive, encode_set("MO", 0, 1))
    for step in start_steps(s):
        interp(drive, encode_set(step.letters, step.index, step.value))
    interp(drive, encode_execute("BG"))


def record(drive: SimDrive, position: int, velocity: int) -> None:
    drive.receive(0x400 + NODE, encode_record(position, velocity))


def step(clock: ManualClock, drive: SimDrive, seconds: float = PERIOD) -> list:
    clock.advance(seconds)
    drive.advance_to(clock.now())
    return [pvt_event(decode_emcy(data)) for can_id, data in drive.pop_frames() if can_id == EMCY]


def test_a_constant_velocity_stream_tracks_within_a_count():
    clock = ManualClock()
    drive = pvt_drive(clock)
    v = 2000  # cnt/s: 20 counts a period
    rows = [(round(v * PERIOD * k), v) for k in range(1, 301)]
    for position, velocity in rows[:32]:
        record(drive, position, velocity)
    start(drive)
    sent = 32
    worst = 0.0
    for k in range(1, len(rows) + 1):
        if sent < len(rows):
            record(drive, *rows[sent])
            sent += 1
        events = step(clock, drive)
        if sent < len(rows) - PvtSettings().low_threshold:
            assert events == []  # a fed queue raises nothing; it runs low and empty at the stream's end
        expected = rows[k - 1][0]
        worst = max(worst, abs(drive.px - expected))
        assert drive.motor_on
    assert worst <= 1
    assert drive.pvt_records == len(rows)


def test_between_rows_the_motion_follows_the_cubic_of_both_ends():
    clock = ManualClock()
    drive = pvt_drive(clock)
    record(drive, 100, 0)  # from rest to 100 counts at rest in one period: the smoothstep
    record(drive, 100, 0)
    start(drive)
    step(clock, drive, PERIOD / 2)
    assert drive.position == pytest.approx(50, abs=0.5)
    assert drive.motor.v == pytest.approx(1.5 * 100 / PERIOD, rel=0.01)  # the cubic's peak speed, mid-row
    step(clock, drive, PERIOD / 2)
    assert drive.px == 100


def test_underflow_stops_the_motor_with_dc_and_sends_motion_terminated():
    clock = ManualClock()
    drive = pvt_drive(clock, PvtSettings(low_threshold=3))
    for k in range(1, 9):
        record(drive, 50 * k, 5000)
    start(drive)
    events = []
    for _ in range(20):
        events += [e for e in step(clock, drive) if e is not None]
    kinds = [e.kind for e in events]
    assert kinds == [PvtEventKind.QUEUE_LOW, PvtEventKind.MOTION_TERMINATED]
    assert events[1].underflow and events[1].field2 == 3
    assert drive.motor_on  # the drive stopped the motion, not the motor
    stop_at = drive.events[-1]
    assert "PVT underflow after 8 rows" in stop_at[1]
    assert stop_at[0] == pytest.approx(8 * PERIOD)  # when the eighth row was played out
    # decelerated from 5000 cnt/s at DC (100000 cnt/s^2 by default): 50 ms, 125 counts past the last row
    for _ in range(10):
        step(clock, drive)
    assert drive.motor.v == 0
    assert drive.px == pytest.approx(400 + 5000**2 / (2 * 100_000), abs=2)


def test_queue_low_arrives_while_rows_are_still_queued():
    clock = ManualClock()
    drive = pvt_drive(clock, PvtSettings(low_threshold=4))
    for k in range(1, 11):
        record(drive, 10 * k, 1000)
    start(drive)
    for _ in range(10):
        events = [e for e in step(clock, drive) if e is not None]
        if events:
            assert [e.kind for e in events] == [PvtEventKind.QUEUE_LOW]
            assert len(drive.pvt.queue) == 3 and drive.pvt.active  # below MP[4]=4, not empty
            break
    else:
        pytest.fail("no queue-low EMCY")
    record(drive, 110, 1000)  # refilled past the threshold and drained again: a second EMCY
    for _ in range(4):
        record(drive, 120, 0)
    kinds = []
    for _ in range(6):
        kinds += [e.kind for e in step(clock, drive) if e is not None]
    assert kinds == [PvtEventKind.QUEUE_LOW]


def test_queue_full_is_an_emcy_naming_the_row():
    clock = ManualClock()
    drive = pvt_drive(clock, PvtSettings(queue_size=8, low_threshold=2))
    for k in range(8):
        record(drive, k, 0)
    assert drive.pop_frames() == []
    record(drive, 9, 0)
    [(can_id, data)] = drive.pop_frames()
    event = pvt_event(decode_emcy(data))
    assert can_id == EMCY and event is not None and event.kind is PvtEventKind.QUEUE_FULL and event.field1 == 1
    assert data.hex(" ") == "00 ff 81 34 01 00 00 00"


def test_records_reach_the_queue_only_on_a_mapped_rpdo():
    clock = ManualClock()
    drive = SimDrive(NODE, clock=clock, settings=SimSettings(mo_settle_s=0.0))
    drive.receive(0x000, bytes([0x01, NODE]))
    record(drive, 10, 0)
    assert drive.pvt_records == 0 and not drive.pvt.queue
    for w in pdo_setup(PvtSettings(), NODE):
        drive.od_write(w.index, w.sub, w.value)
    record(drive, 10, 0)
    assert drive.pvt_records == 1


def test_rpdo_mapping_keeps_cia301_rules():
    clock = ManualClock()
    drive = SimDrive(NODE, clock=clock)
    assert drive.od_read(0x1402, 1) == 0x400 + NODE and drive.od_read(0x1602, 0) == 0
    with pytest.raises(ODError):
        drive.od_write(0x1602, 1, 0x20010040)  # the PDO is valid
    drive.od_write(0x1402, 1, 0x80000000 | 0x400 + NODE)
    with pytest.raises(ODError):
        drive.od_write(0x1602, 1, 0x60640020)  # only the PVT record maps to an RPDO
    drive.od_write(0x1602, 1, 0x20010040)
    drive.od_write(0x1602, 0, 1)
    with pytest.raises(ODError):
        drive.od_write(0x1602, 2, 0x20010040)  # an entry while the count is not 0
    drive.od_write(0x1402, 1, 0x400 + NODE)
    assert drive.rpdos.record_cob(0x400 + NODE)
    with pytest.raises(ODError):
        drive.od_write(0x1402, 1, 0x400 + NODE + 1)  # another CAN-ID while valid


def test_st_and_motor_off_end_the_pvt_motion():
    clock = ManualClock()
    drive = pvt_drive(clock)
    for k in range(1, 20):
        record(drive, 20 * k, 2000)
    start(drive)
    step(clock, drive)
    interp(drive, encode_execute("ST"))
    assert not drive.pvt.active and not drive.pvt.queue
    assert step(clock, drive) == []  # no underflow: the host stopped it
    start(drive)  # nothing queued: the start underflows at once
    assert [e.kind for e in step(clock, drive, 0)] == []  # sent with the BG's frames, drained by interp
    drive2 = pvt_drive(clock)
    for k in range(1, 20):
        record(drive2, 20 * k, 2000)
    start(drive2)
    interp(drive2, encode_set("MO", 0, 0))
    assert not drive2.pvt.active and not drive2.motor_on


def test_a_write_pointer_outside_the_rows_is_refused_at_the_start():
    clock = ManualClock()
    drive = pvt_drive(clock, PvtSettings())
    interp(drive, encode_set("MP", 6, 65))
    interp(drive, encode_set("MO", 0, 1))
    interp(drive, encode_set("PV", 0, 1))
    drive.receive(RPDO2, encode_execute("BG"))
    emcys = [pvt_event(decode_emcy(d)) for c, d in drive.pop_frames() if c == EMCY]
    assert [e.kind for e in emcys if e] == [PvtEventKind.BAD_SETUP]
    assert not drive.pvt.active


@pytest.mark.parametrize("command", [0x81, 0x82])  # reset node, reset communication
def test_a_reset_puts_the_rpdos_back_and_ends_the_pvt_motion(command):
    clock = ManualClock()
    drive = pvt_drive(clock)
    for k in range(1, 20):
        record(drive, 20 * k, 2000)
    start(drive)
    step(clock, drive)
    drive.receive(0x000, bytes([command, NODE]))
    drive.advance_to(clock.now())
    assert not drive.pvt.active and not drive.pvt.queue
    assert (drive.od_read(0x1602, 0), drive.od_read(0x1602, 1)) == (0, 0)
    assert not drive.rpdos.record_cob(0x400 + NODE)


FINITE = st.floats(-1e6, 1e6, allow_nan=False)


@given(FINITE, FINITE, FINITE, FINITE, st.floats(1e-3, 1.0), st.floats(-10.0, 10.0))
def test_a_segment_meets_both_rows_position_and_velocity(x0, v0, x1, v1, period, t0):
    seg = Segment(t0, x0, v0, x1, v1, period)
    scale = 1 + abs(x0) + abs(x1) + (abs(v0) + abs(v1)) * period
    for (x, v), (xe, ve) in ((seg.at(t0), (x0, v0)), (seg.at(t0 + period), (x1, v1))):
        assert x == pytest.approx(xe, abs=1e-9 * scale)
        assert v == pytest.approx(ve, abs=1e-9 * scale / period)


def test_a_segment_of_constant_velocity_is_a_straight_line():
    seg = Segment(0.0, 0.0, 1000.0, 10.0, 1000.0, 0.01)
    assert seg.at(0.005) == pytest.approx((5.0, 1000.0))
