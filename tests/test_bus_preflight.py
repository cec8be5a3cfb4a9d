"""The preflight (bus/health.py) every moving command, recipe and commissioning runs first, and the user
program (PS) checks before SV and motion (elmo/userprog.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from motion_helpers import motors_off

from sherpa_cli.bus.health import BusStateError, check_buses, preflight
from sherpa_cli.bus.session import ArmSession, DriveRef
from sherpa_cli.config import load_config
from sherpa_cli.elmo.userprog import UserProgramError, describe_ps, program_running
from sherpa_cli.sim.arm import SimArm

ARM = Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml"
JOG = ("jog", "elbow_pitch", "--velocity", "0.05", "--for", "0.1", "--apply")  # elbow_1a on can1


def faulty(tmp_path: Path, sim: str) -> str:
    path = tmp_path / "arm.yaml"
    path.write_text(ARM.read_text() + "\nsim:\n" + sim)
    return str(path)


@pytest.mark.parametrize(("sim", "text", "hint"), [
    ("  buses:\n    can1: {state: bus-off, restart_ms: 0}\n", "the controller is BUS-OFF", "termination"),
    ("  buses:\n    can1: {state: error-passive, tec: 140}\n", "the controller is ERROR-PASSIVE (TEC 140, REC 0)",
     "termination"),
    ("  buses:\n    can1: {bitrate: 125000}\n", "bit rate 125000 differs from the config's 1000000",
     "sherpa bus up can1"),
    ("  buses:\n    can1: {up: false}\n", "the link is down", "sherpa bus up can1"),
    ("  buses:\n    can1: {state: stopped}\n", "the controller is STOPPED", "sherpa bus up can1"),
    ("  buses:\n    can1: {present: false}\n", "no interface can1", "plug in the adapter"),
])
def test_a_jog_is_refused_on_an_unfit_bus_before_anything_moves(cli, tmp_path, sim, text, hint):
    result = cli("--sim", "--config", faulty(tmp_path, sim), *JOG)
    assert result.exit_code == 3, result.transcript()
    assert f"error: bus can1 (socketcan:can1): {text}" in result.stderr
    assert "refusing to start moving" in result.stderr
    assert "hint: " in result.stderr and hint in result.stderr
    assert "Traceback" not in result.stderr


def test_a_fault_on_another_bus_does_not_stop_a_jog(cli, tmp_path):
    result = cli("--sim", "--config", faulty(tmp_path, "  buses:\n    can2: {state: bus-off, restart_ms: 0}\n"), *JOG)
    assert result.exit_code == 0, result.transcript()


def test_warning_is_not_a_refusal(cli, tmp_path):
    result = cli("--sim", "--config", faulty(tmp_path, "  buses:\n    can1: {state: error-warning}\n"), *JOG)
    assert result.exit_code == 0, result.transcript()


def test_the_guard_refuses_in_process_and_nothing_is_switched_on():
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

    cfg = load_config(ARM)
    arm = SimArm.in_process(cfg)
    d = cfg.drives["elbow_1a"]
    ref = DriveRef("elbow_1a", d.bus, d.node, d)
    with ArmSession.open(cfg, sim=arm, buses=["can1"]) as s:
        with arm.lock:
            arm.bus_controller("can1").set_state("ERROR-PASSIVE")
        with pytest.raises(BusStateError, match="ERROR-PASSIVE") as err, \
                MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)):
            pytest.fail("the guard let the motion start")
        assert err.value.bus == "can1" and err.value.problem == "error-passive"
        assert err.value.exit_code == 3
        assert motors_off(s)
        with arm.lock:
            arm.bus_controller("can1").set_state("ERROR-ACTIVE")
        preflight(s, [ref])  # fit again: no refusal
        assert [x.bus for x in check_buses(s)] == ["can1"]


def test_recipes_and_commission_check_the_buses_first(cli, tmp_path):
    config = faulty(tmp_path, "  buses:\n    can0: {state: bus-off, restart_ms: 0}\n")
    result = cli("--sim", "--config", config, "commission")
    assert result.exit_code != 0, result.transcript()
    assert "bus can0 (socketcan:can0): the controller is BUS-OFF" in result.stdout + result.stderr
    assert "refusing to start the recipe" in result.stdout + result.stderr


# -- user programs (PS) -----------------------------------------------------------------------------

def test_ps_values():
    assert [program_running(v) for v in (-1, -2, 1, 0, None)] == [False, False, True, None, None]
    assert describe_ps(1) == "a user program is running"
    assert describe_ps(7) == "PS=7 (meaning unknown)"
    assert describe_ps(None) == "not reported by this drive"


def test_sv_is_refused_while_a_user_program_runs(cli, tmp_path):
    config = faulty(tmp_path, "  drives:\n    elbow_1a: {user_program: 1}\n")
    result = cli("--sim", "--config", config, "--json", "program-limits", "elbow_pitch", "--apply", "--save", "--yes")
    assert result.exit_code == 1, result.transcript()
    text = result.stdout + result.stderr
    assert "SV refused: a user program is running on the drive (PS=1)" in text
    assert "Traceback" not in result.stderr


def test_the_simulated_drive_refuses_sv_itself_with_ec_82():
    from sherpa_cli.errors import DriveRefusedError

    cfg = load_config(ARM)
    arm = SimArm.in_process(cfg)
    d = cfg.drives["wrist_2a"]
    with ArmSession.open(cfg, sim=arm, buses=["can2"]) as s:
        c = s.client(DriveRef("wrist_2a", d.bus, d.node, d))
        c.nmt_start()
        assert c.get("PS") == -1 and not c.get("SR") & (1 << 12)
        with arm.lock:
            arm.drives["wrist_2a"].user_program = 1
        assert c.get("PS") == 1 and c.get("SR") & (1 << 12)
        with pytest.raises(DriveRefusedError) as err:
            c.save()
        assert err.value.code == 82


def test_cmd_raw_save_is_refused_while_a_program_runs(cli, tmp_path):
    config = faulty(tmp_path, "  drives:\n    wrist_2a: {user_program: 1}\n")
    result = cli("--sim", "--config", config, "cmd", "wrist_2a", "SV", "--apply", "--raw-save")
    assert result.exit_code == 1, result.transcript()
    assert "SV refused: a user program is running" in result.stderr


def test_motion_is_refused_while_a_program_runs_unless_allowed(cli, tmp_path):
    config = faulty(tmp_path, "  drives:\n    elbow_1a: {user_program: 1}\n")
    result = cli("--sim", "--config", config, *JOG)
    assert result.exit_code == 1, result.transcript()
    assert "elbow_1a (node 40): refusing to move it: a user program is running on it" in result.stderr
    assert "--allow-user-program" in result.stderr
    allowed = cli("--sim", "--config", config, "--allow-user-program", *JOG)
    assert allowed.exit_code == 0, allowed.transcript()


def test_identify_shows_ps(cli, tmp_path):
    config = faulty(tmp_path, "  drives:\n    wrist_2a: {user_program: 1}\n")
    result = cli("--sim", "--config", config, "identify", "--verbose", "wrist_2a", "wrist_2b")
    assert result.exit_code == 1, result.transcript()
    assert "a user program is running" in result.stdout
    assert "idle (no program running)" in result.stdout  # the PS row of each drive, in the details
    assert "wrist_2a: a user program is running (PS=1)" in result.stdout


def test_user_program_error_is_a_safety_refusal():
    assert issubclass(UserProgramError, Exception) and UserProgramError("x").exit_code == 1
