"""Golden outputs of `sherpa diffdrive move`: the move report, dry runs and refusals.

The report's coupling numbers and the number of samples depend on wall time (the move runs in real
time on the simulated arm), so those are replaced before the comparison; positions, commands and the stop lines
are the same on every run. tests/test_diffdrive.py checks the numbers themselves.
"""

from __future__ import annotations

import re

import pytest

MIS = ["--config", "tests/data/diffdrive-arm.yaml", "--sim"]
FAST = ["--config", "tests/data/jog-fast-arm.yaml", "--sim"]
CASES = [
    # Σ 1 rad is an odd count: the held Δ gives way one count, said as planned (not as coupling)
    ("diffdrive-move-sigma", [*MIS, "diffdrive", "move", "diff", "--sigma", "1", "--apply"], 0),
    ("diffdrive-move-delta-relative", [*MIS, "diffdrive", "move", "roll", "--delta", "-200counts", "--relative",
                                       "--naive", "--apply"], 0),
    ("diffdrive-move-json", [*MIS, "--json", "diffdrive", "move", "diff", "--sigma", "0.2", "--delta", "5deg",
                             "--apply"], 0),
    ("diffdrive-move-poll-feedback", [*MIS, "diffdrive", "move", "diff", "--delta", "0.3", "--feedback", "--poll",
                                      "--apply"], 0),
    ("diffdrive-move-dry-run", [*MIS, "diffdrive", "move", "diff", "--sigma", "1", "--feedback"], 0),
    ("diffdrive-refuse-normal-range", [*MIS, "diffdrive", "move", "diff", "--sigma", "3", "--apply"], 2),
    ("diffdrive-refuse-delta-range", [*MIS, "diffdrive", "move", "diff", "--delta", "-120deg", "--apply"], 2),
    ("diffdrive-refuse-nothing", [*MIS, "diffdrive", "move", "diff", "--apply"], 2),
    ("diffdrive-refuse-naive-feedback", [*MIS, "diffdrive", "move", "diff", "--sigma", "1", "--naive",
                                         "--feedback"], 2),
    ("diffdrive-refuse-unit", [*MIS, "diffdrive", "move", "diff", "--sigma", "1furlong"], 2),
    ("diffdrive-refuse-uncalibrated", [*FAST, "diffdrive", "move", "diff", "--sigma", "100counts", "--apply"], 1),
]


def _stable(text: str) -> str:
    text = re.sub(r"^(coupling|off the straight).*$", r"\1: <varies>", text, flags=re.M)
    text = re.sub(r"^(recording: .*), \d+ samples$", r"\1, <n> samples", text, flags=re.M)
    text = re.sub(r'"(duration_s|samples|feedback_corrections)": [0-9.]+', r'"\1": "<varies>"', text)
    text = re.sub(r'("(?:sigma_off_path|delta_off_path|held_excursion)": )\{[^}]*\}', r'\1"<varies>"', text)
    return text


@pytest.mark.golden
@pytest.mark.parametrize("name,args,code", CASES, ids=[c[0] for c in CASES])
def test_diffdrive_golden(cli, golden, name, args, code):
    result = cli(*args)
    assert "Traceback" not in result.stderr
    assert result.exit_code == code, result.transcript()
    golden(f"{name}.txt", _stable(result.transcript()))
