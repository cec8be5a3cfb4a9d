"""The motion guard's watch of its buses (motion/bus_watch.py): a bus the command moves on
that goes BUS-OFF (or ERROR-PASSIVE, `motion.bus_error_passive`)
ends the command, every drive that can still be reached is stopped -- those on the other buses first --
and the report names the bus and its state (exit 3). A bus-off on a bus the command does not move on
leaves it running.

First the watch alone (a fake link reader, error frames fed in, a fake clock); then the guard and
`jog` on the in-process simulated arm, on stepped time (sim/stepped.py: the clock moves only when the
tool waits), with the simulated host controller's state injected as the `bus status` tests do.
"""

from __future__ import annotations

import uuid
from dataclasses import replace

import pytest

from sherpa_cli.bus.errframes import decode_error_frame, encode_error_frame
from sherpa_cli.bus.errwatch import SeenError
from sherpa_cli.bus.linkstate import LinkStatus
from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import ExitCode
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.bus_watch import BusFaultError, GuardBusWatch
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.report import BusFault, GuardReport
from sherpa_cli.motion.request import parse_request
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.jog import run_jog
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.stepped import SteppedTime

# -- the watch alone --------------------------------------------------------------------------------


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt


class Links:
    """A fake ``read_link``: per bus the state it reads now (None: the interface reports none)."""

    def __init__(self, **states: str | None) -> None:
        self.states = dict(states)
        self.reads: list[str] = []
        self.restart_ms: int | None = None

    def __call__(self, bus: str) -> LinkStatus:
        self.reads.append(bus)
        return LinkStatus(bus, "socketcan", bus, "netlink", present=True, up=True, can_state=self.states.get(bus),
                          tec=255 if self.states.get(bus) == "BUS-OFF" else 0, rec=0, restart_ms=self.restart_ms)


def frame(bus: str, *kinds: str, tec: int = 0, rec: int = 0) -> SeenError:
    cls, data = encode_error_frame(list(kinds), tec=tec, rec=rec)
    return SeenError(bus, 0.0, decode_error_frame(cls, data))


def watch(links: Links, clock: Clock, trips: list, events: list, **kw) -> GuardBusWatch:
    w = GuardBusWatch(["can1", "can0"], read=links, where={"can0": "socketcan:can0", "can1": "socketcan:can1"},
                      interval=0.1, now=clock, on_trip=trips.append, on_event=events.append, **kw)
    w.start()
    return w


def test_a_bus_off_error_frame_trips_at_once_naming_the_bus():
    links, clock, trips, events = Links(), Clock(), [], []
    w = watch(links, clock, trips, events)  # the links report no state: error frames only
    assert w.poll() is None
    w.feed(frame("can1", "bus-off", tec=255))  # what the receive thread does
    assert len(trips) == 1 and w.error is trips[0]
    err = w.poll()
    w.feed(frame("can1", "bus-off", tec=255))  # the same state again: nothing new
    w.feed(frame("can0", "bus-off"))  # a second dead bus: reported, the first reason stays
    assert len(trips) == 1 and w.poll() is err
    assert [f.action for f in w.faults] == ["stopped the command", "seen while the command stopped"]
    assert isinstance(err, BusFaultError) and err.exit_code == ExitCode.BUS == 3
    assert str(err) == ("bus can1 (socketcan:can1): went BUS-OFF during the motion (TEC 255, REC 0; seen in an "
                        "error frame): stopping every drive of the command, those on the other buses first")
    assert err.bus == "can1" and err.problem == "bus-off" and "restart-ms" in (err.hint or "")
    assert w.faults[0] == BusFault("can1", "BUS-OFF", "an error frame", "stopped the command", 255, 0)
    w.stop()
    assert w.dead() == {"can0", "can1"} and not w.confirmed_dead("can1")  # the link reports no state: a frame said so


def test_a_bus_already_dead_when_the_watch_starts_trips_at_once():
    trips: list = []
    w = GuardBusWatch(["can1"], read=Links(can1="BUS-OFF"), now=Clock(), on_trip=trips.append)
    w._note("can1", "BUS-OFF", "the link state", 255, 0)  # noted before the start (not active): no trip
    assert trips == []
    w.start()
    assert len(trips) == 1 and w.poll() is trips[0]


