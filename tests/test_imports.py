"""Every module of the package imports on its own, with the dependency versions installed.

The deps-lowest stage of .ci/run runs this against the lowest versions pyproject.toml allows: a
module that uses a name a lower bound does not have yet fails here, not at a technician's bench.
"""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys

import pytest

import sherpa_cli

# `python -m sherpa_cli` runs the CLI when imported; it is imported (and run) by the CLI tests
NOT_IMPORTED = {"sherpa_cli.__main__"}
MODULES = sorted(m.name for m in pkgutil.walk_packages(sherpa_cli.__path__, "sherpa_cli.")
                 if m.name not in NOT_IMPORTED)


def test_the_package_has_its_layers():
    # a walk that found nothing would make the test below pass vacuously
    layers = {name.split(".")[1] for name in MODULES}
    assert {"cli", "api", "ops", "motion", "elmo", "bus", "config", "sim", "log", "joints"} <= layers
    assert len(MODULES) > 100


def test_every_module_imports_in_fresh_interpreters_forty_at_a_time():
    """Fresh interpreters, a chunk of modules each (one interpreter per module would take a minute):
    a module that imports only after a test happened to import something else fails here."""
    failures = []
    chunk = 40
    for start in range(0, len(MODULES), chunk):
        names = MODULES[start:start + chunk]
        code = ("import importlib, sys, traceback\n"
                "bad = []\n"
                f"for name in {names!r}:\n"
                "    try:\n"
                "        importlib.import_module(name)\n"
                "    except Exception as exc:\n"
                "        bad.append(f'{name}: {type(exc).__name__}: {exc}')\n"
                "print('\\n'.join(bad))\n"
                "sys.exit(1 if bad else 0)\n")
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            failures.append(done.stdout.strip() or done.stderr.strip())
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("name", ["sherpa_cli.api", "sherpa_cli.cli.app", "sherpa_cli.sim.arm"])
def test_the_entry_points_import_in_this_interpreter(name):
    assert importlib.import_module(name).__name__ == name
