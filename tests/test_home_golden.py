"""Golden outputs of `sherpa home` on the simulated arm (tests/data/home-arm.yaml): the plan (whole
arm and --json), each kind's report, the refusal without a terminal, and the wiring check
(tests/data/home-wiring-arm.yaml: a swapped pair of inputs and an inverted switch).

The one value that depends on timing is the repeat difference of a home switch (the simulated
switch edge falls within a model step, so it is 0 or +-1): within one count it is replaced before
the comparison, anything larger stays and fails the comparison."""

from __future__ import annotations

import re

import pytest

ARM = ["--config", "tests/data/home-arm.yaml", "--sim"]
WIRING = ["--config", "tests/data/home-wiring-arm.yaml", "--sim"]
CASES = [
    ("home-plan-arm", ["--config", "configs/sherpa-arm.yaml", "home", "--dry-run"], 0, ""),
    ("home-plan-json", [*ARM, "--json", "home", "yaw", "roll", "--dry-run"], 0, ""),
    ("home-refuse-no-terminal", [*ARM, "home", "yaw"], 1, ""),
    ("home-report-home-switch", [*ARM, "home", "yaw", "--yes"], 0, ""),
    ("home-report-end-switches", [*ARM, "home", "stiff", "--yes"], 0, ""),
    ("home-report-pair", [*ARM, "home", "diff", "--yes"], 0, ""),
    ("home-report-abs-encoder", [*ARM, "home", "twist"], 0, ""),
    ("home-report-canopen-encoder", [*ARM, "home", "elbow"], 0, ""),
    ("identify-canopen-encoder", [*ARM, "identify", "can0:45"], 0, ""),
    ("home-wiring-swapped", [*WIRING, "home", "--check-wiring", "stiff"], 1, "\n" * 4),
    ("home-wiring-inverted", [*WIRING, "home", "--check-wiring", "yaw"], 1, "\n" * 2),
    ("home-wiring-ok-pair", [*ARM, "home", "--check-wiring", "pitch"], 0, "\n" * 4),
]


def _stable(text: str) -> str:
    return re.sub(r"repeat difference [+-][01] counts", "repeat difference <within 1> counts", text)


@pytest.mark.golden
@pytest.mark.parametrize("name,args,code,stdin", CASES, ids=[c[0] for c in CASES])
def test_home_golden(cli, golden, name, args, code, stdin):
    result = cli(*args, stdin=stdin)
    assert "Traceback" not in result.stderr
    assert result.exit_code == code, result.transcript()
    golden(f"{name}.txt", _stable(result.transcript()))
