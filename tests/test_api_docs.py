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
