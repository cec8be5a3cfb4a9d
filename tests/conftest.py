"""Shared fixtures: run the CLI in-process through its real error boundary, and golden files.

Golden files hold a command's whole output (exit code, stdout, stderr) at a fixed width with
no colour. They are regenerated only with ``pytest --update-golden``; review the git diff.

Every test is isolated (autouse fixtures below): it gets a state directory of its own, the
user's state directory is a sentinel that must stay empty for the whole session, and a test
that leaves a python-can virtual channel open or a thread running fails.
"""

from __future__ import annotations

import dataclasses
import io
import os
import shlex
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

import pytest
from arm_harness import ArmProcess, TestBus, parse_test_bus
from hypothesis import HealthCheck, settings

# How fast examples are made and run depends on the machine's load, not on the code under test: a
# busy CI host failed a codec round trip on "data generation is extremely slow". Properties are
# judged, their speed is not (benchmarks/run.py measures speed).
settings.register_profile("sherpa", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("sherpa")

pytest_plugins = ["pytester"]  # tests/test_state_files.py runs the isolation fixtures on leaky tests

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = Path(__file__).resolve().parent / "golden"
WIDTH = 100

# The protocol windows (config `protocol:` section) of the in-process simulated arm and the
# sessions of commands run through the cli fixture: the simulated drives are deaf for these and
# the client waits them out, so the real-arm defaults (0.5 s each) would only make the suite slow.
# MO settle can be tiny (the client polls MO until it reads back). The simulated drive is deaf
# for SIM_SV_SHARE (0.6) of sv_blackout counted from when it handles SV, the client waits all of
# it from when it sent SV: 0.2 s leaves 80 ms for a loaded machine's scheduling, plus a retry.
# Tests of the windows themselves load their configs directly (tests/test_sim_e2e.py).
# Strict by default: the drives do not echo sets (protocol.set_echo false, the simulated drive
# follows), so every set is confirmed by its read-back, as on a Whistle whose firmware does not
# echo (elmo-protocol.md 1.3); a test about the echo loads its config as written.
TEST_PROTOCOL_WINDOWS = {"mo_settle": 0.02, "sv_blackout": 0.2, "set_echo": False}

# Threads that outlive a test on purpose; none so far (name them here, with the reason).
KNOWN_GLOBAL_THREADS: frozenset[str] = frozenset()
LEAK_GRACE_S = 5.0  # a thread that is ending (joined with a timeout elsewhere) gets this long


def _with_test_windows(cfg):
    return dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, **TEST_PROTOCOL_WINDOWS))


# -- isolation -----------------------------------------------------------------------------------

