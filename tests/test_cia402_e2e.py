"""Cia402Drive against the simulated CiA 402 drive through the real SDO path: the in-process simulated
arm (tests/data/cia402-arm.yaml, drive `wrist` of type cia402) on stepped time, ArmSession's DriveSdo."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.cia402.drive import Cia402Drive
from sherpa_cli.cia402.protocol import State
from sherpa_cli.config import load_config
from sherpa_cli.drive import DriveStatus, Mode, Ramp
from sherpa_cli.errors import SafetyError
from sherpa_cli.sim.cia402 import SimCia402Drive
from sherpa_cli.sim.drive import SimDrive
from tests.motion_helpers import stepped_session

CONFIG = Path(__file__).resolve().parent / "data" / "cia402-arm.yaml"
HOST = 0x7D


@pytest.fixture
def arm(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    cfg = load_config(CONFIG)
    with stepped_session(cfg) as (session, stepped):
        ref = drive_ref(cfg, "wrist")
        drive = Cia402Drive(session.sdo(ref), f"wrist ({ref.address})", clock=stepped.now, sleep=stepped.sleep)
        yield session, stepped, drive


def beat(session) -> None:
    session.links["can0"].network.send_message(0x700 + HOST, b"\x05")


def test_the_simulated_arm_builds_a_cia402_drive_for_a_cia402_entry(arm):
    session, _, _ = arm
    assert type(session.sim.drives["wrist"]) is SimCia402Drive
    assert type(session.sim.drives["elbow"]) is SimDrive


def test_enable_move_arrive_stop_disable(arm):
    session, stepped, drive = arm
    sdo = session.sdo(drive_ref(session.cfg, "wrist"))
    assert struct.unpack("<I", sdo.upload(0x1000, 0))[0] == 0x00020192
    # the dead-man as motion/guard.py arms it (sizes of motion/deadman.py), then the host's heartbeat
    sdo.download(0x6007, 0, struct.pack("<h", 2))
    sdo.download(0x1029, 1, struct.pack("<B", 2))
    sdo.download(0x1016, 1, struct.pack("<I", HOST << 16 | 1000))
    beat(session)
    stepped.sleep(0.01)
    start = drive.position()
    drive.set_ramp(Ramp(8000, 40000, 40000))
    assert drive.ramp() == Ramp(8000, 40000, 40000)
    drive.enable(Mode.POSITION)
    assert drive.status() == DriveStatus(enabled=True, mode=Mode.POSITION)
    drive.move_to(start + 2000)
    drive.begin()
    assert not drive.profile_done()
    for _ in range(100):  # 0.2 s up, 0.05 s at speed, 0.2 s down: 0.45 s
        beat(session)
        stepped.sleep(0.02)
        if drive.profile_done():
            break
    assert drive.profile_done() and drive.position() == start + 2000
    drive.move_to(start - 4000)
    drive.begin()
    beat(session)
    stepped.sleep(0.3)
    assert drive.velocity() < 0
    assert drive.stop() == "halt"
    for _ in range(20):
        beat(session)
        stepped.sleep(0.02)
    assert drive.velocity() == 0 and drive.profile_done()
    assert drive.status().enabled
    drive.disable()
    assert drive.status() == DriveStatus(enabled=False, mode=Mode.POSITION)
    with session.sim.lock:
        sim = session.sim.drives["wrist"]
        assert isinstance(sim, SimCia402Drive)
        assert sim.state is State.READY_TO_SWITCH_ON and not sim.motor_on
        assert sim.unguarded_motor_on == 0  # the consumer watched when the power stage came on


def test_a_faulted_drive_is_refused_through_sdo(arm):
    session, _, drive = arm
    with session.sim.lock:
        sim = session.sim.drives["wrist"]
        assert isinstance(sim, SimCia402Drive)
        sim.fault(0x3210)
    with pytest.raises(SafetyError, match=r"wrist \(can0:7\): the drive is in Fault \(0x3210 DC link over-voltage"):
        drive.enable(Mode.POSITION)
    assert drive.status().fault == "Fault: 0x3210 DC link over-voltage"