def test_the_link_state_is_read_every_interval_and_trips_without_error_frames():
    links, clock, trips, events = Links(can0="ERROR-ACTIVE", can1="ERROR-ACTIVE"), Clock(), [], []
    w = watch(links, clock, trips, events)
    assert links.reads == ["can0", "can1"]  # one reading at the start
    links.states["can0"] = "BUS-OFF"
    clock.t = 0.05
    assert w.poll() is None and links.reads == ["can0", "can1"]  # not due yet
    clock.t = 0.1
    err = w.poll()
    assert isinstance(err, BusFaultError) and err.bus == "can0"
    assert "went BUS-OFF during the motion (TEC 255, REC 0; seen in the link state)" in str(err)


@pytest.mark.parametrize(("state", "problem"), [("STOPPED", "stopped"), ("down", "down"), ("missing", "missing")])
def test_a_bus_that_stops_goes_down_or_disappears_is_dead_too(state, problem):
    links, clock, trips, events = Links(can0="ERROR-ACTIVE", can1="ERROR-ACTIVE"), Clock(), [], []
    w = watch(links, clock, trips, events)
    clock.t = 1.0

    def gone(bus: str) -> LinkStatus:
        if bus != "can1":
            return Links(can0="ERROR-ACTIVE")(bus)
        if state == "missing":
            return LinkStatus(bus, "socketcan", bus, "netlink", present=False)
        if state == "down":
            return LinkStatus(bus, "socketcan", bus, "netlink", present=True, up=False)
        return LinkStatus(bus, "socketcan", bus, "netlink", present=True, up=True, can_state=state)

    w._read = gone
    err = w.poll()
    assert isinstance(err, BusFaultError) and err.bus == "can1" and err.problem == problem
    assert w.dead() == {"can1"}


def test_error_passive_stops_by_default_and_only_warns_with_the_setting():
    links, clock, trips, events = Links(), Clock(), [], []
    w = watch(links, clock, trips, events)
    w.feed(frame("can1", "passive", tec=136))
    err = w.poll()
    assert isinstance(err, BusFaultError) and err.problem == "error-passive"
    assert "went ERROR-PASSIVE during the motion (TEC 136, REC 0" in str(err)
    assert "motion.bus_error_passive: warn" in (err.hint or "")

    trips2: list = []
    w2 = watch(Links(), Clock(), trips2, events := [], error_passive="warn")
    w2.feed(frame("can1", "passive", tec=136))
    assert w2.poll() is None and trips2 == []
    assert w2.faults == [BusFault("can1", "ERROR-PASSIVE", "an error frame",
                                  "warned (motion.bus_error_passive: warn)", 136, 0)]
    w2.feed(frame("can1", "active"))
    assert events[-1] == "bus can1: back to ERROR-ACTIVE (an error frame)"
    w2.feed(frame("can1", "bus-off", tec=255))  # bus-off always stops
    assert w2.poll() is not None and len(trips2) == 1


def test_nothing_trips_before_start_or_after_stop_and_other_buses_are_not_watched():
    links, clock, trips = Links(), Clock(), []
    w = GuardBusWatch(["can1"], read=links, now=clock, on_trip=trips.append)
    links.states["can0"] = "BUS-OFF"  # not a bus of this watch
    w.feed(frame("can1", "bus-off"))  # before start: no trip
    assert w.error is None and trips == []
    w.start()
    assert w.poll() is None  # the reading at the start says can1 reports no state: nothing known
    clock.t = 1.0
    assert w.poll() is None and links.reads == ["can1"]  # ... and it is not read again (vcan: nothing to say)
    w.feed(frame("can2", "bus-off"))  # not a bus of the command
    w.feed(frame("can1", "crc", "warning", tec=96))  # a warning is no reason to stop
    assert w.poll() is None and w.faults == []
    w.stop()
    w.feed(frame("can1", "bus-off"))
    assert w.error is None and trips == []
    with pytest.raises(ValueError, match="bus_error_passive 'ignore'"):
        GuardBusWatch(["can1"], read=links, error_passive="ignore")


