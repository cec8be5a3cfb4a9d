"""`log step` reports metrics only for a settled step (log/settle.py), and
`log step --compare RUN...` overlays earlier runs with their figures (log/step_compare.py).
The plots are checked through matplotlib's artist tree, not pixels."""

from __future__ import annotations

import json

import pytest

from sherpa_cli.log.settle import judged, settled_at_end
from sherpa_cli.log.step_metrics import step_metrics

ARM = ["--config", "tests/data/step-arm.yaml", "--sim"]


def test_a_record_cut_off_while_moving_has_no_final_value_overshoot_or_error():
    # the case: a ramp cut off at 0.92 of the step; the last 5 % average to a "final" value
    # the trace then crosses, and step_metrics alone would call it settled at the end
    ts = [i * 0.001 - 0.1 for i in range(1100)]
    ys = [0.0 if t < 0 else min(0.9238, 0.9238 * t / 0.9) for t in ts]
    raw = step_metrics(ts, ys, target=1.0)
    assert raw.settled and raw.overshoot == 0.0 and raw.steady_state_error == pytest.approx(0.0762, abs=1e-3)
    assert not settled_at_end(ts, ys, 1.0)  # 7.6 % short of the target: outside 2 % of the step
    shown = judged(raw, settled_at_end(ts, ys, 1.0))
    assert (shown.settled, shown.overshoot, shown.settling_time, shown.steady_state_error) == (False, None, None, None)
    assert shown.dead_time == raw.dead_time and shown.rise_time == raw.rise_time
    assert judged(raw, True).overshoot == raw.overshoot


def test_settled_needs_the_whole_hold_inside_the_band():
    ts = [i * 0.01 - 0.1 for i in range(60)]
    inside = [0.0 if t < 0 else 1.0 for t in ts]
    assert settled_at_end(ts, inside, 1.0)
    late = [*inside[:-5], *(1.05 for _ in range(5))]  # leaves the 2 % band within the last 0.2 s
    assert not settled_at_end(ts, late, 1.0)
    assert not settled_at_end([t + 0.2 for t in ts], inside, 1.0)  # nothing before the command


@pytest.fixture
def two_runs(cli, tmp_path):
    runs = []
    for name, args in (("pos", ["--position", "1"]), ("vel", ["--velocity", "0.1", "--for", "1", "--hold", "0.3"])):
        out = tmp_path / name
        result = cli(*ARM, "log", "step", "arm", *args, "--rate", "500", "-o", str(out), "--apply")
        assert result.exit_code == 0, result.transcript()
        runs.append(out)
    return runs


def test_compare_lists_each_runs_figures_and_draws_them_together(cli, tmp_path, two_runs):
    pytest.importorskip("matplotlib")
    png = tmp_path / "cmp.png"
    result = cli("--json", "log", "step", "--compare", *map(str, two_runs), "-o", str(png))
    assert result.exit_code == 0, result.transcript()
    data = json.loads(result.stdout)
    pos, vel = data["runs"]
    assert (pos["name"], pos["mode"], pos["value"], vel["mode"]) == ("pos", "position", 1.0, "velocity")
    assert vel["steady_speed"] == pytest.approx(0.1, rel=0.05) and vel["steady_ripple"] < 0.05
    assert pos["peak_speed"] > 0.5 and pos["slowing_after_s"] is not None and pos["settled"] is True
    assert data["png"] == str(png) and png.read_bytes()[:4] == b"\x89PNG"
    table = cli("log", "step", "--compare", *map(str, two_runs), "-o", str(png))
    assert table.exit_code == 0 and "slows at" in table.stdout and " pos " in f" {table.stdout}"

    from sherpa_cli.log.step_compare import compare, plot_compare

    fig = plot_compare(compare(two_runs), tmp_path / "again.png")
    fig.canvas.draw()
    top, bottom = fig.axes
    assert top.get_ylabel() == "position change [rad]" and bottom.get_ylabel() == "velocity [rad/s]"
    assert bottom.get_xlabel() == "time since the command [s]" and fig.get_suptitle() == "log step: pos, vel"
    labels = [t.get_text() for t in bottom.get_legend().get_texts()]
    assert labels[0].startswith("pos: position +1, peak +") and "steady +0.099 rad/s" in labels[1]
    assert bottom.get_legend().get_window_extent().x0 >= bottom.get_window_extent().x1  # outside the data
    (pos_line,) = [line for line in top.lines if line.get_label().startswith("pos:")]
    assert pos_line.get_ydata()[0] == 0.0 and max(pos_line.get_ydata()) == pytest.approx(1.0, abs=0.1)


def test_compare_refuses_what_is_not_a_run(cli, tmp_path):
    (tmp_path / "empty").mkdir()
    result = cli("log", "step", "--compare", str(tmp_path / "empty"), "-o", str(tmp_path / "c.png"))
    assert result.exit_code == 2 and "has no metrics.json" in result.stderr
    result = cli("log", "step", "--compare", str(tmp_path / "empty"), "-o", str(tmp_path / "c.csv"))
    assert result.exit_code == 2 and "expected a .png file name" in result.stderr
    result = cli("log", "step", "--compare", str(tmp_path / "empty"), "--position", "1", "-o", str(tmp_path / "c.png"))
    assert result.exit_code == 2 and "--compare reads earlier runs" in result.stderr
    result = cli(*ARM, "log", "step", "arm", "wrist", "--position", "1", "-o", str(tmp_path / "s"))
    assert result.exit_code == 2 and "log step steps one joint; got 2" in result.stderr


def test_hold_must_fit_in_for(cli, tmp_path):
    result = cli(*ARM, "log", "step", "arm", "--velocity", "0.1", "--for", "1", "--hold", "1", "-o", str(tmp_path))
    assert result.exit_code == 2 and "--hold 1.0: expected seconds >= 0 and less than --for 1" in result.stderr


def test_mode_first_is_refused_for_a_torque_step(cli, tmp_path):
    """The motor would be on at TC=0 for the settle window before the step: a loaded joint sags."""
    result = cli(*ARM, "log", "step", "arm", "--torque", "1", "--for", "0.3", "--mode-first", "-o", str(tmp_path),
                 "--apply")
    assert result.exit_code == 2 and "--mode-first is for position and velocity steps" in result.stderr
