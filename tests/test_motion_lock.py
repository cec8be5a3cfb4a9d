"""One motion command per drive at a time (motion/lock.DriveLock, taken by MotionGuard on entry).

Two motion commands on one drive would disarm each other's dead-man (both use the host id and put
0x1016:1 back when the first ends). The second refuses before sending anything, naming the drive and
the holder's pid (exit 5); every exit path releases the lock; a SIGKILLed holder's lock is released
by the kernel; `sherpa stop` needs no lock.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from test_motion_guard import CONFIG

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.errors import ExitCode, SafetyError
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.lock import DriveLock, MotionLockedError
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.stop import stop_drives
from sherpa_cli.sim.arm import SimArm

KILL_BOUND = 10.0  # s a killed holder's lock may take to come free (the kernel frees it at exit)


@pytest.fixture
def cfg(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return load_config(path)


def not_heartbeats(session, name) -> list:
    """The frames the drive received, the host heartbeat (0x77E) left out."""
    with session.sim.lock:
        return [(i, bytes(d)) for _, i, d in session.sim.drives[name].received if i != 0x77E]


def test_a_second_guard_on_a_drive_refuses_before_sending_anything_and_the_first_is_untouched(cfg):
    settings = MotionSettings.from_config(cfg)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r1, r2 = resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")
        with MotionGuard(s, [r1], settings=settings) as first:
            first.enable(r1, 5)
            before = not_heartbeats(s, "drive1"), not_heartbeats(s, "drive2")
            # drive2 comes first and is free: its lock is taken, then given back on the refusal
            with pytest.raises(MotionLockedError) as err, MotionGuard(s, [r2, r1], settings=settings):
                pytest.fail("entered")
            time.sleep(0.05)
            # nothing was sent by the refused guard (no NMT, no query, no SDO): only the first's heartbeat
            assert (not_heartbeats(s, "drive1"), not_heartbeats(s, "drive2")) == before
            first.check()  # the first one goes on
            assert s.sim.drives["drive1"].motor_on
            # drive2's lock was given back: a guard on it alone enters
            with MotionGuard(s, [r2], settings=settings):
                pass
        assert err.value.exit_code == ExitCode.BUSY == 5
        text = str(err.value)
        assert text.startswith("drive1 (can0:5): another sherpa command (this process) is moving this drive")
        assert "nothing sent" in text and "sherpa stop" in err.value.hint
        # the first guard ended normally: the lock is free again
        with MotionGuard(s, [r1], settings=settings):
            pass
        assert not s.sim.drives["drive1"].motor_on and s.sim.errors == []


def test_every_exit_path_releases_the_lock(cfg):
    settings = MotionSettings.from_config(cfg)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r1 = resolve_target(cfg, "drive1")
        with pytest.raises(RuntimeError), MotionGuard(s, [r1], settings=settings):
            raise RuntimeError("boom")
        with pytest.raises(KeyboardInterrupt), MotionGuard(s, [r1], settings=settings):
            raise KeyboardInterrupt
        # a refusal at entry (drive in fault) gives the lock back too
        with s.sim.lock:
            s.sim.drives["drive1"]._mf |= 1 << 12
        with pytest.raises(SafetyError, match="in fault"), MotionGuard(s, [r1], settings=settings):
            pass
        lock = DriveLock(r1)
        lock.acquire()  # free after all of them
        assert lock.holder() == os.getpid()
        lock.release()
        assert not lock.pid_path.exists()


HOLDER = textwrap.dedent("""
    import sys, time
    from sherpa_cli.motion.lock import DriveLock
    from sherpa_cli.bus.session import DriveRef
    lock = DriveLock(DriveRef("drive1", "can0", 5, None))
    lock.acquire()
    print("held", flush=True)
    time.sleep(120)
