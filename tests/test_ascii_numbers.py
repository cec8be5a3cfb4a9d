"""Numbers are ASCII: Python's float() and int() read the digits of every script
(a fullwidth 3 is 3, Arabic-Indic 12 is 12), so `--to` with a fullwidth 3 moved a joint by 3 rad. Every number parser of the CLI
(the boundary, typer's options, units, raw commands, targets, recipes, recordings) and of the
config refuses them with one message; nothing is sent."""

from __future__ import annotations

from pathlib import Path

import pytest

from sherpa_cli.cli.boundary import refuse_non_ascii_numbers
from sherpa_cli.config import load_config, load_config_text
from sherpa_cli.config.yamlnodes import parse_yaml
from sherpa_cli.elmo.codec import parse_expr
from sherpa_cli.errors import ConfigError, SherpaError, UsageError
from sherpa_cli.joints.units import parse_current, parse_position, parse_velocity

ROOT = Path(__file__).resolve().parent.parent
FULLWIDTH_3 = "\uff13"  # FULLWIDTH DIGIT THREE
ARABIC_12 = "\u0661\u0662"  # ARABIC-INDIC 1 and 2
DEVANAGARI_5 = "\u096b"  # ५
WEIRD = [FULLWIDTH_3, ARABIC_12, DEVANAGARI_5, f"{FULLWIDTH_3}.5", f"1e{FULLWIDTH_3}", f"-{ARABIC_12}"]


@pytest.mark.parametrize("text", WEIRD)
def test_python_would_read_these_as_numbers(text):
    float(text)  # the reason for all of this: no ValueError


@pytest.mark.parametrize("text", [*WEIRD, f"{FULLWIDTH_3}deg", f"{FULLWIDTH_3}counts"])
def test_unit_parsers_refuse_non_ascii_digits(text):
    with pytest.raises(UsageError, match="ASCII digits"):
        parse_position(text, 3600)
    with pytest.raises(UsageError, match="ASCII digits"):
        parse_velocity(text + "/s" if text.endswith("deg") else text, 3600)
    with pytest.raises(UsageError, match="ASCII digits"):
        parse_current(text.removesuffix("deg").removesuffix("counts") + "A")


@pytest.mark.parametrize("text", [f"AC={FULLWIDTH_3}", f"CL[1]={FULLWIDTH_3}.5", f"SP={ARABIC_12}",
                                  f"AC=1{DEVANAGARI_5}0"])
def test_raw_commands_refuse_non_ascii_digits(text):
    with pytest.raises(SherpaError, match="ASCII digits"):
        parse_expr(text)


def test_raw_command_index_stays_refused():
    with pytest.raises(SherpaError, match="decimal number"):
        parse_expr(f"LL[{FULLWIDTH_3}]")


@pytest.mark.parametrize("text", [f"a: !!int {FULLWIDTH_3}\n", f"a: !!float {FULLWIDTH_3}.5\n",
                                  f"? !!int {ARABIC_12}\n: 1\n"])
def test_yaml_tagged_numbers_refuse_non_ascii_digits(text):
    with pytest.raises(ConfigError, match="ASCII digits") as info:
        parse_yaml(text, "n.yaml")
    assert str(info.value).startswith("n.yaml:")


def test_yaml_untagged_non_ascii_digits_are_strings_not_numbers():
    text = (ROOT / "configs/appendix-c/example1.yaml").read_text().replace("cpr: 600", f"cpr: 6{FULLWIDTH_3}0")
    with pytest.raises(ConfigError, match="expected an integer"):
        load_config_text(text, "x.yaml")


def test_rosparam_node_keys_are_ascii_digits():
    text = (ROOT / "configs/seed-d1.yaml").read_text().replace("'0': {", f"'{FULLWIDTH_3}': {{", 1)
    with pytest.raises(ConfigError, match="is not a node number"):
        load_config_text(text, "seed.yaml")


def test_bus_node_targets_are_ascii_digits():
    from sherpa_cli.bus.targets import resolve_one

    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    with pytest.raises(UsageError, match="node id must be"):
        resolve_one(cfg, f"can0:{ARABIC_12}")


