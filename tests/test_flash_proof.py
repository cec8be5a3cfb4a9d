"""Flash proven by reset (`--verify-flash`): the stale-flash scenarios the local save ledger cannot know.

A real arm stays powered between two commands, so RAM written by one command is still there
for the next. The ``powered_arm`` fixture plays that with the in-process simulator: each new
`--sim` arm starts with the RAM the previous one ended with (flash is kept as always). Then
RAM can hold the targets while flash does not -- after writes from another state directory,
from `cmd --apply`, or when the ledger was deleted -- and `--save` must never call that fine.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from sherpa_cli.config import load_config
from sherpa_cli.elmo import codec
from sherpa_cli.joints.limits import derive_checked

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE3 = "configs/appendix-c/example3.yaml"
BASE = ["--config", EXAMPLE3, "--sim"]
NMT_RESET_NODE = 0x81


@pytest.fixture
def powered_arm(monkeypatch):
    """The in-process arms the CLI creates; each starts with the previous arm's RAM (no power cycle)."""
    from sherpa_cli.sim.arm import SimArm

    arms: list = []
    original = SimArm.for_session.__func__

    def for_session(cls, cfg, channels, **kwargs):
        arm = original(cls, cfg, channels, **kwargs)
        if arms:
            for name, drive in arm.drives.items():
                drive.ram.update(arms[-1].drives[name].ram)
        arms.append(arm)
        return arm

    monkeypatch.setattr(SimArm, "for_session", classmethod(for_session))
    return arms


def targets() -> dict[str, dict]:
    derived, _ = derive_checked(load_config(ROOT / EXAMPLE3))
    return {d.drive: dict(d.params) for d in derived}


def flash_holds_targets(arm) -> bool:
    return all(all(arm.drives[name].flash.get(k) == v for k, v in params.items())
               for name, params in targets().items())


def executes(drive, letters: str) -> int:
    """Execute commands ``letters`` (e.g. SV) the simulated drive received."""
    from sherpa_cli.elmo import codec

    rpdo2 = 0x300 + drive.node
    requests = [codec.decode_request(bytes(data)) for _, can_id, data in drive.received if can_id == rpdo2]
    return sum(1 for r in requests if r.kind == "execute" and r.letters == letters)


def resets(drive) -> int:
    return sum(1 for _, can_id, data in drive.received if can_id == 0 and data[0] == NMT_RESET_NODE)


def write_ram_by_cmd(cli) -> None:
    """Every target into RAM with raw `cmd --apply` (no SV, nothing in the ledger)."""
    for drive, params in targets().items():
        exprs = [f"{k}={v}" for k, v in params.items()]
        r = cli(*BASE, "cmd", drive, *exprs, "--apply")
        assert r.exit_code == 0, r.transcript()


def _other_state_dir(cli, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "machine-a"))
    assert cli(*BASE, "program-limits", "--apply").exit_code == 0
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "machine-b"))  # another laptop: its own ledger


def _raw_cmd(cli, monkeypatch, tmp_path):
    write_ram_by_cmd(cli)


def _deleted_ledger(cli, monkeypatch, tmp_path):
    assert cli(*BASE, "program-limits", "--apply").exit_code == 0
    shutil.rmtree(tmp_path / "state" / "sherpa-cli")  # ledger and all; the sim's flash was never saved
    assert not (tmp_path / "state" / "sherpa-cli").exists()


