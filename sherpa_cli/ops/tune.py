"""`sherpa tune show|set`: the drive's speed and position loop gains (docs/tune.md).

The gains (real-arm.md 3; MAN-SIMSW ch. 15): KP[2] and KI[2] tune the speed loop, KP[3] the
position loop; FF[] are feed-forwards. What KP[1], KI[1], KI[3] and every FF[] index mean is
UNCONFIRMED: `tune show` says so next to the value. GS[] (gain scheduling, "normally programmed
by the Composer IDE") and KV[] are not read. `tune set` writes through ops/program.py's path
(plan, dry run, --apply with read-back, --save guarded and counted); a gain outside its bounds
(config `tuning:`, defaults below) is refused before anything is sent.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.elmo.commands import COMMANDS, parse_param_key
from sherpa_cli.errors import CodecError, UsageError

# key -> (what it is, confirmed by the sources?)
GAINS: Mapping[str, tuple[str, bool]] = {
    "KP[2]": ("speed loop, proportional", True),
    "KI[2]": ("speed loop, integral", True),
    "KP[3]": ("position loop, proportional", True),
    "KP[1]": ("meaning UNCONFIRMED (current loop?)", False),
    "KI[1]": ("meaning UNCONFIRMED (current loop?)", False),
    "KI[3]": ("meaning UNCONFIRMED", False),
    "FF[1]": ("feed-forward, index meaning UNCONFIRMED", False),
    "FF[2]": ("feed-forward, index meaning UNCONFIRMED", False),
    "FF[3]": ("feed-forward, index meaning UNCONFIRMED", False),
}
# What `tune set` accepts without a `tuning:` section: wide, only the sign and orders of
# magnitude beyond any plausible setting are refused (no Elmo range is published).
DEFAULT_BOUNDS: Mapping[str, tuple[float, float]] = {
    "KP[1]": (0.0, 1000.0), "KP[2]": (0.0, 100.0), "KP[3]": (0.0, 10000.0),
    "KI[1]": (0.0, 100000.0), "KI[2]": (0.0, 100000.0), "KI[3]": (0.0, 10000.0),
    "FF[1]": (0.0, 10.0), "FF[2]": (0.0, 10.0), "FF[3]": (0.0, 10.0),
}


@dataclass(frozen=True)
class GainReading:
    drive: str
    values: dict[str, float | int]


def bounds(cfg: ArmConfig) -> dict[str, tuple[float, float]]:
    return {**DEFAULT_BOUNDS, **cfg.tuning}


def read_gains(session: ArmSession, refs: Sequence[DriveRef]) -> list[GainReading]:
    out = []
    for ref in refs:
        client = session.client(ref)
        client.nmt_start()
        values = {}
        for key in GAINS:
            letters, index = parse_param_key(key)
            values[key] = client.get(letters, index)
        out.append(GainReading(ref.name, values))
    return out


def parse_assignments(cfg: ArmConfig, texts: Sequence[str]) -> dict[str, float]:
    """``["KP[2]=0.8", "KI[2]=150"]`` -> {key: value}; every gain checked against its bounds."""
    if not texts:
        raise UsageError("tune set needs at least one GAIN=VALUE, e.g. KP[2]=0.8")
    limits = bounds(cfg)
    out: dict[str, float] = {}
    for text in texts:
        key, sep, raw = text.partition("=")
        key = key.strip().upper()
        if not sep:
            raise UsageError(f"{text!r}: expected GAIN=VALUE, e.g. KP[2]=0.8")
        try:
            letters, index = parse_param_key(key)
        except CodecError as exc:
            raise UsageError(f"{text!r}: {exc.message}") from None
        canon = f"{letters}[{index}]" if COMMANDS[letters].is_array else letters
        if canon not in GAINS:
            raise UsageError(f"{text!r}: {canon} is not a gain `tune set` writes",
                             hint=f"one of {', '.join(GAINS)}")
        try:
            value = float(raw.strip()) if raw.strip().isascii() else math.nan
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise UsageError(f"{text!r}: {raw.strip()!r} is not a number")
        low, high = limits[canon]
        if not low <= value <= high:
            raise UsageError(f"{canon}={value:g} is outside its bounds {low:g}..{high:g}",
                             hint="the bounds are the config's `tuning:` section (docs/tune.md)")
        out[canon] = value
    return out
