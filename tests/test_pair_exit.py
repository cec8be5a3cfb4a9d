"""How `diffdrive move` and the Σ/Δ jog leave the drives: the scaled SP/AC/DC are
put back like the group id 0x2040, and every motor is stopped before CommonStart's restore (SDO,
which can take sdo_timeout per drive that stops answering), on the end, an error and Ctrl-C; a
second Ctrl-C during the restore does not skip the rest of it."""

from __future__ import annotations

import pytest
from motion_helpers import JOG_CONFIG, calibrate, motors_off

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.pair_start import CommonStart
from sherpa_cli.motion.request import parse_request
from sherpa_cli.ops import diffdrive, joint_jog
from sherpa_cli.ops.diffdrive import PairTarget
from sherpa_cli.sim.arm import SimArm

PROFILE = ("SP", "AC", "DC")


def _profile(s, name):
    c = s.client(drive_ref(s.cfg, name))
    c.nmt_start()
    return {k: int(c.get(k)) for k in PROFILE}


def _frames(s, name):
    with s.sim.lock:
        return [(t, i, bytes(f)) for t, i, f in s.sim.drives[name].received]


def _stop_and_restore(s, name):
    """(time of the last ST to ``name``, time of its 0x2040 restore download) of the last command."""
    node = s.sim.drives[name].node
    rx = _frames(s, name)
    group = [t for t, i, f in rx if i == 0x600 + node and f[0] & 0xE0 == 0x20 and f[1:3] == b"\x40\x20"]
    assert len(group) >= 2, "no 0x2040 write and restore"
    restore = group[-1]
    bg = max(t for t, i, f in rx if i in (0x300 + node, 0x300 + 125) and f[:2] == b"BG" and t < restore)
    st = [t for t, i, f in rx if i == 0x300 + node and f[:2] == b"ST" and bg < t]
    return (st[0] if st else None), restore


def test_diffdrive_puts_back_the_profile_it_scaled():
    """R7: Σ +200 and Δ +200: right = (Σ-Δ)/2 does not move, its share is 0 (SP=AC=DC=1)."""
    cfg = load_config(JOG_CONFIG)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        before = {d: _profile(s, d) for d in ("left", "right")}
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="200counts", delta="200counts",
                                                                 relative=True, uncalibrated=True))
        assert r.motor_commands["right"]["AC"] == 1  # it was scaled
        assert {d: _profile(s, d) for d in ("left", "right")} == before


def test_a_sigma_jog_after_a_diffdrive_move_still_holds_delta():
    """R7: with right's AC=DC=1 left behind, the next Σ jog ran on one motor and Δ drifted."""
    cfg = load_config(JOG_CONFIG)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        calibrate(s, "left", "right")
        diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="200counts", delta="200counts", relative=True))
        axis = resolve_axis(cfg, "pitch")
        r = joint_jog.run(s, axis, parse_request(axis, mode="velocity", velocity="2000counts/s", duration=0.4))
    assert abs(r.joints_end["roll"] - r.joints_start["roll"]) <= 20, (r.joints_start, r.joints_end)


class _CtrlC:
    """A trace that raises KeyboardInterrupt (as Ctrl-C does) at its ``at``-th sample."""

    source = "test"

    def __init__(self, drives, at=5):
        self.samples, self.at = [], at

    def add(self, t, motors):
        self.samples.append(t)
        if len(self.samples) == self.at:
            raise KeyboardInterrupt


def test_ctrl_c_during_a_move_stops_both_motors_before_the_restore_and_restores_the_profile():
    """R8 and R7 on the Ctrl-C path: each motor gets its ST before its 0x2040 restore."""
    cfg = load_config(JOG_CONFIG)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        calibrate(s, "left", "right")
        before = {d: _profile(s, d) for d in ("left", "right")}
        with pytest.raises(KeyboardInterrupt):
            diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="-2000counts", velocity="1000counts/s"),
                               trace_factory=_CtrlC)
        for d in ("left", "right"):
            st, restore = _stop_and_restore(s, d)
            assert st is not None and st < restore, f"{d}: 0x2040 restored before the motor was stopped"
        assert {d: _profile(s, d) for d in ("left", "right")} == before
        assert motors_off(s)


