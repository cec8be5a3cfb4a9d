"""The motion guard on the simulated arm (in-process, python-can virtual, real threads and time).

Every exit path must stop the motor, switch it off when the guard switched it on, and put back
the dead-man objects (checked in the simulated drive's od_writes and received frames).
"""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion.guard import MotionGuard, MotionStopped
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.sim.arm import SimArm

# the guard's own tests run its 300 ms dead-man on wall time (docs/testing.md): .ci/run
# runs `serial` tests alone, after the parallel run
pytestmark = pytest.mark.serial

CONFIG = """\
name: guard-test
protocol: {mo_settle: 0.05, sv_blackout: 0.2}
motion: {consumer_time_ms: 300}
buses:
  can0: {interface: socketcan, channel: can0}
drives:
  drive1: {bus: can0, node: 5, model: whistle-10/60}
  drive2: {bus: can0, node: 6, model: whistle-10/60}
joints:
  j1:
    drive: drive1
    cpr: 4000
    range: {min: -20000, max: 20000, margin: 100, overshoot: 100}
    velocity: {limit: 8000, trip: 12000}
    acceleration: {accel: 40000, decel: 40000}
    current: {continuous: 2.0, peak: 6.0, peak_time: 1}
"""
HOST = 126
CONSUMER_ENTRY = HOST << 16 | 300
ARMED = [(0x6007, 0, 2), (0x1029, 1, 2), (0x1016, 1, CONSUMER_ENTRY)]
RESTORED = [(0x1016, 1, 0), (0x1029, 1, 0), (0x6007, 0, 1)]


