"""Cia402Drive (sherpa_cli/cia402/drive.py) byte-exact: every SDO transfer of enable, move, stop and
disable against a recording fake node that plays the standard's state machine."""

from __future__ import annotations

import struct

import pytest

from sherpa_cli.cia402 import protocol as p
from sherpa_cli.cia402.drive import Cia402Drive, Cia402Settings
from sherpa_cli.cia402.protocol import State
from sherpa_cli.drive import Drive, DriveStatus, Mode, Ramp
from sherpa_cli.errors import SafetyError, SdoError, UsageError


class FakeNode:
    """The objects of one CiA 402 node over SDO; records (op, index, sub, bytes) of every transfer.
    ``stuck``: states the node does not leave; ``ack``: it acknowledges a new set-point;
    ``ack_lag``: statusword reads that still show bit 12 after bit 4 fell; ``speeds``: the velocities read
    first (a drive ramping down), then 0x606C's value; ``error_field``: it has 0x1003."""

    def __init__(self, state: State = State.SWITCH_ON_DISABLED, *, stuck: tuple[State, ...] = (),
                 ack: bool = True, error: int = 0, ack_lag: int = 0, speeds: tuple[int, ...] = (),
                 register: int | None = None, newest: int | None = None, error_field: bool = True) -> None:
        self.state, self.stuck, self.ack, self.ack_lag = state, stuck, ack, ack_lag
        self.log: list[tuple[str, int, int, bytes]] = []
        self.cw = 0
        register = (0x11 if error == p.HEARTBEAT_LOSS_ERROR else 0x01 if error else 0) if register is None else register
        self.values = {p.MODES_DISPLAY: 0, p.ERROR_CODE: error, p.POSITION_ACTUAL: 1234, p.VELOCITY_ACTUAL: -7,
                       p.PROFILE_VELOCITY: 1000, p.PROFILE_ACCELERATION: 5000, p.PROFILE_DECELERATION: 6000,
                       p.MODES_OF_OPERATION: 0, p.ERROR_REGISTER: register,
                       p.ERROR_FIELD: (error | register << 16) if newest is None else newest}
        self.error_field = error_field
        self.speeds = list(speeds)
        self.extra = 0  # statusword bits beside the state's
        self._lag = 0

    def statusword(self) -> int:
        if self._lag:
            self._lag -= 1
            if not self._lag:
                self.extra &= ~p.SW_SET_POINT_ACK
        return p.statusword_of(self.state) | self.extra

    def upload(self, index: int, sub: int = 0, *, name: str | None = None) -> bytes:
        if index == p.ERROR_FIELD and not self.error_field:
            self.log.append(("up", index, sub, b""))
            raise SdoError("0x1003: no such object", detail="abort 0x06020000", reason="abort")
        if index == p.VELOCITY_ACTUAL and self.speeds:
            data = p.encode(index, self.speeds.pop(0))
        else:
            data = p.encode(index, self.statusword() if index == p.STATUSWORD else self.values[index])
        self.log.append(("up", index, sub, data))
        return data

    def download(self, index: int, sub: int, data: bytes, *, name: str | None = None) -> None:
        self.log.append(("down", index, sub, bytes(data)))
        value = p.decode(index, data)
        self.values[index] = value
        if index == p.MODES_OF_OPERATION:
            self.values[p.MODES_DISPLAY] = value
        if index == p.CONTROLWORD:
            rose = value & ~self.cw
            self.cw = value
            if self.state not in self.stuck:
                self.state = p.transition(self.state, value, fault_reset_edge=bool(rose & p.CW_FAULT_RESET))
            if rose & p.CW_NEW_SET_POINT and self.ack:
                self.extra |= p.SW_SET_POINT_ACK
            if not value & p.CW_NEW_SET_POINT and self.extra & p.SW_SET_POINT_ACK:
                if self.ack_lag:
                    self._lag = self.ack_lag + 1  # the (ack_lag + 1)-th read from now shows it cleared
                else:
                    self.extra &= ~p.SW_SET_POINT_ACK


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt


