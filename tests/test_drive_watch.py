"""The guard's watch of its drives on the simulated arm, in process:
an error EMCY from a moving drive, an NMT command another node sends, a drive's heartbeat that goes
silent, and a foreign SDO write that disarms the dead-man each stop every drive of the command.

"Another node" is a second python-can virtual bus on the simulated arm's channel: what it sends
reaches the drives and the command alike, as on a real bus.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable

import can
import pytest

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.elmo.faults import decode_emcy
from sherpa_cli.errors import CommunicationError, ExitCode, SafetyError
from sherpa_cli.motion.drive_watch import DriveRestartedError, DriveSilentError, DriveWatch, DriveWatchError
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.sim.arm import SimArm

# a 200 ms heartbeat, silent after 0.6 s, on wall time (docs/testing.md): .ci/run runs
# `serial` tests alone, after the parallel run
pytestmark = pytest.mark.serial

CONFIG = """\
name: watch-test
protocol: {mo_settle: 0.05, sv_blackout: 0.2, reply_timeout: 1.0, retries: 2}
motion: {consumer_time_ms: 300, deadman_check_interval: 0.1}
buses:
  can0: {interface: socketcan, channel: can0}
drives:
  drive1: {bus: can0, node: 5, model: whistle-10/60}
  drive2: {bus: can0, node: 6, model: whistle-10/60}
sim:
  drives:
    drive1: {heartbeat_ms: 200}
"""
# drive1's heartbeat: silent after 3 periods (0.6 s); with 20 ms (silent after 60 ms) a loaded machine
# that held the in-process simulator's pump for 60 ms turned an EMCY or NMT test into a silence stop
NODE1, NODE2 = 5, 6
BOUND = 5.0  # s a test waits at most for the watch (it needs far less: a few poll periods)


@pytest.fixture
def cfg(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return load_config(path)


@pytest.fixture
def other_node(request):
    """A bus of "another node" on the arm's channel; opened by :func:`open_other`."""
    buses: list[can.BusABC] = []
    yield buses
    for b in buses:
        b.shutdown()


def open_other(session: ArmSession, buses: list) -> can.BusABC:
    ep = dict(session.sim.endpoints["can0"])
    bus = can.Bus(interface="virtual", channel=ep["channel"])
    buses.append(bus)
    return bus


def emcy_frame(node: int, code: int, register: int = 1) -> can.Message:
    return can.Message(arbitration_id=0x80 + node, data=struct.pack("<HBBHH", code, register, 0, 0, 0),
                       is_extended_id=False)


def start_both(g, refs):
    for ref in refs:
        g.enable(ref, 5)
        c = g.client(ref)
        c.set("JV", 0, 3000)
        c.execute("BG")


def run_until_stopped(g, refs, during=None, bound=BOUND):
    """Poll like a jog (PX, SR through the guard) until the guard raises; ``during()`` once moving."""
    deadline = time.monotonic() + bound
    started = None
    while time.monotonic() < deadline:
        g.check()
        for ref in refs:
            g.query(ref, "PX")
        if during is not None and started is None:
            started = time.monotonic()
            during()
        time.sleep(0.01)
    raise AssertionError("the guard did not stop the command")


def assert_all_stopped(s, g):
    for name in ("drive1", "drive2"):
        assert not s.sim.drives[name].motor_on, name
    assert {r.drive for r in g.report.drives} == {"drive1", "drive2"}
    for r in g.report.drives:
        assert r.stopped_by != "not stopped", r.line()


def test_an_error_emcy_from_a_moving_drive_stops_every_drive_of_the_command(cfg, other_node):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        with pytest.raises(DriveWatchError) as info, MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            run_until_stopped(g, refs, during=lambda: other.send(emcy_frame(NODE2, 0x8611)))
        msg = str(info.value)
        assert msg.startswith("drive2 (node 6): EMCY 0x8611: position tracking error"), msg
        assert "stopping every drive of the command" in msg
        assert info.value.exit_code == ExitCode.PROBLEM
        assert g.report.reason == "error"
        assert_all_stopped(s, g)


