"""Checks before anything is written: current limits against the catalog, and derived sets.

Current rules (seed 3.4 and C.1.4 -- "motor, drive or power supply, whichever is lower"):

    continuous <= motor continuous,  continuous <= drive continuous
    peak <= drive peak,              peak <= peak_fraction (0.75) x motor peak
    peak >= continuous

Findings are data, not exceptions, so ``config check`` can list them all at once.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass

from sherpa_cli.config.model import ArmConfig, CurrentLimits
from sherpa_cli.errors import Location
from sherpa_cli.joints.params import DriveParams

# Ratings are printed with two decimals; 0.75 x 25.3 is 18.974999... in binary floating
# point, so a limit equal to the printed rating must not fail on the last bit.
_EPS = 1e-9


@dataclass(frozen=True)
class Finding:
    level: str  # "error" or "warning"
    message: str  # names the joint/pair, the drive and the numbers
    location: Location | None = None  # config line to edit
    drive: str | None = None
    subject: str | None = None  # "joint elbow" / "pair wrist"


def _above(value: float, limit: float) -> bool:
    return value > limit + _EPS * max(1.0, abs(limit))


def _fmt(x: float) -> str:
    return f"{x:g} A"


def _owners(cfg: ArmConfig) -> Iterator[tuple[str, str, CurrentLimits]]:
    for joint in cfg.joints.values():
        if joint.drive and joint.current is not None:
            yield f"joint {joint.name}", joint.drive, joint.current
    for pair in cfg.pairs.values():
        if pair.current is not None:
            for drive in (pair.drive_a, pair.drive_b):
                yield f"pair {pair.name}", drive, pair.current


def check_currents(cfg: ArmConfig) -> list[Finding]:
    """Current limits of every joint and pair against the ratings of their drive and motor."""
    out: list[Finding] = []
    for subject, drive, cur in _owners(cfg):
        out.extend(check_current_limits(cfg, subject, drive, cur))
    return out


def check_current_limits(cfg: ArmConfig, subject: str, drive: str, cur: CurrentLimits) -> list[Finding]:
    where = cur.where

    def f(level: str, msg: str) -> Finding:
        return Finding(level, f"{subject}, drive {drive}: {msg}", where, drive, subject)

    out: list[Finding] = []
    values = {"continuous": cur.continuous, "peak": cur.peak, "peak_time": cur.peak_time}
    bad = [k for k, v in values.items()
           if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0]
    if bad:
        return [f("error", f"current {k} must be a positive number, got {values[k]!r}") for k in bad]
    cont, peak = float(cur.continuous), float(cur.peak)
    if float(cur.peak_time) != int(cur.peak_time):
        out.append(f("error", f"peak_time {cur.peak_time:g} s is not whole seconds (PL[2] is an integer)"))
    if _above(cont, peak):
        out.append(f("error", f"peak current {_fmt(peak)} is below the continuous current {_fmt(cont)}"))

    dcfg = cfg.drives.get(drive)
    model_key = dcfg.model if dcfg is not None else None
    motor_key = dcfg.motor if dcfg is not None else None
    model = cfg.catalog.drives.get(model_key) if model_key else None
    motor = cfg.catalog.motors.get(motor_key) if motor_key else None
    if model is None:
        why = "model unknown" if not model_key else f"model {model_key!r} is not in the catalog"
        out.append(f("warning", f"drive rating check skipped ({why})"))
    else:
        if _above(cont, model.current_cont):
            out.append(f("error", f"continuous current {_fmt(cont)} exceeds the drive's continuous "
                                  f"rating {_fmt(model.current_cont)} ({model.name})"))
        if _above(peak, model.current_peak):
            out.append(f("error", f"peak current {_fmt(peak)} exceeds the drive's peak rating "
                                  f"{_fmt(model.current_peak)} ({model.name})"))
    if motor is None:
        why = "motor unknown" if not motor_key else f"motor {motor_key!r} is not in the catalog"
        out.append(f("warning", f"motor rating check skipped ({why})"))
    else:
        if _above(cont, motor.current_cont):
            out.append(f("error", f"continuous current {_fmt(cont)} exceeds the motor's continuous "
                                  f"rating {_fmt(motor.current_cont)} ({motor.name})"))
        frac = cfg.catalog.peak_fraction
        allowed = frac * motor.current_peak
        if _above(peak, allowed):
            out.append(f("error", f"peak current {_fmt(peak)} exceeds {frac:.0%} of the motor's peak "
                                  f"{_fmt(motor.current_peak)} = {allowed:.3g} A ({motor.name})"))
    return out


def validate_params(params: DriveParams | Mapping[str, float], *, drive: str | None = None,
                    where: Location | None = None,
                    allow_disabled: bool | Collection[str] = False) -> list[Finding]:
    """Consistency of one derived parameter set.

    Errors: VL >= VH for [2] or [3]; LL[3] > VL[3] or VH[3] > HL[3]; a speed trip not
    strictly outside the speed limit; AC/DC not positive; PL[1] < CL[1]; and a value of 0
    that switches a protection off on the drive (LL[3] = HL[3] = 0: no position trip;
    LL[2] or HL[2] = 0: no speed trip). ``allow_disabled`` (True, or a collection of
    "position" / "speed") turns the latter into warnings and skips the order checks that
    involve the disabled trip.
    """
    if not isinstance(params, Mapping):  # a DriveParams
        drive = drive or params.drive
        values: Mapping[str, float] = params.params
    else:
        values = params
    label = f"drive {drive}" if drive else "parameter set"
    allowed = {"position", "speed"} if allow_disabled is True else set(allow_disabled or ())
    out: list[Finding] = []

    def add(level: str, msg: str) -> None:
        out.append(Finding(level, f"{label}: {msg}", where, drive))

    def get(k: str) -> float | None:
        return values.get(k)

    pos_off = get("LL[3]") == 0 and get("HL[3]") == 0
    if pos_off:
        if "position" in allowed:
            add("warning", "LL[3] = HL[3] = 0 disables the position trip (allowed)")
        else:
            add("error", "LL[3] = HL[3] = 0 would disable the position trip")
    speed_off = {k for k in ("LL[2]", "HL[2]") if get(k) == 0}
    for k in sorted(speed_off):
        if "speed" in allowed:
            add("warning", f"{k} = 0 disables the speed trip (allowed)")
        else:
            add("error", f"{k} = 0 would disable the speed trip")

    for n in (2, 3):
        lo, hi = get(f"VL[{n}]"), get(f"VH[{n}]")
        if lo is not None and hi is not None and not lo < hi:
            add("error", f"VL[{n}] = {lo} must be below VH[{n}] = {hi}")
    if not pos_off:
        ll, hl = get("LL[3]"), get("HL[3]")
        if ll is not None and hl is not None and not ll < hl:
            add("error", f"LL[3] = {ll} must be below HL[3] = {hl}")
        vl, vh = get("VL[3]"), get("VH[3]")
        if ll is not None and vl is not None and ll > vl:
            add("error", f"LL[3] = {ll} (position trip) is above VL[3] = {vl} (command limit); "
                         f"the overshoot range must contain the full range")
        if hl is not None and vh is not None and vh > hl:
            add("error", f"VH[3] = {vh} (command limit) is above HL[3] = {hl} (position trip); "
                         f"the overshoot range must contain the full range")
    ll2, hl2, vl2, vh2 = get("LL[2]"), get("HL[2]"), get("VL[2]"), get("VH[2]")
    if "LL[2]" not in speed_off and ll2 is not None and vl2 is not None and not ll2 < vl2:
        add("error", f"speed trip LL[2] = {ll2} must be strictly below the speed limit VL[2] = {vl2}")
    if "HL[2]" not in speed_off and hl2 is not None and vh2 is not None and not hl2 > vh2:
        add("error", f"speed trip HL[2] = {hl2} must be strictly above the speed limit VH[2] = {vh2}")
    for k in ("AC", "DC"):
        v = get(k)
        if v is not None and not v > 0:
            add("error", f"{k} = {v} must be positive")
    cl, pl = get("CL[1]"), get("PL[1]")
    if cl is not None and pl is not None and _above(cl, pl):
        add("error", f"PL[1] = {pl} A (peak) is below CL[1] = {cl} A (continuous)")
    return out
