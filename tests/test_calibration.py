"""What marks a joint calibrated: an absolute encoder, or UI[protocol.calibration_flag]=1 on every
drive of the joint since power-up (the simulated drive keeps UI in RAM: a reset clears it)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.elmo.codec import decode_reply, encode_query, encode_set
from sherpa_cli.motion.calibration import CALIBRATED, absolute, flag_key, judge, mark_calibrated, read_calibration
from sherpa_cli.sim import ManualClock
from sherpa_cli.sim.drive import SimDrive

NODE = 3
RPDO2, TPDO2 = 0x300 + NODE, 0x280 + NODE


@pytest.fixture(scope="module")
def cfg():
    return load_config("configs/sherpa-arm.yaml")


def test_absolute_encoder_joints_need_no_homing(cfg):
    elbow = cfg.joints["elbow_pitch"]
    assert absolute(cfg, elbow)
    c = judge(cfg, elbow, {})
    assert c.calibrated and c.reason == "absolute encoder"


def test_plain_joint_needs_the_flag(cfg):
    yaw = cfg.joints["shoulder_yaw"]
    assert not absolute(cfg, yaw)
    assert judge(cfg, yaw, {"shoulder_1a": 1}).calibrated
    c = judge(cfg, yaw, {"shoulder_1a": 0})
    assert not c.calibrated and c.reason == "not homed since power-up (shoulder_1a UI[3]=0)"


def test_pair_joint_needs_the_flag_on_both_drives(cfg):
    pitch = cfg.joints["shoulder_pitch"]
    assert not absolute(cfg, pitch)
    assert judge(cfg, pitch, {"shoulder_2a": 1, "shoulder_2b": 1}).calibrated
    c = judge(cfg, pitch, {"shoulder_2a": 1, "shoulder_2b": 7})
    assert not c.calibrated and "shoulder_2b UI[3]=7" in c.reason and "shoulder_2a" not in c.reason


def test_the_flag_index_is_a_setting(cfg):
    other = dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, calibration_flag=9))
    assert flag_key(other) == "UI[9]"
    assert "UI[9]=0" in judge(other, other.joints["shoulder_yaw"], {"shoulder_1a": 0}).reason


def test_config_reads_and_checks_calibration_flag(tmp_path):
    from sherpa_cli.config import load_config as load
    from sherpa_cli.errors import ConfigError

    text = Path("configs/appendix-c/example1.yaml").read_text()
    good = tmp_path / "good.yaml"
    good.write_text(text + "\nprotocol: {calibration_flag: 5}\n")
    assert load(good).protocol.calibration_flag == 5
    bad = tmp_path / "bad.yaml"
    bad.write_text(text + "\nprotocol: {calibration_flag: 30}\n")
    with pytest.raises(ConfigError, match=re.escape("calibration_flag 30 must be a UI index 1..24")):
        load(bad)


class _Client:
    """A client that reads and writes one SimDrive's interpreter directly."""

    def __init__(self, drive: SimDrive) -> None:
        self.drive = drive

    def _ask(self, frame: bytes):
        self.drive.receive(RPDO2, frame)
        (frame_out,) = [d for i, d in self.drive.pop_frames() if i == TPDO2]
        reply = decode_reply(frame_out)
        assert reply.ok, reply
        return reply.value

    def get(self, letters: str, index: int = 0):
        return self._ask(encode_query(letters, index))

    def set(self, letters: str, index: int, value) -> None:
        self._ask(encode_set(letters, index, value))


