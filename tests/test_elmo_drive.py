"""The Elmo drive behind the drive seam: byte-exact transcripts of each Drive call (node 10)."""

from __future__ import annotations

import pytest

from sherpa_cli.drive import Drive, DriveStatus, Mode, Ramp
from sherpa_cli.elmo import codec
from sherpa_cli.elmo.client import DriveClient
from sherpa_cli.elmo.drive import ElmoDrive, mode_of
from sherpa_cli.elmo.transport import FakeTransport

NODE = 10
TX, RX = 0x300 + NODE, 0x280 + NODE


def ask(letters: str, value: int) -> list[tuple[str, int, bytes]]:
    return [("tx", TX, codec.encode_query(letters)), ("rx", RX, codec.encode_reply(letters, 0, value, False))]


def put(letters: str, value: int | float) -> list[tuple[str, int, bytes]]:
    is_float = isinstance(value, float)
    return [("tx", TX, codec.encode_set(letters, 0, value)), ("rx", RX, codec.encode_reply(letters, 0, value, is_float))]


def run(letters: str) -> list[tuple[str, int, bytes]]:
    return [("tx", TX, codec.encode_execute(letters)), ("rx", RX, codec.encode_reply(letters, 0, None, False))]


def refused(letters: str, code: int) -> list[tuple[str, int, bytes]]:
    return [("tx", TX, codec.encode_execute(letters)), ("rx", RX, codec.encode_error_reply(letters, 0, code))]


def switched(value: int) -> list[tuple[str, int, bytes]]:
    return put("MO", value) + ask("MO", value)


def elmo(script: list[tuple[str, int, bytes]]) -> tuple[ElmoDrive, FakeTransport]:
    bus = FakeTransport(script)
    t = [0.0]

    def sleep(s: float) -> None:
        t[0] += s

    client = DriveClient(bus, NODE, name="elbow", timeout=0.01, clock=lambda: t[0], sleep=sleep)
    return ElmoDrive(client), bus


def test_it_is_a_drive_of_the_seam():
    d: Drive = elmo([])[0]
    assert d.kind == "elmo" and "elbow" in d.label


def test_status_reads_mo_um_sr_mf_and_decodes_a_fault():
    d, bus = elmo(ask("MO", 1) + ask("UM", 5) + ask("SR", 0) + ask("MF", 0)
                  + ask("MO", 0) + ask("UM", 2) + ask("SR", 0) + ask("MF", 0x200000))
    assert d.status() == DriveStatus(enabled=True, mode=Mode.POSITION, fault=None)
    off = d.status()
    assert off.enabled is False and off.mode is Mode.VELOCITY
    assert off.fault is not None and off.fault != ""
    bus.done()


def test_enable_in_the_mode_the_drive_holds_only_switches_the_motor_on():
    d, bus = elmo(ask("MO", 0) + ask("UM", 5) + switched(1))
    d.enable(Mode.POSITION)
    bus.done()


def test_a_mode_change_switches_the_motor_off_first():
    d, bus = elmo(ask("MO", 1) + ask("UM", 5) + switched(0) + put("UM", 2) + switched(1))
    d.enable(Mode.VELOCITY)
    bus.done()


def test_torque_mode_never_switches_on_with_an_old_torque_command():
    d, bus = elmo(ask("MO", 0) + ask("UM", 1)
                  + [("tx", TX, codec.encode_query("TC")), ("rx", RX, codec.encode_reply("TC", 0, 0.5, True))]
                  + put("TC", 0.0) + switched(1))
    d.enable(Mode.TORQUE)
    bus.done()


def test_ramp_target_begin_and_profile_end():
    d, bus = elmo(ask("SP", 1000) + ask("AC", 5000) + ask("DC", 6000)
                  + put("SP", 200) + put("AC", 300) + put("DC", 400) + put("PA", -1234) + run("BG")
                  + ask("MS", 2) + ask("MS", 0) + ask("PX", -1234) + ask("VX", 0))
    assert d.ramp() == Ramp(1000, 5000, 6000)
    d.set_ramp(Ramp(200, 300, 400))
    d.move_to(-1234)
    d.begin()
    assert d.profile_done() is False
    assert d.profile_done() is True
    assert d.position() == -1234 and d.velocity() == 0
    bus.done()


def test_stop_is_st_and_falls_back_to_jv0_bg_where_st_is_refused():
    d, bus = elmo(run("ST") + refused("ST", 21) + put("JV", 0) + run("BG"))
    assert d.stop() == "ST"
    assert d.stop() == "JV=0 + BG"
    bus.done()


def test_jog_and_disable():
    d, bus = elmo(put("JV", -50) + switched(0))
    d.jog(-50)
    d.disable()
    bus.done()


@pytest.mark.parametrize(("um", "mode"), [(5, Mode.POSITION), (2, Mode.VELOCITY), (1, Mode.TORQUE),
                                           (4, Mode.OTHER), (3, Mode.OTHER)])
def test_unit_modes(um, mode):
    assert mode_of(um) is mode
