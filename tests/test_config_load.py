"""Shipped configs load, round-trip through dump_native, and mean what the seed says."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from sherpa_cli.config import dump_native, load_config, load_config_text
from sherpa_cli.config.catalog import builtin_catalog
from sherpa_cli.config.model import JointRole, SwitchKind

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = sorted((ROOT / "configs").rglob("*.yaml"))
NATIVE = [p for p in CONFIGS if p.name != "seed-d1.yaml"]
SEED = Path("/work/shared/seed/000_36f418c6cf0db1da.txt")


def test_the_shipped_configs_are_there():
    names = {str(p.relative_to(ROOT)) for p in CONFIGS}
    assert {"configs/sherpa-arm.yaml", "configs/seed-d1.yaml", "configs/appendix-c/example1.yaml",
            "configs/appendix-c/example2.yaml", "configs/appendix-c/example3.yaml"} <= names


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_shipped_config_loads(path):
    cfg = load_config(path)
    assert cfg.drives and cfg.joints
    assert cfg.source == str(path)


@pytest.mark.parametrize("path", NATIVE, ids=lambda p: p.name)
def test_native_configs_load_without_warnings(path):
    assert load_config(path).warnings == ()


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_dump_load_round_trip(path):
    cfg = load_config(path)
    text = dump_native(cfg)
    again = load_config_text(text, cfg.source)
    if path.name == "seed-d1.yaml":
        # The rosparam-only warnings (no overshoot, no models) cannot survive conversion.
        assert dataclasses.replace(again, warnings=cfg.warnings) == cfg
    else:
        assert again == cfg
    assert dump_native(again) == text


def test_round_trip_is_not_vacuous():
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    text = dump_native(cfg).replace("margin: 36", "margin: 37", 1)
    assert load_config_text(text, cfg.source) != cfg


def test_dump_leaves_out_the_builtin_catalog_but_keeps_overrides():
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    assert "catalog" not in yaml.safe_load(dump_native(cfg))
    base = (ROOT / "configs/appendix-c/example1.yaml").read_text()
    text = base + "catalog:\n  drives:\n    whistle-10/60: {inputs: 4}\n  peak_fraction: 0.7\n"
    cfg2 = load_config_text(text, "x.yaml")
    assert cfg2.catalog.drives["whistle-10/60"].inputs == 4
    assert cfg2.catalog.drives["whistle-10/60"].current_peak == 20.0
    dumped = yaml.safe_load(dump_native(cfg2))["catalog"]
    assert list(dumped["drives"]) == ["whistle-10/60"] and dumped["peak_fraction"] == 0.7
    assert load_config_text(dump_native(cfg2), "x.yaml") == cfg2


def test_seed_d1_is_the_seed_text_verbatim():
    if not SEED.exists():
        pytest.skip("seed report not available")
    seed = SEED.read_text(encoding="utf-8")
    start = seed.index("ros_can_interface:\n")
    end = seed.index("ext_pos_input: joint/shoulder/joint4/position}", start)
    block = seed[start:end] + "ext_pos_input: joint/shoulder/joint4/position}\n"
    assert block in (ROOT / "configs/seed-d1.yaml").read_text(encoding="utf-8")


def test_rosparam_example_maps_to_four_drives_and_one_pair():
    cfg = load_config(ROOT / "configs/seed-d1.yaml")
    assert {n: (d.bus, d.node, d.model) for n, d in cfg.drives.items()} == {
        "node0": ("can0", 10, None), "node1": ("can0", 20, None), "node2": ("can0", 30, None),
        "node3": ("can1", 40, None)}
    assert [(b.name, b.interface, b.channel, b.send_interval_us, b.poll_interval_ms) for b in cfg.buses.values()] == [
        ("can0", "socketcan", "can0", 1000, 10), ("can1", "socketcan", "can1", 1000, 100)]
    (pair,) = cfg.pairs.values()
    assert (pair.drive_a, pair.drive_b, pair.sigma, pair.delta) == ("node1", "node2", "joint1", "joint2")
    sigma, delta = cfg.joints["joint1"], cfg.joints["joint2"]
    assert (sigma.role, delta.role) == (JointRole.SIGMA, JointRole.DELTA)
    assert sigma.drive is None and sigma.pair == pair.name
    assert (sigma.cpr, sigma.full_range, sigma.margin, sigma.overshoot, sigma.cal_pos) == (6000, (-1500, 1500), 60, 0,
                                                                                           -1450)
    assert [(s.input, s.kind, s.side, s.position) for s in sigma.switches] == [
        (1, SwitchKind.STOP, "low", -1500), (2, SwitchKind.STOP, "high", 1500)]
    assert [(s.input, s.side) for s in delta.switches] == [(3, "low"), (4, "high")]
    j0, j3 = cfg.joints["joint0"], cfg.joints["joint3"]
    assert (j0.drive, j0.cal_speed, j0.cal_pos, j0.switches, j0.vel_limit, j0.current) == ("node0", 300, 0, (), None,
                                                                                           None)
    assert j3.abs_encoder is not None and j3.abs_encoder.source == "joint/shoulder/joint4/position"
    assert j3.cal_pos is None
    assert any("no overshoot" in w for w in cfg.warnings)
    assert any("joint0" in w and "cannot be calibrated" in w for w in cfg.warnings)


def test_pair_drive_a_is_the_lower_node_id_whatever_the_order():
    base = (ROOT / "configs/appendix-c/example3.yaml").read_text()
    text = base.replace("drives: [drive1, drive2]", "drives: [drive2, drive1]")
    assert text != base
    pair = load_config_text(text, "x.yaml").pairs["pair1"]
    assert (pair.drive_a, pair.drive_b) == ("drive1", "drive2")
    # and by node id, not by name
    text = base.replace("node: 1,", "node: 9,")
    pair = load_config_text(text, "x.yaml").pairs["pair1"]
    assert (pair.drive_a, pair.drive_b) == ("drive2", "drive1")


def test_appendix_c_examples_hold_the_seed_numbers():
    ex1 = load_config(ROOT / "configs/appendix-c/example1.yaml").joints["joint1"]
    assert (ex1.cpr, ex1.full_range, ex1.overshoot_range, ex1.normal_range) == (600, (-220, 220), (-240, 240),
                                                                                (-190, 190))
    assert [(s.input, s.kind, s.position) for s in ex1.switches] == [(3, SwitchKind.STOP, -220),
                                                                     (4, SwitchKind.STOP, 220)]
    ex2 = load_config(ROOT / "configs/appendix-c/example2.yaml").joints["joint1"]
    assert [(s.input, s.kind, s.position) for s in ex2.switches] == [(1, SwitchKind.HOME, 20)]
    assert ex2.cal_pos == 20 and ex2.overshoot_range == (-240, 240)
    ex3 = load_config(ROOT / "configs/appendix-c/example3.yaml")
    s, d = ex3.joints["joint_sigma"], ex3.joints["joint_delta"]
    assert (s.full_range, s.overshoot_range, s.margin, s.cal_pos) == ((-220, 220), (-240, 240), 30, -220)
    assert (d.full_range, d.overshoot_range, d.margin) == ((-160, 160), (-170, 170), 10)
    assert [x.input for x in s.switches + d.switches] == [1, 2, 3, 4]


def test_rosparam_table_c2_matches_native_example3():
    text = """\
