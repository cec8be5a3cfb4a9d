"""`log step --from-mode` (the seed's Figs. 9.1 and 9.3): before t = 0 the drive stands in another
mode with its motor on, so the step's switch is the seed's MO=0, UM, MO=1 -- and the refusals, each
before anything moves. `--sim log step` runs on stepped time."""

from __future__ import annotations

import json

import pytest

ARM = ["--config", "tests/data/step-arm.yaml", "--sim"]


def _metrics(cli, tmp_path, *args: str) -> dict:
    out = tmp_path / "run"
    result = cli(*ARM, "log", "step", "arm", *args, "--rate", "200", "-o", str(out), "--apply")
    assert result.exit_code == 0, result.transcript()
    return json.loads((out / "metrics.json").read_text(encoding="utf-8"))


def test_from_another_mode_the_switch_is_motor_off_mode_motor_on(cli, tmp_path):
    m = _metrics(cli, tmp_path, "--position", "0.5", "--from-mode", "velocity")
    assert (m["switch_steps"], m["from_mode"], m["mode_first"]) == (["MO=0", "UM=5", "MO=1"], "velocity", False)


def test_without_it_a_drive_whose_motor_is_off_switches_once(cli, tmp_path):
    m = _metrics(cli, tmp_path, "--position", "0.5")
    assert (m["switch_steps"], m["from_mode"]) == (["MO=1"], None)


@pytest.mark.parametrize(("args", "message"), [
    (["--position", "0.5", "--from-mode", "torque"], "--from-mode torque: expected one of position, velocity"),
    (["--position", "0.5", "--from-mode", "position"], "--from-mode position is the step's own mode"),
    (["--position", "0.5", "--from-mode", "velocity", "--mode-first"], "--from-mode and --mode-first exclude"),
    # velocity steps jog in UM=5 here (motion.velocity_unit_mode): position mode is no other mode
    (["--velocity", "0.1", "--from-mode", "position"], "there would be no switch"),
    (["--position", "0.5", "--from-mode", "velocity", "--source", "drive"], "--from-mode is for --source can"),
])
def test_a_from_mode_that_cannot_give_the_seed_s_switch_is_refused_before_anything_moves(cli, tmp_path, args,
                                                                                       message):
    out = tmp_path / "run"
    result = cli(*ARM, "log", "step", "arm", *args, "-o", str(out), "--apply")
    assert result.exit_code == 2 and message in result.stderr, result.transcript()
    assert "Traceback" not in result.stderr and not out.exists()
