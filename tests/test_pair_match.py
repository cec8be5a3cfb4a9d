"""`sherpa diffdrive match` (ops/pair_match.py): the loop identification and the proposal (pure), the
match on the simulated pair whose speed loops differ (tests/data/match-pair.yaml) and on a matched pair,
the trial gains put back on every exit path, and the command's dry run / --apply / --save."""

from __future__ import annotations

import json
import math
import re

import pytest
from motion_helpers import stepped_session

from sherpa_cli.bus import journal
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config, load_config_text
from sherpa_cli.errors import SafetyError
from sherpa_cli.ops import pair_match
from sherpa_cli.ops.pair_match import LoopModel, MatchSettings, identify, propose, run_match
from sherpa_cli.ops.tune import DEFAULT_BOUNDS, bounds
from sherpa_cli.sim.arm import SimArm
from tests.conftest import ROOT

MATCH = ROOT / "tests" / "data" / "match-pair.yaml"
HELD = {"KP[2]": 0.5, "KI[2]": 200.0, "KP[3]": 30.0}


def _first_order(tau: float, n: int = 2000, dt: float = 0.0005, v: float = 100.0):
    times = [k * dt for k in range(n)]
    return times, [v * (1 - math.exp(-t / tau)) for t in times], [v] * n


def test_identify_finds_the_delay_of_a_first_order_loop():
    m = identify(*_first_order(0.02))
    assert m.delay_s == pytest.approx(0.02, rel=0.02)
    assert m.overshoot == 0.0 and m.zeta == 1.0
    assert m.rise_s == pytest.approx(0.02 * math.log(9), rel=0.02)  # 10-90 % of exp(-t/tau)


def test_identify_reads_a_negative_step_and_an_overshoot():
    times, vel, cmd = _first_order(0.01)
    vel = [-x * (1 + 0.2 * math.exp(-((t - 0.05) / 0.01) ** 2)) for t, x in zip(times, vel, strict=True)]
    m = identify(times, vel, [-c for c in cmd])
    assert m.overshoot == pytest.approx(0.2, abs=0.02)
    assert 0.3 < m.zeta < 0.6


def _models(ta: float, tb: float) -> dict[str, LoopModel]:
    return {"a": LoopModel(ta, 0.0, 0.0, 1.0, 100.0), "b": LoopModel(tb, 0.0, 0.0, 1.0, 100.0)}


def test_propose_slows_the_faster_motor_to_the_slower_ones_delay():
    p = propose(("a", "b"), _models(0.03, 0.01), {"a": HELD, "b": HELD}, DEFAULT_BOUNDS)
    assert list(p.changes) == ["b"]
    s = 0.01 / 0.03
    assert p.changes["b"] == pytest.approx({"KP[2]": 0.5 * s, "KP[3]": 30 * s, "KI[2]": 200 * s * s}, rel=1e-5)
    assert p.predicted_excursion(False) == pytest.approx(100 * 0.02)
    assert p.predicted_excursion(True) == pytest.approx(0.0, abs=1e-3)


def test_propose_leaves_a_matched_pair_alone():
    p = propose(("a", "b"), _models(0.02, 0.0205), {"a": HELD, "b": HELD}, DEFAULT_BOUNDS)
    assert p.changes == {} and "no change" in p.note


def test_propose_refuses_gains_outside_the_bounds():
    narrow = {**DEFAULT_BOUNDS, "KP[3]": (20.0, 100.0)}
    with pytest.raises(SafetyError, match=r"KP\[3\]=10 is outside its bounds 20..100"):
        propose(("a", "b"), _models(0.03, 0.01), {"a": HELD, "b": HELD}, narrow)


def _gains(session, cfg) -> dict[str, dict[str, float]]:
    return pair_match.read_matched_gains(session, pair_match._refs(cfg, cfg.pairs["diff"]))


def test_match_on_the_mismatched_simulated_pair_reaches_the_goal_and_puts_the_trials_back(tmp_path):
    cfg = load_config(MATCH)
    with stepped_session(cfg) as (s, stepped):  # the steps' timing is the simulated pair's, not the load's
        result = run_match(s, cfg.pairs["diff"], MatchSettings(), bounds=bounds(cfg), clock=stepped.now,
                           sleep=stepped.sleep)
        after = _gains(s, cfg)
    assert result.reached and list(result.proposal.changes) == ["right"]  # right's loop is the faster one
    first, best = result.rounds[0], result.rounds[result.chosen]
    assert first.models["left"].delay_s > 2 * first.models["right"].delay_s
    assert best.error("right", "left") <= 0.05
    assert best.excursion < first.excursion
    assert result.proposal.changes["right"]["KP[3]"] < 30  # slowed, not sped up
    assert after == {"left": HELD, "right": HELD}  # the trials were RAM only and put back
    assert journal.leftover(pair_match._refs(cfg, cfg.pairs["diff"])[1]) == []
    from sherpa_cli.log.plot import have_matplotlib

    if have_matplotlib():  # the before/after plot: both speeds and the Δ drag of both rounds
        fig = pair_match.plot(result, str(tmp_path / "match.png"))
        assert (tmp_path / "match.png").stat().st_size > 0
        titles = [ax.get_title() for ax in fig.axes]
        assert f"before (own gains): Δ drag, peak {first.excursion:.0f} counts" in titles
        assert f"after (trial {result.chosen}): Δ drag, peak {best.excursion:.0f} counts" in titles


