"""A moving command killed (SIGKILL) in its own process, the simulated arm in another: the
next motion command refuses the drive and says what a killed command left; `sherpa
recover` says what happened and, with --apply, puts it back so that the drive reads exactly as before
the killed command (SDO and interpreter snapshot); a jog then works. `jog --velocity` and `log record`
are also covered by tests/test_journal_crossprocess.py; here `home`, `diffdrive move` and `log step`,
one simulator process for the module."""

from __future__ import annotations

import signal
import time

import pytest
from killed_helpers import MOVING, Moving, snapshot, wait_moving
from killed_helpers import arm as arm
from killed_helpers import own_arm as own_arm
from killed_helpers import shared_arm as shared_arm
from test_motion_crossprocess import finish, sherpa

from sherpa_cli.config import load_config
from sherpa_cli.sim.drive import UNGUARDED_MO

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
    if name == "diffdrive move":
        # the group start's reset communication came before any motor went on: the consumer that
        # stopped them is the one armed again after it
        ons = 0
        for d in cmd.drives:
            texts = [e["event"] for e in arm.events(d) if e["t"] >= since]
            reset = [i for i, t in enumerate(texts) if t.startswith("NMT reset communication: group id 125")]
            on = [i for i, t in enumerate(texts) if t.startswith("motor on")]
            assert reset and (not on or reset[0] < on[0]), texts
            ons += bool(on)
        assert ons, "no motor of the pair went on before the kill"
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
    unguarded = [e for d in cmd.drives for e in arm.events(d) if e["event"].startswith(UNGUARDED_MO)]
    assert not unguarded, f"a motor went on without an armed dead-man: {unguarded}"
    after = snapshot(arm, cmd.drives)
    assert {k: v for k, v in after.items() if before[k] != v} == {}, "not as before the killed command"
    code, out, err = finish(sherpa(arm, tmp_path, *jog))
    assert code == 0, f"{out}\n{err}"
    assert "Traceback" not in err


def test_a_journal_deleted_by_hand_blinds_recover_but_check_drives_reads_the_drive_and_resets_it(arm, tmp_path):
    """The journal knows only what it holds: deleted by hand, `recover` finds nothing. `--check-drives`
    reads the drive itself (the killed jog's dead-man on a pool id nobody holds, tripped), and
    `--apply` resets it (RAM from flash): the drive reads as before the jog, and the next jog runs."""
    cmd = MOVING["jog"]
    drive = cmd.drives[0]
    before = snapshot(arm, cmd.drives)
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    try:
        wait_moving(arm, cmd, since, proc, tmp_path)
    finally:
        t_kill = time.monotonic()
        proc.send_signal(signal.SIGKILL)
        finish(proc)
    arm.wait_trip(cmd.drives, t_kill)
    notes = list((tmp_path / "state" / "sherpa-cli" / "journal").glob("*.json"))
    assert notes, "the killed jog left no journal"
    for path in notes:
        path.unlink()
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive))
    assert code == 0 and "nothing to recover" in out, f"{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive, "--check-drives"))
    assert code == 0, f"{out}\n{err}"
    assert f"{drive} (" in out and "0x1016:1=0x00" in out and "no sherpa command of this machine holds" in out, out
    assert "MF=0x800: its dead-man tripped" in out and "dry run" in out, out
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive, "--check-drives", "--apply"))
    assert code == 0, f"{out}\n{err}"
    assert "NMT reset node: RAM reloaded from flash" in out and "after the reset: at rest" in out, out
    after = snapshot(arm, cmd.drives)
    assert {k: v for k, v in after.items() if before[k] != v} == {}, "not as before the killed command"
    jog = ("jog", cmd.joint, "--velocity", "0.1", "--for", "0.3", "--apply")
    code, out, err = finish(sherpa(arm, tmp_path, *jog))
    assert code == 0 and "Traceback" not in err, f"{out}\n{err}"


