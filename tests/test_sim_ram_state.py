"""`--sim` keeps the simulated arm powered between commands (sim/state.py: RAM beside flash in the
test's own state directory): homing then jogging works, `sim --power-cycle` brings back the "not
homed" refusal, a command that died mid-motion leaves a stopped motor, and two `--sim` commands at once
are serialised by the RAM lock (or refused after its wait), never corrupting the state."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.sim import state as sim_state
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
HOME_ARM = ROOT / "tests" / "data" / "home-arm.yaml"
ARM = ROOT / "configs" / "sherpa-arm.yaml"


def _px(cli, config: Path, drive: str) -> int:
    result = cli("--config", str(config), "--sim", "--json", "cmd", drive, "PX")
    assert result.exit_code == 0, result.transcript()
    return int(json.loads(result.stdout)["results"][0]["value"])


def test_home_then_jog_works_and_a_power_cycle_brings_back_the_not_homed_refusal(cli):
    config = str(HOME_ARM)
    home = cli("--config", config, "--sim", "home", "yaw", "--yes")
    assert home.exit_code == 0, home.transcript()
    jog = cli("--config", config, "--sim", "jog", "yaw", "--to", "200counts", "--apply")
    assert jog.exit_code == 0, jog.transcript()
    assert abs(_px(cli, HOME_ARM, "yaw_drive") - 200) <= 1  # the joint stayed where the jog left it
    cycled = cli("--config", config, "sim", "--power-cycle")
    assert cycled.exit_code == 0 and "power cycled" in cycled.stdout
    assert _px(cli, HOME_ARM, "yaw_drive") == 0  # PX starts at 0 wherever the joint stands
    refused = cli("--config", config, "--sim", "jog", "yaw", "--to", "100counts", "--apply")
    assert refused.exit_code != 0 and "not homed" in refused.stderr, refused.transcript()


def test_reset_state_forgets_ram_positions_and_flash(cli):
    cli("--sim", "cmd", "shoulder_1a", "AC=150000", "--apply")
    cfg = load_config(ARM)
    assert sim_state.ram_path(cfg).is_file()
    reset = cli("sim", "--reset-state")
    assert reset.exit_code == 0
    assert not sim_state.ram_path(cfg).exists()
    again = json.loads(cli("--sim", "--json", "cmd", "shoulder_1a", "AC").stdout)
    assert again["results"][0]["value"] == 100000


def test_a_command_that_died_mid_motion_leaves_a_stopped_motor(cli):
    """The dead-man armed, the motor jogging, and the command gone without its exit path: the next
    `--sim` command finds the motor off, as the drive's heartbeat consumer leaves it (MF 0x800)."""
    cfg = load_config(ARM)
    arm = SimArm.for_session(cfg, {bus: f"died-{bus}-{os.getpid()}" for bus in cfg.buses})
    arm.start()
    try:
        with arm.lock:
            drive = arm.drives["shoulder_1a"]
            drive.receive(0x000, bytes([0x01, drive.node]))
            drive.od_write(0x1016, 1, 0x7F << 16 | 500)
            drive.receive(0x77F, bytes([0x05]))  # the host's first heartbeat: the consumer watches
            drive.write_param("UM", 5)
            drive.write_param("MO", 1)
            drive.write_param("JV", 100)
            drive._target_kind = "JV"
            drive.execute("BG")
            assert drive.motor_on
    finally:
        arm.stop()  # what the RAM file keeps of a command killed here: the motor on, the consumer watching
    saved = json.loads(sim_state.ram_path(cfg).read_text())["drives"]["shoulder_1a"]
    assert saved["motor_on"] and saved["consumer_watching"]
    mo = json.loads(cli("--sim", "--json", "cmd", "shoulder_1a", "MO", "MF").stdout)["results"]
    assert [r["value"] for r in mo] == [0, 0x800]


def test_a_second_sim_command_waits_for_the_first_and_is_refused_after_the_wait(cli, monkeypatch):
    cfg = load_config(ARM)
    monkeypatch.setattr(SimArm, "RAM_LOCK_TIMEOUT", 0.3)
    holder = sim_state.ram_lock(cfg, 1.0)  # another `--sim` command holds the arm
    try:
        refused = cli("--sim", "cmd", "shoulder_1a", "PX")
    finally:
        sim_state.release_ram_lock(cfg, holder)
    assert refused.exit_code == 5 and "another `--sim` command is using it" in refused.stderr, refused.transcript()
    # said at once, with the holder and the way to a second terminal, before the wait
    assert f"warning: simulated arm 'sherpa-arm': another `--sim` command (pid {os.getpid()}) is using it; " \
           "waiting up to 0.3 s" in refused.stderr, refused.transcript()
    assert "`sherpa sim --serve`" in refused.stderr
    assert cli("--sim", "cmd", "shoulder_1a", "PX").exit_code == 0


