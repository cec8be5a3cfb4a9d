"""`sherpa doctor`: passes on the healthy simulated arm (golden at 80 columns); each row fails with its
fix when its fault is injected."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sherpa_cli.ops import doctor as doc

ARM = Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml"
VERSIONS = {"python": "3.11.0", "sherpa-cli": "0.0.0", "python-can": "4.4.0", "canopen": "2.3.0", "typer": "0.12.0",
            "rich": "13.0.0", "pyroute2": "0.7.0"}


@pytest.fixture(autouse=True)
def fixed_versions(monkeypatch):
    """Versions differ between installs: the table shows these."""
    monkeypatch.setattr(doc, "package_versions", lambda: dict(VERSIONS))


def faulty(tmp_path: Path, sim: str) -> str:
    path = tmp_path / "arm.yaml"
    path.write_text(ARM.read_text() + "\nsim:\n" + sim)
    return str(path)


def rows(result) -> dict[str, dict]:
    return {c["check"]: c for c in json.loads(result.stdout)["checks"]}


@pytest.mark.golden
def test_doctor_passes_on_the_healthy_simulated_arm_80_columns(cli, golden, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    result = cli("--sim", "doctor", "--window", "0.2")
    assert result.exit_code == 0, result.transcript()
    golden("doctor-sim-80.txt", result.transcript())


@pytest.mark.parametrize(("sim", "check", "text", "hint"), [
    ("  buses:\n    can2: {present: false}\n", "bus can2 interface", "no interface can2", "ip link show can2"),
    ("  buses:\n    can2: {up: false}\n", "bus can2 link", "the link is down", "sherpa bus up can2"),
    ("  buses:\n    can1: {bitrate: 500000}\n", "bus can1 bit rate", "bit rate 500000 differs", "sherpa bus up can1"),
    ("  buses:\n    can1: {state: bus-off, restart_ms: 0}\n", "bus can1 state", "BUS-OFF", "termination"),
    ("  buses:\n    can0: {state: error-passive}\n", "bus can0 state", "ERROR-PASSIVE", "termination"),
    ("  drives:\n    wrist_3b: {die_at: 0.0}\n", "drives", "wrist_3b (can2:71) missing", "sherpa scan"),
    ("  drives:\n    elbow_1b: {firmware: 'Whistle 1.0.9.0'}\n", "firmware/model", "firmware 'Whistle 1.0.9.0' differs",
     "sherpa identify"),
    ("  buses:\n    can0: {foreign_heartbeats: [126], heartbeat_period: 0.02}\n", "host node id",
     "can0: heartbeats on host id(s) 126 (not a sherpa command of this machine: another host or tool)",
     "motion.host_node_id / host_id_pool"),
    ("  drives:\n    wrist_2a: {user_program: 1}\n", "user programs", "running on wrist_2a (PS=1)",
     "--allow-user-program"),
])
def test_each_row_fails_with_its_fix(cli, tmp_path, sim, check, text, hint):
    result = cli("--sim", "--config", faulty(tmp_path, sim), "--json", "doctor", "--window", "0.2")
    assert result.exit_code == 1, result.transcript()
    row = rows(result)[check]
    assert row["result"] == "fail" and text in row["detail"], row
    assert hint in row["hint"]
    failed = [c for c, r in rows(result).items() if r["result"] == "fail"]
    assert failed == [check], failed  # only the row of the injected fault
    plain = cli("--sim", "--config", faulty(tmp_path, sim), "doctor", "--window", "0.2")
    assert plain.exit_code == 1 and f"{check}: " in plain.stdout and "1 failed" in plain.stdout


def test_a_missing_or_down_bus_skips_its_other_rows_and_its_drives(cli, tmp_path):
    result = cli("--sim", "--config", faulty(tmp_path, "  buses:\n    can2: {present: false}\n"), "--json", "doctor",
                 "--window", "0")
    r = rows(result)
    assert [r[f"bus can2 {x}"]["result"] for x in ("link", "bit rate", "state", "load")] == ["skip"] * 4
    assert r["drives"]["detail"] == "10 of 10 found (4 on unusable buses)"


def test_unwritable_state_dir_and_no_socketcan_here(cli, tmp_path, monkeypatch):
    # as root chmod does not stop a write: the state directory's parent is a file instead
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    monkeypatch.setenv("XDG_STATE_HOME", str(blocker / "state"))
    result = cli("--json", "doctor", "--window", "0")  # no --sim: this kernel has no CAN interfaces
    assert result.exit_code == 1, result.transcript()
    r = rows(result)
    assert r["state directory"]["result"] == "fail" and "not writable" in r["state directory"]["detail"]
    assert "XDG_STATE_HOME" in r["state directory"]["hint"]
    assert r["bus can0 interface"]["result"] == "fail" and "no interface can0" in r["bus can0 interface"]["detail"]
    assert r["drives"]["result"] == "skip"
    assert r["config"]["result"] == "ok" and r["python"]["result"] == "ok"


def test_a_bad_config_is_a_row_not_a_crash(cli, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nbuses: {can0: {interface: socketcan, channel: can0}}\ndrives: {d: {bus: can9, node: 1}}\n")
    result = cli("--config", str(bad), "doctor", "--window", "0")
    assert result.exit_code == 1 and "Traceback" not in result.stderr
    assert "config" in result.stdout and "FAIL" in result.stdout


def test_bad_window(cli):
    result = cli("--sim", "doctor", "--window", "-1")
    assert result.exit_code == 2 and "--window -1" in result.stderr
