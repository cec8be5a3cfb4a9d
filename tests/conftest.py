"""Shared fixtures: run the CLI in-process through its real error boundary, and golden files.

Golden files hold a command's whole output (exit code, stdout, stderr) at a fixed width with
no colour. They are regenerated only with ``pytest --update-golden``; review the git diff.
"""

from __future__ import annotations

import io
import shlex
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
# The arm under test, over a selectable transport (SHERPA_TEST_BUS):
#   virtual (default)              `--sim`: the simulated arm in this process
#   remote                         `sherpa sim --serve` in another process, python-can-remote
#   socketcan:vcan0,vcan1,vcan2    `sherpa --bus-map ...=socketcan:vcanN sim` in another process
# Tests marked `realbus` use `arm_cli`; their golden transcripts name the logical command
# (`sherpa --sim ...`) so the same file must match on every transport.

import dataclasses
import os
import selectors
import signal
import subprocess
import sys
import time

TEST_BUS = os.environ.get("SHERPA_TEST_BUS", "virtual")
ARM_CONFIG = "configs/sherpa-arm.yaml"


def _free_base_port(count: int) -> int:
    import socket

    for _ in range(50):
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1]
        sockets = []
        try:
            for port in range(base, base + count):
                s = socket.socket()
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                s.bind(("127.0.0.1", port))
                sockets.append(s)
            return base
        except OSError:
            continue
        finally:
            for s in sockets:
                s.close()
    raise RuntimeError("no free consecutive ports on 127.0.0.1")


@dataclasses.dataclass
class ArmProcess:
    """The simulated arm in a separate process, and how to reach and power-cycle it."""

    proc: subprocess.Popen
    config: str
    bus_map: str
    drives: int

    def bus_kwargs(self) -> list[dict]:
        from sherpa_cli.bus.busmap import parse_bus_map

        return [{"interface": t.interface, "channel": t.channel} for t in parse_bus_map([self.bus_map]).values()]

    def power_cycle(self, timeout: float) -> None:
        """NMT reset-node to all drives, then wait for every boot-up: RAM as after power-on."""
        import can

        buses = [can.Bus(**kw) for kw in self.bus_kwargs()]
        try:
            seen: set[tuple[int, int]] = set()
            for bus in buses:
                bus.send(can.Message(arbitration_id=0, data=[0x81, 0], is_extended_id=False))
            deadline = time.monotonic() + timeout
            while len(seen) < self.drives and time.monotonic() < deadline:
                for i, bus in enumerate(buses):
                    msg = bus.recv(timeout=0.01)
                    if msg is not None and 0x701 <= msg.arbitration_id <= 0x77F and bytes(msg.data) == b"\x00":
                        seen.add((i, msg.arbitration_id))
            assert len(seen) == self.drives, f"only {len(seen)} of {self.drives} drives booted after reset"
        finally:
            for bus in buses:
                bus.shutdown()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=30)


def _slow_host_config(tmp_dir) -> str:
    """The arm config with patient interpreter timeouts: the QEMU guest runs Python 15-20x slower."""
    from sherpa_cli.config import dump_native, load_config

    cfg = load_config(ROOT / ARM_CONFIG)
    cfg = dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, reply_timeout=2.0, retries=2,
                                                                mo_confirm_timeout=20.0))
    path = tmp_dir / "arm.yaml"
    path.write_text(dump_native(cfg))
    return str(path)


def _start_arm_process(tmp_dir) -> ArmProcess:
    config = _slow_host_config(tmp_dir)
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_dir / "state"), NO_COLOR="1")
    env.pop("SHERPA_BUS_MAP", None)
    if TEST_BUS == "remote":
        port = _free_base_port(3)
        args = ["sim", "--serve", f"127.0.0.1:{port}"]
        marker = "export SHERPA_BUS_MAP="
    elif TEST_BUS.startswith("socketcan:"):
        channels = TEST_BUS.split(":", 1)[1].split(",")
        bus_map = ",".join(f"can{i}=socketcan:{ch}" for i, ch in enumerate(channels))
        args = ["--bus-map", bus_map, "sim"]
        marker = "drives answering on"
    else:
        raise RuntimeError(f"SHERPA_TEST_BUS={TEST_BUS!r}: expected virtual, remote or socketcan:IF,IF,IF")
    proc = subprocess.Popen([sys.executable, "-m", "sherpa_cli", "--config", config, *args, "--duration", "3600"],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    selector = selectors.DefaultSelector()
    selector.register(proc.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + 300
    lines: list[str] = []
    while time.monotonic() < deadline and proc.poll() is None:
        if selector.select(timeout=1):
            line = proc.stdout.readline()
            lines.append(line)
            if marker in line:
                if TEST_BUS == "remote":
                    bus_map = line.split("=", 1)[1].strip()
                from sherpa_cli.config import load_config

                return ArmProcess(proc, config, bus_map, len(load_config(config).drives))
    proc.kill()
    raise RuntimeError("simulated arm did not start:\n" + "".join(lines) + (proc.stderr.read() or ""))


@pytest.fixture(scope="session")
def arm_process(tmp_path_factory):
    if TEST_BUS == "virtual":
        yield None
        return
    arm = _start_arm_process(tmp_path_factory.mktemp("arm"))
    try:
        yield arm
    finally:
        arm.stop()


@pytest.fixture
def arm_cli(cli, arm_process):
    """``arm_cli(*args)``: `sherpa ARGS` against the simulated arm on the selected transport.

    A fresh (power-cycled) arm for every test. The transcript shows the logical command
    (``--sim``), so golden files are the same whatever the transport.
    """
    if arm_process is not None:
        arm_process.power_cycle(timeout=120)

    def invoke(*args: str, stdin: str = "") -> CliResult:
        if arm_process is None:
            result = cli("--sim", *args, stdin=stdin)
        else:
            result = cli("--config", arm_process.config, "--bus-map", arm_process.bus_map, *args, stdin=stdin)
        return dataclasses.replace(result, args=("--sim", *args))

    return invoke
