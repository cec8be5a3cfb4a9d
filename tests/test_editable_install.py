"""An editable install (`pip install -e .`) leads mypy to the typed package (.ci/editable-mypy.sh).

Runs where this interpreter has the checkout installed editable (CI's venv); elsewhere it is skipped,
since an install from another checkout, or a normal one, says nothing about this pyproject.toml.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from urllib.parse import unquote, urlparse

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _editable_checkout() -> Path | None:
    try:
        text = metadata.distribution("sherpa-cli").read_text("direct_url.json")
    except metadata.PackageNotFoundError:
        return None
    if not text:
        return None
    url = json.loads(text)
    if not url.get("dir_info", {}).get("editable"):
        return None
    return Path(unquote(urlparse(url["url"]).path)).resolve()


@pytest.mark.skipif(_editable_checkout() != ROOT, reason="this checkout is not installed editable here")
@pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")
def test_mypy_finds_the_package_through_the_editable_install():
    out = subprocess.run(["bash", str(ROOT / ".ci" / "editable-mypy.sh"), sys.executable], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Success: no issues found in 3 source files" in out.stdout
