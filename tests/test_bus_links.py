"""The paced canopen network of bus/links.py: its send path and how the session closes the buses."""

from __future__ import annotations

import errno
import threading
import uuid
from pathlib import Path

import can
import pytest

from sherpa_cli.bus.busmap import BusTarget, apply_bus_map
from sherpa_cli.bus.links import BusLink, _paced_network_class, close_links, open_links
from sherpa_cli.config import load_config
from sherpa_cli.errors import CommunicationError

ROOT = Path(__file__).resolve().parent.parent


# -- PacedNetwork.send_message ---------------------------------------------------------------------

class _FlakyBus:
    """A bus whose first ``failures`` sends raise ``CanOperationError(error_code=code)``."""

    def __init__(self, failures: int, code: int = errno.ENOBUFS) -> None:
        self.failures, self.code, self.sent = failures, code, []

    def send(self, message, timeout=None):
        if self.failures:
            self.failures -= 1
            raise can.CanOperationError("No buffer space available", error_code=self.code)
        self.sent.append(message)


def _network(bus):
    net = _paced_network_class()(bus)
    net.sleeps = []
    net.sleep = net.sleeps.append
    net.clock = lambda: pytest.fail("an unpaced network must not read the clock")
    return net


def test_a_full_socket_buffer_is_retried_with_growing_waits():
    bus = _FlakyBus(failures=3)
    net = _network(bus)
    net.send_message(0x30A, b"PX\x00\x00")
    assert len(bus.sent) == 1 and net.sleeps == [0.001, 0.002, 0.003]


def test_a_buffer_that_stays_full_gives_up_after_send_attempts():
    bus = _FlakyBus(failures=99)
    net = _network(bus)
    with pytest.raises(CommunicationError, match="sending 0x30A failed"):
        net.send_message(0x30A, b"PX\x00\x00")
    assert bus.failures == 99 - net.send_attempts and net.sleeps == [0.001, 0.002, 0.003, 0.004]


def test_other_send_errors_are_not_retried():
    bus = _FlakyBus(failures=1, code=errno.ENETDOWN)
    net = _network(bus)
    with pytest.raises(CommunicationError, match="sending 0x30A failed"):
        net.send_message(0x30A, b"PX\x00\x00")
    assert net.sleeps == [] and bus.failures == 0


# -- close_links -----------------------------------------------------------------------------------

class _Notifier:
    def __init__(self, name, log):
        self.name, self.log = name, log

    def stop(self, timeout=5.0):
        self.log.append(("stop", self.name, timeout))


class _Network:
    def __init__(self, name, log, fail=False):
        self.name, self.log, self.fail = name, log, fail
        self.notifier = _Notifier(name, log)

    def disconnect(self):
        self.log.append(("disconnect", self.name))
        self.notifier.stop(1.0)  # as canopen's Network.disconnect does
        if self.fail:
            raise can.CanOperationError("gone")


def test_close_links_flags_every_notifier_before_waiting_for_any():
    log: list = []
    links = {name: BusLink(name, None, None, _Network(name, log, fail=name == "can1"))
             for name in ("can0", "can1", "can2")}
    close_links(links)
    assert log[:3] == [("stop", "can0", 0), ("stop", "can1", 0), ("stop", "can2", 0)], \
        "all receive threads are told to stop at once, none waited for"
    assert [e for e in log[3:] if e[0] == "disconnect"] == [("disconnect", n) for n in ("can0", "can1", "can2")], \
        "a bus that fails to close does not keep the others open"


def test_the_receive_cycle_is_short():
    assert _paced_network_class().NOTIFIER_CYCLE <= 0.05


def test_closing_real_virtual_links_ends_every_receive_thread():
    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    token = uuid.uuid4().hex[:8]
    cfg = apply_bus_map(cfg, {name: BusTarget("virtual", f"close-{token}-{name}") for name in cfg.buses})
    before = set(threading.enumerate())
    links = open_links(cfg)
    started = [t for t in threading.enumerate() if t not in before]
    assert len(started) == len(cfg.buses)
    close_links(links)
    assert not any(t.is_alive() for t in started)
    assert all(link.network.bus is None for link in links.values())