def test_the_exit_waits_for_the_controllers_restart_once_and_reports_a_bus_still_dead():
    links, clock, trips, events = Links(can0="ERROR-ACTIVE", can1="ERROR-ACTIVE"), Clock(), [], []
    w = watch(links, clock, trips, events)
    links.states["can1"] = "BUS-OFF"
    links.restart_ms = 100
    clock.t = 0.1
    assert w.poll() is not None
    w.stop()
    assert w.dead() == {"can1"}
    pulses: list[float] = []

    def sleep(dt: float) -> None:
        clock.sleep(dt)
        if clock.t >= 0.25:
            links.states["can1"] = "ERROR-ACTIVE"  # the kernel restarted it after restart-ms

    assert w.back("can1", sleep=sleep, pulse=lambda: pulses.append(clock.t), max_wait=2.0)
    assert 0.25 <= clock.t <= 0.1 + 0.1 + 0.2 + 1e-9 and pulses  # restart-ms + two intervals at most
    assert events[-1] == "bus can1: back (ERROR-ACTIVE): its drives are stopped as usual"
    # a bus that stays dead: waited for once (restart-ms + 2 intervals), then given up at once
    links.states["can1"] = "BUS-OFF"
    w2 = watch(links, clock2 := Clock(), [], [])
    w2.stop()
    assert w2.dead() == {"can1"} and w2.confirmed_dead("can1")
    assert not w2.back("can1", sleep=clock2.sleep, pulse=lambda: None, max_wait=2.0)
    assert clock2.t == pytest.approx(0.3)
    assert not w2.back("can1", sleep=clock2.sleep, pulse=lambda: None, max_wait=2.0)
    assert clock2.t == pytest.approx(0.3)
    r = w2.unreached("drive1", "can1:6", "can1", 300)
    assert r.stopped_by == "not reached" and "bus can1 is BUS-OFF: no frame reaches the drive" in r.problems[0]
    assert "switches the motor off 300 ms after the last host heartbeat" in r.problems[0]
    assert r.line().startswith("drive1 (can1:6): NOT reached; kept 0x1016:1 (bus BUS-OFF)")
    off = w2.unreached("drive1", "can1:6", "can1", 300, motor_on=False)
    assert "no frame reaches the drive, its motor was off; `sherpa recover drive1 --apply`" in off.problems[0]


def test_the_report_names_the_bus_fault_first_and_keeps_it_in_json():
    report = GuardReport(reason="error", bus_faults=[BusFault("can1", "BUS-OFF", "an error frame",
                                                              "stopped the command", 255, 0)])
    assert report.lines() == ["bus can1: BUS-OFF (TEC 255, REC 0; seen in an error frame): stopped the command"]
    data = report.as_json()
    assert data["bus_faults"][0]["state"] == "BUS-OFF"
    assert GuardReport.from_json(data) == report
    assert "bus_faults" not in GuardReport().as_json()  # a clean run's JSON is as before


# -- the guard on the simulated arm, stepped time -----------------------------------------------------

CONFIG = """\
name: bus-watch-test
protocol: {mo_settle: 0.05, sv_blackout: 0.2, reply_timeout: 1.0, retries: 2}
motion: {consumer_time_ms: 300, bus_check_interval: 0.05}
buses:
  can0: {interface: socketcan, channel: can0}
  can1: {interface: socketcan, channel: can1}
drives:
  drive0: {bus: can0, node: 5, model: whistle-10/60}
  drive1: {bus: can1, node: 6, model: whistle-10/60}
joints:
  j0:
    drive: drive0
    cpr: 4000
    range: {min: -200000, max: 200000, margin: 100, overshoot: 100}
    velocity: {limit: 8000, trip: 12000}
    acceleration: {accel: 40000, decel: 40000}
    current: {continuous: 2.0, peak: 6.0, peak_time: 1}
  j1:
    drive: drive1
    cpr: 4000
    range: {min: -200000, max: 200000, margin: 100, overshoot: 100}
    velocity: {limit: 8000, trip: 12000}
    acceleration: {accel: 40000, decel: 40000}
    current: {continuous: 2.0, peak: 6.0, peak_time: 1}
sim:
  buses:
    can0: {restart_ms: 0}
    can1: {restart_ms: 0}
"""
JOG_S = 1.0  # simulated seconds a jog runs when nothing stops it
FAULT_AT = 0.2  # simulated seconds into the jog when the bus fails


