"""The motion guard, `sherpa stop` and `sherpa recover` with a CiA 402 drive (tests/data/cia402-arm.yaml:
`wrist`), on stepped time: a drive in Quick stop active is powered (stopped at standstill, switched
off, never written to by recover); the mode object 0x6060 is journaled and put back; a drive found
in Operation enabled moves; the first stop pass tells every Elmo drive before any CiA 402 drive."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from motion_helpers import motors_off, stepped_session

from sherpa_cli.bus import journal
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.cia402 import protocol as p
from sherpa_cli.cia402.protocol import State
from sherpa_cli.config import load_config
from sherpa_cli.devices.drives import open_drive
from sherpa_cli.drive import Mode
from sherpa_cli.errors import SdoError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.request import parse_request
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.jog import run_jog
from sherpa_cli.ops.recover import plan_recover, recover
from sherpa_cli.ops.stop import stop_drives

CONFIG = Path(__file__).resolve().parent / "data" / "cia402-arm.yaml"
MODE_STEP = "0x6060:0"


@pytest.fixture
def arm() -> Any:
    cfg = load_config(CONFIG)
    with stepped_session(cfg) as (session, st):
        ref = drive_ref(cfg, "wrist")
        session.client(ref).nmt_start()
        yield session, st, ref, session.sim.drives["wrist"]


def _jog(session: Any, st: Any, by: str = "300counts", sleep: Any = None) -> Any:
    axis = resolve_axis(session.cfg, "wrist")
    req = parse_request(axis, "position", by=by, uncalibrated=True)
    return run_jog(session, axis, req, settings=MotionSettings.from_config(session.cfg), clock=st.now,
                   sleep=sleep or st.sleep)


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                          check=True)
    return int(proc.stdout)


def _quick_stopped(session: Any, st: Any, ref: Any, sim: Any, option: int) -> Any:
    """The wrist jogging at 2000 counts/s, then a quick stop with 0x605A = ``option``."""
    drive = open_drive(session, ref)
    sdo = session.sdo(ref)
    sdo.download(p.QUICK_STOP_OPTION, 0, p.encode(p.QUICK_STOP_OPTION, option))
    sdo.download(p.QUICK_STOP_DECELERATION, 0, p.encode(p.QUICK_STOP_DECELERATION, 2000))
    drive.enable(Mode.VELOCITY)
    drive.jog(2000)
    drive.begin()
    st.sleep(0.5)
    sdo.download(p.CONTROLWORD, 0, p.encode(p.CONTROLWORD, 0x02))  # quick stop: ~1 s on its ramp
    with session.sim.lock:
        assert sim.state is State.QUICK_STOP_ACTIVE and sim.motor.v != 0
    return drive


# -- 1: Quick stop active is powered ----------------------------------------------------------------

def test_stop_of_a_drive_in_quick_stop_active_waits_for_standstill_and_switches_it_off(arm):
    """0x605A = 6: the drive stays in Quick stop active, powered, at standstill. The old status()
    called it off: `sherpa stop` said "motor was off" and left it powered."""
    session, st, ref, sim = arm
    drive = _quick_stopped(session, st, ref, sim, option=6)
    speeds_at_off: list[float] = []
    nxt = sim.on_event

    def seen(d: Any, t: float, text: str) -> None:
        if text.startswith("CiA 402: Quick stop active ->"):
            speeds_at_off.append(d.motor.v)
        if nxt is not None:
            nxt(d, t, text)
    sim.on_event = seen
    (r,) = stop_drives(session, [ref], MotionSettings.from_config(session.cfg), clock=st.now, sleep=st.sleep)
    assert r.ok and r.stopped_by == "quick stop" and r.standstill is True and r.motor_off, r
    assert len(speeds_at_off) == 1 and abs(speeds_at_off[0]) < 1e-6, "the power stage went off while it turned"
    assert not drive.status().enabled and motors_off(session)


def test_recover_writes_nothing_to_a_drive_in_quick_stop_active(arm):
    """A killed command's consumer with 0x6007 = 3 (quick stop) and 0x605A = 6 leaves the drive
    powered in Quick stop active: recover refuses to put objects back under it."""
    session, st, ref, sim = arm
    _quick_stopped(session, st, ref, sim, option=6)
    st.sleep(1.5)  # ramped down, held in Quick stop active
    journal.note(ref, dataclasses.replace(journal.sdo("motion command", p.PROFILE_VELOCITY, 0, 4, 1234),
                                          pid=_dead_pid(), proc=""))
    writes = len(sim.od_writes)
    (res,) = recover(session, plan_recover(session.cfg, ["wrist"]), apply=True).results
    assert any("the power stage is on" in x and "`sherpa stop wrist`" in x for x in res.problems), res
    assert not res.done and len(sim.od_writes) == writes
    assert journal.leftover(ref)


def test_a_quick_stop_from_elsewhere_during_a_jog_ends_it_by_name(arm):
    """Powered is not following: a drive put in Quick stop active during the move is named, as a
    drive switched off is (it was, before Quick stop active counted as powered)."""
    session, st, ref, sim = arm
    session.sdo(ref).download(p.QUICK_STOP_OPTION, 0, p.encode(p.QUICK_STOP_OPTION, 6))  # held there
    sent: list[bool] = []

    def quick_stop_once_moving(s: float) -> None:
        with session.sim.lock:
            moving = sim.state is State.OPERATION_ENABLED and sim.motor.v != 0
        if moving and not sent:
            sent.append(True)
            with session.sim.lock:
                sim.od_write(p.CONTROLWORD, 0, 0x02)
        st.sleep(s)

    from sherpa_cli.errors import SafetyError
    with pytest.raises(SafetyError, match=r"wrist \(can0 node 7\): Quick stop active during"):
        _jog(session, st, by="3000counts", sleep=quick_stop_once_moving)
    assert sent and motors_off(session)


# -- 2: the mode object is journaled and put back ----------------------------------------------------

def test_a_mode_found_is_journaled_before_it_changes_and_put_back_once_switched_off(arm):
    session, st, ref, sim = arm
    session.sdo(ref).download(p.MODES_OF_OPERATION, 0, p.encode(p.MODES_OF_OPERATION, 8))  # found in CSP
    path = journal.path_for(ref.bus, ref.node)
    while_moving: list[dict[str, int]] = []

    def peek(s: float) -> None:
        with session.sim.lock:
            moving = sim.motor.v != 0 and sim.mode == 1
        if moving and path.exists():
            while_moving.append({x["name"]: x["old"] for x in json.loads(path.read_text()).get("steps", [])})
        st.sleep(s)

    r = _jog(session, st, sleep=peek)
    assert r.ok and r.end_counts == 300, r
    assert while_moving and all(steps.get(MODE_STEP) == 8 for steps in while_moving), while_moving[:1]
    (stop,) = r.stop.drives
    assert f"{MODE_STEP}=8" in stop.restored, stop
    with session.sim.lock:
        assert sim.mode == 8 and sim.state is State.READY_TO_SWITCH_ON
    assert not path.exists() or not json.loads(path.read_text()).get("steps")


def test_recover_puts_the_mode_back_after_a_killed_command(arm):
    """What a command killed while it moved leaves: the mode note (0x6060 = 8) in the name of a
    process that is gone, the drive in PP in Fault 0x8130 by its consumer (0x6007 = 1)."""
    session, _st, ref, sim = arm
    sdo = session.sdo(ref)
    journal.note(ref, dataclasses.replace(journal.sdo("motion command", p.MODES_OF_OPERATION, 0, 1, 8),
                                          pid=_dead_pid(), proc=""))
    sdo.download(p.MODES_OF_OPERATION, 0, p.encode(p.MODES_OF_OPERATION, 1))
    with session.sim.lock:
        sim.fault(0x8130)
    (res,) = recover(session, plan_recover(session.cfg, ["wrist"]), apply=True).results
    assert not res.problems, res
    assert res.done is not None and res.done[0] == f"{MODE_STEP}=0x8", res
    # what was reset is named
    assert res.done[-1].startswith("the heartbeat-loss fault reset (Fault: 0x8130 life guard error or heartbeat error;")
    with session.sim.lock:
        assert sim.mode == 8
    assert not journal.leftover(ref)


# -- 7: the heartbeat loss is reset only when it is the only error -----------------------------------

def test_recover_leaves_a_heartbeat_loss_with_another_error_to_the_user(arm):
    """0x603F = 0x8130, but the error register also shows a voltage error: not the consumer's alone."""
    session, _st, ref, sim = arm
    journal.note(ref, dataclasses.replace(journal.sdo("motion command", p.PROFILE_VELOCITY, 0, 4, 1234),
                                          pid=_dead_pid(), proc=""))
    with session.sim.lock:
        sim.fault(0x8130)
        sim._error_register = 0x05  # generic + voltage, as a second EMCY would leave it
    (res,) = recover(session, plan_recover(session.cfg, ["wrist"]), apply=True).results
    assert res.tripped is None, res
    assert any("error register (0x1001) 0x05: more than a communication error" in x and "not reset" in x
               for x in res.problems), res
    assert not any("fault reset" in x for x in res.done or []), res
    with session.sim.lock:
        assert sim.state is State.FAULT