""")


def test_another_process_holds_it_the_refusal_names_its_pid_stop_still_works_and_sigkill_frees_it(cfg):
    settings = MotionSettings.from_config(cfg)
    holder = subprocess.Popen([sys.executable, "-c", HOLDER], stdout=subprocess.PIPE, text=True,
                              env=dict(os.environ))  # the same XDG_STATE_HOME: the test's own
    try:
        assert holder.stdout.readline().strip() == "held"
        with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
            r1 = resolve_target(cfg, "drive1")
            with (
                pytest.raises(MotionLockedError, match=rf"drive1 \(can0:5\): another sherpa command \(pid "
                                                       rf"{holder.pid}\) is moving this drive"),
                MotionGuard(s, [r1], settings=settings),
            ):
                pass
            assert s.sim.drives["drive1"].od_writes == []  # nothing written
            # `sherpa stop` is the emergency path: no lock needed
            c = s.client(r1)
            c.nmt_start()
            c.motor_on()
            (_report,) = stop_drives(s, [r1], settings)
            assert not s.sim.drives["drive1"].motor_on
            # SIGKILL: no exit handler runs, the kernel releases the flock
            os.kill(holder.pid, signal.SIGKILL)
            holder.wait(timeout=KILL_BOUND)
            deadline = time.monotonic() + KILL_BOUND
            while True:
                try:
                    with MotionGuard(s, [r1], settings=settings):
                        break
                except MotionLockedError:
                    assert time.monotonic() < deadline, "the killed holder's lock never came free"
                    time.sleep(0.05)
            assert s.sim.errors == []
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait(timeout=KILL_BOUND)


JOG_ARM = "tests/data/jog-fast-arm.yaml"
ELBOW_HOLDER = HOLDER.replace('DriveRef("drive1", "can0", 5, None)', 'DriveRef("elbow", "can0", 6, None)')


@pytest.mark.golden
def test_jog_on_a_drive_another_process_moves_exits_5_with_one_line(cli, golden, tmp_path):
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / "state"))  # the cli fixture's state directory
    holder = subprocess.Popen([sys.executable, "-c", ELBOW_HOLDER], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert holder.stdout.readline().strip() == "held"
        result = cli("--config", JOG_ARM, "--sim", "jog", "j2", "--to", "10deg", "--apply")
    finally:
        holder.kill()
        holder.wait(timeout=KILL_BOUND)
    assert result.exit_code == 5 and "Traceback" not in result.stderr
    assert f"(pid {holder.pid})" in result.stderr
    golden("jog-motion-locked.txt", result.transcript().replace(str(holder.pid), "PID"))


# -- one write lock per drive for every command that writes to it --------------------------------------

def test_program_limits_is_refused_while_another_command_moves_the_drive(cli):
    from sherpa_cli.bus.targets import drive_ref
    from sherpa_cli.config import load_config as load

    cfg = load("configs/sherpa-arm.yaml")
    held = DriveLock(drive_ref(cfg, "elbow_1a"))  # what a running jog of elbow_pitch holds
    held.acquire()
    try:
        result = cli("--sim", "program-limits", "elbow_pitch", "--apply", "--motor-off")
    finally:
        held.release()
    assert result.exit_code == ExitCode.BUSY, result.transcript()
    assert "elbow_1a (can1:40): another sherpa command (this process) is moving this drive" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_jog_is_refused_while_parameters_are_written_to_its_drive(cli):
    from sherpa_cli.bus.targets import drive_ref
    from sherpa_cli.config import load_config as load

    cfg = load("configs/sherpa-arm.yaml")
    held = DriveLock(drive_ref(cfg, "elbow_1a"), purpose="writing parameters to")
    held.acquire()
    try:
        result = cli("--sim", "jog", "elbow_pitch", "--velocity", "0.05", "--for", "0.2", "--apply")
    finally:
        held.release()
    assert result.exit_code == ExitCode.BUSY, result.transcript()
    assert "is writing parameters to this drive: refused, nothing sent" in result.stderr
