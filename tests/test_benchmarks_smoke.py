"""benchmarks/run.py --smoke (the CI's bench stage): every benchmark has a smoke size its function
accepts, and the smoke verdict fails a benchmark that raised or gave no finite figure, never one that
only missed its goal. No benchmark runs here."""

from __future__ import annotations

import importlib.util
import inspect
import math
import os
import sys
from pathlib import Path

import pytest

RUN_PY = Path(__file__).resolve().parent.parent / "benchmarks" / "run.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("sherpa_benchmarks_run", RUN_PY)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def _result(bench, value=1.0, ratio=0.5, passed=True):
    return bench.Result("x", value, "ms", ratio, "<= 1", passed)


def test_every_benchmark_has_a_smoke_size_its_function_accepts(bench):
    assert set(bench.SMOKE) == set(bench.BENCHMARKS)
    for name, fn in bench.BENCHMARKS.items():
        inspect.signature(fn).bind(**bench.SMOKE[name])  # raises TypeError on an unknown keyword


def test_a_missed_goal_passes_the_smoke_and_says_so(bench):
    outcome = bench.smoke_one("slow", lambda **kw: _result(bench, ratio=3.0, passed=False), {})
    assert outcome.ok
    assert "goal missed" in outcome.line() and "not judged" in outcome.line()
    met = bench.smoke_one("fast", lambda **kw: _result(bench), {})
    assert met.ok and "goal met" in met.line()


def test_a_raising_benchmark_fails_the_smoke_with_one_error_line(bench):
    def broken(rounds: int = 3):
        raise AttributeError("module has no attribute 'MoveRequest'\nsecond line")

    outcome = bench.smoke_one("coupling", broken, {"rounds": 1})
    assert not outcome.ok
    assert outcome.line() == "coupling ERROR AttributeError: module has no attribute 'MoveRequest' second line"


@pytest.mark.parametrize("value, ratio", [(1.0, math.nan), (math.nan, 0.5), (1.0, math.inf), (None, 0.5),
                                          ("12", 0.5)])
def test_no_finite_figure_fails_the_smoke(bench, value, ratio):
    result = _result(bench, value=value, ratio=ratio)
    assert not bench.has_figure(result)
    outcome = bench.smoke_one("nan", lambda: result, {})
    assert not outcome.ok and "NO FIGURE" in outcome.line()
    assert not bench.has_figure(None)


def test_the_smoke_run_goes_on_after_a_failure_and_exits_1(bench, monkeypatch, capsys):
    calls = []

    def boom():
        calls.append("boom")
        raise RuntimeError("no reply")

    def missed():
        calls.append("missed")
        return _result(bench, ratio=9.0, passed=False)

    monkeypatch.setattr(bench, "BENCHMARKS", {"boom": boom, "missed": missed})
    monkeypatch.setattr(bench, "SMOKE", {"boom": {}, "missed": {}})
    assert bench.smoke(["boom", "missed"]) == 1
    assert calls == ["boom", "missed"]
    out = capsys.readouterr().out
    assert "boom ERROR RuntimeError: no reply" in out and "wall time" in out and "broken: boom" in out
    monkeypatch.setattr(bench, "SMOKE", {"boom": {}, "missed": {}})
    assert bench.smoke(["missed"]) == 0  # a missed goal alone passes


def test_a_benchmark_that_changes_the_environment_has_it_put_back(bench, monkeypatch):
    monkeypatch.delenv("XDG_STATE_HOME", raising=False)

    def leaky():
        os.environ["XDG_STATE_HOME"] = "/nonexistent/bench-state"
        return _result(bench)

    outcome = bench.smoke_one("leaky", leaky, {})
    assert "XDG_STATE_HOME" not in os.environ
    assert outcome.ok and outcome.changed_env == ("XDG_STATE_HOME",) and "put back" in outcome.line()


def test_state_home_puts_the_variable_back(bench, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", "/before")
    with bench._state_home("/inside"):
        assert os.environ["XDG_STATE_HOME"] == "/inside"
    assert os.environ["XDG_STATE_HOME"] == "/before"
    monkeypatch.delenv("XDG_STATE_HOME")
    with pytest.raises(RuntimeError), bench._state_home("/inside"):
        raise RuntimeError
    assert "XDG_STATE_HOME" not in os.environ


def test_importing_the_benchmarks_makes_no_temporary_directory(tmp_path, monkeypatch):
    # the helper processes (--responder, --burst) import run.py and end past atexit: nothing at import
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    spec = importlib.util.spec_from_file_location("sherpa_benchmarks_run_import", RUN_PY)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        sys.modules.pop(spec.name, None)
    assert list(tmp_path.iterdir()) == []
