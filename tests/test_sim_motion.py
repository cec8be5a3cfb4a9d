"""Motion behaviour of one simulated Whistle on a ManualClock: the heartbeat consumer's 0x6007 actions,
the timestamped motor events, ST refused in speed mode, a jog in UM=5, motion status."""

from __future__ import annotations

import pytest
from test_sim_drive import EMCY, HOST, assign, hx, motor_on, new_drive, query, reply, run

from sherpa_cli.elmo.codec import encode_execute
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.drive import UNGUARDED_MO
from sherpa_cli.sim.interpreter import EC_NOT_IN_THIS_UM


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


def jogging_with_dead_man(clock, action: int, **settings):
    drive = new_drive(clock, settings=SimSettings(**settings))
    drive.od_write(0x6007, 0, action)
    drive.od_write(0x1029, 1, 1)  # stay operational so the interpreter can be asked
    drive.od_write(0x1016, 1, HOST << 16 | 200)
    assign(drive, "UM", 0, 2)
    assign(drive, "SD", 0, 20000)
    assign(drive, "JV", 0, 10000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    drive.receive(0x700 + HOST, hx("05"))
    run(drive, clock, 0.5)  # at speed, then the heartbeat is 500 ms old: tripped at 200 ms
    assert drive.pop_frames() == [(EMCY, hx("30 81 11 00 00 00 00 00"))]  # EMCY 0x8130 in every case
    return drive


@pytest.mark.parametrize("action", [1, 2])
def test_loss_action_1_and_2_switch_the_motor_off_at_once_and_record_when(clock, action):
    t_heartbeat = clock.now() + 0.5  # motor_on ran 0.5 s before the heartbeat
    drive = jogging_with_dead_man(clock, action)
    assert query(drive, "MO") == 0 and query(drive, "MF") == 0x800
    events = [(round(t - t_heartbeat, 3), text) for t, text in drive.events if t >= t_heartbeat]
    assert events == [(0.0, "BG: UM=2, JV=10000"), (0.2, f"heartbeat lost (0x6007={action})"), (0.2, f"motor off: heartbeat lost, 0x6007={action}")]


def test_loss_action_0_only_reports(clock):
    drive = jogging_with_dead_man(clock, 0)
    assert query(drive, "MO") == 1 and query(drive, "MF") == 0 and query(drive, "VX") == 10000
    assert [text for _, text in drive.events][-1] == "heartbeat lost (0x6007=0)"


def test_loss_action_3_decelerates_with_sd_then_switches_off(clock):
    drive = new_drive(clock)
    drive.od_write(0x6007, 0, 3)
    drive.od_write(0x1029, 1, 1)
    drive.od_write(0x1016, 1, HOST << 16 | 200)
    assign(drive, "UM", 0, 2)
    assign(drive, "SD", 0, 20000)
    assign(drive, "JV", 0, 10000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.3)
    drive.receive(0x700 + HOST, hx("05"))
    t_hb = clock.now()
    run(drive, clock, 0.25)  # tripped at 0.2 s; 10000 cnt/s at 20000 cnt/s^2 needs 0.5 s to stop
    assert drive.pop_frames() == [(EMCY, hx("30 81 11 00 00 00 00 00"))]
    assert query(drive, "MO") == 1 and 0 < query(drive, "VX") < 10000
    run(drive, clock, 0.5)
    assert query(drive, "MO") == 0 and query(drive, "MF") == 0x800
    (off,) = [(t, text) for t, text in drive.events if text.startswith("motor off")]
    assert off[1] == "motor off: heartbeat lost, 0x6007=3 (quick stop done)"
    assert off[0] - t_hb == pytest.approx(0.7, abs=0.002)


def test_motor_events_record_mo_switching_and_bg(clock):
    drive = new_drive(clock)
    assign(drive, "JV", 0, 500)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.1)
    assign(drive, "MO", 0, 0)
    assert [text for _, text in drive.events] == [
        "motor on: MO=1",
        # the drive itself is not armed here: the simulator says so (the tool's invariant)
        "motor on without an armed dead-man: 0x1016:1 host 0 0 ms, no heartbeat heard since armed, 0x6007=1",
        "BG: UM=5, JV=500", "motor off: MO=0"]
    assert drive.unguarded_motor_on == 1


def test_a_motor_on_under_an_armed_and_fed_consumer_is_not_flagged(clock):
    drive = new_drive(clock)
    drive.od_write(0x1016, 1, 126 << 16 | 500)
    drive.receive(0x77E, bytes([5]))  # the host's first heartbeat: the consumer watches from here
    motor_on(drive, clock)
    assert drive.unguarded_motor_on == 0
    texts = [text for _, text in drive.events]
    assert texts[0] == "motor on: MO=1" and not [t for t in texts if t.startswith(UNGUARDED_MO)], texts


def test_jog_in_position_mode_then_a_move_again(clock):
    drive = new_drive(clock)
    assign(drive, "AC", 0, 1_000_000)
    assign(drive, "DC", 0, 1_000_000)
    assign(drive, "JV", 0, 1000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.5)
    assert 480 <= query(drive, "PX") <= 500 and query(drive, "VX") == 1000
    assert query(drive, "MS") == 2  # the profiler is busy while jogging
    assign(drive, "PA", 0, 0)  # a PA after a jog: the next BG is a move again
    reply(drive, encode_execute("BG"))
    run(drive, clock, 1.0)
    assert query(drive, "PX") == 0 and query(drive, "MS") == 0


def test_st_is_refused_in_speed_mode_when_set_so(clock):
    drive = new_drive(clock, settings=SimSettings(st_refused_in_speed_mode=True))
    assign(drive, "UM", 0, 2)
    assign(drive, "JV", 0, 1000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.2)
    answer = reply(drive, encode_execute("ST"))
    assert not answer.ok and answer.error_code == EC_NOT_IN_THIS_UM
    assign(drive, "JV", 0, 0)  # the way [BLISS] stops a jog
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.2)
    assert query(drive, "VX") == 0 and query(drive, "MO") == 1


def test_st_is_accepted_in_speed_mode_by_default_and_in_position_mode_always(clock):
    for um, settings in ((2, SimSettings()), (5, SimSettings(st_refused_in_speed_mode=True))):
        drive = new_drive(clock, settings=settings)
        assign(drive, "UM", 0, um)
        motor_on(drive, clock)
        assert reply(drive, encode_execute("ST")).ok


def test_stop_switch_stops_a_torque_jog(clock):
    # seed C.1.1: in torque mode no position limit acts, but the stop switches do
    drive = new_drive(clock)
    assign(drive, "UM", 0, 1)
    assign(drive, "IL", 4, 21)
    assign(drive, "TC", 0, 0.5)
    drive.set_input(4, True, +1)  # the joint is at its high end switch
    motor_on(drive, clock)
    run(drive, clock, 0.2)
    assert query(drive, "VX") == 0 and query(drive, "PX") == 0
    assert query(drive, "SR") & 1 << 28  # stopped by a limit


def test_a_trip_is_kept_in_the_error_field(clock):
    drive = jogging_with_dead_man(clock, 2)
    assert drive.od_read(0x1003, 1) & 0xFFFF == 0x8130