# -- 5: a drive found in Operation enabled moves ----------------------------------------------------

def test_a_drive_found_in_operation_enabled_is_moved(arm):
    """The old guard took a drive found on as enabled and never called enable(): move_to refused
    (no mode known to the drive object)."""
    session, st, ref, sim = arm
    open_drive(session, ref).enable(Mode.POSITION)
    with session.sim.lock:
        assert sim.state is State.OPERATION_ENABLED
    r = _jog(session, st)
    assert r.ok and r.end_counts == 300 and r.ended_by == "target reached", r


# -- 3: the first stop pass --------------------------------------------------------------------------

class _Clock:
    t = 0.0


def test_the_first_stop_pass_tells_every_elmo_drive_before_a_silent_cia402_drive():
    """A CiA 402 drive's stop is a confirmed SDO exchange; one that does not answer costs its
    timeout. Listed first, it held back the Elmo drive's ST by that timeout."""
    clock, sent, timeout = _Clock(), [], 0.5

    class SilentCia:
        kind = "cia402"

        def stop(self) -> str:
            clock.t += timeout
            sent.append(("cia stop", clock.t))
            raise SdoError("no answer", detail="timeout", reason="timeout")

    class ElmoClient:
        silent = False

        def send_only(self, letters: str, *args: Any) -> None:
            sent.append((letters, clock.t))

    def entry(name: str, native: bool, *, silent: bool = False) -> Any:
        client = ElmoClient() if native else SimpleNamespace(silent=silent)
        drive = SimpleNamespace(kind="elmo") if native else SilentCia()
        return SimpleNamespace(ref=SimpleNamespace(name=name), mo=1, switched_on=True, native=native, um=5,
                               client=client, drive=drive)

    guard = SimpleNamespace(settings=SimpleNamespace(stop_method="st"),
                            _drives={("can0", 7): entry("wrist", False), ("can0", 6): entry("elbow", True)})
    MotionGuard._stop_pass(guard, entering=False)  # type: ignore[arg-type]
    assert sent == [("ST", 0.0), ("cia stop", timeout)]

    # a CiA 402 drive already known silent is not waited on at all (its exit says so)
    sent.clear()
    clock.t = 0.0
    guard._drives = {("can0", 7): entry("wrist", False, silent=True), ("can0", 6): entry("elbow", True)}
    MotionGuard._stop_pass(guard, entering=False)  # type: ignore[arg-type]
    assert sent == [("ST", 0.0)]
