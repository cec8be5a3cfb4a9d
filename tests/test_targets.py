"""The one target policy (sherpa_cli.bus.targets): a test per kind of name, then the commands using it."""

from __future__ import annotations

import pytest

from sherpa_cli.bus import targets
from sherpa_cli.bus.targets import TargetKind
from sherpa_cli.config import load_config
from sherpa_cli.errors import ExitCode, UsageError

ARM = "configs/sherpa-arm.yaml"


@pytest.fixture(scope="module")
def cfg():
    from pathlib import Path

    return load_config(Path(__file__).resolve().parent.parent / ARM)


def names(refs) -> list[str]:
    return [r.name for r in refs]


# --------------------------------------------------------------------------- one per kind of name

def test_drive_name(cfg):
    t = targets.resolve_one(cfg, "elbow_1a")
    assert t.kind is TargetKind.DRIVE and t.text == "elbow_1a"
    assert [(r.name, r.bus, r.node) for r in t.drives] == [("elbow_1a", "can1", 40)]
    assert t.drives[0].config is cfg.drives["elbow_1a"]
    assert t.joint_names == ("elbow_pitch",) and t.pair is None
    assert targets.single_drive(cfg, "elbow_1a") == t.drives[0]


def test_pair_motor_moves_both_pair_joints(cfg):
    t = targets.resolve_one(cfg, "shoulder_2b")
    assert t.kind is TargetKind.DRIVE and t.drive_names == ("shoulder_2b",)
    assert t.joint_names == ("shoulder_pitch", "shoulder_roll") and t.pair.name == "shoulder_diff"


def test_plain_joint(cfg):
    t = targets.resolve_one(cfg, "shoulder_yaw")
    assert t.kind is TargetKind.JOINT and t.drive_names == ("shoulder_1a",)
    assert t.joint_names == ("shoulder_yaw",) and t.pair is None
    assert targets.single_drive(cfg, "shoulder_yaw").name == "shoulder_1a"


@pytest.mark.parametrize("joint", ["shoulder_pitch", "shoulder_roll"])
def test_sigma_and_delta_joints_name_both_motors(cfg, joint):
    t = targets.resolve_one(cfg, joint)
    assert t.kind is TargetKind.JOINT
    assert t.drive_names == ("shoulder_2a", "shoulder_2b")  # config order
    assert t.joint_names == (joint,) and t.pair is cfg.pairs["shoulder_diff"]
    with pytest.raises(UsageError) as info:
        targets.single_drive(cfg, joint)
    assert info.value.message == f"'{joint}' is moved by two drives (shoulder_2a, shoulder_2b); name one of them"


def test_pair(cfg):
    t = targets.resolve_one(cfg, "shoulder_diff")
    assert t.kind is TargetKind.PAIR and t.drive_names == ("shoulder_2a", "shoulder_2b")
    assert t.joint_names == ("shoulder_pitch", "shoulder_roll")
    assert targets.pair_of(cfg, "shoulder_diff") is targets.pair_of(cfg, "shoulder_2a") is cfg.pairs["shoulder_diff"]
    with pytest.raises(UsageError, match="moved by two drives"):
        targets.single_drive(cfg, "shoulder_diff")
    with pytest.raises(UsageError, match="'elbow_pitch' is not part of a differential pair") as info:
        targets.pair_of(cfg, "elbow_pitch")
    assert info.value.hint == "pairs of the config: shoulder_diff"


def test_configured_bus_node(cfg):
    t = targets.resolve_one(cfg, "can0:21")
    assert t.kind is TargetKind.ADDRESS and t.text == "can0:21"
    assert t.drives[0].name == "shoulder_2b" and t.drives[0].config is cfg.drives["shoulder_2b"]
    assert t.pair.name == "shoulder_diff" and t.configured


def test_unconfigured_bus_node(cfg):
    t = targets.resolve_one(cfg, "can2:99")
    assert t.kind is TargetKind.ADDRESS and not t.configured and t.joints == () and t.pair is None
    ref = t.drives[0]
    assert (ref.name, ref.bus, ref.node, ref.config, ref.address) == ("can2:99", "can2", 99, None, "can2:99")
    assert targets.single_drive(cfg, "can2:99") == ref
    assert targets.drive_refs(cfg, ["can2:99"]) == [ref]  # monitor and cmd take ad-hoc drives
    with pytest.raises(UsageError) as info:  # commands over configured drives do not
        targets.drive_names(cfg, ["can2:99"])
    assert info.value.message == "target 'can2:99': no configured drive at can2:99"


def test_unknown_name_with_did_you_mean(cfg):
    with pytest.raises(UsageError) as info:
        targets.resolve(cfg, ["elbow_1a", "shoulder_1"])
    assert info.value.message == "unknown target 'shoulder_1': not a drive, joint, pair or BUS:NODE of the config"
    assert info.value.hint == "did you mean shoulder_1b, shoulder_1a or shoulder_3b?"
    assert info.value.exit_code == ExitCode.USAGE


