"""Unit conversions: exact values, rounding rule, rejection of non-finite input, round trips."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.errors import UsageError
from sherpa_cli.joints import units as u

cprs = st.integers(min_value=1, max_value=10_000_000)


def test_quarter_turn_is_half_pi():
    assert u.counts_to_rad(150, 600) == pytest.approx(math.pi / 2)
    assert u.rad_to_counts(math.pi / 2, 600) == 150
    assert u.counts_to_rad(-600, 600) == pytest.approx(-2 * math.pi)


def test_velocity_and_acceleration_use_the_same_factor():
    assert u.counts_per_s_to_rad_per_s(300, 600) == pytest.approx(math.pi)
    assert u.rad_per_s_to_counts_per_s(math.pi, 600) == 300
    assert u.counts_per_s2_to_rad_per_s2(600, 600) == pytest.approx(2 * math.pi)
    assert u.rad_per_s2_to_counts_per_s2(2 * math.pi, 600) == 600


def test_degree_helpers():
    assert u.counts_to_deg(150, 600) == 90.0
    assert u.deg_to_counts(90, 600) == 150
    assert u.deg_to_rad(180) == pytest.approx(math.pi)
    assert u.rad_to_deg(math.pi) == pytest.approx(180)


def test_milliamps():
    assert u.amps_to_milliamps(1.5) == 1500.0
    assert u.milliamps_to_amps(250) == 0.25


@pytest.mark.parametrize("x, expected", [
    (2.5, 3), (-2.5, -3), (0.5, 1), (-0.5, -1), (1.4999999, 1), (1.5000001, 2),
    (0.49999999999999994, 0), (-0.49999999999999994, 0), (3.0, 3), (-3.0, -3), (0.0, 0),
])
def test_ties_round_half_away_from_zero(x, expected):
    assert u.round_half_away(x) == expected
    assert isinstance(u.round_half_away(x), int)


def test_conversion_to_counts_rounds_half_away_from_zero():
    # 1 count = 1 degree with cpr 360: 2.5 degrees is an exact tie in floating point.
    assert u.deg_to_counts(2.5, 360) == 3
    assert u.deg_to_counts(-2.5, 360) == -3


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("fn", [u.rad_to_counts, u.rad_per_s_to_counts_per_s, u.deg_to_counts,
                                u.counts_to_rad, u.rad_per_s2_to_counts_per_s2])
def test_non_finite_is_a_usage_error(fn, bad):
    with pytest.raises(UsageError, match="finite"):
        fn(bad, 600)


@pytest.mark.parametrize("fn", [u.amps_to_milliamps, u.milliamps_to_amps, u.deg_to_rad, u.rad_to_deg])
def test_non_finite_is_a_usage_error_without_cpr(fn):
    with pytest.raises(UsageError):
        fn(math.nan)


@pytest.mark.parametrize("cpr", [0, -600, 600.0, True, None])
def test_bad_cpr_is_a_usage_error(cpr):
    with pytest.raises(UsageError, match="cpr"):
        u.rad_to_counts(1.0, cpr)


def test_non_number_is_a_usage_error():
    with pytest.raises(UsageError):
        u.rad_to_counts("1.0", 600)


@given(counts=st.integers(min_value=-(10**12), max_value=10**12), cpr=cprs)
def test_counts_rad_counts_round_trip_is_exact(counts, cpr):
    assert u.rad_to_counts(u.counts_to_rad(counts, cpr), cpr) == counts
    assert u.rad_per_s_to_counts_per_s(u.counts_per_s_to_rad_per_s(counts, cpr), cpr) == counts
    assert u.deg_to_counts(u.counts_to_deg(counts, cpr), cpr) == counts


@given(rad=st.floats(min_value=-1000, max_value=1000, allow_nan=False), cpr=cprs)
def test_rad_counts_rad_round_trip_within_half_a_count(rad, cpr):
    back = u.counts_to_rad(u.rad_to_counts(rad, cpr), cpr)
    half_count = math.pi / cpr
    assert abs(back - rad) <= half_count * (1 + 1e-9) + 1e-12


@given(x=st.floats(min_value=-1e12, max_value=1e12, allow_nan=False))
def test_rounding_is_nearest_and_odd_symmetric(x):
    n = u.round_half_away(x)
    assert abs(n - x) <= 0.5
    assert u.round_half_away(-x) == -n


@given(x=st.floats(min_value=-1e6, max_value=1e6, allow_nan=False))
def test_milliamps_round_trip(x):
    assert u.milliamps_to_amps(u.amps_to_milliamps(x)) == pytest.approx(x, rel=1e-12, abs=1e-12)
