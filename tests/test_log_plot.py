"""Step metrics against the closed-form second-order step, and `sherpa log plot` writing a PNG."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sherpa_cli.log.recording import Recording, write_csv
from sherpa_cli.log.step_metrics import step_metrics


def second_order(t: float, zeta: float, wn: float) -> float:
    """Unit step response of wn^2 / (s^2 + 2 zeta wn s + wn^2), 0 < zeta < 1."""
    if t <= 0:
        return 0.0
    wd = wn * math.sqrt(1 - zeta * zeta)
    return 1 - math.exp(-zeta * wn * t) / math.sqrt(1 - zeta * zeta) * math.sin(wd * t + math.acos(zeta))


def _bisect(f, lo: float, hi: float) -> float:
    for _ in range(200):
        mid = (lo + hi) / 2
        if f(lo) * f(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return (lo + hi) / 2


def analytic(zeta: float, wn: float, dead: float, band: float = 0.02) -> dict:
    wd = wn * math.sqrt(1 - zeta * zeta)
    tp = math.pi / wd  # first peak: the response rises monotonically before it
    y = lambda t: second_order(t, zeta, wn)  # noqa: E731
    t10 = _bisect(lambda t: y(t) - 0.1, 0.0, tp)
    t90 = _bisect(lambda t: y(t) - 0.9, 0.0, tp)
    t2 = _bisect(lambda t: y(t) - band, 0.0, tp)
    # settling: the last time |y - 1| = band; outside the envelope bound nothing can leave the band
    t_env = -math.log(band * math.sqrt(1 - zeta * zeta)) / (zeta * wn)
    step = t_env / 20000
    last = 0.0
    t = t_env
    while t > 0:
        if abs(y(t) - 1) > band:
            last = _bisect(lambda s: abs(y(s) - 1) - band, t, t + step)
            break
        t -= step
    return {"dead_time": dead + t2, "rise_time": t90 - t10,
            "overshoot": 100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta * zeta)), "settling_time": dead + last}


def sampled(zeta, wn, dead, amplitude, offset, n=20000, pre=0.05):
    duration = dead + 12 / (zeta * wn)
    ts = [-pre + (duration + pre) * i / n for i in range(n + 1)]
    return ts, [offset + amplitude * second_order(t - dead, zeta, wn) for t in ts]


def _close(got: float, want: float, rel: float = 0.02) -> None:
    assert got == pytest.approx(want, rel=rel), (got, want)


@settings(max_examples=25, deadline=None)
@given(zeta=st.floats(0.15, 0.9), wn=st.floats(5.0, 120.0), dead=st.floats(0.0, 0.3),
       amplitude=st.one_of(st.floats(0.05, 5.0), st.floats(-5.0, -0.05)), offset=st.floats(-3.0, 3.0))
def test_metrics_of_a_second_order_step_match_the_closed_form(zeta, wn, dead, amplitude, offset):
    ts, ys = sampled(zeta, wn, dead, amplitude, offset)
    m = step_metrics(ts, ys, target=offset + amplitude)
    want = analytic(zeta, wn, dead)
    _close(m.dead_time, want["dead_time"])
    _close(m.rise_time, want["rise_time"])
    _close(m.settling_time, want["settling_time"])
    assert m.overshoot == pytest.approx(want["overshoot"], rel=0.02, abs=0.01)
    assert m.final == pytest.approx(offset + amplitude, abs=1e-3 * abs(amplitude))
    assert abs(m.steady_state_error) < 1e-3 * abs(amplitude) and m.settled


def test_known_example_and_steady_state_error():
    ts, ys = sampled(0.5, 20.0, 0.1, 1.0, 0.0)
    m = step_metrics(ts, [0.95 * y for y in ys], target=1.0)
    assert m.overshoot == pytest.approx(16.303, rel=1e-3)  # exp(-pi * 0.5 / sqrt(0.75))
    assert m.steady_state_error == pytest.approx(0.05, abs=1e-4)


def test_a_record_that_never_settles_says_so():
    ts = [i * 0.001 for i in range(1000)]
    m = step_metrics(ts, [math.sin(40 * t) for t in ts])
    assert m.settling_time is None or not m.settled


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        step_metrics([0.0], [1.0])
    with pytest.raises(ValueError):
        step_metrics([0.0, 1.0], [1.0, float("nan")])


def _recording(path):
    ts, ys = sampled(0.4, 30.0, 0.05, 1.0, 0.2, n=2000)
    rec = Recording(times=ts, columns={
        "elbow_pitch.pos_rad": ys,
        "elbow_pitch.vel_rad_s": [0.0] + [(b - a) / (tb - ta) for a, b, ta, tb in zip(ys, ys[1:], ts, ts[1:], strict=False)],
        "elbow_1a.px": [round(y * 10000) for y in ys], "elbow_1a.vx": [0.0] * len(ys)})
    write_csv(rec, path)


def test_plot_writes_a_png_with_the_metrics(cli, tmp_path):
    pytest.importorskip("matplotlib")
    from PIL import Image  # matplotlib's own dependency

    _recording(tmp_path / "run.csv")
    result = cli("log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "run.png"), "--target", "1.2")
    assert result.exit_code == 0, result.stderr
    assert "elbow_pitch" in result.stdout and "overshoot" in result.stdout
    assert "not stepped: none" in result.stdout and "[]" not in result.stdout  # words, not a Python list
    with Image.open(tmp_path / "run.png") as img:
        assert img.format == "PNG" and img.size == (1000, 600)  # fits a screen, whatever the joints
        assert sum(1 for count in img.convert("L").histogram() if count) > 10  # not a blank canvas
    # the velocity of a position step starts and ends at 0: it did not step, so no metrics for it
    js = cli("--json", "log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "v.png"), "--signal", "vel")
    import json

    data = json.loads(js.stdout)
    assert data["metrics"] == [] and data["not_stepped"] == ["elbow_pitch.vel"]
    plain = cli("log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "w.png"), "--signal", "vel")
    assert "not stepped: elbow_pitch.vel" in plain.stdout, plain.stdout


def test_plot_refuses_bad_input(cli, tmp_path):
    _recording(tmp_path / "run.csv")
    other = tmp_path / "x.csv"
    other.write_text("a,b\n1,2\n")
    assert "not a sherpa recording" in cli("log", "plot", str(other), "-o", str(tmp_path / "x.png")).stderr
    joint = cli("log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "x.png"), "--joint", "nose")
    assert joint.exit_code == 2 and "--joint nose" in joint.stderr
    assert cli("log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "x.jpg")).exit_code == 2


def test_plot_without_matplotlib_is_one_clear_message(cli, tmp_path, monkeypatch):
    _recording(tmp_path / "run.csv")
    monkeypatch.setattr("sherpa_cli.log.plot.have_matplotlib", lambda: False)
    result = cli("log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "x.png"))
    assert result.exit_code == 2 and "needs matplotlib" in result.stderr and "sherpa-cli[plot]" in result.stderr


def test_plot_and_step_refuse_non_finite_numbers(cli, tmp_path):
    _recording(tmp_path / "run.csv")
    garbage = tmp_path / "g.csv"
    garbage.write_bytes(bytes(range(128, 256)))
    assert "not a sherpa recording" in cli("log", "plot", str(garbage), "-o", str(tmp_path / "x.png")).stderr
    for opt in ("--target", "--step-at"):
        r = cli("log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "x.png"), opt, "nan")
        assert r.exit_code == 2 and f"{opt} nan" in r.stderr
    r = cli("--sim", "log", "step", "elbow_pitch", "--position", "inf", "-o", str(tmp_path / "s"))
    assert r.exit_code == 2 and "--position inf" in r.stderr


# -- plots a technician reads at a glance: pixel-free, through the artist tree --------------------------

def _artists(fig):
    """Per axes (visible ones, top to bottom): title, labels, legend texts and the legend's placement."""
    fig.canvas.draw()  # lays the figure out: legend and axes extents, tick offsets
    out = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        legend = ax.get_legend()
        out.append({"ax": ax, "title": ax.get_title(), "ylabel": ax.get_ylabel(), "xlabel": ax.get_xlabel(),
                    "labels": [t.get_text() for t in legend.get_texts()] if legend else [],
                    "legend_outside": legend is not None and legend.get_window_extent().x0
                    >= ax.get_window_extent().x1,
                    "offset": ax.yaxis.get_offset_text().get_text(), "ylim": ax.get_ylim()})
    return out


