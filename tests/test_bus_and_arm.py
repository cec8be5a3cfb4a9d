"""Bus layer (bus map, pacing, concurrency) and arm mechanics the drive core does not know about."""

from __future__ import annotations

import dataclasses
import threading
import time

import pytest

from sherpa_cli.bus.busmap import BusTarget, apply_bus_map, bus_kwargs, parse_bus_map
from sherpa_cli.bus.parallel import run_concurrently
from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.errors import CommunicationError, UsageError
from sherpa_cli.sim.arm import SimArm


def test_bus_map_parses_several_forms():
    mapping = parse_bus_map(["can0=socketcan:vcan0,can1=remote:127.0.0.1:54702", " can2 = virtual:x "])
    assert mapping == {"can0": BusTarget("socketcan", "vcan0"), "can1": BusTarget("remote", "127.0.0.1:54702"),
                       "can2": BusTarget("virtual", "x")}


@pytest.mark.parametrize("bad", ["can0", "can0=", "can0=socketcan", "=socketcan:vcan0", "can0=:vcan0"])
def test_bus_map_rejects_malformed_items(bad):
    with pytest.raises(UsageError, match="BUS=INTERFACE:CHANNEL"):
        parse_bus_map([bad])


def test_bus_map_changes_only_the_named_buses():
    cfg = load_config("configs/sherpa-arm.yaml")
    mapped = apply_bus_map(cfg, {"can1": BusTarget("socketcan", "vcan1")})
    assert bus_kwargs(mapped.buses["can1"]) == {"interface": "socketcan", "channel": "vcan1", "bitrate": 1000000}
    assert mapped.buses["can0"] == cfg.buses["can0"]


def test_open_failure_names_the_bus(tmp_path):
    cfg = load_config("configs/sherpa-arm.yaml")
    bad = apply_bus_map(cfg, {"can2": BusTarget("no_such_interface", "x")})
    from sherpa_cli.bus.links import open_links

    with pytest.raises(CommunicationError, match=r"bus can2 .*cannot open"):
        open_links(bad, ["can2"])


def test_run_concurrently_overlaps_and_keeps_order():
    barrier = threading.Barrier(3, timeout=2)  # passes only if all three run at the same time

    def job(value):
        def run():
            barrier.wait()
            if value == "b":
                raise RuntimeError("b failed")
            return value
        return run

    outcomes = run_concurrently({"a": job("a"), "b": job("b"), "c": job("c")})
    assert list(outcomes) == ["a", "b", "c"]
    assert outcomes["a"].value == "a" and outcomes["c"].value == "c"
    assert isinstance(outcomes["b"].error, RuntimeError) and not outcomes["b"].ok


def test_a_signal_while_waiting_for_the_jobs_is_not_a_jobs_error():
    """A SIGTERM (the entry's Terminated) that lands while the main thread waits for the jobs ends the
    command; it was recorded as the first job's error and swallowed, so a scan ran on to exit 0
    (seen under load: `sherpa --sim scan` ignored a SIGHUP at 0.2 s)."""
    import os
    import signal
    import time

    class Stop(BaseException):
        pass

    released = threading.Event()

    def handler(signum, frame):
        released.set()
        raise Stop

    def job():
        time.sleep(0.2)  # the main thread is waiting for this job by then (else Stop comes from submit)
        os.kill(os.getpid(), signal.SIGUSR1)
        released.wait(5)
        return "done"

    previous = signal.signal(signal.SIGUSR1, handler)
    try:
        with pytest.raises(Stop):
            run_concurrently({"a": job})
    finally:
        signal.signal(signal.SIGUSR1, previous)
    assert released.is_set()


def test_paced_network_keeps_the_send_gap():
    import can

    from sherpa_cli.bus.links import _paced_network_class

    now = [0.0]
    waits: list[float] = []
    net = _paced_network_class()(can.Bus(interface="virtual", channel="pace-test"))
    net.gap = 0.001
    net.clock = lambda: now[0]
    net.sleep = lambda s: (waits.append(round(s, 9)), now.__setitem__(0, now[0] + s))
    try:
        for _ in range(3):
            net.send_message(0x300 + 1, b"PX\x00\x00")
    finally:
        net.bus.shutdown()
    assert waits == [0.001, 0.001], "the first frame goes at once, each next one after the gap"


