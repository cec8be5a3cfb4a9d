"""cli/output.py: a table's title is one line, whether stdout is a pipe or a terminal narrower than it."""

from __future__ import annotations

import io

import pytest

from sherpa_cli.cli.output import Output

TITLE = "Motor speed and acceleration (both motors)"


def _print_table(monkeypatch: pytest.MonkeyPatch, title: str) -> list[str]:
    buf = io.StringIO()  # not a terminal: the piped layout
    monkeypatch.setattr("sys.stdout", buf)
    Output.create(no_color=True).table(title, ["limit", "value"], [["AC (counts/s²)", 1000]], right=(1,))
    return buf.getvalue().splitlines()


def test_a_title_wider_than_its_table_is_not_wrapped_when_piped(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    lines = _print_table(monkeypatch, TITLE)
    assert lines[0] == TITLE
    assert lines[1].strip() == ""  # the table follows at once: no second title line
    assert len(lines[2]) < len(TITLE)  # the table kept its own width


def test_a_title_wider_than_the_terminal_is_not_cut_off(monkeypatch):
    monkeypatch.setenv("COLUMNS", "30")
    assert _print_table(monkeypatch, TITLE)[0].startswith(TITLE)


def test_a_short_title_is_padded_to_the_table_as_before(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    lines = _print_table(monkeypatch, "limits")
    assert lines[0].rstrip() == "limits"
    assert len(lines[0]) == len(lines[1])
