"""One simulated Whistle at CAN-frame level: NMT, interpreter reply rules, motor model, faults.

Frames are compared byte for byte; time only moves through a ManualClock.
"""

from __future__ import annotations

import math

import pytest

from sherpa_cli.elmo.codec import decode_reply, encode_execute, encode_query, encode_set
from sherpa_cli.elmo.faults import decode_emcy, decode_sr
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.od import ABORT_NO_OBJECT, ABORT_READ_ONLY, ODError

NODE = 3
RPDO2, TPDO2, EMCY, HB = 0x300 + NODE, 0x280 + NODE, 0x80 + NODE, 0x700 + NODE
HOST = 100


def hx(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


def new_drive(clock: ManualClock, *, start: bool = True, **kwargs) -> SimDrive:
    settings = kwargs.pop("settings", SimSettings())
    drive = SimDrive(NODE, clock=clock, settings=settings, serial=0x1234, **kwargs)
    if start:
        drive.receive(0x000, bytes([0x01, NODE]))
    drive.pop_frames()
    return drive


def send(drive: SimDrive, frame: bytes) -> list[tuple[int, bytes]]:
    drive.receive(RPDO2, frame)
    return drive.pop_frames()


def reply(drive: SimDrive, frame: bytes):
    frames = send(drive, frame)
    assert [can_id for can_id, _ in frames] == [TPDO2], frames
    return decode_reply(frames[0][1])


def query(drive: SimDrive, letters: str, index: int = 0):
    answer = reply(drive, encode_query(letters, index))
    assert answer.ok, answer
    return answer.value


def assign(drive: SimDrive, letters: str, index: int, value) -> None:
    answer = reply(drive, encode_set(letters, index, value))
    assert answer.ok, answer


def run(drive: SimDrive, clock: ManualClock, seconds: float, step: float = 0.01) -> None:
    for _ in range(round(seconds / step)):
        clock.advance(step)
        drive.tick()


def motor_on(drive: SimDrive, clock: ManualClock) -> None:
    assign(drive, "MO", 0, 1)
    run(drive, clock, 0.5)


# -- NMT and boot -------------------------------------------------------------------------------

def test_boot_up_frame_then_pre_operational(clock):
    drive = SimDrive(NODE, clock=clock, serial=1)
    assert drive.pop_frames() == [(0x703, hx("00"))]
    assert drive.nmt_state == 0x7F


def test_interpreter_ignored_before_nmt_start(clock):
    drive = new_drive(clock, start=False)
    assert send(drive, hx("41 43 00 00")) == []
    drive.receive(0x000, bytes([0x01, 0]))  # node 0 = all nodes
    assert send(drive, hx("41 43 00 00")) == [(TPDO2, hx("41 43 00 00 A0 86 01 00"))]
    drive.receive(0x000, bytes([0x02, NODE]))
    assert send(drive, hx("41 43 00 00")) == []


def test_nmt_for_another_node_is_not_recorded(clock):
    drive = new_drive(clock, start=False)
    drive.receive(0x000, bytes([0x01, NODE + 1]))
    assert drive.nmt_state == 0x7F
    assert drive.received == []


def test_heartbeat_producer_reports_nmt_state(clock):
    drive = new_drive(clock, start=False, settings=SimSettings(heartbeat_ms=100))
    run(drive, clock, 0.1)
    assert drive.pop_frames() == [(HB, hx("7F"))]
    drive.receive(0x000, bytes([0x01, NODE]))
    run(drive, clock, 0.2)
    assert drive.pop_frames() == [(HB, hx("05")), (HB, hx("05"))]
    drive.od_write(0x1017, 0, 0)
    run(drive, clock, 0.5)
    assert drive.pop_frames() == []


# -- reply rules --------------------------------------------------------------------------------

def test_query_returns_factory_value_in_short_and_long_form(clock):
    drive = new_drive(clock)
    expected = [(TPDO2, hx("41 43 00 00 A0 86 01 00"))]  # AC = 100000
    assert send(drive, hx("41 43 00 00")) == expected
    assert send(drive, hx("41 43 00 40 00 00 00 00")) == expected
    assert query(drive, "UM") == 5
    assert query(drive, "IL", 1) == 4


def test_set_is_echoed_and_stored(clock):
    drive = new_drive(clock)
    assert send(drive, hx("41 43 00 00 F0 49 02 00")) == [(TPDO2, hx("41 43 00 00 F0 49 02 00"))]
    assert query(drive, "AC") == 150000
    assert send(drive, hx("43 4C 01 80 00 00 80 3F")) == [(TPDO2, hx("43 4C 01 80 00 00 80 3F"))]
    assert send(drive, hx("43 4C 01 00")) == [(TPDO2, hx("43 4C 01 80 00 00 80 3F"))]


def test_echo_sets_false_is_silent_but_still_replies_errors(clock):
    drive = new_drive(clock, settings=SimSettings(echo_sets=False))
    assert send(drive, hx("41 43 00 00 F0 49 02 00")) == []
    assert query(drive, "AC") == 150000
    assert send(drive, hx("5A 5A 00 00 01 00 00 00")) == [(TPDO2, hx("5A 5A 00 40 02 00 00 00"))]


@pytest.mark.parametrize(("frame", "code"), [
    ("5A 5A 00 00", 2),  # unknown command
    ("49 4C 07 00 15 00 00 00", 3),  # IL[7] on a 6-input drive
    ("41 43 05 00", 3),  # index on a scalar command
    ("55 4D 00 00 03 00 00 00", 21),  # UM=3: the model has no stepper mode
    ("43 4C 01 80 00 00 30 41", 21),  # CL[1]=11.0 > MC/2
    ("56 58 00 00 05 00 00 00", 23),  # VX is read-only
])
def test_error_codes(clock, frame, code):
    drive = new_drive(clock)
    answer = reply(drive, hx(frame))
    assert answer.error_code == code
    assert query(drive, "EC") == code


def test_motor_off_parameter_with_motor_on_is_refused(clock):
    drive = new_drive(clock)
    motor_on(drive, clock)
    assert send(drive, encode_set("LL", 3, -240)) == [(TPDO2, hx("4C 4C 03 40 39 00 00 00"))]
    assert query(drive, "LL", 3) == -1_000_000_000
    assert send(drive, hx("53 56 00 00")) == [(TPDO2, hx("53 56 00 40 39 00 00 00"))]
    assert drive.save_count == 0 and drive.flash == {}


def test_bg_with_motor_off_is_refused(clock):
    drive = new_drive(clock)
    assert send(drive, hx("42 47 00 00")) == [(TPDO2, hx("42 47 00 40 3A 00 00 00"))]


def test_mo_settle_window_ignores_requests(clock):
    drive = new_drive(clock)
    assert send(drive, hx("4D 4F 00 00 01 00 00 00")) == [(TPDO2, hx("4D 4F 00 00 01 00 00 00"))]
    run(drive, clock, 0.49)
    assert send(drive, hx("4D 4F 00 00")) == []
    run(drive, clock, 0.01)
    assert send(drive, hx("4D 4F 00 00")) == [(TPDO2, hx("4D 4F 00 00 01 00 00 00"))]


# -- flash ---------------------------------------------------------------------------------------

def test_sv_counts_saves_and_blacks_out_can(clock):
    drive = new_drive(clock)
    assign(drive, "LL", 3, -240)
    assert send(drive, hx("53 56 00 00")) == [(TPDO2, hx("53 56 00 00 00 00 00 00"))]
    assert drive.save_count == 1 and drive.flash["LL[3]"] == -240
    run(drive, clock, 0.29)
    lost_frame = hx("4C 4C 03 00")
    assert send(drive, lost_frame) == []
    assert drive.lost == [(pytest.approx(0.29), RPDO2, lost_frame)]
    assert drive.received[-1] == drive.lost[-1]
    run(drive, clock, 0.01)
    assert query(drive, "LL", 3) == -240


def test_unsaved_values_are_lost_on_reset_saved_ones_survive(clock):
    drive = new_drive(clock)
    assign(drive, "HL", 3, 240)
    send(drive, hx("53 56 00 00"))
    run(drive, clock, 0.3)
    assign(drive, "LL", 3, -240)
    drive.receive(0x000, bytes([0x81, NODE]))
    assert drive.pop_frames() == [(HB, hx("00"))]
    assert send(drive, encode_query("HL", 3)) == []  # pre-operational again
    drive.receive(0x000, bytes([0x01, NODE]))
    assert query(drive, "HL", 3) == 240
    assert query(drive, "LL", 3) == -1_000_000_000
    # the caller persists flash and save_count across power cycles
    again = new_drive(clock, flash=drive.flash, save_count=drive.save_count)
    assert query(again, "HL", 3) == 240 and again.save_count == 1


def test_ld_reloads_flash(clock):
    drive = new_drive(clock, flash={"AC": 5000})
    assign(drive, "AC", 0, 7000)
    reply(drive, encode_execute("LD"))
    assert query(drive, "AC") == 5000


def test_bad_flash_image_is_rejected(clock):
    with pytest.raises(ValueError, match="PX is not saved"):
        SimDrive(NODE, clock=clock, flash={"PX": 3})
    with pytest.raises(ValueError, match="0x1029:1"):
        SimDrive(NODE, clock=clock, flash={"0x1029:1": 9})


# -- motor model ---------------------------------------------------------------------------------

def test_speed_mode_reaches_clipped_speed_and_integrates_px(clock):
    drive = new_drive(clock)
    assign(drive, "UM", 0, 2)
    assign(drive, "VH", 2, 20000)
    assign(drive, "JV", 0, 50000)
    motor_on(drive, clock)
    assert query(drive, "SR") >> 7 & 7 == 2
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.1)
    assert query(drive, "MS") == 2  # still accelerating at AC = 100000
    run(drive, clock, 0.9)
    assert query(drive, "VX") == 20000
    assert query(drive, "MS") == 1
    # 0.2 s ramp (2000 counts) + 0.8 s at 20000 cnt/s
    assert query(drive, "PX") == pytest.approx(18000, abs=1)
    assert isinstance(query(drive, "PX"), int)


