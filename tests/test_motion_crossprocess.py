"""The dead-man and the stop paths across processes: `sherpa jog --velocity` in a subprocess, the
simulated arm in another (python-can-remote on 127.0.0.1, or the realbus harness's simulator on
SHERPA_TEST_BUS), and a signal or a second `sherpa stop` from the test.

The simulator's event log (`sherpa sim --event-log`) says when each motor went on and off, on
time.monotonic()'s scale, which every process of this machine shares.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import pytest
from conftest import ROOT, _patient_config
from test_cross_process import _env, _start_sim, _stop

from sherpa_cli.config import load_config

pytestmark = [pytest.mark.realbus, pytest.mark.crossprocess]

DRIVE, NODE, JOINT = "elbow_1a", 40, "elbow_pitch"
START_TIMEOUT = 120.0  # s for the jog to switch the motor on (Python start-up in the QEMU guest is slow)
EXIT_TIMEOUT = 60.0
# s for a simulator event the test waits for but does not time (a dead-man trip after a kill): the
# simulator in the QEMU guest notices late, and a fixed sleep there raced it
EVENT_TIMEOUT = 60.0


@dataclass
class Arm:
    config: str
    bus_map: str
    event_log: Path
    shared: bool = False  # the realbus harness's simulator, kept from test to test (joints stay where they were)

    @cached_property
    def consumer_s(self) -> float:
        """The dead-man time the commands arm their drives with (s): the config's motion.consumer_time_ms,
        500 ms in the bundled one, longer in the vcan stage's guest (SHERPA_TEST_CONSUMER_MS, conftest)."""
        return load_config(ROOT / self.config).motion.consumer_time_ms / 1000

    def events(self, drive: str = DRIVE) -> list[dict]:
        if not self.event_log.exists():
            return []
        lines = self.event_log.read_text(encoding="utf-8").splitlines()
        return [e for e in (json.loads(line) for line in lines if line.strip()) if e["drive"] == drive]

    def wait_event(self, predicate, timeout: float, after: float = float("-inf"), drive: str = DRIVE) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for e in self.events(drive):
                if e["t"] >= after and predicate(e["event"]):
                    return e
            time.sleep(0.02)
        raise AssertionError(f"no such event of {drive} within {timeout} s; events: {self.events(drive)}")

    def wait_trip(self, drives: tuple[str, ...], after: float) -> None:
        """Until each of ``drives`` recorded its dead-man trip ("heartbeat lost") since ``after``."""
        for drive in drives:
            self.wait_event(lambda text: text.startswith("heartbeat lost"), EVENT_TIMEOUT, after=after, drive=drive)


@pytest.fixture
def arm(arm_process, tmp_path, rebaseline):
    """The simulated arm in another process: the realbus harness's, or (SHERPA_TEST_BUS=virtual) our own
    `sherpa sim --serve` with an event log."""
    if arm_process is not None:
        arm_process.new_test()
        rebaseline()  # a simulator restarted after the last test's SV: its threads are the session's
        arm_process.before_command()
        yield Arm(arm_process.config, arm_process.bus_map, arm_process.event_log, shared=True)
        return
    log = tmp_path / "events.jsonl"
    proc = bus_map = None
    output = ""
    for _ in range(3):
        proc, bus_map, output = _start_sim(tmp_path, "--event-log", str(log))
        if proc is not None:
            break
    assert proc is not None, f"sim did not start:\n{output}"
    try:
        # the commands' config as the realbus harness and the killed-tool tests give theirs: the served
        # simulator answers on a loaded machine's scheduling, which a drive's firmware does not, and none
        # of these tests times an answer (a jog's 0.1 s PX poll ran out under load average 12)
        yield Arm(_patient_config(tmp_path), bus_map, log)
    finally:
        _stop(proc)


def sherpa(arm: Arm, tmp_path, *args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "sherpa_cli", "--config", arm.config, "--bus-map", arm.bus_map,
                             *args], cwd=ROOT, env=_env(tmp_path), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kwargs)


