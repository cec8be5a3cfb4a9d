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
