"""The quantity parser behind `sherpa jog --to/--by/--velocity/--torque`: exact cases and properties."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.errors import UsageError
from sherpa_cli.joints import units as u

cprs = st.integers(min_value=1, max_value=10_000_000)


@pytest.mark.parametrize("text, cpr, counts", [
    ("10deg", 3600, 100), ("-10deg", 3600, -100), ("90DEG", 360, 90), ("200counts", 3600, 200),
    ("-200counts", 6000, -200), ("1count", 6000, 1), ("7cnt", 10, 7), ("2e2counts", 10, 200),
    ("0", 3600, 0), ("-0.5", 6000, -477), ("0.5rad", 6000, 477), (".25", 600, 24), ("+1.5deg", 360, 2),
    (" 30 deg ", 360, 30), (str(math.pi), 600, 300),
])
def test_positions(text, cpr, counts):
    assert u.parse_position(text, cpr) == counts


@pytest.mark.parametrize("text, cpr, rate", [
    ("5deg", 3600, 50), ("5deg/s", 3600, 50), ("300counts/s", 6000, 300), ("300counts", 6000, 300),
    ("0.5", 6000, 477), ("0.5rad/s", 6000, 477), ("-1rad/s", 600, -95),
])
def test_velocities(text, cpr, rate):
    assert u.parse_velocity(text, cpr) == rate


@pytest.mark.parametrize("text, amps", [("1.5", 1.5), ("1.5A", 1.5), ("800mA", 0.8), ("-2a", -2.0),
                                        ("-250MA", -0.25), ("0", 0.0)])
def test_currents(text, amps):
    assert u.parse_current(text) == pytest.approx(amps)


@pytest.mark.parametrize("text, words", [
    ("10deg/s", "is a speed"), ("abc", "cannot read"), ("", "cannot read"), ("1.5counts", "whole number"),
    ("10furlong", "unknown unit 'furlong'"), ("nan", "cannot read"), ("inf", "cannot read"),
    ("1e400", "too large"), ("1 0deg", "cannot read"), ("--5", "cannot read"), ("5 deg s", "cannot read"),
])
def test_bad_positions_name_what_is_wrong(text, words):
    with pytest.raises(UsageError, match="--to") as info:
        u.parse_position(text, 3600, what="--to")
    assert words in str(info.value)
    assert repr(text) in str(info.value) or text == ""


@pytest.mark.parametrize("text", ["1.5V", "2A/s", "x"])
def test_bad_currents(text):
    with pytest.raises(UsageError, match="--torque"):
        u.parse_current(text, what="--torque")


def test_non_text_is_a_usage_error():
    with pytest.raises(UsageError):
        u.parse_position(1.5, 600)  # type: ignore[arg-type]


def test_quantity_prints_as_typed_in_canonical_units():
    assert str(u.parse_angle("10DEG")) == "10deg"
    assert str(u.parse_angle("5", velocity=True)) == "5rad/s"
    assert str(u.parse_angle("3count")) == "3counts"


def test_describe_counts():
    assert u.describe_counts(900, 3600) == "1.5708 rad (90.00 deg, 900 counts)"


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


@given(x=finite, cpr=cprs)
def test_plain_number_is_radians(x, cpr):
    assert u.parse_position(repr(x), cpr) == u.rad_to_counts(x, cpr)
    assert u.parse_position(f"{x!r}rad", cpr) == u.rad_to_counts(x, cpr)


@given(x=finite, cpr=cprs)
def test_deg_suffix_matches_deg_to_counts(x, cpr):
    assert u.parse_position(f"{x!r}deg", cpr) == u.deg_to_counts(x, cpr)
    assert u.parse_velocity(f"{x!r}deg/s", cpr) == u.deg_to_counts(x, cpr)


@given(n=st.integers(min_value=-(10**9), max_value=10**9), cpr=cprs)
def test_counts_are_exact_and_ignore_cpr(n, cpr):
    assert u.parse_position(f"{n}counts", cpr) == n
    assert u.parse_velocity(f"{n}counts/s", cpr) == n


@given(x=finite, cpr=cprs)
def test_sign_is_symmetric(x, cpr):
    for unit in ("", "deg", "rad"):
        assert u.parse_position(f"{-x!r}{unit}", cpr) == -u.parse_position(f"{x!r}{unit}", cpr)


@given(x=finite)
def test_milliamps_are_a_thousandth(x):
    assert u.parse_current(f"{x!r}mA") == pytest.approx(u.parse_current(repr(x)) / 1000, rel=1e-12, abs=1e-15)
