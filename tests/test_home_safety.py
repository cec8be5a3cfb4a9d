"""Safety regressions of `sherpa home` (review 2, findings R1, R2, R10) on the simulated arm
(tests/data/home-arm.yaml):

- R1: a re-home clears the calibration mark (UI[flag] = 0) on the unit's drives before it arms the
  drive's homing, so a re-home that fails after a counter was reset leaves the joint uncalibrated
  instead of "calibrated" with a counter that no longer means the joint;
- R2: HM[1] (the drive's homing) is disarmed on every exit path of an armed search, Ctrl-C included,
  so a later jog over the switch is not stopped and its PX reset by a left-over home event;
- R10: in a pair search, once one drive's home event fired, the other's must fire within
  ``homing.pair_edge_window_ms``, else both motors are stopped and the error names a wiring fault
  (before: the other motor ran its whole PR alone, Σ and Δ both off their ranges).
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.elmo import codec
from sherpa_cli.errors import ConfigError, SafetyError
from sherpa_cli.motion import calibration
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops import home
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "tests" / "data" / "home-arm.yaml"


def variant(tmp_path: Path, *replace: tuple[str, str]):
    text = ARM.read_text(encoding="utf-8")
    for old, new in replace:
        assert old in text
        text = text.replace(old, new, 1)
    path = tmp_path / "arm.yaml"
    path.write_text(text, encoding="utf-8")
    return load_config(path)


def motor(session, drive: str) -> tuple[float, int]:
    """(the motor's real position, its PX) in the simulator."""
    with session.sim.lock:
        d = session.sim.drives[drive]
        return d.position, d.px


def ram(session, drive: str, key: str) -> int:
    with session.sim.lock:
        return int(session.sim.drives[drive].ram.get(key, 0))


def calibrated(session, cfg, joint: str) -> bool:
    return calibration.read_calibration(cfg, cfg.joints[joint],
                                        lambda n: session.client(drive_ref(cfg, n))).calibrated


# -- R1: the calibration mark ------------------------------------------------------------------------

def test_a_failed_pair_rehome_leaves_no_stale_calibration_mark():
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        home.run_home(s, home.plan_home(cfg, ["diff"]))
        assert calibrated(s, cfg, "pitch")
        for d in ("pair_a", "pair_b"):
            s.sim.press_switch(d, 3, False)  # the Δ (roll) low switch stays open: the re-home fails at Δ
        with pytest.raises(SafetyError, match="roll"):
            home.run_home(s, home.plan_home(cfg, ["diff"]))
        # the Σ re-approach already reset both counters (Σ reference): they no longer mean the joint,
        # and the joint must not read calibrated
        (a, pa), (b, pb) = motor(s, "pair_a"), motor(s, "pair_b")
        assert abs((pa + pb) - (a + b)) > 1
        assert not calibrated(s, cfg, "pitch") and not calibrated(s, cfg, "roll")
        assert ram(s, "pair_a", "UI[3]") == 0 and ram(s, "pair_b", "UI[3]") == 0


def test_a_failed_rehome_of_a_plain_joint_clears_its_mark():
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        home.run_home(s, home.plan_home(cfg, ["stiff"]))
        assert calibrated(s, cfg, "stiff")
        s.sim.press_switch("stiff_drive", 3, False)  # the low end switch stays open
        with pytest.raises(SafetyError, match="stiff"):
            home.run_home(s, home.plan_home(cfg, ["stiff"]))
        assert not calibrated(s, cfg, "stiff")


def test_the_mark_is_cleared_before_the_homing_is_armed():
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        home.run_home(s, home.plan_home(cfg, ["stiff"]))
        with s.sim.lock:
            before = len(s.sim.drives["stiff_drive"].received)
        home.run_home(s, home.plan_home(cfg, ["stiff"]))
        with s.sim.lock:
            frames = [bytes(f) for _, i, f in s.sim.drives["stiff_drive"].received[before:] if 0x300 < i < 0x380]
        sets = [(r.letters, r.index, r.value) for r in map(codec.decode_request, frames) if r.kind == "set"]
        ui_clear = sets.index(("UI", 3, 0))
        first_hm = next(i for i, (letters, _, _) in enumerate(sets) if letters == "HM")
        assert ui_clear < first_hm
        assert ram(s, "stiff_drive", "UI[3]") == 1  # marked again at the end of the successful re-home


# -- R2: HM[1] disarmed on every exit path ---------------------------------------------------------

def test_ctrl_c_during_the_search_disarms_the_homing():
    cfg = load_config(ARM)
    calls = {"n": 0}

    def sleep(t: float) -> None:
        calls["n"] += 1
        if calls["n"] == 3:  # inside the search's wait, with HM[1] armed
            raise KeyboardInterrupt
        time.sleep(t)

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(KeyboardInterrupt):
            home.run_home(s, home.plan_home(cfg, ["yaw"]), sleep=sleep)
        assert ram(s, "yaw_drive", "HM[1]") == 0, "HM[1] still armed after Ctrl-C"
        with s.sim.lock:
            assert not s.sim.drives["yaw_drive"].motor_on  # the guard's stop came first


def test_an_error_during_a_pair_search_disarms_both_drives():
    cfg = load_config(ARM)
    calls = {"n": 0}

    def sleep(t: float) -> None:
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("boom (test)")
        time.sleep(t)

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        with pytest.raises(RuntimeError, match="boom"):
            home.run_home(s, home.plan_home(cfg, ["diff"]), sleep=sleep)
        assert ram(s, "pair_a", "HM[1]") == 0 and ram(s, "pair_b", "HM[1]") == 0


# -- R10: one drive of a pair sees the edge, the other does not -------------------------------------

def test_pair_search_stops_both_when_only_one_drive_sees_the_switch(tmp_path):
    # pair_b's wire of the Σ low switch (input 1) goes to input 5: only pair_a's homing fires
    cfg = variant(tmp_path, ("buses:", "  wiring: {pair_b: {swap: [[1, 5]]}}\n"
                                       "homing: {pair_edge_window_ms: 50}\nbuses:"))
    assert cfg.homing.pair_edge_window_ms == 50
    with stepped_session(cfg) as (s, stepped):  # the 50 ms window and the drift in simulated time
        (a0, _), (b0, _) = motor(s, "pair_a"), motor(s, "pair_b")
        with pytest.raises(SafetyError, match=r"pitch: pair_a saw the switch on input 1 during the search but "
                                              r"pair_b did not within 50 ms.*wiring fault") as info:
            home.run_home(s, home.plan_home(cfg, ["diff"]), clock=stepped.now, sleep=stepped.sleep)
        assert "--check-wiring pitch" in (info.value.hint or "")
        (a, _), (b, _) = motor(s, "pair_a"), motor(s, "pair_b")
        with s.sim.lock:
            assert not s.sim.drives["pair_a"].motor_on and not s.sim.drives["pair_b"].motor_on
        # pair_b was stopped shortly after pair_a's edge, not at the end of its PR (545 counts; before
        # the fix Δ drifted about 300 counts, into the hard stop)
        assert abs((a - b) - (a0 - b0)) < 200, f"Δ drifted {(a - b) - (a0 - b0):.0f} counts"
        assert ram(s, "pair_a", "HM[1]") == 0 and ram(s, "pair_b", "HM[1]") == 0


def test_pair_edge_window_is_validated(tmp_path):
    with pytest.raises(ConfigError, match="pair_edge_window_ms"):
        variant(tmp_path, ("buses:", "homing: {pair_edge_window_ms: 0}\nbuses:"))
    assert load_config(ARM).homing.pair_edge_window_ms == 100


# -- an interrupted home says what it left -----------------------------------------------------------

def test_ctrl_c_during_a_pair_home_reports_the_stop_and_the_joints_left_unhomed():
    cfg = load_config(ARM)
    pair = next(iter(cfg.pairs))
    calls = {"n": 0}
    steps: list[str] = []

    def sleep(t: float) -> None:
        if steps:  # the search reports its steps: the guard is entered and the motors are on
            calls["n"] += 1
            if calls["n"] == 3:  # inside the pair's search
                raise KeyboardInterrupt
        time.sleep(t)

    report = home.HomeReport()
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s, pytest.raises(KeyboardInterrupt):
        home.run_home(s, home.plan_home(cfg, [pair]), sleep=sleep, report=report, on_step=steps.append)
    assert report.interrupted == pair
    assert sorted(report.not_homed) == sorted(j.name for j in cfg.joints.values() if j.pair == pair)
    assert report.stop is not None and {d.drive for d in report.stop.drives} == {cfg.pairs[pair].drive_a, cfg.pairs[pair].drive_b}
    assert all(d.motor_off or d.stopped_by == "motor was off" for d in report.stop.drives)
    assert steps and "search" in steps[0] and " s (homing " in steps[0]


def test_cli_home_interrupted_prints_the_stop_report_and_which_joints_are_not_homed(cli, monkeypatch):
    from sherpa_cli.ops import home as home_mod

    real_wait = home_mod._Runner.wait
    calls = {"n": 0}

    def wait(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 1:
            raise KeyboardInterrupt
        return real_wait(self, *a, **k)
    monkeypatch.setattr(home_mod._Runner, "wait", wait)
    result = cli("--sim", "home", "shoulder_diff", "--yes")
    assert result.exit_code == 130, result.transcript()
    assert "stop: shoulder_2a (can0:20): stopped" in result.stderr
    assert "not homed: shoulder_pitch, shoulder_roll (shoulder_diff did not finish" in result.stderr
    assert "Traceback" not in result.stderr


# -- a home that resumes past its switch --------------------------------------------------------------

def test_a_home_interrupted_past_its_switch_goes_back_before_it_instead_of_into_the_hard_stop():
    """R5: Ctrl-C after the search met the home switch, the joint then past it (the search's overshoot,
    a push by hand): the next home searched on, away from the switch, 6.9 s into the hard stop, and
    ended "blocked". The unfinished home leaves UI[3] = 2 (PX counts from the switch); the next home
    moves back before the switch first, then finds it."""
    from sherpa_cli.motion.calibration import SWITCH_SEEN

    cfg = load_config(ROOT / "configs/sherpa-arm.yaml")
    joint = "shoulder_yaw"  # a home switch at 0, searched upwards at 300 counts/s
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        drive = s.sim.drives["shoulder_1a"]

        def sleep(t: float) -> None:
            if drive.ram.get(f"UI[{cfg.protocol.calibration_flag}]") == SWITCH_SEEN:
                raise KeyboardInterrupt  # home saw the switch met: PX counts from it, not homed yet
            time.sleep(t)

        with pytest.raises(KeyboardInterrupt):
            home.run_home(s, home.plan_home(cfg, [joint]), sleep=sleep)
        ref = resolve_target(cfg, "shoulder_1a")
        c = s.client(ref)
        assert int(c.get("UI", cfg.protocol.calibration_flag)) == SWITCH_SEEN
        with s.sim.lock:
            drive.motor.counts += 800  # pushed on, well past the switch (it reads released there)
        # the simulated inputs follow the motor at its next step, not at this assignment
        deadline = time.monotonic() + 10  # a hang guard: a step is due every 2 ms
        while c.get("IP") & 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not c.get("IP") & 1  # input 1, the home switch: released
        events_before = len(drive.events)
        report = home.run_home(s, home.plan_home(cfg, [joint]))
        assert report.interrupted is None and not report.not_homed, report.as_dict()
        after = [text for _, text in drive.events[events_before:]]
        assert not [t for t in after if "blocked" in t or "stall" in t], after
        assert int(c.get("UI", cfg.protocol.calibration_flag)) == 1
        assert abs(int(c.get("PX"))) <= 5


class _StoppedFromElsewhere:
    """A guard over one drive whose search was stopped by `sherpa stop` from another terminal: the
    drive stands (MS 1) short of its target, no home event (HM[1] 1), and the stop's MO=0 comes a few
    polls after its ST, as `sherpa stop` waits for standstill between them."""

    def __init__(self, mo_off_after: int | None) -> None:
        self.polls, self.mo_off_after = 0, mo_off_after

    def check(self) -> None:
        self.polls += 1

    def query(self, ref, letters: str, index: int = 0) -> int:
        if letters == "HM":
            return 1
        if letters == "MS":
            return 1
        if letters == "MO":
            return 0 if self.mo_off_after is not None and self.polls > self.mo_off_after else 1
        return 0  # MF, PX


def test_a_search_stopped_from_elsewhere_is_never_reported_as_the_search_bound():
    """`sherpa stop` sends ST, waits for standstill, then MO=0: a search that saw the motion end before
    the MO=0 used to say "the switch never triggered: stopped at the search bound"."""
    cfg = load_config(ARM)
    t = [0.0]

    def sleep(dt: float) -> None:
        t[0] += dt

    runner = home._Runner(None, cfg,  # type: ignore[arg-type]  # the session is never used here
                           MotionSettings(standstill_timeout=1.0, poll_interval=0.01), lambda: t[0], sleep)
    refs = {"yaw_drive": resolve_target(cfg, "yaw_drive")}
    with pytest.raises(SafetyError) as info:
        runner.wait(_StoppedFromElsewhere(mo_off_after=5), refs, distance=1000, speed=300, homing=True,
                    what="yaw: the search")
    assert str(info.value) == ("yaw_drive: the motor was switched off during yaw: the search: MO=0 from elsewhere "
                               "(sherpa stop, another tool)")
    with pytest.raises(SafetyError) as info:
        runner.wait(_StoppedFromElsewhere(mo_off_after=None), refs, distance=1000, speed=300, homing=True,
                    what="yaw: the search")
    assert str(info.value).startswith("yaw: the search: stopped short of its bound without the home event")
    assert t[0] >= 1.0  # it waited the standstill timeout for an MO=0 that never came