def centre(arm: Arm, tmp_path, *joints: str) -> None:
    """Put ``joints`` back at 0 on a shared simulator. It keeps where earlier tests left a joint, and in
    the 15-20x slower vcan guest every velocity jog runs seconds before the test acts: elbow_pitch
    walked to the end of its range within a few tests, and then the limit watch, not the test's
    signal or second command, ended the jog (measured 2026-11-28: program-limits found nothing moving
    and wrote its limits; the first of two jogs stopped itself by MO=0)."""
    if not arm.shared:
        return  # a simulator of this test's own: its joints start where power-up puts them
    for joint in joints:
        code, out, err = finish(sherpa(arm, tmp_path, "jog", joint, "--to", "0", "--uncalibrated", "--apply"))
        assert code == 0, f"putting {joint} back at 0 failed:\n{out}\n{err}"


def start_jog(arm: Arm, tmp_path) -> tuple[subprocess.Popen, float]:
    """`sherpa jog --velocity` until Ctrl-C, in its own process; returns once the motor is on and moving
    (the simulator logged the BG that started the jog). Slow (29 counts/s): in the emulated vcan guest a
    second `sherpa` process takes seconds to start, and the joint must not reach its range meanwhile
    (at 0.3 rad/s it did, and the limit watch, not the stop, ended the jog)."""
    centre(arm, tmp_path, JOINT)
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, "jog", JOINT, "--velocity", "0.05", "--apply")
    try:
        on = arm.wait_event(lambda text: text.startswith("motor on"), START_TIMEOUT, after=since)
        arm.wait_event(lambda text: text.startswith("BG: UM=5, JV="), START_TIMEOUT, after=on["t"])
    except AssertionError:
        proc.kill()
        out, err = proc.communicate(timeout=EXIT_TIMEOUT)
        raise AssertionError(f"the jog did not switch the motor on:\n{out}\n{err}") from None
    time.sleep(0.2)  # well into the motion
    return proc, on["t"]


def finish(proc: subprocess.Popen) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=EXIT_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate(timeout=EXIT_TIMEOUT)
        raise AssertionError(f"the jog did not end by itself:\n{out}\n{err}") from None
    return proc.returncode, out, err


def motor_offs(arm: Arm, after: float) -> list[dict]:
    """Motor-off events since ``after`` (the simulator's record)."""
    return [e for e in arm.events() if e["t"] >= after and e["event"].startswith("motor off")]


@pytest.mark.parametrize("signum,exit_code", [(signal.SIGINT, 0), (signal.SIGTERM, 130)])
def test_a_signal_to_a_velocity_jog_stops_the_motor_and_switches_it_off(arm, tmp_path, signum, exit_code):
    proc, t_on = start_jog(arm, tmp_path)
    proc.send_signal(signum)
    code, out, err = finish(proc)
    assert code == exit_code, f"{out}\n{err}"
    assert "Traceback" not in err
    offs = motor_offs(arm, t_on)
    assert [e["event"] for e in offs] == ["motor off: MO=0"], arm.events()  # the guard's MO=0, not a trip
    assert not any("heartbeat lost" in e["event"] for e in arm.events() if e["t"] >= t_on)  # put back in time
    if signum == signal.SIGINT:  # Ctrl-C is how an open-ended velocity jog ends: a normal result
        assert f"{JOINT} ({DRIVE}, can1:{NODE}): stopped at" in out and "Ctrl-C" in out
    else:
        assert "SIGTERM received" in err and f"stop: {DRIVE} (can1:{NODE}): stopped; motor off" in err


def test_sigkill_leaves_the_drive_to_stop_itself_within_the_consumer_time(arm, tmp_path):
    proc, t_on = start_jog(arm, tmp_path)
    t_kill = time.monotonic()
    os.kill(proc.pid, signal.SIGKILL)
    finish(proc)
    off = arm.wait_event(lambda text: text.startswith("motor off"), 10 * arm.consumer_s, after=t_on)
    assert off["event"] == "motor off: heartbeat lost, 0x6007=2", arm.events()
    ratio = (off["t"] - t_kill) / arm.consumer_s
    assert 0 < ratio <= 1.5, f"motor off {off['t'] - t_kill:.3f} s after SIGKILL (consumer time {arm.consumer_s} s)"


def test_sherpa_stop_from_a_second_process_stops_a_running_jog(arm, tmp_path):
    proc, t_on = start_jog(arm, tmp_path)
    stopper = sherpa(arm, tmp_path, "stop", JOINT)
    s_code, s_out, s_err = finish(stopper)
    assert s_code == 0, f"{s_out}\n{s_err}"
    code, out, err = finish(proc)  # the jog sees the motor switched off and ends
    assert code == 1, f"{out}\n{err}"
    assert "the motor was switched off during the jog" in err, f"{out}\n{err}"
    offs = motor_offs(arm, t_on)
    assert offs and offs[0]["event"] == "motor off: MO=0", arm.events()
    assert not any("heartbeat lost" in e["event"] for e in arm.events() if e["t"] >= t_on)