@pytest.fixture
def cfg(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(CONFIG, encoding="utf-8")
    return load_config(path)


def with_sim_bus(cfg: ArmConfig, bus: str, **kw) -> ArmConfig:
    return replace(cfg, sim_buses={**cfg.sim_buses, bus: replace(cfg.sim_buses[bus], **kw)})


class Stepped:
    """The in-process arm on stepped time, and a session whose clients wait on it too."""

    def __init__(self, cfg: ArmConfig) -> None:
        self.cfg = cfg
        self.time = SteppedTime()
        token = uuid.uuid4().hex[:8]
        self.arm = SimArm(cfg, {b: {"interface": "virtual", "channel": f"busw-{token}-{b}"} for b in cfg.buses},
                          clock=self.time.clock)

    def session(self):
        return ArmSession.open(self.cfg, sim=self.arm)

    def prepare(self, s: ArmSession) -> None:
        arm = self.arm
        s.client_overrides.update(self.time.client_overrides(
            self.cfg.protocol.reply_timeout, self.cfg.protocol.retries,
            lambda: (sum(d.unheard for d in arm.drives.values()), sum(d.unheard_s for d in arm.drives.values()))))

    def set_state(self, bus: str, state: str) -> None:
        with self.arm.lock:
            self.arm.bus_controller(bus).set_state(state)

    def motor_on(self, name: str) -> bool:
        with self.arm.lock:
            return self.arm.drives[name].motor_on


def jog(cfg: ArmConfig, target: str, *, during=None, settings: MotionSettings | None = None):
    """`jog TARGET --velocity 2 --for 1` on stepped time; ``during(stepped)`` once, FAULT_AT s into it.
    Returns (the result or the error, the Stepped arm, events, motor states right after the jog)."""
    st = Stepped(cfg)
    events: list[str] = []
    fired: list[float] = []

    def progress(p) -> None:
        if during is not None and not fired and p.elapsed >= FAULT_AT:
            fired.append(p.elapsed)
            during(st)

    with st.session() as s:
        st.prepare(s)
        try:
            axis = resolve_axis(cfg, target)
            out = run_jog(s, axis, parse_request(axis, "velocity", velocity=2.0, duration=JOG_S),
                          settings=settings or MotionSettings.from_config(cfg), clock=st.time.now,
                          sleep=st.time.sleep, on_progress=progress, on_event=events.append)
        except BusFaultError as exc:
            out = exc
        after = {name: st.motor_on(name) for name in cfg.drives}
        st.time.sleep(0.6)  # two consumer times of simulated time: a drive no frame reached stops by itself
        st.after_consumer = {name: st.motor_on(name) for name in cfg.drives}  # type: ignore[attr-defined]
        assert s.sim.errors == []
    return out, st, events, after


def test_a_bus_off_during_a_jog_on_its_bus_stops_it_and_names_the_bus(cfg):
    err, st, events, _after = jog(cfg, "drive1", during=lambda st: st.set_state("can1", "BUS-OFF"))
    assert isinstance(err, BusFaultError), err
    assert err.exit_code == 3 and err.bus == "can1" and err.problem == "bus-off"
    assert str(err).startswith("bus can1 (socketcan:can1): went BUS-OFF during the motion")
    report = err.motion_report  # type: ignore[attr-defined]
    assert report.reason == "error"
    assert report.lines()[0].startswith("bus can1: BUS-OFF (")
    assert report.bus_faults[0].action == "stopped the command"
    (drive,) = report.drives
    # restart_ms 0: the bus stays off, nothing reaches the drive; its consumer switches it off
    assert drive.drive == "drive1" and drive.stopped_by == "not reached"
    assert "bus can1 is BUS-OFF" in drive.problems[0]
    assert st.after_consumer["drive1"] is False
    assert any(e.startswith("bus can1: BUS-OFF") for e in events)


def test_a_bus_off_on_another_bus_leaves_the_jog_running(cfg):
    """The guard stops on bus-off of any bus it moves on; can0 is not the jog's bus."""
    result, _st, events, _after = jog(cfg, "drive1", during=lambda st: st.set_state("can0", "BUS-OFF"))
    assert not isinstance(result, BaseException), result
    assert result.ended_by == "time up" and result.duration >= JOG_S
    assert result.stop.bus_faults == []
    (drive,) = result.stop.drives
    assert drive.stopped_by == "ST" and drive.motor_off and drive.standstill
    assert not any("can0" in e for e in events)


def test_error_passive_stops_by_default_and_every_drive_is_stopped_as_usual(cfg):
    err, _st, _events, after = jog(cfg, "drive1", during=lambda st: st.set_state("can1", "ERROR-PASSIVE"))
    assert isinstance(err, BusFaultError) and err.problem == "error-passive" and err.exit_code == 3
    assert "went ERROR-PASSIVE during the motion" in str(err)
    (drive,) = err.motion_report.drives  # type: ignore[attr-defined]
    # an error-passive bus still carries frames: stopped, standstill and motor off confirmed
    assert drive.stopped_by == "ST" and drive.motor_off and drive.standstill and not drive.problems
    assert after["drive1"] is False


def test_error_passive_with_warn_goes_on_and_its_recovery_is_reported(cfg):
    settings = replace(MotionSettings.from_config(cfg), bus_error_passive="warn")

    def passive_then_back(st: Stepped) -> None:
        st.set_state("can1", "ERROR-PASSIVE")
        st.time.sleep(0.1)
        st.set_state("can1", "ERROR-ACTIVE")

    result, _st, events, _after = jog(cfg, "drive1", during=passive_then_back, settings=settings)
    assert not isinstance(result, BaseException), result
    assert result.ended_by == "time up"
    (fault,) = result.stop.bus_faults
    assert fault.bus == "can1" and fault.state == "ERROR-PASSIVE" and fault.action.startswith("warned")
    assert any(e.startswith("bus can1: back to ERROR-ACTIVE") for e in events)
    assert result.stop.drives[0].motor_off and not result.stop.drives[0].problems


def test_a_bus_that_restarts_ends_the_command_and_its_drive_is_stopped_as_usual(cfg):
    cfg = with_sim_bus(cfg, "can1", restart_ms=100)
    err, _st, events, after = jog(cfg, "drive1", during=lambda st: st.set_state("can1", "BUS-OFF"))
    assert isinstance(err, BusFaultError) and err.bus == "can1"
    (drive,) = err.motion_report.drives  # type: ignore[attr-defined]
    assert drive.stopped_by != "not reached" and drive.motor_off and not drive.problems, drive.line()
    assert any(e.startswith("bus can1: back (ERROR-ACTIVE)") for e in events)
    assert after["drive1"] is False


def test_a_command_on_two_buses_stops_the_other_bus_first_when_one_goes_bus_off(cfg):
    st = Stepped(cfg)
    refs = [resolve_target(cfg, "drive1"), resolve_target(cfg, "drive0")]  # the bus that fails first
    events: list[str] = []
    with st.session() as s:
        st.prepare(s)
        with pytest.raises(BusFaultError) as info, MotionGuard(
                s, refs, settings=MotionSettings.from_config(cfg), clock=st.time.now, sleep=st.time.sleep,
                on_event=events.append) as g:
            for ref in refs:
                g.enable(ref, 5)
                g.client(ref).set("JV", 0, 3000)
                g.client(ref).execute("BG")
            t0 = st.time.now()
            fired = False
            while True:
                g.check()
                for ref in refs:
                    g.query(ref, "PX")
                if st.time.now() - t0 >= FAULT_AT and not fired:
                    fired = True
                    st.set_state("can1", "BUS-OFF")
                assert st.time.now() - t0 < JOG_S, "the guard did not stop the command"
                st.time.sleep(0.01)
        assert info.value.bus == "can1"
        stop_at = st.time.now()
        assert stop_at - t0 < FAULT_AT + 0.2  # within a few bus checks of the fault, not a reply timeout
        assert [d.drive for d in g.report.drives] == ["drive0", "drive1"]  # the bus that carries frames first
        first, dead = g.report.drives
        assert first.stopped_by == "ST" and first.motor_off and first.standstill and not first.problems
        assert not st.motor_on("drive0")
        assert dead.stopped_by == "not reached"
        assert [f.bus for f in g.report.bus_faults] == ["can1"]
        st.time.sleep(0.6)
        assert not st.motor_on("drive1")  # its own consumer: no host heartbeat reached it
        assert s.sim.errors == []


def test_a_bus_off_error_frame_alone_stops_the_jog_and_a_bus_that_still_answers_is_stopped_as_usual(cfg):
    """The error-frame path on its own: another sender's CAN_ERR_BUSOFF frame on the jog's bus while
    the controller itself stays ERROR-ACTIVE (what the vcan guest test does on kernel vcan)."""
    import can

    others: list[can.BusABC] = []

    def error_frame(st: Stepped) -> None:
        other = can.Bus(interface="virtual", channel=st.arm.endpoints["can1"]["channel"])
        others.append(other)
        cls, data = encode_error_frame(["bus-off"], tec=255, rec=0)
        other.send(can.Message(arbitration_id=cls, data=data, is_extended_id=False, is_error_frame=True))

    try:
        err, _st, _events, after = jog(cfg, "drive1", during=error_frame)
    finally:
        for other in others:
            other.shutdown()
    assert isinstance(err, BusFaultError), err
    assert "went BUS-OFF during the motion (TEC 255, REC 0; seen in an error frame)" in str(err)
    (drive,) = err.motion_report.drives  # type: ignore[attr-defined]
    # the link reads ERROR-ACTIVE again: the drive is reached, stopped and switched off as on any exit
    assert drive.stopped_by == "ST" and drive.motor_off and drive.standstill and not drive.problems
    assert after["drive1"] is False


def test_on_a_link_without_a_controller_state_an_error_frame_trips_and_the_drive_is_probed_then_stopped():
    """What the vcan guest test checks, on python-can virtual without --sim: the link reports no
    controller state (read once, not again), so only the BUS-OFF error frame says the bus is off; the
    exit probes the drive with one request, it answers, and it is stopped and switched off as usual."""
    import time

    import can

    from sherpa_cli.config import load_config_text

    channel = f"busw-plain-{uuid.uuid4().hex[:8]}"
    cfg = load_config_text(f"""\
name: bus-watch-plain
protocol: {{mo_settle: 0.05, sv_blackout: 0.2}}
motion: {{consumer_time_ms: 300, bus_check_interval: 0.05}}
buses:
  can0: {{interface: virtual, channel: {channel}}}
drives:
  drive1: {{bus: can0, node: 5, model: whistle-10/60}}
""", "plain.yaml")
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": channel}}).start()
    other = can.Bus(interface="virtual", channel=channel)
    try:
        with ArmSession.open(cfg) as s:  # no sim: read_link falls back to python-can (virtual: no state)
            ref = resolve_target(cfg, "drive1")
            with pytest.raises(BusFaultError) as info, MotionGuard(s, [ref], settings=MotionSettings.from_config(cfg)) as g:
                g.enable(ref, 5)
                g.client(ref).set("JV", 0, 2000)
                g.client(ref).execute("BG")
                cls, data = encode_error_frame(["bus-off"], tec=255, rec=1)
                other.send(can.Message(arbitration_id=cls, data=data, is_extended_id=False, is_error_frame=True))
                deadline = time.monotonic() + 10
                while time.monotonic() < deadline:
                    g.check()
                    g.query(ref, "PX")
                    time.sleep(0.01)
                pytest.fail("the guard did not stop the command")
            assert "bus can0 (virtual:" in str(info.value) and "seen in an error frame" in str(info.value)
            (drive,) = g.report.drives
            assert drive.stopped_by not in ("not reached", "not stopped") and drive.motor_off, drive.line()
            with arm.lock:
                assert not arm.drives["drive1"].motor_on
    finally:
        other.shutdown()
        arm.stop()
