"""SIGINT and SIGTERM to every moving command (jog, home, diffdrive move, log step, log record) at
0.05 s, at 0.2 s and mid-move, each in its own process with the simulated arm in
another (one simulator for the module): the documented exit code (docs/exit-codes.md "Signals"), one
`error:` line and no traceback, the stop report when a motor was on, and nothing left in the journal."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import pytest
from killed_helpers import MOVING, wait_moving
from killed_helpers import arm as arm
from killed_helpers import shared_arm as shared_arm
from test_motion_crossprocess import finish, sherpa

# 30 runs of a second Python process: the CI tests stage runs them (python-can-remote); the 15-20x
# slower vcan guest would spend most of its time limit here (the signal paths do not depend on the bus)
pytestmark = pytest.mark.crossprocess

ERROR_LINE = {signal.SIGINT: "error: interrupted", signal.SIGTERM: "error: interrupted by SIGTERM"}
BEFORE_MOTION = {signal.SIGINT: 130, signal.SIGTERM: 143}  # nothing to stop yet
IN_MOTION = 130  # the guard (or the recorder) stopped what ran, then 130 for either signal


def _caught(pid: int) -> set[int]:
    """The signals the process has a handler for (Linux: SigCgt in /proc/PID/status)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return set()
    for line in text.splitlines():
        if line.startswith("SigCgt:"):
            mask = int(line.split()[1], 16)
            return {n for n in range(1, 65) if mask >> (n - 1) & 1}
    return set()


def _leftovers(tmp_path: Path) -> dict[str, list]:
    folder = tmp_path / "state" / "sherpa-cli" / "journal"
    files = sorted(folder.glob("*.json")) if folder.exists() else []
    return {f.name: steps for f in files if (steps := json.loads(f.read_text() or "{}").get("steps"))}


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads SigCgt from /proc")
@pytest.mark.parametrize("when", ["0.05 s", "0.2 s", "mid-move"])
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=lambda s: signal.Signals(s).name)
@pytest.mark.parametrize("name", list(MOVING))
def test_a_signal_to_a_moving_command(arm, tmp_path, name, signum, when):
    cmd = MOVING[name]
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    try:
        if when == "mid-move":
            wait_moving(arm, cmd, since, proc, tmp_path)
            time.sleep(0.3)
        else:
            # Python's own start (before sherpa's first instruction) is not sherpa's to handle: wait
            # for the entry's handlers if a loaded machine takes longer than that to get there
            while signal.SIGTERM not in _caught(proc.pid) and time.monotonic() - since < 30 and proc.poll() is None:
                time.sleep(0.002)
            time.sleep(max(0.0, float(when.split()[0]) - (time.monotonic() - since)))
        assert proc.poll() is None, f"`{name}` ended before the signal:\n{finish(proc)}"
        proc.send_signal(signum)
        code, out, err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            finish(proc)
    why = f"exit {code}\n--- stdout\n{out}--- stderr\n{err}"
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, why
    moved = any(e["t"] >= since and e["event"].startswith("motor on") for d in cmd.drives for e in arm.events(d))
    stop_lines = [ln for ln in err.splitlines() if ln.startswith("stop: ")]
    errors = [ln for ln in err.splitlines() if ln.startswith("error: ")]
    if when == "mid-move" or moved or stop_lines:
        assert code == IN_MOTION, why
        if cmd.name != "log record":
            assert moved, why
            assert any(f"{d} (" in ln and "stopped; motor off" in ln for ln in stop_lines for d in cmd.drives), why
    else:  # the signal came before anything was opened or moved
        assert code == BEFORE_MOTION[signum], why
        assert errors == [ERROR_LINE[signum]], why
    assert len(errors) <= 1, why
    if cmd.name == "log record" and when == "mid-move":
        assert "interrupted" in err and "restored" in err, why
    assert _leftovers(tmp_path) == {}, f"the journal kept changes that were not put back\n{why}"
