"""`sherpa params restore`: a dump-params file back into the (simulated) drives."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.elmo import codec
from sherpa_cli.errors import ConfigError, SafetyError
from sherpa_cli.ops import program
from sherpa_cli.ops.params_file import read_dump, write_dump
from sherpa_cli.ops.restore import restore_targets
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE3 = "configs/appendix-c/example3.yaml"
BASE = ["--config", EXAMPLE3, "--sim"]


@pytest.fixture
def factory_dump(cli, tmp_path, monkeypatch):
    """A dump of example 3's drives in factory state (the sim's flash is empty at first)."""
    monkeypatch.setenv("SHERPA_DUMP_DATE", "2024-05-02")
    path = tmp_path / "factory.yaml"
    r = cli(*BASE, "dump-params", "-o", str(path))
    assert r.exit_code == 0, r.stderr
    return path


def _program_and_save(cli) -> None:
    r = cli(*BASE, "program-limits", "--apply", "--save", "--yes")
    assert r.exit_code == 0, r.stderr


def _edited(path: Path, out: Path, drive: str, **changes) -> Path:
    dump = read_dump(path)
    d = dump.drives[drive]
    identity = dict(d.identity)
    params = dict(d.params)
    for key, value in changes.items():
        if key == "serial":
            identity["serial"] = value
        else:
            params[key] = value
    drives = dict(dump.drives)
    drives[drive] = dataclasses.replace(d, identity=identity, params=params)
    write_dump(out, dataclasses.replace(dump, drives=drives))
    return out


def _transcript(result, tmp_path: Path) -> str:
    return result.transcript().replace(str(tmp_path), "TMP")


@pytest.mark.golden
def test_restore_plan_apply_save_and_the_values_survive(cli, golden, factory_dump, tmp_path):
    _program_and_save(cli)
    plan = cli(*BASE, "params", "restore", str(factory_dump))
    assert plan.exit_code == 0
    golden("params-restore-plan.txt", _transcript(plan, tmp_path))
    saved = cli(*BASE, "params", "restore", str(factory_dump), "--apply", "--save", "--yes")
    assert saved.exit_code == 0, saved.stderr
    golden("params-restore-save.txt", _transcript(saved, tmp_path))
    # a new invocation (power cycle): the drives hold the dump's values from flash
    again = tmp_path / "again.yaml"
    assert cli(*BASE, "dump-params", "-o", str(again)).exit_code == 0
    before, after = read_dump(factory_dump), read_dump(again)
    assert {n: d.params for n, d in after.drives.items()} == {n: d.params for n, d in before.drives.items()}
    nothing = cli(*BASE, "params", "restore", str(factory_dump), "--apply", "--save", "--yes")
    assert "drive1: nothing to change: RAM holds the targets; flash NOT proven" in nothing.stdout
    assert "no SV needed" not in nothing.stdout


@pytest.mark.golden
def test_restore_json(cli, golden, factory_dump, tmp_path):
    _program_and_save(cli)
    r = cli(*BASE, "--json", "params", "restore", str(factory_dump), "--apply")
    assert r.exit_code == 0, r.stderr
    golden("params-restore-json.txt", _transcript(r, tmp_path))
    body = json.loads(r.stdout)
    assert body["command"] == "params restore" and body["apply"] and not body["save"]
    assert {p["key"]: p["result"] for p in body["drives"][0]["params"]}["LL[3]"] == "written, verified"


@pytest.mark.golden
def test_restore_refuses_a_dump_of_another_drive(cli, golden, factory_dump, tmp_path):
    other = _edited(factory_dump, tmp_path / "other.yaml", "drive2", serial=0x5A00FFFF)
    r = cli(*BASE, "params", "restore", str(other), "--apply")
    assert r.exit_code == 1
    golden("params-restore-other-serial.txt", _transcript(r, tmp_path))
    assert "nothing was written" in r.stderr
    ok = cli(*BASE, "params", "restore", str(other), "--apply", "--other-serial")
    assert ok.exit_code == 0, ok.stderr


@pytest.mark.golden
def test_restore_skips_moment_state_and_names_it(cli, golden, factory_dump, tmp_path):
    edited = _edited(factory_dump, tmp_path / "edited.yaml", "drive1", MO=1, PX=1234, UM=2, AC=2000)
    r = cli(*BASE, "params", "restore", str(edited))
    assert r.exit_code == 0, r.stderr
    golden("params-restore-skipped.txt", _transcript(r, tmp_path))


CASES = [
    ("params-restore-unknown-drive", "drive7: {bus: can0, node: 7, params: {AC: 1000}}"),
    ("params-restore-bad-key", "drive1: {bus: can0, node: 1, identity: {serial: 1}, params: {XQ: 1}}"),
    ("params-restore-no-serial", "drive1: {bus: can0, node: 1, params: {AC: 1000}}"),
    ("params-restore-protection-off", "drive1: {bus: can0, node: 1, identity: {serial: 1509949697}, "
                                      "params: {'CL[2]': 1.0, AC: 1000}}"),
    ("params-restore-wrong-node", "drive1: {bus: can0, node: 9, identity: {serial: 1}, params: {AC: 1000}}"),
]


@pytest.mark.golden
@pytest.mark.parametrize("name,drive", CASES, ids=[c[0] for c in CASES])
def test_restore_bad_dumps_golden(cli, golden, tmp_path, name, drive):
    path = tmp_path / "dump.yaml"
    path.write_text(f"meta: {{tool: sherpa-cli}}\ndrives:\n  {drive}\n")
    r = cli(*BASE, "params", "restore", str(path), "--apply")
    assert "Traceback" not in r.stderr
    golden(f"{name}.txt", _transcript(r, tmp_path))


def test_restore_exit_codes(cli, tmp_path):
    assert cli(*BASE, "params", "restore", str(tmp_path / "missing.yaml")).exit_code == 2
    assert cli(*BASE, "params", "restore", "x.yaml", "--save").exit_code == 2


# --------------------------------------------------------------------------- ops level

def requests(drive) -> list[codec.Request]:
    return [codec.decode_request(data) for _, can_id, data in drive.received if can_id == 0x300 + drive.node]


def sets(drive) -> list[tuple[str, int | float]]:
    return [(program.param_key(r.letters, r.index), r.value) for r in requests(drive) if r.kind == "set"]


def executes(drive) -> list[str]:
    return [r.letters for r in requests(drive) if r.kind == "execute"]


def sdo_downloads(drive) -> list[bytes]:
    return [data for _, can_id, data in drive.received if can_id == 0x600 + drive.node and data[0] & 0xE0 == 0x20]


def test_restore_writes_only_changes_never_identity_and_the_mode_first(state_home, tmp_path, monkeypatch):
    cfg = load_config(ROOT / EXAMPLE3)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        serials = {n: d.serial for n, d in session.sim.drives.items()}
    from sherpa_cli.ops.params_file import DriveDump, ParamDump

    drives = {n: DriveDump(n, "can0", cfg.drives[n].node, {"serial": serials[n]},
                           {"AC": 100000, "UM": 2, "LL[3]": -300, "VL[3]": -250, "CA[18]": 4096,
                            "PX": 55, "MC": 20.0}, {})
              for n in ("drive1", "drive2")}
    path = tmp_path / "d.yaml"
    write_dump(path, ParamDump({"tool": "test"}, drives))
    targets, _warnings = restore_targets(cfg, read_dump(path), path)
    assert dict(targets[0].skipped) == {"MC": "read-only", "PX": "position counter; restoring it would shift "
                                        "the joint's position"}
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        plans = program.read_plans(session, targets, need_serial=True)
        program.check_apply(plans, motor_off=False)
        result = program.apply_plans(session, plans)
        assert result.ok
        for d in session.sim.drives.values():
            assert sets(d) == [("UM", 2), ("VL[3]", -250), ("LL[3]", -300)]
            assert sdo_downloads(d) == [] and d.od_writes == [] and executes(d) == []
            assert not [r for r in requests(d) if r.letters == "PX" and r.kind == "set"]


def test_restore_targets_refuses_before_io():
    cfg = load_config(ROOT / EXAMPLE3)
    from sherpa_cli.ops.params_file import DriveDump, ParamDump

    no_serial = ParamDump({}, {"drive1": DriveDump("drive1", "can0", 1, {"serial": None}, {"AC": 1}, {})})
    with pytest.raises(SafetyError, match="no serial number"):
        restore_targets(cfg, no_serial, Path("x.yaml"))
    targets, _ = restore_targets(cfg, no_serial, Path("x.yaml"), other_serial=True)
    assert targets[0].expected_serial is None
    with pytest.raises(ConfigError, match="holds no drives"):
        restore_targets(cfg, ParamDump({}, {}), Path("x.yaml"))


@pytest.fixture
def state_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    return tmp_path / "state"


def test_restore_value_a_drive_cannot_hold_names_the_file(cli, tmp_path):
    path = tmp_path / "dump.yaml"
    path.write_text("meta: {tool: sherpa-cli}\ndrives:\n"
                    "  drive1: {bus: can0, node: 1, identity: {serial: 1}, params: {AC: 99999999999999}}\n")
    r = cli(*BASE, "params", "restore", str(path))
    assert r.exit_code == 2 and "Traceback" not in r.stderr
    assert r.stderr.startswith(f"error: {path}: drives.drive1.params: ") and "outside int32" in r.stderr
    assert "<input>" not in r.stderr
