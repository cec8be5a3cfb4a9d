"""The looking commands on an absolute-encoder joint whose counter restarted (a power cycle): they
write nothing, and they show the joint as not calibrated with both numbers (docs/motion.md) --
`monitor --once` and `identify` showed the counter, 0.0000 rad, as the joint's position, with "ok"."""

from __future__ import annotations

import json
import re


def power_cycled_away_from_zero(cli) -> None:
    assert cli("--sim", "jog", "elbow_pitch", "--by", "0.3", "--apply").exit_code == 0
    assert cli("sim", "--power-cycle").exit_code == 0


NOTE = "elbow_pitch not calibrated: its counter PX=0 does not match its absolute encoder (172 counts)"


def test_monitor_once_shows_no_position_and_both_numbers(cli):
    before = cli("--sim", "monitor", "--once", "elbow_pitch")
    assert before.exit_code == 0 and "not calibrated" not in before.stdout
    power_cycled_away_from_zero(cli)
    result = cli("--sim", "monitor", "--once", "elbow_pitch")
    row = next(line for line in result.stdout.splitlines() if "elbow_1a" in line and "operational" in line)
    assert " ? " in row and "0.0000" not in row, row
    assert f"elbow_1a (can1:40): {NOTE}" in result.stdout
    as_json = json.loads(cli("--sim", "--json", "monitor", "--once", "elbow_pitch").stdout)
    drive = next(d for d in as_json["drives"] if d["drive"] == "elbow_1a")
    assert drive["position_rad"] is None and drive["uncalibrated"].startswith("not calibrated: its counter PX=0")


def test_identify_shows_the_joint_not_calibrated_and_writes_nothing(cli):
    power_cycled_away_from_zero(cli)
    result = cli("--sim", "identify", "elbow_pitch")
    assert result.exit_code == 0, result.stderr
    assert "elbow_pitch ? (not calibrated)" in result.stdout and f"elbow_1a: {NOTE}" in result.stdout
    after = cli("--sim", "cmd", "elbow_1a", "PX")  # nothing re-synced it: a looking command writes nothing
    assert after.exit_code == 0 and re.search(r"^\s*PX\s+0\s*$", after.stdout, re.M), after.stdout