def _with_can0_unreachable(bus_map: str) -> str:
    """The arm's bus map with can0 pointed at nothing: a closed port, or a SocketCAN interface that
    does not exist (the adapter a technician forgot to plug in)."""
    entries = dict(item.split("=", 1) for item in bus_map.split(","))
    interface = entries["can0"].split(":", 1)[0]
    entries["can0"] = "remote:127.0.0.1:1" if interface == "remote" else f"{interface}:sherpanone0"
    return ",".join(f"{bus}={target}" for bus, target in entries.items())


def test_sherpa_stop_with_one_bus_unreachable_still_stops_a_jog_on_another_bus(arm, tmp_path):
    proc, t_on = start_jog(arm, tmp_path)  # the jog runs on can1
    stopper = subprocess.Popen([sys.executable, "-m", "sherpa_cli", "--config", arm.config,
                                "--bus-map", _with_can0_unreachable(arm.bus_map), "stop"],
                               cwd=ROOT, env=_env(tmp_path), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    s_code, s_out, s_err = finish(stopper)
    assert s_code == 1, f"{s_out}\n{s_err}"  # partly stopped
    assert "partly stopped" in s_err and "not reached (bus could not be opened)" in s_err, s_err
    assert "Traceback" not in s_err
    assert "NOT REACHED" in s_out and DRIVE in s_out
    offs = motor_offs(arm, t_on)
    assert offs and offs[0]["event"] == "motor off: MO=0", arm.events()
    code, out, err = finish(proc)  # the jog sees its motor switched off and ends
    assert code == 1, f"{out}\n{err}"


def test_program_limits_during_a_jog_in_another_process_is_refused_with_exit_5(arm, tmp_path):
    proc, t_on = start_jog(arm, tmp_path)
    try:
        programmer = sherpa(arm, tmp_path, "program-limits", JOINT, "--apply", "--motor-off")
        p_code, p_out, p_err = finish(programmer)
        offs = motor_offs(arm, t_on)  # before the jog's own stop below
        jog_ran = proc.poll() is None
    finally:
        proc.send_signal(signal.SIGINT)
        code, out, err = finish(proc)
    why = f"program-limits (exit {p_code}):\n{p_out}\n{p_err}\nthe jog (exit {code}):\n{out}\n{err}\nevents: {arm.events()}"
    assert jog_ran, "the jog had ended before program-limits did: " + why
    assert p_code == 5, why
    assert f"{DRIVE} (can1:{NODE}): another sherpa command (pid {proc.pid}) is moving this drive" in p_err
    assert "Traceback" not in p_err
    # the jog was not touched: its motor is still on, nobody switched it off
    assert not offs, why
    assert code == 0, f"{out}\n{err}"


def test_sigkill_during_hold_leaves_the_motor_stopped_by_the_drives_consumer(arm, tmp_path):
    """`jog --hold`: after its short velocity move the joint is held in position mode; a SIGKILL of
    the holding tool leaves the drive's own consumer to switch the motor off."""
    since = time.monotonic()
    proc = sherpa(arm, tmp_path, "jog", JOINT, "--velocity", "0.2", "--for", "0.3", "--hold", "--apply")
    try:
        on = arm.wait_event(lambda text: text.startswith("motor on"), START_TIMEOUT, after=since)
        arm.wait_event(lambda text: text.startswith("BG: UM=5, PA="), START_TIMEOUT, after=on["t"])  # holding
    except AssertionError:
        proc.kill()
        out, err = proc.communicate(timeout=EXIT_TIMEOUT)
        raise AssertionError(f"the jog did not start holding:\n{out}\n{err}") from None
    time.sleep(0.3)  # well into the hold
    assert not motor_offs(arm, on["t"]), "the held motor went off before the kill"
    t_kill = time.monotonic()
    os.kill(proc.pid, signal.SIGKILL)
    finish(proc)
    off = arm.wait_event(lambda text: text.startswith("motor off"), 10 * arm.consumer_s, after=on["t"])
    assert off["event"] == "motor off: heartbeat lost, 0x6007=2", arm.events()
    assert 0 < (off["t"] - t_kill) / arm.consumer_s <= 1.5


# -- two commands on one bus; the profile a plain `jog --to` sets ------------------------------------

OTHER_DRIVE, OTHER_JOINT = "wrist_1a", "wrist_1"  # a second plain joint on the same bus (can1)


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGSTOP])
def test_two_motion_commands_on_one_bus_a_killed_or_frozen_one_stops_its_drive_the_other_keeps_running(
        arm, tmp_path, how):
    """Each command's drives watch that command's heartbeat, so another sherpa motion
    command on the same bus never keeps a killed (SIGKILL) or frozen (SIGSTOP) command's drive moving
    (it did for 6.7 s, until the other command ended), and the other command's drive keeps running."""
    centre(arm, tmp_path, OTHER_JOINT)
    first, t_on = start_jog(arm, tmp_path)  # elbow_pitch on can1
    since = time.monotonic()
    second = sherpa(arm, tmp_path, "jog", OTHER_JOINT, "--velocity", "0.05", "--apply")
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not [e for e in arm.events(OTHER_DRIVE) if e["t"] >= since and e["event"].startswith("BG: UM=5, JV=")]:
            assert time.monotonic() < deadline, f"the second jog did not start: {arm.events(OTHER_DRIVE)}"
            assert second.poll() is None, f"the second jog ended: {second.communicate()}"
            time.sleep(0.02)
        time.sleep(0.2)
        t_sig = time.monotonic()
        os.kill(first.pid, how)
        off = arm.wait_event(lambda text: text.startswith("motor off"), 10 * arm.consumer_s, after=t_on)
        assert off["event"] == "motor off: heartbeat lost, 0x6007=2", arm.events()
        ratio = (off["t"] - t_sig) / arm.consumer_s
        assert 0 < ratio <= 1.5, f"{DRIVE} went off {off['t'] - t_sig:.3f} s after {how.name} (consumer {arm.consumer_s} s)"
        time.sleep(3 * arm.consumer_s)  # the other command's drive is still moving well after the kill
        other_offs = [e for e in arm.events(OTHER_DRIVE) if e["t"] >= since and e["event"].startswith("motor off")]
        assert not other_offs, f"the other command's drive stopped too: {other_offs}"
        assert second.poll() is None, "the other command ended"
    finally:
        if how == signal.SIGSTOP:
            os.kill(first.pid, signal.SIGKILL)
        finish(first)
        if second.poll() is None:
            second.send_signal(signal.SIGINT)
        code, out, err = finish(second)
    assert code == 0, f"{out}\n{err}"  # Ctrl-C ends an open-ended jog normally


