"""A bus that goes away mid-command: the served simulator is killed (SIGKILL) while
`jog`, `home` or `log record` runs in another process. The command ends with one `error:` line naming
the bus, exit 3, and no thread traceback from the CAN library (python-can's Listener.on_error path)."""

from __future__ import annotations

import time

import pytest
from killed_helpers import MOVING, fresh, wait_moving
from killed_helpers import remote_arm as remote_arm
from test_motion_crossprocess import finish, sherpa

# python-can-remote only: on kernel vcan a killed simulator leaves the interface up (its drives go
# silent instead: the drive watch's case, tests/test_drive_watch*.py)
pytestmark = pytest.mark.crossprocess

BUS_OF = {"jog": "can1", "home": "can0", "log record": "can1", "log step": "can1"}
LONGEST_LINE = 240  # characters: a drive's stop line names the lost bus once, not once per object


@pytest.mark.parametrize("name", list(BUS_OF))
def test_the_simulator_killed_mid_command_gives_one_line_and_exit_3(remote_arm, tmp_path, name):
    arm = fresh(remote_arm)
    cmd = MOVING[name]
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    try:
        wait_moving(arm, cmd, since, proc, tmp_path)
        assert proc.poll() is None, f"`{name}` ended before the simulator was killed:\n{finish(proc)}"
        killed = remote_arm.kill()
        code, out, err = finish(proc)
        ended = time.monotonic() - killed
    finally:
        if proc.poll() is None:
            proc.kill()
            finish(proc)
    why = f"exit {code} {ended:.2f} s after the kill\n--- stdout\n{out}--- stderr\n{err}"
    assert code == 3, why
    assert "Traceback" not in err and "Exception in thread" not in err and "not properly shut down" not in err, why
    errors = [ln for ln in err.splitlines() if ln.startswith("error: ")]
    assert len(errors) == 1 and errors[0].startswith(f"error: bus {BUS_OF[name]} (") and \
        "the connection to the bus was lost" in errors[0], why
    assert ended < 30, why  # not the recording's 60 s
    # one short line per drive not reached (it repeated the connection error per object,
    # 750-970 characters), saying "not reached" as the docs do
    for line in err.splitlines():
        assert len(line) <= LONGEST_LINE, f"{len(line)} characters: {line}"
    stops = [ln for ln in err.splitlines() if ln.startswith("stop: ")]
    assert all("NOT stopped" not in ln for ln in stops), why
