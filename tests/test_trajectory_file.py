"""log/trajectory_file.py: a recording written by the project's own CSV and MCAP writers (and by
`sherpa --sim log record`) reads back as a playable trajectory; a planner's CSV; every bad file is
one line naming the file and the row, exit 2, no traceback."""

from __future__ import annotations

import math
import sys

import pytest
from conftest import ROOT

from sherpa_cli.config import load_config
from sherpa_cli.errors import ExitCode, UsageError
from sherpa_cli.joints.trajectory import motor_points
from sherpa_cli.log.mcap_out import FrameWriter, write_recording
from sherpa_cli.log.recording import Recording, write_csv
from sherpa_cli.log.trajectory_file import load_trajectory
from sherpa_cli.units import counts_to_rad

CONFIG = ROOT / "tests" / "data" / "move-arm.yaml"
CFG = load_config(CONFIG)
EXTRA = "pip install 'sherpa-cli[robotics]'"


def swing(t: float, amplitude: float, duration: float) -> float:
    """A smooth move of ``amplitude`` counts in ``duration`` s (half a cosine): at rest at both ends."""
    return amplitude * (1 - math.cos(math.pi * min(t, duration) / duration)) / 2


def moving_recording() -> tuple[Recording, dict[str, list[int]]]:
    """A recording as `log record` makes it: samples at about 10 ms with the host's jitter, a burst of
    catch-up SYNCs at the start, whole counts latched at each sample's time, every joint moving, a
    sample one drive missed."""
    n = 60
    times = [0.0, 0.00009, 0.00021] + [0.01 * i + (0.0004 if i % 3 == 0 else -0.0002) for i in range(1, n - 2)]
    amplitude = {"j1": 500, "j2": -400, "pitch": 600, "roll": -300}
    counts = {name: [round(swing(t, a, 0.55)) for t in times] for name, a in amplitude.items()}
    columns: dict[str, list[float]] = {}
    for name, values in counts.items():
        cpr = CFG.joints[name].cpr
        columns[f"{name}.pos_rad"] = [counts_to_rad(c, cpr) for c in values]
        columns[f"{name}.vel_rad_s"] = [0.0] * n
    columns["yaw.px"] = [float(c) for c in counts["j1"]]
    columns["yaw.vx"] = [0.0] * n
    columns["j2.pos_rad"][30] = math.nan  # the elbow's TPDO did not come for this SYNC
    return Recording(times=times, columns=columns), counts


@pytest.mark.parametrize("suffix", [".csv", ".mcap"])
def test_a_recording_written_by_the_project_reads_back_and_is_playable(tmp_path, suffix):
    rec, counts = moving_recording()
    path = tmp_path / f"run{suffix}"
    if suffix == ".csv":
        write_csv(rec, path)
    else:
        write_recording(path, rec, CFG, time_zero_ns=1_700_000_000_000_000_000)
    traj = load_trajectory(path, CFG, period=0.01)  # checked, stream included
    assert traj.joints == ("j1", "j2", "pitch", "roll")
    # the catch-up burst and the row the elbow missed are left out; the rest, times from 0
    kept = [0] + [i for i in range(3, 60) if i != 30]
    assert traj.samples == len(kept)
    assert traj.times[0] == 0 and traj.times[-1] == pytest.approx(rec.times[-1], abs=1e-6)
    for name, values in counts.items():
        got = traj.position(name)
        assert all(abs(g - values[i]) < 0.01 for g, i in zip(got, kept, strict=True)), name
    if suffix == ".csv":
        assert traj.rows[:3] == (2, 5, 6)  # the file's lines: messages name them
    stream = motor_points(CFG, traj, 0.01)
    assert stream.drives == ("yaw", "left", "right", "elbow")
    assert stream.motor("yaw").positions[-1] == counts["j1"][-1]


def test_a_recording_of_the_simulated_arm_by_log_record_is_playable(cli, tmp_path):
    out_csv, out_mcap = tmp_path / "sim.csv", tmp_path / "sim.mcap"
    result = cli("--config", str(CONFIG), "--sim", "log", "record", "--rate", "100", "--for", "0.2",
                 "-o", str(out_csv), "-o", str(out_mcap))
    assert result.exit_code == 0, result.transcript()
    for path in (out_csv, out_mcap):
        traj = load_trajectory(path, CFG, period=0.01)
        assert traj.joints == ("j1", "j2", "pitch", "roll") and traj.samples >= 2


