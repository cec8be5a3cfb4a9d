"""examples/read_arm.py runs as a user would run it, on the simulated arm, and prints what the arm holds."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from sherpa_cli.api import Arm
from sherpa_cli.ops.params_file import read_dump

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "read_arm.py"


def test_read_arm_prints_positions_identity_and_dumps_the_parameters(tmp_path):
    # the simulated drives keep their RAM in this test's state directory between processes: a joint
    # moved here is where the example, a process of its own, must find it
    with Arm.open(ROOT / "configs" / "sherpa-arm.yaml", sim=True) as arm:
        moved = arm.jog("elbow_pitch", by=0.25)
        assert moved.ok
        drives = len(arm.config.drives)
        joints = list(arm.config.joints)
    dump = tmp_path / "dump.yaml"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, str(EXAMPLE), str(dump)], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    rad = dict(re.findall(r"^(\w+)\s+([+-]\d+\.\d{4}) rad", out.stdout, flags=re.M))
    assert list(rad) == joints
    assert float(rad["elbow_pitch"]) == pytest.approx(0.25, abs=0.005)
    assert float(rad["wrist_3"]) == 0.0
    assert "shoulder_yaw" in out.stdout and "(not calibrated)" in out.stdout.splitlines()[0]
    assert out.stdout.count("firmware Whistle") == drives
    assert f"{drives} drives identified, 0 finding(s)" in out.stdout
    assert len(read_dump(dump).drives) == drives