def test_a_plain_jog_to_sets_the_configured_speed_whatever_sp_the_drive_holds(arm, tmp_path):
    """A position jog on a drive holding SP=100000 (set by another node) moves at the
    joint's configured velocity limit (400 counts/s), not at what the drive held: the tool writes SP
    before its BG. Read on the bus, as another node would."""
    from test_drive_watch_crossprocess import other_node, send

    from sherpa_cli.elmo.codec import decode_request, encode_set

    # The served arm keeps where earlier tests left the joint (in the slow guest a velocity jog runs
    # further), so first put it back at 0: the measured jog of +0.2 rad then stays inside its range.
    code, out, err = finish(sherpa(arm, tmp_path, "jog", JOINT, "--to", "0", "--uncalibrated", "--apply"))
    assert code == 0, f"{out}\n{err}"
    bus = other_node(arm)
    frames: list[bytes] = []
    try:
        send(bus, 0x000, bytes([0x01, NODE]))  # NMT start: the interpreter listens on RPDO2
        time.sleep(0.1)
        send(bus, 0x300 + NODE, encode_set("SP", 0, 100000))
        time.sleep(0.1)
        while bus.recv(timeout=0.05) is not None:  # what came before the jog
            pass
        proc = sherpa(arm, tmp_path, "jog", JOINT, "--by", "0.2", "--uncalibrated", "--apply")
        deadline = time.monotonic() + START_TIMEOUT + EXIT_TIMEOUT
        while proc.poll() is None and time.monotonic() < deadline:
            msg = bus.recv(timeout=0.05)
            if msg is not None and msg.arbitration_id == 0x300 + NODE and not msg.is_error_frame:
                frames.append(bytes(msg.data))
        code, out, err = finish(proc)
    finally:
        bus.shutdown()
    assert code == 0, f"{out}\n{err}"
    requests = [decode_request(f) for f in frames]
    bg = [i for i, r in enumerate(requests) if r.letters == "BG"]
    assert bg, f"no BG seen: {requests}"
    sp = [r.value for r in requests[:bg[0]] if r.letters == "SP" and r.kind == "set"]
    # the joint's velocity limit is 400 counts/s; the move's plan keeps one count/s for rounding (motion/plan.py)
    assert sp and sp[-1] == 399, f"SP before the move's BG: {sp} (the joint's velocity limit is 400 counts/s)"


