"""`Arm.tune_show`, `Arm.tune_set` and `Arm.match_pair`: `sherpa tune show|set` and `sherpa diffdrive
match` from Python, on the simulated arm."""

from __future__ import annotations

from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.api import Arm, GainReading, MatchResult, ProgramReport
from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "sherpa-arm.yaml"
MATCH = ROOT / "tests" / "data" / "match-pair.yaml"


def _kp2(arm: Arm, target: str) -> float:
    (reading,) = arm.tune_show(target)
    return float(reading.values["KP[2]"])


def test_show_reads_each_drive_of_a_pair():
    with Arm.open(CONFIG, sim=True) as arm:
        readings = arm.tune_show("shoulder_diff")
    assert [r.drive for r in readings] == ["shoulder_2a", "shoulder_2b"]
    assert all(isinstance(r, GainReading) and r.values["KP[2]"] == 0.5 for r in readings)


def test_set_is_a_dry_run_unless_apply_and_reads_back_with_it():
    with Arm.open(CONFIG, sim=True) as arm:
        dry = arm.tune_set("elbow_pitch", {"KP[2]": 0.8, "KI[2]": 150})
        assert isinstance(dry, ProgramReport) and not dry.apply and dry.result is None
        (plan,) = dry.plans
        assert plan.drive == "elbow_1a" and {p.key for p in plan.changes} == {"KP[2]", "KI[2]"}
        assert _kp2(arm, "elbow_pitch") == 0.5  # nothing written
        done = arm.tune_set("elbow_pitch", ["KP[2]=0.8"], apply=True)
        assert done.ok and done.result is not None
        assert _kp2(arm, "elbow_pitch") == pytest.approx(0.8)  # as float32 holds it
        assert arm.session.sim.drives["elbow_1a"].save_count == 0  # RAM only without save


def test_set_refuses_before_anything_is_sent():
    with Arm.open(CONFIG, sim=True) as arm:
        with pytest.raises(UsageError, match=r"KP\[2\]=800 is outside its bounds 0\.\.100"):
            arm.tune_set("elbow_pitch", {"KP[2]": 800}, apply=True)
        with pytest.raises(UsageError, match="--save needs --apply"):
            arm.tune_set("elbow_pitch", {"KP[2]": 0.8}, save=True)
        with pytest.raises(UsageError, match="AC is not a gain"):
            arm.tune_set("elbow_pitch", "AC=1000", apply=True)
        assert _kp2(arm, "elbow_pitch") == 0.5
        assert arm.session.sim.drives["elbow_1a"].od_writes == []


def test_save_needs_a_confirmation():
    with Arm.open(CONFIG, sim=True) as arm:
        report = arm.tune_set("elbow_pitch", {"KP[2]": 0.7}, apply=True, save=True, check=False)
        assert not report.ok  # refuse_unconfirmed: the default says no
        assert arm.session.sim.drives["elbow_1a"].save_count == 0


def test_match_pair_proposes_gains_for_the_faster_motor_and_puts_the_trials_back():
    cfg = load_config(MATCH)
    with stepped_session(cfg) as (session, stepped):
        arm = Arm(session)
        result = arm.match_pair("diff", clock=stepped.now, sleep=stepped.sleep)
        held = {r.drive: r.values["KP[2]"] for r in arm.tune_show("diff")}
        assert isinstance(result, MatchResult) and result.reached
        assert list(result.proposal.changes) == ["right"]
        assert held == {"left": 0.5, "right": 0.5}  # the trials were RAM only and put back
        written = arm.tune_set("right", result.proposal.changes["right"], apply=True)
        assert written.ok
        assert arm.tune_show("right")[0].values["KP[2]"] == pytest.approx(result.proposal.changes["right"]["KP[2]"])


def test_the_tune_and_match_commands_are_layers_over_the_api(cli, monkeypatch):
    calls: list[str] = []
    for name in ("tune_show", "tune_set", "match_pair"):
        real = getattr(Arm, name)

        def spy(self, *args, _real=real, _name=name, **kw):
            calls.append(_name)
            return _real(self, *args, **kw)

        monkeypatch.setattr(Arm, name, spy)
    assert cli("--sim", "tune", "show", "elbow_pitch").exit_code == 0
    assert cli("--sim", "tune", "set", "elbow_pitch", "KP[2]=0.6").exit_code == 0
    base = ("--config", str(MATCH), "--sim")
    applied = cli(*base, "diffdrive", "match", "diff", "--apply")
    assert applied.exit_code == 0, applied.transcript()
    assert calls == ["tune_show", "tune_set", "match_pair", "tune_set"]


def test_set_takes_any_real_number_for_a_gain_and_refuses_what_is_not_one():
    from fractions import Fraction

    from sherpa_cli.api.arm import gain_texts

    # a Fraction's repr is "Fraction(4, 5)": written as text it was refused as "not a number"
    assert gain_texts({"KP[2]": Fraction(4, 5), "KI[2]": 150}) == ["KP[2]=0.8", "KI[2]=150.0"]
    assert gain_texts({"KP[2]": "0.8"}) == ["KP[2]=0.8"] and gain_texts("KP[2]=0.8") == ["KP[2]=0.8"]
    with pytest.raises(UsageError, match="KP\\[2\\]: True is not a number"):
        gain_texts({"KP[2]": True})
    with pytest.raises(UsageError, match="too large for a gain"):
        gain_texts({"KP[2]": 10 ** 400})
    with Arm.open(CONFIG, sim=True) as arm:
        dry = arm.tune_set("elbow_pitch", {"KP[2]": Fraction(4, 5)})
        (plan,) = dry.plans
        assert [(p.key, p.target) for p in plan.changes] == [("KP[2]", pytest.approx(0.8))]
