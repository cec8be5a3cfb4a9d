"""`sherpa --sim log step --source drive`: one step recorded by the drive's own recorder and
over CAN at once, golden reports on stepped time (tests/test_log_step_golden.py explains it), and the
two recordings' step metrics agree within one CAN sample period. Also: the recorder settings are put
back, the drive's recording is at the servo rate, and --source drive refuses an MCAP output."""

from __future__ import annotations

import csv
import json

import pytest

from sherpa_cli.elmo.recorder import RecorderSettings

ARM = ["--config", "tests/data/step-arm.yaml", "--sim"]
RATE = 500
CASES = [
    ("log-step-drive-velocity", ["--velocity", "0.1", "--for", "1"]),
    ("log-step-drive-position", ["--position", "1"]),
    ("log-step-drive-torque", ["--torque", "1", "--for", "0.3"]),
]


@pytest.mark.golden
@pytest.mark.parametrize("name,args", CASES, ids=[c[0] for c in CASES])
def test_drive_and_can_recordings_of_one_step_agree_within_one_sample(cli, golden, tmp_path, name, args):
    out = tmp_path / "step"
    result = cli(*ARM, "log", "step", "arm", *args, "--rate", str(RATE), "-o", str(out), "--source", "drive",
                 "--apply")
    assert result.exit_code == 0, result.transcript()
    golden(f"{name}.txt", result.transcript().replace(str(tmp_path), "TMP"))
    report = json.loads((out / "metrics.json").read_text())
    period = 1 / RATE
    for key in ("dead_time", "rise_time", "settling_time"):
        drive, can = report["drive"]["metrics"][key], report["metrics"][key]
        assert drive is not None and can is not None, key
        assert abs(drive - can) <= period, (key, drive, can)
    # the drive's recording is at the servo rate, finer than the bus's
    assert report["drive"]["period_s"] < period
    with (out / "recording.csv").open() as f:
        drive_rows = list(csv.DictReader(f))
    with (out / "can-recording.csv").open() as f:
        can_rows = list(csv.DictReader(f))
    t0 = float(drive_rows[0]["time_s"])
    assert len(drive_rows) > len([r for r in can_rows if float(r["time_s"]) >= t0])  # over the same span
    from sherpa_cli.log.plot import have_matplotlib

    assert (out / "step.png").is_file() == have_matplotlib()  # the drive's recording, the bus's beside it


def test_the_recorder_settings_are_put_back(cli, tmp_path):
    before = cli(*ARM, "cmd", "elbow", "RC", "RL", "RG")
    assert before.exit_code == 0, before.transcript()
    result = cli(*ARM, "log", "step", "arm", "--velocity", "0.1", "--for", "0.5", "--rate", str(RATE),
                 "-o", str(tmp_path / "s"), "--source", "drive", "--apply")
    assert result.exit_code == 0, result.transcript()
    after = cli(*ARM, "cmd", "elbow", "RC", "RL", "RG")
    assert after.stdout == before.stdout


def test_source_drive_refuses_mcap_and_unknown_sources(cli, tmp_path):
    result = cli(*ARM, "log", "step", "arm", "--velocity", "0.1", "-o", str(tmp_path / "x.mcap"), "--source", "drive")
    assert result.exit_code == 2 and "--source drive writes a directory" in result.stderr
    result = cli(*ARM, "log", "step", "arm", "--velocity", "0.1", "-o", str(tmp_path / "x"), "--source", "usb")
    assert result.exit_code == 2 and "--source usb: expected can or drive" in result.stderr


def test_a_recording_longer_than_the_drive_holds_is_refused_before_anything_moves():
    from sherpa_cli.elmo.recorder import plan_recording
    from sherpa_cli.errors import UsageError

    with pytest.raises(UsageError):
        plan_recording(1e6, RecorderSettings())
