"""`sherpa recover` after a killed command on a CiA 402 drive, in process on stepped time
(tests/data/cia402-arm.yaml: `wrist` on a cia402 drive). What a jog killed while it moved leaves:
the journal's notes of the dead-man objects it armed (0x6007, 0x1029:1, 0x1016:1) in the name of a
process that is gone, the objects still armed on the drive, and the drive as its consumer left it
(0x6007 = 1: Fault 0x8130; 0x6007 = 2: disabled). The next jog refuses the drive and names `sherpa
recover`; the dry run says what happened and writes nothing; `--apply` puts the objects back and
resets the heartbeat-loss fault under a dead-man of its own; then the jog runs. The cross-process
kill itself is tests/test_cia402_killed.py."""

from __future__ import annotations

import dataclasses
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from motion_helpers import motors_off, stepped_session

from sherpa_cli.bus import journal
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.cia402.protocol import State
from sherpa_cli.config import load_config
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.request import parse_request
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops.jog import run_jog
from sherpa_cli.ops.recover import plan_recover, recover
from sherpa_cli.sim.drive import UNGUARDED_MO

CONFIG = Path(__file__).resolve().parent / "data" / "cia402-arm.yaml"
# what the killed jog armed: (index, sub, struct format, value; None: the 0x6007 action of the case)
ARMED = ((0x6007, 0, "<h", None), (0x1029, 1, "<B", 2), (0x1016, 1, "<I", (0x7E << 16) | 300))


def _dead_pid() -> int:
    """The pid of a process that has ended (the killed command's)."""
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                          check=True)
    return int(proc.stdout)


def _read(session: Any, ref: Any, index: int, sub: int, fmt: str) -> int:
    raw = bytes(session.sdo(ref).upload(index, sub))[:struct.calcsize(fmt)]
    return int(struct.unpack(fmt, raw)[0])


@pytest.fixture(params=[1, 2], ids=["loss_action_1_fault", "loss_action_2_disabled"])
def killed(request) -> Any:
    """The arm as a jog of `wrist` killed while it moved leaves it, with its consumer's 0x6007 action."""
    action = request.param
    cfg = load_config(CONFIG)
    with stepped_session(cfg) as (session, st):
        events: list[tuple[str, str, bool]] = []  # drive, text, the drive's dead-man watching at that instant
        for name, d in session.sim.drives.items():
            nxt = d.on_event

            def seen(drive: Any, t: float, text: str, _name: str = name, _next: Any = nxt) -> None:
                events.append((_name, text, drive.deadman_watching()))
                if _next is not None:
                    _next(drive, t, text)
            d.on_event = seen
        ref = drive_ref(cfg, "wrist")
        session.client(ref).nmt_start()
        sdo, pid = session.sdo(ref), _dead_pid()
        olds = {(i, s): _read(session, ref, i, s, f) for i, s, f, _ in ARMED}
        # the notes first, as the guard writes them, in the name of the process that is gone
        journal.note(ref, *(dataclasses.replace(journal.sdo("motion command", i, s, struct.calcsize(f), olds[(i, s)]),
                                                pid=pid, proc="") for i, s, f, _ in ARMED))
        for i, s, f, value in ARMED:
            sdo.download(i, s, struct.pack(f, action if value is None else value))
        with session.sim.lock:
            drive = session.sim.drives["wrist"]
            if action == 1:
                drive.fault(0x8130)  # what its consumer does with 0x6007 = 1 on the heartbeat loss
        yield session, st, ref, events, olds, action


def _jog(session: Any, st: Any, by: str = "200counts") -> Any:
    axis = resolve_axis(session.cfg, "wrist")
    req = parse_request(axis, "position", by=by, uncalibrated=True)
    return run_jog(session, axis, req, settings=MotionSettings.from_config(session.cfg), clock=st.now,
                   sleep=st.sleep)