def test_position_move_reaches_target_exactly(clock):
    drive = new_drive(clock)
    motor_on(drive, clock)
    assign(drive, "PA", 0, -3000)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.05)
    assert query(drive, "MS") == 2
    run(drive, clock, 2.0)
    assert query(drive, "PX") == -3000
    assert query(drive, "MS") == 0
    assert not decode_sr(query(drive, "SR")).stopped_by_limit


def test_position_target_is_clipped_to_vh3(clock):
    drive = new_drive(clock)
    assign(drive, "VH", 3, 5000)
    motor_on(drive, clock)
    assign(drive, "PA", 0, 8000)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 3.0)
    assert query(drive, "PX") == 5000
    sr = decode_sr(query(drive, "SR"))
    assert sr.stopped_by_limit and sr.motion_status == 0 and sr.motor_on and sr.unit_mode == 5


def test_relative_move_adds_to_position_once(clock):
    drive = new_drive(clock)
    assign(drive, "PX", 0, 500)
    motor_on(drive, clock)
    assign(drive, "PR", 0, 1000)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 1.0)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 1.0)
    assert query(drive, "PX") == 1500
    assert query(drive, "PA") == 1500
    assert drive.position == 1000  # PX=500 moved the counter, not the motor


def test_repeated_mo1_does_not_stop_a_motion(clock):
    drive = new_drive(clock)
    assign(drive, "UM", 0, 2)
    assign(drive, "JV", 0, 10000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.5)
    motor_on(drive, clock)
    assert query(drive, "VX") == 10000