def test_warning_class_emcys_are_counted_and_a_flood_never_stalls_the_command(tmp_path, other_node):
    # The in-process simulator shares this process: on a loaded machine its pump, busy with the two
    # floods of 3000 frames, once kept drive1's heartbeat (20 ms then) away 0.37 s and the silence watch
    # stopped the command first. Heartbeats of 0.5 s (silent after 1.5 s) leave the floods the test.
    # The same pump answers the guard's SDO reads on its way out, after the floods: with four busy
    # processes beside the suite that took more than the real bus's 0.3 s, hence 2 s here.
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("drive1: {heartbeat_ms: 200}", "drive1: {heartbeat_ms: 500}\n"
                                   "    drive2: {heartbeat_ms: 500}")
                    .replace("retries: 2}", "retries: 2, sdo_timeout: 2.0}"), encoding="utf-8")
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        assert [d.settings.heartbeat_ms for d in s.sim.drives.values()] == [500, 500]
        assert cfg.protocol.sdo_timeout == 2.0
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        with pytest.raises(DriveWatchError, match="EMCY 0x2340: short circuit"), \
                MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            for _ in range(3000):  # a flood of warnings (CAN message lost): the motion goes on
                other.send(emcy_frame(NODE1, 0x8110))
            for _ in range(20):  # polls still answered at their pace, nothing stopped
                g.check()
                g.query(refs[0], "PX")
            assert s.sim.drives["drive1"].motor_on and s.sim.drives["drive2"].motor_on
            t0 = time.monotonic()
            for _ in range(3000):  # then a flood of errors: the first one stops the command
                other.send(emcy_frame(NODE1, 0x2340))
            run_until_stopped(g, refs)
        assert time.monotonic() - t0 < BOUND
        assert_all_stopped(s, g)


def test_a_configured_warning_code_does_not_stop_the_motion(tmp_path, other_node):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("deadman_check_interval: 0.1", "deadman_check_interval: 0.1, "
                                   "emcy_warning_codes: [0x8611]"), encoding="utf-8")
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1")]
        other = open_other(s, other_node)
        with MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            other.send(emcy_frame(NODE1, 0x8611))
            for _ in range(20):
                g.check()
                g.query(refs[0], "PX")
                time.sleep(0.01)
            assert s.sim.drives["drive1"].motor_on
        assert g.report.ok


@pytest.mark.parametrize("command,what", [(0x02, "NMT Stopped"), (0x80, "NMT Pre-operational")])
@pytest.mark.parametrize("target", [NODE1, 0])
def test_an_nmt_command_from_another_node_ends_the_command_at_once(cfg, other_node, command, what, target):
    """The drive made deaf by NMT Stopped would keep the command waiting 3 x 1 s per request."""
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        t_sent: list[float] = []

        def send() -> None:
            t_sent.append(time.monotonic())
            other.send(can.Message(arbitration_id=0, data=bytes([command, target]), is_extended_id=False))

        with pytest.raises(DriveWatchError) as info, MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            run_until_stopped(g, refs, during=send)
        took = time.monotonic() - t_sent[0]
        assert f"another node sent {what}" in str(info.value)
        # a deaf drive costs 3 attempts x 1 s per request; the margin below is for a loaded machine
        assert took < 2.5, f"{took:.2f} s: the command waited for a deaf drive"
        assert_all_stopped(s, g)


def slow_boot_cfg(tmp_path):
    """drive1 takes 0.3 s to boot after a reset, deaf meanwhile (a real drive is not instant)."""
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("{heartbeat_ms: 200}", "{heartbeat_ms: 200, boot_ms: 300}"), encoding="utf-8")
    return load_config(path)