def test_an_error_during_a_sigma_jog_stops_both_motors_before_the_restore():
    """R8 in joint_jog.py: a velocity jog of Σ ends in an error (here from on_progress)."""
    cfg = load_config(JOG_CONFIG)
    seen = []

    def progress(joints):
        seen.append(joints)
        if len(seen) == 5:
            raise RuntimeError("the view went away")

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        axis = resolve_axis(cfg, "pitch")
        with pytest.raises(RuntimeError):
            joint_jog.run(s, axis, parse_request(axis, mode="velocity", velocity="1000counts/s", duration=2.0),
                          on_progress=progress)
        for d in ("left", "right"):
            st, restore = _stop_and_restore(s, d)
            assert st is not None and st < restore, f"{d}: 0x2040 restored before the motor was stopped"
        assert motors_off(s)


class _Sdo:
    def __init__(self, log, name, interrupt):
        self.log, self.name, self.interrupt = log, name, interrupt

    def upload(self, index, sub, name=None):
        return bytes([7])

    def download(self, index, sub, data, name=None):
        self.log.append((self.name, index, bytes(data)))
        if self.interrupt and len([x for x in self.log if x[0] == self.name]) == 2:
            raise KeyboardInterrupt  # a second Ctrl-C, during the restore


class _Session:
    def __init__(self, cfg, interrupt):
        self.cfg, self.log = cfg, []
        self._sdo = {name: _Sdo(self.log, name, name in interrupt) for name in cfg.drives}

    def sdo(self, ref):
        return self._sdo[ref.name]


@pytest.mark.parametrize("interrupt", [("left",), ("left", "right")])
def test_a_second_ctrl_c_during_the_restore_does_not_skip_the_rest_of_it(interrupt):
    cfg = load_config(JOG_CONFIG)
    session = _Session(cfg, interrupt)
    refs = [drive_ref(cfg, "left"), drive_ref(cfg, "right")]
    stopped = []
    start = CommonStart(session, refs, {}, "group", 125, stop=lambda: stopped.append(len(session.log)))
    start.__enter__()
    assert [x[0] for x in session.log] == ["left", "right"]  # group id written to both
    with pytest.raises(KeyboardInterrupt):
        start.__exit__(None, None, None)
    assert stopped == [2]  # the stop came before any restore
    assert session.log[2:] == [("left", 0x2040, bytes([7])), ("right", 0x2040, bytes([7]))]


@pytest.mark.parametrize("how", ["diffdrive", "sigma_jog"])
def test_one_pair_drive_dying_stops_the_partner_at_once_and_ends_the_command_naming_it(tmp_path, how, monkeypatch):
    """`right` dies mid-move. Its partner gets its stop after at most one request to
    the dead drive (the request's attempts), never after the dead drive's timeouts of every exit step;
    the command ends with an error naming the dead drive, and the dead drive costs no more requests
    in the exit (the guard, the common start's restore and the recorder skip a silent drive)."""
    import time

    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.errors import CommunicationError

    # the tool's own count of requests to the drive once it was found silent (load cannot change it)
    after_silent: list[str] = []
    real_exchange = DriveClient._exchange

    def exchange(self, frame, letters, index, **kw):
        if self.name == "right" and self.silent:
            after_silent.append(letters)
        return real_exchange(self, frame, letters, index, **kw)
    monkeypatch.setattr(DriveClient, "_exchange", exchange)

    cfg = load_config(JOG_CONFIG)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        right = s.sim.drives["right"]
        right_node = right.node

        def sleep(seconds: float) -> None:
            """The command's poll sleep: once both motors run (right has its BG), right dies."""
            with s.sim.lock:
                moving = any(f[:2] == b"BG" for _, i, f in right.received if i in (0x300 + right_node, 0x300 + 125))
                if moving and not right.dead and right.motor_on:
                    right.die()
            time.sleep(seconds)

        with pytest.raises(CommunicationError, match="right"):
            if how == "diffdrive":
                diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="2500counts", delta="0counts",
                                                                     relative=True, uncalibrated=True), sleep=sleep)
            else:
                axis = resolve_axis(cfg, "pitch")
                joint_jog.run(s, axis, parse_request(axis, mode="velocity", velocity="1000counts/s", duration=5.0),
                              sleep=sleep)
        with s.sim.lock:
            died = [t for t, event in s.sim.drives["right"].events if event == "motor off: the drive died"]
        assert died, "the drive did not die during the move"
        t_dead = died[0]
        left_st = [t for t, i, f in _frames(s, "left") if i == 0x300 + 10 and f[:2] == b"ST" and t >= t_dead]
        assert left_st, "the partner was never stopped"
        # once the dead drive was found silent it gets one more plain request on the way out, no
        # timeout per exit step (those cost 11 requests and more)
        assert len(after_silent) <= 1, after_silent
        assert motors_off(s)


