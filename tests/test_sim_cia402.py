"""The simulated CiA 402 drive (sherpa_cli/sim/cia402.py) on its own ManualClock: NMT and identity, the
power state machine, a PP move in its trapezoid time, halt, PV, quick stop, the heartbeat loss per
0x6007 with its EMCY, fault and fault reset."""

from __future__ import annotations

import struct

import pytest

from sherpa_cli.cia402 import protocol as p
from sherpa_cli.cia402.protocol import State
from sherpa_cli.sim.cia402 import SimCia402Drive
from sherpa_cli.sim.clock import ManualClock
from sherpa_cli.sim.od import ODError

NODE, HOST = 12, 0x7D
EMCY = 0x80 + NODE


def make() -> tuple[SimCia402Drive, ManualClock]:
    clock = ManualClock()
    drive = SimCia402Drive(NODE, clock=clock)
    return drive, clock


def run(drive: SimCia402Drive, clock: ManualClock, seconds: float, step: float = 0.01) -> None:
    for _ in range(round(seconds / step)):
        clock.advance(step)
        drive.tick()


def arm_deadman(drive: SimCia402Drive, action: int, timeout_ms: int = 100) -> None:
    """As motion/guard.py arms it: 0x6007, 0x1029:1, 0x1016:1 (host << 16 | ms), then the host's beat."""
    drive.od_write(0x6007, 0, action)
    drive.od_write(0x1029, 1, 2)
    drive.od_write(0x1016, 1, HOST << 16 | timeout_ms)
    drive.receive(0x700 + HOST, b"\x05")


def enable(drive: SimCia402Drive, mode: int = 1) -> None:
    drive.od_write(p.MODES_OF_OPERATION, 0, mode)
    for cw in (0x06, 0x07, 0x0F | (p.CW_HALT if mode == 3 else 0)):
        drive.od_write(p.CONTROLWORD, 0, cw)
    assert drive.state is State.OPERATION_ENABLED


def emcy_codes(drive: SimCia402Drive) -> list[int]:
    return [struct.unpack_from("<H", data)[0] for can_id, data in drive.pop_frames() if can_id == EMCY]


def test_boot_identity_and_device_type():
    drive, _ = make()
    assert drive.pop_frames() == [(0x700 + NODE, b"\x00")]  # boot-up
    assert drive.od_read(0x1000, 0) == 0x00020192  # CiA 402, servo drive
    assert drive.od_read(0x1018, 0) == 4 and drive.od_read(0x1018, 4) == 1
    assert drive.state is State.SWITCH_ON_DISABLED
    assert p.state_of(drive.od_read(p.STATUSWORD, 0)) is State.SWITCH_ON_DISABLED


def test_nmt_reset_communication_puts_the_communication_objects_back():
    drive, _ = make()
    drive.od_write(0x1017, 0, 50)
    drive.od_write(p.PROFILE_VELOCITY, 0, 1234)
    drive.pop_frames()
    drive.receive(0x000, bytes([0x82, NODE]))  # reset communication
    assert drive.od_read(0x1017, 0) == 0
    assert drive.od_read(p.PROFILE_VELOCITY, 0) == 1234  # the application keeps its objects
    assert drive.pop_frames() == [(0x700 + NODE, b"\x00")]
    drive.receive(0x000, bytes([0x01, NODE]))
    assert drive.nmt_state == 0x05
    drive.receive(0x000, bytes([0x81, NODE]))  # reset node: everything back
    assert drive.od_read(p.PROFILE_VELOCITY, 0) == 100_000


def test_heartbeat_producer():
    drive, clock = make()
    drive.pop_frames()
    drive.od_write(0x1017, 0, 100)
    run(drive, clock, 0.35)
    assert drive.pop_frames() == [(0x700 + NODE, b"\x7f")] * 3  # Pre-operational


def test_the_power_state_machine_and_the_motor():
    drive, _ = make()
    drive.od_write(p.MODES_OF_OPERATION, 0, 1)
    assert drive.od_read(p.MODES_DISPLAY, 0) == 1
    drive.od_write(p.CONTROLWORD, 0, 0x0F)  # enable operation from Switch on disabled: no transition
    assert drive.state is State.SWITCH_ON_DISABLED and not drive.motor_on
    drive.od_write(p.CONTROLWORD, 0, 0x06)
    assert drive.od_read(p.STATUSWORD, 0) & 0x6F == 0x21
    drive.od_write(p.CONTROLWORD, 0, 0x07)
    drive.od_write(p.CONTROLWORD, 0, 0x0F)
    assert drive.state is State.OPERATION_ENABLED and drive.motor_on
    assert drive.od_read(p.STATUSWORD, 0) & 0x6F == 0x27
    drive.od_write(p.CONTROLWORD, 0, 0x06)
    assert drive.state is State.READY_TO_SWITCH_ON and not drive.motor_on


