"""`sherpa scan` on an arm with an F/T sensor (tests/data/ft-arm.yaml): the sensor is no CANopen node,
so scan asks it once on its base id and says whether it answered; a silent one is a wiring problem
(exit 1), as a missing drive is."""

from __future__ import annotations

import json
import re
from pathlib import Path

ARM = Path(__file__).resolve().parent / "data" / "ft-arm.yaml"


def test_scan_names_the_sensor_that_answered(cli):
    result = cli("--config", str(ARM), "--sim", "scan")
    assert result.exit_code == 0, result.stderr
    assert re.search(r"^F/T sensor wrist_ft \(can0, base 0x010, replies on 0x015/0x016\): answered, \|F\| 9\.\d\d N, "
                     r"status ok$", result.stdout, re.M), result.stdout
    assert "every configured drive answered" in result.stdout


def test_a_silent_sensor_is_a_wiring_problem(cli, tmp_path):
    text = ARM.read_text(encoding="utf-8").replace("      seed: 7", "      seed: 7\n      silent_at: 0")
    assert "silent_at: 0" in text
    config = tmp_path / "arm.yaml"
    config.write_text(text, encoding="utf-8")
    result = cli("--config", str(config), "--sim", "scan")
    assert result.exit_code == 1, result.stdout + result.stderr
    assert "F/T sensor wrist_ft (can0, base 0x010, replies on 0x015/0x016): no answer: F/T sensor wrist_ft" in result.stdout
    assert "every configured drive answered" not in result.stdout
    as_json = json.loads(cli("--config", str(config), "--sim", "--json", "scan").stdout)
    assert as_json["ft_sensors"][0]["device"] == "wrist_ft" and as_json["ft_sensors"][0]["wrench"] is None
