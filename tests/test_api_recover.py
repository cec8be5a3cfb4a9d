"""`Arm.recover()` raises what `sherpa recover` exits with when a drive is still not recovered
(check=True, as the other API calls do), after the report is made; check=False returns it."""

from __future__ import annotations

from pathlib import Path

import pytest

from sherpa_cli.api import Arm
from sherpa_cli.bus.journal import RecoverResult
from sherpa_cli.errors import SafetyError
from sherpa_cli.ops import recover as ops_recover
from sherpa_cli.ops.recover import RecoverReport

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml"


def test_a_drive_still_not_recovered_raises_unless_check_is_off(monkeypatch):
    stuck = RecoverReport(True, [RecoverResult("elbow_1a", "can1:40", ["UM=2"], problems=["no answer to MO"])])
    monkeypatch.setattr(ops_recover, "recover", lambda *a, **k: stuck)
    with Arm.open(CONFIG, sim=True, buses=["can1"]) as arm:
        with pytest.raises(SafetyError, match="not recovered: elbow_1a"):
            arm.recover(apply=True)
        assert arm.recover(apply=True, check=False).not_recovered == ["elbow_1a"]
        monkeypatch.setattr(ops_recover, "recover", lambda *a, **k: RecoverReport(True))
        assert arm.recover(apply=True).not_recovered == []