def test_a_mode_the_simulator_does_not_play_is_taken_shown_and_holds_the_motor_still():
    drive, clock = make()
    drive.od_write(p.MODES_OF_OPERATION, 0, 8)  # CSP: a drive is found in it, and it is put back
    assert drive.od_read(p.MODES_DISPLAY, 0) == 8
    enable(drive, 8)
    drive.od_write(p.TARGET_POSITION, 0, 5000)
    drive.od_write(p.CONTROLWORD, 0, 0x1F)
    run(drive, clock, 0.5)
    assert drive.od_read(p.POSITION_ACTUAL, 0) == 0
    with pytest.raises(ODError) as err:
        drive.od_write(p.MODES_OF_OPERATION, 0, 200)
    assert err.value.abort_code == 0x06090030


def test_a_mode_change_while_enabled_acts_at_once_pv_runs_its_old_target_velocity():
    """As a drive does: 0x6060 := PV in Operation enabled without halt runs to 0x60FF at once."""
    drive, clock = make()
    enable(drive)
    drive.od_write(p.TARGET_VELOCITY, 0, 500)  # left from an earlier jog
    drive.od_write(p.MODES_OF_OPERATION, 0, 3)
    run(drive, clock, 0.5)
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) == 500
    halted, clock = make()
    enable(halted)
    halted.od_write(p.TARGET_VELOCITY, 0, 500)
    halted.od_write(p.CONTROLWORD, 0, 0x010F)  # halt first: the new mode holds still
    halted.od_write(p.MODES_OF_OPERATION, 0, 3)
    run(halted, clock, 0.5)
    assert halted.od_read(p.VELOCITY_ACTUAL, 0) == 0 and halted.od_read(p.POSITION_ACTUAL, 0) == 0


def test_pp_move_arrives_in_the_trapezoid_time():
    drive, clock = make()
    enable(drive)
    for index, value in ((p.PROFILE_VELOCITY, 1000), (p.PROFILE_ACCELERATION, 10_000), (p.PROFILE_DECELERATION, 10_000),
                         (p.TARGET_POSITION, 10_000)):
        drive.od_write(index, 0, value)
    drive.od_write(p.CONTROLWORD, 0, 0x3F)
    assert drive.od_read(p.STATUSWORD, 0) & p.SW_SET_POINT_ACK
    assert not drive.od_read(p.STATUSWORD, 0) & p.SW_TARGET_REACHED
    drive.od_write(p.CONTROLWORD, 0, 0x0F)
    # bit 12 falls on the drive's next cycle after bit 4 fell, not with the write
    assert drive.od_read(p.STATUSWORD, 0) & p.SW_SET_POINT_ACK
    run(drive, clock, 0.01)
    assert not drive.od_read(p.STATUSWORD, 0) & p.SW_SET_POINT_ACK
    # 0.1 s up to 1000 counts/s (50 counts), 9.9 s at speed, 0.1 s down: 10.1 s
    run(drive, clock, 10.04)
    assert not drive.od_read(p.STATUSWORD, 0) & p.SW_TARGET_REACHED
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) > 0
    run(drive, clock, 0.07)
    assert drive.od_read(p.STATUSWORD, 0) & p.SW_TARGET_REACHED
    assert drive.od_read(p.POSITION_ACTUAL, 0) == 10_000


def test_a_set_point_without_change_immediately_waits_for_the_running_one():
    drive, clock = make()
    enable(drive)
    drive.od_write(p.PROFILE_VELOCITY, 0, 1000)
    drive.od_write(p.TARGET_POSITION, 0, 500)
    drive.od_write(p.CONTROLWORD, 0, 0x1F)
    drive.od_write(p.CONTROLWORD, 0, 0x0F)
    drive.od_write(p.TARGET_POSITION, 0, 0)
    drive.od_write(p.CONTROLWORD, 0, 0x1F)  # buffered
    run(drive, clock, 0.3)
    assert drive.od_read(p.POSITION_ACTUAL, 0) > 200  # still on its way to 500
    run(drive, clock, 2.0)
    assert drive.od_read(p.POSITION_ACTUAL, 0) == 0  # then back to 0


def test_halt_stops_from_motion_with_the_profile_deceleration():
    drive, clock = make()
    enable(drive)
    drive.od_write(p.PROFILE_VELOCITY, 0, 1000)
    drive.od_write(p.PROFILE_DECELERATION, 0, 10_000)
    drive.od_write(p.TARGET_POSITION, 0, 100_000)
    drive.od_write(p.CONTROLWORD, 0, 0x3F)
    run(drive, clock, 1.0)
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) == 1000
    drive.od_write(p.CONTROLWORD, 0, 0x10F)
    assert not drive.od_read(p.STATUSWORD, 0) & p.SW_TARGET_REACHED
    run(drive, clock, 0.11)  # 1000 / 10000 = 0.1 s
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) == 0
    assert drive.od_read(p.STATUSWORD, 0) & p.SW_TARGET_REACHED  # halted: target reached is speed 0
    stood = drive.od_read(p.POSITION_ACTUAL, 0)
    run(drive, clock, 0.5)
    assert drive.od_read(p.POSITION_ACTUAL, 0) == stood and drive.state is State.OPERATION_ENABLED


