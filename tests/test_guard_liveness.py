"""The motion guard's sign of life counts the requests its command's own thread sends
(ArmSession.watch_requests): a step of many requests inside the guard (a recorder's PDO set-up,
a pair's start, their restore) never outlasts the dead-man's liveness allowance, however slow the
bus or the machine. In the vcan guest, 15-20x slower, `diffdrive move`'s 28 set-up requests without
a check took longer than the 5 s allowance and the heartbeat stopped ("no sign of life (hung?)")."""

from __future__ import annotations

import threading
from typing import ClassVar

import pytest
from motion_helpers import stepped_session
from test_diffdrive import MISMATCHED
from test_motion_guard import cfg  # noqa: F401 - fixture

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.elmo.client import DriveClient
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops import diffdrive
from sherpa_cli.ops.diffdrive import PairTarget
from sherpa_cli.sim.arm import SimArm


class Traced(MotionGuard):
    """A motion guard that logs its signs of life ("pulse") beside the requests of the command's
    thread ("request" + object), in order."""

    log: ClassVar[list[tuple[str, str]]] = []

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        heartbeat, pulse = self._heartbeat, self._heartbeat.pulse

        def logged(*a, **k):
            Traced.log.append(("pulse", ""))
            return pulse(*a, **k)
        heartbeat.pulse = logged

    def __enter__(self):
        Traced.log.append(("enter", ""))
        return super().__enter__()

    def __exit__(self, *exc):
        try:
            return super().__exit__(*exc)
        finally:
            Traced.log.append(("exited", ""))


def _trace_requests(session: ArmSession, nodes: set[int], monkeypatch: pytest.MonkeyPatch) -> None:
    """Every interpreter (RPDO2) and SDO request frame to ``nodes`` the command's thread sends, seen on
    the network, below every seam a request could take; the stop pass's frames sent without waiting
    for an answer (DriveClient.send_only) are no requests the command waits for, and not logged."""
    main = threading.get_ident()
    requests = {0x300 + n for n in nodes} | {0x600 + n for n in nodes}
    sending_only = threading.local()
    send_only = DriveClient.send_only

    def unlogged(self, *a, **k):
        sending_only.on = True
        try:
            return send_only(self, *a, **k)
        finally:
            sending_only.on = False
    monkeypatch.setattr(DriveClient, "send_only", unlogged)
    for link in session.links.values():
        network, send = link.network, link.network.send_message

        def traced(can_id, data, *a, _send=send, **k):
            if threading.get_ident() == main and can_id in requests and not getattr(sending_only, "on", False):
                Traced.log.append(("request", f"0x{can_id:03X} {bytes(data).hex()}"))
            return _send(can_id, data, *a, **k)
        network.send_message = traced


def _longest_run_without_a_pulse(log: list[tuple[str, str]]) -> list[str]:
    inside, run, longest = False, [], []
    for kind, what in log:
        if kind == "enter":
            inside = True
        elif kind == "exited":
            inside = False
        elif kind == "pulse":
            run = []
        elif kind == "request" and inside:
            run.append(what)
            longest = max(longest, run, key=len)
    return longest


def test_every_request_of_a_diffdrive_move_comes_with_a_sign_of_life(monkeypatch):
    """The whole move, set-up (recorder, pair start, profiles) to restore: no request of the command's
    thread goes out without a sign of life right before it (28 in a row before the fix)."""
    arm = load_config(MISMATCHED)
    Traced.log = []
    with stepped_session(arm) as (s, stepped):
        _trace_requests(s, {arm.drives[d].node for d in ("left", "right")}, monkeypatch)
        r = diffdrive.run_move(s, arm.pairs["diff"], PairTarget(sigma="0.5"), guard_factory=Traced, timebase=stepped)
    assert r.ok, r.as_dict()
    requests = [what for kind, what in Traced.log if kind == "request"]
    assert len(requests) > 60  # the recorder's, the pair start's and the move's own
    assert len(_longest_run_without_a_pulse(Traced.log)) == 1  # each request its own sign of life


def test_requests_of_another_thread_or_after_the_guard_are_no_sign_of_life(cfg):  # noqa: F811
    settings = MotionSettings.from_config(cfg, {"can0"})
    ref = resolve_target(cfg, "drive1")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        client = s.client(ref)
        guard = Traced(s, [ref], settings=settings)
        with guard:
            Traced.log = []
            worker = threading.Thread(target=lambda: (client.get("PX"), s.sdo(ref).upload(0x1000, 0)))
            worker.start()
            worker.join()
            assert Traced.log == []  # a watch thread's requests say nothing about the command's loop
            client.get("PX")
            assert Traced.log and set(Traced.log) == {("pulse", "")}  # one per attempt (a retry on a loaded machine: two)
            Traced.log = []
            s.sdo(ref).upload(0x1000, 0)
            assert Traced.log == [("pulse", "")]  # one per transfer
        Traced.log = []
        client.get("PX")
        assert Traced.log == [] and s._request_watchers == []


def test_a_guard_whose_entry_fails_stops_watching_requests(cfg):  # noqa: F811
    settings = MotionSettings.from_config(cfg, {"can0"})
    ref = resolve_target(cfg, "drive1")
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with s.sim.lock:
            s.sim.drives["drive1"]._mf = 0x400000  # latched fault: the entry refuses
        with pytest.raises(SafetyError, match="in fault"), MotionGuard(s, [ref], settings=settings):
            pytest.fail("the body must not run")
        assert s._request_watchers == []