def test_unknown_name_without_a_close_one(cfg):
    with pytest.raises(UsageError) as info:
        targets.resolve_one(cfg, "xyzzy")
    assert info.value.hint == "see `sherpa config check` for the names"


def test_bad_bus(cfg):
    with pytest.raises(UsageError) as info:
        targets.resolve_one(cfg, "can7:10")
    assert info.value.message == "target 'can7:10': no bus 'can7' in the config"
    assert info.value.hint == "configured buses: can0, can1, can2"


@pytest.mark.parametrize("text", ["can0:0", "can0:128", "can0:x", "can0:", "can0:-1"])
def test_bad_node_id(cfg, text):
    with pytest.raises(UsageError) as info:
        targets.resolve_one(cfg, text)
    assert info.value.message == f"target '{text}': node id must be 1..127"


# --------------------------------------------------------------------------- lists

def test_default_is_every_configured_drive(cfg):
    assert names(targets.drive_refs(cfg, None)) == list(cfg.drives)
    assert targets.drive_names(cfg, []) == list(cfg.drives)
    assert all(t.kind is TargetKind.DRIVE for t in targets.resolve(cfg, None))


def test_no_repeats_in_the_order_asked(cfg):
    asked = ["elbow_pitch", "shoulder_roll", "shoulder_2a", "can1:40", "shoulder_diff", "elbow_1a"]
    assert names(targets.drive_refs(cfg, asked)) == ["elbow_1a", "shoulder_2a", "shoulder_2b"]
    assert targets.drive_names(cfg, asked) == ["elbow_1a", "shoulder_2a", "shoulder_2b"]
    # names meaning the same drives and joints are one target (the first name given) ...
    found = targets.resolve(cfg, ["elbow_pitch", "elbow_pitch", "elbow_1a", "can1:40"])
    assert [(t.text, t.kind) for t in found] == [("elbow_pitch", TargetKind.JOINT)]
    # ... a pair motor and a Σ joint are not: the motor moves both joints, the Σ joint one
    found = targets.resolve(cfg, ["shoulder_2a", "shoulder_pitch", "shoulder_diff"])
    assert [t.kind for t in found] == [TargetKind.DRIVE, TargetKind.JOINT, TargetKind.PAIR]


def test_every_name_is_checked_before_any_is_returned(cfg):
    with pytest.raises(UsageError, match="no bus 'can9'"):
        targets.drive_refs(cfg, ["elbow_pitch", "can9:1"])


def test_a_joint_without_drive_is_named(cfg):
    import dataclasses

    bad = dataclasses.replace(cfg, joints={**cfg.joints, "spare": dataclasses.replace(
        cfg.joints["elbow_pitch"], name="spare", drive=None)})
    with pytest.raises(UsageError, match="joint 'spare' has no drive in the config"):
        targets.resolve_one(bad, "spare")


# --------------------------------------------------------------------------- every command uses it

@pytest.mark.parametrize("argv", [
    ["cmd", "shoulder_1", "PX"],
    ["monitor", "--once", "shoulder_1"],
    ["identify", "shoulder_1"],
    ["dump-params", "shoulder_1"],
    ["params", "diff", "config", "-t", "shoulder_1"],
    ["limits", "show", "shoulder_1"],
    ["program-limits", "shoulder_1"],
    ["diffdrive", "limits", "shoulder_1"],
])
def test_every_command_words_an_unknown_name_alike(cli, argv):
    r = cli("--sim", *argv)
    assert r.exit_code == 2 and r.stdout == ""
    assert r.stderr == ("error: unknown target 'shoulder_1': not a drive, joint, pair or BUS:NODE of the config\n"
                        "hint: did you mean shoulder_1b, shoulder_1a or shoulder_3b?\n")


@pytest.mark.parametrize("argv", [
    ["identify", "can0:99"],
    ["dump-params", "can0:99"],
    ["limits", "show", "can0:99"],
    ["program-limits", "can0:99"],
])
def test_configured_drive_commands_refuse_an_empty_address(cli, argv):
    r = cli("--sim", *argv)
    assert r.exit_code == 2 and "target 'can0:99': no configured drive at can0:99" in r.stderr


def test_limits_show_takes_a_bus_node(cli):
    by_address = cli("--json", "limits", "show", "can0:20")
    by_name = cli("--json", "limits", "show", "shoulder_2a")
    assert by_address.exit_code == 0 and by_address.stdout == by_name.stdout


def test_limits_show_of_a_sigma_joint_shows_both_motors(cli):
    import json

    r = cli("--json", "limits", "show", "shoulder_pitch")
    assert [d["drive"] for d in json.loads(r.stdout)["drives"]] == ["shoulder_2a", "shoulder_2b"]