HOME_DRIVE, HOME_JOINT = "elbow_1b", "elbow_stiffness"  # end switches; searches down at 100 counts/s
SECOND_HOME_S = 8.0  # s of motion for a home that starts at its switch (a push into the end stop: 28.6 s)


def test_an_interrupted_home_then_home_finds_the_switch_without_pushing_the_end_stop(arm, tmp_path):
    """Ctrl-C just after the search met the switch (the return move had begun) left the
    joint at or past its switch; the next `home` searched away from it and pushed against the end stop
    for its whole 28.6 s bound. It must find the switch and end normally, its motion short."""
    since = time.monotonic()
    first = sherpa(arm, tmp_path, "home", HOME_JOINT, "--yes")
    deadline = time.monotonic() + START_TIMEOUT + 30
    while len([e for e in arm.events(HOME_DRIVE) if e["t"] >= since and e["event"].startswith("BG")]) < 2:
        if first.poll() is not None or time.monotonic() > deadline:
            first.kill()
            out, err = first.communicate(timeout=EXIT_TIMEOUT)
            raise AssertionError(f"the first home never began its return move:\n{out}\n{err}\n{arm.events(HOME_DRIVE)}")
        time.sleep(0.005)
    first.send_signal(signal.SIGINT)  # the wrong moment: at the switch, the return just started
    code, out, err = finish(first)
    assert code == 130, f"{out}\n{err}"
    assert "Traceback" not in err
    assert HOME_JOINT in err and "not homed" in err, err  # Ctrl-C says which joints are no longer homed

    t_second = time.monotonic()
    second = sherpa(arm, tmp_path, "home", HOME_JOINT, "--yes")
    code, out, err = finish(second)
    assert code == 0, f"the second home failed:\n{out}\n{err}"
    events = [e for e in arm.events(HOME_DRIVE) if e["t"] >= t_second]
    ons = [e["t"] for e in events if e["event"].startswith("motor on")]
    offs = [e["t"] for e in events if e["event"].startswith("motor off")]
    assert ons and offs, events
    assert offs[-1] - ons[0] <= SECOND_HOME_S, f"the second home moved {offs[-1] - ons[0]:.1f} s: {events}"


# -- other users and other hosts on the bus -------------------------------------------------------

PRODUCER = """\
import sys, time
from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
from sherpa_cli.bus.links import open_bus
from sherpa_cli.config import load_config
import can
config, bus_map, bus, host_id, seconds = sys.argv[1:6]
cfg = apply_bus_map(load_config(config), parse_bus_map(bus_map.split(",")))
link = open_bus(cfg.buses[bus])
print("sending", flush=True)
end = time.monotonic() + float(seconds)
try:
    while time.monotonic() < end:
        link.send(can.Message(arbitration_id=0x700 + int(host_id), data=[5], is_extended_id=False))
        time.sleep(0.05)
finally:
    link.shutdown()
"""


