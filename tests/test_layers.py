"""The layer contracts (pyproject.toml [tool.importlinter], docs/architecture.md) hold, and they bite:
a deliberately wrong import, planted in a copy of the package, makes `lint-imports` fail."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "sherpa_cli"


def _lint_imports(tree: Path) -> subprocess.CompletedProcess[str]:
    """Run import-linter over the package found first on PYTHONPATH (``tree``), with the project's contracts."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    script = ("import sys; from importlinter.cli import lint_imports_command; "
              "sys.argv = ['lint-imports', '--config', sys.argv[1], '--no-cache']; lint_imports_command()")
    return subprocess.run([sys.executable, "-c", script, str(ROOT / "pyproject.toml")], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture
def package_copy(tmp_path: Path) -> Path:
    shutil.copytree(PACKAGE, tmp_path / "sherpa_cli", ignore=shutil.ignore_patterns("__pycache__"))
    return tmp_path


def test_the_contracts_hold_for_the_tree(package_copy: Path) -> None:
    run = _lint_imports(package_copy)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "0 broken" in run.stdout


@pytest.mark.parametrize("module, line, contract", [
    # an upward import: the codec (elmo) reaching for the CLI
    ("elmo/codec.py", "from sherpa_cli.cli import output  # noqa", "Layers (imports point down)"),
    # a cycle hidden in a function: the guard importing a procedure that imports it
    ("motion/guard.py", "def _planted():\n    from sherpa_cli.ops import jog  # noqa\n", "Layers (imports point down)"),
    # the simulator importing the motion guard
    ("sim/drive.py", "from sherpa_cli.motion import guard  # noqa", "The simulator sits beside the stack"),
    # a cycle between two siblings of one package, inside a function
    ("ops/params_file.py", "def _planted():\n    from sherpa_cli.ops import params_diff  # noqa\n", "No import cycles"),
    ("bus/sdo.py", "def _planted():\n    from sherpa_cli.bus import session  # noqa\n", "No import cycles"),
    # the pipeline speaking Elmo's letters or CiA 402's objects instead of asking through the seam
    ("motion/run.py", "from sherpa_cli.elmo.protocol import UM_POSITION  # noqa",
     "The motion pipeline asks every drive through the drive seam"),
    ("ops/seam_jog.py", "def _planted():\n    from sherpa_cli.cia402 import protocol  # noqa\n",
     "The motion pipeline asks every drive through the drive seam"),
])
def test_a_wrong_import_breaks_a_contract(package_copy: Path, module: str, line: str, contract: str) -> None:
    path = package_copy / "sherpa_cli" / module
    path.write_text(path.read_text(encoding="utf-8") + "\n\n" + line + "\n", encoding="utf-8")
    run = _lint_imports(package_copy)
    assert run.returncode != 0, run.stdout
    broken = [ln for ln in run.stdout.splitlines() if ln.rstrip().endswith("BROKEN")]
    assert any(ln.startswith(contract) for ln in broken), run.stdout


def test_no_private_name_is_imported_across_modules() -> None:
    """What one module shares with another has a public name in the module that owns it."""
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sherpa_cli"):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} imports {node.module}.{alias.name}")
    assert offenders == []
