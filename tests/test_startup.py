"""`sherpa --help` must stay fast: the CAN stack and rich load only in commands that use them."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT

HEAVY = ("can", "canopen", "rich", "yaml", "pyroute2")


def test_help_imports_no_heavy_module():
    code = (
        "import sys\n"
        "from sherpa_cli.cli.app import run\n"
        "rc = run(['--help'])\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules), rc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[] 0", out.stdout


def test_the_command_tree_is_built_once_per_process():
    from sherpa_cli.cli import app as _app  # noqa: F401  (installs the root)
    from sherpa_cli.cli.boundary import root_command

    assert root_command() is root_command()


#: what no `--help` may import: typer 0.29's pydantic adapters (pinned below 0.29 in pyproject.toml),
#: the CAN stack, rich, the plot, the full-screen view and the simulator
NOT_FOR_HELP = ("pydantic", "can", "canopen", "rich", "matplotlib", "textual", "sherpa_cli.sim",
                # the state files' lock and directory helpers, and the journal (~40 ms together)
                "filelock", "platformdirs", "sherpa_cli.bus.journal")


@pytest.mark.parametrize("argv", [["--help"], ["scan", "--help"], ["jog", "--help"], ["log", "record", "--help"],
                                  ["commission", "--help"]])
def test_help_imports_neither_pydantic_nor_anything_heavy(argv):
    code = (
        "import sys\n"
        "from sherpa_cli.cli.app import run\n"
        f"rc = run({argv!r})\n"
        f"print(sorted(m for m in {NOT_FOR_HELP!r} if m in sys.modules), rc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[] 0", out.stdout


#: what `sherpa --sim scan` never runs, so never imports (benchmark `scan`): the plot, the
#: full-screen view, the MCAP writer; the programming engine and the flash ledger (`sherpa_cli.api`
#: reaches `Arm` without them), the stop procedure, the motion core, recording, recipes, the
#: journal, and the preflight only recipes and moving commands run
NOT_FOR_SCAN = ("matplotlib", "textual", "mcap", "pydantic", "sherpa_cli.ops.program", "sherpa_cli.ops.save_ledger",
                "sherpa_cli.ops.stop", "sherpa_cli.motion", "sherpa_cli.log", "sherpa_cli.recipes",
                "sherpa_cli.bus.journal", "sherpa_cli.bus.health")


def test_a_bus_command_imports_only_what_it_runs():
    """`--sim scan` needs the CAN stack, the simulator, rich and the API's `Arm`, nothing else heavy."""
    code = (
        "import sys\n"
        "from sherpa_cli.cli.app import run\n"
        "rc = run(['--sim', 'scan'])\n"
        f"print(sorted(m for m in {NOT_FOR_SCAN!r} if m in sys.modules), rc)\n"
        "print(sorted(m for m in ('can', 'canopen', 'sherpa_cli.sim', 'sherpa_cli.api.arm') if m not in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    imported, missing = out.stdout.strip().splitlines()[-2:]
    assert imported == "[] 0", out.stdout
    assert missing == "[]", out.stdout  # the scan did run over the simulated arm, through the API


@pytest.mark.parametrize("xdg", [None, "", "  ", "/tmp/sherpa-xdg"])
def test_the_user_config_directory_is_platformdirs_own(monkeypatch, xdg):
    """cli/app.py spells platformdirs' Linux rule out to spare its import; the two must agree."""
    from platformdirs import user_config_dir

    from sherpa_cli.cli.app import _user_config_dir

    if xdg is None:
        monkeypatch.delenv("XDG_CONFIG_HOME", raising=False)
    else:
        monkeypatch.setenv("XDG_CONFIG_HOME", xdg)
    assert str(_user_config_dir()) == user_config_dir("sherpa-cli")
