"""`Arm.state()` and `Arm.joint(name)`: the arm read in joint units, on the simulated arm."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.api import Arm
from sherpa_cli.config import load_config
from sherpa_cli.config.model import SimDriveConfig
from sherpa_cli.elmo.protocol import NMT_PRE_OPERATIONAL
from sherpa_cli.errors import CommunicationError, UsageError
from sherpa_cli.joints.units import TAU
from sherpa_cli.ops.state import DriveState, JointState, joint_state

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "sherpa-arm.yaml"


def test_a_fresh_arm_is_read_without_an_nmt_start_by_the_caller():
    with Arm.open(CONFIG, sim=True) as arm:
        drives = arm.session.sim.drives
        assert drives["elbow_1a"].nmt_state == NMT_PRE_OPERATIONAL  # the interpreter would not answer yet
        state = arm.state()
    assert [j.name for j in state] == list(arm.config.joints)  # every joint, config order
    assert {d.drive for d in state.drives} == set(arm.config.drives)
    elbow = state["elbow_pitch"]
    assert isinstance(elbow, JointState) and elbow.drives == ("elbow_1a",)
    assert (elbow.calibrated, elbow.calibration) == (True, "absolute encoder")
    assert not state["shoulder_yaw"].calibrated and "not homed since power-up" in state["shoulder_yaw"].calibration
    assert (elbow.motor_on, elbow.mode, elbow.mode_text) == (False, 5, "single-feedback position")
    assert elbow.faults == () and state.ok


def test_a_jog_by_a_known_amount_reads_back_in_rad():
    with Arm.open(CONFIG, sim=True) as arm:
        joint = arm.joint("elbow_pitch")
        before = joint.position
        result = arm.jog("elbow_pitch", by=0.2)
        after = joint.status
        px = arm.session.sim.drives["elbow_1a"].px
    assert result.ok
    cpr = arm.config.joints["elbow_pitch"].cpr
    assert after.position_counts == px  # what the drive's counter holds now
    assert after.position == pytest.approx(px * TAU / cpr)
    assert after.position - before == pytest.approx(0.2, abs=0.005)
    assert not after.motor_on and after.velocity == pytest.approx(0.0, abs=0.01)


def test_a_sigma_and_delta_joint_follow_from_both_motors():
    with Arm.open(CONFIG, sim=True) as arm:
        arm.jog("shoulder_pitch", velocity="250counts/s", duration=0.4, uncalibrated=True)
        state = arm.state(["shoulder_diff"])
        by_motor = arm.state(["shoulder_2b"])
        a, b = (arm.session.sim.drives[d].px for d in ("shoulder_2a", "shoulder_2b"))
    assert [j.name for j in state] == ["shoulder_pitch", "shoulder_roll"]
    sigma, delta = state["shoulder_pitch"], state["shoulder_roll"]
    assert a > 20 and b > 20  # both motors moved, the same way
    assert (sigma.position_counts, delta.position_counts) == (a + b, a - b)
    cpr = load_config(CONFIG).joints["shoulder_pitch"].cpr
    assert sigma.position == pytest.approx((a + b) * TAU / cpr)
    assert sigma.drives == delta.drives == ("shoulder_2a", "shoulder_2b")
    assert [j.name for j in by_motor] == ["shoulder_pitch", "shoulder_roll"]  # one motor named: both joints
    assert by_motor["shoulder_roll"].position_counts == a - b
    assert [(d.drive, d.position_counts) for d in by_motor.drives] == [("shoulder_2a", a), ("shoulder_2b", b)]


def test_velocity_while_a_joint_moves():
    # on the simulated arm's stepped time: the motor speeds up only while the test waits on that
    # clock, so how fast it goes by the read does not depend on the host's load
    with stepped_session(load_config(CONFIG), ["can1"]) as (session, stepped):
        arm = Arm(session)
        with arm.live_jog(["elbow_pitch"], clock=stepped.now, sleep=stepped.sleep) as live:
            seen = 0.0
            while stepped.now() < 3.0 and seen < 190:  # 3 s of simulated time
                live.set_velocity("elbow_pitch", 200)  # counts/s
                live.tick()
                stepped.sleep(0.05)
                status = arm.joint("elbow_pitch").status
                seen = status.velocity_counts
            live.stop_all()
    cpr = arm.config.joints["elbow_pitch"].cpr
    assert 190 <= seen <= 210 and status.motor_on
    assert status.velocity == pytest.approx(seen * TAU / cpr)


def test_a_pair_joint_current_is_the_torque_both_motors_put_on_it():
    cfg = load_config(CONFIG)

    def drive(name: str, current: float, mode: int = 1) -> DriveState:
        return DriveState(name, "can0", 1, 100, 10, current, True, mode, 0, 0, ())

    motors = {"shoulder_2a": drive("shoulder_2a", 1.5), "shoulder_2b": drive("shoulder_2b", 0.5)}
    calib = dataclasses.make_dataclass("C", ["calibrated", "reason"])(True, "homed")
    sigma = joint_state(cfg, cfg.joints["shoulder_pitch"], motors, calib)
    delta = joint_state(cfg, cfg.joints["shoulder_roll"], motors, calib)
    assert (sigma.current, delta.current) == (1.0, 0.5)
    assert (sigma.velocity_counts, delta.velocity_counts) == (20, 0)
    mixed = {**motors, "shoulder_2b": drive("shoulder_2b", 0.5, mode=5)}
    assert joint_state(cfg, cfg.joints["shoulder_pitch"], mixed, calib).mode is None


def test_faults_are_decoded_text_and_a_silent_drive_raises():
    cfg = load_config(CONFIG)
    cfg = dataclasses.replace(cfg, sim={"elbow_1a": SimDriveConfig(limit_trip_at=0.0),
                                        "elbow_1b": SimDriveConfig(die_at=0.0)})
    with Arm.open(cfg, sim=True) as arm:
        elbow = arm.joint("elbow_pitch").status
        with pytest.raises(CommunicationError, match="elbow_1b"):
            arm.state(["elbow_stiffness"])
    assert not elbow.ok
    assert "elbow_1a: position limit exceeded (LL[3]/HL[3]) - check LL[3]/HL[3] and the joint's switches" \
        in elbow.faults


def test_limits_are_the_config_in_joint_units():
    with Arm.open(CONFIG, sim=True) as arm:
        limits = arm.joint("elbow_pitch").limits
        j = arm.config.joints["elbow_pitch"]
        with pytest.raises(UsageError, match="nope"):
            arm.joint("nope")
    assert limits.full == (pytest.approx(j.pos_min * TAU / j.cpr), pytest.approx(j.pos_max * TAU / j.cpr))
    assert limits.normal[1] < limits.full[1] < limits.overshoot[1]
    assert j.vel_limit is not None and limits.velocity == pytest.approx(j.vel_limit * TAU / j.cpr)
    assert limits.current is not None and limits.current.continuous == j.current.continuous  # type: ignore[union-attr]
    assert math.isclose(limits.full[1], 0.75 * math.pi)  # 135 deg, as configured


def test_state_takes_the_time_it_is_given():
    with Arm.open(CONFIG, sim=True) as arm:
        assert arm.state(["wrist_3"], clock=lambda: 42.0).at == 42.0


# -- identify and dump_params: the commands' results, from Python

def test_identify_reads_who_each_drive_is_and_where_its_joint_stands():
    with Arm.open(CONFIG, sim=True) as arm:
        arm.jog("elbow_pitch", by=0.1)
        report = arm.identify(["elbow_pitch", "shoulder_diff"])
        px = arm.session.sim.drives["elbow_1a"].px
    assert [d.drive for d in report.drives] == ["elbow_1a", "shoulder_2a", "shoulder_2b"]
    elbow = report.drives[0]
    assert elbow.error is None and report.errors == () and report.findings == []
    assert elbow.identity["device_name"] and elbow.identity["vendor_id"] == 0x9A  # Elmo's CiA vendor id
    assert elbow.state["PX"] == px and elbow.joint is not None
    assert elbow.joint.joint == "elbow_pitch" and elbow.joint.rad == pytest.approx(0.1, abs=0.005)
    assert report.drives[1].joint is not None and report.drives[1].joint.formula == "Σ = shoulder_2a + shoulder_2b"


def test_dump_params_returns_what_it_writes(tmp_path):
    from sherpa_cli.ops.params_file import read_dump

    path = tmp_path / "arm.yaml"
    with Arm.open(CONFIG, sim=True) as arm:
        arm.program_limits(["elbow_pitch"], apply=True)
        dump = arm.dump_params(path, ["elbow_pitch"])
        in_memory = arm.dump_params(targets=["wrist_3"])
    assert list(dump.drives) == ["elbow_1a"] and list(in_memory.drives) == ["wrist_3a"]
    params = dump.drives["elbow_1a"].params
    assert params["CL[1]"] == pytest.approx(3.0) and params["UM"] == 5  # the limit just programmed
    assert read_dump(path).drives == dump.drives  # the file holds what was returned


def test_the_identify_and_dump_params_commands_call_the_api(cli, monkeypatch):
    seen = []
    real_identify, real_dump = Arm.identify, Arm.dump_params
    monkeypatch.setattr(Arm, "identify", lambda self, *a, **k: seen.append("identify") or real_identify(self, *a, **k))
    monkeypatch.setattr(Arm, "dump_params", lambda self, *a, **k: seen.append("dump") or real_dump(self, *a, **k))
    assert cli("--sim", "identify", "elbow_1a").exit_code == 0
    assert cli("--sim", "dump-params", "elbow_1a").exit_code == 0
    assert seen == ["identify", "dump"]


def test_the_docs_examples_of_reading_the_arm_pass_mypy_strict(tmp_path):
    """What a user copies from docs/api.md's reading sections type-checks as it is written."""
    import re
    import subprocess
    import sys

    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    wanted = ("## Read the arm", "## Identify the drives and dump their parameters", "## From moteus, ODrive or canopen")
    files = []
    for title in wanted:
        section = text.split(title, 1)[1].split("\n## ", 1)[0]
        (block,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
        files.append(tmp_path / f"example_{len(files)}.py")
        files[-1].write_text(block, encoding="utf-8")
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent",
                          "--cache-dir", str(tmp_path / "cache"), *map(str, files)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
