"""A simulator's bus whose link goes down and up (`ip link set vcanN down` / `up`): the bus pump keeps
reopening it every ``link_retry_s``, logs one line per outage and serves again once the link is back;
`sherpa sim` never ends in a traceback.

This machine has no SocketCAN, so the interface is a python-can bus of the test's whose recv/send
raise python-can's CanOperationError (ENETDOWN) while the test holds it down. Nothing here depends on
wall time: the arm runs on a ManualClock and the test waits (bounded) for what the pump did.
"""

from __future__ import annotations

import errno
import logging
import queue
import struct
import threading
from pathlib import Path

import can
import pytest

from sherpa_cli.config import load_config
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.clock import ManualClock

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "tests" / "data" / "home-arm.yaml"
NODE = 10  # yaw_drive on can0
WAIT_S = 5.0  # wall time for the simulator's thread to get somewhere (a loaded machine)


class Link:
    """One kernel interface, across every bus the simulator opens on it."""

    def __init__(self, *, quiet_recv: bool = False) -> None:
        # quiet_recv: while down, receive only times out (a SocketCAN socket reports ENETDOWN once and
        # then stays silent) and only sends fail; else every receive fails too
        self.quiet_recv = quiet_recv
        self.down = False
        self.to_sim: queue.Queue[can.Message] = queue.Queue()
        self.from_sim: queue.Queue[can.Message] = queue.Queue()
        self.cond = threading.Condition()
        self.opened = 0
        self.failures = 0

    def open(self, **kwargs: object) -> can.BusABC:
        with self.cond:
            self.opened += 1
            self.cond.notify_all()
        return LinkBus(self)

    def fail(self) -> None:
        with self.cond:
            self.failures += 1
            self.cond.notify_all()
        raise can.CanOperationError("Network is down", error_code=errno.ENETDOWN)

    def wait_for(self, predicate, what: str) -> None:
        with self.cond:
            assert self.cond.wait_for(predicate, timeout=WAIT_S), what

    def ask(self, can_id: int, data: bytes, answer_id: int) -> bytes | None:
        """Send a frame to the simulator; the first frame on ``answer_id`` it sends back (None: none)."""
        self.to_sim.put(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        while True:
            try:
                msg = self.from_sim.get(timeout=WAIT_S)
            except queue.Empty:
                return None
            if msg.arbitration_id == answer_id:
                return bytes(msg.data)


class LinkBus(can.BusABC):
    def __init__(self, link: Link) -> None:
        self.link = link
        super().__init__(channel="link")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.link.down:
            self.link.fail()
        self.link.from_sim.put(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.link.down and not self.link.quiet_recv:
            self.link.fail()
        try:
            return self.link.to_sim.get(timeout=timeout), False
        except queue.Empty:
            return None, False


def _serial_request() -> bytes:
    return struct.pack("<BHBL", 0x40, 0x1018, 4, 0)


@pytest.mark.parametrize("quiet_recv", [False, True], ids=["recv-and-send-fail", "send-fails"])
def test_the_pump_survives_its_link_going_down_and_serves_again(caplog, quiet_recv):
    cfg = load_config(ARM)
    link = Link(quiet_recv=quiet_recv)
    arm = SimArm(cfg, {"can0": {"interface": "test-link"}}, clock=ManualClock(), bus_factory=link.open,
                 link_retry_s=0.001)
    expected = bytes.fromhex("43 18 10 04") + arm.drives["yaw_drive"].serial.to_bytes(4, "little")
    with caplog.at_level(logging.INFO, logger="sherpa_cli.sim.arm"), arm:
        assert link.ask(0x600 + NODE, _serial_request(), 0x580 + NODE) == expected
        link.down = True
        if quiet_recv:  # only a send shows the outage: a request whose answer is lost on the way out
            link.to_sim.put(can.Message(arbitration_id=0x600 + NODE, data=_serial_request(), is_extended_id=False))
        # reopened at least once; while every receive fails, again and again
        reopened = 2 if quiet_recv else 4
        link.wait_for(lambda: link.failures >= 1 and link.opened >= reopened, "the pump did not reopen the bus")
        link.down = False
        while not link.from_sim.empty():
            link.from_sim.get()
        assert link.ask(0x600 + NODE, _serial_request(), 0x580 + NODE) == expected
        assert link.ask(0x600 + NODE, _serial_request(), 0x580 + NODE) == expected
    assert arm.errors == []
    assert arm.link_outages == {"can0": 1}
    down = [r.getMessage() for r in caplog.records if "link down" in r.getMessage()]
    assert len(down) == 1 and "can0" in down[0] and "Network is down" in down[0], down
    assert [r.getMessage() for r in caplog.records if "link back" in r.getMessage()] == \
        ["simulated bus can0: link back, serving again"]


def test_stop_during_an_outage_ends_the_pump(caplog):
    cfg = load_config(ARM)
    link = Link()
    arm = SimArm(cfg, {"can0": {"interface": "test-link"}}, clock=ManualClock(), bus_factory=link.open,
                 link_retry_s=0.001)
    arm.start()
    try:
        link.down = True
        link.wait_for(lambda: link.opened >= 3, "the pump did not reopen the bus")
    finally:
        arm.stop()
    assert arm.errors == []
    assert not any(t.name == "sim-can0" and t.is_alive() for t in threading.enumerate())


def test_sherpa_sim_ends_without_a_traceback_when_its_link_went_down(cli, monkeypatch):
    """`sherpa --bus-map can0=socketcan:vcan0 sim` with the link set down: stopping it (the same path as
    SIGTERM: the wait ends, the arm stops) exits 0 with no traceback."""
    from sherpa_cli.sim import serve as serving

    link = Link()

    def run_on_buses(cfg, endpoints, **kwargs):
        arm = SimArm(cfg, endpoints, clock=ManualClock(), bus_factory=link.open, link_retry_s=0.001).start()
        link.down = True
        link.wait_for(lambda: link.failures >= 2 and link.opened >= 3, "the pump did not meet the outage")
        return arm

    monkeypatch.setattr(serving, "run_on_buses", run_on_buses)
    result = cli("--bus-map", "can0=socketcan:vcan0", "sim", "--duration", "0.001")
    assert result.exit_code == 0, result.stderr
    assert "Traceback" not in result.stderr


def test_sherpa_sim_reports_internal_faults_in_one_line(cli, monkeypatch):
    """A fault the pump kept (SimArm.errors) ends `sherpa sim` with one error line, not a traceback."""
    from sherpa_cli.sim import serve as serving

    class Faulted:
        def __init__(self) -> None:
            self.errors = [can.CanOperationError("Network is down", error_code=errno.ENETDOWN)]

        def stop(self) -> None:
            pass

    monkeypatch.setattr(serving, "run_on_buses", lambda cfg, endpoints, **kwargs: Faulted())
    result = cli("--bus-map", "can0=socketcan:vcan0", "sim", "--duration", "0.001")
    assert result.exit_code == 1
    assert "Traceback" not in result.stderr
    assert "error: the simulated arm had 1 internal fault; the first: CanOperationError: Network is down" \
        in result.stderr