def make(node: FakeNode, **settings: object) -> tuple[Cia402Drive, Clock]:
    clock = Clock()
    return Cia402Drive(node, "j7 (can0 node 7)", settings=Cia402Settings(**settings),  # type: ignore[arg-type]
                       clock=clock.now, sleep=clock.sleep), clock


def up(index: int, value: int) -> tuple[str, int, int, bytes]:
    return ("up", index, 0, p.encode(index, value))


def down(index: int, value: int) -> tuple[str, int, int, bytes]:
    return ("down", index, 0, p.encode(index, value))


SW = p.STATUSWORD
CW = p.CONTROLWORD


def test_it_is_a_drive():
    drive: Drive = make(FakeNode())[0]
    assert drive.kind == "cia402"


def test_enable_position_from_switch_on_disabled_transcript():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    assert node.log == [
        up(SW, 0x0060),  # Switch on disabled: nothing forbids
        down(p.MODES_OF_OPERATION, 1), up(p.MODES_DISPLAY, 1),
        down(CW, 0x06), up(SW, 0x0021),  # shutdown -> Ready to switch on
        down(CW, 0x07), up(SW, 0x0023),  # switch on -> Switched on
        down(CW, 0x0F), up(SW, 0x0027),  # enable operation -> Operation enabled
    ]
    # the bytes themselves, once, so the codec cannot hide a wrong width
    assert node.log[1] == ("down", 0x6060, 0, b"\x01") and node.log[3] == ("down", 0x6040, 0, b"\x06\x00")


def test_move_to_and_begin_transcript():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    node.log.clear()
    drive.move_to(-100000)
    drive.begin()
    assert node.log == [
        down(p.TARGET_POSITION, -100000),
        up(SW, 0x0027),  # still Operation enabled: a begin() never powers a drive on
        up(SW, 0x0027),  # bit 12 down: no acknowledge left over from a set-point before
        down(CW, 0x3F),  # enable operation + new set-point + change set immediately
        up(SW, 0x1027),  # bit 12: acknowledged
        down(CW, 0x0F),  # bit 4 down again
        up(SW, 0x0027),  # bit 12 down again: the handshake is over
    ]
    assert node.log[0][3] == b"\x60\x79\xfe\xff"


def test_begin_without_change_set_immediately():
    node = FakeNode()
    drive, _ = make(node, change_set_immediately=False)
    drive.enable(Mode.POSITION)
    node.log.clear()
    drive.begin()
    assert node.log[2] == down(CW, 0x1F)


def test_stop_and_disable_transcript():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    node.log.clear()
    assert drive.stop() == "halt"
    drive.disable()
    assert node.log == [
        up(SW, 0x0027), down(CW, 0x010F),  # halt, still enabled
        up(SW, 0x0027), down(CW, 0x06), up(SW, 0x0021),  # shutdown -> Ready to switch on
    ]


@pytest.mark.parametrize("state", [State.READY_TO_SWITCH_ON, State.SWITCHED_ON])
def test_stop_and_begin_never_power_a_drive_on(state):
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.VELOCITY)
    node.state = state  # switched down behind the drive's back (another tool, a shutdown)
    node.log.clear()
    assert drive.stop() == f"off: {state.value}"
    with pytest.raises(SafetyError, match=f"begin refused: the drive is in {state.value}, not Operation enabled"):
        drive.begin()
    assert [entry for entry in node.log if entry[0] == "down"] == []
    assert node.state is state


def test_set_ramp_checks_every_value_before_writing():
    node = FakeNode()
    drive, _ = make(node)
    with pytest.raises(UsageError, match="profile deceleration -1 outside"):
        drive.set_ramp(Ramp(10, 20, -1))
    assert node.log == []


def test_velocity_mode_holds_until_begin():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.VELOCITY)
    assert node.log[-2] == down(CW, 0x010F)  # enabled with halt: a stale 0x60FF does not run
    node.log.clear()
    drive.jog(-300)
    drive.begin()
    assert node.log == [down(p.TARGET_VELOCITY, -300), up(SW, 0x0027), down(CW, 0x0F)]