def _group_id(s, name):
    return bytes(s.sdo(drive_ref(s.cfg, name)).upload(0x2040, 0))[0]


def test_a_group_id_the_start_could_not_put_back_goes_back_at_the_guards_exit():
    """The start's close skips a drive that did not answer its stop; the guard's exit reaches it
    again and puts its group id back, naming it, instead of reading "settings put back" over it."""
    from sherpa_cli.bus import journal
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

    cfg = load_config(JOG_CONFIG)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [drive_ref(cfg, d) for d in ("left", "right")]
        before = {r.name: _group_id(s, r.name) for r in refs}
        with MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g:
            start = CommonStart(s, refs, {r.name: g.client(r) for r in refs}, "group", cfg.motion.pair_group_id,
                                stop=lambda: ["right"])  # as if right had not answered the stop
            with start:
                assert _group_id(s, "right") == cfg.motion.pair_group_id != before["right"]
            assert _group_id(s, "right") == cfg.motion.pair_group_id  # the close skipped it
            assert journal.leftover(refs[1]) == [] and journal.own_steps(refs[1], "pair start")
        assert {r.name: _group_id(s, r.name) for r in refs} == before
        assert all(not journal.steps_of(journal._load(journal.path_for(r.bus, r.node))) for r in refs)
        right = next(d for d in g.report.drives if d.drive == "right")
        assert f"0x2040:0={before['right']:#x}" in right.restored and not right.problems
        left = next(d for d in g.report.drives if d.drive == "left")
        assert not any(x.startswith("0x2040") for x in left.restored)  # the close put it back


def test_a_group_id_that_cannot_be_put_back_at_the_exit_is_named_with_recover(monkeypatch):
    from sherpa_cli.bus import journal
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

    cfg = load_config(JOG_CONFIG)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        refs = [drive_ref(cfg, d) for d in ("left", "right")]
        with (pytest.raises(SafetyError, match=r"right: 0x2040:0=0x0 not put back .*`sherpa recover` puts it back"),
              MotionGuard(s, refs, settings=MotionSettings.from_config(cfg)) as g):
            with CommonStart(s, refs, {r.name: g.client(r) for r in refs}, "group", cfg.motion.pair_group_id,
                             stop=lambda: ["right"]):
                pass
            # the group id object refuses every write from now on
            sdo = s.sdo(refs[1])
            real = sdo.download

            def refuse(index, sub, data, *, name=None):
                if index == 0x2040:
                    from sherpa_cli.errors import SdoError
                    raise SdoError("right: SDO abort (read only)", detail="read only", reason="abort")
                return real(index, sub, data, name=name)
            monkeypatch.setattr(sdo, "download", refuse)
        right = next(d for d in g.report.drives if d.drive == "right")
        assert any(p.startswith("0x2040:0=") and "`sherpa recover` puts it back" in p for p in right.problems)
        assert right.line().endswith("`sherpa recover` puts it back")
        assert [st.name for st in journal.own_steps(refs[1], "pair start")] == ["0x2040:0"]
        journal.forget(refs[1], "pair start")