def test_match_on_a_matched_pair_proposes_no_change_and_tries_nothing():
    text = re.sub(r"lag: [0-9.]+", "lag: 0.05", MATCH.read_text(encoding="utf-8"))  # both loops alike
    assert text.count("lag: 0.05") == 2
    cfg = load_config_text(text, "matched.yaml")
    with stepped_session(cfg) as (s, stepped):
        result = run_match(s, cfg.pairs["diff"], MatchSettings(), bounds=bounds(cfg), clock=stepped.now,
                           sleep=stepped.sleep)
    assert result.proposal.changes == {} and len(result.rounds) == 1


def test_a_trial_that_fails_puts_the_gains_back(monkeypatch):
    cfg = load_config(MATCH)
    real = pair_match.measure
    calls = []

    def failing(*args, **kw):
        calls.append(1)
        if len(calls) == 2:  # the first trial, with the faster drive's gains changed
            raise SafetyError("injected")
        return real(*args, **kw)

    monkeypatch.setattr(pair_match, "measure", failing)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(SafetyError, match="injected"):
            run_match(s, cfg.pairs["diff"], MatchSettings(), bounds=bounds(cfg))
        assert _gains(s, cfg) == {"left": HELD, "right": HELD}
    assert journal.leftover(pair_match._refs(cfg, cfg.pairs["diff"])[1]) == []


def test_the_command_dry_run_moves_nothing_and_apply_writes_with_read_back(cli):
    base = ("--config", str(MATCH), "--sim")
    result = cli(*base, "diffdrive", "match", "diff")
    assert result.exit_code == 0, result.stderr
    assert "nothing sent; add --measure" in result.stdout
    result = cli(*base, "diffdrive", "match", "diff", "--measure")
    assert result.exit_code == 0, result.stderr
    assert "proposal: right KP[2] 0.5 -> " in result.stdout and "nothing written; add --apply" in result.stdout
    shown = cli(*base, "tune", "show", "right")
    assert "KP[2]           0.5" in shown.stdout  # --measure left the drive's own gains
    result = cli(*base, "diffdrive", "match", "diff", "--apply")
    assert result.exit_code == 0, result.stderr
    assert "3 written and verified" in result.stdout
    shown = cli(*base, "tune", "show", "right")
    assert "KP[2]           0.5 " not in shown.stdout
    # now matched: no change
    result = cli(*base, "diffdrive", "match", "diff", "--measure")
    assert result.exit_code == 0 and "no change" in result.stdout


def test_save_needs_apply_and_is_refused_without_a_terminal(cli):
    base = ("--config", str(MATCH), "--sim")
    result = cli(*base, "diffdrive", "match", "diff", "--save")
    assert result.exit_code == 2 and "--save needs --apply" in result.stderr


def test_a_delay_shorter_than_one_sample_gives_no_infinite_bandwidth():
    times = [k * 0.0005 for k in range(200)]
    m = identify(times, [100.0] * 200, [100.0] * 200)  # an ideal loop: the speed is the command at once
    assert m.delay_s == 0.0 and m.sample_s == pytest.approx(0.0005)
    assert m.bandwidth_hz is None
    assert m.bandwidth_above_hz == pytest.approx(2 / 0.0005 / (2 * math.pi))
    assert m.bandwidth_text() == "> 637"
    data = m.as_dict()
    assert data["bandwidth_hz"] is None and "shorter than one sample (0.50 ms)" in data["bandwidth_note"]
    assert not any(isinstance(v, float) and not math.isfinite(v) for v in data.values())


def test_a_measured_delay_gives_its_bandwidth():
    m = identify(*_first_order(0.02))
    assert m.bandwidth_hz == pytest.approx(2 / 0.02 / (2 * math.pi), rel=0.03)
    assert m.as_dict()["bandwidth_note"] is None
    assert m.bandwidth_text() == f"{m.bandwidth_hz:.1f}"


def test_the_ideal_simulated_pair_prints_no_inf(cli):
    result = cli("--sim", "diffdrive", "match", "shoulder_diff", "--measure", "--uncalibrated")
    assert result.exit_code == 0, result.stderr
    assert not re.search(r"\binf\b|\bnan\b", result.stdout, re.IGNORECASE)
    assert re.search(r"shoulder_2a .*> \d+ ", result.stdout)
    assert "bandwidth: the delay is shorter than one sample" in result.stdout
    data = cli("--sim", "--json", "diffdrive", "match", "shoulder_diff", "--measure", "--uncalibrated")
    assert data.exit_code == 0, data.stderr
    assert "Infinity" not in data.stdout and "NaN" not in data.stdout
    models = json.loads(data.stdout)["proposal"]["models"]
    assert models["shoulder_2a"]["bandwidth_hz"] is None and models["shoulder_2a"]["bandwidth_note"]
