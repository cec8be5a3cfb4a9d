"""examples/arm_script.py, the controls developer's first script, runs as a user would run it on the
simulated arm: every calibrated joint read in rad, two joints moved together in one motion session
and back, 1 s recorded at 200 Hz into memory, the drives identified and their parameters dumped.
CI also checks it with `mypy --strict` (lint stage, editable and normal installs)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from sherpa_cli.api import Arm

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "arm_script.py"


def test_the_script_reads_moves_records_identifies_and_dumps():
    with Arm.open(ROOT / "configs" / "sherpa-arm.yaml", sim=True) as arm:
        drives = len(arm.config.drives)
        assert arm.jog("wrist_1", by=0.2).ok  # the script starts from where the arm stands
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, str(EXAMPLE)], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    read = re.fullmatch(r"calibrated joints: upper_arm_twist \+0\.000, elbow_pitch \+0\.000, wrist_1 ([+-]\d\.\d{3}), "
                        r"wrist_2 \+0\.000, wrist_3 \+0\.000", lines[0])
    assert read and abs(float(read[1]) - 0.2) <= 0.002, lines[0]
    assert lines[1] == "moved together: True, back: True"
    samples = re.fullmatch(r"(\d+) samples over (\d\.\d\d) s", lines[2])
    assert samples and 195 <= int(samples[1]) <= 202 and samples[2] in ("0.99", "1.00"), lines[2]
    assert re.fullmatch(rf"{drives} drives identified, \d+ parameters read", lines[3]), lines[3]
    with Arm.open(ROOT / "configs" / "sherpa-arm.yaml", sim=True) as arm:  # back where it started
        assert abs(arm.joint("wrist_1").position - 0.2) <= 0.002