@pytest.fixture
def cfg(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return load_config(path)


def writes(session, name):
    with session.sim.lock:
        return [(i, s, v) for _, i, s, v in session.sim.drives[name].od_writes]


def sim_drive(session, name):
    return session.sim.drives[name]


def move(guard, ref, target):
    guard.enable(ref, 5)
    c = guard.client(ref)
    c.set("PA", 0, target)
    c.execute("BG")
    deadline = time.monotonic() + 5
    while c.get("MS") != 0:
        guard.check()
        assert time.monotonic() < deadline
        time.sleep(0.01)
    return c.get("PX")


def assert_stopped_and_restored(session, name="drive1", *, switched_on=True):
    d = sim_drive(session, name)
    assert not d.motor_on
    assert writes(session, name) == ARMED + RESTORED
    texts = [t for _, t in d.events]
    if switched_on:
        assert texts[-1] == "motor off: MO=0", texts


def test_position_move_ends_at_target_then_stops_and_restores(cfg):
    settings = MotionSettings.from_config(cfg)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        events = []
        with MotionGuard(s, [ref], settings=settings, on_event=events.append) as g:
            px = move(g, ref, 2500)
            sent = g.heartbeats_sent
        assert px == 2500
        assert sent >= 1
        (r,) = g.report.drives
        assert (r.drive, r.stopped_by, r.standstill, r.motor_off) == ("drive1", "ST", True, True)
        assert r.restored == ["0x1016:1", "0x1029:1", "0x6007:0"] and not r.problems
        assert g.report.reason == "end"
        assert_stopped_and_restored(s)
        # the host heartbeat: COB 0x700 + 126, one byte 0x05 (operational)
        hb = [data for _, can_id, data in sim_drive(s, "drive1").received if can_id == 0x700 + HOST]
        assert hb and set(hb) == {b"\x05"}
        assert s.sim.errors == []


def test_exception_in_the_body_stops_and_restores(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with (
            pytest.raises(RuntimeError, match="boom"),
            MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g,
        ):
            g.enable(ref, 5)
            c = g.client(ref)
            c.set("JV", 0, 4000)
            c.execute("BG")
            time.sleep(0.1)
            raise RuntimeError("boom")
        assert g.report.reason == "error"
        (r,) = g.report.drives
        assert r.stopped_by == "ST" and r.standstill and r.motor_off
        assert_stopped_and_restored(s)


def test_keyboard_interrupt_stops_and_restores(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with pytest.raises(KeyboardInterrupt), MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
            g.enable(ref, 5)
            c = g.client(ref)
            c.set("JV", 0, -4000)
            c.execute("BG")
            time.sleep(0.1)
            raise KeyboardInterrupt
        assert g.report.reason == "interrupted"
        assert g.report.drives[0].motor_off
        assert_stopped_and_restored(s)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_signal_to_the_process_stops_and_restores(cfg, signum):
    # what the process had (SIG_DFL, or SIG_IGN under nohup, which a CI runner may use)
    before = signal.getsignal(signum)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with (
            pytest.raises(MotionStopped, match=signal.Signals(signum).name),
            MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g,
        ):
            g.enable(ref, 5)
            c = g.client(ref)
            c.set("JV", 0, 4000)
            c.execute("BG")
            os.kill(os.getpid(), signum)  # delivered to this (the main) thread
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline:
                g.check()
                time.sleep(0.01)
        assert g.report.reason == signal.Signals(signum).name
        assert g.report.drives[0].stopped_by == "ST" and g.report.drives[0].motor_off
        assert_stopped_and_restored(s)
    # the handlers are put back: the process's own SIGTERM/SIGHUP handling again
    assert signal.getsignal(signum) is before and before in (signal.SIG_DFL, signal.SIG_IGN)


class LateSignal(Exception):
    pass


def test_a_signal_during_the_stop_of_a_motion_that_ended_is_delivered_after_the_stop(cfg):
    """A SIGTERM that comes while the guard stops a motion that ended by itself must not cut the
    stop short, nor be lost (an exit 0): once everything is back, it goes to the handler from before
    the guard. It is sent from another thread, as the kernel may hand it to any thread that does
    not block it while the main thread's stop sequence does."""
    def late(signum, frame):
        raise LateSignal(signal.Signals(signum).name)

    def on_event(text):
        if not (g._exiting and threading.current_thread() is threading.main_thread()) or sent:
            return
        sent.append(text)
        killer = threading.Thread(target=os.kill, args=(os.getpid(), signal.SIGTERM))
        killer.start()
        killer.join()
        deadline = time.monotonic() + 5
        while g._late_signal is None:  # the Python handler runs on this thread, between two bytecodes
            assert time.monotonic() < deadline, "the SIGTERM never reached the guard's handler"
            time.sleep(0.001)

    sent: list[str] = []
    previous = signal.signal(signal.SIGTERM, late)
    try:
        with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
            ref = resolve_target(cfg, "drive1")
            g = MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg), on_event=on_event)
            with pytest.raises(LateSignal, match="SIGTERM"), g:
                move(g, ref, 2000)
            assert sent, "the guard's stop sequence reported no event"
            assert g.report.reason == "end"  # the motion had ended: the signal stopped nothing
            assert g.report.drives[0].motor_off
            assert_stopped_and_restored(s)
            assert signal.getsignal(signal.SIGTERM) is late  # the handler from before is back
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_a_drive_in_fault_is_refused_with_the_decoded_reason(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with s.sim.lock:
            sim_drive(s, "drive2")._mf = 0x400000  # latched: a position limit trip
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        with pytest.raises(SafetyError) as info, MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)):
            pytest.fail("the body must not run")
        assert "drive2 (node 6): in fault" in str(info.value)
        assert "position limit exceeded (LL[3]/HL[3])" in str(info.value)
        assert writes(s, "drive1") == [] and writes(s, "drive2") == []  # the dead-man was never armed
        assert not sim_drive(s, "drive1").motor_on


def test_unit_mode_changes_only_when_needed_with_the_motor_off_first(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
            g.enable(ref, 5)  # UM is 5 already: no UM write
            g.enable(ref, 1)  # MO=0, UM=1, MO=1
            g.client(ref).set("TC", 0, 0.5)
            time.sleep(0.05)
        frames = [data for _, can_id, data in sim_drive(s, "drive1").received if can_id == 0x305 and len(data) == 8
                  and not data[3] & 0x40]
        sets = [(d[:2].decode(), int.from_bytes(d[4:], "little", signed=True)) for d in frames
                if d[:2] in (b"MO", b"UM")]
        assert sets == [("MO", 1), ("MO", 0), ("UM", 1), ("MO", 1), ("MO", 0), ("UM", 5)]
        (r,) = g.report.drives
        assert r.stopped_by == "TC=0 + ST" and "UM=5" in r.restored


def test_keep_leaves_the_dead_man_and_unit_mode(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg), keep=True) as g:
            g.enable(ref, 2)
        (r,) = g.report.drives
        assert r.kept == ["UM=2", "0x1016:1", "0x1029:1", "0x6007:0"] and r.restored == []
        assert writes(s, "drive1") == ARMED


