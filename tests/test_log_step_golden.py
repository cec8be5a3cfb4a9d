"""Golden outputs of `sherpa --sim log step` (a position step of 1 rad with the MO/UM
switch's delay when the drive was in another mode and none when it was not, a velocity step of
0.1 rad/s, a torque step of 1 A).

`--sim log step` runs the in-process arm on stepped time (sim/stepped.py): SYNC and the clock move
in lockstep, the drive clients' waits are charged on that clock, so every figure printed is the
simulated drive's and the same on every run and machine; nothing is replaced before the
comparison except the test's temporary directory. The drive's mode before the step is set on the
simulated drive after power-up (a technician's earlier command), past its MO settle window.
"""

from __future__ import annotations

import json

import pytest
from conftest import TEST_PROTOCOL_WINDOWS

from sherpa_cli.sim.arm import SimArm

ARM = ["--config", "tests/data/step-arm.yaml", "--sim"]
CASES = [
    # (golden, step arguments, drive state before the command: (UM, MO) or None = power-up)
    ("log-step-position-switch", ["--position", "1"], (2, 1)),  # velocity mode, motor on: MO=0, UM=5, MO=1
    ("log-step-position-no-switch", ["--position", "1"], (5, 1)),  # already position mode, motor on
    ("log-step-velocity", ["--velocity", "0.1", "--for", "1"], None),
    ("log-step-torque", ["--torque", "1", "--for", "0.3"], None),
    # cut off before it settles -> "not settled within 0.2 s", no overshoot or error
    ("log-step-position-not-settled", ["--position", "1", "--for", "0.2"], None),
    # Fig. 9.2: the drive put in position mode before t = 0, so the step has no switch
    ("log-step-position-mode-first", ["--position", "1", "--mode-first"], None),
    # Figs. 9.3/9.6: a velocity step that goes on recording its constant speed
    ("log-step-velocity-hold", ["--velocity", "0.1", "--for", "1", "--hold", "0.5"], None),
]


def _preset(monkeypatch, um: int, mo: int) -> None:
    start = SimArm.start

    def started(self):
        start(self)
        with self.lock:
            drive = self.drives["elbow"]
            drive.write_param("UM", um)
            drive.write_param("MO", mo)
            self.clock.advance(0.5)  # well past the MO settle window before the command's first request
            drive.tick()
        return self

    monkeypatch.setattr(SimArm, "start", started)


@pytest.mark.golden
@pytest.mark.parametrize("name,args,before", CASES, ids=[c[0] for c in CASES])
def test_log_step_golden(cli, golden, monkeypatch, tmp_path, name, args, before):
    if before is not None:
        _preset(monkeypatch, *before)
    out = tmp_path / "step"
    result = cli(*ARM, "log", "step", "arm", *args, "--rate", "500", "-o", str(out), "--apply")
    assert "Traceback" not in result.stderr
    assert result.exit_code == 0, result.transcript()
    golden(f"{name}.txt", result.transcript().replace(str(tmp_path), "TMP"))
    metrics = json.loads((out / "metrics.json").read_text())
    if name == "log-step-position-no-switch":
        assert metrics["switch_s"] == 0 and metrics["metrics"]["dead_time"] < 0.05
    elif name == "log-step-position-switch":
        # MO=0, UM 2 -> 5, MO=1: at least the drive's two MO settle windows (the cli fixture's)
        assert metrics["switch_s"] >= 2 * TEST_PROTOCOL_WINDOWS["mo_settle"] - 1e-9
        assert metrics["metrics"]["dead_time"] > metrics["switch_s"]
        assert metrics["switch_steps"] == ["MO=0", "UM=5", "MO=1"]  # the motor was on: two settle windows
    elif name == "log-step-position-not-settled":
        assert metrics["settled"] is False and metrics["ended_by"] == "time up"
        m = metrics["metrics"]
        assert m["overshoot"] is None and m["steady_state_error"] is None and m["settling_time"] is None
        assert "not settled within 0.2 s" in result.stdout and "overshoot" not in result.stdout.split("no overshoot")[0]
    elif name == "log-step-position-mode-first":
        assert metrics["switch_steps"] == [] and metrics["switch_s"] < 0.01 and metrics["settled"] is True
        assert metrics["metrics"]["dead_time"] < 0.05
    elif name == "log-step-velocity-hold":
        times = [float(line.split(",")[0]) for line in (out / "recording.csv").read_text().splitlines()[1:]]
        # settled (>= the 0.2 s hold of the settle check) and then recorded 0.5 s more
        assert metrics["settled"] is True and times[-1] >= metrics["metrics"]["settling_time"] + 0.5


def test_the_same_step_gives_the_same_recording_twice(cli, tmp_path):
    """Stepped time: two runs record the same samples, to the last digit."""
    runs = []
    for i in range(2):
        out = tmp_path / f"run{i}"
        # the same arm each time: --sim keeps it powered (the joint would start where run 0 left it)
        assert cli(*ARM[:2], "sim", "--reset-state").exit_code == 0
        result = cli(*ARM, "log", "step", "arm", "--position", "1", "--rate", "500", "-o", str(out), "--apply")
        assert result.exit_code == 0, result.transcript()
        runs.append((out / "recording.csv").read_text())
    assert runs[0] == runs[1]
