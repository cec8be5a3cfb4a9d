"""Shared options are declared once (sherpa_cli/cli/options.py) and read alike in every command."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import typer.main

CLI = Path(__file__).resolve().parent.parent / "sherpa_cli" / "cli"
SHARED = ("--apply", "--save", "--yes", "--motor-off", "--from", "--report", "--junit", "--quiet", "--set")


def test_no_command_module_declares_a_shared_flag_itself():
    for path in sorted(CLI.glob("*.py")):
        if path.name == "options.py":
            continue
        text = path.read_text(encoding="utf-8")
        for flag in SHARED:
            assert not re.search(rf'typer\.Option\([^)]*"{flag}"', text), f"{path.name} declares {flag}; use cli/options.py"


def _params(*path: str) -> dict[str, object]:
    from sherpa_cli.cli.app import app

    cmd = typer.main.get_command(app)
    for name in path:
        cmd = cmd.commands[name]  # type: ignore[attr-defined]
    return {p.name: p for p in cmd.params}


@pytest.mark.parametrize("option", ["apply", "save", "yes", "motor_off"])
def test_program_limits_and_params_restore_share_their_write_options(option):
    a, b = _params("program-limits")[option], _params("params", "restore")[option]
    assert a.opts == b.opts and a.secondary_opts == b.secondary_opts and a.help == b.help


def test_target_lists_read_alike():
    commands = [("identify",), ("dump-params",), ("monitor",), ("program-limits",), ("limits", "show")]
    args = [next(p for p in _params(*c).values() if p.param_type_name == "argument") for c in commands]
    assert {(a.metavar, a.help) for a in args} == {("[TARGET]...", "Drive, joint or pair names, or BUS:NODE; "
                                                   "default: every configured drive.")}


def test_recipe_commands_share_their_options():
    run, commission = _params("recipe", "run"), _params("commission")
    for option in ("yes", "start", "report", "junit", "quiet", "sets"):
        assert run[option].opts == commission[option].opts and run[option].help == commission[option].help
