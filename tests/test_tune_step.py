"""`sherpa tune step` (ops/tune_step.py): a step with the drive's gains and one with trial gains on the
simulated arm, whose servo model runs on the gains (sim/servo.py); the trial gains are RAM only and put
back on every way out; the dry run sends nothing."""

from __future__ import annotations

import json

import pytest

from sherpa_cli.bus import journal
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError
from sherpa_cli.ops.step import resolve_step_target
from sherpa_cli.ops.tune_step import run_tune_step
from sherpa_cli.sim.arm import SimArm
from tests.conftest import ROOT

ARM = ["--config", "tests/data/step-arm.yaml", "--sim"]


def _kp2(cli) -> str:
    shown = cli(*ARM, "tune", "show", "arm")
    return next(line.split()[1] for line in shown.stdout.splitlines() if line.strip().startswith("KP[2]"))


def test_dry_run_sends_nothing(cli):
    result = cli(*ARM, "tune", "step", "arm", "--velocity", "0.1", "KP[2]=2")
    assert result.exit_code == 0 and "nothing sent; add --apply" in result.stdout
    assert _kp2(cli) == "0.5"


def test_the_trial_gain_changes_the_simulated_step_and_is_put_back(cli):
    result = cli("--json", *ARM, "tune", "step", "arm", "--velocity", "0.1", "--for", "1", "KP[2]=2", "--apply")
    assert result.exit_code == 0, result.transcript()
    report = json.loads(result.stdout)
    before, after = report["before"]["metrics"], report["after"]["metrics"]
    assert after["rise_time"] < 0.7 * before["rise_time"]  # a stiffer speed loop rises faster
    assert after["overshoot"] < before["overshoot"]  # and is better damped (sim/servo.py)
    assert report["held"] == {"KP[2]": 0.5} and report["trial"] == {"KP[2]": 2.0}
    assert _kp2(cli) == "0.5"


def test_tune_step_draws_both_steps_with_the_gains_in_the_legend(cli, tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from sherpa_cli.log import plot as log_plot

    drawn = []
    draw = log_plot.plot_step_runs
    monkeypatch.setattr(log_plot, "plot_step_runs", lambda *a, **k: drawn.append(draw(*a, **k)) or drawn[-1])
    out = tmp_path / "tune.png"
    result = cli(*ARM, "tune", "step", "arm", "--position", "0.2", "--for", "1", "KP[3]=40", "--plot", str(out),
                 "--apply")
    assert result.exit_code == 0, result.transcript()
    assert out.read_bytes()[:4] == b"\x89PNG" and f"plot: {out}" in result.stdout
    (fig,) = drawn
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels[0].startswith("own gains (KP[3]=") and labels[1].startswith("trial (KP[3]=40)")
    assert fig.get_suptitle().startswith("tune step arm: position +0.2 rad with own gains (KP[3]=")
    assert "-0.2 rad with trial (KP[3]=40)" in fig.get_suptitle()


def test_bad_trial_gains_are_refused_before_the_bus(cli):
    result = cli(*ARM, "tune", "step", "arm", "--velocity", "0.1", "KP[2]=-1", "--apply")
    assert result.exit_code == 2 and "outside its bounds" in result.stderr


def test_a_failing_trial_step_puts_the_gains_back():
    cfg = load_config(ROOT / "tests" / "data" / "step-arm.yaml")
    target = resolve_step_target(cfg, "arm")
    calls = []

    def step(mode, value):
        calls.append((mode, value))
        if len(calls) == 2:
            raise SafetyError("injected")
        return None

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(SafetyError, match="injected"):
            run_tune_step(s, target, "position", 0.2, {"KP[3]": 45.0}, step)
        assert float(s.client(target.ref).get("KP", 3)) == 30.0
    assert calls == [("position", 0.2), ("position", -0.2)]  # back the way it came
    assert journal.leftover(target.ref) == []