def test_recorded_files_are_read_with_ascii_digits_only(tmp_path):
    from sherpa_cli.log.candecode import parse_candump_line
    from sherpa_cli.log.recording import _read_csv

    with pytest.raises(ValueError, match="ASCII"):
        parse_candump_line(f"(1600000000.{FULLWIDTH_3}) can0 123#00", "x.log:1")
    with pytest.raises(ValueError, match="ASCII"):
        parse_candump_line(f"(1600000000.0) can0 1{ARABIC_12}#00", "x.log:1")
    path = tmp_path / "r.csv"
    path.write_text(f"time_s,a.px\n0,1\n0.1,{FULLWIDTH_3}\n", encoding="utf-8")
    with pytest.raises(UsageError, match=r"r\.csv:3: .*ASCII"):
        _read_csv(path)


@pytest.mark.parametrize("argv, named", [
    (["jog", "j", "--to", FULLWIDTH_3], "--to"),
    (["jog", "j", f"--to={FULLWIDTH_3}deg"], "--to"),
    (["cmd", "d", f"AC={ARABIC_12}"], "AC"),
    (["recipe", "run", "r.yaml", "--set", f"n={FULLWIDTH_3}"], "n"),
    (["sim", "--duration", f"{DEVANAGARI_5}"], "--duration"),
    (["stop", FULLWIDTH_3], "argument"),
])
def test_the_boundary_refuses_number_shaped_arguments_naming_them(argv, named):
    with pytest.raises(UsageError) as info:
        refuse_non_ascii_numbers(argv)
    assert str(info.value).startswith(f"{named} '") and "ASCII digits 0-9" in str(info.value)


@pytest.mark.parametrize("argv", [["config", "check", f"configs/x{FULLWIDTH_3}.yaml"], ["--set", "name=Zoë"],
                                  ["jog", "j", "--to", "-0.5"], ["cmd", "d", "AC=150000"], ["stop", "café"]])
def test_names_and_ascii_numbers_pass_the_boundary(argv):
    refuse_non_ascii_numbers(argv)


@pytest.mark.parametrize("args", [
    ("--sim", "jog", "elbow_pitch", "--to", FULLWIDTH_3, "--apply"),
    ("--sim", "jog", "elbow_pitch", "--by", f"{FULLWIDTH_3}deg", "--apply"),
    ("--sim", "jog", "elbow_pitch", "--velocity", "0.1", "--for", FULLWIDTH_3, "--apply"),
    ("--sim", "jog", "elbow_pitch", "--torque", f"{FULLWIDTH_3}A", "--for", "0.1", "--apply"),
    ("--sim", "cmd", "shoulder_1a", f"AC={ARABIC_12}0000", "--apply"),
    ("--sim", "cmd", f"can0:{FULLWIDTH_3}", "PX"),
    ("--sim", "log", "record", "--rate", DEVANAGARI_5, "--for", "0.1"),
    ("sim", "--duration", FULLWIDTH_3),
    ("sim", "--serve", f"127.0.0.1:5470{FULLWIDTH_3}", "--duration", "0.1"),
])
def test_cli_refuses_non_ascii_digits_in_one_line_before_anything_is_sent(cli, args):
    result = cli(*args)
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and ("ASCII" in errors[0] or "node id" in errors[0] or "HOST:PORT" in errors[0]), \
        result.transcript()
    assert "moved" not in result.stdout and "sent" not in result.stdout.replace("nothing sent", "")


def test_recipe_check_and_run_refuse_a_step_with_non_ascii_digits(cli, tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text(f"name: r\nsteps:\n  - name: move\n    run: jog elbow_pitch --to {FULLWIDTH_3}\n",
                    encoding="utf-8")
    for args in (("recipe", "check", str(path)), ("--sim", "recipe", "run", str(path), "--apply", "--yes")):
        result = cli(*args)
        assert result.exit_code == 2, result.transcript()
        assert "Traceback" not in result.stderr and "ASCII digits" in result.stderr, result.transcript()
        assert f"{path}:3" in result.stderr, result.transcript()  # the step's line


def test_recipe_from_step_number_is_ascii(cli):
    result = cli("--sim", "recipe", "run", "recipes/backup.yaml", "--from", FULLWIDTH_3)
    assert result.exit_code == 2 and "Traceback" not in result.stderr, result.transcript()
