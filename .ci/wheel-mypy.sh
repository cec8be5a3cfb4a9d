#!/usr/bin/env bash
# mypy finds sherpa_cli through a normal install too: the wheel built from this checkout, installed
# into a fresh venv (no dependencies: mypy follows the package's own imports silently), checked from an
# empty directory outside the checkout, so only the installed files and their py.typed can lead mypy
# to the package. The examples a user copies must type-check against what `pip install` gives them.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
away=$(mktemp -d)
trap 'rm -rf "$away"' EXIT
python -m pip wheel -q --no-deps -w "$away/wheel" "$repo"
python -m venv "$away/venv"
"$away/venv/bin/python" -m pip install -q --no-deps --no-index "$away"/wheel/*.whl
cd "$away"
env -u PYTHONPATH -u MYPYPATH python -m mypy --python-executable "$away/venv/bin/python" --strict \
  --follow-imports=silent --cache-dir "$away/cache" \
  "$repo/examples/arm_api.py" "$repo/examples/read_arm.py" "$repo/examples/arm_script.py"
