"""Plots whose titles say what their legends say, read from the functions that build them (no image
comparison): a step's title and its target line, the pair plot's held joint, the match plot's
before/after columns on one y scale with labelled axes, `tune step`'s runs."""

from __future__ import annotations

import math

import pytest

from sherpa_cli.log.plot import StepMarks, StepRun, pair_rows, pair_title, runs_title, step_title, value_text
from sherpa_cli.log.step_metrics import step_metrics
from sherpa_cli.ops.pair_match import LoopModel, MatchResult, MatchRound, PairStep, Proposal, match_panels


def test_a_position_steps_title_says_where_it_went_as_its_target_line_does():
    """Fig. 9.2 steps -2 rad from +1 rad: to -1 rad, which the title said nowhere ("position step -2 rad")."""
    marks = StepMarks("position", -2.0, 0.0, target=-1.0)
    title = step_title("shoulder_yaw", marks)
    assert title == "shoulder_yaw: position step -2 rad (to -1 rad); no mode switch"
    assert f"target {value_text(-1.0, 'rad')}" == "target -1 rad"  # the legend's line, the same digits
    velocity = StepMarks("velocity", 0.1, 0.03, target=0.1)  # a velocity step's value is its target
    assert step_title("elbow_pitch", velocity) == "elbow_pitch: velocity step +0.1 rad/s; MO/UM switch 30 ms"


def test_the_held_joint_is_titled_with_its_legends_level_not_its_rounded_target():
    """The Δ target was one count off where Δ stood: the title said "Δ to -0.0010", the legend
    "held at +0.0000"."""
    from sherpa_cli.log.plot import PairTrace

    count = 2 * math.pi / 6000
    trace = PairTrace("diff", "pitch", "roll", [0.0, 0.1], [0.0, 0.1], [0.0, 0.0], 0.0995, -count, held="roll",
                      subtitle="group")
    sigma, delta = pair_rows(trace)
    assert delta.level_label == "held at +0.0000 rad" and sigma.level_label == "target +0.0995 rad"
    title = pair_title(trace)
    assert title == "diffdrive move diff: Σ target +0.0995 rad, Δ held at +0.0000 rad (group)"
    assert "-0.0010" not in title
    for joint in ("pitch", "roll"):  # each joint named once, in its panel's title
        assert " ".join((title, sigma.title, delta.title)).count(joint) == 1
    assert sigma.title == "Σ pitch" and delta.title == "Δ roll (held)"


def _step(delay_a: float, delay_b: float, lag: int) -> PairStep:
    times = [k * 0.001 for k in range(200)]
    vel = {d: [100 * (1 - math.exp(-t / tau)) for t in times] for d, tau in (("a", delay_a), ("b", delay_b))}
    pos = {d: [sum(vel[d][:k]) * 0.001 for k in range(200)] for d in ("a", "b")}
    pos["b"] = [p - (lag if 50 < k < 120 else 0) for k, p in enumerate(pos["b"])]
    data = {d: {"pos": pos[d], "vel": vel[d], "vel_cmd": [100.0] * 200} for d in ("a", "b")}
    return PairStep(times, data, 100, 0.001)


def _model(delay: float) -> LoopModel:
    return LoopModel(delay, 2.2 * delay, 0.0, 1.0, 100.0)


def _result() -> MatchResult:
    before, after = _step(0.02, 0.005, 40), _step(0.02, 0.018, 4)
    rounds = [MatchRound(1.0, {"a": _model(0.02), "b": _model(0.005)}, before.delta_excursion(("a", "b"))),
              MatchRound(0.3, {"a": _model(0.02), "b": _model(0.018)}, after.delta_excursion(("a", "b")))]
    proposal = Proposal(("a", "b"), rounds[0].models, {}, {"b": {"KP[2]": 0.15}}, 0.3, 0.75, 0.05, 100.0)
    return MatchResult("diff", proposal, rounds, 1, [before, after], True)


