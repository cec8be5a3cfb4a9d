"""Shared by the killed-tool and signal tests: one simulated arm in its own process per
test module (the realbus harness's when SHERPA_TEST_BUS selects one, else our own `sherpa sim --serve`
on 127.0.0.1, power-cycled before every test as the harness does), and the moving commands as a
user runs them in another process."""

from __future__ import annotations

import json
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass

import pytest
from arm_harness import ArmProcess, TestBus
from conftest import ROOT, _patient_config
from test_motion_crossprocess import EXIT_TIMEOUT, START_TIMEOUT, Arm

from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config

# what the moving commands change on a drive (the journal's objects)
SDO_OBJECTS = [(0x1016, 1, "<I"), (0x1029, 1, "<B"), (0x6007, 0, "<h"), (0x2040, 0, "<B"), (0x1401, 2, "<B"),
               (0x1800, 1, "<I"), (0x1800, 2, "<B"), (0x1A00, 0, "<B"), (0x1A00, 1, "<I"), (0x1A00, 2, "<I"),
               (0x1802, 1, "<I"), (0x1802, 2, "<B"), (0x1A02, 0, "<B"), (0x1A02, 1, "<I")]
INTERP = [("UM", 0), ("SP", 0), ("AC", 0), ("DC", 0), ("MF", 0), ("HM", 1)]


@dataclass(frozen=True)
class Moving:
    """A moving command: its arguments (``{out}``: a path in the test's directory), the drives it
    moves, the joint a follow-up jog moves, and the journal owner a kill leaves behind."""

    name: str
    args: tuple[str, ...]
    drives: tuple[str, ...]
    joint: str
    owner: str

    def argv(self, tmp_path) -> list[str]:
        return [a.replace("{out}", str(tmp_path / "out")) for a in self.args]


# slow, long moves: still moving when the test acts on them, also in the emulated vcan guest
MOVING = {
    "jog": Moving("jog", ("jog", "elbow_pitch", "--velocity", "0.05", "--for", "60", "--apply"), ("elbow_1a",),
                  "elbow_pitch", "motion command"),
    "home": Moving("home", ("home", "shoulder_yaw", "--yes"), ("shoulder_1a",), "shoulder_yaw", "home"),
    "diffdrive move": Moving("diffdrive move", ("diffdrive", "move", "shoulder_diff", "--sigma", "0.6", "--velocity",
                                                "0.03", "--uncalibrated", "--apply"), ("shoulder_2a", "shoulder_2b"),
                             "shoulder_pitch", "motion command"),
    "log step": Moving("log step", ("log", "step", "elbow_pitch", "--velocity", "0.05", "--for", "60", "--hold", "55",
                                    "-o", "{out}",
                                    "--apply"), ("elbow_1a",), "elbow_pitch", "log record"),
    "log record": Moving("log record", ("log", "record", "elbow_1a", "--rate", "100", "--for", "60", "-o",
                                        "{out}.csv"), ("elbow_1a",), "elbow_pitch", "log record"),
}


def served_process(config: str, work) -> Iterator[ArmProcess]:
    """`sherpa sim --serve` of ``config`` on 127.0.0.1 for a fixture: started (skipped if it cannot
    start), stopped afterwards."""
    proc = ArmProcess(TestBus("remote"), ROOT, config, work)
    try:
        proc.start()
    except RuntimeError as exc:
        pytest.skip(f"the served simulator did not start: {exc}")
    try:
        yield proc
    finally:
        proc.stop()


@pytest.fixture(scope="module")
def shared_arm(arm_process, tmp_path_factory):
    """One simulator process for the module (the harness's if it runs one)."""
    if arm_process is not None:
        yield arm_process
        return
    work = tmp_path_factory.mktemp("arm")
    # the harness's patient timeouts: on a loaded machine the served arm once missed the bundled
    # 0.1 s reply timeout of the jog that follows `recover` (exit 3, not the killed tool's doing)
    yield from served_process(_patient_config(work), work)


