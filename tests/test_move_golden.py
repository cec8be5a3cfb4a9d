"""Golden outputs of `sherpa move POSE` on the simulated arm (tests/data/move-arm.yaml: j1 on can1, j2
and the Σ/Δ pair on can0): dry runs (the plan), applied moves, refusals.

Position moves end exactly on their targets in the simulator and the guard's stop lines are fixed;
what depends on wall time -- the measured start skew, the move's duration and arrival times -- is
replaced before the comparison.
"""

from __future__ import annotations

import re

import pytest

F = ["--config", "tests/data/move-arm.yaml", "--sim"]
CASES = [
    # dry runs: the plan, nothing moves
    ("move-dry-run", [*F, "move", "reach"], 0),
    ("move-dry-run-pair", [*F, "move", "ready", "--uncalibrated"], 0),
    ("move-dry-run-held", [*F, "move", "level", "--uncalibrated", "--speed-scale", "0.5"], 0),
    ("move-dry-run-json", [*F, "--json", "move", "ready", "--joints", "j1", "--joints", "pitch", "--uncalibrated"], 0),
    # applied (the joints start at 0 in a fresh simulator)
    ("move-apply", [*F, "move", "ready", "--uncalibrated", "--apply"], 0),
    ("move-apply-json", [*F, "--json", "move", "reach", "--apply"], 0),
    # refusals: one line each, nothing moves
    ("move-refuse-unknown-pose", [*F, "move", "redy"], 2),
    ("move-refuse-unknown-joint", [*F, "move", "ready", "--joints", "j3"], 2),
    ("move-refuse-joint-not-in-pose", [*F, "move", "reach", "--joints", "pitch"], 2),
    ("move-refuse-speed-scale", [*F, "move", "reach", "--speed-scale", "2"], 2),
    ("move-refuse-uncalibrated", [*F, "move", "ready", "--apply"], 1),
]


def _stable(text: str) -> str:
    text = re.sub(r"skew [0-9.]+ ms", "skew <varies> ms", text)
    text = re.sub(r'"(duration_s|time_s|skew_s)": [0-9.]+', r'"\1": "<varies>"', text)
    return text


@pytest.mark.golden
@pytest.mark.parametrize("name,args,code", CASES, ids=[c[0] for c in CASES])
def test_move_golden(cli, golden, name, args, code):
    result = cli(*args)
    assert "Traceback" not in result.stderr
    assert result.exit_code == code, result.transcript()
    golden(f"{name}.txt", _stable(result.transcript()))
