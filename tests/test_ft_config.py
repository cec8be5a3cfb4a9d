"""`devices:` entries of type ft_sensor: parsed into FtSensorConfig, dumped back, and every bad one
refused by `config check` with one line naming the file, line and key."""

from __future__ import annotations

import pytest

from sherpa_cli.config import load_config_text
from sherpa_cli.config.dump import dump_native
from sherpa_cli.errors import ConfigError

BASE = """\
name: ft-arm
buses:
  can0: {interface: virtual, channel: ft0}
  can1: {interface: virtual, channel: ft1}
drives:
  elbow_a: {bus: can0, node: 10}
  wrist_a: {bus: can1, node: 30}
devices:
  wrist_ft:
    type: ft_sensor
    bus: can1
    base_id: 0x010
    counts_per_force: 500
    counts_per_torque: 1000
    frame: wrist_ft_link
    force_limit: 40
    torque_limit: 4
joints:
  elbow:
    drive: elbow_a
    cpr: 3600
    range: {min: -1000, max: 1000}
  wrist:
    drive: wrist_a
    cpr: 2000
    range: {min: -500, max: 500}
sim:
  ft_sensors:
    wrist_ft: {payload_kg: 1.5, wrist: [wrist], wall_joint: wrist, wall_position: 300}
"""


def edit(old: str, new: str) -> str:
    assert BASE.count(old) == 1, old
    return BASE.replace(old, new)


def test_a_sensor_parses_into_its_settings():
    cfg = load_config_text(BASE, "ft.yaml")
    dev = cfg.devices["wrist_ft"]
    assert dev.type == "ft_sensor" and dev.bus == "can1" and not dev.canopen and dev.address == "can1:0x010"
    assert dev.ft is not None
    assert (dev.ft.base_id, dev.ft.counts_per_force, dev.ft.counts_per_torque) == (0x10, 500, 1000)
    assert (dev.ft.frame, dev.ft.force_limit, dev.ft.torque_limit, dev.ft.reply_ms) == ("wrist_ft_link", 40, 4, 20)
    assert cfg.ft_sensors() == [dev]
    sim = cfg.sim_ft["wrist_ft"]
    assert (sim.payload_kg, sim.wrist, sim.wall_joint, sim.wall_position) == (1.5, ("wrist",), "wrist", 300)


def test_dump_gives_the_same_config_back():
    cfg = load_config_text(BASE, "ft.yaml")
    again = load_config_text(dump_native(cfg), "again.yaml")
    assert again.devices == cfg.devices and again.sim_ft == cfg.sim_ft


def test_limits_are_optional():
    cfg = load_config_text(edit("    force_limit: 40\n    torque_limit: 4\n", ""), "ft.yaml")
    ft = cfg.devices["wrist_ft"].ft
    assert ft is not None and ft.force_limit is None and ft.torque_limit is None


