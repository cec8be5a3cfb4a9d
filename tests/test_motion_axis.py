"""The one axis (motion/axis.py): the joint <-> motor maps of every kind, the one move-time bound,
and the one resolver."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from motion_helpers import JOG_CONFIG

from sherpa_cli.config import load_config
from sherpa_cli.errors import UsageError
from sherpa_cli.motion.axis import joints_moved_by, move_time_bound, resolve_axis

CFG = load_config(JOG_CONFIG)
AXES = {name: resolve_axis(CFG, name) for name in ("j1", "pitch", "roll", "left", "can0:11")}

counts = st.integers(min_value=-10**7, max_value=10**7)


@given(name=st.sampled_from(sorted(AXES)), target=counts, ma=counts, mb=counts)
def test_a_position_target_maps_to_motors_and_back(name, target, ma, mb):
    axis = AXES[name]
    motors = {"yaw": ma, "left": ma, "right": mb}
    after = {**motors, **axis.motor_targets(target, motors)}
    assert axis.position(after) == target  # the moved joint lands exactly where asked
    if axis.is_pair_joint:
        (other,) = [j for j in axis.watched if j.name != axis.name]
        # the other joint holds, or gives way by one count on a parity clash (never more)
        assert abs(other.position(after) - other.position(motors)) <= 1


@given(name=st.sampled_from(sorted(AXES)), v=counts)
def test_a_speed_maps_to_motors_and_back(name, v):
    axis = AXES[name]
    speeds = axis.motor_velocities(v)
    assert set(speeds) == set(axis.drives)
    full = {"yaw": 0, "left": 0, "right": 0, **speeds}
    # an odd pair speed rounds both halves away from zero: one count/s more, never less (diffpair)
    assert axis.velocity(full) - v in ((0,) if not axis.is_pair_joint or v % 2 == 0 else (1, -1))
    assert abs(axis.velocity(full)) >= abs(v)
    if axis.is_pair_joint:
        (other,) = [j for j in axis.watched if j.name != axis.name]
        assert other.velocity(full) == 0


@given(name=st.sampled_from(sorted(AXES)), amps=st.floats(min_value=-50, max_value=50, allow_nan=False))
def test_a_current_maps_to_motors_and_back(name, amps):
    axis = AXES[name]
    currents = axis.motor_currents(amps)
    assert axis.current(currents) == pytest.approx(amps)
    if axis.is_pair_joint:
        (other,) = [j for j in axis.watched if j.name != axis.name]
        assert other.current(currents) == pytest.approx(0.0)


@given(d1=st.integers(0, 10**7), d2=st.integers(0, 10**7), speed=st.integers(1, 10**6),
       accel=st.none() | st.integers(1, 10**7), decel=st.none() | st.integers(1, 10**7))
def test_the_move_time_bound_grows_with_the_distance(d1, d2, speed, accel, decel):
    lo, hi = sorted((d1, d2))
    assert move_time_bound(lo, speed, accel, decel) <= move_time_bound(hi, speed, accel, decel)
    # never below the profile's own time: a move that is on time is never called late
    assert move_time_bound(hi, speed, accel, decel) >= hi / speed
    axis = AXES["pitch"]
    assert axis.move_time_bound(lo, speed) <= axis.move_time_bound(hi, speed)


def test_one_resolver_for_every_kind():
    assert {n: a.kind for n, a in AXES.items()} == {"j1": "plain", "pitch": "sigma", "roll": "delta",
                                                     "left": "motor", "can0:11": "motor"}
    assert AXES["j1"].drives == ("yaw",) and AXES["j1"].ref.name == "yaw"
    assert AXES["pitch"].drives == ("left", "right") and AXES["pitch"].sign == 1
    assert AXES["roll"].sign == -1
    # a pair motor alone moves both pair joints: the watch senses both motors
    assert AXES["left"].sensed == ("left", "right")
    assert [j.name for j in AXES["left"].watched] == ["pitch", "roll"]
    assert [j.name for j in joints_moved_by(CFG, ["right"])] == ["pitch", "roll"]
    with pytest.raises(UsageError, match="is a differential pair: name the joint to move"):
        resolve_axis(CFG, "diff")
    with pytest.raises(UsageError, match="moves no single joint"):
        _ = AXES["left"].joint_config


def test_a_position_move_speed_comes_from_the_request_or_the_config_never_the_drive():
    from sherpa_cli.motion.axis import profile_speed

    j1 = AXES["j1"]
    assert j1.vel_limit and profile_speed(j1, 100) == j1.vel_limit
    assert profile_speed(j1, 100, requested=-250) == 250
    bare = resolve_axis(CFG, "can0:99")  # a drive of no joint: no limit, the configured fallback
    assert bare.kind == "drive" and profile_speed(bare, 123) == 123