def test_st_refused_in_speed_mode_falls_back_to_jv0_bg(cfg, monkeypatch):
    import dataclasses

    from sherpa_cli.config.model import SimDriveConfig

    cfg = dataclasses.replace(cfg, sim={"drive1": SimDriveConfig(st_refused_in_speed_mode=True)})
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
            g.enable(ref, 2)
            c = g.client(ref)
            c.set("JV", 0, 4000)
            c.execute("BG")
            time.sleep(0.1)
        (r,) = g.report.drives
        assert r.stopped_by == "JV=0 + BG" and r.standstill and r.motor_off and not r.problems


def test_a_hung_command_stops_the_heartbeat_and_the_drive_stops_itself(cfg):
    import dataclasses

    settings = dataclasses.replace(MotionSettings.from_config(cfg), liveness_timeout=0.2, request_bound=0.01)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with MotionGuard(s, [ref], settings=settings) as g:
            g.enable(ref, 5)
            c = g.client(ref)
            c.set("JV", 0, 2000)
            c.execute("BG")
            t0 = time.monotonic()
            while sim_drive(s, "drive1").motor_on:  # "hung": no check() for longer than the allowance
                assert time.monotonic() - t0 < 3
                time.sleep(0.01)
            with pytest.raises(Exception, match="no sign of life"):
                g.check()
        d = sim_drive(s, "drive1")
        assert any("heartbeat lost (0x6007=2)" in t for _, t in d.events)
        assert d.mf & 0x800
        assert g.report.drives[0].stopped_by == "motor was off"


def test_host_id_of_a_drive_is_refused(cfg):
    import dataclasses

    settings = dataclasses.replace(MotionSettings.from_config(cfg), host_node_id=5)
    with pytest.raises(Exception, match="host heartbeat id"):
        MotionGuard(None, [resolve_target(cfg, "drive1")], settings=settings)


def test_guard_in_a_worker_thread_leaves_signals_alone(cfg):
    errors = []

    def work():
        try:
            with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
                ref = resolve_target(cfg, "drive1")
                with MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
                    g.enable(ref, 5)
                assert g.report.drives[0].motor_off
        except BaseException as exc:  # noqa: BLE001  # pragma: no cover - shown by the assert below
            errors.append(exc)

    t = threading.Thread(target=work)
    t.start()
    t.join(20)
    assert errors == []


# -- the motion: config section ----------------------------------------------------------------------

