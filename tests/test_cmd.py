"""`sherpa cmd` on the simulated arm: golden outputs, dry run, errors."""

from __future__ import annotations

import json

import pytest

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.ops.raw import run_raw
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
    assert dry.exit_code == 0 and "not sent (dry run)" in dry.stdout and "3 command(s) not sent" in dry.stdout