@pytest.fixture(scope="session", autouse=True)
def _user_state_sentinel(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The user's state directory for the whole session: a sentinel that must stay empty.

    Each test gets its own directory (``_isolated_state``); anything that still reaches this one
    (a session fixture, a test that undoes the isolation) wrote into the user's real state.
    """
    sentinel = tmp_path_factory.mktemp("user-state-sentinel")
    patch = pytest.MonkeyPatch()
    patch.setenv("XDG_STATE_HOME", str(sentinel))
    patch.setenv("SHERPA_LOCK_DIR", str(sentinel / "machine-locks"))
    try:
        yield sentinel
    finally:
        patch.undo()
    left = sorted(str(p.relative_to(sentinel)) for p in sentinel.rglob("*"))
    if left:
        pytest.fail(f"the suite wrote into the user's state directory: {', '.join(left)}", pytrace=False)


@pytest.fixture(autouse=True)
def _isolated_state(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A state directory (save ledger, simulated flash) and a machine lock directory (the dead-man
    host ids, motion/lock.py MachineLock) of the test's own: the processes one test starts share it,
    as the commands of one machine do."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.setenv("SHERPA_LOCK_DIR", str(tmp_path / "locks"))


def _open_virtual_buses() -> dict[object, int]:
    from can.interfaces import virtual

    with virtual.channels_lock:
        return {channel: len(queues) for channel, queues in virtual.channels.items()}


def _leaks(channels_before: dict[object, int], threads_before: set[threading.Thread]) -> list[str]:
    channels = {ch: n - channels_before.get(ch, 0) for ch, n in _open_virtual_buses().items()}
    threads = [t for t in threading.enumerate()
               if t not in threads_before and t.is_alive() and t.name not in KNOWN_GLOBAL_THREADS]
    return ([f"python-can virtual channel {ch!r} ({n} bus{'es' if n > 1 else ''} not shut down)"
             for ch, n in channels.items() if n > 0]
            + [f"thread {t.name!r} ({'daemon' if t.daemon else 'non-daemon'})" for t in threads])


LEAK_BASELINE = pytest.StashKey[tuple[dict[object, int], set[threading.Thread]]]()


def _leak_baseline(item: pytest.Item) -> None:
    """What a test may leave behind: what exists now. Taken before the test's fixtures, and again
    after the session's simulator harness (re)started its own threads for the test."""
    item.stash[LEAK_BASELINE] = (_open_virtual_buses(), set(threading.enumerate()))


@pytest.fixture
def rebaseline(request: pytest.FixtureRequest) -> Callable[[], None]:
    """``rebaseline()``: the threads and buses existing now are the session's, not the test's leftovers
    (a fixture that restarted the session's simulator harness for the test calls it)."""
    return lambda: _leak_baseline(request.node)


@pytest.fixture(autouse=True)
def _no_leftovers(request: pytest.FixtureRequest) -> Iterator[None]:
    """Fail a test that leaves a python-can virtual bus open or a thread running."""
    _leak_baseline(request.node)
    yield
    channels_before, threads_before = request.node.stash[LEAK_BASELINE]
    deadline = time.monotonic() + LEAK_GRACE_S
    while (left := _leaks(channels_before, threads_before)) and time.monotonic() < deadline:
        time.sleep(0.01)  # a thread that was told to stop may still be on its way out
    if left:
        pytest.fail("the test left behind: " + "; ".join(left), pytrace=False)


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
def cli_windows(monkeypatch: pytest.MonkeyPatch) -> Callable[[bool], None]:
    """``cli_windows(short)``: whether the in-process simulated arm the cli fixture's commands
    build (SimArm.in_process) and their sessions (ArmSession.open) use TEST_PROTOCOL_WINDOWS
    (the default) or the windows of the config as written (a simulator in another process has
    those). Both sides get the same windows; what a command prints from its config stays as written."""
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.sim.arm import SimArm

    written = {cls: cls.__dict__[name] for cls, name in ((ArmSession, "open"), (SimArm, "in_process"))}
    open_session, in_process = ArmSession.open, SimArm.in_process

    def open_short(cfg, *args, **kwargs):
        return open_session(_with_test_windows(cfg), *args, **kwargs)

    def in_process_short(cfg, *args, **kwargs):
        return in_process(_with_test_windows(cfg), *args, **kwargs)

    def choose(short: bool) -> None:
        monkeypatch.setattr(ArmSession, "open", staticmethod(open_short) if short else written[ArmSession])
        monkeypatch.setattr(SimArm, "in_process", staticmethod(in_process_short) if short else written[SimArm])

    return choose


@pytest.fixture
def cli(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, cli_windows):
    """Run ``sherpa ARGS`` in-process from the repo root, fixed width, no colour; the configs it
    loads get short protocol windows (TEST_PROTOCOL_WINDOWS)."""
    from sherpa_cli.cli.app import run

    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("COLUMNS", str(WIDTH))
    monkeypatch.setenv("LINES", "50")
    monkeypatch.setenv("NO_COLOR", "1")
    monkeypatch.setenv("TERM", "dumb")
    monkeypatch.delenv("SHERPA_CONFIG", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))  # no user config: ./configs is the default
    cli_windows(True)

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


