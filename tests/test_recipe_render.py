"""A recipe step's results are rendered only when someone sees or reads them
(--verbose, --report/--junit, --json, an expectation on stdout); otherwise no table is laid out."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sherpa_cli.cli import output

RECIPE = "steps:\n  - {name: limits, run: limits show elbow_pitch}\n"


@pytest.fixture
def tables(monkeypatch):
    drawn: list[str | None] = []
    real = output.make_table

    def counting(title, *args, **kwargs):
        drawn.append(title)
        return real(title, *args, **kwargs)

    monkeypatch.setattr(output, "make_table", counting)
    return drawn


def _recipe(tmp_path: Path, text: str = RECIPE) -> str:
    path = tmp_path / "r.yaml"
    path.write_text(text, encoding="utf-8")
    return str(path)


def test_a_step_nobody_reads_draws_no_table(cli, tmp_path, tables):
    r = cli("recipe", "run", _recipe(tmp_path))
    assert r.exit_code == 0, r.stderr
    assert "[1/1] limits  passed" in r.stdout
    assert tables == []


def test_verbose_shows_the_steps_table(cli, tmp_path, tables):
    r = cli("recipe", "run", _recipe(tmp_path), "--verbose")
    assert r.exit_code == 0, r.stderr
    assert tables and "elbow_pitch" in r.stdout


def test_a_report_stores_the_steps_output(cli, tmp_path, tables):
    report = tmp_path / "rep.json"
    r = cli("recipe", "run", _recipe(tmp_path), "--report", str(report))
    assert r.exit_code == 0, r.stderr
    step = json.loads(report.read_text(encoding="utf-8"))["steps"][0]
    assert "elbow_pitch" in step["stdout"] and tables


def test_an_expectation_on_stdout_still_sees_it(cli, tmp_path, tables):
    text = "steps:\n  - {name: limits, run: limits show elbow_pitch, expect: {stdout_contains: [elbow_pitch]}}\n"
    r = cli("recipe", "run", _recipe(tmp_path, text))
    assert r.exit_code == 0, r.stdout + r.stderr
    assert tables


def test_checking_a_recipe_leaves_the_shared_command_tree_as_it_was(cli, tmp_path):
    """The recipe check parses each step on the command tree `run` uses (built once per process);
    click keeps the first help option it makes for a command, so the check must not change it."""
    text = "steps:\n  - {run: program-limits elbow_pitch}\n  - {run: log record elbow_pitch --for 1 -o x.csv}\n"
    r = cli("recipe", "check", _recipe(tmp_path, text))
    assert r.exit_code == 0, r.stdout + r.stderr
    for argv in (["program-limits", "--help"], ["log", "record", "--help"]):
        assert "-h, --help" in cli(*argv).stdout, argv