def test_a_sim_stop_that_cannot_reach_the_arm_says_nothing_was_stopped_at_once(cli, monkeypatch):
    """`sherpa --sim stop` in a second terminal while a `--sim` jog runs in the first: the motor lives
    in the jog's process. It used to wait for the jog to end and report "motor was off" for every
    drive; now it is refused at once, exit 5, saying nothing was stopped and where the arm is."""
    cfg = load_config(ARM)
    monkeypatch.setattr(SimArm, "RAM_LOCK_TIMEOUT", 30.0)  # a wait would outlast the test's bound
    holder = sim_state.ram_lock(cfg, 1.0)
    try:
        refused = cli("--sim", "stop")
    finally:
        sim_state.release_ram_lock(cfg, holder)
    assert refused.exit_code == 5, refused.transcript()
    assert refused.stderr.startswith(f"error: NOTHING WAS STOPPED: simulated arm 'sherpa-arm': another `--sim` "
                                     f"command (pid {os.getpid()}) is using it"), refused.transcript()
    assert "motor was off" not in refused.stdout and "waiting" not in refused.stderr
    assert cli("--sim", "stop").exit_code == 0


def test_two_sim_commands_at_once_are_serialised_and_the_state_stays_whole(tmp_path):
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / "state"), NO_COLOR="1", COLUMNS="100")
    env.pop("SHERPA_CONFIG", None)
    argv = [sys.executable, "-m", "sherpa_cli", "--sim"]
    runs = [subprocess.Popen([*argv, "cmd", drive, f"AC={value}", "--apply"], cwd=ROOT, env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for drive, value in (("shoulder_1a", 150000), ("elbow_1a", 160000))]
    for run in runs:
        _out, err = run.communicate(timeout=120)
        assert run.returncode == 0, err
    for drive, value in (("shoulder_1a", 150000), ("elbow_1a", 160000)):
        check = subprocess.run([*argv, "--json", "cmd", drive, "AC"], cwd=ROOT, env=env, capture_output=True,
                               text=True, timeout=120)
        assert json.loads(check.stdout)["results"][0]["value"] == value  # neither run lost the other's RAM


@pytest.mark.parametrize("content", ["{", '{"format": 1, "drives": {"shoulder_1a": {"ram": 5, "position": 0}}}'])
def test_a_damaged_ram_file_is_one_located_message(cli, content):
    cfg = load_config(ARM)
    path = sim_state.ram_path(cfg)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(content, encoding="utf-8")
    result = cli("--sim", "cmd", "shoulder_1a", "PX")
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert "RAM state is damaged" in result.stderr and "--power-cycle" in result.stderr


def test_a_sim_jog_killed_with_sigkill_leaves_what_recover_finds_on_a_served_arm(tmp_path):
    """`sherpa --sim jog ... --apply` SIGKILLed mid-motion: no exit path ran, so nothing saved the RAM
    at stop. It used to leave the RAM file as before the jog, and `recover` said the drive "already
    holds every value (reset or power-cycled since?)". The file follows the running arm now: the next
    command's power-on finds the motor on with its consumer watching, the consumer acts (MF 0x800), and
    `recover` says the dead-man tripped and puts it back, as on `sim --serve`."""
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / "state"), NO_COLOR="1", COLUMNS="100")
    env.pop("SHERPA_CONFIG", None)
    argv = [sys.executable, "-m", "sherpa_cli", "--sim"]

    def sherpa(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*argv, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)

    ram = tmp_path / "state" / "sherpa-cli" / "sim" / sim_state.ram_path(load_config(ARM)).name
    jog = subprocess.Popen([*argv, "jog", "elbow_pitch", "--velocity", "0.05", "--for", "60", "--apply"], cwd=ROOT,
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120  # a hang guard: the file says when the motor runs under its dead-man
        while True:
            assert jog.poll() is None, f"the jog ended before the kill: {jog.communicate()}"
            assert time.monotonic() < deadline, "the running jog's RAM file never showed its motor on"
            try:
                drive = json.loads(ram.read_text(encoding="utf-8"))["drives"]["elbow_1a"]
            except (OSError, ValueError, KeyError):
                drive = {}
            if drive.get("motor_on") and drive.get("consumer_watching"):
                break
            time.sleep(0.05)
    finally:
        jog.kill()  # SIGKILL
        jog.communicate(timeout=120)
    refused = sherpa("jog", "elbow_pitch", "--velocity", "0.1", "--for", "0.3", "--apply")
    assert refused.returncode == 1 and "did not finish (killed?) left temporary changes" in refused.stderr, \
        refused.stderr
    dry = sherpa("recover", "elbow_pitch")
    assert dry.returncode == 0 and "its dead-man tripped" in dry.stdout and "MF 0x800 latched" in dry.stdout, \
        dry.stdout + dry.stderr
    applied = sherpa("recover", "elbow_pitch", "--apply")
    assert applied.returncode == 0 and "MF 0x800 cleared" in applied.stdout, applied.stdout + applied.stderr
    after = sherpa("jog", "elbow_pitch", "--velocity", "0.1", "--for", "0.3", "--apply")
    assert after.returncode == 0, after.stdout + after.stderr