# The dead-man time (ms) the commands against a separate simulator arm their drives with, if set; the
# vcan stage sets it: in its QEMU guest a command's heartbeat thread can starve past the bundled 500 ms
# while another Python process starts beside it, and the drive then trips before the test has acted.
# Tests that time the dead-man read it back from the config (test_motion_crossprocess.Arm.consumer_s).
CONSUMER_MS_ENV = "SHERPA_TEST_CONSUMER_MS"
# The time (s) a command's loop may go without a sign of life before its heartbeat stops, if set; the
# vcan stage sets it too: the guest's 1 s of the bundled config is 50-70 ms of a native machine, and a
# jog whose loop waited that long beside a starting Python process stopped itself (MO=0) first.
LIVENESS_S_ENV = "SHERPA_TEST_LIVENESS_S"
# The rate (Hz) `diffdrive move` records its pair at, if set (motion.pair_record_rate, 500 Hz bundled);
# the vcan stage sets it lower: the guest's simulator cannot answer 500 SYNCs a second on top of the
# command's requests, its backlog grew until it lost the host's heartbeats, and the drives stopped the
# move before its motors went on.
PAIR_RECORD_RATE_ENV = "SHERPA_TEST_PAIR_RECORD_RATE"


def _patient_config(tmp_dir: Path) -> str:
    """The arm config with patient interpreter and SDO timeouts: the QEMU guest runs Python 15-20x slower;
    and the dead-man time of SHERPA_TEST_CONSUMER_MS, the liveness of SHERPA_TEST_LIVENESS_S and the pair
    recording rate of SHERPA_TEST_PAIR_RECORD_RATE where set."""
    from sherpa_cli.config import dump_native, load_config

    cfg = load_config(ROOT / ARM_CONFIG)
    cfg = dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, reply_timeout=2.0, retries=2,
                                                                mo_confirm_timeout=20.0, sdo_timeout=3.0))
    if os.environ.get(CONSUMER_MS_ENV):
        cfg = dataclasses.replace(cfg, motion=dataclasses.replace(
            cfg.motion, consumer_time_ms=int(os.environ[CONSUMER_MS_ENV])))
    if os.environ.get(LIVENESS_S_ENV):
        cfg = dataclasses.replace(cfg, motion=dataclasses.replace(
            cfg.motion, liveness_timeout=float(os.environ[LIVENESS_S_ENV])))
    if os.environ.get(PAIR_RECORD_RATE_ENV):
        cfg = dataclasses.replace(cfg, motion=dataclasses.replace(
            cfg.motion, pair_record_rate=float(os.environ[PAIR_RECORD_RATE_ENV])))
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
def arm_cli(request, cli, cli_windows, arm_process):
    """``arm_cli(*args)``: `sherpa ARGS` against the simulated arm on the selected transport.

    Every test starts with factory flash, every command with a power-cycled arm (`sim
    --power-cycle` before each in-process `--sim` command, NMT reset with a separate simulator). The transcript shows the logical command (``--sim``), so golden files are the
    same whatever the transport. A simulator in another process keeps its config's protocol
    windows (a slow guest needs them), so the commands use those too.
    """
    if arm_process is not None:
        cli_windows(False)
        arm_process.new_test()
        _leak_baseline(request.node)  # a restarted simulator's threads are the session's

    def invoke(*args: str, stdin: str = "") -> CliResult:
        _check_arm_args(args)
        if arm_process is None:
            # `--sim` keeps the arm powered between commands; a separate simulator is reset before each
            # command (arm_harness), so here too: one golden file for every transport
            cycled = cli("sim", "--power-cycle")
            assert cycled.exit_code == 0, cycled.transcript()
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
def arm_console(request, arm_process, tmp_path):
    """``arm_console(*args)``: like arm_cli, but the installed `sherpa` console script in a process
    of its own, as a technician runs it (slow in the QEMU guest: use for a few tests only)."""
    script = Path(sys.executable).parent / "sherpa"
    assert script.exists(), f"no console script {script}: install the project (pip install -e .)"
    env = {k: v for k, v in os.environ.items() if k not in ("SHERPA_CONFIG", "SHERPA_BUS_MAP")}
    env.update(COLUMNS=str(WIDTH), LINES="50", NO_COLOR="1", TERM="dumb", XDG_STATE_HOME=str(tmp_path / "state"),
               XDG_CONFIG_HOME=str(tmp_path / "config"))
    if arm_process is not None:
        arm_process.new_test()
        _leak_baseline(request.node)  # a restarted simulator's threads are the session's

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
