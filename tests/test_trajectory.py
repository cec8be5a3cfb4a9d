"""joints/trajectory.py: the trajectory model, its checks (one line each, naming where), the cubic
Hermite resampling to the stream period and the per-motor points, exact and as properties."""

from __future__ import annotations

import dataclasses
import itertools
import math

import pytest
from conftest import ROOT
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError
from sherpa_cli.joints import diffpair
from sherpa_cli.joints.jointmap import joint_map
from sherpa_cli.joints.trajectory import (
    MotorStream,
    Trajectory,
    check_trajectory,
    motor_points,
    resample,
)
from sherpa_cli.units import round_half_away

CFG = load_config(ROOT / "tests" / "data" / "move-arm.yaml")
JOINTS = ("j1", "j2", "pitch", "roll")
SRC = "path.csv"


def traj(times, **joints) -> Trajectory:
    return Trajectory(tuple(joints), tuple(times), tuple(tuple(v) for v in joints.values()),
                      tuple(range(2, 2 + len(times))))


def ok(times=(0.0, 0.1, 0.2), **over) -> Trajectory:
    joints = {"j1": [0, 100, 200], "j2": [0, 0, 0], "pitch": [0, 10, 20], "roll": [0, -10, -20]}
    joints.update(over)
    return traj(times, **joints)


def refused(t: Trajectory, cfg=CFG, period=None) -> str:
    with pytest.raises(UsageError) as info:
        check_trajectory(cfg, t, source=SRC, period=period)
    message = str(info.value)
    assert "\n" not in message
    return message


def with_joint(name: str, **changes):
    joints = dict(CFG.joints)
    joints[name] = dataclasses.replace(joints[name], **changes)
    return dataclasses.replace(CFG, joints=joints)


# -- checks ----------------------------------------------------------------------------------------

def test_a_trajectory_inside_every_limit_is_accepted():
    check_trajectory(CFG, ok(), source=SRC, period=0.01)


@pytest.mark.parametrize(("t", "expected"), [
    (Trajectory(("j1",), (), ((),)), "path.csv: the trajectory is empty"),
    (traj([0.0], j1=[0]), "path.csv: the trajectory has one sample"),
    (traj([0.0, 0.1], pich=[0, 1]), "path.csv: joint 'pich' is not a joint of the config; did you mean 'pitch'?"),
    (traj([0.0, 0.1], pitch=[0, 1]), "path.csv: pitch is a joint of the Σ/Δ pair diff; the trajectory must give roll"),
    (traj([0.0, 0.1], roll=[0, 1]), "the trajectory must give pitch too"),
    (ok(j2=[0, math.nan, 0]), "path.csv:3 (t=0.100 s): j2 is not a finite number (nan)"),
    (ok(j2=[0, 0, math.inf]), "path.csv:4 (t=0.200 s): j2 is not a finite number (inf)"),
    (ok(times=(0.0, math.nan, 0.2)), "path.csv:3 (t=nan): the time is not a finite number"),
    (ok(times=(0.0, 0.1, 0.1)), "path.csv:4 (t=0.100 s): the time repeats the previous sample's 0.1 s"),
    (ok(times=(0.0, 0.1, 0.05)), "path.csv:4 (t=0.050 s): the time goes back from the previous sample's 0.1 s"),
    (ok(times=(0.5, 0.6, 0.7)), "path.csv:2 (t=0.500 s): the first sample is at 0.5 s; a trajectory starts at 0"),
    (ok(j1=[0, 100, 1901]), "path.csv:4 (t=0.200 s): j1 at 1901.0 counts (+2.9861 rad) is outside its normal "
                            "range [-1900, 1900] counts"),
    (ok(roll=[0, -1901, -1901], times=(0.0, 0.5, 1.0)), "roll at -1901.0 counts"),
    (ok(j1=[0, 801, 801]), "path.csv:3 (t=0.100 s): j1 moves at 8010 counts/s (12.5821 rad/s) from the previous "
                           "sample, above its speed limit 8000 counts/s"),
    (ok(j1=[0, 0, 500]), "path.csv:3 (t=0.100 s): j1 accelerates at 50000 counts/s² (78.540 rad/s²), above its "
                         "accel 40000 counts/s² (joints.j1.acceleration.accel)"),
    (ok(j1=[0, 500, 500]), "path.csv:3 (t=0.100 s): j1 decelerates at 50000 counts/s²"),
])
def test_each_bad_trajectory_is_one_line_naming_where(t, expected):
    assert expected in refused(t)