def test_fault_is_refused_with_its_code_and_nothing_is_written():
    node = FakeNode(State.FAULT, error=0x2310)
    drive, _ = make(node)
    with pytest.raises(SafetyError, match=r"j7 \(can0 node 7\): the drive is in Fault \(0x2310 continuous over-current"):
        drive.enable(Mode.POSITION)
    assert [entry for entry in node.log if entry[0] == "down"] == []
    assert node.state is State.FAULT


def test_disable_leaves_a_fault_alone():
    node = FakeNode(State.FAULT, error=0x8130)
    drive, _ = make(node)
    drive.disable()
    assert node.log == [up(SW, 0x0008)]
    assert drive.status() == DriveStatus(enabled=False, mode=Mode.OTHER,
                                         fault="Fault: 0x8130 life guard error or heartbeat error",
                                         heartbeat_lost=True)


def test_only_the_heartbeat_loss_fault_is_called_the_consumers():
    drive, _ = make(FakeNode(State.FAULT, error=0x2310))
    assert drive.status() == DriveStatus(enabled=False, mode=Mode.OTHER, fault="Fault: 0x2310 continuous over-current")
    drive, _ = make(FakeNode(State.SWITCH_ON_DISABLED, error=0x8130))  # an old code, no fault: nothing to say
    assert drive.status() == DriveStatus(enabled=False, mode=Mode.OTHER)


def test_fault_reset_is_a_rising_bit_7_confirmed_and_leaves_the_power_stage_off():
    node = FakeNode(State.FAULT, error=0x8130)
    node.cw = 0x0080  # a word that left bit 7 up: without 0x00 first the reset would be no edge
    drive, _ = make(node)
    drive.fault_reset()
    fault, disabled = p.statusword_of(State.FAULT), p.statusword_of(State.SWITCH_ON_DISABLED)
    assert node.log == [up(SW, fault), down(p.CONTROLWORD, 0x0000), down(p.CONTROLWORD, 0x0080), up(SW, disabled)]
    assert node.state is State.SWITCH_ON_DISABLED


def test_fault_reset_sends_nothing_to_a_drive_not_in_fault():
    node = FakeNode(State.SWITCH_ON_DISABLED)
    drive, _ = make(node)
    drive.fault_reset()
    assert node.log == [up(SW, p.statusword_of(State.SWITCH_ON_DISABLED))]


def test_a_fault_that_stays_after_its_reset_is_named():
    node = FakeNode(State.FAULT, stuck=(State.FAULT,), error=0x2310)
    drive, clock = make(node)
    with pytest.raises(SafetyError, match="stuck in Fault after 'fault reset'"):
        drive.fault_reset()
    assert clock.t >= 0.5


def test_a_stuck_drive_is_named_with_its_state():
    node = FakeNode(stuck=(State.READY_TO_SWITCH_ON,))
    drive, clock = make(node, confirm_timeout=0.1)
    with pytest.raises(SafetyError, match=r"stuck in Ready to switch on after 'switch on' for 0.1 s \(statusword 0x0021\)"):
        drive.enable(Mode.POSITION)
    assert 0.1 <= clock.t < 0.2


def test_an_unacknowledged_set_point_is_bounded():
    node = FakeNode(ack=False)
    drive, _ = make(node, confirm_timeout=0.05)
    drive.enable(Mode.POSITION)
    with pytest.raises(SafetyError, match="not acknowledged"):
        drive.begin()
    assert node.log[-1] == down(CW, 0x0F)  # the new set-point bit is taken back


def test_torque_is_refused_clearly():
    node = FakeNode()
    drive, _ = make(node)
    with pytest.raises(UsageError, match="torque mode is not built for CiA 402 drives"):
        drive.enable(Mode.TORQUE)
    assert node.log == []


