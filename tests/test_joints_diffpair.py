"""Differential pair kinematics: parity, inverse, and the motor box (inclusion and tightness)."""

from __future__ import annotations

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from sherpa_cli.errors import UsageError
from sherpa_cli.joints.diffpair import (
    MotorBox,
    inside_joint_limits,
    is_reachable,
    motor_box,
    nearest_reachable,
    to_joints,
    to_motors,
)

ints = st.integers(min_value=-10**9, max_value=10**9)
small = st.integers(min_value=-40, max_value=40)


@st.composite
def rect(draw, lo=-40, hi=40):
    a = draw(st.integers(lo, hi))
    b = draw(st.integers(lo, hi))
    return (min(a, b), max(a, b))


def test_forward_and_inverse_examples():
    assert to_joints(190, 30) == (220, 160)
    assert to_motors(220, 160) == (190, 30)
    assert to_motors(-3, 1) == (-1, -2)


def test_mixed_parity_is_refused_with_an_explanation():
    with pytest.raises(UsageError, match="both even or both odd") as info:
        to_motors(221, 160)
    assert "Σ=221" in info.value.message and "Δ=160" in info.value.message
    assert not is_reachable(221, 160)


@pytest.mark.parametrize("bad", [1.0, "3", None, True])
def test_non_integer_counts_are_refused(bad):
    with pytest.raises(UsageError):
        to_motors(bad, 0)
    with pytest.raises(UsageError):
        to_joints(0, bad)


def test_nearest_reachable_rule():
    assert nearest_reachable(220, 160) == (220, 160)  # already reachable
    assert nearest_reachable(221, 160) == (221, 159)  # Δ toward zero
    assert nearest_reachable(221, -160) == (221, -159)
    assert nearest_reachable(1, 0) == (1, -1)  # from 0, -1 first
    # Δ is at its range edge: Δ away from zero is next
    assert nearest_reachable(221, 160, delta_range=(160, 170)) == (221, 161)
    # Δ pinned to one value: Σ moves instead
    assert nearest_reachable(221, 160, sigma_range=(-240, 240), delta_range=(160, 160)) == (220, 160)
    with pytest.raises(UsageError):
        nearest_reachable(221, 160, sigma_range=(221, 221), delta_range=(160, 160))


@given(s=ints, d=ints)
def test_nearest_reachable_is_reachable_and_one_count_away(s, d):
    rs, rd = nearest_reachable(s, d)
    assert is_reachable(rs, rd)
    assert abs(rs - s) + abs(rd - d) == (0 if is_reachable(s, d) else 1)
    to_motors(rs, rd)


def test_seed_example_3_box():
    assert motor_box((-220, 220), (-160, 160)) == MotorBox(a=(-190, 190), b=(-190, 190))
    assert motor_box((-240, 240), (-170, 170)) == MotorBox(a=(-205, 205), b=(-205, 205))


def test_asymmetric_box_rounds_inward():
    # m_a in [(-101 + -50)/2, (200 + 31)/2] = [-75.5, 115.5] -> [-75, 115]
    # m_b in [(-101 - 31)/2, (200 + 50)/2] = [-66, 125]
    assert motor_box((-101, 200), (-50, 31)) == MotorBox(a=(-75, 115), b=(-66, 125))


def test_box_of_an_unreachable_single_point_is_refused():
    with pytest.raises(UsageError, match="parity"):
        motor_box((1, 1), (0, 0))
    assert motor_box((2, 2), (0, 0)) == MotorBox(a=(1, 1), b=(1, 1))


def test_bad_ranges_are_refused():
    with pytest.raises(UsageError, match="empty"):
        motor_box((10, -10), (0, 0))
    with pytest.raises(UsageError):
        motor_box((0.5, 1), (0, 0))


def test_box_is_necessary_not_sufficient():
    box = motor_box((-220, 220), (-160, 160))
    assert box.contains(190, 190)
    assert not inside_joint_limits(190, 190, (-220, 220), (-160, 160))  # Σ = 380
    assert inside_joint_limits(190, 30, (-220, 220), (-160, 160))
    assert not inside_joint_limits(191, 30, (-220, 220), (-160, 160))


@given(m_a=ints, m_b=ints)
def test_motor_joint_round_trip(m_a, m_b):
    s, d = to_joints(m_a, m_b)
    assert is_reachable(s, d)
    assert to_motors(s, d) == (m_a, m_b)


@given(s=ints, d=ints)
def test_joint_motor_round_trip(s, d):
    assume(is_reachable(s, d))
    assert to_joints(*to_motors(s, d)) == (s, d)


def _points(sr, dr):
    """Every integer motor position whose (Σ, Δ) lies in the rectangle."""
    for s in range(sr[0], sr[1] + 1):
        for d in range(dr[0], dr[1] + 1):
            if (s - d) % 2 == 0:
                yield to_motors(s, d)


@given(sr=rect(), dr=rect())
def test_box_contains_every_reachable_point_and_is_tight(sr, dr):
    pts = list(_points(sr, dr))
    if not pts:
        with pytest.raises(UsageError):
            motor_box(sr, dr)
        return
    box = motor_box(sr, dr)
    for m_a, m_b in pts:
        assert box.contains(m_a, m_b)
        assert inside_joint_limits(m_a, m_b, sr, dr)
    # tightness: each bound is attained by a point of the rectangle
    assert min(a for a, _ in pts) == box.a[0]
    assert max(a for a, _ in pts) == box.a[1]
    assert min(b for _, b in pts) == box.b[0]
    assert max(b for _, b in pts) == box.b[1]


@given(sr=rect(-10**9, 10**9), dr=rect(-10**9, 10**9))
def test_box_bounds_are_attained_for_large_ranges(sr, dr):
    assume(sr[0] < sr[1] or dr[0] < dr[1])
    box = motor_box(sr, dr)
    # Find a rectangle point for each bound: the bound's (Σ, Δ) corner, moved by one count
    # along an edge when the corner has mixed parity.
    for m_a, m_b in _witnesses(box, sr, dr):
        assert inside_joint_limits(m_a, m_b, sr, dr)


def _witnesses(box, sr, dr):
    for want_a, target in ((True, box.a[0]), (True, box.a[1]), (False, box.b[0]), (False, box.b[1])):
        found = None
        for s in (sr[0], sr[0] + 1, sr[1] - 1, sr[1]):
            for d in (dr[0], dr[0] + 1, dr[1] - 1, dr[1]):
                if not (sr[0] <= s <= sr[1] and dr[0] <= d <= dr[1]) or (s - d) % 2:
                    continue
                m = to_motors(s, d)
                if (m[0] if want_a else m[1]) == target:
                    found = m
        assert found is not None, f"bound {target} of motor {'a' if want_a else 'b'} not attained"
        yield found


@given(sr=rect(), dr=rect(), m_a=small, m_b=small)
def test_outside_box_means_outside_limits(sr, dr, m_a, m_b):
    assume(any(True for _ in _points(sr, dr)))
    if not motor_box(sr, dr).contains(m_a, m_b):
        assert not inside_joint_limits(m_a, m_b, sr, dr)


@given(v_s=st.integers(0, 10**6), v_d=st.integers(0, 10**6))
def test_symmetric_box_is_the_seed_rule(v_s, v_d):
    box = motor_box((-v_s, v_s), (-v_d, v_d))
    assert box.a == box.b == (-((v_s + v_d) // 2), (v_s + v_d) // 2)