def test_the_match_plots_columns_are_titled_from_what_they_draw():
    result = _result()
    before, after = match_panels(result)
    for panel, rnd in ((before, result.rounds[0]), (after, result.rounds[1])):
        peak = max(abs(v) for v in panel.drag)
        assert panel.drag_title.endswith(f"Δ drag, peak {peak:.0f} counts") and round(peak) == round(rnd.excursion)
        assert panel.legends["b"] == f"b, delay {rnd.models['b'].delay_s * 1e3:.1f} ms"
    assert before.label == "before (own gains)" and after.label == "after (trial 1)"


def test_the_match_plots_before_and_after_share_one_y_scale_per_row_and_label_every_axis(tmp_path):
    pytest.importorskip("matplotlib")
    from sherpa_cli.ops.pair_match import plot

    fig = plot(_result(), str(tmp_path / "match.png"))
    (speed_b, speed_a), (drag_b, drag_a) = ((fig.axes[0], fig.axes[1]), (fig.axes[2], fig.axes[3]))
    assert speed_b.get_ylim() == speed_a.get_ylim()
    assert drag_b.get_ylim() == drag_a.get_ylim()  # 40 counts before, 4 after: on one scale
    assert drag_b.get_ylim()[1] - drag_b.get_ylim()[0] >= 40
    for ax in fig.axes:
        assert "[" in ax.get_ylabel() and ax.get_ylabel().endswith("]"), ax.get_ylabel()
    assert speed_b.get_ylabel() == "speed [counts/s]" and drag_b.get_ylabel() == "Δ drag [counts]"
    assert drag_b.get_xlabel() == drag_a.get_xlabel() == "time since BG [ms]"


def test_a_step_plot_of_one_joint_names_it_once(tmp_path):
    pytest.importorskip("matplotlib")
    from sherpa_cli.log.plot import plot_recording
    from sherpa_cli.log.recording import Recording

    ts = [i * 0.001 - 0.1 for i in range(600)]
    rec = Recording(times=ts, columns={"elbow_pitch.pos_rad": [1.0 - 2.0 * min(1.0, max(0.0, t * 5)) for t in ts]})
    t, y = rec.series("elbow_pitch", "pos")
    m = step_metrics(t, y, target=-1.0)
    marks = StepMarks("position", -2.0, 0.0, target=-1.0)
    fig = plot_recording(rec, ["elbow_pitch"], tmp_path / "s.png", metrics={("elbow_pitch", "pos"): m}, marks=marks,
                         title=step_title("elbow_pitch", marks))
    ax = fig.axes[0]
    texts = [fig.get_suptitle(), ax.get_title(), ax.get_ylabel(), *[x.get_text() for x in ax.get_legend().get_texts()]]
    assert sum(text.count("elbow_pitch") for text in texts) == 1
    assert "target -1 rad" in texts and "(to -1 rad)" in fig.get_suptitle()


def test_tune_steps_runs_are_titled_with_their_legend_entries(tmp_path):
    ts = [i * 0.001 for i in range(300)]
    up = [min(0.2, t) for t in ts]
    back = [0.2 - v for v in up]
    runs = [StepRun("own gains (KP[3]=30)", 0.2, ts, up, step_metrics(ts, up, target=0.2)),
            StepRun("trial (KP[3]=40)", -0.2, ts, back, step_metrics(ts, back, target=0.0))]
    title = runs_title("elbow_pitch", "position", runs)
    assert title == ("tune step elbow_pitch: position +0.2 rad with own gains (KP[3]=30), "
                     "-0.2 rad with trial (KP[3]=40)")
    pytest.importorskip("matplotlib")
    from sherpa_cli.log.plot import plot_step_runs

    fig = plot_step_runs("elbow_pitch", "position", "pos", runs, tmp_path / "tune.png")
    ax = fig.axes[0]
    labels = [x.get_text() for x in ax.get_legend().get_texts()]
    assert [label.split(":")[0] for label in labels[:2]] == [r.label for r in runs]
    back_line = ax.lines[1].get_ydata()
    assert back_line[-1] == pytest.approx(0.2)  # the way back drawn along its own step: it rises too
    assert ax.get_ylabel() == "position moved along the step [rad]" and (tmp_path / "tune.png").stat().st_size > 0