def test_receive_reports_whether_the_frame_arrived(clock):
    drive = new_drive(clock)
    assert drive.receive(0x600 + NODE, hx("40 18 10 01 00 00 00 00")) is True
    assert drive.receive(0x600 + NODE + 1, hx("40 18 10 01 00 00 00 00")) is False
    send(drive, hx("53 56 00 00"))
    assert drive.receive(0x600 + NODE, hx("40 18 10 01 00 00 00 00")) is False


def test_leaving_hl3_trips_with_mf_and_emcy(clock):
    drive = new_drive(clock)
    assign(drive, "HL", 3, 1000)
    motor_on(drive, clock)
    assign(drive, "PA", 0, 5000)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 2.0)
    frames = drive.pop_frames()
    assert frames == [(EMCY, hx("80 86 01 00 00 00 00 00"))]
    assert query(drive, "MO") == 0
    assert query(drive, "MF") == 0x400000
    assert decode_sr(query(drive, "SR")).motor_failure
    assert 1000 < query(drive, "PX") < 1100
    assert query(drive, "PA") == 5000
    assert drive.od_read(0x1001, 0) == 0x01
    # still beyond HL[3]: MO=1 clears the fault (CiA 301: EMCY 0x0000 "error reset", before the
    # MO reply), then it trips again at once
    frames = send(drive, encode_set("MO", 0, 1))
    assert frames[0] == (EMCY, hx("00 00 00 00 00 00 00 00")) and frames[1][0] == TPDO2, frames
    run(drive, clock, 0.5)
    assert drive.pop_frames() == [(EMCY, hx("80 86 01 00 00 00 00 00"))]
    assign(drive, "HL", 3, 2000)
    frames = send(drive, encode_set("MO", 0, 1))  # MO=1 clears MF (and says so)
    assert [f[0] for f in frames] == [EMCY, TPDO2], frames
    run(drive, clock, 0.5)
    assert query(drive, "MF") == 0 and query(drive, "MO") == 1