def test_a_recording_whose_time_goes_back_is_refused_and_a_repeated_microsecond_is_left_out(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("time_s,j1.pos_rad\n0.000000,0\n0.000000,0\n0.010000,0\n0.020000,0\n0.015000,0\n")
    with pytest.raises(UsageError) as info:
        load_trajectory(path, CFG)
    assert one_line(info.value).startswith(f"{path}:6 (t=0.015 s): the time goes back from the previous sample's")
    path.write_text("time_s,j1.pos_rad\n0.000000,0\n0.000000,0\n0.010000,0\n0.020000,0\n")
    assert load_trajectory(path, CFG).rows == (2, 4, 5)


def test_a_planner_csv(tmp_path):
    path = tmp_path / "plan.csv"
    path.write_text("t,j1,pitch,roll\n"
                    "0.5,0,0,0\n"
                    "\n"
                    "0.6, 0.1 ,0.05,-0.05\n"
                    "0.7,0.2,0.1,-0.1\n")
    traj = load_trajectory(path, CFG)
    assert traj.joints == ("j1", "pitch", "roll")
    assert traj.times == pytest.approx((0.0, 0.1, 0.2))  # from the first row
    assert traj.rows == (2, 4, 5)
    assert traj.position("j1")[2] == pytest.approx(0.2 * 4000 / (2 * math.pi))


def test_a_path_outside_the_limits_is_refused_naming_the_file_and_line(tmp_path):
    path = tmp_path / "plan.csv"
    path.write_text("t,j1\n0,0\n0.1,0.01\n0.2,1.5\n")
    with pytest.raises(UsageError) as info:
        load_trajectory(path, CFG)
    assert str(info.value).startswith(f"{path}:4 (t=0.200 s): j1 moves at ")
    # unchecked, it loads
    assert load_trajectory(path, CFG, check=False).samples == 3


BAD_CSV = [
    ("", "{p}: empty: no header and no samples"),
    ("\n\n", "{p}: empty: no header and no samples"),
    ("t,j1\n", "{p}: no samples after the header"),
    ("time,j1\n0,0\n", "{p}:1: no time column: the first column is 'time', expected 't' (a planner's CSV) or "
                       "'time_s' (a `sherpa log record` CSV)"),
    ("t\n0\n0.1\n", "{p}:1: the header names no joint column after 't'"),
    ("t,j1,\n0,0,0\n", "{p}:1: column 3 has no name"),
    ("t,j1,j1\n0,0,0\n", "{p}:1: joint 'j1' is named twice"),
    ("t,j1,pich,roll\n0,0,0,0\n", "{p}:1: joint 'pich' is not a joint of the config; did you mean 'pitch'?"),
    ("t,j1,pitch\n0,0,0\n0.1,0,0\n", "{p}:1: pitch is a joint of the Σ/Δ pair diff; the trajectory must give roll too"),
    ("t,j1\n0,0\n0.1,abc\n", "{p}:3: column 'j1': 'abc' is not a number"),
    ("t,j1\n0,0\n0.1,\n", "{p}:3: column 'j1' is empty; every cell must be a number"),
    ("t,j1\n0,0\n0.1,\uff13\n", "{p}:3: column 'j1': '\uff13' is not a number"),
    ("t,j1\n0,0\n0.1\n", "{p}:3: 1 cells, the header has 2"),
    ("t,j1\n0,0\nnan,0\n", "{p}:3: the time 'nan' is not a finite number"),
    ("t,j1\n0,0\nx,0\n", "{p}:3: column 't': 'x' is not a number"),
    ("t,j1\n0,0\n0.1,nan\n", "{p}:3 (t=0.100 s): j1 is not a finite number (nan)"),
    ("t,j1\n0,0\n0.1,inf\n", "{p}:3 (t=0.100 s): j1 is not a finite number (inf)"),
    ("t,j1\n0,0\n", "{p}: the trajectory has one sample; it needs two or more"),
    ("t,j1\n0,0\n0.1,0.01\n0.1,0.02\n", "{p}:4 (t=0.100 s): the time repeats the previous sample's 0.1 s"),
    ("t,j1\n0,0\n0.2,0.01\n0.1,0.02\n", "{p}:4 (t=0.100 s): the time goes back from the previous sample's 0.2 s"),
    ("t,j1\n0,0\n0.5,2.0\n1,3.0\n", "{p}:4 (t=1.000 s): j1 at 1909.9 counts (+3.0000 rad) is outside its normal range "
                                    "[-1900, 1900] counts"),
    ("t,j1\n0,0\n0.1,0\n0.2,0.8\n", "{p}:3 (t=0.100 s): j1 accelerates at "),
    ("time_s,j1.pos_rad,j1.vel_rad_s\n0,,0\n0.01,,0\n", "{p}: no samples after the header (every row lacks a joint "
                                                         "position)"),
]


def one_line(exc: UsageError) -> str:
    text = str(exc)
    assert "\n" not in text and "Traceback" not in text
    assert exc.exit_code == ExitCode.USAGE == 2
    return text


@pytest.mark.parametrize(("text", "expected"), BAD_CSV)
def test_every_bad_csv_is_one_line_naming_file_and_row(tmp_path, text, expected):
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(UsageError) as info:
        load_trajectory(path, CFG)
    assert expected.format(p=path) in one_line(info.value)


def test_a_missing_file_a_directory_and_a_binary_file(tmp_path):
    cases = {tmp_path / "none.csv": "none.csv: no such file", tmp_path: ": not a file"}
    binary = tmp_path / "image.csv"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe")
    cases[binary] = "image.csv: not a CSV text file (not UTF-8 text)"
    nul = tmp_path / "nul.csv"
    nul.write_bytes(b"t,j1\n0,\x000\n")
    cases[nul] = "nul.csv: not a CSV text file (it holds NUL bytes)"
    for path, expected in cases.items():
        with pytest.raises(UsageError) as info:
            load_trajectory(path, CFG)
        assert expected in one_line(info.value)


def test_an_mcap_that_is_not_a_recording(tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"t,j1\n0,0\n")
    with pytest.raises(UsageError) as info:
        load_trajectory(garbage, CFG)
    assert one_line(info.value).startswith(f"{garbage}: not a readable .mcap recording (")
    capture = tmp_path / "capture.mcap"
    with FrameWriter(capture):
        pass
    with pytest.raises(UsageError) as info:
        load_trajectory(capture, CFG)
    assert one_line(info.value) == f"{capture}: no /joint_states messages: not a recording of joints"


def test_an_mcap_with_an_unknown_joint_names_it(tmp_path):
    other = load_config(ROOT / "configs" / "sherpa-arm.yaml")
    joint = next(iter(other.joints))
    cpr = other.joints[joint].cpr
    rec = Recording(times=[0.0, 0.01], columns={f"{joint}.pos_rad": [0.0, counts_to_rad(1, cpr)],
                                                f"{joint}.vel_rad_s": [0.0, 0.0]})
    path = tmp_path / "other.mcap"
    write_recording(path, rec, other, time_zero_ns=10**18)
    with pytest.raises(UsageError) as info:
        load_trajectory(path, CFG)
    assert one_line(info.value).startswith(f"{path}: /joint_states: joint '{joint}' is not a joint of the config")


def test_an_mcap_without_the_extra_says_what_to_install(tmp_path, monkeypatch):
    path = tmp_path / "run.mcap"
    path.write_bytes(b"")
    for name in ("mcap", "mcap.reader", "mcap.writer", "mcap_ros2", "mcap_ros2.writer", "mcap_ros2.decoder"):
        monkeypatch.setitem(sys.modules, name, None)  # `import mcap` raises ImportError
    with pytest.raises(UsageError) as info:
        load_trajectory(path, CFG)
    assert EXTRA in one_line(info.value) and str(path) in str(info.value)


def test_no_bad_input_escapes_as_another_exception(tmp_path):
    """Whatever the bytes, the loader answers with a UsageError or a trajectory, never a traceback."""
    samples = [b"t,j1\r\n0,0\r\n0.1,0.01\r\n", b"\xef\xbb\xbft,j1\n0,0\n", b"t;j1\n0;0\n", b"\x00" * 10,
               b"t,j1\n" + b"0," * 5000 + b"\n", b'"t","j1"\n"0","0"\n"0.1","0.01"\n']
    for i, data in enumerate(samples):
        path = tmp_path / f"f{i}.csv"
        path.write_bytes(data)
        try:
            load_trajectory(path, CFG)
        except UsageError as exc:  # anything else fails the test with its traceback
            one_line(exc)
