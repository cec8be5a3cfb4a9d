"""motion/plan.py: the multi-joint plan (pure). Every motor's profile is one shape scaled by its
distance, so every joint starts and arrives together; no joint runs above its speed limit."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError
from sherpa_cli.joints.diffpair import to_joints
from sherpa_cli.motion.plan import joint_targets, plan_motion, profile_time

CFG = load_config(Path(__file__).resolve().parent / "data" / "move-arm.yaml")
ZERO = {"yaw": 0, "elbow": 0, "left": 0, "right": 0}


def test_the_slowest_joint_runs_at_its_limit_and_sets_the_time():
    p = plan_motion(CFG, {"j1": 1000, "j2": -500}, ZERO)
    assert p.paced_by == "j1"
    assert p.joint("j1").speed == pytest.approx(7999)  # the limit 8000, one count/s kept for rounding up
    assert p.joint("j2").speed == pytest.approx(7999 / 2)
    yaw, elbow = (m for m in p.motors if m.drive in ("yaw", "elbow"))
    assert (yaw.profile.sp, yaw.profile.ac) == (7999, 40000)
    assert (elbow.profile.sp, elbow.profile.ac) == (4000, 20000)  # half the distance: half of everything


def test_a_pair_moves_both_motors_in_one_profile_and_its_other_joint_holds():
    p = plan_motion(CFG, {"pitch": 400}, {**ZERO, "left": 10, "right": -10})  # Δ = 20 holds
    assert p.held == {"roll": 20}
    left, right = p.motors
    assert (left.target, right.target) == (210, 190) and to_joints(210, 190) == (400, 20)
    assert left.profile == right.profile
    assert [a.name for a in p.watched] == ["pitch", "roll"]


def test_parity_makes_the_held_joint_give_way_by_one_count():
    p = plan_motion(CFG, {"pitch": 401}, ZERO)  # Σ odd, Δ = 0 even: Δ gives way
    (a, b) = p.motors
    s, d = to_joints(a.target, b.target)
    assert s == 401 and abs(d) == 1


def test_a_joint_already_there_switches_no_motor_on():
    p = plan_motion(CFG, {"j1": 0, "j2": 100}, ZERO)
    assert [m.drive for m in p.motors] == ["elbow"]
    nothing = plan_motion(CFG, {"j1": 0}, ZERO)
    assert nothing.motors == () and nothing.duration == 0


@pytest.mark.parametrize("targets,scale,phrase", [
    ({"j9": 0}, 1.0, "joint 'j9' is not a joint of the config"),
    ({"j1": 1950}, 1.0, "outside the joint's normal range [-1900, 1900]"),
    ({"j1": 100}, 0.0, "--speed-scale 0"),
    ({"j1": 100}, 1.5, "--speed-scale 1.5"),
    ({}, 1.0, "no joint named"),
])
def test_refusals(targets, scale, phrase):
    with pytest.raises(UsageError) as exc:
        plan_motion(CFG, targets, ZERO, speed_scale=scale)
    assert phrase in str(exc.value)


def test_pose_values_read_in_joint_units():
    assert joint_targets(CFG, {"j1": math.pi / 2, "j2": "10deg", "pitch": "-40counts"}) == \
        {"j1": 1000, "j2": 100, "pitch": -40}
    with pytest.raises(UsageError, match="unknown unit"):
        joint_targets(CFG, {"j1": "1furlong"})


positions = st.integers(-1500, 1500)


@given(j1=positions, j2=positions, pitch=st.integers(-2500, 2500), roll=st.integers(-1800, 1800),
       start=st.lists(st.integers(-900, 900), min_size=4, max_size=4),
       scale=st.sampled_from([1.0, 0.5, 0.1, 0.01]))
def test_every_joint_keeps_its_limit_and_follows_the_same_progress(j1, j2, pitch, roll, start, scale):
    motors = dict(zip(("yaw", "elbow", "left", "right"), start, strict=True))
    p = plan_motion(CFG, {"j1": j1, "j2": j2, "pitch": pitch, "roll": roll}, motors, speed_scale=scale)
    for j in p.joints:
        assert j.speed <= j.limit * scale + 1e-6, j
    moving = [j for j in p.joints if j.distance]
    if not moving:
        return
    # one progress rate V for every joint: its speed over its distance
    v = moving[0].speed / abs(moving[0].distance)
    for j in moving:
        assert j.speed / abs(j.distance) == pytest.approx(v)
    # every motor at V·|d| rounded up to whole counts/s: the joints still keep their limits
    by = {m.drive: m for m in p.motors}
    for m in p.motors:
        d = abs(m.target - m.start)
        assert v * d - 1e-6 <= m.profile.sp < v * d + 1 or (d == 0 and m.profile.sp == 1)
    if "yaw" in by:
        assert by["yaw"].profile.sp <= max(1, CFG.joints["j1"].vel_limit * scale)
    if "left" in by:
        for name in ("pitch", "roll"):
            j = p.joint(name)
            # the joint's speed on its line, both motors rounded up by less than one count/s each
            assert abs(j.speed) + 2 <= max(3, CFG.joints[name].vel_limit * scale) + 1e-6 or not j.distance
    assert p.duration > 0 and p.timeout > p.duration
    # every motor of a longer move ends its profile when the plan does, to 10 ms or 0.5 %: the ramps
    # make up for SP's rounding (a very slow move, whose AC and DC are a few counts/s², keeps more of
    # their own rounding: docs/move.md)
    for m in p.motors:
        d = abs(m.target - m.start)
        if d >= 100 and scale >= 0.1:
            assert profile_time(d, m.profile) == pytest.approx(p.duration, abs=max(0.010, 0.005 * p.duration)), m


def test_rounding_the_speed_up_is_made_up_by_gentler_ramps():
    # 1000 counts against 37: j2's exact speed is a fraction of a count/s, rounded up; its ramps give it back
    p = plan_motion(CFG, {"j1": 1000, "j2": 37}, ZERO, speed_scale=0.01)
    j2 = next(m for m in p.motors if m.drive == "elbow")
    assert j2.profile.sp > 37 / 1000 * p.joint("j1").speed
    assert profile_time(37, j2.profile) == pytest.approx(p.duration, rel=0.02)
    assert j2.profile.ac <= math.ceil(40000 * 37 / 1000)
