"""Empty is a normal case: every table renders with zero rows.

A table with no rows crashed the renderer (``max()`` of a single int in ``fit_columns``); configs
whose sections end up empty through YAML tags (``!foo``, ``!!set``) or merge keys reached it.
"""

from __future__ import annotations

import json

import pytest
from rich.console import Console

from sherpa_cli.cli.output import Output, fit_columns, make_table

COLUMNS = ["drive", "bus:node", "would write", "would save", "problems"]


@pytest.mark.parametrize("width", [100, 40, 12, 1])
@pytest.mark.parametrize("title", ["plan", None])
def test_make_table_renders_zero_rows_at_any_width(width, title):
    table = make_table(title, COLUMNS, [], right=(1, 3), drop=(4, 2), width=width)
    console = Console(width=max(width, 20), file=None, color_system=None, record=True)
    with console.capture() as captured:
        console.print(table)
    assert "drive" in captured.get()  # the header is still shown
    assert table.row_count == 0


def test_fit_columns_with_no_rows_keeps_what_the_headers_need():
    assert fit_columns(COLUMNS, [], 100) == [0, 1, 2, 3, 4]
    assert fit_columns(COLUMNS, [], 20)[0] == 0
    assert fit_columns(["only"], [], 1) == [0]


@pytest.mark.parametrize("json_mode", [False, True], ids=["text", "json"])
def test_output_table_with_zero_rows(capsys, monkeypatch, json_mode):
    monkeypatch.setenv("COLUMNS", "100")
    out = Output.create(json_mode=json_mode, no_color=True)
    out.table("Drives", COLUMNS, iter(()))
    out.table(None, ["", "name"], [])
    captured = capsys.readouterr()
    assert "Drives" in captured.out and "would write" in captured.out and captured.err == ""


NONE_BY_TAG = "name: x\nbuses: {can0: {interface: virtual, channel: a}}\ndrives: !foo {}\njoints: !foo {}\n"
NONE_BY_SET = "name: x\nbuses: !!set {can0}\ndrives: !!set {}\njoints: {}\n"
NONE_BY_MERGE = ("name: x\nbuses: {can0: {interface: virtual, channel: a}}\ndrives: &none {}\n"
                 "joints: {<<: *none}\n")
CONFIGS = {"tag !foo": NONE_BY_TAG, "tag !!set": NONE_BY_SET, "merge key": NONE_BY_MERGE}


@pytest.mark.parametrize("argv, header", [
    (["config", "check", "{path}"], "full range"),
    (["--json", "config", "check", "{path}"], '"drives": []'),
    (["--config", "{path}", "limits", "show"], ""),
    (["--json", "--config", "{path}", "limits", "show"], '"drives": []'),
    (["--sim", "--config", "{path}", "scan"], "verdict"),
    (["--json", "--sim", "--config", "{path}", "scan"], '"nodes": []'),
    (["--sim", "--config", "{path}", "stop"], "stopped by"),
    (["--json", "--sim", "--config", "{path}", "stop"], '"drives": []'),
    (["--sim", "--config", "{path}", "monitor", "--once"], ""),
    (["--sim", "--config", "{path}", "identify"], "0 of 0"),
    (["--sim", "--config", "{path}", "commission"], "would write"),
    (["--sim", "--config", "{path}", "program-limits"], "nothing to change"),
], ids=lambda v: " ".join(v) if isinstance(v, list) else None)
@pytest.mark.parametrize("config", CONFIGS.values(), ids=CONFIGS.keys())
def test_configs_with_empty_sections_render_or_refuse_in_one_line(cli, tmp_path, config, argv, header):
    path = tmp_path / "empty.yaml"
    path.write_text(config)
    result = cli(*(a.format(path=path) for a in argv))
    assert "Traceback" not in result.stderr and "Error" not in result.stderr, result.transcript()
    assert result.exit_code in (0, 1, 2), result.transcript()
    if result.exit_code == 2:  # refused: one located line
        assert [ln for ln in result.stderr.splitlines() if ln.startswith("error:")] == \
            [result.stderr.splitlines()[0]], result.transcript()
    else:
        assert header in result.stdout, result.transcript()
        if "--json" in argv:
            json.loads(result.stdout)
