"""`sherpa cmd` on the simulated arm: golden outputs, dry run, errors."""

from __future__ import annotations

import json

import pytest

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError, SherpaError
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.raw import run_raw, run_raw_guarded, starts_motion
from sherpa_cli.sim.arm import SimArm

# Meaningful on a real bus: run through arm_cli, so also over python-can-remote and vcan.
ARM_CASES = [
    ("cmd-sim-queries", ["cmd", "shoulder_1a", "PX", "LL[3]", "MF", "SR", "IP", "IL[1]", "EC"]),
    ("cmd-sim-dry-run", ["cmd", "shoulder_1a", "AC=150000", "CL[1]=2.5", "BG"]),
    ("cmd-sim-apply", ["cmd", "shoulder_1a", "AC=150000", "AC", "CL[1]=2.5", "CL[1]", "--apply"]),
    ("cmd-sim-json", ["--json", "cmd", "can0:10", "PX", "MF", "AC=1000"]),
    ("cmd-sim-joint-name", ["cmd", "elbow_pitch", "UM", "VH[3]"]),
    ("cmd-sim-refused", ["cmd", "shoulder_1a", "AC", "BG", "PX", "--apply"]),
    ("cmd-sim-other-buses", ["cmd", "wrist_3b", "UM", "IP"]),
]


@pytest.mark.golden
@pytest.mark.realbus
@pytest.mark.parametrize("name,args", ARM_CASES, ids=[c[0] for c in ARM_CASES])
def test_cmd_on_the_arm_golden(arm_golden, name, args):
    arm_golden(name, args)


CASES = [
    ("cmd-sim-missing-node", ["--sim", "cmd", "can0:99", "PX"]),
    ("cmd-bad-index", ["--sim", "cmd", "shoulder_1a", "LL[9]"]),
    ("cmd-lower-case", ["--sim", "cmd", "shoulder_1a", "px"]),
    ("cmd-pair-joint", ["--sim", "cmd", "shoulder_pitch", "PX"]),
    ("cmd-unknown-target", ["--sim", "cmd", "shoulder_1", "PX"]),
    ("cmd-bus-map-and-sim", ["--sim", "--bus-map", "can0=virtual:x", "cmd", "shoulder_1a", "PX"]),
    ("cmd-bus-map-syntax", ["--bus-map", "can0", "cmd", "shoulder_1a", "PX"]),
    ("cmd-bus-map-unknown-bus", ["--bus-map", "can7=virtual:x", "cmd", "shoulder_1a", "PX"]),
    ("cmd-bus-map-multicast", ["--bus-map", "can0=udp_multicast:239.0.0.1", "cmd", "shoulder_1a", "PX"]),
]


@pytest.mark.golden
@pytest.mark.parametrize("name,args", CASES, ids=[c[0] for c in CASES])
def test_cmd_golden(cli, golden, name, args):
    result = cli(*args)
    assert "Traceback" not in result.stderr
    golden(f"{name}.txt", result.transcript())


def test_exit_codes(cli):
    assert cli("--sim", "cmd", "shoulder_1a", "PX").exit_code == 0
    assert cli("--sim", "cmd", "shoulder_1a", "BG", "--apply").exit_code == 4  # drive refused: motor off
    assert cli("--sim", "cmd", "can0:99", "PX").exit_code == 3  # nobody answers
    assert cli("--sim", "cmd", "shoulder_1a", "XQ").exit_code == 2  # unknown command, nothing sent


def test_apply_then_a_new_invocation_sees_the_powered_drive_and_a_power_cycle_forgets_it(cli):
    cli("--sim", "cmd", "shoulder_1a", "AC=150000", "--apply")
    again = json.loads(cli("--sim", "--json", "cmd", "shoulder_1a", "AC").stdout)
    assert again["results"][0]["value"] == 150000  # --sim keeps the arm powered: RAM stays
    assert cli("sim", "--power-cycle").exit_code == 0
    again = json.loads(cli("--sim", "--json", "cmd", "shoulder_1a", "AC").stdout)
    assert again["results"][0]["value"] == 100000  # not saved: RAM is new after the power cycle
    cli("--sim", "cmd", "shoulder_1a", "AC=150000", "SV", "--apply", "--raw-save")
    assert cli("sim", "--power-cycle").exit_code == 0
    saved = json.loads(cli("--sim", "--json", "cmd", "shoulder_1a", "AC").stdout)
    assert saved["results"][0]["value"] == 150000


