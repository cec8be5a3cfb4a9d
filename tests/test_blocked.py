"""A commanded move that stops progressing ends as "blocked" within about motion.stall_time, naming
the end switch that blocks it: a pair move into a pressed Σ end switch ran for its
whole time bound (12.6 s) and then said only that it did not reach its target."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.errors import SafetyError
from sherpa_cli.motion.axis import resolve_axis
from sherpa_cli.motion.blocked import StallWatch, min_progress_for, torque_min_progress
from sherpa_cli.motion.request import parse_request
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.ops import diffdrive
from sherpa_cli.ops.diffdrive import PairTarget
from sherpa_cli.ops.jog import run_jog
from sherpa_cli.sim.arm import SimArm

ARM = Path(__file__).resolve().parent / "data" / "home-arm.yaml"


def test_stall_watch_fires_only_after_the_stall_time_without_progress():
    w = StallWatch(stall_time=1.0, min_progress=5)
    assert not w.feed({"a": 0}, 0.0)
    assert not w.feed({"a": 4}, 0.9)  # less than min_progress: no progress...
    assert w.feed({"a": 4}, 1.0)  # ...for the whole stall time: blocked
    w = StallWatch(stall_time=1.0, min_progress=5)
    w.feed({"a": 0, "b": 0}, 0.0)
    assert not w.feed({"a": 0, "b": 5}, 0.9)  # one motor progressed: the clock restarts
    assert not w.feed({"a": 0, "b": 6}, 1.8)
    assert w.feed({"a": 0, "b": 6}, 2.0)


def test_a_stall_time_of_zero_turns_the_watch_off():
    w = StallWatch(stall_time=0.0, min_progress=2)
    assert not any(w.feed({"a": 0}, t) for t in (0.0, 10.0, 100.0))


@given(speed=st.floats(min_value=-1e6, max_value=1e6, allow_nan=False), stall=st.floats(min_value=0.01, max_value=30))
def test_min_progress_is_a_tenth_of_the_travel_and_at_least_two_counts(speed, stall):
    got = min_progress_for(speed, stall)
    assert got >= 2
    assert got <= max(2, abs(speed) * stall * 0.1)


def test_a_pair_move_into_a_pressed_end_switch_ends_blocked_naming_it():
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        for d in ("pair_a", "pair_b"):
            s.sim.press_switch(d, 2, True)  # the Σ (pitch) high end switch is held
        with pytest.raises(SafetyError, match=r"diff: blocked: no progress for 1 s; pitch high end switch \(input 2\) active"):
            diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="400counts", delta="0counts",
                                                                 relative=True, uncalibrated=True))
        with s.sim.lock:
            assert not any(d.motor_on for d in s.sim.drives.values())


def test_a_plain_jog_into_a_pressed_end_switch_ends_blocked_naming_it():
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        c = s.client(resolve_axis(cfg, "stiff").ref)
        c.nmt_start()
        c.set("IL", 3, cfg.il_codes.stop)  # the switch's stop function, as program-limits writes it
        s.sim.press_switch("stiff_drive", 3, True)  # the low end switch is held
        with pytest.raises(SafetyError, match=r"blocked: no progress for 1 s; stiff low end switch \(input 3\) active"):
            run_jog(s, resolve_axis(cfg, "stiff"), parse_request(resolve_axis(cfg, "stiff"), mode="velocity", velocity=-0.5, duration=10.0),
                    settings=MotionSettings.from_config(cfg))
        with s.sim.lock:
            assert not s.sim.drives["stiff_drive"].motor_on


@given(standstill=st.floats(min_value=0, max_value=100), stall=st.floats(min_value=0.01, max_value=30))
def test_torque_progress_is_a_mean_speed_above_standstill_and_at_least_two_counts(standstill, stall):
    got = torque_min_progress(standstill, stall)
    assert got >= 2
    assert got >= standstill * stall  # slower than standstill over the stall time is no progress
    assert got <= max(2, standstill * stall + 1)


def test_a_torque_jog_into_a_pressed_end_switch_ends_blocked_naming_it():
    cfg = load_config(ARM.parent / "matrix-arm.yaml")  # stiff has current limits there
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        c = s.client(resolve_axis(cfg, "stiff").ref)
        c.nmt_start()
        c.set("IL", 3, cfg.il_codes.stop)  # the switch's stop function, as program-limits writes it
        s.sim.press_switch("stiff_drive", 3, True)  # the low end switch is held
        axis = resolve_axis(cfg, "stiff")
        with pytest.raises(SafetyError, match=r"blocked: no progress for 0.3 s; stiff low end switch \(input 3\) "
                           "active"):
            run_jog(s, axis, parse_request(axis, mode="torque", torque=-0.3, duration=5.0),
                    settings=MotionSettings.from_config(cfg))
        with s.sim.lock:
            assert not s.sim.drives["stiff_drive"].motor_on


class _StopFromElsewhere:
    """A sleep on stepped time that, once ``name`` has moved past ``after`` counts, stops it as
    `sherpa stop` from another terminal does on a busy host: ST, then MO=0 only ``mo_off_after`` s
    later (None: never)."""

    def __init__(self, session, stepped, name: str, after: int, mo_off_after: float | None) -> None:
        self.s, self.stepped, self.name, self.after, self.mo_off_after = session, stepped, name, after, mo_off_after
        self.st_at: float | None = None

    def __call__(self, dt: float) -> None:
        with self.s.sim.lock:
            drive = self.s.sim.drives[self.name]
            if self.st_at is None and drive.motor_on and abs(drive.px) > self.after:
                drive.execute("ST")
                self.st_at = self.stepped.now()
            elif (self.st_at is not None and self.mo_off_after is not None and drive.motor_on
                  and self.stepped.now() - self.st_at >= self.mo_off_after):
                drive.write_param("MO", 0)
        self.stepped.sleep(dt)


@pytest.mark.parametrize("mo_off_after,said", [
    (1.5, r"the motor was switched off during the (jog|move): MO=0 from elsewhere"),
    (None, r"the motors stand short of the target with their profiles ended, still on: stopped \(ST\) "
           r"from elsewhere"),
])
def test_a_position_jog_stopped_from_elsewhere_is_never_called_blocked(mo_off_after, said):
    """`sherpa stop` from another terminal on a busy host: its ST stopped the jog and its MO=0 came
    more than the stall time later; the jog said "blocked: no progress for 1 s ... a hard stop or a
    load?" -- the stop from elsewhere is the reason, named (or, without the MO=0, the ST)."""
    from motion_helpers import JOG_CONFIG, stepped_session

    cfg = load_config(JOG_CONFIG)
    with stepped_session(cfg) as (s, stepped):
        target = resolve_axis(cfg, "j2")
        sleep = _StopFromElsewhere(s, stepped, "elbow", 200, mo_off_after)
        with pytest.raises(SafetyError, match=said) as info:
            run_jog(s, target, parse_request(target, mode="position", to="1500counts", uncalibrated=True),
                    settings=MotionSettings.from_config(cfg), clock=stepped.now, sleep=sleep)
        assert "blocked: no progress" not in str(info.value) and sleep.st_at is not None


@pytest.mark.parametrize("mo_off_after", [1.5, None])
def test_a_pair_move_stopped_from_elsewhere_is_never_called_blocked(mo_off_after):
    from motion_helpers import JOG_CONFIG, stepped_session

    cfg = load_config(JOG_CONFIG)
    with stepped_session(cfg) as (s, stepped):
        sleep = _StopFromElsewhere(s, stepped, "left", 150, mo_off_after)
        with pytest.raises(SafetyError) as info:
            diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="1500counts", delta="0counts", relative=True,
                                                                uncalibrated=True),
                               clock=stepped.now, sleep=sleep)
        assert "blocked: no progress" not in str(info.value) and sleep.st_at is not None
        assert "from elsewhere" in str(info.value)
