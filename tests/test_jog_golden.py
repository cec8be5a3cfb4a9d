"""Golden outputs of `sherpa jog` on the simulated arm: results (plain, Σ, Δ; --json), the joint-limit
watch, dry runs and refusals.

On tests/data/jog-fast-arm.yaml (fast joints, patient timeouts: the machine is shared). Only what
is the same on every run is compared: position moves end exactly on their target in the
simulator and the guard's stop lines are fixed; velocity and torque end positions depend on wall
time, so they are covered by tests/test_jog_pair.py instead. The plain path's JSON has the motion's
duration (``duration_s``); it is the one value replaced before the comparison.
"""

from __future__ import annotations

import re

import pytest

FAST = "tests/data/jog-fast-arm.yaml"

F = ["--config", FAST, "--sim"]
CASES = [
    # results (position moves end exactly on their target in the simulator)
    ("jog-plain-position", [*F, "jog", "j2", "--to", "10deg", "--apply"], 0),
    ("jog-plain-position-json", [*F, "--json", "jog", "j2", "--by", "200counts", "--apply"], 0),
    ("jog-sigma-position", [*F, "jog", "pitch", "--by", "100counts", "--uncalibrated", "--apply"], 0),
    ("jog-delta-position", [*F, "jog", "roll", "--to", "-5deg", "--uncalibrated", "--apply"], 0),
    ("jog-sigma-position-json", [*F, "--json", "jog", "pitch", "--to", "0.05", "--uncalibrated", "--apply"], 0),
    ("jog-pair-motor-position", [*F, "jog", "right", "--to", "300counts", "--uncalibrated", "--apply"], 0),
    # the joint-limit watch (the joints reach their full range in a fraction of a second)
    ("jog-limit-plain-velocity", [*F, "jog", "j1", "--velocity", "6000counts/s", "--for", "3", "--apply"], 1),
    ("jog-limit-sigma-velocity", [*F, "jog", "pitch", "--velocity", "-6000counts", "--for", "3", "--apply"], 1),
    # dry runs
    ("jog-dry-run-sigma-velocity", [*F, "jog", "pitch", "--velocity", "5deg/s", "--for", "2"], 0),
    ("jog-dry-run-delta-torque", [*F, "jog", "roll", "--torque", "800mA", "--for", "0.5"], 0),
    ("jog-dry-run-sigma-json", [*F, "--json", "jog", "pitch", "--to", "0.1"], 0),
    # refusals
    ("jog-refuse-normal-range", [*F, "jog", "pitch", "--to", "170deg", "--apply"], 2),
    ("jog-refuse-normal-range-plain", [*F, "jog", "j2", "--to", "1780counts", "--apply"], 2),
    ("jog-refuse-uncalibrated-pair", [*F, "jog", "roll", "--by", "1deg", "--apply"], 1),
    ("jog-refuse-uncalibrated-plain", [*F, "jog", "j1", "--to", "1deg", "--apply"], 1),
    ("jog-refuse-torque-without-for", [*F, "jog", "pitch", "--torque", "1", "--apply"], 2),
    ("jog-refuse-velocity-without-for", [*F, "jog", "roll", "--velocity", "0.1", "--apply"], 2),
    ("jog-refuse-speed", [*F, "jog", "pitch", "--velocity", "9000counts", "--for", "1", "--apply"], 2),
    ("jog-refuse-current", [*F, "jog", "roll", "--torque", "3.5A", "--for", "1", "--apply"], 2),
    ("jog-refuse-unit", [*F, "jog", "j2", "--to", "10furlong"], 2),
    ("jog-refuse-half-count", [*F, "jog", "pitch", "--by", "2.5counts"], 2),
]


def _stable(text: str) -> str:
    return re.sub(r'"duration_s": [0-9.]+', '"duration_s": "<varies>"', text)


@pytest.mark.golden
@pytest.mark.parametrize("name,args,code", CASES, ids=[c[0] for c in CASES])
def test_jog_golden(cli, golden, name, args, code):
    result = cli(*args)
    assert "Traceback" not in result.stderr
    assert result.exit_code == code, result.transcript()
    golden(f"{name}.txt", _stable(result.transcript()))