ros_can_interface:
  interfaces: [can0]
  nodes:
    '1': {topics: j/1, dev_bus: can0, dev_id: 1, dev_type: 1, cpr: 600, pos_min: -220, pos_max: 220,
          pos_margin: 30, diffdrive: 2, pos_min_dd: -160, pos_max_dd: 160, pos_margin_dd: 10, cal_pos: -220,
          cal_sw_L: 1, cal_sw_H: 2, cal_sw_dd_L: 3, cal_sw_dd_H: 4}
    '2': {topics: j/2, dev_bus: can0, dev_id: 2, dev_type: 1, cpr: 600, pos_min: -220, pos_max: 220,
          pos_margin: 30, diffdrive: 1, pos_min_dd: -160, pos_max_dd: 160, pos_margin_dd: 10, cal_pos: -220,
          cal_sw_L: 1, cal_sw_H: 2, cal_sw_dd_L: 3, cal_sw_dd_H: 4}
"""
    cfg = load_config_text(text, "c2.yaml")
    native = load_config(ROOT / "configs/appendix-c/example3.yaml")
    for ros, nat in (("joint1", "joint_sigma"), ("joint2", "joint_delta")):
        r, n = cfg.joints[ros], native.joints[nat]
        assert (r.cpr, r.full_range, r.margin, [(s.input, s.kind, s.side) for s in r.switches]) == \
               (n.cpr, n.full_range, n.margin, [(s.input, s.kind, s.side) for s in n.switches])
    assert cfg.joints["joint1"].cal_pos == -220


def test_rosparam_single_low_switch_is_a_home_switch_at_cal_pos():
    text = """\
ros_can_interface:
  interfaces: can0
  nodes:
    '0': {topics: j, dev_bus: can0, dev_id: 1, dev_type: 1, cpr: 600, pos_min: -220, pos_max: 220,
          pos_margin: 30, cal_sw_L: 1, cal_pos: 20}
    '1': {topics: j, dev_bus: can0, dev_id: 2, dev_type: 1, cpr: 600, pos_min: -220, pos_max: 220,
          pos_margin: 30, cal_sw_L: 1}
