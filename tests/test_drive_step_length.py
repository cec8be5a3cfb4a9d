"""`log step --source drive`: the drive's recorder holds the whole step, the MO/UM switch (the
drive's settle window after each MO) and the time the step loop takes to notice its end included.
On the simulated arm's stepped time with the bundled config's own 0.5 s settle window."""

from __future__ import annotations

import csv

import pytest

from sherpa_cli.ops.drive_step import PRE_S, TAIL_S, WORST_SWITCH, record_length, switch_time

ARM = ["--sim"]  # configs/sherpa-arm.yaml: the seed's 0.5 s MO settle window


def _times(path):
    with path.open() as f:
        return [float(r["time_s"]) for r in csv.DictReader(f)]


@pytest.mark.parametrize("mode,args", [("torque", ["--torque", "1", "--for", "1"]),
                                       ("velocity", ["--velocity", "0.1", "--for", "1"])])
def test_the_drive_recording_reaches_the_end_of_the_can_recording(cli, cli_windows, tmp_path, mode, args):
    cli_windows(False)  # the config's 0.5 s MO settle window: the switch is longer than the old margin
    out = tmp_path / "step"
    result = cli(*ARM, "log", "step", "elbow_pitch", *args, "--rate", "500", "-o", str(out), "--source", "drive", "--apply")
    assert result.exit_code == 0, result.transcript()
    drive, can = _times(out / "recording.csv"), _times(out / "can-recording.csv")
    if mode == "torque":
        assert can[-1] > 1.5  # the switch (MO=1, 0.5 s) came before the 1 s of the step
    period = drive[1] - drive[0]
    assert drive[-1] >= can[-1] - period, (drive[-1], can[-1])


def test_the_length_counts_the_switch_only_where_the_recording_starts_before_it():
    assert switch_time(("MO=1",), 0.5) == pytest.approx(0.55)
    assert switch_time(WORST_SWITCH, 0.5) == pytest.approx(1.15)
    assert switch_time((), 0.5) == 0.0
    assert record_length("now", 1.0, 0.55) == pytest.approx(PRE_S + 0.55 + 1.0 + TAIL_S)
    assert record_length("bg", 1.0, 0.55) == pytest.approx(1.0 + TAIL_S)  # it starts at the BG, after the switch
