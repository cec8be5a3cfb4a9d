"""`sherpa --help` must stay fast: the CAN stack and rich load only in commands that use them."""

from __future__ import annotations

import subprocess
import sys

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