@pytest.fixture(scope="module")
def remote_arm(tmp_path_factory):
    """One `sherpa sim --serve` of the module's own, whatever SHERPA_TEST_BUS says: for tests whose
    premise is python-can-remote's (the bus goes away with the simulator's process)."""
    work = tmp_path_factory.mktemp("arm")
    proc = ArmProcess(TestBus("remote"), ROOT, str(ROOT / "configs/sherpa-arm.yaml"), work)
    try:
        proc.start()
    except RuntimeError as exc:
        pytest.skip(f"the served simulator did not start: {exc}")
    try:
        yield proc
    finally:
        proc.stop()


@pytest.fixture
def own_arm(tmp_path_factory, rebaseline):
    """A simulated arm of the test's own, just powered up (joints where power-up puts them), whatever
    SHERPA_TEST_BUS says: for a test whose premise is where a joint starts (a home's search side),
    which a simulator shared from test to test does not keep."""
    work = tmp_path_factory.mktemp("own-arm")
    proc = ArmProcess(TestBus("remote"), ROOT, _patient_config(work), work)
    try:
        proc.start()
    except RuntimeError as exc:
        pytest.skip(f"the served simulator did not start: {exc}")
    try:
        rebaseline()
        yield fresh(proc)
    finally:
        proc.stop()


def fresh(process: ArmProcess) -> Arm:
    """The arm as after power-on (RAM, NMT state, latched faults), for one test; a new simulator
    process if a test killed the last one."""
    if not process.alive():
        process.start()
    process.new_test()
    process.before_command()
    return Arm(process.config, process.bus_map, process.event_log)


@pytest.fixture
def arm(shared_arm, rebaseline):
    """The arm as after power-on, for one test (:func:`fresh`)."""
    arm = fresh(shared_arm)
    rebaseline()  # a simulator (re)started for this test: its threads are the module's
    return arm


def snapshot(arm_: Arm, drives: tuple[str, ...]) -> dict[str, int]:
    """What the moving commands change, read through a session of the test's own (SDO and the
    interpreter; NMT start first, which changes nothing the commands touch)."""
    cfg = apply_bus_map(load_config(ROOT / arm_.config), parse_bus_map([arm_.bus_map]))
    out: dict[str, int] = {}
    refs = [resolve_target(cfg, d) for d in drives]
    with ArmSession.open(cfg, buses=sorted({r.bus for r in refs})) as s:
        for ref in refs:
            c = s.client(ref)
            c.nmt_start()
            for letters, index in INTERP:
                out[f"{ref.name}.{letters}[{index}]"] = int(c.get(letters, index))
            for index, sub, fmt in SDO_OBJECTS:
                raw = s.sdo(ref).upload(index, sub)
                value = struct.unpack(fmt, (bytes(raw) + bytes(4))[:struct.calcsize(fmt)])[0]
                out[f"{ref.name}.0x{index:04X}:{sub}"] = value
    return out


def wait_moving(arm_: Arm, cmd: Moving, since: float, proc, tmp_path) -> float:
    """Block until the simulator logged a motor of ``cmd`` switched on (log record: its TPDO set-up
    is in the journal and the recording runs); returns that time."""
    deadline = time.monotonic() + START_TIMEOUT
    if cmd.name == "log record":
        journal = tmp_path / "state" / "sherpa-cli" / "journal" / "can1-node40.json"  # elbow_1a
        while time.monotonic() < deadline and proc.poll() is None:
            if journal.exists() and len(json.loads(journal.read_text() or "{}").get("steps", [])) >= 5:
                time.sleep(0.5)  # recording
                return time.monotonic()
            time.sleep(0.05)
        raise AssertionError(f"`sherpa {' '.join(cmd.args)}` did not start recording")
    while time.monotonic() < deadline and proc.poll() is None:
        for drive in cmd.drives:
            for e in arm_.events(drive):
                if e["t"] >= since and e["event"].startswith("motor on"):
                    return e["t"]
        time.sleep(0.02)
    proc.kill()
    out, err = proc.communicate(timeout=EXIT_TIMEOUT)
    events = {drive: arm_.events(drive) for drive in cmd.drives}
    raise AssertionError(f"`sherpa {' '.join(cmd.args)}` did not switch a motor on (exit {proc.returncode}):\n"
                         f"{out}\n{err}\nevents: {events}")