def test_speed_outside_hl2_trips_in_speed_mode(clock):
    drive = new_drive(clock)
    assign(drive, "UM", 0, 2)
    assign(drive, "HL", 2, 5000)
    assign(drive, "JV", 0, 8000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 1.0)
    frames = drive.pop_frames()
    assert frames == [(EMCY, hx("81 84 01 00 00 00 00 00"))]
    assert query(drive, "MF") == 0x20000 and query(drive, "MO") == 0


def test_no_speed_or_position_limit_acts_in_torque_mode(clock):
    # seed C.1.1/C.1.2: "The position limits do not work in torque mode", "no velocity limit at all"
    # a free-running load: no friction, no back-EMF, 1 A = 10000 cnt/s^2 (sim/load.py)
    free = SimSettings(viscous=0.0, coulomb=0.0, back_emf=0.0, inertia=1 / (10000 / (3600 / (2 * math.pi))))
    drive = new_drive(clock, settings=free)
    assign(drive, "UM", 0, 1)
    assign(drive, "HL", 2, 5000)
    assign(drive, "LL", 3, -1000)
    assign(drive, "HL", 3, 1000)
    assign(drive, "TC", 0, 2.0)  # 2 A * 10000 cnt/s^2/A: HL[2] passed after 0.25 s, HL[3] after ~0.32 s
    motor_on(drive, clock)
    run(drive, clock, 1.0)
    assert drive.pop_frames() == []
    assert query(drive, "MF") == 0 and query(drive, "MO") == 1
    assert query(drive, "PX") > 5000 and query(drive, "VX") > 5000


def test_iq_reads_tc_in_torque_mode(clock):
    drive = new_drive(clock)
    assign(drive, "UM", 0, 1)
    assign(drive, "TC", 0, 0.5)
    motor_on(drive, clock)
    assert query(drive, "IQ") == 0.5
    assert 0 < query(drive, "VX") < 2500  # the default load's friction: slower than a free motor would be


def test_st_decelerates_with_sd(clock):
    drive = new_drive(clock)
    assign(drive, "UM", 0, 2)
    assign(drive, "JV", 0, 10000)
    assign(drive, "SD", 0, 20000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.5)
    reply(drive, encode_execute("ST"))
    run(drive, clock, 0.25)
    assert query(drive, "VX") == 5000
    run(drive, clock, 0.25)
    assert query(drive, "VX") == 0


def test_speed_gain_makes_one_motor_faster(clock):
    slow = new_drive(clock)
    fast = SimDrive(NODE + 1, clock=clock, speed_gain=1.1)
    fast.receive(0x000, bytes([0x01, 0]))
    slow.receive(0x000, bytes([0x01, 0]))
    for drive in (slow, fast):
        rpdo = 0x300 + drive.node
        for frame in (encode_set("UM", 0, 2), encode_set("JV", 0, 10000), encode_set("MO", 0, 1)):
            drive.receive(rpdo, frame)
    run(slow, clock, 0.5)
    fast.tick()
    for drive in (slow, fast):
        drive.receive(0x300 + drive.node, encode_execute("BG"))
    run(slow, clock, 1.0)
    fast.tick()
    assert fast.motor.v == pytest.approx(11000)
    assert slow.motor.v == pytest.approx(10000)


# -- inputs ---------------------------------------------------------------------------------------

