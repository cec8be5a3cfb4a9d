"""Dead-man host ids safe across users and hosts, in process and across processes.

- the machine lock of an id (motion/lock.py MachineLock) is seen by every process whatever its state
  directory, and the kernel drops it with its process, even by SIGKILL;
- a command listens to the pool's ids before taking one and never takes an id another node sends;
- a heartbeat on the command's own id that it did not send stops the command.

"Another host" is a second python-can virtual bus on the simulated arm's channel (in process) or
another process on the served simulator (tests/test_motion_crossprocess.py).
"""

from __future__ import annotations

import dataclasses
import os
import signal
import struct
import subprocess
import sys
import threading
import time

import can
import pytest
from conftest import ROOT

from sherpa_cli.bus.machine_lock import MachineLock, wire_key
from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.errors import ExitCode
from sherpa_cli.motion.drive_watch import DriveWatchError
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.lock import HostIdLock, MotionLockedError
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.sim.arm import SimArm

CONFIG = """\
name: host-id-test
protocol: {mo_settle: 0.05, sv_blackout: 0.2, reply_timeout: 1.0, retries: 2}
motion: {consumer_time_ms: 300, deadman_check_interval: 0.1}
buses:
  can0: {interface: socketcan, channel: can0}
drives:
  drive1: {bus: can0, node: 5, model: whistle-10/60}
"""
KEY = wire_key("socketcan", "vcan7")
HOLD = """\
import sys, time
from sherpa_cli.motion.lock import MachineLock
lock = MachineLock(sys.argv[1], "host126")
assert lock.try_acquire()
print("held", flush=True)
time.sleep(60)
"""


