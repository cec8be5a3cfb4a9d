"""The guard's drive watch across processes: `sherpa jog --velocity` in a subprocess, the simulated arm
in another, and the test as "another node" on the served bus (python-can-remote, or vcan under
SHERPA_TEST_BUS) sending an EMCY flood, NMT Stopped, or an SDO write that disarms the dead-man.
"""

from __future__ import annotations

import struct
import time

import can
import pytest
from test_motion_crossprocess import DRIVE, NODE, finish, motor_offs, start_jog
from test_motion_crossprocess import arm as arm

from sherpa_cli.bus.busmap import parse_bus_map

pytestmark = [pytest.mark.realbus, pytest.mark.crossprocess]


def other_node(arm_) -> can.BusABC:
    """A bus of its own on the jog's bus (can1), as another node of the arm's CAN bus."""
    target = parse_bus_map([arm_.bus_map])["can1"]
    return can.Bus(interface=target.interface, channel=target.channel)


def send(bus: can.BusABC, can_id: int, data: bytes) -> None:
    bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))


def test_an_emcy_flood_from_the_moving_drive_stops_the_jog(arm, tmp_path):
    proc, t_on = start_jog(arm, tmp_path)
    bus = other_node(arm)
    try:
        frame = struct.pack("<HBBHH", 0x8611, 0x01, 0, 0, 0)  # position tracking error
        t_flood = time.monotonic()
        for _ in range(2000):
            try:
                send(bus, 0x80 + NODE, frame)
            except can.CanOperationError:  # a full vcan queue: a flood is what it is
                time.sleep(0.001)
        code, out, err = finish(proc)
    finally:
        bus.shutdown()
    assert code == 1, f"{out}\n{err}"
    assert f"{DRIVE} (node {NODE}): EMCY 0x8611: position tracking error" in err, err
    assert "Traceback" not in err
    offs = motor_offs(arm, t_on)
    assert offs and offs[0]["event"] == "motor off: MO=0", arm.events()  # the guard's stop, not a trip
    assert offs[0]["t"] > t_flood


def test_nmt_stopped_sent_to_a_moving_drive_ends_the_command_within_half_a_second(arm, tmp_path):
    proc, t_on = start_jog(arm, tmp_path)
    bus = other_node(arm)
    try:
        t_sent = time.monotonic()
        send(bus, 0x000, bytes([0x02, NODE]))
        code, out, err = finish(proc)
    finally:
        bus.shutdown()
    assert code == 1, f"{out}\n{err}"
    assert f"{DRIVE} (node {NODE}): another node sent NMT Stopped" in err, err
    assert "Traceback" not in err
    offs = motor_offs(arm, t_on)
    assert offs and offs[0]["event"] == "motor off: MO=0", arm.events()  # stopped by the guard
    took = offs[0]["t"] - t_sent
    assert took < 0.5, f"motor off {took:.3f} s after NMT Stopped"


def test_a_foreign_sdo_write_that_disarms_the_dead_man_stops_the_jog(arm, tmp_path):
    proc, t_on = start_jog(arm, tmp_path)
    bus = other_node(arm)
    try:
        send(bus, 0x600 + NODE, bytes([0x23, 0x16, 0x10, 1, 0, 0, 0, 0]))  # 0x1016:1 = 0
        code, out, err = finish(proc)
    finally:
        bus.shutdown()
    assert code == 1, f"{out}\n{err}"
    assert f"{DRIVE} (node {NODE}): its dead-man entry 0x1016:1 reads 0x00000000" in err, err
    offs = motor_offs(arm, t_on)
    assert offs and offs[0]["event"] == "motor off: MO=0", arm.events()