def foreign_producer(arm: Arm, tmp_path, host_id: int, seconds: float) -> subprocess.Popen:
    """Another host's node sending heartbeats as ``host_id`` on can1 (the elbow's and wrist's bus)."""
    proc = subprocess.Popen([sys.executable, "-c", PRODUCER, arm.config, arm.bus_map, "can1", str(host_id),
                             str(seconds)], cwd=ROOT, env=_env(tmp_path), stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline().strip()
    assert line == "sending", f"the producer did not start: {line!r}"
    return proc


def sherpa_as(arm: Arm, tmp_path, who: str, *args: str, own_lock_dir: bool) -> subprocess.Popen:
    """`sherpa` as another user (a state directory of its own) and, with ``own_lock_dir``, as if on
    another host (a machine lock directory of its own: only the listening can keep the ids apart)."""
    env = dict(_env(tmp_path), XDG_STATE_HOME=str(tmp_path / f"state-{who}"))
    if own_lock_dir:
        env["SHERPA_LOCK_DIR"] = str(tmp_path / f"locks-{who}")
    return subprocess.Popen([sys.executable, "-m", "sherpa_cli", "--config", arm.config, "--bus-map", arm.bus_map,
                             *args], cwd=ROOT, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_jog_running(arm: Arm, proc: subprocess.Popen, drive: str, since: float) -> float:
    deadline = time.monotonic() + START_TIMEOUT
    while True:
        on = [e for e in arm.events(drive) if e["t"] >= since and e["event"].startswith("BG: UM=5, JV=")]
        if on:
            return on[0]["t"]
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            out, err = proc.communicate(timeout=EXIT_TIMEOUT)
            raise AssertionError(f"the jog of {drive} did not start:\n{out}\n{err}\n{arm.events(drive)}")
        time.sleep(0.02)


def consumer_entries(arm: Arm, drive: str, since: float) -> list[str]:
    return [e["event"] for e in arm.events(drive) if e["t"] >= since and "0x1016:1" in e["event"]]


@pytest.mark.parametrize("own_lock_dir", [False, True], ids=["two-users", "two-hosts"])
def test_a_second_user_or_host_never_shares_the_dead_man_id_and_a_killed_jog_stops_by_its_consumer(
        arm, tmp_path, own_lock_dir):
    """R1: two sherpa processes with different state directories (another user, sudo) or on different
    hosts (different lock directories too) jog two joints of one bus; SIGKILL of the first stops its
    motor within the consumer time, the second keeps running. Before, both took id 126 and the
    elbow ran on for 6.7 s."""
    centre(arm, tmp_path, JOINT, OTHER_JOINT)
    since = time.monotonic()
    first = sherpa_as(arm, tmp_path, "a", "jog", JOINT, "--velocity", "0.05", "--apply", own_lock_dir=own_lock_dir)
    second = None
    try:
        t_on = wait_jog_running(arm, first, DRIVE, since)
        since2 = time.monotonic()
        second = sherpa_as(arm, tmp_path, "b", "jog", OTHER_JOINT, "--velocity", "0.05", "--apply",
                           own_lock_dir=own_lock_dir)
        wait_jog_running(arm, second, OTHER_DRIVE, since2)
        time.sleep(0.2)
        t_kill = time.monotonic()
        os.kill(first.pid, signal.SIGKILL)
        off = arm.wait_event(lambda text: text.startswith("motor off"), 10 * arm.consumer_s, after=t_on)
        assert off["event"] == "motor off: heartbeat lost, 0x6007=2", arm.events()
        ratio = (off["t"] - t_kill) / arm.consumer_s
        assert 0 < ratio <= 1.5, f"{DRIVE} went off {off['t'] - t_kill:.3f} s after SIGKILL"
        time.sleep(3 * arm.consumer_s)
        assert second.poll() is None, "the other user's jog ended"
        assert not [e for e in arm.events(OTHER_DRIVE) if e["t"] >= since2 and e["event"].startswith("motor off")]
    finally:
        finish(first) if first.poll() is not None else (first.kill(), finish(first))
        if second is not None:
            if second.poll() is None:
                second.send_signal(signal.SIGINT)
            code, out, err = finish(second)
            assert code == 0, f"{out}\n{err}"


def test_a_second_user_on_the_same_drive_is_refused_before_anything_is_sent(arm, tmp_path):
    """The drive lock is machine-wide: a jog of another user (another state directory) on the drive a
    jog moves is refused (exit 5) and the first jog goes on. Before, both took the drive, and the
    second cleared the first's dead-man entry as a leftover."""
    centre(arm, tmp_path, JOINT)
    since = time.monotonic()
    first = sherpa_as(arm, tmp_path, "a", "jog", JOINT, "--velocity", "0.05", "--apply", own_lock_dir=False)
    try:
        wait_jog_running(arm, first, DRIVE, since)
        code, out, err = finish(sherpa_as(arm, tmp_path, "b", "jog", JOINT, "--velocity", "0.05", "--for", "0.3",
                                          "--apply", own_lock_dir=False))
        assert code == 5, f"{out}\n{err}"
        assert f"another sherpa command (pid {first.pid}, another user or state directory) is using this drive" \
            in err, err
        assert first.poll() is None, "the first user's jog ended"
        assert not consumer_entries(arm, DRIVE, since)[1:], consumer_entries(arm, DRIVE, since)
    finally:
        if first.poll() is None:
            first.send_signal(signal.SIGINT)
        code, out, err = finish(first)
    assert code == 0, f"{out}\n{err}"


def test_a_foreign_producer_on_126_is_heard_and_the_jog_takes_another_id_which_its_kill_stops(arm, tmp_path):
    """R1: a foreign producer on id 126 (another host's tool) started before the jog: the jog listens,
    takes another id, and a SIGKILL of the jog still stops its motor by the consumer although 126 goes
    on being sent."""
    centre(arm, tmp_path, JOINT)
    producer = foreign_producer(arm, tmp_path, 126, 30)
    try:
        since = time.monotonic()
        proc = sherpa(arm, tmp_path, "jog", JOINT, "--velocity", "0.05", "--apply")
        t_on = wait_jog_running(arm, proc, DRIVE, since)
        time.sleep(0.2)
        t_kill = time.monotonic()
        os.kill(proc.pid, signal.SIGKILL)
        finish(proc)
        off = arm.wait_event(lambda text: text.startswith("motor off"), 10 * arm.consumer_s, after=t_on)
        assert off["event"] == "motor off: heartbeat lost, 0x6007=2", arm.events()
        assert 0 < (off["t"] - t_kill) / arm.consumer_s <= 1.5
        assert producer.poll() is None, "the producer stopped early: the test proves nothing"
    finally:
        producer.kill()
        producer.wait()


def test_a_foreign_producer_starting_on_the_jogs_own_id_stops_the_jog(arm, tmp_path):
    """R1: a heartbeat on the command's own id that it did not send (another host that took it at
    the same moment) ends the jog with exit 1 and the reason, every motor off."""
    proc, t_on = start_jog(arm, tmp_path)
    producer = foreign_producer(arm, tmp_path, 126, 30)
    try:
        code, out, err = finish(proc)
    finally:
        producer.kill()
        producer.wait()
    assert code == 1, f"{out}\n{err}"
    assert "another node sends heartbeats as 126, this command's dead-man id, on bus can1" in err, err
    assert [e for e in motor_offs(arm, t_on)], arm.events()


def test_a_drive_another_host_arms_on_the_jogs_own_id_stops_the_jog(arm, tmp_path):
    """R1: during the jog another host arms a drive the jog does not move (wrist_1a) to watch the jog's
    id: the jog's heartbeat would keep that drive's motor on after the other host dies. The jog ends
    with exit 1 naming the drive, its motor off; the other drive is never written by the jog."""
    from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
    from sherpa_cli.bus.session import ArmSession, resolve_target

    proc, t_on = start_jog(arm, tmp_path)
    cfg = apply_bus_map(load_config(ROOT / arm.config), parse_bus_map([arm.bus_map]))
    ref = resolve_target(cfg, OTHER_DRIVE)
    entry = (126 << 16 | 500).to_bytes(4, "little")
    try:
        with ArmSession.open(cfg, buses=[ref.bus]) as s:
            s.sdo(ref).download(0x1016, 1, entry)
        code, out, err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            finish(proc)
        with ArmSession.open(cfg, buses=[ref.bus]) as s:
            s.sdo(ref).download(0x1016, 1, bytes(4))
    assert code == 1, f"{out}\n{err}"
    assert f"{OTHER_DRIVE} (can1:50), a drive this command does not arm, watches its dead-man id 126" in err, err
    assert "Traceback" not in err
    assert [e for e in motor_offs(arm, t_on)], arm.events()


SEND = """\
import sys
from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
from sherpa_cli.bus.links import open_bus
from sherpa_cli.config import load_config
import can
config, bus_map, bus, can_id, data = sys.argv[1:6]
cfg = apply_bus_map(load_config(config), parse_bus_map(bus_map.split(",")))
link = open_bus(cfg.buses[bus])
try:
    link.send(can.Message(arbitration_id=int(can_id, 16), data=bytes.fromhex(data), is_extended_id=False))
finally:
    link.shutdown()
"""


def send_frame(arm: Arm, tmp_path, bus: str, can_id: int, data: bytes) -> None:
    """One frame from another node (another host's tool) on ``bus``."""
    done = subprocess.run([sys.executable, "-c", SEND, arm.config, arm.bus_map, bus, f"{can_id:X}", data.hex()],
                          cwd=ROOT, env=_env(tmp_path), capture_output=True, text=True, timeout=EXIT_TIMEOUT)
    assert done.returncode == 0, done.stderr


def test_a_drive_reset_during_a_jog_leaves_no_notes_that_make_the_next_command_refuse(arm, tmp_path):
    """NMT reset node from another node during a jog: the jog stops (exit 1, the reset
    named); the drive's RAM is back at its flash values, so the next jog does not refuse it for
    notes of values the reset already put back, and `recover` has nothing to put back."""
    proc, _ = start_jog(arm, tmp_path)
    send_frame(arm, tmp_path, "can1", 0x000, bytes([0x81, NODE]))
    code, out, err = finish(proc)
    assert code == 1 and "NMT reset node" in err, f"{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "recover", DRIVE))
    assert code == 0 and ("nothing to recover" in out or "already holds every value" in out), f"{out}\n{err}"
    code, out, err = finish(sherpa(arm, tmp_path, "jog", JOINT, "--velocity", "0.05", "--for", "0.3", "--apply"))
    assert code == 0, f"{out}\n{err}"
    assert "did not finish" not in err, err


def test_scan_reset_is_refused_while_a_jog_runs_on_the_bus(arm, tmp_path):
    """A reset communication during a jog would put the drive's consumer back (its
    dead-man gone); `scan --reset --apply` refuses with exit 5 before sending, the jog runs on."""
    proc, t_on = start_jog(arm, tmp_path)
    try:
        code, out, err = finish(sherpa(arm, tmp_path, "scan", "--bus", "can1", "--reset", "--apply"))
        assert code == 5, f"{out}\n{err}"
        assert "is moving this drive: refused, nothing sent" in err and "Traceback" not in err, err
        assert proc.poll() is None, "the jog ended"
        assert not motor_offs(arm, t_on), arm.events()
    finally:
        proc.send_signal(signal.SIGINT)
        code, out, err = finish(proc)
    assert code == 0, f"{out}\n{err}"


ROUNDS = 20


@pytest.fixture
def long_arm(arm_process, tmp_path, rebaseline):
    """:func:`arm`, with a served simulator that lives 300 s (the default 60 s is shorter than 20 rounds)."""
    if arm_process is not None:
        arm_process.new_test()
        rebaseline()
        arm_process.before_command()
        yield Arm(arm_process.config, arm_process.bus_map, arm_process.event_log, shared=True)
        return
    log = tmp_path / "events.jsonl"
    proc, bus_map, output = _start_sim(tmp_path, "--event-log", str(log), "--duration", "300")
    assert proc is not None, f"sim did not start:\n{output}"
    try:
        yield Arm(_patient_config(tmp_path), bus_map, log)
    finally:
        _stop(proc)


def test_a_recording_beside_a_jog_on_one_drive_never_takes_the_jogs_sdo_answers(long_arm, tmp_path):
    """`log record` and a jog on one drive, started together 20 times: their SDO
    transfers (the recorder's TPDO set-up and restore, the guard's dead-man objects and checks) take
    turns on the drive's one SDO channel (bus/machine_lock.py TransferLock). Before, one run in a few
    ended the jog with "SDO upload of 0x1016:1: malformed answer (Node returned a value for 0x1A00:02
    instead)"."""
    centre(long_arm, tmp_path, JOINT)
    for i in range(ROUNDS):
        rec = sherpa(long_arm, tmp_path, "log", "record", DRIVE, "--rate", "100", "--for", "1", "-o",
                     str(tmp_path / f"rec-{i}.csv"))
        direction = "0.05" if i % 2 == 0 else "-0.05"  # back and forth: the joint stays near 0
        jog = sherpa(long_arm, tmp_path, "jog", JOINT, "--velocity", direction, "--for", "0.3", "--apply")
        j_code, j_out, j_err = finish(jog)
        r_code, r_out, r_err = finish(rec)
        assert "malformed" not in j_err + r_err and "Traceback" not in j_err + r_err, \
            f"round {i}:\n{j_out}\n{j_err}\n{r_out}\n{r_err}"
        assert j_code == 0 and r_code == 0, f"round {i}: jog {j_code}, record {r_code}:\n{j_err}\n{r_err}"
