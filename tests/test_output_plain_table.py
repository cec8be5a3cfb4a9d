"""cli/output.py plain_table: the text rich prints for make_table (no title, no colour), byte for byte,
on random tables; and None wherever rich must lay the table out itself."""

from __future__ import annotations

import io
import random

import pytest

from sherpa_cli.cli.output import make_table, plain_table

WORDS = ["AC", "IL[1]", "100000", "1.5", "-", "yes", "", "not written", "shoulder_yaw", "0.001", "-42", "VH[3]"]


def _rich(columns, rows, right, width) -> str:
    from rich.console import Console

    buf = io.StringIO()
    console = Console(file=buf, width=width, no_color=True, color_system=None, highlight=False, soft_wrap=False,
                      emoji=False)
    console.print(make_table(None, columns, rows, right=right, width=width))
    return buf.getvalue()


@pytest.mark.parametrize("seed", range(40))
def test_plain_table_is_what_rich_prints(seed):
    rnd = random.Random(seed)
    ncols = rnd.randint(1, 6)
    columns = [rnd.choice(["param", "now", "target", "change", "order", "a", "value (counts)"]) for _ in range(ncols)]
    rows = [[rnd.choice(WORDS) if rnd.random() < 0.9 else rnd.randint(-5, 500) for _ in range(ncols)]
            for _ in range(rnd.randint(0, 6))]
    right = [i for i in range(ncols) if rnd.random() < 0.5]
    width = rnd.choice([100, 10_000])
    text = plain_table(columns, rows, right=right, width=width)
    assert text is not None
    assert text == _rich(columns, rows, right, width)


@pytest.mark.parametrize("cell", ["[bold]x", "a\\b", "é", "tab\there", "two\nlines"])
def test_rich_lays_out_what_it_would_parse_or_measure_differently(cell):
    assert plain_table(["a", "b"], [["x", cell]], width=100) is None


def test_a_table_wider_than_the_output_is_left_to_rich():
    assert plain_table(["param"], [["x" * 40]], width=30) is None
    assert plain_table(["param"], [["x" * 40]], width=44) is not None
