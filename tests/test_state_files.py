"""The state directory (platformdirs), its file locks, and the suite's own isolation.

- The save ledger and the simulated flash are read-modify-written under a file lock: two
  commands (here: threads with ledgers of their own, and processes) updating at once lose nothing.
- Every test has a state directory of its own; the user's is a sentinel that stays empty
  (checked at session end by conftest's ``_user_state_sentinel``).
- A test that leaves a python-can virtual bus open or a thread running fails (conftest's
  ``_no_leftovers``); shown here on a copy of the conftest in a pytester run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import platformdirs

from sherpa_cli.config import load_config
from sherpa_cli.ops.save_ledger import SaveLedger
from sherpa_cli.paths import state_dir
from sherpa_cli.sim import state as sim_state

ROOT = Path(__file__).resolve().parent.parent
TESTS = Path(__file__).resolve().parent
SERIAL = 0x5A000101


# -- where -------------------------------------------------------------------------------------

def test_state_dir_is_platformdirs_and_honours_xdg_state_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert state_dir() == Path(platformdirs.user_state_dir("sherpa-cli", appauthor=False))
    if sys.platform.startswith("linux"):
        assert state_dir() == tmp_path / "xdg" / "sherpa-cli"


def test_every_test_has_a_state_dir_of_its_own(tmp_path):
    assert state_dir() == tmp_path / "state" / "sherpa-cli"


# -- the save ledger ---------------------------------------------------------------------------

def test_ledgers_in_threads_of_their_own_lose_no_save(tmp_path):
    # Separate SaveLedger objects share no thread lock: only the file lock keeps them apart.
    path = tmp_path / "state" / "save-ledger.json"
    threads_n, saves_n = 4, 25
    barrier = threading.Barrier(threads_n, timeout=10)
    errors: list[BaseException] = []

    def saver(i: int) -> None:
        try:
            ledger = SaveLedger(path)
            barrier.wait()
            for _ in range(saves_n):
                record = ledger.record(SERIAL, f"drive{i}")
                assert record.warning is None or "not updated" not in record.warning, record.warning
                ledger.mark_unsaved(SERIAL + 1 + i, f"drive{i}")
        except BaseException as exc:  # noqa: BLE001  surfaced below, not lost in the thread
            errors.append(exc)

    threads = [threading.Thread(target=saver, args=(i,)) for i in range(threads_n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    ledger = SaveLedger(path)
    assert ledger.count(SERIAL) == threads_n * saves_n
    assert all(ledger.unsaved(SERIAL + 1 + i) for i in range(threads_n))


_SAVER = """
import sys
from pathlib import Path
from sherpa_cli.ops.save_ledger import SaveLedger
ledger = SaveLedger(Path(sys.argv[1]))
for _ in range(int(sys.argv[2])):
    ledger.record(0x5A000101, "drive1")