def test_quick_stop_active_leaves_by_disable_voltage():
    node = FakeNode(State.QUICK_STOP_ACTIVE)
    node.values[p.VELOCITY_ACTUAL] = 0
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    writes = [struct.unpack("<H", data)[0] for op, index, _, data in node.log if op == "down" and index == CW]
    assert writes == [0x00, 0x06, 0x07, 0x0F]


def test_status_ramp_position_velocity():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.VELOCITY)
    assert drive.status() == DriveStatus(enabled=True, mode=Mode.VELOCITY)
    assert drive.ramp() == Ramp(1000, 5000, 6000)
    drive.set_ramp(Ramp(10, 20, 30))
    assert drive.ramp() == Ramp(10, 20, 30)
    assert (drive.position(), drive.velocity()) == (1234, -7)
    assert drive.profile_done() is False  # PV: done when the velocity is 0


def test_profile_done_is_target_reached_in_pp():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    assert drive.profile_done() is False
    node.extra |= p.SW_TARGET_REACHED
    assert drive.profile_done() is True


def test_move_needs_position_mode():
    drive, _ = make(FakeNode())
    drive.enable(Mode.VELOCITY)
    with pytest.raises(UsageError, match="move_to needs the drive enabled in profile position mode"):
        drive.move_to(5)


# -- Quick stop active and Fault reaction active keep the power stage on -------------------------------

def test_quick_stop_active_and_fault_reaction_active_are_powered():
    assert make(FakeNode(State.QUICK_STOP_ACTIVE))[0].status() == DriveStatus(enabled=True, mode=Mode.OTHER,
                                                                              stopping="Quick stop active")
    status = make(FakeNode(State.FAULT_REACTION_ACTIVE, error=0x2310))[0].status()
    assert status.enabled and status.fault == "Fault reaction active: 0x2310 continuous over-current"
    assert status.stopping == "Fault reaction active"


def test_stop_sends_nothing_to_a_drive_ramping_down_on_its_own():
    for state, how in ((State.QUICK_STOP_ACTIVE, "quick stop"), (State.FAULT_REACTION_ACTIVE, "fault reaction")):
        node = FakeNode(state)
        drive, _ = make(node)
        assert drive.stop() == how  # halt + enable operation could take a quick stop back to Operation enabled
        assert [e for e in node.log if e[0] == "down"] == []


def test_disable_from_quick_stop_active_waits_for_standstill_before_the_power_stage_goes_off():
    node = FakeNode(State.QUICK_STOP_ACTIVE, speeds=(-300, -120))
    node.values[p.VELOCITY_ACTUAL] = 0
    drive, clock = make(node)
    drive.disable()
    assert node.log == [
        up(SW, 0x0007),
        up(p.VELOCITY_ACTUAL, -300), up(p.VELOCITY_ACTUAL, -120), up(p.VELOCITY_ACTUAL, 0),  # ramping down
        down(CW, 0x00), up(SW, 0x0060),  # disable voltage only at standstill
        down(CW, 0x06), up(SW, 0x0021),
    ]
    assert clock.t == pytest.approx(2 * 0.005)


def test_enable_from_quick_stop_active_waits_for_standstill_and_a_drive_that_keeps_moving_is_named():
    node = FakeNode(State.QUICK_STOP_ACTIVE)  # 0x606C stays -7
    drive, _ = make(node, standstill_timeout=0.1)
    with pytest.raises(SafetyError, match=r"still moving \(-7 counts/s\) 0.1 s into the quick stop "
                                          r"\(now Quick stop active\)"):
        drive.enable(Mode.POSITION)
    assert [e for e in node.log if e[0] == "down"] == []  # nothing written: the power stage stays on
    with pytest.raises(SafetyError, match="still moving"):
        drive.disable()
    assert [e for e in node.log if e[0] == "down"] == []


# -- a mode change in Operation enabled: halt first ----------------------------------------------------