def test_motion_settings_defaults_and_heartbeat_period():
    from sherpa_cli.config import load_config as load

    arm = load(Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml")
    s = MotionSettings.from_config(arm)
    assert (s.host_node_id, s.consumer_time_ms, s.loss_action, s.comm_error_behaviour) == (126, 500, 2, 2)
    assert s.heartbeat_period == 0.125 and s.consumer_entry == 0x7E01F4
    assert s.poll_interval == 0.01 and s.request_bound == pytest.approx(0.2)


@pytest.mark.parametrize("motion,message", [
    ("{host_node_id: 5}", "host_node_id 5 is the node id of drive 'drive1'"),
    ("{host_node_id: 0}", "host_node_id 0 out of range 1..127"),
    ("{consumer_time_ms: 70000}", "consumer_time_ms 70000 must be 1..65535"),
    ("{consumer_time_ms: 60000}", "consumer_time_ms 60000 is above the safe bound 2000 ms"),
    ("{loss_action: 0}", "loss_action 0 is refused (the safe bound is 1..3): a drive would keep moving"),
    ("{liveness_timeout: 1.0e+9}", "liveness_timeout 1000000000.0 s is above the safe bound 10 s"),
    ("{liveness_timeout: .nan}", "liveness_timeout"),
    ("{consumer_time_ms: 200, heartbeat_period_ms: 150}", "at most half of consumer_time_ms"),
    ("{loss_action: 4}", "loss_action 4 must be 0..3"),
    ("{stop_method: brake}", "stop_method 'brake': expected one of auto, st, jv0"),
    ("{velocity_unit_mode: 3}", "velocity_unit_mode 3"),
    ("{standstill_timeout: 0}", "standstill_timeout 0.0 s must be > 0"),
    ("{standstill_velocity: -1}", "standstill_velocity -1 counts/s must be 0..1000"),
    ("{bus_error_passive: ignore}", "bus_error_passive 'ignore': expected one of stop, warn"),
    ("{bus_check_interval: 0}", "bus_check_interval 0.0 s must be 0.01..5"),
    ("{hostid: 3}", "hostid"),
])
def test_motion_config_errors_name_the_key(tmp_path, motion, message):
    from sherpa_cli.errors import ConfigError

    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG.replace("motion: {consumer_time_ms: 300}", f"motion: {motion}"), encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert message in str(info.value) and "arm.yaml:3" in str(info.value)


def test_motion_config_round_trips_through_convert(tmp_path, cfg):
    from sherpa_cli.config import dump_native, load_config_text

    again = load_config_text(dump_native(cfg), "again.yaml")
    assert again.motion == cfg.motion and again.motion.consumer_time_ms == 300


# -- the exit's safety defects -----------------------------------------------------------------------

def test_a_failed_mo0_keeps_the_dead_man_armed_and_says_so(cfg, monkeypatch):
    from sherpa_cli.errors import CommunicationError

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with (
            pytest.raises(SafetyError, match="MO=0: no reply"),
            MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g,
        ):
            g.enable(ref, 2)
            c = g.client(ref)

            def lost(*a, **k):
                raise CommunicationError("no reply")
            monkeypatch.setattr(c, "motor_off", lost)
            monkeypatch.setattr(c, "set", lambda *a, **k: None if a[0] != "UM" else lost())
        (r,) = g.report.drives
        assert not r.motor_off
        assert r.kept == ["UM=2 (motor not confirmed off)", "0x1016:1 (stop failed)", "0x1029:1 (stop failed)",
                          "0x6007:0 (stop failed)"] and r.restored == []
        assert any("UM=5 not restored" in p for p in r.problems)
        assert writes(s, "drive1") == ARMED  # nothing put back: the consumer still watches
        assert not g._hb_thread.is_alive()
        deadline = time.monotonic() + 5  # no heartbeat any more: the drive switches itself off
        while sim_drive(s, "drive1").motor_on:
            assert time.monotonic() < deadline
            time.sleep(0.02)


def test_an_os_error_on_one_drive_still_stops_the_other_and_the_heartbeat(cfg, monkeypatch):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        with (
            pytest.raises(SafetyError, match="OSError: bus gone"),
            MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g,
        ):
            for ref in refs:
                g.enable(ref, 5)
            c1 = g.client(refs[0])

            def gone(*a, **k):
                raise OSError("bus gone")
            monkeypatch.setattr(c1, "execute", gone)
            monkeypatch.setattr(c1, "motor_off", gone)
        r1, r2 = g.report.drives
        assert r1.stopped_by == "not stopped" and "0x1016:1 (stop failed)" in r1.kept
        assert (r2.stopped_by, r2.motor_off, r2.problems) == ("ST", True, [])
        assert not sim_drive(s, "drive2").motor_on and writes(s, "drive2") == ARMED + RESTORED
        assert not g._hb_thread.is_alive()


def test_a_hung_exit_step_lets_the_heartbeat_stop_within_that_step(cfg, monkeypatch):
    import dataclasses

    settings = dataclasses.replace(MotionSettings.from_config(cfg), liveness_timeout=0.2, request_bound=0.01)
    seen = {}
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        try:
            with MotionGuard(s, [ref], settings=settings) as g:
                g.enable(ref, 5)
                c = g.client(ref)
                real_get = c.get

                def get(letters, *a):
                    if letters == "PX" and g._exiting and "alive" not in seen:
                        time.sleep(1.0)  # the PX read hangs (longer than one step's allowance)
                        seen["alive"] = g._hb_thread.is_alive()
                    return real_get(letters, *a)
                monkeypatch.setattr(c, "get", get)
        except SafetyError:
            pass  # the drive tripped meanwhile: the restore may fail, that is not what this test is about
    assert seen == {"alive": False}


def test_the_original_unit_mode_is_recorded_before_the_um_write(cfg, monkeypatch):
    from sherpa_cli.errors import CommunicationError

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        with pytest.raises(CommunicationError), MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
            c = g.client(ref)
            real_set = c.set

            def half(letters, *a):
                real_set(letters, *a)
                if letters == "UM" and not g._exiting:
                    raise CommunicationError("UM written, reply lost")
            monkeypatch.setattr(c, "set", half)
            g.enable(ref, 2)
        assert "UM=5" in g.report.drives[0].restored


def test_a_leftover_consumer_entry_of_our_host_id_is_cleared_on_exit(cfg):
    import struct

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        s.client(ref).nmt_start()
        s.sdo(ref).download(0x1016, 1, struct.pack("<I", HOST << 16 | 500), name="consumer")  # a killed run's
        events = []
        with MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg), on_event=events.append) as g:
            g.enable(ref, 5)
        after = struct.unpack("<I", bytes(s.sdo(ref).upload(0x1016, 1, name="consumer"))[:4])[0]
    assert after == 0
    assert "0x1016:1" in g.report.drives[0].restored
    assert any("left over from a run that did not exit cleanly" in e for e in events)


