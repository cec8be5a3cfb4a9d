"""Shared fixtures: run the CLI in-process through its real error boundary, and golden files.

Golden files hold a command's whole output (exit code, stdout, stderr) at a fixed width with
no colour. They are regenerated only with ``pytest --update-golden``; review the git diff.
"""

from __future__ import annotations

import io
import shlex
from collections.abc import Callable
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = Path(__file__).resolve().parent / "golden"
WIDTH = 100


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--update-golden", action="store_true", default=False,
                     help="rewrite tests/golden/* from the current output instead of comparing")


@dataclass
class CliResult:
    args: tuple[str, ...]
    exit_code: int
    stdout: str
    stderr: str

    def transcript(self) -> str:
        return (f"$ sherpa {shlex.join(self.args)}\n[exit {self.exit_code}]\n"
                f"--- stdout\n{self.stdout}--- stderr\n{self.stderr}")


@pytest.fixture
def cli(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    """Run ``sherpa ARGS`` in-process from the repo root, fixed width, no colour."""
    from sherpa_cli.cli.app import run

    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("COLUMNS", str(WIDTH))
    monkeypatch.setenv("LINES", "50")
    monkeypatch.setenv("NO_COLOR", "1")
    monkeypatch.setenv("TERM", "dumb")
    monkeypatch.delenv("SHERPA_CONFIG", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))  # no user config: ./configs is the default

    def invoke(*args: str, stdin: str = "") -> CliResult:
        out, err = io.StringIO(), io.StringIO()
        monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
        with redirect_stdout(out), redirect_stderr(err):
            code = run(list(args))
        return CliResult(tuple(args), int(code), out.getvalue(), err.getvalue())

    return invoke


@pytest.fixture
def golden(request: pytest.FixtureRequest):
    """``golden(name, text)``: compare text with tests/golden/<name>, or rewrite it with --update-golden."""
    update = request.config.getoption("--update-golden")

    def check(name: str, text: str) -> None:
        path = GOLDEN / name
        if update:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            return
        assert path.exists(), f"golden file {path.relative_to(ROOT)} is missing; run pytest --update-golden and review it"
        expected = path.read_text(encoding="utf-8")
        assert text == expected, f"output differs from {path.relative_to(ROOT)} (regenerate with --update-golden and review the diff)"

    return check


# --------------------------------------------------------------------------------------------
# The arm under test, over the transport SHERPA_TEST_BUS selects (virtual | remote |
# socketcan:IF,IF,IF; see arm_harness.py and docs/testing.md). Tests marked `realbus` use
# `arm_cli`; their golden transcripts name the logical command (`sherpa --sim ...`), so the same
# file must match on every transport.

import dataclasses
import os
import subprocess
import sys

from arm_harness import ArmProcess, TestBus, parse_test_bus

ARM_CONFIG = "configs/sherpa-arm.yaml"
# global options arm_cli supplies itself: a test giving them would test another arm than the bus's
ARM_OWNED_OPTIONS = ("--sim", "--config", "--bus-map")
TEST_BUS_KEY = pytest.StashKey[TestBus]()


def pytest_configure(config: pytest.Config) -> None:
    try:
        config.stash[TEST_BUS_KEY] = parse_test_bus(os.environ.get("SHERPA_TEST_BUS"))
    except ValueError as exc:
        raise pytest.UsageError(str(exc)) from None


def pytest_report_header(config: pytest.Config) -> str:
    return f"SHERPA_TEST_BUS: {config.stash[TEST_BUS_KEY].describe()}"


def _patient_config(tmp_dir: Path) -> str:
    """The arm config with patient interpreter and SDO timeouts: the QEMU guest runs Python 15-20x slower."""
    from sherpa_cli.config import dump_native, load_config

    cfg = load_config(ROOT / ARM_CONFIG)
    cfg = dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, reply_timeout=2.0, retries=2,
                                                                mo_confirm_timeout=20.0, sdo_timeout=3.0))
    path = tmp_dir / "arm.yaml"
    path.write_text(dump_native(cfg))
    return str(path)


