"""Every write obeys --apply: raw `cmd ... SV` (needs --raw-save, one per run, counted), `monitor --heartbeat`
and `scan --reset` (dry run without --apply); recipe dry runs strip them. Proven by the simulated drives'
frame records and SDO write records."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sherpa_cli.elmo import codec
from sherpa_cli.recipes.model import Step

NMT_RESET_COMM = 0x82


@pytest.fixture
def arms(monkeypatch):
    """The in-process simulated arms the CLI creates."""
    from sherpa_cli.sim.arm import SimArm

    made: list = []
    original = SimArm.for_session.__func__

    def for_session(cls, cfg, channels, **kwargs):
        arm = original(cls, cfg, channels, **kwargs)
        made.append(arm)
        return arm

    monkeypatch.setattr(SimArm, "for_session", classmethod(for_session))
    return made


def requests(drive) -> list[codec.Request]:
    rpdo2 = 0x300 + drive.node
    return [codec.decode_request(bytes(d)) for _, can_id, d in drive.received if can_id == rpdo2]


def sv_count(drive) -> int:
    return sum(1 for r in requests(drive) if r.kind == "execute" and r.letters == "SV")


def ledger(tmp_path: Path) -> dict:
    path = tmp_path / "state" / "sherpa-cli" / "save-ledger.json"
    return json.loads(path.read_text())["drives"] if path.exists() else {}


# --------------------------------------------------------------------------- cmd SV


def test_cmd_sv_without_raw_save_sends_nothing(cli, arms, tmp_path):
    r = cli("--sim", "cmd", "shoulder_1a", "AC=150000", "SV", "--apply")
    assert r.exit_code == 1 and "Traceback" not in r.stderr
    assert "SV (save to flash) is refused without --raw-save; nothing was sent" in r.stderr
    assert not arms, "refused before the bus was opened: not even the NMT start went out"
    assert ledger(tmp_path) == {}


def test_two_svs_in_one_invocation_are_refused(cli, arms, tmp_path):
    r = cli("--sim", "cmd", "shoulder_1a", "SV", "AC=1", "SV", "--apply", "--raw-save")
    assert r.exit_code == 2 and "2 SV in one command" in r.stderr and "nothing was sent" in r.stderr
    assert not arms and ledger(tmp_path) == {}


def test_cmd_sv_with_raw_save_is_sent_once_and_counted(cli, arms, tmp_path):
    from sherpa_cli.config import load_config
    from sherpa_cli.sim.state import default_serial

    r = cli("--sim", "cmd", "shoulder_1a", "AC=150000", "SV", "--apply", "--raw-save")
    assert r.exit_code == 0, r.transcript()
    assert "saved (save 1 of this drive by this tool)" in r.stdout
    drive = arms[-1].drives["shoulder_1a"]
    assert sv_count(drive) == 1 and drive.save_count == 1
    serial = f"0x{default_serial(load_config('configs/sherpa-arm.yaml'), 'shoulder_1a'):08X}"
    assert ledger(tmp_path) == {serial: {"saves": 1, "last_name": "shoulder_1a"}}
    cli("--sim", "cmd", "shoulder_1a", "SV", "--apply", "--raw-save")
    assert ledger(tmp_path)[serial]["saves"] == 2


def test_cmd_sv_refused_by_the_drive_is_not_counted(cli, arms, tmp_path, monkeypatch):
    from sherpa_cli.sim.arm import SimArm

    counting = SimArm.for_session.__func__  # the arms fixture's hook

    def motor_on(cls, cfg, channels, **kwargs):
        arm = counting(cls, cfg, channels, **kwargs)
        arm.drives["shoulder_1a"]._motor_on = True  # SV needs MO=0: the drive answers with an error
        return arm

    monkeypatch.setattr(SimArm, "for_session", classmethod(motor_on))
    r = cli("--sim", "cmd", "shoulder_1a", "SV", "--apply", "--raw-save")
    assert r.exit_code == 4, r.transcript()
    assert sv_count(arms[-1].drives["shoulder_1a"]) == 1 and arms[-1].drives["shoulder_1a"].save_count == 0
    assert ledger(tmp_path) == {}


def test_cmd_sv_dry_run_shows_the_frame_and_the_rule(cli, arms):
    r = cli("--sim", "cmd", "shoulder_1a", "SV")
    assert r.exit_code == 0
    assert "not sent (dry run): 0x30A  53 56 00 00" in r.stdout
    assert "SV also needs --raw-save" in r.stdout
    assert sv_count(arms[-1].drives["shoulder_1a"]) == 0


# --------------------------------------------------------------------------- monitor --heartbeat


def test_monitor_heartbeat_without_apply_sends_no_sdo_download(cli, arms):
    r = cli("--sim", "monitor", "--once", "--heartbeat", "200", "elbow_1a")
    assert r.exit_code == 0, r.transcript()
    assert "dry run: --heartbeat 200 would set the producer heartbeat (0x1017)" in r.stderr
    drive = arms[-1].drives["elbow_1a"]
    assert drive.od_writes == []
    downloads = [d for _, can_id, d in drive.received if can_id == 0x600 + drive.node and d[0] & 0xE0 == 0x20]
    assert downloads == [], "no SDO download in the frame record"


def test_monitor_heartbeat_with_apply_writes_and_restores(cli, arms):
    r = cli("--sim", "monitor", "--once", "--heartbeat", "200", "--apply", "elbow_1a")
    assert r.exit_code == 0, r.transcript()
    assert "dry run" not in r.stderr
    writes = [(i, s, v) for _, i, s, v in arms[-1].drives["elbow_1a"].od_writes]
    assert writes == [(0x1017, 0, 200), (0x1017, 0, 0)]


# --------------------------------------------------------------------------- scan --reset


def _nmt_resets(arm) -> int:
    return sum(1 for d in arm.drives.values() for _, can_id, data in d.received
               if can_id == 0 and data[0] == NMT_RESET_COMM)


def test_scan_reset_without_apply_resets_nothing(cli, arms):
    r = cli("--sim", "scan", "--bus", "can1", "--reset")
    assert r.exit_code == 0, r.transcript()
    assert "dry run: --reset would send NMT reset communication" in r.stderr
    assert _nmt_resets(arms[-1]) == 0
    assert all(d.boots == 1 for d in arms[-1].drives.values()), "only the power-up boot"


def test_scan_reset_with_apply_resets(cli, arms):
    r = cli("--sim", "scan", "--bus", "can1", "--reset", "--apply")
    assert r.exit_code == 0, r.transcript()
    assert _nmt_resets(arms[-1]) > 0


# --------------------------------------------------------------------------- recipe dry runs


@pytest.mark.parametrize("argv,dry", [
    (("monitor", "--once", "--heartbeat", "200"), ("monitor", "--once")),
    (("monitor", "--once", "--heartbeat=200", "--apply"), ("monitor", "--once")),
    (("program-limits", "--apply", "--verify-flash"), ("program-limits",)),
    (("cmd", "d1", "SV", "--apply", "--raw-save"), ("cmd", "d1", "SV")),
    (("scan", "--reset", "--apply"), ("scan",)),
])
def test_recipe_dry_runs_strip_every_write_option(argv, dry):
    step = Step(1, "s", argv=argv)
    assert step.writes
    assert step.dry_argv() == dry