"""


def test_two_processes_saving_at_once_lose_no_count(tmp_path):
    path = tmp_path / "state" / "save-ledger.json"
    saves_n = 40
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / "state"))
    procs = [subprocess.Popen([sys.executable, "-c", _SAVER, str(path), str(saves_n)], cwd=ROOT, env=env)
             for _ in range(2)]
    assert [p.wait(timeout=120) for p in procs] == [0, 0]
    assert SaveLedger(path).count(SERIAL) == 2 * saves_n


# -- the simulated flash -----------------------------------------------------------------------

def _saved(flash: sim_state.DriveFlash, key: str, value: int) -> sim_state.DriveFlash:
    return sim_state.DriveFlash(flash.serial, {**flash.flash, key: value}, flash.save_count + 1)


def test_two_simulators_of_one_arm_keep_each_others_saves():
    cfg = load_config(ROOT / "configs" / "appendix-c" / "example3.yaml")
    first, second = sim_state.load(cfg), sim_state.load(cfg)  # two commands, both at factory flash
    mine = {**first, "drive1": _saved(first["drive1"], "AC", 150_000)}
    theirs = {**second, "drive2": _saved(second["drive2"], "DC", 120_000),
              "drive1": _saved(second["drive1"], "SP", 900)}
    sim_state.save_changes(cfg, first, mine)
    sim_state.save_changes(cfg, second, theirs)
    now = sim_state.load(cfg)
    assert now["drive2"].flash == {"DC": 120_000} and now["drive2"].save_count == 1
    # both saved drive1: the later flash image wins (a save writes the drive's whole RAM), both saves count
    assert now["drive1"].flash == {"SP": 900} and now["drive1"].save_count == 2
    # a simulator that saved nothing writes nothing back over the others
    sim_state.save_changes(cfg, first, first)
    assert sim_state.load(cfg) == now


def test_simulators_in_threads_lose_no_save():
    cfg = load_config(ROOT / "configs" / "appendix-c" / "example3.yaml")
    rounds = 15
    errors: list[BaseException] = []

    def simulator(drive: str) -> None:
        try:
            for i in range(rounds):
                before = sim_state.load(cfg)
                sim_state.save_changes(cfg, before, {**before, drive: _saved(before[drive], "AC", i)})
        except BaseException as exc:  # noqa: BLE001  surfaced below, not lost in the thread
            errors.append(exc)

    threads = [threading.Thread(target=simulator, args=(d,)) for d in ("drive1", "drive2", "drive1")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    now = sim_state.load(cfg)
    assert (now["drive1"].save_count, now["drive2"].save_count) == (2 * rounds, rounds)
    assert json.loads(sim_state.state_path(cfg).read_text())["format"] == sim_state.FORMAT


# -- the suite's own isolation -----------------------------------------------------------------

_LEAKY_TESTS = '''
import threading, time
import can
import pytest

OPEN = []  # a bus nobody refers to is shut down by the garbage collector

def test_leaves_a_virtual_bus_open():
    OPEN.append(can.Bus(interface="virtual", channel="leaky-test-channel"))

def test_leaves_a_thread_running():
    threading.Thread(target=time.sleep, args=(1.0,), name="leaky-thread", daemon=True).start()

def test_cleans_up():
    bus = can.Bus(interface="virtual", channel="tidy-test-channel")
    t = threading.Thread(target=time.sleep, args=(0.01,))
    t.start()
    t.join()
    bus.shutdown()

@pytest.fixture(scope="session")
def writes_user_state():
    from sherpa_cli.paths import state_dir
    state_dir().mkdir(parents=True)
    (state_dir() / "oops.json").write_text("{}")

def test_a_session_fixture_writing_user_state(writes_user_state):
    pass
'''


def test_the_isolation_fixtures_catch_leaks_and_user_state(pytester):
    conftest = (TESTS / "conftest.py").read_text(encoding="utf-8")
    pytester.makeconftest(conftest.replace("LEAK_GRACE_S = 5.0", "LEAK_GRACE_S = 0.1"))
    pytester.makepyfile(test_leaky=_LEAKY_TESTS, arm_harness=(TESTS / "arm_harness.py").read_text(encoding="utf-8"))
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-p", "no:randomly")
    # a teardown failure is an error of a test that passed
    result.assert_outcomes(passed=4, errors=3)
    out = result.stdout.str()
    assert "python-can virtual channel 'leaky-test-channel'" in out
    assert "thread 'leaky-thread'" in out
    assert "the suite wrote into the user's state directory: sherpa-cli, sherpa-cli/oops.json" in out


def test_cli_sessions_on_the_simulated_arm_use_the_short_protocol_windows(cli, monkeypatch):
    from conftest import TEST_PROTOCOL_WINDOWS

    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.sim.arm import SimArm

    seen = []
    factory = SimArm.for_session.__func__

    def capture(cls, cfg, channels):
        seen.append(cfg.protocol)
        return factory(cls, cfg, channels)

    monkeypatch.setattr(SimArm, "for_session", classmethod(capture))
    init = ArmSession.__init__  # the simulated arm and the session (its clients) must agree

    def session_init(self, cfg, *args, **kwargs):
        seen.append(cfg.protocol)
        init(self, cfg, *args, **kwargs)

    monkeypatch.setattr(ArmSession, "__init__", session_init)
    result = cli("--sim", "cmd", "elbow_1a", "PX")
    assert result.exit_code == 0, result.transcript()
    windows = tuple(TEST_PROTOCOL_WINDOWS.values())
    assert [(p.mo_settle, p.sv_blackout, p.set_echo) for p in seen] == [windows, windows]
    # what a command prints from the config stays as written
    assert "sv_blackout" not in cli("config", "convert", "configs/seed-d1.yaml").stdout  # defaults: not written