SCENARIOS = {"other-state-directory": _other_state_dir, "raw-cmd-writes": _raw_cmd, "deleted-ledger": _deleted_ledger}


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_stale_flash_save_without_proof_never_says_no_sv_needed(cli, powered_arm, monkeypatch, tmp_path, scenario):
    SCENARIOS[scenario](cli, monkeypatch, tmp_path)
    r = cli(*BASE, "program-limits", "--apply", "--save", "--yes")
    assert "Traceback" not in r.stderr
    assert "no SV needed" not in r.stdout
    assert r.stdout.count("RAM holds the targets; flash NOT proven") == 2, r.stdout
    assert not flash_holds_targets(powered_arm[-1])  # and the tool did not claim otherwise


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_stale_flash_is_proven_different_then_saved_and_proven(cli, powered_arm, monkeypatch, tmp_path, scenario):
    SCENARIOS[scenario](cli, monkeypatch, tmp_path)
    r = cli(*BASE, "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    assert r.exit_code == 0, r.transcript()
    assert "no SV needed" not in r.stdout
    assert "drive1: flash differs in 17 of 19" in r.stdout and "drive2: flash differs in 17 of 19" in r.stdout
    after = r.stdout.split("flash proof after SV:")[1]
    assert "drive1: flash holds the targets (19 read back)" in after
    assert "drive2: flash holds the targets (19 read back)" in after
    arm = powered_arm[-1]
    assert flash_holds_targets(arm)
    for drive in arm.drives.values():
        assert executes(drive, "SV") == 1, "one SV per drive"
        assert resets(drive) == 2, "proven before and after the save"
    ledger = json.loads(Path(_state(monkeypatch), "sherpa-cli", "save-ledger.json").read_text())
    assert sorted(e["saves"] for e in ledger["drives"].values()) == [1, 1]


def _state(monkeypatch) -> str:
    import os
    return os.environ["XDG_STATE_HOME"]


def test_proof_of_a_saved_arm_writes_and_saves_nothing(cli, powered_arm):
    assert cli(*BASE, "program-limits", "--apply", "--save", "--yes").exit_code == 0
    r = cli(*BASE, "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    assert r.exit_code == 0, r.transcript()
    assert r.stdout.count("RAM and flash hold the targets (flash proven by reset), no SV") == 2
    assert "flash proof after SV" not in r.stdout
    arm = powered_arm[-1]
    for drive in arm.drives.values():
        assert executes(drive, "SV") == 0 and resets(drive) == 1
        assert drive.save_count == 1


def test_only_the_drive_whose_flash_differs_is_saved(cli, powered_arm):
    assert cli(*BASE, "program-limits", "--apply", "--save", "--yes").exit_code == 0
    # drive2's RAM changed by hand and saved: its flash no longer holds the targets
    assert cli(*BASE, "cmd", "drive2", "AC=777", "SV", "--apply", "--raw-save").exit_code == 0
    r = cli(*BASE, "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    assert r.exit_code == 0, r.transcript()
    assert "drive1: flash holds the targets" in r.stdout
    assert "drive2: flash differs in 1 of 19: AC = 777 (target 500)" in r.stdout
    arm = powered_arm[-1]
    assert executes(arm.drives["drive1"], "SV") == 0 and executes(arm.drives["drive2"], "SV") == 1
    assert resets(arm.drives["drive1"]) == 1 and resets(arm.drives["drive2"]) == 2
    assert flash_holds_targets(arm)


def test_proof_without_save_reports_the_difference_and_exits_1(cli, powered_arm):
    write_ram_by_cmd(cli)
    r = cli(*BASE, "program-limits", "--apply", "--verify-flash")
    assert r.exit_code == 1, r.transcript()
    assert "flash of drive1, drive2 differs from the targets" in r.stderr
    assert all(executes(d, "SV") == 0 for d in powered_arm[-1].drives.values())


def test_verify_flash_dry_run_resets_nothing_and_says_what_a_reset_clears(cli, powered_arm):
    r = cli(*BASE, "program-limits", "--verify-flash")
    assert r.exit_code == 0, r.transcript()
    text = " ".join(r.stdout.split())  # the note is wrapped at 80 columns
    assert "would reset drive1, drive2 (NMT reset node)" in text
    assert "restarts the position counter and clears any homing (calibration) mark" in text
    assert "dry run: nothing was written; no drive was reset" in r.stdout
    for drive in powered_arm[-1].drives.values():
        assert resets(drive) == 0
        assert all(can_id != 0x300 + drive.node or _query(data) for _, can_id, data in drive.received)


def _query(data: bytes) -> bool:
    from sherpa_cli.elmo import codec
    return codec.decode_request(bytes(data)).kind == "query"


def test_verify_flash_refuses_a_motor_that_is_on_before_any_reset(cli, powered_arm, monkeypatch):
    from sherpa_cli.sim.arm import SimArm

    previous = SimArm.for_session

    def motor_on(cls, cfg, channels, **kwargs):
        arm = previous.__func__(cls, cfg, channels, **kwargs)
        arm.drives["drive1"]._motor_on = True
        return arm

    monkeypatch.setattr(SimArm, "for_session", classmethod(motor_on))
    r = cli(*BASE, "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    assert r.exit_code == 1 and "motor is on: drive1" in r.stderr and "no drive was reset" in r.stderr
    assert all(resets(d) == 0 for d in powered_arm[-1].drives.values())


def test_no_terminal_no_yes_refuses_before_any_reset(cli, powered_arm):
    r = cli(*BASE, "program-limits", "--apply", "--save", "--verify-flash")
    assert r.exit_code == 1 and "no drive was reset" in r.stderr
    assert all(resets(d) == 0 for d in powered_arm[-1].drives.values())


def test_params_restore_verify_flash(cli, powered_arm, tmp_path, monkeypatch):
    monkeypatch.setenv("SHERPA_DUMP_DATE", "2024-05-02T10:00:00Z")
    assert cli(*BASE, "program-limits", "--apply", "--save", "--yes").exit_code == 0
    dump = tmp_path / "dump.yaml"
    assert cli(*BASE, "dump-params", "-o", str(dump)).exit_code == 0
    write = cli(*BASE, "cmd", "drive1", "AC=777", "SV", "--apply", "--raw-save")
    assert write.exit_code == 0, write.transcript()
    r = cli(*BASE, "params", "restore", str(dump), "--apply", "--save", "--verify-flash", "--yes")
    assert r.exit_code == 0, r.transcript()
    assert "drive1: flash differs in 1 of" in r.stdout and "AC = 777 (target 500)" in r.stdout
    assert "drive2: flash holds the targets" in r.stdout
    assert powered_arm[-1].drives["drive1"].flash["AC"] == 500


def test_json_carries_both_proofs(cli, powered_arm):
    write_ram_by_cmd(cli)
    r = cli(*BASE, "--json", "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    assert r.exit_code == 0, r.transcript()
    body = json.loads(r.stdout)
    assert body["verify_flash"] is True
    d1 = body["drives"][0]
    assert d1["flash_proof"]["status"] == "differs" and len(d1["flash_proof"]["differences"]) == 17
    assert d1["flash_proof_after_save"]["status"] == "holds"
    assert d1["outcome"]["status"] == "saved"


# --------------------------------------------------------------------------- the client's reset


class _BootTransport:
    """Records frames; answers NMT reset node with a boot-up only when ``boots``."""

    def __init__(self, boots: bool) -> None:
        self.boots = boots
        self.sent: list[tuple[int, bytes]] = []
        self.callbacks: dict[int, list] = {}

    def subscribe(self, can_id, callback) -> None:
        self.callbacks.setdefault(can_id, []).append(callback)

    def send(self, can_id, data) -> None:
        self.sent.append((can_id, bytes(data)))
        if can_id == 0 and data[0] == NMT_RESET_NODE and self.boots:
            for cb in self.callbacks.get(0x700 + data[1], []):
                cb(0x700 + data[1], b"\x7f", 0.0)  # a heartbeat is not a boot-up
                cb(0x700 + data[1], b"\x00", 0.0)


class _FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def test_reset_node_waits_for_the_boot_up_then_starts_the_node():
    from sherpa_cli.elmo.client import DriveClient

    transport, clock = _BootTransport(boots=True), _FakeClock()
    client = DriveClient(transport, 5, name="d5", clock=clock.now, sleep=clock.sleep)
    client.reset_node(2.0)
    assert transport.sent == [(0, bytes([0x81, 5])), (0, bytes([0x01, 5]))]
    assert clock.t == 0.0, "the boot-up ended the wait at once"


def test_reset_node_without_boot_up_times_out_on_the_injected_clock():
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.errors import DriveTimeoutError

    transport, clock = _BootTransport(boots=False), _FakeClock()
    client = DriveClient(transport, 5, name="d5", clock=clock.now, sleep=clock.sleep)
    with pytest.raises(DriveTimeoutError, match=r"d5 \(node 5\): no boot-up within 2 s after NMT reset node"):
        client.reset_node(2.0)
    assert transport.sent == [(0, bytes([0x81, 5]))], "not started after a failed reset"
    assert 2.0 <= clock.t < 2.1


def test_boot_timeout_is_a_checked_protocol_setting(tmp_path):
    from sherpa_cli.errors import ConfigError

    path = tmp_path / "arm.yaml"
    path.write_text((ROOT / EXAMPLE3).read_text() + "\nprotocol: {boot_timeout: 0}\n")
    with pytest.raises(ConfigError, match=r"protocol.boot_timeout: boot_timeout 0(\.0)? s must be > 0 and <= 60"):
        load_config(path)
    path.write_text((ROOT / EXAMPLE3).read_text() + "\nprotocol: {boot_timeout: 5}\n")
    assert load_config(path).protocol.boot_timeout == 5


def test_a_drive_that_does_not_boot_stops_everything_before_any_write(cli, powered_arm, tmp_path, monkeypatch):
    from sherpa_cli.sim.arm import SimArm

    config = tmp_path / "example3-slow-boot.yaml"
    config.write_text((ROOT / EXAMPLE3).read_text() + "\nprotocol: {boot_timeout: 0.2}\n")
    carrying = SimArm.for_session.__func__  # powered_arm's hook

    def silent_reset(cls, cfg, channels, **kwargs):
        arm = carrying(cls, cfg, channels, **kwargs)
        drive = arm.drives["drive2"]
        nmt = drive._nmt
        drive._nmt = lambda cs: None if cs == NMT_RESET_NODE else nmt(cs)  # never reboots, never boots up
        return arm

    monkeypatch.setattr(SimArm, "for_session", classmethod(silent_reset))
    r = cli("--config", str(config), "--sim", "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    assert r.exit_code == 3, r.transcript()  # a drive that did not answer: bus/communication
    assert "drive2: flash not proven: drive2 (node 2): no boot-up within 0.2 s after NMT reset node" in r.stderr
    assert "drive2: flash NOT proven: drive2 (node 2): no boot-up" in r.stdout
    arm = powered_arm[-1]
    for drive in arm.drives.values():
        assert executes(drive, "SV") == 0
        sets = [codec.decode_request(bytes(d)) for _, can_id, d in drive.received if can_id == 0x300 + drive.node]
        assert [q for q in sets if q.kind == "set"] == [], "nothing written after the failed proof"


@pytest.mark.golden
def test_verify_flash_golden(cli, golden, powered_arm):
    dry = cli(*BASE, "program-limits", "drive1", "--verify-flash")
    golden("program-limits-example3-verify-flash-dry-run.txt", dry.transcript())
    saved = cli(*BASE, "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    golden("program-limits-example3-verify-flash-save.txt", saved.transcript())
    again = cli(*BASE, "program-limits", "--apply", "--save", "--verify-flash", "--yes")
    golden("program-limits-example3-verify-flash-again.txt", again.transcript())
    assert (dry.exit_code, saved.exit_code, again.exit_code) == (0, 0, 0)