def test_a_refused_drive_at_entry_sends_no_stop_to_a_drive_the_guard_never_switched_on(cfg):
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref1 = resolve_target(cfg, "drive1")
        c = s.client(ref1)  # another host moves drive1
        c.nmt_start()
        c.motor_on()
        c.set("JV", 0, 1000)
        c.execute("BG")
        with s.sim.lock:
            sim_drive(s, "drive2")._mf = 0x400000
        with (
            pytest.raises(SafetyError, match=r"drive2 .*in fault"),
            MotionGuard(s, [ref1, resolve_target(cfg, "drive2")], settings=MotionSettings.from_config(cfg)),
        ):
            pytest.fail("the body must not run")
        d1 = sim_drive(s, "drive1")
        executed = [d[:2] for _, cid, d in d1.received if cid == 0x305 and len(d) == 4]
        assert b"ST" not in executed and b"BG" in executed and d1.motor_on  # no ST from the refused guard


def test_standstill_allows_the_configured_velocity_noise():
    from types import SimpleNamespace

    from sherpa_cli.motion.stopping import stop_drive

    class Held:  # a stopped motor whose VX jitters by one count/s
        label, settings = "held", SimpleNamespace(mo_confirm_timeout=0.1)

        def get(self, letters, index=0):
            return {"MO": 1, "VX": -1}[letters]

        def execute(self, cmd):
            pass

    now = [0.0]

    def sleep(dt):
        now[0] += dt
    how, standstill, problems = stop_drive(Held(), unit_mode=5, clock=lambda: now[0], sleep=sleep,
                                           standstill_velocity=2)
    assert (how, standstill, problems) == ("ST", True, [])
    assert MotionSettings().standstill_velocity == 2


def test_every_moving_drive_hears_its_stop_before_a_slow_drive_is_waited_for(cfg, monkeypatch):
    # A first stop pass sends every moving drive its stop without waiting for replies; only then
    # does the careful per-drive exit (standstill, MO=0, restore) begin, where a dead drive's
    # timeouts would otherwise hold back the stop of the drives after it.
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")]
        order: list[str] = []
        with MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            for ref in refs:
                g.enable(ref, 2)
                c = g.client(ref)
                c.set("JV", 0, 2000)
                c.execute("BG")
            for ref in refs:
                c = g.client(ref)
                for name in ("send_only", "get", "execute", "motor_off"):
                    real = getattr(c, name)

                    def spy(*a, _real=real, _name=name, _drive=ref.name, **k):
                        order.append(f"{_drive}.{_name}({a[0] if a else ''})")
                        return _real(*a, **k)
                    monkeypatch.setattr(c, name, spy)
        first_exit_request = next(i for i, e in enumerate(order) if ".send_only" not in e)
        assert order[:first_exit_request] == ["drive1.send_only(ST)", "drive2.send_only(ST)"], order
        assert not sim_drive(s, "drive1").motor_on and not sim_drive(s, "drive2").motor_on
        assert [r.stopped_by for r in g.report.drives] == ["ST", "ST"]


def test_the_first_stop_pass_follows_the_stop_method_and_torque_mode(cfg, monkeypatch):
    import dataclasses
    settings = dataclasses.replace(MotionSettings.from_config(cfg), stop_method="jv0")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        sent: list[tuple] = []
        with MotionGuard(s, [ref], settings=settings) as g:
            g.enable(ref, 1)
            c = g.client(ref)
            real = c.send_only
            monkeypatch.setattr(c, "send_only", lambda *a: sent.append(a) or real(*a))
        assert sent == [("TC", 0, 0.0), ("JV", 0, 0), ("BG",)]
        assert not sim_drive(s, "drive1").motor_on


