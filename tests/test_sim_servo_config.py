"""The simulator's servo-loop keys (`sim: drives: NAME: servo_bandwidth / servo_damping /
servo_current_limit / supply_current_limit`, sim/servo.py) are range-checked like every number of
the config: a bad value is refused at load with file:line, the key path and the allowed range
(exit 2), never a traceback or a simulator that misbehaves later."""

from __future__ import annotations

import pytest

from sherpa_cli.config import load_config_text
from sherpa_cli.errors import ConfigError, ExitCode
from sherpa_cli.sim.arm import settings_for

BASE = """\
name: servo-test
buses:
  can0: {interface: socketcan, channel: can0}
drives:
  elbow: {bus: can0, node: 6, model: whistle-10/60}
joints:
  arm:
    drive: elbow
    cpr: 3600
    range: {min: -1800, max: 1800}
sim:
  drives:
    elbow:
      servo_bandwidth: 8
      servo_damping: 0.4
      servo_current_limit: 5
      supply_current_limit: 1
"""
LINE = {"servo_bandwidth": 14, "servo_damping": 15, "servo_current_limit": 16, "supply_current_limit": 17}

CASES = [
    # bandwidth: 0 (the kinematic model) .. 100 Hz, finite
    ("servo_bandwidth", "-1", "is out of range; expected 0..100 Hz"),
    ("servo_bandwidth", "1000", "is out of range; expected 0..100 Hz"),
    ("servo_bandwidth", ".nan", "is not a finite number"),
    # damping: > 0 (0 never settles), finite
    ("servo_damping", "0", "is out of range; expected > 0 and <= 10"),
    ("servo_damping", "-0.5", "is out of range; expected > 0 and <= 10"),
    ("servo_damping", ".inf", "is not a finite number"),
    # current limits: > 0 A, finite
    ("servo_current_limit", "0", "is out of range; expected > 0 and <= 1000 A"),
    ("servo_current_limit", ".nan", "is not a finite number"),
    ("supply_current_limit", "-1", "is out of range; expected > 0 and <= 1000 A"),
    ("supply_current_limit", ".inf", "is not a finite number"),
]


def test_the_base_is_valid_and_reaches_the_simulator():
    cfg = load_config_text(BASE, "servo.yaml")
    s = settings_for(cfg, "elbow")
    assert (s.servo_bandwidth_hz, s.servo_damping, s.servo_current_limit, s.supply_current_limit) == (8, 0.4, 5, 1)
    load_config_text(BASE.replace("servo_bandwidth: 8", "servo_bandwidth: 0"), "off.yaml")  # 0: kinematic model


@pytest.mark.parametrize("key,value,phrase", CASES, ids=[f"{k}={v}" for k, v, _ in CASES])
def test_a_bad_servo_value_is_refused_with_its_location(key, value, phrase):
    lines = BASE.splitlines(True)
    line = LINE[key]
    assert lines[line - 1].strip().startswith(f"{key}:")
    lines[line - 1] = f"      {key}: {value}\n"
    with pytest.raises(ConfigError) as exc:
        load_config_text("".join(lines), "cfg/servo.yaml")
    err = exc.value
    assert err.exit_code == ExitCode.USAGE == 2
    assert (err.location.file, err.location.line) == ("cfg/servo.yaml", line), str(err)
    assert str(err).startswith(f"cfg/servo.yaml:{line}: sim.drives.elbow.{key}: {key} "), str(err)
    assert phrase in str(err), str(err)


def test_config_check_names_the_key(cli, tmp_path):
    path = tmp_path / "servo.yaml"
    path.write_text(BASE.replace("servo_damping: 0.4", "servo_damping: 0"), encoding="utf-8")
    result = cli("--config", str(path), "config", "check")
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert f"{path}:15: sim.drives.elbow.servo_damping: servo_damping 0.0 is out of range" in result.stderr


@pytest.mark.parametrize("key", ["lag", "start_skew"])
def test_the_other_simulated_times_are_bounded_too(key):
    """`lag` and `start_skew` (the pair's mismatch): a negative or endless time was taken by `config
    check` and then refused by the simulator with a traceback."""
    text = BASE.replace("      supply_current_limit: 1\n", f"      supply_current_limit: 1\n      {key}: -0.5\n")
    with pytest.raises(ConfigError) as exc:
        load_config_text(text, "cfg/servo.yaml")
    assert str(exc.value).startswith(f"cfg/servo.yaml:18: sim.drives.elbow.{key}: {key} -0.5 is out of range")
    load_config_text(text.replace("-0.5", "0.01"), "ok.yaml")
