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
    with Image.open(tmp_path / "run.png") as img:
        assert img.format == "PNG" and img.size[0] >= 400 and img.size[1] >= 300
        assert sum(1 for count in img.convert("L").histogram() if count) > 10  # not a blank canvas
    js = cli("--json", "log", "plot", str(tmp_path / "run.csv"), "-o", str(tmp_path / "v.png"), "--signal", "vel")
    import json

    assert json.loads(js.stdout)["metrics"][0]["signal"] == "vel"


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