def _labelled(ax, label):
    return [a for a in (*ax.lines, *ax.patches) if a.get_label() == label]


def _step_recording(still_joint: bool = False):
    ts, ys = sampled(0.5, 25.0, 0.08, 0.1, 0.0, n=1500)
    cols = {"elbow_pitch.vel_rad_s": ys, "elbow_pitch.pos_rad": [0.01 * t for t in ts]}
    if still_joint:  # a joint that holds still: a few 1e-16 of float noise on a constant
        cols["wrist_1.pos_rad"] = [0.25 + (1e-16 if i % 2 else 0.0) for i in range(len(ts))]
    return Recording(times=ts, columns=cols)


def test_a_step_plot_has_units_the_command_the_switch_window_and_settling_with_the_legend_outside(tmp_path):
    pytest.importorskip("matplotlib")
    from sherpa_cli.log.plot import FIG_SIZE, StepMarks, plot_recording, step_title

    rec = _step_recording()
    t, y = rec.series("elbow_pitch", "vel")
    m = step_metrics(t, y, target=0.1)
    marks = StepMarks("velocity", 0.1, 0.03)
    fig = plot_recording(rec, ["elbow_pitch"], tmp_path / "s.png", metrics={("elbow_pitch", "vel"): m},
                         marks=marks, title=step_title("elbow_pitch", marks))
    assert tuple(fig.get_size_inches()) == FIG_SIZE and fig.dpi == 100  # 1000 x 600 px
    assert fig.get_suptitle() == "elbow_pitch: velocity step +0.1 rad/s; MO/UM switch 30 ms"
    pos, vel = _artists(fig)
    assert pos["ylabel"] == "position [rad]" and vel["ylabel"] == "velocity [rad/s]"
    assert vel["xlabel"] == "time since the command [s]" and pos["title"] == ""  # named once: in the suptitle
    for axes in (pos, vel):
        assert axes["legend_outside"] and axes["offset"] == ""
        assert "command (t = 0)" in axes["labels"] and "MO/UM switch 30 ms" in axes["labels"]
        (command,) = _labelled(axes["ax"], "command (t = 0)")
        assert list(command.get_xdata()) == [0.0, 0.0]
        (window,) = _labelled(axes["ax"], "MO/UM switch 30 ms")  # axvspan: x in data, y the whole axes
        xs = window.get_path().transformed(window.get_patch_transform()).vertices[:, 0]
        assert min(xs) == 0.0 and max(xs) == pytest.approx(0.03)
    settled = f"settled (2 %) {1000 * m.settling_time:.1f} ms"
    assert settled in vel["labels"] and f"final {m.final:.4g} rad/s" in vel["labels"]
    assert any(label.startswith("overshoot: ") for label in vel["labels"])
    assert _labelled(vel["ax"], settled)[0].get_xdata()[0] == pytest.approx(m.settling_time)
    assert "JV" not in fig.get_suptitle() and "JV" not in " ".join(vel["labels"])


