#!/usr/bin/env bash
# mypy finds sherpa_cli through the editable install alone (docs/api.md: the package is typed). Run from
# an empty directory outside the checkout, so neither the current directory nor the project's mypy
# settings can lead mypy to the package: only what `pip install -e .` put into site-packages can. An
# install that reaches sherpa_cli through an import hook (setuptools' default editable finder for a flat
# layout) fails here with "Cannot find implementation or library stub for module named 'sherpa_cli'".
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
# the interpreter whose site-packages hold the install (default: the one on PATH, which also runs mypy)
target=$(command -v "${1:-python}")
away=$(mktemp -d)
trap 'rm -rf "$away"' EXIT
cd "$away"
env -u PYTHONPATH -u MYPYPATH python -m mypy --python-executable "$target" --strict --follow-imports=silent --cache-dir "$away/cache" \
  "$repo/examples/arm_api.py" "$repo/examples/read_arm.py" "$repo/examples/arm_script.py"
