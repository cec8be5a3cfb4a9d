"""Across every transport: an absolute-encoder joint's counter PX restarts at 0 when
its drive is reset (the harness power-cycles the arm before every command), wherever the joint
stands. The next moving command re-syncs PX from the encoder (drive:PY) with the motor off before
it plans, so targets and the limit watch mean the joint's real position."""

from __future__ import annotations

import json

import pytest

CPR = 3600  # elbow_pitch (configs/sherpa-arm.yaml): range -1350..1350, margin 36, overshoot 20


def _px_py(arm_cli) -> tuple[int, int]:
    result = arm_cli("--json", "cmd", "elbow_1a", "PX", "PY")
    assert result.exit_code == 0, result.transcript()
    values = {r["command"]: r["value"] for r in json.loads(result.stdout)["results"]}
    return int(values["PX"]), int(values["PY"])


def _counts(rad: float) -> int:
    import math

    return round(rad / (2 * math.pi) * CPR)


@pytest.fixture
def back_to_zero(arm_cli):
    """The served arm keeps where its joints stand between tests (only RAM is power-cycled): put
    elbow_pitch back at 0, so the next test's relative jog starts where it expects."""
    yield
    arm_cli("jog", "elbow_pitch", "--to", "0", "--apply")


@pytest.mark.realbus
def test_a_position_jog_after_a_reset_goes_where_the_encoder_says(arm_cli, back_to_zero):
    moved = arm_cli("jog", "elbow_pitch", "--to", "1.2", "--apply")
    assert moved.exit_code == 0, moved.transcript()
    px, py = _px_py(arm_cli)  # a power cycle came between: the counter restarted, the encoder did not
    assert abs(py - _counts(1.2)) <= 3 and abs(px) <= 3, (px, py)
    back = arm_cli("jog", "elbow_pitch", "--to", "0.5", "--apply")
    assert back.exit_code == 0, back.transcript()
    # a counter taken as it was (0 at 1.2 rad) would have sent the joint to 1.7 rad
    _, py = _px_py(arm_cli)
    assert abs(py - _counts(0.5)) <= 3, py


@pytest.mark.realbus
def test_the_watch_fires_at_the_encoders_full_range_after_a_reset(arm_cli, back_to_zero):
    assert arm_cli("jog", "elbow_pitch", "--to", "1.2", "--apply").exit_code == 0
    # outward at speed: with PX restarted at 0 the watch would let the joint run 1.2 rad past its range
    run = arm_cli("jog", "elbow_pitch", "--velocity", "0.5", "--for", "4", "--apply")
    assert run.exit_code == 1, run.transcript()
    assert "elbow_pitch left its full range [-1350, 1350] on the high side" in run.stdout, run.transcript()
    _, py = _px_py(arm_cli)
    assert abs(py - 1314) <= 3, py  # brought back to the normal range's edge, by the encoder