def test_a_speed_exactly_at_the_limit_is_accepted_and_one_count_above_is_not():
    check_trajectory(CFG, ok(j1=[0, 800, 1600], times=(0.0, 0.1, 0.2)), source=SRC)
    assert "8010 counts/s" in refused(ok(j1=[0, 801, 1602], times=(0.0, 0.1, 0.2)))


def test_a_joint_without_a_speed_limit_is_refused():
    assert "j2 has no speed limit configured" in refused(ok(), cfg=with_joint("j2", vel_limit=None))


def test_only_a_configured_acceleration_is_checked():
    t = ok(j1=[0, 0, 500])
    assert "accelerates" in refused(t)
    check_trajectory(with_joint("j1", accel=None, decel=None), t, source=SRC)
    # a joint with only one of the two takes it both ways
    assert "decelerates at 50000 counts/s² (78.540 rad/s²), above its accel 40000" in refused(
        ok(j1=[0, 500, 500]), cfg=with_joint("j1", decel=None))


def test_a_pair_whose_motors_leave_their_box_is_refused():
    # a config whose normal range reaches past the full range (a negative margin) lets a Σ inside the
    # normal range put the motors outside the box: the box check still stands between it and the drives
    cfg = with_joint("pitch", margin=-600)
    message = refused(ok(pitch=[0, 300, 3300], roll=[0, 0, 1900], times=(0.0, 0.5, 1.0)), cfg=cfg)
    assert message.startswith("path.csv:4 (t=1.000 s): diff: motor positions left=2600, right=700 are outside "
                              "the motor box left [-2500, 2500], right [-2500, 2500]"), message


def test_the_stream_is_checked_where_the_samples_turn_too_sharply():
    # from standing still to the limit in one sample: the samples' speeds are within the limit, the
    # Hermite between them is not (up to 4/3 of the segment's speed, two thirds of the way)
    t = traj([0.0, 0.1, 0.2, 0.3], j1=[0, 0, 700, 1400])
    cfg = with_joint("j1", accel=None, decel=None)  # else the acceleration is refused first
    check_trajectory(cfg, t, source=SRC)
    message = refused(t, cfg=cfg, period=0.01)
    assert message.startswith("path.csv: t=0.150 s: j1 would move at 8750 counts/s in the stream resampled "
                              "to 0.01 s, above its speed limit 8000 counts/s"), message


# -- resampling, exact -------------------------------------------------------------------------------

def test_a_linear_ramp_resamples_to_itself_with_its_exact_velocity():
    rs = resample(traj([0.0, 0.5, 1.0], j1=[0, 500, 1000]), 0.1)
    assert rs.times[-1] == 1.0 and len(rs.times) == 11
    for t, x, v in zip(rs.times, rs.position("j1"), rs.velocity("j1"), strict=True):
        assert x == pytest.approx(1000 * t, abs=1e-9) and v == pytest.approx(1000, abs=1e-9)


def test_the_last_point_is_exactly_at_the_end():
    rs = resample(traj([0.0, 0.105], j1=[0, 105]), 0.01)
    assert rs.times[-2] == pytest.approx(0.1) and rs.times[-1] == 0.105
    assert rs.position("j1")[-1] == 105


def test_a_step_does_not_overshoot():
    rs = resample(traj([0.0, 1.0, 2.0, 3.0], j1=[0, 0, 10, 10]), 0.01)
    xs = rs.position("j1")
    assert min(xs) == 0 and max(xs) == pytest.approx(10, abs=1e-12)
    assert all(b >= a - 1e-12 for a, b in itertools.pairwise(xs))
    # standing before and after: not a fraction of a count of motion there
    assert set(xs[:101]) == {0} and all(x == pytest.approx(10, abs=1e-12) for x in xs[200:])


@pytest.mark.parametrize("period", [0.0, -0.01, math.nan, math.inf])
def test_a_bad_period_is_refused(period):
    with pytest.raises(UsageError, match="stream period"):
        resample(ok(), period)


# -- motor points, exact -----------------------------------------------------------------------------

