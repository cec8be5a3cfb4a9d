"""benchmarks/run.py --smoke (the CI's bench stage): every benchmark has a smallest size its function
accepts, and the smoke verdict fails a benchmark that raises or gives no figure, not one that only
misses its goal. No benchmark runs here (the bench stage runs them all)."""

from __future__ import annotations

import importlib.util
import inspect
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("sherpa_benchmarks", ROOT / "benchmarks" / "run.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def test_every_benchmark_has_a_smoke_size_its_function_accepts(bench):
    assert set(bench.SMOKE) == set(bench.BENCHMARKS)
    for name, fn in bench.BENCHMARKS.items():
        inspect.signature(fn).bind(**bench.SMOKE[name])  # TypeError names the argument it does not take


def _result(bench, value=1.0, ratio=1.0, passed=True):
    return bench.Result("x", value, "ms", ratio, "<= 1", passed)


def test_a_missed_goal_passes_the_smoke_run(bench):
    outcome = bench.smoke_one("x", lambda: _result(bench, ratio=9.0, passed=False), {})
    assert outcome.ok and "goal missed" in outcome.line()


@pytest.mark.parametrize("value,ratio", [(float("nan"), 1.0), (1.0, float("nan")), (float("inf"), 1.0)])
def test_no_finite_figure_fails_it(bench, value, ratio):
    outcome = bench.smoke_one("x", lambda: _result(bench, value=value, ratio=ratio), {})
    assert not outcome.ok and "NO FIGURE" in outcome.line()


def test_a_benchmark_that_raises_fails_it_and_the_others_still_run(bench, monkeypatch, capsys):
    def broken(**_):
        raise AttributeError("module 'x' has no attribute 'MoveRequest'")

    monkeypatch.setattr(bench, "BENCHMARKS", {"broken": broken, "fine": lambda **_: _result(bench)})
    monkeypatch.setattr(bench, "SMOKE", {"broken": {}, "fine": {}})
    assert bench.smoke(["broken", "fine"]) == 1
    out = capsys.readouterr().out
    assert "broken        ERROR AttributeError: module 'x' has no attribute 'MoveRequest'" in out
    assert "fine " in out and "1 of 2 benchmarks gave a figure" in out and "broken: broken" in out


def test_all_figures_pass(bench, monkeypatch, capsys):
    monkeypatch.setattr(bench, "BENCHMARKS", {"fine": lambda **_: _result(bench)})
    monkeypatch.setattr(bench, "SMOKE", {"fine": {}})
    assert bench.smoke(["fine"]) == 0
    assert "1 of 1 benchmarks gave a figure" in capsys.readouterr().out
