"""A jog of a CiA 402 joint SIGKILLed in its own process, the simulated arm (tests/data/cia402-arm.yaml)
served in another: the drive's own heartbeat consumer, armed by the motion guard through SDO, ends the
motion per 0x6007 as the guard armed it (motion.loss_action: 2 disables the drive, 1 puts it in Fault),
and no motor went on without an armed dead-man. Then the way back: the next jog refuses the drive (the
journal's leftovers) and names `sherpa recover`; `recover` says what happened, `--apply` puts the
objects back and resets a heartbeat-loss fault under a dead-man of its own; the jog runs again."""

from __future__ import annotations

import dataclasses
import signal
import time
from pathlib import Path

import pytest
from killed_helpers import fresh, served_process
from test_motion_crossprocess import EVENT_TIMEOUT, START_TIMEOUT, finish, sherpa

from sherpa_cli.config import dump_native, load_config
from sherpa_cli.sim.drive import UNGUARDED_MO

pytestmark = [pytest.mark.realbus, pytest.mark.crossprocess]

CONFIG = Path(__file__).resolve().parent / "data" / "cia402-arm.yaml"


@pytest.fixture(scope="module", params=[2, 1], ids=["loss_action_2", "loss_action_1"])
def served(tmp_path_factory, request):
    work = tmp_path_factory.mktemp("cia402-arm")
    cfg = load_config(CONFIG)
    cfg = dataclasses.replace(cfg, motion=dataclasses.replace(cfg.motion, loss_action=request.param))
    # the harness's patient timeouts (a loaded machine, the QEMU guest)
    cfg = dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, reply_timeout=2.0, retries=2,
                                                                mo_confirm_timeout=20.0, sdo_timeout=3.0))
    # a slow wrist: a jog of it still runs when the test kills it
    slow = dataclasses.replace(cfg.joints["wrist"], vel_limit=20)
    cfg = dataclasses.replace(cfg, joints={**cfg.joints, "wrist": slow})
    path = work / "arm.yaml"
    path.write_text(dump_native(cfg))
    yield from served_process(str(path), work)


def test_a_killed_jog_of_a_cia402_joint_is_stopped_by_the_drives_own_consumer(served, tmp_path):
    arm = fresh(served)
    since = time.monotonic()
    # a slow move: 3000 counts at 20 counts/s, still running when it is killed
    proc = sherpa(arm, tmp_path, "jog", "wrist", "--by", "3000counts", "--uncalibrated", "--apply")
    try:
        try:
            arm.wait_event(lambda text: text.startswith("PP: target"), START_TIMEOUT, after=since, drive="wrist")
        except AssertionError as exc:
            raise AssertionError(f"{exc}\n{finish(proc)}") from None
        assert proc.poll() is None, f"the jog ended before the kill:\n{finish(proc)}"
    finally:
        t_kill = time.monotonic()
        proc.send_signal(signal.SIGKILL)
        finish(proc)
    tripped = arm.wait_event(lambda text: text.startswith("heartbeat lost"), EVENT_TIMEOUT, after=t_kill,
                             drive="wrist")
    # 0x6007 as the guard armed it: motion.loss_action (2 disable voltage, 1 fault: the power stage off)
    loss_action = load_config(served.config).motion.loss_action
    assert tripped["event"] == f"heartbeat lost (0x6007={loss_action})", tripped
    off = arm.wait_event(lambda text: text.startswith("motor off"), EVENT_TIMEOUT, after=t_kill, drive="wrist")
    assert off["t"] >= tripped["t"], (tripped, off)  # by the consumer, not by the killed tool
    texts = [e["event"] for e in arm.events("wrist") if e["t"] >= since]
    assert not [t for t in texts if t.startswith(UNGUARDED_MO)], texts
    # what the drive says afterwards: the motor off (monitor), and `stop` reaches it
    code, out, err = finish(sherpa(arm, tmp_path, "monitor", "--once", "wrist"))
    row = next(line for line in out.splitlines() if " wrist " in line)
    assert " off " in row and "Traceback" not in err, f"{code}\n{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "stop", "wrist"))
    assert code == 0 and "motor was off" in out, f"{out}\n{err}"

    # the next jog refuses the drive: what the killed one armed is still on it (the journal)
    code, out, err = finish(sherpa(arm, tmp_path, "jog", "wrist", "--by", "20counts", "--uncalibrated", "--apply"))
    assert code == 1 and "did not finish" in err and "sherpa recover wrist" in err, f"{code}\n{out}\n{err}"
    # recover's dry run says what was left and what the consumer did, and changes nothing
    code, out, err = finish(sherpa(arm, tmp_path, "recover", "wrist"))
    assert code == 0 and "left by a command that did not finish" in out and "0x1016:1=0x0" in out, f"{out}\n{err}"
    said = "dead-man tripped" if loss_action == 1 else "dead-man is still armed"
    assert said in out and f"0x6007={loss_action}" in out, f"{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", "wrist"))
    assert code == 0 and "left by a command that did not finish" in out, f"the dry run put something back:\n{out}\n{err}"
    # --apply: the objects back, a heartbeat-loss fault reset under a dead-man of its own
    since_apply = time.monotonic()
    code, out, err = finish(sherpa(arm, tmp_path, "recover", "wrist", "--apply"))
    assert code == 0 and "put back: 0x1016:1=0x0" in out, f"{code}\n{out}\n{err}"
    if loss_action == 1:
        assert "fault reset" in out, out
        assert arm.wait_event(lambda text: text == "fault reset", EVENT_TIMEOUT, after=since_apply, drive="wrist")
    # the jog runs again
    code, out, err = finish(sherpa(arm, tmp_path, "jog", "wrist", "--by", "20counts", "--uncalibrated", "--apply"))
    assert code == 0, f"{code}\n{out}\n{err}"
    every = [(d, e["event"]) for d in load_config(served.config).drives for e in arm.events(d) if e["t"] >= since]
    assert not [(d, t) for d, t in every if t.startswith(UNGUARDED_MO)], every