def test_motor_points_of_plain_joints_and_a_pair():
    t = traj([0.0, 0.1], j1=[0, 100], j2=[5, 5], pitch=[0, 100], roll=[0, 20])
    ms = motor_points(CFG, t, 0.05)
    assert isinstance(ms, MotorStream)
    assert ms.drives == ("yaw", "left", "right", "elbow")
    assert ms.times == (0.0, 0.05, 0.1)
    assert ms.motor("yaw").positions == (0, 50, 100) and ms.motor("yaw").velocities == (1000, 1000, 1000)
    assert ms.motor("elbow").positions == (5, 5, 5) and ms.motor("elbow").velocities == (0, 0, 0)
    # m_a = (Σ+Δ)/2, m_b = (Σ-Δ)/2; velocities alike
    assert ms.motor("left").positions == (0, 30, 60) and ms.motor("left").velocities == (600, 600, 600)
    assert ms.motor("right").positions == (0, 20, 40) and ms.motor("right").velocities == (400, 400, 400)


def test_a_pair_point_of_mixed_parity_keeps_sigma_and_delta_gives_way_as_plan_does():
    t = traj([0.0, 0.1], pitch=[3, 3], roll=[0, 0])
    ms = motor_points(CFG, t, 0.1)
    a, b = ms.motor("left").positions[0], ms.motor("right").positions[0]
    assert diffpair.to_joints(a, b) == (3, -1) == diffpair.hold_other(3, 0, "sigma", CFG.joints["roll"].normal_range)


def test_only_the_drives_of_named_joints_get_points():
    assert motor_points(CFG, traj([0.0, 0.1], j2=[0, 10]), 0.01).drives == ("elbow",)


# -- properties --------------------------------------------------------------------------------------

PERIOD = 0.01
finite = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)


@st.composite
def paths(draw, joints=("j1",)):
    """Any values at increasing times (not necessarily inside limits)."""
    n = draw(st.integers(2, 12))
    gaps = draw(st.lists(st.floats(0.001, 1.0), min_size=n - 1, max_size=n - 1))
    times = [0.0]
    for g in gaps:
        times.append(times[-1] + g)
    values = {j: draw(st.lists(finite, min_size=n, max_size=n)) for j in joints}
    return traj(times, **values)


@given(paths(), st.floats(0.001, 0.2))
def test_every_segment_stays_between_its_samples(t, period):
    rs = resample(t, period)
    xs, ts = t.position("j1"), t.times
    for time, x in zip(rs.times, rs.position("j1"), strict=True):
        i = min(max(0, next(k for k in range(len(ts)) if ts[k] >= time) - 1), len(ts) - 2) if time > 0 else 0
        lo, hi = sorted((xs[i], xs[i + 1]))
        slack = 1e-9 * max(1.0, abs(lo), abs(hi))
        assert lo - slack <= x <= hi + slack


@given(paths(("j1", "j2")))
def test_resampling_a_path_sampled_at_the_period_returns_it(t):
    grid = Trajectory(t.joints, tuple(k * PERIOD for k in range(t.samples)), t.positions)
    rs = resample(grid, PERIOD)
    assert rs.times == grid.times
    assert rs.positions == grid.positions


@given(st.floats(-8000, 8000), finite, st.integers(2, 10), st.floats(0.001, 0.1))
def test_a_linear_ramp_has_its_exact_velocity_everywhere(speed, start, n, period):
    times = [k * 0.1 for k in range(n)]
    rs = resample(traj(times, j1=[start + speed * t for t in times]), period)
    for t, x, v in zip(rs.times, rs.position("j1"), rs.velocity("j1"), strict=True):
        assert v == pytest.approx(speed, rel=1e-9, abs=1e-6)
        assert x == pytest.approx(start + speed * t, rel=1e-9, abs=1e-6)


@st.composite
def inside_limits(draw):
    """A path built inside every joint's limits of the config: sampled at PERIOD, each segment's speed
    within the speed limit, the speed changing by no more than half the acceleration allows, positions
    inside the normal range (a path of at most 20 samples at 8000 counts/s travels 1520 counts). Half:
    the stream's speeds at the samples are the cubic's tangents, each between its two neighbouring
    segments' speeds, so two tangents differ by at most the change across two segments -- twice the
    samples' own; the resampled stream is checked against the acceleration too."""
    n = draw(st.integers(2, 20))
    values = {}
    for name in JOINTS:
        j = CFG.joints[name]
        vel = [draw(st.floats(-1.0, 1.0)) * j.vel_limit]
        for _ in range(n - 2):
            dv = draw(st.floats(-1.0, 1.0)) * j.accel * PERIOD / 2
            vel.append(max(-j.vel_limit, min(j.vel_limit, vel[-1] + dv)))
        lo, hi = j.normal_range
        x = [draw(st.floats(lo / 4, hi / 4))]
        for v in vel:
            x.append(x[-1] + v * PERIOD)
        values[name] = x
    return traj([k * PERIOD for k in range(n)], **values)


