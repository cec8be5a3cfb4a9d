"""The host heartbeat's thread asks for real-time priority where the OS permits (motion/deadman.py):
on a loaded computer a normal thread's heartbeats slip and the drives' own dead-man stops a healthy
command. The scheduler call is faked: the test never changes this machine's scheduling."""

from __future__ import annotations

import os
import threading

from sherpa_cli.motion import deadman


class Net:
    def __init__(self) -> None:
        self.frames: list[int] = []

    def send_message(self, can_id: int, data: bytes) -> None:
        self.frames.append(can_id)


def _run(monkeypatch, setter, realtime: bool = True) -> tuple[deadman.HostHeartbeat, list[int]]:
    calls: list[int] = []

    def fake(pid: int, policy: int, param: object) -> None:
        calls.append(threading.get_ident())
        setter(pid, policy, param)

    monkeypatch.setattr(os, "sched_setscheduler", fake, raising=False)
    monkeypatch.setattr(os, "SCHED_FIFO", getattr(os, "SCHED_FIFO", 1), raising=False)
    monkeypatch.setattr(os, "sched_param", getattr(os, "sched_param", lambda p: p), raising=False)
    hb = deadman.HostHeartbeat(lambda: [Net()], 126, 0.01, 1.0, realtime=realtime)
    hb.start()
    hb.stop()
    return hb, calls


def test_the_heartbeat_thread_takes_real_time_priority_for_itself_where_permitted(monkeypatch):
    hb, calls = _run(monkeypatch, lambda pid, policy, param: None)
    assert hb.priority == f"SCHED_FIFO {deadman.RT_PRIORITY}"
    assert calls and calls[0] != threading.get_ident()  # the sending thread's own, not the command's
    assert hb.thread is not None and calls[0] == hb.thread.ident


def test_where_it_is_not_permitted_the_thread_runs_normally_and_says_why(monkeypatch):
    def refuse(pid: int, policy: int, param: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    hb, calls = _run(monkeypatch, refuse)
    assert len(calls) == 1
    assert hb.priority == "normal (real-time priority not permitted: Operation not permitted)"
    assert hb.sent >= 1  # it sends all the same


def test_motion_heartbeat_realtime_false_never_asks(monkeypatch):
    hb, calls = _run(monkeypatch, lambda pid, policy, param: None, realtime=False)
    assert calls == [] and hb.priority == "normal"


def test_a_machine_that_holds_the_whole_process_up_is_no_hung_command_but_a_hang_still_stops_it():
    """A loaded host descheduled the command's process for longer than its allowance: on waking,
    the heartbeat thread took the command for hung and stopped, and the drives' consumers switched
    a healthy command's motors off. The thread's own lateness is the machine's, and the command's
    thread was held up no less: it is given back. A command that hangs while it runs still stops."""
    import time

    offset = [0.0]
    net = Net()
    hb = deadman.HostHeartbeat(lambda: [net], 126, 0.01, 1.0, realtime=False,
                               clock=lambda: time.monotonic() + offset[0])
    hb.start()
    try:
        while hb.sent < 2:  # hang guard only: the thread sends at once
            time.sleep(0.001)
        offset[0] += 5.0  # five seconds the process did not run, the thread's wait included
        sent = hb.sent
        guard = time.monotonic() + 10
        while hb.sent < sent + 3 and hb.given_up is None and time.monotonic() < guard:
            time.sleep(0.001)
        assert hb.given_up is None and hb.sent >= sent + 3
        assert hb.held_up >= 4.9
        while hb.given_up is None and time.monotonic() < guard:  # no pulse: the command hangs
            time.sleep(0.005)
        assert hb.given_up == "the command showed no sign of life (hung?)"
    finally:
        hb.stop()
