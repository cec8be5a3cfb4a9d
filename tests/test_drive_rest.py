"""`recover --check-drives` (sherpa_cli/ops/drive_rest.py): a drive's RAM read for what a command
leaves behind, with no journal to go by; a reset node where something is found, and the flash named
when it holds the finding."""

from __future__ import annotations

import struct

import pytest
from conftest import ROOT

from sherpa_cli.bus.machine_lock import MachineLock, wire_key
from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.ops.drive_rest import check_drive
from sherpa_cli.sim.arm import SimArm


@pytest.fixture
def arm():
    cfg = load_config(ROOT / "configs" / "sherpa-arm.yaml")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        yield cfg, s


def _start(s: ArmSession, ref):
    s.client(ref).nmt_start()  # the interpreter answers in NMT Operational only
    return ref


def _arm_homing(s: ArmSession, ref) -> None:
    """HM[1] = 1 on a switch input, as home leaves it mid-search (an immediate event fires at once)."""
    c = s.client(ref)
    c.set("HM", 3, s.sim.drives[ref.name].settings.hm_event_input_base + 1)
    c.set("HM", 1, 1)


def _u32(s: ArmSession, ref, index: int, sub: int) -> int:
    return struct.unpack("<I", (bytes(s.sdo(ref).upload(index, sub)) + bytes(4))[:4])[0]


def _leave_everything(cfg, s: ArmSession, ref) -> None:
    """What a killed pair command and a killed home leave on a pair drive, its journal gone."""
    _arm_homing(s, ref)
    s.sdo(ref).download(0x1016, 1, struct.pack("<I", 124 << 16 | 500))
    s.sdo(ref).download(0x2040, 0, bytes([cfg.motion.pair_group_id]))


def test_a_drive_at_rest_has_no_finding(arm):
    cfg, s = arm
    res = check_drive(s, cfg, resolve_target(cfg, "shoulder_2a"), apply=True)
    assert (res.findings, res.done, res.problems, res.after_reset) == ([], [], [], None)


def test_every_sign_of_a_command_that_did_not_finish_is_found_and_a_dry_run_changes_nothing(arm):
    cfg, s = arm
    ref = _start(s, resolve_target(cfg, "shoulder_2a"))
    _leave_everything(cfg, s, ref)
    res = check_drive(s, cfg, ref, apply=False)
    assert [(f.what, f.value) for f in res.findings] == [
        ("0x1016:1", "0x007C01F4"), ("0x2040", str(cfg.motion.pair_group_id)), ("HM[1]", "1")]
    assert "a dead-man on host 124 that no sherpa command of this machine holds" in res.findings[0].meaning
    assert res.done == [] and res.problems == []
    assert _u32(s, ref, 0x1016, 1) == 124 << 16 | 500  # nothing written


def test_rpdo2_left_synchronous_is_found_without_the_deaf_interpreter_and_never_reset_blind(arm):
    cfg, s = arm
    ref = _start(s, resolve_target(cfg, "shoulder_2a"))
    s.sdo(ref).download(0x1401, 2, bytes([1]))
    res = check_drive(s, cfg, ref, apply=True)
    assert [(f.what, f.value) for f in res.findings] == [("0x1401:2", "1")]
    assert res.done == [] and res.problems[0].startswith("RPDO2 is synchronous: the interpreter cannot tell whether "
                                                         "the motor is on, so no reset; switch the drive's power")
    assert bytes(s.sdo(ref).upload(0x1401, 2))[0] == 1


def test_apply_resets_the_drive_and_reads_it_at_rest_again(arm):
    cfg, s = arm
    ref = _start(s, resolve_target(cfg, "shoulder_2a"))
    _leave_everything(cfg, s, ref)
    res = check_drive(s, cfg, ref, apply=True, boot_timeout=2.0)
    assert res.done and res.done[0].startswith("NMT reset node: RAM reloaded from flash")
    assert res.after_reset == [] and res.problems == []
    assert _u32(s, ref, 0x1016, 1) == 0
    assert int(s.client(ref).get("HM", 1)) == 0


def test_a_finding_the_flash_holds_survives_the_reset_and_is_said_so(arm):
    """An SV made while a dead-man was armed puts it into flash: a reset cannot take it back, and the
    tool never reports it as put back."""
    cfg, s = arm
    ref = _start(s, resolve_target(cfg, "elbow_1a"))
    s.sdo(ref).download(0x1016, 1, struct.pack("<I", 126 << 16 | 500))
    s.client(ref).execute("SV")
    res = check_drive(s, cfg, ref, apply=True, boot_timeout=2.0)
    assert [f.what for f in res.after_reset or []] == ["0x1016:1"]
    assert res.problems == [f"0x1016:1=0x007E01F4 after the reset: the flash holds it ({res.findings[0].meaning})"]


def test_a_drive_a_running_command_holds_is_not_judged(arm):
    cfg, s = arm
    ref = _start(s, resolve_target(cfg, "elbow_1a"))
    s.sdo(ref).download(0x1016, 1, struct.pack("<I", 124 << 16 | 500))
    link = s.links["can1"].config
    lock = MachineLock(wire_key(link.interface, link.channel), "host124")
    assert lock.try_acquire()
    try:
        res = check_drive(s, cfg, ref, apply=True)
    finally:
        lock.release()
    assert res.findings == [] and res.done == []
    assert res.in_use is not None and res.in_use.startswith("its dead-man watches host 124, held by sherpa pid ")
    assert _u32(s, ref, 0x1016, 1) == 124 << 16 | 500


def test_a_motor_on_is_not_reset(arm):
    cfg, s = arm
    ref = _start(s, resolve_target(cfg, "elbow_1a"))
    _arm_homing(s, ref)
    s.client(ref).motor_on()
    try:
        res = check_drive(s, cfg, ref, apply=True)
    finally:
        s.client(ref).motor_off()
    assert res.done == [] and res.problems == ["the motor is on (MO=1): not reset; stop it first (`sherpa stop`)"]
    assert int(s.client(ref).get("HM", 1)) == 1


def test_the_cli_lists_every_drive_and_exits_0_when_all_are_at_rest(cli):
    result = cli("--sim", "recover", "elbow_pitch", "wrist_1a", "--check-drives")
    assert result.exit_code == 0, result.transcript()
    assert result.stdout.splitlines()[0] == "elbow_1a (can1:40): at rest: nothing a command leaves behind"
    assert result.stdout.splitlines()[-1].startswith("dry run:")