def test_a_mode_change_in_operation_enabled_halts_before_0x6060_transcript():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    node.values[p.VELOCITY_ACTUAL] = 0
    node.log.clear()
    drive.enable(Mode.VELOCITY)
    assert node.log == [
        up(SW, 0x0027), up(p.MODES_DISPLAY, 1),  # Operation enabled in PP
        down(CW, 0x010F),  # halt first: PV would run the old 0x60FF the moment 0x6060 changes
        up(p.VELOCITY_ACTUAL, 0),  # at standstill
        down(p.MODES_OF_OPERATION, 3), up(p.MODES_DISPLAY, 3),
        down(CW, 0x010F),  # still held until begin()
    ]
    assert node.log[2] == ("down", 0x6040, 0, b"\x0f\x01")


def test_the_same_mode_in_operation_enabled_is_not_halted():
    node = FakeNode()
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    node.log.clear()
    drive.enable(Mode.POSITION)
    assert node.log == [up(SW, 0x0027), up(p.MODES_DISPLAY, 1), down(p.MODES_OF_OPERATION, 1),
                        up(p.MODES_DISPLAY, 1), down(CW, 0x0F)]


# -- the set-point handshake --------------------------------------------------------------------------

def test_begin_waits_for_a_stale_bit_12_to_fall_and_names_it_when_it_stays():
    node = FakeNode()
    drive, _ = make(node, confirm_timeout=0.05)
    drive.enable(Mode.POSITION)
    node.extra |= p.SW_SET_POINT_ACK  # left from a set-point before: it would pass for this one's acknowledge
    node.log.clear()
    with pytest.raises(SafetyError, match=r"set-point acknowledge \(statusword bit 12\) still set before the new "
                                          r"set-point for 0.05 s \(Operation enabled, statusword 0x1027\)"):
        drive.begin()
    assert [e for e in node.log if e[0] == "down"] == []  # bit 4 never raised


def test_begin_waits_for_bit_12_to_fall_after_bit_4_fell():
    node = FakeNode(ack_lag=2)
    drive, _ = make(node)
    drive.enable(Mode.POSITION)
    node.log.clear()
    drive.begin()
    assert node.log == [
        up(SW, 0x0027), up(SW, 0x0027), down(CW, 0x3F), up(SW, 0x1027), down(CW, 0x0F),
        up(SW, 0x1027), up(SW, 0x1027), up(SW, 0x0027),  # bit 12 falls a little after bit 4
    ]
    node.log.clear()
    drive.begin()  # the next set-point's handshake starts from bit 12 down
    assert node.log[:3] == [up(SW, 0x0027), up(SW, 0x0027), down(CW, 0x3F)]


def test_a_bit_12_that_never_falls_after_the_set_point_is_bounded():
    node = FakeNode(ack_lag=10**6)
    drive, clock = make(node, confirm_timeout=0.05)
    drive.enable(Mode.POSITION)
    with pytest.raises(SafetyError, match=r"still set after the set-point was acknowledged for 0.05 s"):
        drive.begin()
    assert 0.05 <= clock.t < 0.07


# -- the heartbeat loss is the only error, or not -----------------------------------------------------

@pytest.mark.parametrize(("kwargs", "lost", "more"), [
    ({}, True, ""),
    ({"error_field": False}, True, ""),  # 0x1003 is optional: the error register is all there is
    ({"register": 0x13}, False, "; error register (0x1001) 0x13: more than a communication error"),
    ({"newest": 0x2310}, False, "; newest error (0x1003:1) 0x2310 continuous over-current: more than the heartbeat loss"),
])
def test_heartbeat_lost_only_when_the_communication_error_is_the_only_one(kwargs, lost, more):
    node = FakeNode(State.FAULT, error=0x8130, **kwargs)
    status = make(node)[0].status()
    assert status.heartbeat_lost is lost
    assert status.fault == "Fault: 0x8130 life guard error or heartbeat error" + more
    assert ("up", p.ERROR_REGISTER, 0, p.encode(p.ERROR_REGISTER, kwargs.get("register", 0x11))) in node.log