def test_stop_switch_blocks_motion_toward_it_not_away(clock):
    drive = new_drive(clock)
    assign(drive, "IL", 1, 21)
    assign(drive, "UM", 0, 2)
    assign(drive, "JV", 0, 10000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.5)
    drive.set_input(1, True, direction=+1)
    run(drive, clock, 0.1)  # SD = 1e6: stops within 10 ms
    assert query(drive, "VX") == 0
    assert decode_sr(query(drive, "SR")).stopped_by_limit
    stopped_at = query(drive, "PX")
    reply(drive, encode_execute("BG"))  # toward the switch again: nothing moves
    run(drive, clock, 0.5)
    assert query(drive, "PX") == stopped_at
    assign(drive, "JV", 0, -10000)  # away from it
    reply(drive, encode_execute("BG"))
    run(drive, clock, 0.5)
    assert query(drive, "VX") == -10000
    assert query(drive, "PX") < stopped_at
    assert query(drive, "IP") == 1 << 16 | 1 << 0 | 1 << 8 | 1 << 9


def test_ignored_input_shows_in_ip_but_does_not_block(clock):
    drive = new_drive(clock)
    motor_on(drive, clock)
    drive.set_input(2, True, direction=+1)  # factory IL[2] = 4: ignore
    assert query(drive, "IP") == 1 << 17 | 1 << 1
    assign(drive, "PA", 0, 500)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 1.0)
    assert query(drive, "PX") == 500


def test_position_move_stops_at_switch(clock):
    drive = new_drive(clock)
    assign(drive, "IL", 3, 21)
    motor_on(drive, clock)

    def switch_at_2000(d: SimDrive) -> None:
        d.set_input(3, d.position >= 2000, direction=+1)

    drive.on_step = switch_at_2000
    assign(drive, "PA", 0, 10000)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 2.0)
    px = query(drive, "PX")
    assert 2000 < px <= 2201  # 20000 cnt/s at the switch, SD = 1e6: 200 counts to stop
    assert query(drive, "MS") == 1 and query(drive, "MO") == 1


def test_set_input_checks_its_arguments(clock):
    drive = new_drive(clock)
    with pytest.raises(ValueError):
        drive.set_input(7, True)
    with pytest.raises(ValueError):
        drive.set_input(1, True, direction=2)


# -- heartbeat consumer ---------------------------------------------------------------------------

def test_heartbeat_dead_man_stops_a_moving_motor(clock):
    drive = new_drive(clock)
    drive.od_write(0x1016, 1, HOST << 16 | 200)
    drive.od_write(0x1029, 1, 1)  # stay operational so the interpreter can be asked
    assign(drive, "UM", 0, 2)
    assign(drive, "JV", 0, 10000)
    motor_on(drive, clock)
    reply(drive, encode_execute("BG"))
    run(drive, clock, 1.0)  # no host heartbeat yet: monitoring has not started
    assert query(drive, "MO") == 1
    for _ in range(10):
        drive.receive(0x700 + HOST, hx("05"))
        run(drive, clock, 0.15)
    assert query(drive, "MO") == 1 and drive.pop_frames() == []
    run(drive, clock, 0.06)  # 210 ms since the last heartbeat
    assert drive.pop_frames() == [(EMCY, hx("30 81 11 00 00 00 00 00"))]
    assert query(drive, "MO") == 0 and query(drive, "VX") == 0
    assert query(drive, "MF") == 0x800
    assert "heartbeat" in decode_emcy(hx("30 81 11 00 00 00 00 00")).text


def test_heartbeat_loss_goes_pre_operational_by_default(clock):
    drive = new_drive(clock)
    drive.od_write(0x1016, 1, HOST << 16 | 100)
    drive.receive(0x700 + HOST, hx("05"))
    run(drive, clock, 0.2)
    assert drive.nmt_state == 0x7F
    assert drive.pop_frames() == [(EMCY, hx("30 81 11 00 00 00 00 00"))]
    assert drive.mf == 0  # motor was off: nothing to shut down


# -- object dictionary ----------------------------------------------------------------------------

