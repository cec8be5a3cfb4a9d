"""Joint-limit watch (seed 6.1) on samples: breach detection, the way back, the loop; and the pair's
joint-to-motor maps for speed and current."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config import load_config
from sherpa_cli.joints.diffpair import hold_other, motor_currents, motor_velocities, to_joints
from sherpa_cli.motion.axis import Axis, joints_moved_by
from sherpa_cli.motion.limit_watch import Breach, check, recovery_targets, watch
from sherpa_cli.sim.clock import ManualClock

ARM = "configs/sherpa-arm.yaml"

PLAIN = Axis("yaw", "plain", full=(-1750, 1750), normal=(-1714, 1714), drive_a="m1")
SIGMA = Axis("pitch", "sigma", full=(-1500, 1500), normal=(-1440, 1440), drive_a="a", drive_b="b", sign=1)
DELTA = Axis("roll", "delta", full=(-1000, 1000), normal=(-950, 950), drive_a="a", drive_b="b", sign=-1)
PAIR = [SIGMA, DELTA]


def test_joints_of_the_arm_config():
    cfg = load_config(ARM)
    pair = joints_moved_by(cfg, ["shoulder_2b"])
    assert [(j.name, j.drive_a, j.drive_b, j.sign) for j in pair] == [
        ("shoulder_pitch", "shoulder_2a", "shoulder_2b", 1), ("shoulder_roll", "shoulder_2a", "shoulder_2b", -1)]
    assert pair[0].full == (-1500, 1500) and pair[0].normal == (-1440, 1440)
    (yaw,) = joints_moved_by(cfg, ["shoulder_1a"])
    assert (yaw.name, yaw.drives, yaw.normal) == ("shoulder_yaw", ("shoulder_1a",), (-1714, 1714))


def test_inside_and_on_the_edge_is_no_breach():
    assert check([PLAIN], {"m1": 1750}) == []
    assert check([PLAIN], {"m1": -1750}) == []
    assert check(PAIR, {"a": 1000, "b": 500}) == []  # Σ 1500, Δ 500


def test_plain_breach_goes_back_to_the_nearest_normal_edge():
    (b,) = check([PLAIN], {"m1": 1751})
    assert (b.joint, b.position, b.side, b.back_to) == ("yaw", 1751, "high", 1714)
    assert recovery_targets([PLAIN], {"m1": 1751}, [b]) == {"m1": 1714}
    (b,) = check([PLAIN], {"m1": -1800})
    assert (b.side, b.back_to) == ("low", -1714)
    assert "left its full range [-1750, 1750] on the low side" in b.describe()


def test_pair_breach_is_judged_in_joint_space():
    # Each motor is well inside any per-motor box of ±1250, but Σ = 1510 is past its full range.
    motors = {"a": 755, "b": 755}
    (b,) = check(PAIR, motors)
    assert (b.joint, b.position) == ("pitch", 1510)
    targets = recovery_targets(PAIR, motors, [b])
    assert to_joints(targets["a"], targets["b"]) == (1440, 0)  # Σ to its normal edge, Δ held


def test_pair_recovery_keeps_the_other_joint_and_fixes_parity_with_it():
    motors = {"a": 806, "b": 705}  # Σ 1511, Δ 101
    breaches = check(PAIR, motors)
    assert [b.joint for b in breaches] == ["pitch"]
    s, d = to_joints(*(recovery_targets(PAIR, motors, breaches)[k] for k in ("a", "b")))
    assert s == 1440 and abs(d - 101) == 1  # Σ exact, Δ gives way by one count (parity)


def test_pair_delta_breach_moves_delta_back():
    motors = {"a": 520, "b": -490}  # Σ 30, Δ 1010
    breaches = check(PAIR, motors)
    assert [(b.joint, b.side) for b in breaches] == [("roll", "high")]
    s, d = to_joints(*(recovery_targets(PAIR, motors, breaches)[k] for k in ("a", "b")))
    assert (s, d) == (30, 950)


def test_both_pair_joints_out():
    motors = {"a": 1300, "b": 250}  # Σ 1550, Δ 1050
    breaches = check(PAIR, motors)
    assert {b.joint for b in breaches} == {"pitch", "roll"}
    s, d = to_joints(*(recovery_targets(PAIR, motors, breaches)[k] for k in ("a", "b")))
    assert (s, d) == (1440, 950) or (abs(s - 1440) <= 1 and d == 950)


def test_untouched_drives_get_no_target():
    motors = {"m1": 1800, "a": 0, "b": 0}
    breaches = check([PLAIN, *PAIR], motors)
    assert recovery_targets([PLAIN, *PAIR], motors, breaches) == {"m1": 1714}


@given(a=st.integers(-3000, 3000), b=st.integers(-3000, 3000))
def test_recovery_always_lands_inside_both_normal_ranges(a, b):
    motors = {"a": a, "b": b}
    breaches = check(PAIR, motors)
    if not breaches:
        assert recovery_targets(PAIR, motors, breaches) == {}
        return
    t = recovery_targets(PAIR, motors, breaches)
    s, d = to_joints(t["a"], t["b"])
    assert SIGMA.normal[0] <= s <= SIGMA.normal[1]
    assert DELTA.normal[0] <= d <= DELTA.normal[1]
    s0, d0 = to_joints(a, b)
    for joint, before, after in ((SIGMA, s0, s), (DELTA, d0, d)):
        lo, hi = joint.normal
        nearest = min(max(before, lo), hi)
        assert abs(after - nearest) <= 1  # the nearest normal edge (or stays), one count for parity


# -- the loop ---------------------------------------------------------------------------------

class Track:
    """Motor positions that move on a fake clock, sampled like a drive's PX."""

    def __init__(self, clock: ManualClock, speeds: dict[str, float]) -> None:
        self.clock, self.speeds = clock, speeds
        self.start = clock.now()

    def __call__(self) -> dict[str, int]:
        t = self.clock.now() - self.start
        return {k: int(v * t) for k, v in self.speeds.items()}


