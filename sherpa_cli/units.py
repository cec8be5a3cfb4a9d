"""Unit conversions between drive counts and SI units.

``rad = counts * 2*pi / cpr`` (``cpr`` = counts per joint revolution, gearing included);
velocities use the same factor per second. Conversions toward counts return ``int``
because the drive only takes whole counts.

Rounding toward counts is *half away from zero*: 2.5 -> 3, -2.5 -> -3. It is chosen over
Python's ``round`` (half to even) so that ``to_counts(-x) == -to_counts(x)``: a symmetric
range in radians stays symmetric in counts. Ties are decided on the float value after
scaling, so a value that is a tie only in exact arithmetic may round either way.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from numbers import Integral, Real

from sherpa_cli.errors import UsageError

TAU = 2.0 * math.pi


def _finite(value: float, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real):
        raise UsageError(f"{what} must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise UsageError(f"{what} must be a finite number, got {value!r}")
    return x


def _cpr(cpr: int) -> int:
    if isinstance(cpr, bool) or not isinstance(cpr, Integral) or cpr <= 0:
        raise UsageError(f"counts per revolution (cpr) must be a positive integer, got {cpr!r}")
    return int(cpr)


def round_half_away(value: float) -> int:
    """Nearest integer; exact halves go away from zero. Non-finite input raises UsageError."""
    x = _finite(value, "value")
    a = abs(x)
    lower = math.floor(a)
    # For a >= 0, a - floor(a) is exact (Sterbenz), so the tie test is not fooled by the
    # rounding that adding 0.5 would introduce (0.49999999999999994 + 0.5 == 1.0).
    n = int(lower) + (1 if a - lower >= 0.5 else 0)
    return -n if x < 0 else n


def counts_to_rad(counts: float, cpr: int) -> float:
    return _finite(counts, "position (counts)") * TAU / _cpr(cpr)


def rad_to_counts(rad: float, cpr: int) -> int:
    """Nearest whole count (half away from zero); NaN/inf raise UsageError."""
    return round_half_away(_finite(rad, "position (rad)") * _cpr(cpr) / TAU)


def counts_per_s_to_rad_per_s(counts_per_s: float, cpr: int) -> float:
    return _finite(counts_per_s, "velocity (counts/s)") * TAU / _cpr(cpr)


def rad_per_s_to_counts_per_s(rad_per_s: float, cpr: int) -> int:
    return round_half_away(_finite(rad_per_s, "velocity (rad/s)") * _cpr(cpr) / TAU)


def counts_per_s2_to_rad_per_s2(counts_per_s2: float, cpr: int) -> float:
    return _finite(counts_per_s2, "acceleration (counts/s^2)") * TAU / _cpr(cpr)


def rad_per_s2_to_counts_per_s2(rad_per_s2: float, cpr: int) -> int:
    return round_half_away(_finite(rad_per_s2, "acceleration (rad/s^2)") * _cpr(cpr) / TAU)


def deg_to_rad(deg: float) -> float:
    return math.radians(_finite(deg, "angle (deg)"))


def rad_to_deg(rad: float) -> float:
    return math.degrees(_finite(rad, "angle (rad)"))


def counts_to_deg(counts: float, cpr: int) -> float:
    return _finite(counts, "position (counts)") * 360.0 / _cpr(cpr)


def deg_to_counts(deg: float, cpr: int) -> int:
    """Nearest whole count (half away from zero); computed without a detour via radians."""
    return round_half_away(_finite(deg, "angle (deg)") * _cpr(cpr) / 360.0)


def amps_to_milliamps(amps: float) -> float:
    """The Elmo GUI shows mA; the joint controller and CL/PL use A."""
    return _finite(amps, "current (A)") * 1000.0


def milliamps_to_amps(milliamps: float) -> float:
    return _finite(milliamps, "current (mA)") / 1000.0


# --------------------------------------------------------------------------- typed quantities
#
# What a technician types after --to / --by / --velocity / --torque: a number with an optional
# unit suffix, no space needed ("10deg", "-0.5", "200counts", "5deg/s", "1.5A", "800mA").
# Positions and velocities default to rad (rad/s), currents to A. Velocities may carry "/s"
# ("5deg/s" = "5deg"); a position must not. A count is whole: "200.5counts" is refused rather
# than rounded, because the technician then meant something else.

ANGLE_UNITS = {"rad": "rad", "deg": "deg", "counts": "counts", "count": "counts", "cnt": "counts"}
CURRENT_UNITS = {"a": "A", "ma": "mA"}

# re.ASCII: \d is 0-9 only (a str pattern's \d takes every script's digits, and float() reads U+FF13 as 3)
_QUANTITY = re.compile(r"\s*([+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z]*(?:/s)?)\s*", re.ASCII)


@dataclass(frozen=True)
class Quantity:
    """A number as typed plus its canonical unit (``rad``, ``deg``, ``counts``, ``A``, ``mA``)."""

    value: float
    unit: str
    per_second: bool = False

    def __str__(self) -> str:
        number = f"{self.value:g}"
        return f"{number}{self.unit}{'/s' if self.per_second else ''}"


def _split(text: object, what: str, examples: str) -> tuple[float, str, bool]:
    if not isinstance(text, str):
        raise UsageError(f"{what}: expected text like {examples}, got {text!r}")
    if not text.isascii():
        raise UsageError(f"{what}: {text!r} is not a number with ASCII digits 0-9", hint=f"write e.g. {examples}")
    m = _QUANTITY.fullmatch(text)
    if m is None:
        raise UsageError(f"{what}: cannot read {text!r} as a number with an optional unit",
                         hint=f"write e.g. {examples}")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise UsageError(f"{what}: {text!r} is too large")
    suffix = m.group(2)
    per_second = suffix.endswith("/s")
    return value, suffix[:-2] if per_second else suffix, per_second


def parse_angle(text: str, *, what: str = "position", velocity: bool = False) -> Quantity:
    """``"10deg"`` -> Quantity(10.0, "deg"); no suffix means rad (rad/s with ``velocity``).

    A velocity may end in ``/s``; a position may not. Counts must be whole.
    """
    examples = "0.5, 10deg/s, 300counts/s" if velocity else "0.5, 10deg, 200counts"
    value, unit, per_second = _split(text, what, examples)
    if per_second and not velocity:
        raise UsageError(f"{what}: {text!r} is a speed; a position takes rad, deg or counts",
                         hint=f"write e.g. {examples}")
    canon = ANGLE_UNITS.get(unit.lower() if unit else "rad")
    if canon is None:
        raise UsageError(f"{what}: unknown unit {unit!r} in {text!r}; use rad (the default), deg or counts"
                         + ("" if not velocity else " (per second, '/s' optional)"),
                         hint=f"write e.g. {examples}")
    if canon == "counts" and not value.is_integer():
        raise UsageError(f"{what}: {text!r} is not a whole number of counts")
    return Quantity(value, canon, velocity)


def angle_to_counts(q: Quantity, cpr: int) -> int:
    """A parsed angle (or angular speed) in whole counts (counts/s) of a joint with ``cpr``."""
    if q.unit == "counts":
        return int(q.value)
    if q.unit == "deg":
        return deg_to_counts(q.value, cpr)
    if q.unit == "rad":
        return rad_to_counts(q.value, cpr)
    raise UsageError(f"{q} is not an angle")


def parse_position(text: str, cpr: int, *, what: str = "position") -> int:
    """Joint position (or distance) in counts from ``"0.5"`` (rad), ``"10deg"``, ``"200counts"``."""
    return angle_to_counts(parse_angle(text, what=what), cpr)


def parse_velocity(text: str, cpr: int, *, what: str = "velocity") -> int:
    """Joint speed in counts/s from ``"0.5"`` (rad/s), ``"10deg"``/``"10deg/s"``, ``"300counts/s"``."""
    return angle_to_counts(parse_angle(text, what=what, velocity=True), cpr)


def parse_current(text: str, *, what: str = "torque") -> float:
    """Motor current in A from ``"1.5"`` / ``"1.5A"`` / ``"1500mA"``."""
    value, unit, per_second = _split(text, what, "1.5, 1.5A, 800mA")
    canon = CURRENT_UNITS.get(unit.lower() if unit else "a")
    if canon is None or per_second:
        raise UsageError(f"{what}: unknown unit {unit + ('/s' if per_second else '')!r} in {text!r}; "
                         f"use A (the default) or mA", hint="write e.g. 1.5, 1.5A, 800mA")
    return milliamps_to_amps(value) if canon == "mA" else value


def describe_counts(counts: int, cpr: int) -> str:
    """``"0.5236 rad (30 deg, 500 counts)"``: how results show a joint position."""
    return f"{counts_to_rad(counts, cpr):.4f} rad ({counts_to_deg(counts, cpr):.2f} deg, {counts} counts)"