def test_object_dictionary_identity_and_errors(clock):
    drive = new_drive(clock)
    assert drive.od_read(0x1018, 1) == 0x9A
    assert drive.od_read(0x1018, 4) == 0x1234
    assert drive.od_read(0x1008, 0) == "Whistle"
    assert drive.od_read(0x1009, 0) == "0x1FF6B"
    assert drive.od_read(0x1000, 0) & 0xFFFF == 402
    with pytest.raises(ODError) as info:
        drive.od_write(0x1018, 1, 5)
    assert info.value.abort_code == ABORT_READ_ONLY
    with pytest.raises(ODError) as info:
        drive.od_read(0x2000, 0)
    assert info.value.abort_code == ABORT_NO_OBJECT
    drive.od_write(0x6007, 0, 2)
    assert drive.od_writes == [(0.0, 0x6007, 0, 2)]


def test_sv_saves_communication_objects(clock):
    drive = new_drive(clock)
    drive.od_write(0x1017, 0, 250)
    send(drive, hx("53 56 00 00"))
    drive.receive(0x000, bytes([0x81, 0]))
    assert drive.od_read(0x1017, 0) == 250
    assert drive.flash["0x1017:0"] == 250


# -- fault injection ------------------------------------------------------------------------------

def test_die_at_silences_the_drive(clock):
    drive = new_drive(clock, settings=SimSettings(die_at=1.0, heartbeat_ms=100))
    run(drive, clock, 0.99)
    assert len(drive.pop_frames()) == 9
    assert query(drive, "AC") == 100000
    run(drive, clock, 0.02)
    assert drive.dead
    assert send(drive, hx("41 43 00 00")) == []
    run(drive, clock, 1.0)
    assert drive.pop_frames() == []
    assert drive.lost[-1][1:] == (RPDO2, hx("41 43 00 00"))


def test_reboot_at_reboots_once(clock):
    drive = new_drive(clock, settings=SimSettings(reboot_at=0.5))
    assign(drive, "AC", 0, 7000)
    run(drive, clock, 2.0)
    assert drive.pop_frames() == [(HB, hx("00"))]
    assert drive.boots == 2 and drive.nmt_state == 0x7F
    drive.receive(0x000, bytes([0x01, NODE]))
    assert query(drive, "AC") == 100000


def test_reply_latency_holds_the_reply(clock):
    drive = new_drive(clock, settings=SimSettings(reply_latency_s=0.05))
    assert send(drive, hx("41 43 00 00")) == []
    clock.advance(0.049)
    drive.tick()
    assert drive.pop_frames() == []
    clock.advance(0.001)
    drive.tick()
    assert drive.pop_frames() == [(TPDO2, hx("41 43 00 00 A0 86 01 00"))]


def test_drop_probability_one_loses_everything(clock):
    drive = new_drive(clock, settings=SimSettings(drop_probability=1.0))
    assert drive.nmt_state == 0x7F  # even the NMT start was lost
    assert len(drive.lost) == 1


def test_received_records_every_frame_addressed_to_the_drive(clock):
    drive = new_drive(clock)
    clock.advance(0.25)
    drive.receive(RPDO2, hx("41 43 00 00"))
    drive.receive(0x300 + NODE + 1, hx("41 43 00 00"))  # another drive's RPDO2
    assert drive.received == [(0.0, 0x000, bytes([0x01, NODE])), (0.25, RPDO2, hx("41 43 00 00"))]


def test_the_frame_record_stays_bounded(monkeypatch):
    from sherpa_cli.sim.drive import FrameRecord

    monkeypatch.setattr(FrameRecord, "limit", 10)
    record = FrameRecord()
    for i in range(25):
        record.append(i)
    assert len(record) <= 10 and record[-1] == 24 and record == list(range(record[0], 25))


def test_a_stopped_node_sends_no_emcy_and_0x1003_0_written_0_clears_the_history(clock):
    """CiA 301: no EMCY in NMT Stopped (the error is still stored); 0x1003:0 := 0 deletes
    the stored errors, any other value is refused."""
    from sherpa_cli.sim.od import ODError

    drive = new_drive(clock)
    assign(drive, "HL", 3, 1000)
    motor_on(drive, clock)
    drive.receive(0x000, bytes([0x02, NODE]))  # NMT Stopped
    drive.pop_frames()
    drive._emcy(0x8680, 0x01)  # a trip while Stopped
    assert drive.pop_frames() == []  # stored, not sent
    assert drive.od_read(0x1003, 0) == 1
    with pytest.raises(ODError):
        drive.od_write(0x1003, 0, 1)
    drive.od_write(0x1003, 0, 0)
    assert drive.od_read(0x1003, 0) == 0