def test_recover_killed_right_after_its_mo1_leaves_the_motor_to_its_consumer_and_the_journal_to_the_next(
        arm, tmp_path):
    """`recover --apply` clears a tripped dead-man with MO=1, MO=0. It used to send MO=1
    with the consumer already put back (0x1016:1 = 0) and the journal already deleted: killed in that
    window the motor stayed on, and `recover` then said "nothing to recover". Now it arms a dead-man of
    its own first and keeps the journal until the drive is back."""
    cmd = MOVING["jog"]
    drive = cmd.drives[0]
    before = snapshot(arm, cmd.drives)
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    wait_moving(arm, cmd, since, proc, tmp_path)
    t_kill = time.monotonic()
    proc.send_signal(signal.SIGKILL)
    finish(proc)
    arm.wait_trip(cmd.drives, t_kill)
    since = time.monotonic()
    rec = sherpa(arm, tmp_path, "recover", drive, "--apply")
    try:
        wait_moving(arm, cmd, since, rec, tmp_path)  # its MO=1; the drive is deaf for its settle window
    finally:
        t_kill = time.monotonic()
        rec.send_signal(signal.SIGKILL)
        finish(rec)
    off = arm.wait_event(lambda text: text.startswith("motor off"), 10 * arm.consumer_s, after=since)
    assert off["event"] == "motor off: heartbeat lost, 0x6007=2", arm.events()
    assert 0 < (off["t"] - t_kill) / arm.consumer_s <= 1.5, f"{off['t'] - t_kill:.3f} s after the kill"
    unguarded = [e for e in arm.events(drive) if e["event"].startswith(UNGUARDED_MO)]
    assert not unguarded, f"a motor went on without an armed dead-man: {unguarded}"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive))
    assert code == 0 and "left by a command that did not finish" in out, f"{out}\n{err}"
    assert "its dead-man tripped" in out, out
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive, "--apply"))
    assert code == 0 and "MF 0x800 cleared" in out, f"{out}\n{err}"
    after = snapshot(arm, cmd.drives)
    assert {k: v for k, v in after.items() if before[k] != v} == {}, "not as before the killed command"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive))
    assert code == 0 and "nothing to recover" in out, out


PAIR_JOG = Moving("pair jog", ("jog", "shoulder_pitch", "--velocity", "0.03", "--for", "60", "--apply"),
                  ("shoulder_2a", "shoulder_2b"), "shoulder_pitch", "motion command")


@pytest.mark.parametrize("name", ["home", "diffdrive move", "pair jog"])
def test_sherpa_stop_from_elsewhere_ends_home_and_a_pair_move_normally_with_every_setting_put_back(
        own_arm, tmp_path, name):
    """`sherpa stop` during `home` (4/5) or a pair move ended with "no answer to HM[1]
    within 0.1 s ... check that the drive is powered" (exit 3) and left UM, SP, HM[1] and the dead-man
    changed (the indexed query skipped the MO settle wait). Now: exit 1, the stop from elsewhere
    named, nothing about power, the drives as before, nothing for `recover`."""
    arm = own_arm  # the home must start on its search side of the switch: a just powered-up arm
    cmd = PAIR_JOG if name == "pair jog" else MOVING[name]
    before = snapshot(arm, cmd.drives)
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    try:
        t_on = wait_moving(arm, cmd, since, proc, tmp_path)
        time.sleep(0.3)
        assert proc.poll() is None, f"`{name}` ended before the stop:\n{finish(proc)}"
        s_code, s_out, s_err = finish(sherpa(arm, tmp_path, "stop", cmd.joint))
        assert s_code == 0, f"{s_out}\n{s_err}"
    finally:
        if proc.poll() is None:
            code, out, err = finish(proc)
        else:
            code, out, err = proc.returncode, *proc.communicate()
    assert code == 1, f"{out}\n{err}"
    assert "from elsewhere (sherpa stop" in err, err
    assert "powered" not in err and "Traceback" not in err, err
    assert not [e for d in cmd.drives for e in arm.events(d) if e["t"] >= t_on and "heartbeat lost" in e["event"]]
    after = snapshot(arm, cmd.drives)
    assert {k: v for k, v in after.items() if before[k] != v} == {}, "settings not put back"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", *cmd.drives))
    assert code == 0 and "nothing to recover" in out, f"{out}\n{err}"


@pytest.mark.parametrize("name", ["home", "diffdrive move", "log step", "log record"])
def test_a_drive_reset_during_a_command_leaves_nothing_the_next_command_refuses(own_arm, tmp_path, name):
    """NMT reset node from another node while a command runs: its RAM is back at flash
    values, so no note of it may make the next motion command refuse the drive."""
    from test_motion_crossprocess import send_frame

    arm = own_arm  # where a home's joint starts matters: a just powered-up arm
    cmd = MOVING[name]
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, *cmd.argv(tmp_path))
    try:
        wait_moving(arm, cmd, since, proc, tmp_path)
        time.sleep(0.3)
        drives = load_config(arm.config).drives
        for d in cmd.drives:  # every drive of the command reset by another node (a second host's tool)
            send_frame(arm, tmp_path, drives[d].bus, 0x000, bytes([0x81, drives[d].node]))
        if name == "log record":
            time.sleep(1.0)
            proc.send_signal(signal.SIGINT)
        code, out, err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            finish(proc)
    assert "Traceback" not in err, err
    # the reset named, exit 1 (Ctrl-C ends the recording: 130); not a confirmation polling a deaf drive
    assert code == (130 if name == "log record" else 1), f"{out}\n{err}"
    assert "not confirmed" not in err and "NOT reached" not in err, err
    jog = ("jog", cmd.joint, "--velocity", "0.03", "--for", "0.3", "--uncalibrated", "--apply")
    code, out, err = finish(sherpa(arm, tmp_path, *jog))
    assert code == 0 and "did not finish" not in err, f"{out}\n{err}"