def test_sim_drive_keeps_the_flag_in_ram_until_a_reset(cfg):
    clock = ManualClock()
    drive = SimDrive(NODE, clock=clock, serial=1)
    drive.receive(0x000, bytes([0x01, NODE]))
    drive.pop_frames()
    client = _Client(drive)
    yaw = dataclasses.replace(cfg.joints["shoulder_yaw"], drive="d")
    arm = dataclasses.replace(cfg, joints={"shoulder_yaw": yaw})
    assert client.get("UI", 3) == 0
    assert not read_calibration(arm, yaw, lambda name: client).calibrated
    mark_calibrated(arm, client)
    assert client.get("UI", 3) == CALIBRATED
    assert read_calibration(arm, yaw, lambda name: client).calibrated
    drive.receive(0x000, bytes([0x81, NODE]))  # NMT reset node: RAM reloaded from flash
    drive.receive(0x000, bytes([0x01, NODE]))
    drive.pop_frames()
    assert client.get("UI", 3) == 0


def test_sv_does_not_save_the_flag_in_the_sim():
    clock = ManualClock()
    drive = SimDrive(NODE, clock=clock, serial=1)
    drive.receive(0x000, bytes([0x01, NODE]))
    drive.pop_frames()
    client = _Client(drive)
    client.set("UI", 3, 1)
    drive.execute("SV")
    assert "UI[3]" not in drive.flash


def _elbow_after_a_reset(s, cfg, at: int):
    """elbow_1a's joint stands at ``at`` (its encoder PY reads it), PX meant it, then an NMT reset:
    PX restarts at 0 wherever the joint stands."""
    from sherpa_cli.bus.targets import drive_ref

    c = s.client(drive_ref(cfg, "elbow_1a"))
    c.nmt_start()
    with s.sim.lock:
        s.sim.drives["elbow_1a"].motor.counts = at
    c.set("PX", 0, at)
    c.reset_node(boot_timeout=5.0)
    return c


@pytest.fixture
def elbow_session(tmp_path, monkeypatch, cfg):
    import canopen

    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.sim.arm import SimArm

    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    monkeypatch.setattr(canopen.Network, "NOTIFIER_CYCLE", 0.02)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can1"]) as s:
        yield s


def test_an_absolute_joint_whose_counter_restarted_is_not_calibrated_when_only_looked_at(elbow_session, cfg):
    """After a drive reset PX restarts at 0 while the joint stands elsewhere, and
    the limits and the watch read PX: never assumed calibrated; a looking command writes nothing."""
    from sherpa_cli.bus.targets import drive_ref

    s = elbow_session
    elbow = cfg.joints["elbow_pitch"]
    c = _elbow_after_a_reset(s, cfg, 1370)
    cal = read_calibration(cfg, elbow, lambda n: s.client(drive_ref(cfg, n)))
    assert not cal.calibrated and "PX=0 does not match its absolute encoder (1370 counts)" in cal.reason
    assert int(c.get("PX")) == 0  # nothing written


def test_a_moving_command_resyncs_the_counter_with_the_motor_off(elbow_session, cfg):
    from sherpa_cli.bus.targets import drive_ref

    s = elbow_session
    elbow = cfg.joints["elbow_pitch"]
    c = _elbow_after_a_reset(s, cfg, -1200)
    cal = read_calibration(cfg, elbow, lambda n: s.client(drive_ref(cfg, n)), resync=True)
    assert cal.calibrated and cal.reason == "absolute encoder (counter re-synced: PX was 0, now -1200)"
    assert int(c.get("PX")) == -1200
    # synced now: nothing more to do, and a second look agrees
    assert read_calibration(cfg, elbow, lambda n: s.client(drive_ref(cfg, n))).reason == "absolute encoder"


def test_a_counter_is_not_resynced_under_a_running_motor(elbow_session, cfg):
    from sherpa_cli.bus.targets import drive_ref

    s = elbow_session
    elbow = cfg.joints["elbow_pitch"]
    c = _elbow_after_a_reset(s, cfg, 900)
    c.nmt_start()
    c.set("UM", 0, 2)
    c.motor_on()
    cal = read_calibration(cfg, elbow, lambda n: s.client(drive_ref(cfg, n)), resync=True)
    c.motor_off()
    assert not cal.calibrated and "its motor is on" in cal.reason
    assert abs(int(c.get("PX"))) <= 2  # left alone