@given(inside_limits())
def test_every_trajectory_built_inside_the_limits_is_accepted(t):
    check_trajectory(CFG, t, source=SRC, period=PERIOD)


@given(inside_limits(), st.sampled_from([0.01, 0.004, 0.02]))
def test_motor_points_transform_back_to_the_joints_within_one_count(t, period):
    ms = motor_points(CFG, t, period)
    rs = resample(t, period)
    for name in JOINTS:
        jm = joint_map(CFG, CFG.joints[name])
        assert jm is not None
        for k in range(len(ms.times)):
            motors = [ms.motor(d).positions[k] for d in jm.drives]
            back = jm.value(*motors)
            assert abs(back - round_half_away(rs.position(name)[k])) <= 1
            assert abs(back - rs.position(name)[k]) <= 1.5
            speeds = [ms.motor(d).velocities[k] for d in jm.drives]
            assert abs(jm.value(*speeds) - rs.velocity(name)[k]) <= 1


@given(inside_limits(), st.sampled_from([0.01, 0.003]))
def test_the_motors_of_an_accepted_pair_stay_in_their_box(t, period):
    box = diffpair.motor_box(CFG.joints["pitch"].full_range, CFG.joints["roll"].full_range)
    ms = motor_points(CFG, t, period)
    assert all(box.contains(a, b) for a, b in zip(ms.motor("left").positions, ms.motor("right").positions,
                                                   strict=True))


@given(paths(("j1", "j2")))
def test_at_every_sample_the_velocity_lies_between_the_speeds_of_the_segments_beside_it(t):
    grid = Trajectory(t.joints, tuple(k * PERIOD for k in range(t.samples)), t.positions)
    rs = resample(grid, PERIOD)
    for name in grid.joints:
        xs = grid.position(name)
        secants = [(b - a) / PERIOD for a, b in itertools.pairwise(xs)]
        for i, v in enumerate(rs.velocity(name)):
            beside = secants[max(0, i - 1):i + 1]
            slack = 1e-9 * max(1.0, *(abs(s) for s in beside))
            assert min(beside) - slack <= v <= max(beside) + slack


@given(paths(), st.floats(0.001, 0.2))
def test_between_samples_the_speed_stays_within_one_and_a_half_times_the_fastest_segment(t, period):
    xs = t.position("j1")
    fastest = max(abs(b - a) / (t2 - t1) for a, b, t1, t2 in zip(xs, xs[1:], t.times, t.times[1:], strict=False))
    rs = resample(t, period)
    assert all(abs(v) <= 1.5 * fastest * (1 + 1e-9) + 1e-9 for v in rs.velocity("j1"))


def test_the_stream_between_samples_and_from_rest_is_held_to_the_acceleration():
    from sherpa_cli.joints.trajectory import check_played_from_rest, resample

    # segments at 0, 390, 780 counts/s: each change 39000 counts/s², within j1's 40000; the cubic's
    # tangents at the samples are 0 and 520 counts/s (between their segments): 52000 counts/s² apart
    sharp = traj([0.0, 0.01, 0.02, 0.03], j1=[0, 0, 3.9, 11.7])
    with pytest.raises(UsageError, match=r"j1 would (accelerate|decelerate) at .* in the stream resampled to 0\.01 s"):
        check_trajectory(CFG, sharp, source=SRC, period=0.01)
    # a path that starts moving at 1000 counts/s: from rest in one period is 100000 counts/s²
    moving = traj([0.0, 0.1, 0.2], j1=[0, 100, 200])
    check_trajectory(CFG, moving, source=SRC, period=0.01)  # its samples are within every limit
    with pytest.raises(UsageError, match=r"j1 would accelerate .* \(from rest at its start, to rest at its end\)"):
        check_played_from_rest(CFG, resample(moving, 0.01), SRC)
