"""Golden outputs of `sherpa jog` on the simulated arm: results (plain, Σ, Δ; --json), the joint-limit
watch, dry runs and refusals.

Only what is the same on every run is compared: position moves end exactly on their target in the
simulator and the guard's stop lines are fixed; velocity and torque end positions depend on wall
time, so they are covered by tests/test_jog_pair.py instead. The plain path's JSON has the motion's
duration (``duration_s``); it is the one value replaced before the comparison.
"""

from __future__ import annotations

import re

import pytest

FAST = "tests/data/jog-fast-arm.yaml"

CASES = [
    # results on the bundled arm
    ("jog-plain-position", ["--sim", "jog", "elbow_pitch", "--to", "10deg", "--apply"], 0),
    ("jog-plain-position-json", ["--sim", "--json", "jog", "elbow_pitch", "--by", "200counts", "--apply"], 0),
    ("jog-sigma-position", ["--sim", "jog", "shoulder_pitch", "--by", "100counts", "--uncalibrated", "--apply"], 0),
    ("jog-delta-position", ["--sim", "jog", "shoulder_roll", "--to", "-5deg", "--uncalibrated", "--apply"], 0),
    ("jog-sigma-position-json", ["--sim", "--json", "jog", "shoulder_pitch", "--to", "0.05", "--uncalibrated",
                                 "--apply"], 0),
    # the joint-limit watch (a fast arm: the joints reach their full range in a fraction of a second)
    ("jog-limit-plain-velocity", ["--config", FAST, "--sim", "jog", "j1", "--velocity", "6000counts/s", "--for", "3",
                                  "--apply"], 1),
    ("jog-limit-sigma-velocity", ["--config", FAST, "--sim", "jog", "pitch", "--velocity", "-6000counts", "--for",
                                  "3", "--apply"], 1),
    # dry runs
    ("jog-dry-run-sigma-velocity", ["--sim", "jog", "shoulder_pitch", "--velocity", "5deg/s", "--for", "2"], 0),
    ("jog-dry-run-delta-torque", ["--sim", "jog", "shoulder_roll", "--torque", "800mA", "--for", "0.5"], 0),
    ("jog-dry-run-sigma-json", ["--sim", "--json", "jog", "shoulder_pitch", "--to", "0.1"], 0),
    # refusals
    ("jog-refuse-normal-range", ["--sim", "jog", "shoulder_pitch", "--to", "90deg", "--apply"], 1),
    ("jog-refuse-normal-range-plain", ["--sim", "jog", "elbow_pitch", "--to", "1400counts", "--apply"], 1),
    ("jog-refuse-uncalibrated-pair", ["--sim", "jog", "shoulder_roll", "--by", "1deg", "--apply"], 1),
    ("jog-refuse-uncalibrated-plain", ["--sim", "jog", "shoulder_yaw", "--to", "1deg", "--apply"], 1),
    ("jog-refuse-torque-without-for", ["--sim", "jog", "shoulder_pitch", "--torque", "1", "--apply"], 2),
    ("jog-refuse-velocity-without-for", ["--sim", "jog", "shoulder_roll", "--velocity", "0.1", "--apply"], 2),
    ("jog-refuse-speed", ["--sim", "jog", "shoulder_pitch", "--velocity", "1", "--for", "1", "--apply"], 1),
    ("jog-refuse-current", ["--sim", "jog", "shoulder_roll", "--torque", "7A", "--for", "1", "--apply"], 1),
    ("jog-refuse-unit", ["--sim", "jog", "elbow_pitch", "--to", "10furlong"], 2),
    ("jog-refuse-half-count", ["--sim", "jog", "shoulder_pitch", "--by", "2.5counts"], 2),
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
