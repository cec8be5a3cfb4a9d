"""`log record --source drive`: the drives' own recorders through the CLI on the simulated arm."""

from __future__ import annotations

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.errors import ProtocolError
from sherpa_cli.log.recording import read_csv
from sherpa_cli.ops.drive_record import record_drives
from sherpa_cli.sim.arm import SimArm
from tests.conftest import ROOT


def test_pair_recorded_together_at_the_servo_rate(cli, tmp_path):
    out = tmp_path / "pair.csv"
    result = cli("--sim", "log", "record", "shoulder_diff", "--source", "drive", "--for", "0.2", "-o", str(out))
    assert result.exit_code == 0, result.stderr
    assert "shoulder_2a: 556 samples at 2777.8 Hz (RG=1)" in result.stdout
    assert "shoulder_2b: 556 samples at 2777.8 Hz (RG=1)" in result.stdout
    rec = read_csv(out)
    assert len(rec.times) == 556
    assert rec.times[1] == pytest.approx(360e-6)
    for col in ("shoulder_pitch.pos_rad", "shoulder_roll.vel_rad_s", "shoulder_2a.px", "shoulder_2a.vx",
                "shoulder_2a.iq_a", "shoulder_2a.pe", "shoulder_2b.vcmd"):
        assert col in rec.columns


@pytest.mark.parametrize(("args", "message"), [
    (["--source", "disk"], "--source disk: expected can or drive"),
    (["--source", "drive", "--trigger", "later"], "--trigger later: expected now or bg"),
    (["--source", "drive", "--poll"], "--poll and --foxglove do not apply"),
    (["--source", "drive", "--for", "2000"], "holds at most"),
    (["--source", "drive", "--for", "-1"], "expected seconds > 0"),
])
def test_bad_options_one_message_exit_2(cli, tmp_path, args, message):
    result = cli("--sim", "log", "record", "shoulder_2a", "--for", "0.1", "-o", str(tmp_path / "x.csv"), *args)
    assert result.exit_code == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "x.csv").exists()


def test_mcap_output_is_refused(cli, tmp_path):
    result = cli("--sim", "log", "record", "shoulder_2a", "--source", "drive", "--for", "0.1",
                 "-o", str(tmp_path / "x.mcap"))
    assert result.exit_code == 2 and "one CSV file" in result.stderr


def test_bad_upload_writes_no_file_and_restores_the_ram(tmp_path, monkeypatch):
    """One drive's upload is cut short: one error, nothing returned, both drives' RAM as before."""
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    arm = SimArm.in_process(cfg)
    refs = drive_refs(cfg, ["shoulder_diff"], configured_only=True)
    with ArmSession.open(cfg, sim=arm) as session:
        drives = {r.name: arm.drives[r.name] for r in refs}
        b = drives["shoulder_2b"]
        monkeypatch.setattr(b.recorder, "settings",
                            type(b.settings)(**{**b.settings.__dict__, "recorder_upload_fault": "short"}))
        before = {n: {k: v for k, v in d.ram.items() if k[:2] in ("RV", "RC", "RG", "RL", "RP")}
                  for n, d in drives.items()}
        with pytest.raises(ProtocolError, match=r"shoulder_2b .*0x2030:1 \(pos\): header says"):
            record_drives(session, refs, 0.05)
        for n, d in drives.items():
            assert {k: v for k, v in d.ram.items() if k[:2] in ("RV", "RC", "RG", "RL", "RP")} == before[n]
            assert d.recorder.state == 0 and d.save_count == 0