@pytest.fixture
def cfg(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return load_config(path)


def _holder_process(tmp_path, state: str) -> subprocess.Popen:
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / state))  # SHERPA_LOCK_DIR: the test's (conftest)
    proc = subprocess.Popen([sys.executable, "-c", HOLD, KEY], cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_an_id_another_users_command_holds_is_refused_whatever_the_state_directory(tmp_path, monkeypatch):
    """R1: the lock lives in the machine's lock directory, not in the user's state directory."""
    proc = _holder_process(tmp_path, "state-of-user-a")
    try:
        monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state-of-user-b"))
        lock = MachineLock(KEY, "host126")
        assert not lock.try_acquire()
        assert lock.holder() == proc.pid
        ids = HostIdLock({"can0": KEY}, (126, 124))
        assert ids.acquire() == 124
        ids.release()
        only = HostIdLock({"can0": KEY}, (126,))
        with pytest.raises(MotionLockedError, match=rf"126: taken by sherpa pid {proc.pid} on can0"):
            only.acquire()
    finally:
        proc.kill()
        proc.wait()
    # SIGKILL: the kernel dropped the flock; the pid left in the file does not count
    lock = MachineLock(KEY, "host126")
    assert lock.holder() is None
    assert lock.try_acquire()
    lock.release()


def test_an_id_heard_on_the_bus_is_never_taken():
    ids = HostIdLock({"can0": KEY, "can1": wire_key("socketcan", "vcan8")}, (126, 124, 123))
    assert ids.acquire({"can1": {126}, "can0": {124}}) == 123
    ids.release()
    with pytest.raises(MotionLockedError, match=r"126: heard on can0 \(another host or tool\)"):
        HostIdLock({"can0": KEY}, (126,)).acquire({"can0": {126}})


def test_the_lock_directory_is_made_sticky_and_world_writable(tmp_path, monkeypatch):
    """The first user's command makes it; every other user's must be able to create lock files in it."""
    monkeypatch.delenv("SHERPA_LOCK_DIR")
    base = tmp_path / "run-lock"
    base.mkdir()
    monkeypatch.setattr("sherpa_cli.paths.lock_dir", lambda: base / "sherpa-cli")
    lock = MachineLock(KEY, "host126")
    assert lock.try_acquire()
    try:
        assert (base / "sherpa-cli").stat().st_mode & 0o7777 == 0o1777
        assert lock.path.stat().st_mode & 0o777 == 0o666
    finally:
        lock.release()


def _beats(bus: can.BusABC, host_id: int, stop: threading.Event, period: float = 0.05) -> threading.Thread:
    def run() -> None:
        while not stop.is_set():
            bus.send(can.Message(arbitration_id=0x700 + host_id, data=[0x05], is_extended_id=False))
            stop.wait(period)

    t = threading.Thread(target=run, name="foreign-producer", daemon=True)
    t.start()
    return t


def _consumer(s: ArmSession, ref) -> int:
    return struct.unpack("<I", bytes(s.sdo(ref).upload(0x1016, 1, name="consumer"))[:4])[0]


def test_a_command_takes_an_id_nobody_sends_and_arms_its_drives_with_it(cfg):
    """A producer on 126 (another host's sherpa, a ROS node) before the command: it takes 124."""
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        other = can.Bus(interface="virtual", channel=s.sim.endpoints["can0"]["channel"])
        stop = threading.Event()
        producer = _beats(other, 126, stop)
        try:
            settings = MotionSettings.from_config(cfg)
            with MotionGuard(s, [ref], settings=settings) as g:
                assert g.host_id == 124
                assert _consumer(s, ref) == 124 << 16 | 300
                g.enable(ref, 5)
                for _ in range(20):  # the other producer goes on; this command is not disturbed
                    g.check()
                    time.sleep(0.02)
        finally:
            stop.set()
            producer.join()
            other.shutdown()


def _listened(cfg, *, shared: bool) -> float:
    """Seconds a guard's entry slept (on a stepped clock) before it took its id; ``shared``: its bus
    as another process sees it (a served or kernel bus) instead of the in-process arm's private one."""
    settings = MotionSettings.from_config(cfg)
    t = [0.0]
    slept: list[float] = []

    def sleep(dt: float) -> None:
        slept.append(dt)
        t[0] += dt
        time.sleep(0.001)

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        guard = MotionGuard(s, [ref], settings=settings, clock=lambda: t[0], sleep=sleep)
        if shared:
            guard._host_lock.buses = {"can0": wire_key("remote", "127.0.0.1:1/can0")}
        with guard as g:
            assert g.host_id == 126
    return sum(slept)


def test_the_command_listens_the_whole_window_on_a_shared_bus_and_two_periods_on_a_private_one(cfg):
    """On a bus other processes share, a command killed a moment ago may have drives still watching an
    id: the whole window (consumer time + one period). The in-process arm's bus is this process's
    alone: two heartbeat periods hear its producers."""
    settings = MotionSettings.from_config(cfg)
    assert settings.host_id_listen == pytest.approx(0.3 + 0.075)
    assert settings.host_id_listen_private == pytest.approx(2 * 0.075)
    assert _listened(cfg, shared=True) >= settings.host_id_listen
    assert settings.host_id_listen_private <= _listened(cfg, shared=False) < settings.host_id_listen


def test_a_foreign_heartbeat_on_the_commands_own_id_stops_the_command(cfg):
    """Another host that took the same id at the same moment, or a tool that starts sending it during
    the motion: the command stops every drive, exit 1, and says who to look for."""
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        other = can.Bus(interface="virtual", channel=s.sim.endpoints["can0"]["channel"])
        stop = threading.Event()
        producer = None
        try:
            with pytest.raises(DriveWatchError) as info, \
                    MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
                g.enable(ref, 5)
                g.client(ref).set("JV", 0, 3000)
                g.client(ref).execute("BG")
                producer = _beats(other, g.host_id, stop)
                deadline = time.monotonic() + 5
                while time.monotonic() < deadline:
                    g.check()
                    time.sleep(0.01)
            msg = str(info.value)
            assert msg.startswith("another node sends heartbeats as 126, this command's dead-man id, on bus can0"), msg
            assert info.value.exit_code == ExitCode.PROBLEM
            assert "outside motion.host_id_pool" in (info.value.hint or "")
            assert not s.sim.drives["drive1"].motor_on
            assert _consumer(s, ref) == 0  # put back
        finally:
            stop.set()
            if producer is not None:
                producer.join()
            other.shutdown()


TWO_DRIVES = CONFIG + "  drive2: {bus: can0, node: 6, model: whistle-10/60}\n"


@pytest.fixture
def cfg2(tmp_path):
    path = tmp_path / "arm2.yaml"
    path.write_text(TWO_DRIVES, encoding="utf-8")
    return load_config(path)


def _arm_consumer(s: ArmSession, ref, host_id: int, ms: int = 300) -> None:
    """What another host (or a tool killed after arming) leaves: the drive watches ``host_id``."""
    s.sdo(ref).download(0x1016, 1, struct.pack("<I", host_id << 16 | ms), name="consumer")


def test_an_id_a_drive_the_command_does_not_arm_watches_is_not_taken(cfg2):
    """drive2 watches 126 (armed by a tool that died, or another host whose heartbeat has not started):
    a command on drive1 sending 126 would switch that watch on. It takes 124, and with no other id
    in the pool it refuses before anything is armed, naming the drive."""
    with ArmSession.open(cfg2, sim=SimArm.in_process(cfg2)) as s:
        ref1, ref2 = resolve_target(cfg2, "drive1"), resolve_target(cfg2, "drive2")
        _arm_consumer(s, ref2, 126)
        settings = MotionSettings.from_config(cfg2)
        with MotionGuard(s, [ref1], settings=settings) as g:
            assert g.host_id == 124
            assert _consumer(s, ref1) == 124 << 16 | 300
        only_126 = dataclasses.replace(settings, host_id_pool=())
        with pytest.raises(MotionLockedError) as info, MotionGuard(s, [ref1], settings=only_126):
            pass
        assert "126: watched by drive2 (0x1016:1 of a drive this command does not arm" in str(info.value)
        assert _consumer(s, ref1) == 0  # nothing armed
        assert _consumer(s, ref2) == 126 << 16 | 300  # another's drive: never written


def test_a_drive_the_command_does_not_arm_that_starts_watching_its_id_stops_the_command(cfg2):
    """During the motion another node arms drive2 on this command's id: its heartbeat would keep
    drive2's motor on after that node dies. The command stops every drive it moves, exit 1."""
    with ArmSession.open(cfg2, sim=SimArm.in_process(cfg2)) as s:
        ref1, ref2 = resolve_target(cfg2, "drive1"), resolve_target(cfg2, "drive2")
        with pytest.raises(DriveWatchError) as info, \
                MotionGuard(s, [ref1], settings=MotionSettings.from_config(cfg2)) as g:
            g.enable(ref1, 5)
            g.client(ref1).set("JV", 0, 3000)
            g.client(ref1).execute("BG")
            for _ in range(10):
                g.check()
                time.sleep(0.01)
            _arm_consumer(s, ref2, g.host_id)
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline:
                g.check()
                time.sleep(0.01)
        msg = str(info.value)
        assert msg.startswith("drive2 (can0:6), a drive this command does not arm, watches its dead-man id 126"), msg
        assert info.value.exit_code == ExitCode.PROBLEM
        assert not s.sim.drives["drive1"].motor_on
        assert _consumer(s, ref1) == 0  # put back


def test_a_sigkilled_holders_id_is_free_at_once_but_the_listen_outlasts_its_drives_consumer(tmp_path):
    """The lock is free the moment its holder dies; the listen window (consumer time plus a period)
    is what keeps a new command from feeding the dead one's drives (motion/host_ids.py)."""
    proc = _holder_process(tmp_path, "state")
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert MachineLock(KEY, "host126").holder() is None
    m = MotionSettings(consumer_time_ms=500)
    assert m.host_id_listen > m.consumer_time_ms / 1000


def test_scan_calls_a_pool_heartbeat_no_sherpa_command_here_holds_a_foreign_host(cli, tmp_path):
    """R1: the simulated arm's own producer on 126 is nobody's command on this machine: a problem (exit 1)."""
    from test_doctor import faulty

    result = cli("--sim", "--config", faulty(tmp_path, "  buses:\n    can0: {foreign_heartbeats: [126], "
                                                       "heartbeat_period: 0.02}\n"), "--json", "scan", "--bus", "can0")
    assert result.exit_code == 1, result.transcript()
    import json

    nodes = {n["node"]: n for b in json.loads(result.stdout)["buses"] for n in b["nodes"]}
    assert nodes[126]["verdict"] == "foreign host", nodes[126]
    assert "no sherpa command of this machine holds" in " ".join(nodes[126]["notes"])


def test_scan_calls_a_pool_heartbeat_a_sherpa_command_here_holds_a_sherpa_host(tmp_path):
    from sherpa_cli.ops.scan import FOREIGN_HOST, SHERPA_HOST, scan_bus

    class Net:  # a bus on which only a heartbeat on 124 is heard
        def __init__(self):
            self.subs = {}

        def subscribe(self, can_id, cb):
            self.subs.setdefault(can_id, []).append(cb)

        def unsubscribe(self, can_id, cb=None):
            self.subs.pop(can_id, None)

        def send_message(self, can_id, data, remote=False):
            if can_id == 0x000:
                for cb in self.subs.get(0x700 + 124, []):
                    cb(0x700 + 124, bytearray([5]), 0.0)

    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    from sherpa_cli.ops.scan import ScanSettings

    settings = ScanSettings(sdo_timeout=0.01, quiet_s=0.01)
    held = scan_bus(cfg, "can0", Net(), settings, reset=True, host_holder=lambda hid: 4242)
    free = scan_bus(cfg, "can0", Net(), settings, reset=True, host_holder=lambda hid: None)
    here = {n.node: n for n in held.nodes}[124]
    there = {n.node: n for n in free.nodes}[124]
    assert here.verdict == SHERPA_HOST and "pid 4242" in " ".join(here.notes)
    assert there.verdict == FOREIGN_HOST