BAD = [
    ("unknown-type", "    type: ft_sensor\n", "    type: ft-sensor\n", "type: ft-sensor",
     "devices.wrist_ft.type", "unknown type 'ft-sensor'; known: canopen-encoder, ft_sensor"),
    ("base-is-a-drive-sdo-id", "base_id: 0x010", "base_id: 0x598", "base_id:", "devices.wrist_ft.base_id",
     "base_id 0x598: its base+6 id 0x59E is SDO tx 0x59E of drive wrist_a (node 30)"),
    ("base-is-a-drive-tpdo2", "base_id: 0x010", "base_id: 0x299", "base_id:", "devices.wrist_ft.base_id",
     "its base+5 id 0x29E is TPDO2 0x29E of drive wrist_a (node 30)"),
    ("base-is-a-drive-rpdo2", "base_id: 0x010", "base_id: 0x31E", "base_id:", "devices.wrist_ft.base_id",
     "its base id 0x31E is RPDO2 0x31E of drive wrist_a (node 30)"),
    ("base-is-emcy", "base_id: 0x010", "base_id: 0x098", "base_id:", "devices.wrist_ft.base_id",
     "its base+6 id 0x09E is EMCY 0x09E of drive wrist_a (node 30)"),
    ("base-is-sync", "base_id: 0x010", "base_id: 0x07A", "base_id:", "devices.wrist_ft.base_id",
     "its base+6 id 0x080 is SYNC"),
    ("base-is-the-host-heartbeat", "base_id: 0x010", "base_id: 0x778", "base_id:", "devices.wrist_ft.base_id",
     "its base+6 id 0x77E is heartbeat 0x77E of the tool's heartbeat (node 126)"),
    ("base-out-of-range", "base_id: 0x010", "base_id: 0x7FA", "base_id:", "devices.wrist_ft.base_id",
     "base_id 0x7FA out of range 0x001..0x7F9"),
    ("missing-counts-per-force", "    counts_per_force: 500\n", "", "  wrist_ft:", "devices.wrist_ft",
     "counts_per_force missing; take it from the sensor's calibration sheet"),
    ("missing-counts-per-torque", "    counts_per_torque: 1000\n", "", "  wrist_ft:", "devices.wrist_ft",
     "counts_per_torque missing"),
    ("zero-counts", "counts_per_torque: 1000", "counts_per_torque: 0", "counts_per_torque:",
     "devices.wrist_ft.counts_per_torque", "counts_per_torque 0 must be > 0"),
    ("force-limit-zero", "force_limit: 40", "force_limit: 0", "force_limit:", "devices.wrist_ft.force_limit",
     "force_limit 0 N must be > 0"),
    ("torque-limit-negative", "torque_limit: 4", "torque_limit: -1", "torque_limit:",
     "devices.wrist_ft.torque_limit", "torque_limit -1 N·m must be > 0"),
    # one axis saturates at 32767 / 500 = 65.53 N: a push along it past that is never seen
    ("force-limit-past-the-range", "force_limit: 40", "force_limit: 70", "force_limit:", "devices.wrist_ft.force_limit",
     "force_limit 70 N is beyond what the sensor reports on one axis (32767 counts / counts_per_force 500 = 65.53 N)"),
    ("torque-limit-past-the-range", "torque_limit: 4", "torque_limit: 32.767", "torque_limit:",
     "devices.wrist_ft.torque_limit", "torque_limit 32.767 N·m is beyond what the sensor reports on one axis"),
    ("node-instead-of-base", "    base_id: 0x010\n", "    node: 16\n", "node: 16", "devices.wrist_ft.node",
     "an ft_sensor is no CANopen node: give its base_id"),
    ("ft-key-on-an-encoder", "    type: ft_sensor\n    bus: can1\n", "    type: canopen-encoder\n    bus: can1\n"
     "    node: 45\n", "base_id:", "devices.wrist_ft.base_id", "'base_id' is a key of ft_sensor devices"),
    ("sim-unknown-wall-joint", "wall_joint: wrist,", "wall_joint: wrsit,", "    wrist_ft: {payload",
     "sim.ft_sensors.wrist_ft", "unknown joint 'wrsit'; did you mean 'wrist'?"),
]


def _line_of(text: str, marker: str) -> int:
    return text[:text.index(marker)].count("\n") + 1


@pytest.mark.parametrize(("old", "new", "marker", "path", "phrase"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_sensor_config_is_one_error_at_its_line(old, new, marker, path, phrase):
    text = edit(old, new)
    with pytest.raises(ConfigError) as err:
        load_config_text(text, "ft.yaml")
    message = str(err.value)
    assert f"ft.yaml:{_line_of(text, marker)}: {path}" in message, message
    assert phrase in message, message


@pytest.mark.parametrize("case", [BAD[0], BAD[1], BAD[8], BAD[11]], ids=lambda c: c[0])
def test_config_check_prints_one_clear_line(cli, tmp_path, case):
    _, old, new, marker, path, phrase = case
    text = edit(old, new)
    file = tmp_path / "ft.yaml"
    file.write_text(text, encoding="utf-8")
    result = cli("config", "check", str(file))
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert result.exit_code == 2, result.stderr
    assert errors == [f"error: {file}:{_line_of(text, marker)}: {path}: " + errors[0].split(f"{path}: ", 1)[1]]
    assert phrase in errors[0] and "Traceback" not in result.stderr


PAIR = """\
  pa: {bus: can1, node: 40}
  pb: {bus: can1, node: 41}
"""
PAIR_JOINTS = """\
pairs:
  wrist_diff:
    drives: [pa, pb]
    sigma: {name: s, cpr: 3600, range: {min: -100, max: 100}}
    delta: {name: d, cpr: 3600, range: {min: -100, max: 100}}
"""


def test_a_pair_on_the_bus_reserves_the_group_ids_rpdo2():
    text = edit("  wrist_a: {bus: can1, node: 30}\n", "  wrist_a: {bus: can1, node: 30}\n" + PAIR)
    text = text.replace("sim:\n", PAIR_JOINTS + "sim:\n")
    load_config_text(text, "ft.yaml")  # base 0x010: clear
    with pytest.raises(ConfigError, match="its base\\+6 id 0x37D is RPDO2 0x37D of the pairs' group id "
                                          "\\(node 125\\) on can1"):
        load_config_text(text.replace("base_id: 0x010", "base_id: 0x377"), "ft.yaml")
    load_config_text(BASE.replace("base_id: 0x010", "base_id: 0x377"), "ft.yaml")  # no pair: the id is free
