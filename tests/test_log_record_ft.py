"""`log record` records the F/T sensor on the recorded buses: columns ``wrist_ft.fx_n`` ..
``wrist_ft.tz_nm`` in the CSV, ``/sherpa/wrench/wrist_ft`` geometry_msgs/WrenchStamped in the MCAP
(read back with the mcap reader). A real-time recording (the sensor answers requests, not SYNC):
the tests assert what load cannot change -- the columns, the schema, the frame, the values -- not how
many samples arrived."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.devices.ft_sensor import FtTrack, Wrench
from sherpa_cli.log import ros_msgs
from sherpa_cli.log.record import bus_budget

ROOT = Path(__file__).resolve().parent.parent
ARM = "tests/data/ft-arm.yaml"
COLUMNS = ["wrist_ft.fx_n", "wrist_ft.fy_n", "wrist_ft.fz_n", "wrist_ft.tx_nm", "wrist_ft.ty_nm", "wrist_ft.tz_nm"]


def test_csv_has_the_sensor_columns(cli, tmp_path):
    out = tmp_path / "run.csv"
    result = cli("--config", ARM, "--sim", "log", "record", "--for", "0.5", "--rate", "50", "-o", str(out))
    assert result.exit_code == 0, result.stderr
    assert "wrist_ft: " in result.stdout and " samples of " in result.stdout
    with out.open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and all(c in rows[0] for c in COLUMNS)
    fz = [float(r["wrist_ft.fz_n"]) for r in rows if r["wrist_ft.fz_n"]]
    assert fz and all(-9.9 < v < -9.7 for v in fz)  # the 1 kg payload, wrist at 0


def test_mcap_has_wrench_stamped_in_the_sensor_frame(cli, tmp_path):
    pytest.importorskip("mcap_ros2")
    from mcap_ros2.reader import read_ros2_messages

    out = tmp_path / "run.mcap"
    result = cli("--config", ARM, "--sim", "log", "record", "--for", "0.5", "--rate", "50", "-o", str(out))
    assert result.exit_code == 0, result.stderr
    with out.open("rb") as fh:
        msgs = list(read_ros2_messages(fh, ["/sherpa/wrench/wrist_ft"]))
    assert msgs, "no WrenchStamped message"
    for m in msgs:
        assert m.schema.name == "geometry_msgs/msg/WrenchStamped"
        assert m.ros_msg.header.frame_id == "wrist_ft_link"
        assert -9.9 < m.ros_msg.wrench.force.z < -9.7 and abs(m.ros_msg.wrench.torque.x) < 0.05
        stamp = m.ros_msg.header.stamp
        assert stamp.sec * 10**9 + stamp.nanosec == m.log_time_ns


def test_track_columns_and_budget():
    cfg = load_config(ROOT / ARM)
    track = FtTrack(cfg.devices["wrist_ft"])
    track.add(2, Wrench(1.0, 2.0, 3.0, 0.1, 0.2, 0.3))
    cols = track.columns([1, 2])
    assert list(cols) == COLUMNS
    assert math.isnan(cols["wrist_ft.fx_n"][0]) and [v[1] for v in cols.values()] == [1.0, 2.0, 3.0, 0.1, 0.2, 0.3]
    refs = drive_refs(cfg, None)
    plain = bus_budget(cfg, refs, 100, current=False)[0].bits_per_sync
    with_ft = bus_budget(cfg, refs, 100, current=False, ft_sensors=[cfg.devices["wrist_ft"]])[0].bits_per_sync
    assert with_ft > plain  # a request and two 8-byte replies per sample


def test_wrench_stamped_definition_is_rosbag2s():
    text = ros_msgs.WRENCH_STAMPED_DEF
    assert text.startswith("std_msgs/Header header\nWrench wrench\n")
    assert "MSG: geometry_msgs/Wrench\nVector3 force\nVector3 torque\n" in text
    assert "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n" in text
    msg = ros_msgs.wrench_stamped(1_500_000_000, "f", [1, 2, 3], [4, 5, 6])
    assert msg == {"header": {"stamp": {"sec": 1, "nanosec": 500_000_000}, "frame_id": "f"},
                   "wrench": {"force": {"x": 1.0, "y": 2.0, "z": 3.0}, "torque": {"x": 4.0, "y": 5.0, "z": 6.0}}}