def test_a_step_that_did_not_settle_draws_no_final_line_and_no_overshoot(tmp_path):
    pytest.importorskip("matplotlib")
    from sherpa_cli.log.plot import StepMarks, plot_recording

    ts = [i * 0.001 for i in range(400)]
    ys = [min(1.0, t * 2.5) + 0.2 * math.sin(60 * t) * (t > 0.3) for t in ts]  # still ringing at the end
    m = step_metrics(ts, ys, target=1.0)
    assert not m.settled
    rec = Recording(times=ts, columns={"arm.pos_rad": ys})
    fig = plot_recording(rec, ["arm"], tmp_path / "n.png", metrics={("arm", "pos"): m},
                         marks=StepMarks("position", 1.0, 0.0))
    (pos,) = _artists(fig)
    assert "not settled: no overshoot or steady-state error" in pos["labels"]
    assert not any(label.startswith(("final", "overshoot", "settled", "steady-state")) for label in pos["labels"])
    assert "MO/UM switch" not in " ".join(pos["labels"])  # no switch: no window drawn


def test_a_joint_that_holds_still_is_a_flat_line_with_a_minimum_span_and_no_offset(tmp_path):
    pytest.importorskip("matplotlib")
    from sherpa_cli.log.plot import MIN_SPAN, plot_recording

    fig = plot_recording(_step_recording(still_joint=True), ["elbow_pitch", "wrist_1"], tmp_path / "two.png")
    assert tuple(fig.get_size_inches() * fig.dpi) == (1000, 600)  # two joints: the same size
    wrist = [a for a in _artists(fig) if a["title"] == "wrist_1"]
    (still,) = wrist
    lo, hi = still["ylim"]
    assert hi - lo >= MIN_SPAN["pos"] * 0.999 and lo < 0.25 < hi
    assert still["offset"] == "" and still["legend_outside"]
    labels = [t.get_text() for t in still["ax"].get_yticklabels()]
    assert labels and not any("e-" in t or "1e" in t for t in labels)


def test_log_plot_computes_metrics_only_for_signals_that_stepped(cli, tmp_path):
    pytest.importorskip("matplotlib")
    write_csv(_step_recording(still_joint=True), tmp_path / "r.csv")
    result = cli("log", "plot", str(tmp_path / "r.csv"), "-o", str(tmp_path / "r.png"))
    assert result.exit_code == 0, result.transcript()
    assert "elbow_pitch pos" in result.stdout  # 0.01 rad/s ramp over 0.5 s: a step of its own
    assert "wrist_1 pos: did not step (changed less than 0.005 rad): no step metrics" in result.stdout
    assert "wrist_1 pos:" not in result.stdout.replace("wrist_1 pos: did not step", "")


