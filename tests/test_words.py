"""sherpa_cli/words.py: counts in words, singular for one."""

from __future__ import annotations

import pytest

from sherpa_cli.words import plural


@pytest.mark.parametrize(("count", "noun", "nouns", "text"), [
    (0, "drive", None, "0 drives"),
    (1, "drive", None, "1 drive"),
    (2, "drive", None, "2 drives"),
    (1, "differential pair", None, "1 differential pair"),
    (3, "differential pair", None, "3 differential pairs"),
    (1, "bus", "buses", "1 bus"),
    (3, "bus", "buses", "3 buses"),
])
def test_plural(count, noun, nouns, text):
    assert plural(count, noun, nouns) == text


def test_one_drive_of_a_dump_is_singular(cli, tmp_path):
    result = cli("--sim", "dump-params", "-o", str(tmp_path / "one.yaml"), "elbow_1a")
    assert result.exit_code == 0, result.stderr
    assert result.stdout == f"wrote 1 drive to {tmp_path / 'one.yaml'}\n"
