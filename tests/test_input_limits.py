"""Parsers with limits and damaged state files.

YAML inputs (configs, recipes, parameter dumps) refuse alias bombs, deep nesting, numbers of
thousands of digits and files above the size cap, each with one located message. A damaged
save ledger or simulator state file is reported with its path and a way out; an unwritable
state directory fails with one message and leaves the old file as it was.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import pytest

from sherpa_cli.config import load_config, load_config_text
from sherpa_cli.config.yamlnodes import MAX_DEPTH, MAX_INPUT_BYTES, parse_yaml
from sherpa_cli.errors import ConfigError, SherpaError

ROOT = Path(__file__).resolve().parent.parent


def laughs(levels: int = 9) -> str:
    text = "a: &a [x, x, x, x, x, x, x, x, x, x]\n"
    for i in range(1, levels):
        prev, name = chr(96 + i), chr(97 + i)
        text += f"{name}: &{name} [{', '.join(['*' + prev] * 10)}]\n"
    return text


@pytest.mark.parametrize("text, message", [
    (laughs(), "expands to more than 50,000 values"),
    ("a: &a [*a]\n", "recursive alias"),
    ("a: " + "[" * 2000 + "]" * 2000 + "\n", f"nesting deeper than {MAX_DEPTH} levels"),
    ("".join("  " * i + f"k{i}:\n" for i in range(40)) + "  " * 40 + "v: 1\n", "nesting deeper"),
    ("a: " + "9" * 5000 + "\n", "has 5000 characters"),
    ("a: -" + "1" * 5000 + ".5\n", "has 5003 characters"),
    ("? " + "7" * 5000 + "\n: 1\n", "is a number of 5000 characters"),
])
def test_hostile_yaml_is_refused_with_one_located_message(text, message):
    with pytest.raises(ConfigError) as info:
        parse_yaml(text, "bad.yaml")
    assert message in str(info.value) and str(info.value).startswith("bad.yaml")


def test_merge_keys_within_the_cap_still_work():
    root = parse_yaml("base: &b {x: 1}\nother: {<<: *b, y: 2}\n", "ok.yaml")
    assert sorted(root.value["other"].value) == ["x", "y"]


def test_input_files_have_a_size_cap(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_text("# padding\n" * (MAX_INPUT_BYTES // 10 + 1))
    with pytest.raises(ConfigError, match="larger than 1024 KiB"):
        load_config(big)


def test_a_device_is_cut_off_at_the_cap():
    with pytest.raises(ConfigError, match="larger than"):
        load_config("/dev/zero")


def test_non_finite_numbers_in_yaml_reach_validation_not_a_traceback():
    text = (ROOT / "configs/appendix-c/example1.yaml").read_text()
    with pytest.raises(ConfigError):
        load_config_text(text + "protocol: {reply_timeout: .inf}\n", "x.yaml")


# -- state files --------------------------------------------------------------------------------

@pytest.fixture
def state(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    return tmp_path / "state" / "sherpa-cli"


@pytest.mark.parametrize("content, problem", [
    ("[[[", "is not a valid ledger"),
    ('{"format": 1, "drives": {"0x5A00010A": {"saves": "many"}}}', "entry '0x5A00010A' is damaged"),
    ('{"format": 7, "drives": {}}', "has format 7"),
    ('[1, 2]', "is not a save ledger"),
    ("\udcff", "is not a valid ledger"),
])
def test_damaged_ledger_is_reported_with_path_and_way_out_before_any_write(cli, state, content, problem):
    state.mkdir(parents=True)
    ledger = state / "save-ledger.json"
    ledger.write_bytes(content.encode("utf-8", "surrogateescape"))
    result = cli("--sim", "program-limits", "elbow_pitch", "--apply")
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr
    assert str(ledger) in result.stderr and problem in result.stderr and "move it aside" in result.stderr
    assert "written" not in result.stdout.lower() or "nothing" in result.stdout.lower()
    assert ledger.read_bytes() == content.encode("utf-8", "surrogateescape")  # left for a look


@pytest.mark.parametrize("content, problem", [
    ("{", "is damaged"),
    ('{"format": 1, "drives": {"shoulder_1a": {"serial": "x"}}}', "serial \"x\" is not an integer"),
    ('{"format": 1, "drives": {"shoulder_1a": {"flash": {"AC": "fast"}}}}', "flash key 'AC'"),
    ('{"format": 1, "drives": {"shoulder_1a": {"flash": {"0x1017:0": 70000}}}}', "flash key '0x1017:0'"),
    ('{"format": 1, "drives": {"shoulder_1a": {"flash": {"QQ": 1}}}}', "flash key 'QQ'"),
    ('{"format": 1, "drives": []}', "is not a simulator state file"),
    ('{"format": 1, "drives": {"shoulder_1a": 5}}', "expected a mapping"),
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
])
def test_damaged_sim_state_is_reported_with_path_and_way_out(cli, state, content, problem):
    assert cli("--sim", "cmd", "shoulder_1a", "AC=150000", "SV", "--apply", "--raw-save").exit_code == 0
    (path,) = [p for p in (state / "sim").glob("*.json") if not p.name.endswith(".ram.json")]  # the flash file
    path.write_text(content)
    result = cli("--sim", "cmd", "shoulder_1a", "AC")
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr
    assert str(path) in result.stderr and problem in result.stderr
    assert "move it aside" in result.stderr and "--reset-state" in result.stderr


def test_unwritable_sim_state_fails_with_one_message_and_keeps_the_old_file(tmp_path):
    from sherpa_cli.sim import state as sim_state

    cfg = load_config(ROOT / "configs/appendix-c/example1.yaml")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    flash = sim_state.load(cfg, blocker / "sim.json")  # a missing file: factory state
    with pytest.raises(SherpaError) as info:
        sim_state.save(cfg, flash, blocker / "sim.json")
    assert "cannot save the simulated drives' flash" in str(info.value) and "unchanged" in info.value.hint
    good = tmp_path / "sim.json"
    sim_state.save(cfg, flash, good)
    before = good.read_text()
    good.parent.chmod(0o500)
    try:
        # unwritable (not as root): one message; root may write, that is fine too
        with contextlib.suppress(SherpaError):
            sim_state.save(cfg, {k: v for k, v in flash.items()}, good)
        assert json.loads(good.read_text()) == json.loads(before)
        assert [p.name for p in good.parent.iterdir() if p.name.startswith(".sim.json.")] == []
    finally:
        good.parent.chmod(0o700)


# -- every number has a range (item 5) ------------------------------------------------------------

EXAMPLE1 = (ROOT / "configs/appendix-c/example1.yaml").read_text()


@pytest.mark.parametrize("old, new, path, phrase", [
    ("velocity: {limit: 100, trip: 150}", "velocity: {limit: 100, trip: .inf}", "joints.joint1.velocity.trip",
     "expected an integer"),
    ("current: {continuous: 3.0, peak: 12.0, peak_time: 2}", "current: {continuous: .nan, peak: 12.0, peak_time: 2}",
     "joints.joint1.current.continuous", "is not a finite number"),
    ("current: {continuous: 3.0, peak: 12.0, peak_time: 2}", "current: {continuous: 3.0, peak: 12.0, peak_time: 61}",
     "joints.joint1.current.peak_time", "expected 0..60 s (PL[2])"),
    ("current: {continuous: 3.0, peak: 12.0, peak_time: 2}", "current: {continuous: 3.0, peak: .inf, peak_time: 2}",
     "joints.joint1.current.peak", "is not a finite number"),
    ("range: {min: -220, max: 220, margin: 30, overshoot: 20}",
     "range: {min: -220, max: 2147483648, margin: 30, overshoot: 20}", "joints.joint1.range.max", "32-bit integer"),
    ("range: {min: -220, max: 220, margin: 30, overshoot: 20}",
     "range: {min: -220, max: 2147483640, margin: 30, overshoot: 20}", "joints.joint1.range.overshoot",
     "does not fit the drive's 32-bit"),
    ("acceleration: {accel: 500, decel: 500}", "acceleration: {accel: 500, decel: 4294967296}",
     "joints.joint1.acceleration.decel", "expected 1..2147483647"),
    ("cpr: 600", "cpr: 99999999999", "joints.joint1.cpr", "expected 1..2147483647"),
    ("bitrate: 1000000}", "bitrate: 2000000}", "buses.can0.bitrate", "expected 1..1000000 bit/s"),
])
def test_out_of_range_numbers_are_refused_with_file_line_and_key(old, new, path, phrase):
    assert old in EXAMPLE1
    with pytest.raises(ConfigError) as info:
        load_config_text(EXAMPLE1.replace(old, new), "ex1.yaml")
    assert info.value.location.path == path, str(info.value)
    assert info.value.location.line is not None and phrase in str(info.value)


@pytest.mark.parametrize("extra, path, phrase", [
    ("protocol: {reply_timeout: .inf}\n", "protocol.reply_timeout", "expected 0..60 s"),
    ("protocol: {mo_settle: .nan}\n", "protocol.mo_settle", "is not a finite number"),
    ("protocol: {sv_blackout: 1000000000.0}\n", "protocol.sv_blackout", "expected 0..60 s"),
    ("protocol: {sdo_timeout: .nan}\n", "protocol.sdo_timeout", "must be > 0"),
    ("protocol: {retries: 1000000}\n", "protocol.retries", "expected 0..100"),
    ("il_codes: {stop: 24, home: 5}\n", "il_codes.stop", "expected 0..23"),
    ("sim: {drives: {drive1: {heartbeat_ms: 70000}}}\n", "sim.drives.drive1.heartbeat_ms", "u16"),
    ("sim: {drives: {drive1: {reply_latency: .inf}}}\n", "sim.drives.drive1.reply_latency", "expected 0..60 s"),
    ("sim: {drives: {drive1: {die_at: .nan}}}\n", "sim.drives.drive1.die_at", "is not a finite number"),
    ("catalog: {peak_fraction: .nan}\n", "catalog.peak_fraction", "must be above 0"),
])
def test_out_of_range_settings_are_refused(extra, path, phrase):
    with pytest.raises(ConfigError) as info:
        load_config_text(EXAMPLE1 + extra, "ex1.yaml")
    assert info.value.location.path == path, str(info.value)
    assert phrase in str(info.value)


def test_config_check_fails_where_program_limits_would_refuse(cli, tmp_path):
    bad = tmp_path / "ex1.yaml"
    bad.write_text(EXAMPLE1.replace("peak_time: 2}", "peak_time: 1.5}"))
    check = cli("config", "check", str(bad))
    assert check.exit_code == 1 and "PL[2]" in check.stdout, check.transcript()
    plan = cli("--config", str(bad), "--sim", "program-limits")
    assert plan.exit_code != 0 and "Traceback" not in plan.stderr