def test_dry_run_sends_no_set_and_no_execute(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    cfg = load_config("configs/sherpa-arm.yaml")
    ref = resolve_target(cfg, "shoulder_1a")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can0"]) as session:
        client = session.client(ref)
        client.nmt_start()
        results = run_raw(client, ref.node, ["AC=150000", "PX", "BG", "SV", "LL[3]=-5"], apply=False)
        frames = [data for _, can_id, data in session.sim.drives["shoulder_1a"].received if can_id == 0x30A]
    assert [r.sent for r in results] == [False, True, False, False, False]
    assert frames == [bytes.fromhex("50580000")], "only the PX query reached the drive"


@pytest.mark.realbus
def test_mo1_then_a_move_in_one_cmd_goes_through_the_confirmed_motor_switch(arm_cli):
    # MO=1 makes the drive deaf while it settles (protocol.mo_settle, 0.5 s on the arm): a PA sent
    # right after a bare MO=1 would get no answer. The confirmed switch polls MO until it reads 1.
    result = arm_cli("--json", "cmd", "elbow_1a", "MO=1", "PA=300", "BG", "--apply")
    assert result.exit_code == 0, result.transcript()
    assert [r["sent"] for r in json.loads(result.stdout)["results"]] == [True, True, True]
    dry = arm_cli("cmd", "elbow_1a", "MO=1", "PA=300", "BG")  # the dry-run rule stays
    assert dry.exit_code == 0 and "not sent (dry run)" in dry.stdout and "3 commands not sent" in dry.stdout


def _guarded(exprs: list[str], *, fault: int = 0):
    """``cmd elbow_1a EXPRS --apply`` through its engine on an in-process arm: the results, the guard's
    exit lines and the simulated drive (its MO=1 without a dead-man counted)."""
    cfg = load_config("configs/sherpa-arm.yaml")
    ref = resolve_target(cfg, "elbow_1a")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can1"]) as session:
        drive = session.sim.drives["elbow_1a"]
        if fault:
            drive._mf = fault
        session.client(ref).nmt_start()
        on_exit: list[str] = []
        results: list = []
        error = None
        try:
            run_raw_guarded(session, ref, exprs, MotionSettings.from_config(cfg, ["can1"]), results=results,
                            on_exit=on_exit)
        except SherpaError as exc:
            error = exc
        consumer = bytes(session.sdo(ref).upload(0x1016, 1))
        return results, on_exit, drive, consumer, error


def test_mo1_in_cmd_runs_under_an_armed_dead_man_and_the_motor_is_off_when_cmd_ends():
    """Never a motor on without an armed dead-man: `cmd DRIVE MO=1 --apply` used to switch the motor on
    and leave it on with nothing watching the tool."""
    assert starts_motion(["MO=1"]) and starts_motion(["PA=3", "BG"]) and not starts_motion(["MO=0", "PX", "AC=5"])
    results, on_exit, drive, consumer, error = _guarded(["MO=1", "MO", "PA=300", "BG"])
    assert error is None
    assert [(r.text, r.sent) for r in results] == [("MO=1", True), ("MO", True), ("PA=300", True), ("BG", True)]
    assert results[1].value == 1
    assert drive.unguarded_motor_on == 0
    assert not drive.motor_on
    assert consumer == bytes(4)  # the dead-man put back
    assert on_exit == ["elbow_1a (can1:40): stopped; motor off; settings put back: `cmd` keeps no motor on after "
                       "it ends (its dead-man ends with it); `sherpa jog JOINT --hold` holds a joint"]


def test_mo1_mo0_in_cmd_clears_a_latched_fault_under_the_dead_man_but_a_bg_on_a_faulted_drive_is_refused():
    results, _, drive, _, error = _guarded(["MO=1", "MO=0", "MF"], fault=0x800)
    assert error is None and results[-1].value == 0 and drive.unguarded_motor_on == 0
    results, _, drive, _, error = _guarded(["MO=1", "PA=300", "BG"], fault=0x800)
    assert isinstance(error, SafetyError) and "in fault, refusing to move it" in str(error)
    assert results == [] and not drive.motor_on
