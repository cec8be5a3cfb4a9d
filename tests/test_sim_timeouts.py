"""With --sim the reply timeout is the simulator's (patient), real-bus defaults stay."""

from __future__ import annotations

import json

from tests.conftest import ROOT

EXAMPLE3 = ROOT / "configs/appendix-c/example3.yaml"


def _config(tmp_path, sim: str) -> str:
    path = tmp_path / "arm.yaml"
    path.write_text(EXAMPLE3.read_text() + "\nsim:\n" + sim)
    return str(path)


def test_a_slow_simulated_drive_is_waited_for(cli, tmp_path):
    # 0.3 s per reply: far beyond protocol.reply_timeout (0.1 s), well inside the sim's 1 s default
    cfg = _config(tmp_path, "  drives:\n    drive1: {reply_latency: 0.3}\n")
    r = cli("--config", cfg, "--sim", "--json", "cmd", "drive1", "PX")
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["results"][0]["value"] is not None


def test_a_sim_timeout_says_the_simulated_arm_was_too_slow(cli, tmp_path):
    cfg = _config(tmp_path, "  reply_timeout: 0.05\n  drives:\n    drive1: {reply_latency: 0.3}\n")
    r = cli("--config", cfg, "--sim", "cmd", "drive1", "PX")
    assert r.exit_code == 3
    assert "no answer to PX within 0.05 s" in r.stderr
    assert "the simulated arm answered too slowly" in r.stderr
    assert "check that the drive is powered" not in r.stderr


def test_real_bus_defaults_stay(tmp_path):
    from sherpa_cli.config import load_config
    from sherpa_cli.config.model import ArmConfig, ProtocolConfig
    from sherpa_cli.elmo.client import ClientSettings

    cfg = load_config(EXAMPLE3)
    assert cfg.protocol.reply_timeout == ProtocolConfig().reply_timeout == 0.1
    assert cfg.sim_reply_timeout == ArmConfig.sim_reply_timeout == 1.0
    assert "check that the drive is powered" in ClientSettings().timeout_hint


def test_sim_reply_timeout_is_checked_and_round_trips(cli, tmp_path):
    from sherpa_cli.config import dump_native, load_config

    bad = _config(tmp_path, "  reply_timeout: 0\n")
    r = cli("config", "check", bad)
    assert r.exit_code == 2 and "reply_timeout" in r.stderr and "Traceback" not in r.stderr
    good = _config(tmp_path, "  reply_timeout: 2.5\n")
    cfg = load_config(good)
    assert cfg.sim_reply_timeout == 2.5
    again = tmp_path / "again.yaml"
    again.write_text(dump_native(cfg))
    assert load_config(again).sim_reply_timeout == 2.5


def test_a_slow_simulated_sdo_answer_is_waited_for_too(cli, tmp_path):
    # 0.5 s per SDO answer: beyond protocol.sdo_timeout (0.3 s), inside the sim's 1 s: the in-process
    # simulator shares a possibly loaded machine, so its SDO answers get the patient timeout as well
    cfg = _config(tmp_path, "  drives:\n    drive1: {sdo_latency: 0.5}\n")
    r = cli("--config", cfg, "--sim", "--json", "identify", "drive1")
    assert r.exit_code == 0, r.transcript()
    assert json.loads(r.stdout)["drives"][0]["error"] is None


def test_an_unanswered_simulated_sdo_says_the_simulated_arm_was_too_slow(cli, tmp_path):
    # docs/simulator.md: a --sim timeout names the simulated arm, not the drive's power; the SDO
    # transfers said "check that the drive is powered" still
    cfg = _config(tmp_path, "  reply_timeout: 0.05\n  drives:\n    drive1: {sdo_latency: 0.9}\n")
    r = cli("--config", cfg, "--sim", "identify", "drive1")
    assert "no answer to the SDO upload" in r.stderr and "within 0.3 s" in r.stderr, r.transcript()
    assert "the simulated arm answered too slowly" in r.stderr
    assert "check that the drive is powered" not in r.stderr