@pytest.mark.parametrize("keep", [False, True])
def test_a_profile_the_motion_changed_is_put_back_on_exit_unless_kept(cfg, keep):
    # SP/AC/DC are RAM settings a motion command scales (pair profiles, limit recovery): put back
    # on exit so a later SV never flashes them (keep=True leaves them, like UM and the dead-man).
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        s.client(ref).nmt_start()  # the interpreter answers in Operational only
        before = {k: s.client(ref).get(k) for k in ("SP", "AC", "DC")}
        with (
            pytest.raises(RuntimeError),
            MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg), keep=keep) as g,
        ):
            g.client(ref).set("SP", 0, 1)
            g.client(ref).set("DC", 0, before["DC"] // 2)
            raise RuntimeError("body failed")
        after = {k: s.client(ref).get(k) for k in ("SP", "AC", "DC")}
        (r,) = g.report.drives
        if keep:
            assert after == {**before, "SP": 1, "DC": before["DC"] // 2}
        else:
            assert after == before
            assert r.restored[:2] == [f"SP={before['SP']}", f"DC={before['DC']}"]


# -- hand-over (the interactive view's calibrate key: `home` guards the drive meanwhile) ---------------

def test_release_hands_a_drive_over_stopped_and_restored_and_adopt_takes_it_back(cfg):
    settings = MotionSettings.from_config(cfg)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r1, r2 = resolve_target(cfg, "drive1"), resolve_target(cfg, "drive2")
        with MotionGuard(s, [r1, r2], settings=settings) as g:
            g.enable(r1, 5)
            (out,) = g.release([r1])
            assert (out.stopped_by, out.motor_off) == ("ST", True)
            assert not sim_drive(s, "drive1").motor_on
            assert writes(s, "drive1") == ARMED + RESTORED  # put back: another guard may arm it now
            with pytest.raises(Exception, match="not guarded by this motion guard"):
                g.client(r1)
            # the other drive stays guarded; another guard takes drive1 meanwhile, one at a time
            g.keep_alive(10.0)  # the other guard's entry and motor-on confirmation give no sign of life to g
            with MotionGuard(s, [r1], settings=settings) as other:
                move(other, r1, 300)
            # the other guard is another command: its dead-man id is its own (126 is g's), so neither
            # heartbeat keeps the other's drives alive
            assert other.host_id == settings.host_id_pool[0] != g.host_id == HOST
            armed_other = [*ARMED[:2], (0x1016, 1, other.host_id << 16 | 300)]
            g.check()
            g.adopt([r1])
            assert writes(s, "drive1") == ARMED + RESTORED + armed_other + RESTORED + ARMED
            assert move(g, r1, 600) == 600
        assert {d.drive for d in g.report.drives} == {"drive1", "drive2"}
        assert_stopped_and_restored(s, "drive2", switched_on=False)
        assert writes(s, "drive1") == ARMED + RESTORED + armed_other + RESTORED + ARMED + RESTORED
        assert not sim_drive(s, "drive1").motor_on and s.sim.errors == []


def test_a_released_drive_not_taken_back_is_in_the_report_and_adopt_refuses_a_fault(cfg):
    settings = MotionSettings.from_config(cfg)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        r1 = resolve_target(cfg, "drive1")
        with MotionGuard(s, [r1], settings=settings) as g:
            g.release([r1])
            with s.sim.lock:
                sim_drive(s, "drive1")._mf |= 1 << 12  # a latched motor failure meanwhile
            with pytest.raises(SafetyError, match="in fault"):
                g.adopt([r1])
        (r,) = g.report.drives
        assert r.drive == "drive1" and r.stopped_by == "motor was off"
        assert writes(s, "drive1") == ARMED + RESTORED  # nothing armed on the faulted drive


def test_no_motion_after_a_sigterm_whose_exception_was_lost(cfg):
    """The entry noted a SIGTERM whose Terminated never arrived (errors.py): a guard that starts after
    it refuses before anything is sent, so nothing moves after the user asked to stop."""
    from sherpa_cli.errors import Terminated, note_signal

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        ref = resolve_target(cfg, "drive1")
        note_signal(signal.SIGTERM)
        try:
            with (pytest.raises(Terminated, match="SIGTERM"),
                  MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg))):
                pytest.fail("the body must not run")
        finally:
            note_signal(None)
        assert writes(s, "drive1") == [] and not sim_drive(s, "drive1").motor_on
        with MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)):  # nothing left held
            pass
