"""A jog of a CiA 402 joint SIGKILLed in its own process, the simulated arm (tests/data/cia402-arm.yaml)
served in another: the drive's own heartbeat consumer, armed by the motion guard through SDO, ends the
motion per 0x6007 as the guard armed it (motion.loss_action), and no motor went on without an armed dead-man."""

from __future__ import annotations

import dataclasses
import signal
import time
from pathlib import Path

import pytest
from arm_harness import ArmProcess, TestBus
from conftest import ROOT
from killed_helpers import fresh
from test_motion_crossprocess import EVENT_TIMEOUT, START_TIMEOUT, finish, sherpa

from sherpa_cli.config import dump_native, load_config
from sherpa_cli.sim.drive import UNGUARDED_MO

pytestmark = [pytest.mark.realbus, pytest.mark.crossprocess]

CONFIG = Path(__file__).resolve().parent / "data" / "cia402-arm.yaml"


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    work = tmp_path_factory.mktemp("cia402-arm")
    cfg = load_config(CONFIG)
    # the harness's patient timeouts (a loaded machine, the QEMU guest)
    cfg = dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, reply_timeout=2.0, retries=2,
                                                                mo_confirm_timeout=20.0, sdo_timeout=3.0))
    # a slow wrist: a jog of it still runs when the test kills it
    slow = dataclasses.replace(cfg.joints["wrist"], vel_limit=20)
    cfg = dataclasses.replace(cfg, joints={**cfg.joints, "wrist": slow})
    path = work / "arm.yaml"
    path.write_text(dump_native(cfg))
    proc = ArmProcess(TestBus("remote"), ROOT, str(path), work)
    try:
        proc.start()
    except RuntimeError as exc:
        pytest.skip(f"the served simulator did not start: {exc}")
    try:
        yield proc
    finally:
        proc.stop()


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
        time.sleep(0.3)  # moving
        assert proc.poll() is None, f"the jog ended before the kill:\n{finish(proc)}"
    finally:
        t_kill = time.monotonic()
        proc.send_signal(signal.SIGKILL)
        finish(proc)
    tripped = arm.wait_event(lambda text: text.startswith("heartbeat lost"), EVENT_TIMEOUT, after=t_kill,
                             drive="wrist")
    # 0x6007 as the guard armed it: motion.loss_action (2, disable voltage: the power stage off)
    assert tripped["event"] == f"heartbeat lost (0x6007={load_config(CONFIG).motion.loss_action})", tripped
    off = arm.wait_event(lambda text: text.startswith("motor off"), EVENT_TIMEOUT, after=t_kill, drive="wrist")
    assert off["t"] >= tripped["t"], (tripped, off)  # by the consumer, not by the killed tool
    # stopped within the consumer time after the last heartbeat, with margin for the two processes
    assert tripped["t"] - t_kill <= arm.consumer_s + 2.0, (t_kill, tripped)
    texts = [e["event"] for e in arm.events("wrist") if e["t"] >= since]
    assert not [t for t in texts if t.startswith(UNGUARDED_MO)], texts
    # what the drive says afterwards: the motor off (monitor), and `stop` reaches it
    code, out, err = finish(sherpa(arm, tmp_path, "monitor", "--once", "wrist"))
    row = next(line for line in out.splitlines() if " wrist " in line)
    assert " off " in row and "Traceback" not in err, f"{code}\n{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "stop", "wrist"))
    assert code == 0 and "motor was off" in out, f"{out}\n{err}"
