"""`sherpa tune show|set` on the simulated arm: dry run writes nothing, --apply reads back, --save is
guarded and counted, bounds (config `tuning:`) refuse before anything is sent."""

from __future__ import annotations

import pytest

from sherpa_cli.config import load_config_text
from sherpa_cli.errors import UsageError
from sherpa_cli.ops.tune import DEFAULT_BOUNDS, parse_assignments
from tests.conftest import ROOT


def _kp2(cli) -> str:
    result = cli("--sim", "tune", "show", "elbow_pitch")
    assert result.exit_code == 0, result.stderr
    return next(line.split()[1] for line in result.stdout.splitlines() if line.strip().startswith("KP[2]"))


def test_show_names_the_unconfirmed_meanings(cli):
    result = cli("--sim", "tune", "show", "shoulder_diff")
    assert result.exit_code == 0
    assert "shoulder_2a:" in result.stdout and "shoulder_2b:" in result.stdout
    assert "KP[2]           0.5  speed loop, proportional" in result.stdout
    assert "FF[1]           0.0  feed-forward, index meaning UNCONFIRMED" in result.stdout


def test_dry_run_writes_nothing_apply_is_ram_save_is_flash(cli):
    result = cli("--sim", "tune", "set", "elbow_pitch", "KP[2]=0.8", "KI[2]=150")
    assert result.exit_code == 0 and "dry run: nothing was written" in result.stdout
    assert _kp2(cli) == "0.5"
    result = cli("--sim", "tune", "set", "elbow_pitch", "KP[2]=0.8", "--apply")
    assert result.exit_code == 0 and "1 written and verified" in result.stdout
    assert _kp2(cli) == "0.8"  # in RAM: the simulated arm stays powered between --sim commands
    assert cli("sim", "--power-cycle").exit_code == 0
    assert _kp2(cli) == "0.5"  # RAM only: a power cycle brings back the flash's value
    result = cli("--sim", "tune", "set", "elbow_pitch", "KP[2]=0.8", "--apply", "--save", "--yes")
    assert result.exit_code == 0 and "saved (save 1 of this drive by this tool)" in result.stdout
    assert _kp2(cli) == "0.8"
    result = cli("--sim", "tune", "set", "elbow_pitch", "KP[2]=0.8", "--apply", "--save", "--yes")
    assert result.exit_code == 0 and "save 2" not in result.stdout  # nothing changed: no SV


@pytest.mark.parametrize(("args", "message"), [
    (["KP[2]=800"], "KP[2]=800 is outside its bounds 0..100"),
    (["KP[2]=-1"], "outside its bounds"),
    (["KP[2]"], "expected GAIN=VALUE"),
    (["KP[2]=fast"], "'fast' is not a number"),
    (["AC=1000"], "AC is not a gain"),
    (["KP[9]=1"], "KP[9]: index outside 1..3"),
    (["KP[2]=0.8", "--save"], "--save needs --apply"),
])
def test_bad_gains_one_message_exit_2_nothing_sent(cli, args, message):
    result = cli("--sim", "tune", "set", "elbow_pitch", *args)
    assert result.exit_code == 2, result.stdout
    assert message in result.stderr and "Traceback" not in result.stderr


def test_config_bounds_win_over_the_defaults():
    text = (ROOT / "configs/sherpa-arm.yaml").read_text() + "\ntuning:\n  KP[2]: [0.1, 2]\n"
    cfg = load_config_text(text, "arm.yaml")
    assert cfg.tuning == {"KP[2]": (0.1, 2.0)}
    assert parse_assignments(cfg, ["kp[2]=1.5"]) == {"KP[2]": 1.5}
    with pytest.raises(UsageError, match=r"outside its bounds 0\.1\.\.2"):
        parse_assignments(cfg, ["KP[2]=3"])
    assert parse_assignments(cfg, ["KI[2]=90000"]) == {"KI[2]": 90000.0}  # default bound
    assert DEFAULT_BOUNDS["KI[2]"] == (0.0, 100000.0)


def test_bad_tuning_section_is_a_config_error():
    from sherpa_cli.errors import ConfigError

    text = (ROOT / "configs/sherpa-arm.yaml").read_text() + "\ntuning:\n  KP[2]: [3, 1]\n"
    with pytest.raises(ConfigError, match=r"tuning.KP\[2\]: low 3 is above high 1"):
        load_config_text(text, "arm.yaml")


def test_gains_are_in_dump_params_and_params_diff(cli, tmp_path):
    dump = tmp_path / "before.yaml"
    assert cli("--sim", "dump-params", "elbow_pitch", "-o", str(dump)).exit_code == 0
    text = dump.read_text()
    assert "KP[2]: 0.5" in text and "KI[2]: 200.0" in text and "FF[1]: 0.0" in text
    assert cli("--sim", "tune", "set", "elbow_pitch", "KP[2]=0.8", "--apply").exit_code == 0
    result = cli("--sim", "params", "diff", str(dump), "live", "--only-differences")
    assert result.exit_code == 1
    rows = [line.split() for line in result.stdout.splitlines() if line.strip().startswith("KP")]
    assert len(rows) == 1 and rows[0][:3] == ["KP[2]", "0.5", "0.8"]  # only the gain that was changed