RECORDER = [("RC", 0), ("RG", 0), ("RL", 0), ("RP", 3), *(("RV", n) for n in range(1, 6))]


def _recorder_settings(arm, drive: str) -> dict[str, int]:
    from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
    from sherpa_cli.bus.session import ArmSession, resolve_target

    cfg = apply_bus_map(load_config(arm.config), parse_bus_map([arm.bus_map]))
    ref = resolve_target(cfg, drive)
    with ArmSession.open(cfg, buses=[ref.bus]) as s:
        c = s.client(ref)
        c.nmt_start()
        return {f"{k}[{i}]": int(c.get(k, i)) for k, i in RECORDER}


def test_a_killed_drive_recording_leaves_its_recorder_settings_to_recover(arm, tmp_path):
    """The drive recorder's settings (RV, RC, RG, RL, RP[3]) are journaled before they
    change: a SIGKILLed `log record --source drive` leaves them listed by `recover`, which puts them back."""
    import json

    drive = "elbow_1a"
    before = _recorder_settings(arm, drive)
    proc = sherpa(arm, tmp_path, "log", "record", drive, "--source", "drive", "--trigger", "bg", "--for", "2",
                  "-o", str(tmp_path / "rec.csv"))
    path = tmp_path / "state" / "sherpa-cli" / "journal" / "can1-node40.json"
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            steps = json.loads(path.read_text() or "{}").get("steps", []) if path.exists() else []
            if any(s["owner"] == "drive recorder" for s in steps):
                time.sleep(0.3)  # configured and armed, waiting for a BG
                break
            time.sleep(0.02)
        assert proc.poll() is None, f"the recording ended:\n{finish(proc)}"
    finally:
        proc.send_signal(signal.SIGKILL)
        finish(proc)
    assert _recorder_settings(arm, drive) != before, "the recording changed nothing: the test proves nothing"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive))
    assert code == 0 and "RC=" in out and "RL=" in out, f"{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", drive, "--apply"))
    assert code == 0, f"{out}\n{err}"
    assert _recorder_settings(arm, drive) == before


KILLED_AT_SV = """\
import os, signal, sys
from sherpa_cli.elmo.client import DriveClient
DriveClient.save = lambda self: os.kill(os.getpid(), signal.SIGKILL)  # a crash between the writes and the SV
from sherpa_cli.cli.app import run
sys.exit(run(sys.argv[1:]))
"""


def test_program_limits_killed_before_its_sv_is_saved_by_the_rerun_and_recover_says_so(arm, tmp_path):
    """SIGKILL between the last verified write and the SV. The rerun used to say
    "nothing to change: RAM holds the targets ... no SV sent" and the next power-up lost every value.
    Now the save ledger is marked before the first write: `recover` lists the drive as SV pending,
    and the rerun with --save saves (after read-back), counted."""
    import subprocess
    import sys

    from conftest import ROOT
    from test_cross_process import _env

    args = ["--config", arm.config, "--bus-map", arm.bus_map, "program-limits", "elbow_pitch", "--apply", "--save",
            "--yes"]
    killed = subprocess.run([sys.executable, "-c", KILLED_AT_SV, *args], cwd=ROOT, env=_env(tmp_path),
                            capture_output=True, text=True, timeout=120)
    assert killed.returncode == -signal.SIGKILL, f"{killed.returncode}\n{killed.stdout}\n{killed.stderr}"
    code, out, err = finish(sherpa(arm, tmp_path, "recover"))
    assert code == 0 and "elbow_1a: values written and not saved to flash (SV pending)" in out, f"{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, *args[4:]))
    assert code == 0, f"{out}\n{err}"
    assert "SV due" in out and "saved" in out and "no SV sent" not in out, out
    code, out, err = finish(sherpa(arm, tmp_path, "recover"))
    assert "SV pending" not in out, out
    code, out, err = finish(sherpa(arm, tmp_path, *args[4:]))  # saved: nothing more to do
    assert code == 0 and "SV due" not in out, out