def test_a_drive_another_node_resets_is_started_after_its_boot_up_and_stopped_cleanly(tmp_path, other_node):
    """The exit's NMT start sent while the drive still boots is lost: the drive would come up in
    Pre-operational, deaf to every exit step ("MO=0 not confirmed", nothing put back)."""
    cfg = slow_boot_cfg(tmp_path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        reset = can.Message(arbitration_id=0, data=bytes([0x81, NODE1]), is_extended_id=False)
        with pytest.raises(DriveWatchError, match="another node sent NMT reset node"), \
                MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            run_until_stopped(g, refs, during=lambda: other.send(reset))
        assert_all_stopped(s, g)
        assert s.sim.drives["drive1"].boots == 2
        assert [r.line() for r in g.report.drives if r.problems] == []


def test_a_trip_between_two_requests_is_raised_by_the_next_request_not_its_timeout(tmp_path, other_node):
    """The watch cuts short the request the command waits for; one sent after the trip went to a
    deaf drive, waited out its attempts and ended the command with "no answer" (exit 3), the reset
    unnamed. The inner clean-up's requests after it are not cut short."""
    cfg = slow_boot_cfg(tmp_path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        with pytest.raises(DriveWatchError, match="another node sent NMT reset node") as info, \
                MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            other.send(can.Message(arbitration_id=0, data=bytes([0x81, NODE1]), is_extended_id=False))
            deadline = time.monotonic() + BOUND
            while g._watch.error is None and time.monotonic() < deadline:
                time.sleep(0.005)  # no request meanwhile: the trip falls between two
            try:
                g.client(refs[0]).set("SP", 0, 1000)
            finally:
                assert g.client(refs[1]).get("SP") > 0  # the next request goes out again
        assert isinstance(info.value, DriveWatchError)
        assert_all_stopped(s, g)


def reset_before_motor_off(client, other, node: int, seen: Callable[[], bool]) -> None:
    """The client's next MO=0 (once) is preceded by an NMT reset node of ``node`` (0: every node) from
    the other node, and goes out once ``seen()`` says the watch noticed it (bounded)."""
    motor_off = client.motor_off

    def reset_then_motor_off(*args, **kwargs):
        client.motor_off = motor_off  # once
        other.send(can.Message(arbitration_id=0, data=bytes([0x81, node]), is_extended_id=False))
        deadline = time.monotonic() + BOUND
        while not seen() and time.monotonic() < deadline:
            time.sleep(0.005)
        return motor_off(*args, **kwargs)

    client.motor_off = reset_then_motor_off


def test_a_drive_reset_during_its_own_stop_is_stopped_once_more_once_it_booted(tmp_path, other_node):
    """A reset that lands in the middle of the exit (here: right before its MO=0): the step it
    cuts short and every later one would wait out their reply timeouts on a deaf drive."""
    cfg = slow_boot_cfg(tmp_path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        with MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            # the MO=0 goes out while the drive boots
            reset_before_motor_off(g.client(refs[0]), other, NODE1,
                                   lambda: g._watch.resetting("can0", NODE1))
            for _ in range(10):
                g.check()
                time.sleep(0.01)
            started = time.monotonic()
        took = time.monotonic() - started
        assert_all_stopped(s, g)
        by = {r.drive: r for r in g.report.drives}
        assert by["drive1"].stopped_by == "reset during its stop" and by["drive1"].motor_off, by["drive1"].line()
        assert g.report.ok, [r.line() for r in g.report.drives]
        # one MO confirmation waits 20 s and each later step 2 x 1 s on a deaf drive; a loaded machine's margin
        assert took < 10, f"{took:.1f} s"


def test_a_drive_whose_heartbeat_goes_silent_stops_the_others(tmp_path):
    # the guard's re-read of drive1's dead-man entry would find the dead drive first (an SDO timeout):
    # here only its heartbeat may tell
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("deadman_check_interval: 0.1", "deadman_check_interval: 10"), encoding="utf-8")
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        with pytest.raises(DriveSilentError, match=r"drive1 \(node 5\): its heartbeat went silent") as info, \
                MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            for _ in range(40):  # a few of its heartbeats (200 ms)
                g.check()
                time.sleep(0.01)
            with s.sim.lock:
                s.sim.drives["drive1"].die()
            deadline = time.monotonic() + BOUND
            while time.monotonic() < deadline:  # no request to drive1: only its heartbeat tells
                g.check()
                g.query(refs[1], "PX")
                time.sleep(0.01)
        assert isinstance(info.value, CommunicationError)
        assert not s.sim.drives["drive2"].motor_on
        by = {r.drive: r for r in g.report.drives}
        assert by["drive1"].stopped_by == "not reached"
        assert by["drive2"].motor_off


def test_a_foreign_sdo_write_that_disarms_the_dead_man_stops_the_command(cfg, other_node):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        disarm = can.Message(arbitration_id=0x600 + NODE2, data=bytes([0x23, 0x16, 0x10, 1, 0, 0, 0, 0]),
                             is_extended_id=False)
        with pytest.raises(DriveWatchError, match=r"drive2 \(node 6\): its dead-man entry 0x1016:1 reads "
                                                  r"0x00000000, not the 0x007E012C"), \
                MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            run_until_stopped(g, refs, during=lambda: other.send(disarm))
        assert_all_stopped(s, g)


def test_an_error_emcy_from_a_drive_with_its_motor_off_is_only_logged(cfg, other_node):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        with MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs[:1])  # drive2 is guarded, its motor stays off
            other.send(emcy_frame(NODE2, 0x8611))
            for _ in range(20):
                g.check()
                g.query(refs[0], "PX")
                time.sleep(0.01)
        assert g.report.ok


# -- the watch alone, on fakes and a fake clock -------------------------------------------------------

class FakeNetwork:
    def __init__(self) -> None:
        self.subs: dict[int, list] = {}

    def subscribe(self, can_id, cb):
        self.subs.setdefault(can_id, []).append(cb)

    def unsubscribe(self, can_id, cb=None):
        self.subs[can_id].remove(cb)

    def deliver(self, can_id, data):
        for cb in list(self.subs.get(can_id, [])):
            cb(can_id, bytearray(data), 0.0)


class FakeClient:
    def __init__(self) -> None:
        self.emcy_cbs: list = []
        self.aborted: list = []
        self.silent = False

    def on_emcy(self, cb):
        self.emcy_cbs.append(cb)

    def remove_emcy(self, cb):
        self.emcy_cbs.remove(cb)

    def abort_pending(self, error):
        self.aborted.append(error)

    def clear_abort(self):
        self.cleared = True


def make_watch():
    now = [0.0]
    net, client = FakeNetwork(), FakeClient()
    w = DriveWatch(lambda bus: net, now=lambda: now[0], min_silence=0.03)
    w.add("can0", 5, "d (node 5)", client)
    w.start()
    return w, net, client, now


def test_heartbeat_states_other_than_operational_trip_and_abort_the_pending_request():
    w, net, client, _ = make_watch()
    net.deliver(0x705, b"\x05")
    assert w.poll() is None
    net.deliver(0x705, b"\x04")
    assert isinstance(w.poll(), DriveWatchError) and "heartbeat says Stopped" in str(w.error)
    assert client.aborted == [w.error]


def test_silence_is_three_heartbeat_periods_on_the_watch_clock():
    w, net, client, now = make_watch()
    for t in (0.0, 0.1, 0.2):
        now[0] = t
        net.deliver(0x705, b"\x05")
    now[0] = 0.49
    assert w.poll() is None
    now[0] = 0.51
    assert isinstance(w.poll(), DriveSilentError) and client.silent


def test_after_stop_nothing_trips_and_after_close_every_subscription_is_undone():
    w, net, client, _ = make_watch()
    w.stop()
    net.deliver(0x705, b"\x04")
    net.deliver(0x000, bytes([0x02, 5]))
    assert w.poll() is None and not client.aborted
    assert client.cleared  # the guard's exit requests wait for their answers again
    w.close()
    assert all(not cbs for cbs in net.subs.values()) and not client.emcy_cbs


def test_after_stop_a_reset_is_followed_and_its_boot_up_ends_the_pending_request():
    """The guard's exit must know a drive another node reset: deaf until its boot-up, then in
    Pre-operational (the request it waited for is cut short, the exit starts it again)."""
    w, net, client, _ = make_watch()
    w.stop()
    net.deliver(0x000, bytes([0x81, 6]))  # another drive
    assert not w.resetting("can0", 5)
    net.deliver(0x000, bytes([0x81, 0]))  # every node
    assert w.resetting("can0", 5) and w.boots("can0", 5) == 0 and not client.aborted
    net.deliver(0x705, b"\x00")
    assert not w.resetting("can0", 5) and w.boots("can0", 5) == 1
    assert len(client.aborted) == 1 and isinstance(client.aborted[0], DriveRestartedError)
    assert w.poll() is None  # no trip: the exit is already under way


def test_warning_codes_and_error_reset_never_trip_a_moving_drive():
    w, _net, client, _ = make_watch()
    w.set_moving("can0", 5, True)
    for code in (0x0000, 0x6300, 0x8110):
        client.emcy_cbs[0](decode_emcy(struct.pack("<HBBHH", code, 0, 0, 0, 0)))
    assert w.poll() is None
    client.emcy_cbs[0](decode_emcy(struct.pack("<HBBHH", 0x8130, 0x11, 0, 0, 0)))
    assert isinstance(w.poll(), SafetyError) and "EMCY 0x8130: heartbeat event" in str(w.error)


def test_a_trip_of_the_outer_guard_leaves_a_drive_released_to_an_inner_guard_to_that_guard(cfg, other_node):
    """The live view hands a joint to `home`'s own guard while it keeps watching the others. A trip
    of the outer watch (an EMCY from drive2) must not cut short the inner guard's exit of drive1:
    it raised at the inner exit's first request, MO=0 went out without a stop from standstill and
    the dead-man stayed armed ("stop failed")."""
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        settings = MotionSettings.from_config(cfg)
        with pytest.raises(DriveWatchError, match=r"drive2 .*EMCY 0x8611"), MotionGuard(s, refs, settings=settings) as outer:
            start_both(outer, refs[1:])
            outer.release(refs[:1])
            with MotionGuard(s, refs[:1], settings=settings) as inner:
                start_both(inner, refs[:1])
                other.send(emcy_frame(NODE2, 0x8611))
                deadline = time.monotonic() + BOUND
                while outer._watch.error is None and time.monotonic() < deadline:
                    time.sleep(0.005)
                assert outer._watch.error is not None
            outer.check()
        (stop,) = inner.report.drives
        assert stop.motor_off and stop.standstill is not False and not stop.problems, stop.line()
        assert not any("stop failed" in k for k in stop.kept), stop.line()
        assert_all_stopped_drives(s)


def assert_all_stopped_drives(s):
    with s.sim.lock:
        assert not any(d.motor_on for d in s.sim.drives.values())


def test_without_set_echoes_a_set_after_a_trip_never_reaches_the_drive(tmp_path, other_node):
    """A drive that does not echo sets: the set went out first and the trip was raised after it."""
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("protocol: {", "protocol: {set_echo: false, "), encoding="utf-8")
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        with pytest.raises(DriveWatchError, match="EMCY 0x8611"), \
                MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            other.send(emcy_frame(NODE2, 0x8611))
            deadline = time.monotonic() + BOUND
            while g._watch.error is None and time.monotonic() < deadline:
                time.sleep(0.005)  # no request meanwhile: the trip falls between two
            g.client(refs[0]).set("JV", 0, 9000)
        with s.sim.lock:
            assert s.sim.drives["drive1"].ram["JV"] == 3000
        assert_all_stopped(s, g)


def test_drives_that_all_boot_again_before_their_turn_in_the_exit_are_stopped_cleanly(tmp_path, other_node):
    """NMT reset node to every node (node 0) during the first drive's stop: the second drive's
    boot-up, heard then, left its requests refused when its own turn came ("MO=0: ... booted
    again", the dead-man kept as "stop failed")."""
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("drive1: {heartbeat_ms: 200}", "drive1: {heartbeat_ms: 200, boot_ms: 300}\n"
                                   "    drive2: {boot_ms: 300}"), encoding="utf-8")
    cfg = load_config(path)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        other = open_other(s, other_node)
        with MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start_both(g, refs)
            # every node reset: drive2 boots while drive1's stop goes on
            reset_before_motor_off(g.client(refs[0]), other, 0, lambda: g._watch.boots("can0", NODE2) > 0)
            g.check()
        assert_all_stopped(s, g)
        assert [r.line() for r in g.report.drives if r.problems or "stop failed" in " ".join(r.kept)] == []
