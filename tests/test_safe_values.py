"""Safe values: rates, durations and dead-man settings outside the bounds that keep
the tool alive and the dead-man meaningful are refused, naming the bound (exit 2), before anything
is sent. Unicode digits: tests/test_ascii_numbers.py."""

from __future__ import annotations

import pytest
from conftest import ROOT

from sherpa_cli.config import load_config
from sherpa_cli.errors import ConfigError

ARM = ROOT / "configs" / "sherpa-arm.yaml"


@pytest.mark.parametrize("motion,message", [
    ("{loss_action: 0}", "loss_action 0 is refused (the safe bound is 1..3)"),
    ("{consumer_time_ms: 60000}", "consumer_time_ms 60000 is above the safe bound 2000 ms"),
    ("{consumer_time_ms: 2001}", "consumer_time_ms 2001 is above the safe bound 2000 ms"),
    ("{liveness_timeout: 1.0e+9}", "liveness_timeout 1000000000.0 s is above the safe bound 10 s"),
    ("{liveness_timeout: .inf}", "liveness_timeout inf s is above the safe bound 10 s"),
    ("{max_torque_for: 1000}", "max_torque_for 1000.0 s must be > 0 and at most 60 s"),
    ("{max_torque_for: 0}", "max_torque_for 0.0 s must be > 0 and at most 60 s"),
])
def test_unsafe_dead_man_settings_are_refused_naming_the_bound(tmp_path, motion, message):
    path = tmp_path / "arm.yaml"
    path.write_text(ARM.read_text(encoding="utf-8") + f"\nmotion: {motion}\n", encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert message in str(info.value) and "motion." in str(info.value)


@pytest.mark.parametrize("motion", ["{loss_action: 1}", "{consumer_time_ms: 2000}", "{liveness_timeout: 10}",
                                    "{max_torque_for: 60}"])
def test_the_bounds_themselves_are_accepted(tmp_path, motion):
    path = tmp_path / "arm.yaml"
    path.write_text(ARM.read_text(encoding="utf-8") + f"\nmotion: {motion}\n", encoding="utf-8")
    load_config(path)


@pytest.mark.parametrize("args,message", [
    (["log", "record", "elbow_1a", "--rate", "0.5", "--for", "1"], "--rate 0.5: expected Hz >= 1"),
    (["log", "record", "elbow_1a", "--rate", "1e-9", "--for", "1"], "--rate 1e-09: expected Hz >= 1"),
    (["log", "record", "elbow_1a", "--rate", "nan", "--for", "1"], "--rate nan: expected Hz >= 1"),
    (["log", "step", "elbow_pitch", "--velocity", "0.1", "--rate", "0.5", "--apply"], "--rate 0.5: expected Hz >= 10"),
    (["log", "step", "elbow_pitch", "--velocity", "0.1", "--rate", "9", "--apply"], "--rate 9: expected Hz >= 10"),
    (["jog", "elbow_pitch", "--torque", "0.1", "--for", "1e9", "--apply"],
     "--for 1e+09 s is longer than motion.max_torque_for (10 s)"),
    (["jog", "shoulder_pitch", "--torque", "0.1", "--for", "11", "--apply"],
     "--for 11 s is longer than motion.max_torque_for (10 s)"),
    (["log", "step", "elbow_pitch", "--torque", "0.1", "--for", "20", "--apply"],
     "--for 20 s is longer than motion.max_torque_for (10 s)"),
    (["log", "record", "elbow_1a", "--for", "1e9"], "--for 1000000000.0: expected seconds > 0 and <= 3600"),
])
def test_low_rates_and_huge_durations_are_refused_before_anything_is_sent(cli, tmp_path, args, message):
    out = tmp_path / ("r.csv" if args[1] == "record" else "step") if args[0] == "log" else None
    result = cli("--sim", *args, *(["-o", str(out)] if out is not None else []))
    assert result.exit_code == 2, result.transcript()
    assert message in result.stderr, result.transcript()
    assert "Traceback" not in result.stderr
    assert out is None or not out.exists()