def test_after_a_killed_jog_the_next_refuses_recover_says_why_puts_back_and_the_jog_runs(killed):
    session, st, ref, events, olds, action = killed

    # the next jog refuses the drive and names recover; nothing was switched on
    with pytest.raises(journal.LeftoverError, match="did not finish") as refused:
        _jog(session, st)
    assert "`sherpa recover wrist`" in (refused.value.hint or ""), refused.value.hint
    left = [f"0x1016:1={olds[(0x1016, 1)]:#x}", f"0x1029:1={olds[(0x1029, 1)]:#x}", f"0x6007:0={olds[(0x6007, 0)]:#x}"]
    assert ", ".join(left) in str(refused.value), refused.value
    assert not [t for n, t, _ in events if n == "wrist" and t.startswith("motor on")]

    # the dry run: what was left and what happened, nothing written
    writes = len(session.sim.drives["wrist"].od_writes)
    (dry,) = recover(session, plan_recover(session.cfg, ["wrist"]), apply=False).results
    assert dry.found == left, dry
    assert not dry.problems and not dry.done, dry
    assert dry.tripped is not None and f"0x6007={action}" in dry.tripped, dry
    if action == 1:
        assert "dead-man tripped" in dry.tripped and "0x8130" in dry.tripped, dry
    else:
        assert "still armed" in dry.tripped and "nothing latched" in dry.tripped, dry
    assert len(session.sim.drives["wrist"].od_writes) == writes, "the dry run wrote to the drive"
    assert journal.leftover(ref), "the dry run dropped the notes"

    # --apply: every note put back, the heartbeat-loss fault reset under a dead-man of its own
    (done,) = recover(session, plan_recover(session.cfg, ["wrist"]), apply=True).results
    assert not done.problems, done
    assert done.done is not None and done.done[:3] == left, done
    resets = [watching for n, t, watching in events if n == "wrist" and t == "fault reset"]
    if action == 1:
        assert any("fault reset" in line for line in done.done), done
        assert resets == [True], "the fault reset was not sent under an armed dead-man"
    else:
        assert resets == [] and len(done.done) == 3, done  # disabled, nothing latched: nothing to reset
    assert session.sim.drives["wrist"].state is State.SWITCH_ON_DISABLED
    assert {(i, s): _read(session, ref, i, s, f) for i, s, f, _ in ARMED} == olds
    assert not journal.leftover(ref) and journal.damaged(ref) is None

    # the next jog runs, and no motor ever went on without an armed dead-man
    r = _jog(session, st)
    assert r.ok and r.end_counts == r.target_counts == 200, r
    assert motors_off(session)
    assert not [t for _n, t, _ in events if t.startswith(UNGUARDED_MO)], events


def test_recover_leaves_a_fault_that_is_not_the_heartbeat_loss_to_the_user(killed):
    session, _st, _ref, events, _olds, _action = killed
    with session.sim.lock:
        drive = session.sim.drives["wrist"]
        drive.fault(0x2310)  # over-current, beside (or after) the trip
    (res,) = recover(session, plan_recover(session.cfg, ["wrist"]), apply=True).results
    assert res.problems and "more than the heartbeat loss" in res.problems[-1], res
    assert not [t for n, t, _ in events if n == "wrist" and t == "fault reset"], "a fault reset was sent"
    assert session.sim.drives["wrist"].state is State.FAULT


def test_with_recover_the_jog_puts_the_leftovers_back_itself_and_runs(killed):
    """`sherpa --recover jog ...`: the guard's entry does what `recover --apply` does, then moves."""
    session, st, ref, events, olds, action = killed
    journal.set_auto_recover(True)
    try:
        r = _jog(session, st)
    finally:
        journal.set_auto_recover(False)
    assert r.ok and r.end_counts == 200, r
    assert not journal.leftover(ref)
    resets = [watching for n, t, watching in events if n == "wrist" and t == "fault reset"]
    assert resets == ([True] if action == 1 else []), events
    assert {(i, s): _read(session, ref, i, s, f) for i, s, f, _ in ARMED} == olds
    assert motors_off(session)
    assert not [t for _n, t, _ in events if t.startswith(UNGUARDED_MO)], events