"""
    cfg = load_config_text(text, "c1.yaml")
    (home,) = cfg.joints["joint0"].switches
    assert (home.input, home.kind, home.position, home.side) == (1, SwitchKind.HOME, 20, None)
    (home1,) = cfg.joints["joint1"].switches
    assert home1.position == -220 and cfg.joints["joint1"].cal_pos == -220


def test_rosparam_partner_values_that_differ_give_a_warning():
    text = (ROOT / "configs/seed-d1.yaml").read_text()
    text = text.replace("diffdrive: 1, pos_min_dd: -1500", "diffdrive: 1, pos_min_dd: -1400")
    cfg = load_config_text(text, "d1.yaml")
    assert cfg.joints["joint2"].pos_min == -1500  # the lower node wins
    assert any("disagree on pos_min_dd" in w for w in cfg.warnings)


def test_sherpa_arm_describes_the_whole_arm():
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    assert list(cfg.buses) == ["can0", "can1", "can2"]
    assert all(b.interface == "socketcan" and b.bitrate == 1_000_000 for b in cfg.buses.values())
    assert list(cfg.drives) == ["shoulder_1a", "shoulder_1b", "shoulder_2a", "shoulder_2b", "shoulder_3a",
                                "shoulder_3b", "elbow_1a", "elbow_1b", "wrist_1a", "wrist_1b", "wrist_2a",
                                "wrist_2b", "wrist_3a", "wrist_3b"]
    pair = cfg.pairs["shoulder_diff"]
    assert (pair.drive_a, pair.drive_b, pair.sigma, pair.delta) == ("shoulder_2a", "shoulder_2b", "shoulder_pitch",
                                                                    "shoulder_roll")
    pitch, roll = cfg.joints["shoulder_pitch"], cfg.joints["shoulder_roll"]
    assert sorted(s.input for s in pitch.switches + roll.switches) == [1, 2, 3, 4]
    assert all(s.kind is SwitchKind.STOP for s in pitch.switches + roll.switches)
    yaw = cfg.joints["shoulder_yaw"]
    assert [s.kind for s in yaw.switches] == [SwitchKind.HOME]
    assert all(cfg.joint_of_drive(d) or cfg.pair_of_drive(d) for d in cfg.drives)


def test_sherpa_arm_currents_pass_the_catalog_rule():
    # Seed 3.4: continuous <= min(motor, drive) continuous; peak <= drive peak and <= 75 % motor peak.
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    cat = builtin_catalog()
    checked = 0
    for drive in cfg.drives.values():
        joint, pair = cfg.joint_of_drive(drive.name), cfg.pair_of_drive(drive.name)
        cur = joint.current if joint else pair.current
        assert cur is not None
        dm = cat.drives[drive.model]
        assert cur.continuous <= dm.current_cont and cur.peak <= dm.current_peak
        if drive.motor:
            mm = cat.motors[drive.motor]
            assert cur.continuous <= mm.current_cont and cur.peak <= cat.peak_fraction * mm.current_peak
            checked += 1
    assert checked >= 5


def test_catalog_names_are_normalised():
    base = (ROOT / "configs/appendix-c/example1.yaml").read_text()
    text = base.replace("model: whistle-10/60, motor: tq-robodrive-50x14", "model: Whistle 10/60, motor: TQ-Robodrive-50x14")
    assert text != base
    drive = load_config_text(text, "x.yaml").drives["drive1"]
    assert (drive.model, drive.motor) == ("whistle-10/60", "tq-robodrive-50x14")


def test_yaml_merge_keys_and_defaults():
    text = """\
name: tiny
buses:
  can0:
drives:
  d1: {bus: can0, node: 5}
joints:
  d1:
    drive: d1
    cpr: 100
    range: &r {min: -10, max: 10}
    abs_encoder: {source: "drive:PY"}
"""
    cfg = load_config_text(text, "tiny.yaml")
    bus = cfg.buses["can0"]
    assert (bus.interface, bus.channel, bus.bitrate, bus.send_interval_us, bus.poll_interval_ms) == (None, None, None,
                                                                                                     1000, 10)
    j = cfg.joints["d1"]  # a joint may share its drive's name: they are the same thing
    assert (j.margin, j.overshoot, j.vel_limit, j.current, j.abs_encoder.offset) == (0, 0, None, None, 0)
    assert cfg.il_codes.stop == 21 and cfg.il_codes.home == 5
    assert any("no current limits" in w for w in cfg.warnings)
    assert any("no model" in w for w in cfg.warnings)


def test_unused_drive_is_a_warning_with_its_line():
    base = (ROOT / "configs/appendix-c/example1.yaml").read_text()
    text = base.replace("drives:\n", "drives:\n  spare: {bus: can0, node: 9, model: whistle-10/60}\n", 1)
    cfg = load_config_text(text, "x.yaml")
    line = text.splitlines().index("  spare: {bus: can0, node: 9, model: whistle-10/60}") + 1
    assert f"x.yaml:{line}: drives.spare: drive 'spare' moves no joint or pair" in cfg.warnings


def test_load_config_missing_file(tmp_path):
    from sherpa_cli.errors import ConfigError

    with pytest.raises(ConfigError) as exc:
        load_config(tmp_path / "nope.yaml")
    assert "nope.yaml" in str(exc.value) and "not found" in str(exc.value)
    assert exc.value.exit_code == 2
