"""A moving command killed (SIGKILL) in its own process, the simulated arm in another (issue 22 "Killed
tool"): the next motion command refuses the drive and says what a killed command left; `sherpa
recover` says what happened and, with --apply, puts it back so that the drive reads exactly as before
the killed command (SDO and interpreter snapshot); a jog then works. `jog --velocity` and `log record`
are also covered by tests/test_journal_crossprocess.py; here `home`, `diffdrive move` and `log step`,
one simulator process for the module."""

from __future__ import annotations

import signal
import time

import pytest
from killed_helpers import MOVING, snapshot, wait_moving
from killed_helpers import arm as arm
from killed_helpers import shared_arm as shared_arm
from test_motion_crossprocess import finish, sherpa

pytestmark = [pytest.mark.realbus, pytest.mark.crossprocess]


@pytest.mark.parametrize("name", ["home", "diffdrive move", "log step"])
def test_a_killed_moving_command_is_refused_until_recover_puts_the_drive_back(arm, tmp_path, name):
    cmd = MOVING[name]
    before = snapshot(arm, cmd.drives)
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    try:
        wait_moving(arm, cmd, since, proc, tmp_path)
        time.sleep(0.3)  # well into the motion
        assert proc.poll() is None, f"`{name}` ended before the kill:\n{finish(proc)}"
    finally:
        t_kill = time.monotonic()
        proc.send_signal(signal.SIGKILL)  # not os.kill: a command that already ended was reaped
        finish(proc)
    arm.wait_trip(cmd.drives, t_kill)  # what `recover` is to report
    jog = ("jog", cmd.joint, "--velocity", "0.1", "--for", "0.3", "--apply")
    code, out, err = finish(sherpa(arm, tmp_path, *jog))
    assert code == 1, f"{out}\n{err}"
    first = cmd.drives[0]
    assert f"{first} (" in err and "that did not finish (killed?) left temporary changes" in err, err
    assert cmd.owner in err and "sherpa recover" in err and "Traceback" not in err, err
    code, out, err = finish(sherpa(arm, tmp_path, "recover", *cmd.drives))  # dry run: what happened
    assert code == 0 and "dry run" in out and "its dead-man tripped" in out, f"{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", *cmd.drives, "--apply"))
    assert code == 0, f"{out}\n{err}"
    assert "MF 0x800 cleared" in out, out
    after = snapshot(arm, cmd.drives)
    assert {k: v for k, v in after.items() if before[k] != v} == {}, "not as before the killed command"
    code, out, err = finish(sherpa(arm, tmp_path, *jog))
    assert code == 0, f"{out}\n{err}"
    assert "Traceback" not in err