def test_pv_runs_when_halt_is_released():
    drive, clock = make()
    enable(drive, mode=3)
    drive.od_write(p.TARGET_VELOCITY, 0, -2000)
    run(drive, clock, 0.2)
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) == 0  # halted
    drive.od_write(p.CONTROLWORD, 0, 0x0F)
    run(drive, clock, 0.2)
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) == -2000
    assert drive.od_read(p.STATUSWORD, 0) & p.SW_TARGET_REACHED
    drive.od_write(p.CONTROLWORD, 0, 0x10F)
    run(drive, clock, 0.2)
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) == 0


@pytest.mark.parametrize(("action", "after", "code"), [
    (1, State.FAULT, 0x8130), (2, State.SWITCH_ON_DISABLED, 0), (3, State.SWITCH_ON_DISABLED, 0)])
def test_heartbeat_loss_ends_the_motion_per_0x6007(action, after, code):
    drive, clock = make()
    drive.od_write(p.QUICK_STOP_DECELERATION, 0, 10_000)
    arm_deadman(drive, action)
    enable(drive, mode=3)
    drive.od_write(p.TARGET_VELOCITY, 0, 1000)
    drive.od_write(p.CONTROLWORD, 0, 0x0F)
    assert drive.unguarded_motor_on == 0
    for _ in range(5):  # the host beats while it runs
        run(drive, clock, 0.05)
        drive.receive(0x700 + HOST, b"\x05")
    drive.pop_frames()
    assert drive.od_read(p.VELOCITY_ACTUAL, 0) == 1000
    run(drive, clock, 0.11)  # the host falls silent: 100 ms
    assert emcy_codes(drive) == [0x8130]
    if action == 3:
        assert drive.state is State.QUICK_STOP_ACTIVE and drive.motor_on  # on the quick stop ramp
        run(drive, clock, 0.12)
    assert drive.state is after and not drive.motor_on
    assert drive.od_read(p.ERROR_CODE, 0) == code
    assert drive.nmt_state == 0x04  # 0x1029:1 = 2: Stopped


def test_without_a_consumer_the_motor_on_is_counted_unguarded():
    drive, _ = make()
    enable(drive)
    assert drive.unguarded_motor_on == 1


def test_fault_and_fault_reset():
    drive, _ = make()
    enable(drive)
    drive.pop_frames()
    drive.fault(0x2310)
    assert drive.state is State.FAULT and not drive.motor_on
    assert drive.od_read(p.STATUSWORD, 0) & 0x4F == 0x08
    assert drive.od_read(p.ERROR_CODE, 0) == 0x2310
    assert emcy_codes(drive) == [0x2310]
    drive.od_write(p.CONTROLWORD, 0, 0x0F)
    assert drive.state is State.FAULT  # nothing but a fault reset leaves Fault
    drive.od_write(p.CONTROLWORD, 0, 0x80)  # rising edge of bit 7
    assert drive.state is State.SWITCH_ON_DISABLED
    assert drive.od_read(p.ERROR_CODE, 0) == 0
    assert emcy_codes(drive) == [0x0000]


def test_fault_reset_needs_a_rising_edge():
    drive, _ = make()
    drive.od_write(p.CONTROLWORD, 0, 0x80)
    drive.fault(0x1000)
    drive.od_write(p.CONTROLWORD, 0, 0x80)  # bit 7 was already up: no edge
    assert drive.state is State.FAULT
    drive.od_write(p.CONTROLWORD, 0, 0x00)
    drive.od_write(p.CONTROLWORD, 0, 0x80)
    assert drive.state is State.SWITCH_ON_DISABLED


def test_quick_stop_command_then_switch_on_disabled():
    drive, clock = make()
    enable(drive, mode=3)
    drive.od_write(p.QUICK_STOP_DECELERATION, 0, 20_000)
    drive.od_write(p.TARGET_VELOCITY, 0, 2000)
    drive.od_write(p.CONTROLWORD, 0, 0x0F)
    run(drive, clock, 0.5)
    drive.od_write(p.CONTROLWORD, 0, 0x02)
    assert drive.state is State.QUICK_STOP_ACTIVE
    run(drive, clock, 0.11)
    assert drive.state is State.SWITCH_ON_DISABLED and drive.od_read(p.VELOCITY_ACTUAL, 0) == 0


def test_ram_snapshot_round_trip():
    drive, clock = make()
    enable(drive)
    drive.od_write(p.PROFILE_VELOCITY, 0, 4321)
    saved = drive.ram_snapshot()
    other = SimCia402Drive(NODE, clock=clock)
    other.restore_ram(saved)
    assert other.state is State.OPERATION_ENABLED and other.motor_on
    assert other.od_read(p.PROFILE_VELOCITY, 0) == 4321
