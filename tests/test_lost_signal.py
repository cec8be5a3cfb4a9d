"""A SIGTERM whose exception was lost (errors.py: CPython drops a signal handler's exception raised
inside some C code) is still heard by the commands that run until they are told to stop: `log
record`'s wait, `log capture`, `bus watch` and `monitor`. Before, such a command ran its whole
--for (a 60 s `log record` once outlived a test's 60 s wait for its exit), or forever, since the
entry ignores a second SIGTERM while the first one unwinds."""

from __future__ import annotations

import signal
import threading
import uuid

import can
import pytest

from sherpa_cli.errors import Terminated, note_signal


@pytest.fixture
def lost_sigterm():
    note_signal(signal.SIGTERM)
    yield
    note_signal(None)


def _no_sleep(seconds: float) -> None:
    raise AssertionError(f"slept {seconds} s after the signal")


def test_a_recording_wait_ends_with_the_lost_signal(lost_sigterm, monkeypatch):
    from sherpa_cli.cli import log_cmd

    monkeypatch.setattr(log_cmd, "sleep", _no_sleep)
    with pytest.raises(Terminated, match="SIGTERM"):
        log_cmd._wait_for(60.0)


def test_a_recording_wait_without_a_signal_sleeps_to_its_end(monkeypatch):
    from sherpa_cli.cli import log_cmd

    t = [0.0]
    monkeypatch.setattr(log_cmd._time, "monotonic", lambda: t[0])
    monkeypatch.setattr(log_cmd, "sleep", lambda s: t.__setitem__(0, t[0] + s))
    assert log_cmd._wait_for(1.0) is False
    assert t[0] == pytest.approx(1.0)


def test_a_capture_ends_with_the_lost_signal_and_keeps_its_frames(lost_sigterm, tmp_path):
    from sherpa_cli.log.capture import capture, read_frames

    channel = f"lostsig-{uuid.uuid4().hex[:8]}"
    listen = can.Bus(interface="virtual", channel=channel)
    send = can.Bus(interface="virtual", channel=channel)
    try:
        send.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False))
        with pytest.raises(Terminated):
            capture({"can0": listen}, tmp_path / "c.log", ["can0"], stop=threading.Event())
    finally:
        listen.shutdown()
        send.shutdown()
    assert [(f.can_id, f.data) for f in read_frames(tmp_path / "c.log", ["can0"])] == [(0x701, b"\x05")]


def test_an_endless_bus_watch_ends_with_the_lost_signal(lost_sigterm):
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config import load_config
    from sherpa_cli.ops.buswatch import watch
    from sherpa_cli.sim.arm import SimArm
    from tests.test_bus_cli import ARM

    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can1"]) as session, \
            pytest.raises(Terminated):
        watch(session, ["can1"], duration=None, interval=0.25, clock=lambda: 0.0, sleep=_no_sleep)


def test_monitor_without_a_terminal_ends_with_the_lost_signal(cli, lost_sigterm):
    with pytest.raises(Terminated):
        cli("--sim", "monitor", "--interval", "0.2")
