"""`type: elmo | cia402` under drives: (docs/config.md): loaded, dumped, checked by `config check`."""

from __future__ import annotations

from pathlib import Path

import pytest

from sherpa_cli.config import load_config, load_config_text
from sherpa_cli.config.dump import dump_native
from sherpa_cli.errors import ConfigError

EXAMPLE = Path(__file__).resolve().parent / "data" / "cia402-arm.yaml"
TEXT = EXAMPLE.read_text(encoding="utf-8")


def test_the_example_loads_with_one_cia402_drive():
    cfg = load_config(EXAMPLE)
    assert {name: d.type for name, d in cfg.drives.items()} == {
        "elbow": "elmo", "wrist": "cia402", "left": "elmo", "right": "elmo"}


def test_the_type_survives_a_dump_and_elmo_stays_implicit():
    text = dump_native(load_config(EXAMPLE))
    assert "type: cia402" in text and "type: elmo" not in text
    assert {n: d.type for n, d in load_config_text(text).drives.items()}["wrist"] == "cia402"


def test_an_unknown_type_is_refused_with_the_valid_ones():
    bad = TEXT.replace("wrist: {type: cia402,", "wrist: {type: canopen,")
    with pytest.raises(ConfigError) as err:
        load_config_text(bad, "arm.yaml")
    assert err.value.message == "arm.yaml:11: drives.wrist.type: drive 'wrist': unknown type 'canopen'; valid: elmo, cia402"


def test_a_cia402_drive_in_a_pair_is_refused():
    bad = TEXT.replace("left: {bus: can0,", "left: {type: cia402, bus: can0,")
    with pytest.raises(ConfigError) as err:
        load_config_text(bad, "arm.yaml")
    assert err.value.message == ("arm.yaml:12: drives.left.type: drive 'left' of differential pair 'diff' is a "
                                 "cia402 drive; a pair's synchronized start needs elmo drives")


def test_config_check_passes_the_example(cli):
    result = cli("--config", str(EXAMPLE), "config", "check")
    assert result.exit_code == 0, result.stderr
    assert "cia402-test -- valid" in result.stdout