def test_the_pair_plot_marks_the_held_joints_excursion_with_a_sensible_span(tmp_path):
    pytest.importorskip("matplotlib")
    from sherpa_cli.log.plot import PairTrace, plot_pair

    count = 2 * math.pi / 4000
    ts = [i * 0.01 for i in range(200)]
    sigma = [min(0.5, t) for t in ts]
    delta = [0.1 + count * (1 if 30 < i < 60 else 0) for i in range(200)]  # one count of quantisation
    trace = PairTrace("diff", "pitch", "roll", ts, sigma, delta, 0.5, 0.1, held="roll", held_excursion=count,
                      held_span=20 * count, subtitle="group")
    fig = plot_pair(trace, tmp_path / "pair.png")
    assert tuple(fig.get_size_inches() * fig.dpi) == (1000, 600)
    assert fig.get_suptitle() == ("diffdrive move diff: Σ target +0.5000 rad, Δ held at +0.1000 rad (group)")
    top, bottom = _artists(fig)
    assert top["title"] == "Σ pitch" and top["ylabel"] == "Σ position [rad]" and "target +0.5000 rad" in top["labels"]
    assert "held at +0.1000 rad" in bottom["labels"]
    assert bottom["title"] == "Δ roll (held)" and bottom["xlabel"] == "time since the command [s]"
    lo, hi = bottom["ylim"]
    assert hi - lo >= 20 * count * 0.999  # not autoscaled to ±1 count
    excursion = f"peak excursion ±{count:.4f} rad"
    assert excursion in bottom["labels"] and _labelled(bottom["ax"], excursion)
    assert all(a["legend_outside"] and a["offset"] == "" for a in (top, bottom))


@pytest.mark.parametrize("args", [
    ("diffdrive", "move", "shoulder_diff", "--sigma", "0.05", "--apply"),
    ("diffdrive", "match", "shoulder_diff", "--measure"),
    ("tune", "step", "elbow_pitch", "--velocity", "0.1", "KP[2]=0.8", "--apply"),
])
def test_a_plot_that_cannot_be_drawn_is_refused_before_anything_moves(cli, tmp_path, monkeypatch, args):
    """`diffdrive move --plot` without matplotlib moved the pair, then failed with no result table."""
    from sherpa_cli.bus.session import ArmSession

    def no_session(*_a, **_k):
        raise AssertionError("a session was opened: the command went to the bus before refusing its plot")

    monkeypatch.setattr(ArmSession, "open", staticmethod(no_session))
    monkeypatch.setattr("sherpa_cli.log.plot.have_matplotlib", lambda: False)
    result = cli("--sim", *args, "--plot", str(tmp_path / "p.png"))
    assert result.exit_code == 2, result.transcript()
    assert "--plot needs matplotlib" in result.stderr and "nothing was moved" in result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    monkeypatch.setattr("sherpa_cli.log.plot.have_matplotlib", lambda: True)
    (tmp_path / "dir.png").mkdir()
    result = cli("--sim", *args, "--plot", str(tmp_path / "dir.png"))
    assert result.exit_code == 2 and "is a directory" in result.stderr, result.transcript()
    # a file where a directory would have to be made: the plot could never be saved
    (tmp_path / "f").write_text("x")
    result = cli("--sim", *args, "--plot", str(tmp_path / "f" / "p.png"))
    assert result.exit_code == 2 and "cannot write the plot: Not a directory" in result.stderr, result.transcript()


def test_a_pair_plot_makes_its_missing_directory(tmp_path):
    """savefig makes no directory: plot_pair (diffdrive move --plot) makes it, as every written file's
    missing directories are made (a recipe's dry run passes a plot path whose directory comes later)."""
    from sherpa_cli.log.plot import save_png

    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig = plt.figure()
    try:
        save_png(fig, tmp_path / "new" / "deeper" / "p.png")
    finally:
        plt.close(fig)
    assert (tmp_path / "new" / "deeper" / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("source", ["can", "drive"])
def test_log_step_says_it_draws_no_png_before_the_step_moves(cli, tmp_path, monkeypatch, source):
    """Without matplotlib `log step` writes its CSV and metrics and no PNG: it says so before the bus
    is opened (it said so after the step had moved), for --source drive as for can."""
    import sys

    from sherpa_cli.bus.session import ArmSession

    said: list[str] = []

    def no_session(*_a, **_k):
        said.append(sys.stderr.getvalue())  # the cli fixture's captured stderr so far
        raise KeyboardInterrupt

    monkeypatch.setattr(ArmSession, "open", staticmethod(no_session))
    monkeypatch.setattr("sherpa_cli.log.plot.have_matplotlib", lambda: False)
    cli("--sim", "log", "step", "elbow_pitch", "--velocity", "0.1", "-o", str(tmp_path / "s"), "--source", source,
        "--apply")
    assert said and "no PNG: matplotlib is not installed" in said[0]