def test_a_joint_stops_at_its_hard_stop(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    # the joint powers up where PX reads 0 (else the simulator puts it away from its switch), so PX
    # reads the hard stop's position
    cfg = dataclasses.replace(load_config("configs/appendix-c/example1.yaml"), sim_power_up={"joint1": 0})
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        client = session.client(resolve_target(cfg, "drive1"))
        client.nmt_start()
        client.set("IL", 3, 4)  # switches off: only the mechanics stop the joint now
        client.set("IL", 4, 4)
        client.set("UM", 0, 2)
        client.motor_on()
        client.set("JV", 0, 2000)
        client.execute("BG")
        deadline = time.monotonic() + 2
        while time.monotonic() < deadline and session.sim.drives["drive1"].position < 240:
            time.sleep(0.02)
        time.sleep(0.05)
        assert session.sim.drives["drive1"].position == 240  # overshoot range edge of example 1
        assert client.get("PX") == 240


class _Stop(BaseException):
    pass


def _raising(signum, frame):
    raise _Stop(signum)


def test_a_signal_while_the_buses_close_is_delivered_after_every_bus_is_closed():
    """A SIGTERM half-way through closing left the other buses open (python-can's "VirtualBus was
    not properly shut down" at exit, seen with `sherpa --sim scan` and SIGHUP): the close runs to
    its end and the signal goes to the handler from before afterwards."""
    import os
    import signal
    from types import SimpleNamespace

    from sherpa_cli.bus.links import close_links

    closed: list[str] = []

    def network(name, signal_me):
        def disconnect():
            if signal_me:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(0.05)  # the handler runs on this (the main) thread meanwhile
            closed.append(name)
        return SimpleNamespace(notifier=None, disconnect=disconnect)

    links = {name: SimpleNamespace(network=network(name, name == "can0")) for name in ("can0", "can1", "can2")}
    previous = signal.signal(signal.SIGTERM, _raising)
    try:
        with pytest.raises(_Stop):
            close_links(links)  # type: ignore[arg-type]
        assert closed == ["can0", "can1", "can2"]
        assert signal.getsignal(signal.SIGTERM) is _raising
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_signals_held_leave_an_ignored_signal_ignored_and_deliver_nothing_without_one():
    import signal

    from sherpa_cli.bus.held_signals import signals_held

    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with signals_held():
            assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
            signal.raise_signal(signal.SIGHUP)
        assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, previous)


@pytest.mark.parametrize("where", ["building the SDO servers", "waiting for the pumps"])
def test_a_signal_while_the_in_process_arm_starts_leaves_no_bus_open(monkeypatch, where):
    """A Terminated half-way through SimArm.start (seen: SIGHUP at 0.5 s of `sherpa --sim scan`) stops
    the pumps it started and closes every bus it had opened."""
    import can

    import sherpa_cli.sim.sdo as sim_sdo
    from sherpa_cli.sim.arm import SimArm

    arm = SimArm.in_process(load_config("configs/sherpa-arm.yaml"))
    opened: list[can.BusABC] = []

    def factory(**kwargs):
        opened.append(can.Bus(**kwargs))
        return opened[-1]

    arm.bus_factory = factory
    if where == "building the SDO servers":
        real = sim_sdo.SdoServer
        built: list[object] = []

        def server(*args, **kwargs):
            if len(built) == 3:
                raise _Stop("SIGTERM")
            built.append(real(*args, **kwargs))
            return built[-1]

        monkeypatch.setattr(sim_sdo, "SdoServer", server)
    else:
        real_wait = threading.Event.wait

        def wait(self, timeout=None):
            if threading.current_thread() is threading.main_thread():
                raise _Stop("SIGTERM")
            return real_wait(self, timeout)

        monkeypatch.setattr(threading.Event, "wait", wait)
    with pytest.raises(_Stop):
        arm.start()
    monkeypatch.undo()
    assert len(opened) == 3 and all(bus._is_shutdown for bus in opened)
    assert not [t for t in threading.enumerate() if t.name.startswith("sim-") and t.is_alive()]