@pytest.fixture(scope="session")
def test_bus(request: pytest.FixtureRequest) -> TestBus:
    return request.config.stash[TEST_BUS_KEY]


@pytest.fixture(scope="session")
def arm_process(test_bus, tmp_path_factory):
    """`sherpa sim` in its own process on the selected transport, or None for `virtual`."""
    if not test_bus.separate_process:
        yield None
        return
    work = tmp_path_factory.mktemp("arm")
    arm = ArmProcess(test_bus, ROOT, _patient_config(work), work)
    arm.start()
    try:
        yield arm
    finally:
        arm.stop()


def _check_arm_args(args: tuple[str, ...]) -> None:
    owned = [a for a in args if a.split("=", 1)[0] in ARM_OWNED_OPTIONS]
    if owned:
        pytest.fail(f"arm_cli{args}: {', '.join(owned)} is arm_cli's own (the bundled arm on the selected "
                    "transport); use the cli fixture for another arm", pytrace=False)


@pytest.fixture
def arm_cli(cli, arm_process):
    """``arm_cli(*args)``: `sherpa ARGS` against the simulated arm on the selected transport.

    Every test starts with factory flash, every command with a power-cycled arm, as with
    `--sim`. The transcript shows the logical command (``--sim``), so golden files are the
    same whatever the transport.
    """
    if arm_process is not None:
        arm_process.new_test()

    def invoke(*args: str, stdin: str = "") -> CliResult:
        _check_arm_args(args)
        if arm_process is None:
            result = cli("--sim", *args, stdin=stdin)
        else:
            arm_process.before_command()
            result = cli("--config", arm_process.config, "--bus-map", arm_process.bus_map, *args, stdin=stdin)
            if not arm_process.alive():
                pytest.fail(f"the simulated arm stopped during `sherpa {shlex.join(args)}`:\n{arm_process.log()}")
        return dataclasses.replace(result, args=("--sim", *args))

    return invoke


@pytest.fixture
def arm_golden(arm_cli, golden):
    """``arm_golden(name, args, exit_code=None, clean=None)``: run ARGS through arm_cli and compare
    the transcript (after ``clean``) with ``tests/golden/NAME.txt``; no traceback either way."""

    def check(name: str, args: list[str], *, exit_code: int | None = None,
              clean: Callable[[str], str] | None = None) -> CliResult:
        result = arm_cli(*args)
        assert "Traceback" not in result.stderr
        if exit_code is not None:
            assert result.exit_code == exit_code, result.transcript()
        text = result.transcript()
        golden(f"{name}.txt", clean(text) if clean else text)
        return result

    return check


@pytest.fixture
def arm_console(arm_process, tmp_path):
    """``arm_console(*args)``: like arm_cli, but the installed `sherpa` console script in a process
    of its own, as a technician runs it (slow in the QEMU guest: use for a few tests only)."""
    script = Path(sys.executable).parent / "sherpa"
    assert script.exists(), f"no console script {script}: install the project (pip install -e .)"
    env = {k: v for k, v in os.environ.items() if k not in ("SHERPA_CONFIG", "SHERPA_BUS_MAP")}
    env.update(COLUMNS=str(WIDTH), LINES="50", NO_COLOR="1", TERM="dumb", XDG_STATE_HOME=str(tmp_path / "state"),
               XDG_CONFIG_HOME=str(tmp_path / "config"))
    if arm_process is not None:
        arm_process.new_test()

    def invoke(*args: str, stdin: str = "") -> CliResult:
        _check_arm_args(args)
        if arm_process is None:
            argv = ["--sim", *args]
        else:
            arm_process.before_command()
            argv = ["--config", arm_process.config, "--bus-map", arm_process.bus_map, *args]
        done = subprocess.run([str(script), *argv], cwd=ROOT, env=env, input=stdin, capture_output=True,
                              text=True, timeout=600)
        return CliResult(("--sim", *args), done.returncode, done.stdout, done.stderr)

    return invoke
