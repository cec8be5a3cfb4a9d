"""`sherpa pose list|show|diff|save` on the simulated arm: poses are shown as written and in joint
units; `diff` reads how far the arm stands from one; `save` teaches one into the config file the
tool loaded, keeping every comment, and refuses with nothing written what it cannot prove."""

from __future__ import annotations

import dataclasses
import difflib
import json
import shutil
from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.errors import ConfigError, UsageError
from sherpa_cli.ops.poses import save_pose
from sherpa_cli.ops.state import ArmState

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "configs" / "sherpa-arm.yaml"
ENCODER_JOINTS = "elbow_pitch,wrist_1"  # absolute encoders: calibrated from power-up, no homing needed


@pytest.fixture
def arm_file(tmp_path):
    path = tmp_path / "arm.yaml"
    shutil.copy(SHIPPED, path)
    return path


def test_list_and_show_give_the_poses_as_written_and_in_joint_units(cli, golden):
    listed = cli("pose", "list")
    assert listed.exit_code == 0, listed.stderr
    golden("pose/list.txt", listed.transcript())
    shown = cli("pose", "show", "transport")
    assert shown.exit_code == 0, shown.stderr
    golden("pose/show-transport.txt", shown.transcript())


def test_an_unknown_pose_is_one_line_naming_the_known_ones(cli):
    result = cli("pose", "show", "transprot")
    assert result.exit_code == 2
    assert result.stderr.startswith("error: pose 'transprot' is not in the config; did you mean 'transport'?")
    assert "Traceback" not in result.stderr


def test_save_then_diff_round_trips_and_keeps_every_line_of_the_file(cli, arm_file, golden):
    before = arm_file.read_text(encoding="utf-8")
    saved = cli("--config", str(arm_file), "--sim", "pose", "save", "dock", "--joints", ENCODER_JOINTS)
    assert saved.exit_code == 0, saved.stderr
    after = arm_file.read_text(encoding="utf-8")
    # every line of the file is still there, in order; the pose is appended to poses:
    old, new = before.splitlines(), after.splitlines()
    it = iter(new)
    assert all(line in it for line in old)
    added = [line[2:] for line in difflib.ndiff(old, new) if line.startswith("+ ")]
    assert added == ["  dock:", "    elbow_pitch: 0.0", "    wrist_1: 0.0"], added
    cfg = load_config(arm_file)
    assert dict(cfg.poses["dock"].counts) == {"elbow_pitch": 0, "wrist_1": 0}
    at = cli("--config", str(arm_file), "--sim", "pose", "diff", "dock")
    assert at.exit_code == 0 and "at pose dock: every joint within 1 count" in at.stdout, at.stdout + at.stderr
    moved = cli("--config", str(arm_file), "--sim", "jog", "elbow_pitch", "--by", "0.05", "--apply")
    assert moved.exit_code == 0, moved.stderr
    off = cli("--config", str(arm_file), "--sim", "pose", "diff", "dock")
    assert off.exit_code == 0
    golden("pose/diff-after-jog.txt", off.transcript().replace(str(arm_file.parent), "<tmp>"))
    back = cli("--config", str(arm_file), "--sim", "move", "dock", "--apply")  # taught, then reached
    assert back.exit_code == 0, back.transcript()
    there = cli("--config", str(arm_file), "--sim", "--json", "pose", "diff", "dock")
    report = json.loads(there.stdout)
    assert report["at_pose"] and all(abs(j["off_counts"]) <= 1 for j in report["joints"].values()), report


def test_save_refuses_with_nothing_written(cli, arm_file):
    before = arm_file.read_text(encoding="utf-8")
    uncal = cli("--config", str(arm_file), "--sim", "pose", "save", "dock")
    assert uncal.exit_code == 2 and "not calibrated: where they stand is not known" in uncal.stderr
    exists = cli("--config", str(arm_file), "--sim", "pose", "save", "transport", "--joints", ENCODER_JOINTS)
    assert exists.exit_code == 2 and "pose 'transport' exists" in exists.stderr and "--replace" in exists.stderr
    assert arm_file.read_text(encoding="utf-8") == before
    replaced = cli("--config", str(arm_file), "--sim", "pose", "save", "transport", "--joints", ENCODER_JOINTS,
                   "--replace")
    assert replaced.exit_code == 0 and "replaced pose transport" in replaced.stdout, replaced.stderr
    assert dict(load_config(arm_file).poses["transport"].counts) == {"elbow_pitch": 0, "wrist_1": 0}


def test_a_pose_the_config_would_refuse_is_never_written(arm_file):
    """A joint standing outside its normal range (moved by hand with the power off, or a range
    narrowed since): the new file would not load, so the old one stays."""
    from sherpa_cli.ops.state import JointState

    cfg = load_config(arm_file)
    j = cfg.joints["elbow_pitch"]
    outside = j.pos_max + j.overshoot + 1000
    state = ArmState((JointState("elbow_pitch", outside * 6.283185307179586 / j.cpr, 0.0, 0.0, outside, 0, True,
                                 "absolute encoder", False, 5, (), ("elbow_1a",)),), (), 0.0)
    before = arm_file.read_text(encoding="utf-8")
    with pytest.raises(ConfigError, match="pose far: the config would refuse it, nothing written"):
        save_pose(cfg, "far", state)
    assert arm_file.read_text(encoding="utf-8") == before
    with pytest.raises(UsageError, match="came from none"):
        save_pose(dataclasses.replace(cfg, source=None), "far", state)
