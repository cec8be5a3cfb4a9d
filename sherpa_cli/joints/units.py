"""Unit conversions between drive counts and SI units, and the quantities a technician types.

They live in :mod:`sherpa_cli.units`, below the config (which reads poses in them); the joint math
names them here as it always did.
"""

from sherpa_cli.units import (
    ANGLE_UNITS,
    CURRENT_UNITS,
    TAU,
    Quantity,
    amps_to_milliamps,
    angle_to_counts,
    counts_per_s2_to_rad_per_s2,
    counts_per_s_to_rad_per_s,
    counts_to_deg,
    counts_to_rad,
    deg_to_counts,
    deg_to_rad,
    describe_counts,
    milliamps_to_amps,
    parse_angle,
    parse_current,
    parse_position,
    parse_velocity,
    rad_per_s2_to_counts_per_s2,
    rad_per_s_to_counts_per_s,
    rad_to_counts,
    rad_to_deg,
    round_half_away,
)

__all__ = ["ANGLE_UNITS", "CURRENT_UNITS", "TAU", "Quantity", "amps_to_milliamps", "angle_to_counts",
           "counts_per_s2_to_rad_per_s2", "counts_per_s_to_rad_per_s", "counts_to_deg", "counts_to_rad",
           "deg_to_counts", "deg_to_rad", "describe_counts", "milliamps_to_amps", "parse_angle", "parse_current",
           "parse_position", "parse_velocity", "rad_per_s2_to_counts_per_s2", "rad_per_s_to_counts_per_s",
           "rad_to_counts", "rad_to_deg", "round_half_away"]
