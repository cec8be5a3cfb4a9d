"""docs/api.md's examples run as written, on the simulated arm."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "api.md"
BLOCKS = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def test_the_doc_has_examples():
    assert len(BLOCKS) >= 4


@pytest.mark.parametrize("code", BLOCKS, ids=[f"example-{i + 1}" for i in range(len(BLOCKS))])
def test_example_runs(code, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)  # the examples name configs/sherpa-arm.yaml as a user in the checkout would
    exec(compile(code, f"{DOC}:example", "exec"), {"__name__": "docs_api_example"})
    # every example that prints, prints something real (not an empty list or None)
    out = capsys.readouterr().out
    assert "None" not in out


def test_no_example_needs_what_the_first_install_lacks():
    """The README's first install is `pip install -e .`: an example that imports a test tool (pytest
    was one) fails for the user who copies it. Only the standard library and sherpa_cli."""
    import ast
    import sys

    for k, code in enumerate(BLOCKS, 1):
        for node in ast.walk(ast.parse(code)):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                top = name.split(".")[0]
                assert top == "sherpa_cli" or top in sys.stdlib_module_names, f"example {k} imports {name}"


# the sections whose examples call what the API grew for the rest of the command line
TYPED_SECTIONS = ("Record", "Monitor", "Tune the loops, match a pair", "Raw commands, recovery, the doctor")


def test_the_record_monitor_tune_and_raw_examples_pass_mypy_strict(tmp_path):
    import subprocess
    import sys

    text = DOC.read_text(encoding="utf-8")
    files = []
    for k, title in enumerate(TYPED_SECTIONS):
        section = text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]
        (block,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
        files.append(tmp_path / f"example_{k}.py")
        files[-1].write_text(block, encoding="utf-8")
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent",
                          "--cache-dir", str(tmp_path / "cache"), *map(str, files)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_unconfirmed_save_example_runs_on_an_arm_commissioned_before(cli, capsys):
    """A newcomer runs the README's first command, then docs/api.md's examples in that one state
    directory: wrist_3 then needs nothing, so the refusal the example showed never came and its
    `else: raise AssertionError` fired. It says why nothing was asked instead."""
    (block,) = [b for b in BLOCKS if "nobody confirmed" in b]
    assert cli("--sim", "program-limits", "--apply", "--save", "--yes").exit_code == 0
    exec(compile(block, f"{DOC}:example", "exec"), {"__name__": "docs_api_example"})
    assert "nothing to change, so nothing to confirm" in capsys.readouterr().out