def loop(track, joints, **kw):
    clock = track.clock
    return watch(joints, track, clock=clock.now, sleep=clock.advance, interval=0.01, **kw)


def test_watch_stops_on_the_first_sample_past_the_full_range():
    clock = ManualClock()
    result = loop(Track(clock, {"a": 500.0, "b": 500.0}), PAIR, duration=10.0)
    assert result.outcome == "breach"
    (b,) = result.breaches
    assert b.joint == "pitch" and 1500 < b.position <= 1510  # Σ grows 10 counts per 10 ms sample
    assert result.joints["pitch"] == b.position and result.joints["roll"] == 0
    assert result.elapsed == pytest.approx(1.51, abs=0.011)


def test_watch_ends_when_the_duration_is_over():
    clock = ManualClock()
    result = loop(Track(clock, {"m1": 100.0}), [PLAIN], duration=0.25)
    assert result.outcome == "elapsed" and result.elapsed == pytest.approx(0.25)
    assert result.motors == {"m1": 25}


def test_watch_ends_when_the_motion_finishes():
    clock = ManualClock()
    result = loop(Track(clock, {"m1": 100.0}), [PLAIN], finished=lambda m: m["m1"] >= 50)
    assert result.outcome == "finished" and result.motors["m1"] == 50


def test_breach_wins_over_finished_and_drive_check_runs_each_sample():
    clock = ManualClock()
    calls = []
    result = loop(Track(clock, {"m1": 10_000.0}), [PLAIN], finished=lambda m: True,
                  check_drives=lambda: calls.append(1))
    assert result.outcome == "finished" and calls == [1]  # t=0: inside, finished
    clock2 = ManualClock()
    track = Track(clock2, {"m1": 10_000.0})
    clock2.advance(0.2)  # 2000 counts: out at the first sample
    result = loop(track, [PLAIN], finished=lambda m: True)
    assert result.outcome == "breach"


def test_a_failing_drive_check_ends_the_watch():
    clock = ManualClock()

    def fault() -> None:
        raise RuntimeError("MF")

    with pytest.raises(RuntimeError):
        loop(Track(clock, {"m1": 1.0}), [PLAIN], duration=1.0, check_drives=fault)


def test_watch_must_end():
    with pytest.raises(ValueError):
        watch([PLAIN], lambda: {"m1": 0}, clock=lambda: 0.0, sleep=lambda s: None, interval=0.01)


# -- joint speeds and currents to motors -----------------------------------------------------

def test_pair_speed_and_current_maps():
    assert motor_velocities(300, 0) == (150, 150)
    assert motor_velocities(0, 300) == (150, -150)
    assert motor_velocities(-300, 0) == (-150, -150)
    assert motor_velocities(301, 0) == (151, 151)  # one count/s over, the held joint still 0
    assert motor_currents(1.5, 0.0) == (1.5, 1.5)
    assert motor_currents(0.0, 1.5) == (1.5, -1.5)


@given(v=st.integers(-10**6, 10**6))
def test_one_joint_speed_leaves_the_other_at_zero(v):
    a, b = motor_velocities(v, 0)
    s, d = to_joints(a, b)
    assert d == 0 and abs(s - v) <= 1
    a, b = motor_velocities(0, v)
    s, d = to_joints(a, b)
    assert s == 0 and abs(d - v) <= 1


@given(s=st.integers(-5000, 5000), d=st.integers(-5000, 5000), moving=st.sampled_from(["sigma", "delta"]))
def test_hold_other_keeps_the_moving_joint_exact(s, d, moving):
    s2, d2 = hold_other(s, d, moving)
    assert (s2 - d2) % 2 == 0
    if moving == "sigma":
        assert s2 == s and abs(d2 - d) <= 1
    else:
        assert d2 == d and abs(s2 - s) <= 1


def test_hold_other_prefers_inside_the_held_range():
    assert hold_other(101, 0, "sigma") == (101, -1)  # toward zero first: -1 before +1
    assert hold_other(101, 0, "sigma", held_range=(0, 10)) == (101, 1)


def test_breach_json():
    b = Breach("yaw", 1751, (-1750, 1750), (-1714, 1714))
    assert b.as_dict() == {"joint": "yaw", "position": 1751, "full_range": [-1750, 1750], "side": "high",
                           "back_to": 1714}


def test_watch_ends_when_the_time_left_is_too_small_to_move_the_clock():
    # started at 0.15 s, twenty 10 ms sleeps later the clock reads 0.35 and the float difference is
    # 0.19999999999999998: 0.35 plus what is left is 0.35 again -- a watch that sleeps the rest
    # waits forever on a stepped clock
    clock = ManualClock()
    for _ in range(15):
        clock.advance(0.01)
    sleeps = []

    def sleep(s: float) -> None:
        sleeps.append(s)
        assert len(sleeps) < 100, "the watch does not end"
        clock.advance(s)
    result = watch([PLAIN], Track(clock, {"m1": 100.0}), clock=clock.now, sleep=sleep, interval=0.01, duration=0.2)
    assert result.outcome == "elapsed"
