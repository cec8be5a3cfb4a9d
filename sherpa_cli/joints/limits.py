"""Drive parameters from the arm config: the derivation of seed Appendix C.

Plain joint (C.1, C.2):

    LL[3] / HL[3] = overshoot range  (trip: motor off beyond it)
    VL[3] / VH[3] = full range       (position commands are clipped to it)
    VL[2] / VH[2] = -vel_limit / +vel_limit   (speed commands are clipped)
    LL[2] / HL[2] = -vel_trip  / +vel_trip    (trip, a safeguard above the limit)
    AC, DC        = accel, decel (counts/s^2)
    CL[1], PL[1], PL[2] = continuous A, peak A, peak duration s (whole seconds)
    IL[n]         = il_codes.stop / il_codes.home for each switch on input n, and
                    il_codes.unused for every other input 1..inputs of the drive's model (6 if
                    unknown), so a switch the config no longer names leaves no function behind

Differential pair (C.3): each motor gets the integer motor box of the Σ/Δ rectangle
(see :mod:`sherpa_cli.joints.diffpair`), from the full ranges for VL[3]/VH[3] and from the
overshoot ranges for LL[3]/HL[3]; drive_a takes the m_a box, drive_b the m_b box.

Speed, acceleration and deceleration of a pair use the same box rule on the symmetric
ranges ``[-v_Σ, v_Σ] x [-v_Δ, v_Δ]``: motor limit = ``floor((v_Σ + v_Δ) / 2)`` for both
motors. Rounding down keeps every motor limit inside the exact box, so a drive never
allows a motor speed that no allowed joint motion needs. Like the position box this is
necessary, not sufficient: both motors at the limit in the same direction give
``|Σ'| = v_Σ + v_Δ``, so joint speed limits must still be enforced in joint space by the tool.
Rounding down also keeps the pair's trip strictly above its limit whenever each joint's
trip is strictly above that joint's limit (sum of trips >= sum of limits + 2).

A value that is ``None`` in the config is left out: that drive parameter is not written.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from sherpa_cli.config.model import (
    ArmConfig,
    CurrentLimits,
    JointConfig,
    JointRole,
    PairConfig,
    SwitchConfig,
    SwitchKind,
)
from sherpa_cli.errors import ConfigError, Location, UsageError
from sherpa_cli.joints.currents import Finding, check_currents, validate_params
from sherpa_cli.joints.diffpair import MotorBox, motor_box
from sherpa_cli.joints.params import PARAM_ORDER, DriveParams, ParamValue
from sherpa_cli.words import plural


@dataclass(frozen=True)
class PairExplanation:
    """How a pair's motor limits follow from its Σ/Δ ranges (for ``sherpa diffdrive limits``)."""

    pair: str
    drive_a: str
    drive_b: str
    sigma: str
    delta: str
    sigma_full: tuple[int, int]
    delta_full: tuple[int, int]
    sigma_overshoot: tuple[int, int]
    delta_overshoot: tuple[int, int]
    motor_a_full: tuple[int, int]  # VL[3] / VH[3] of drive_a
    motor_b_full: tuple[int, int]  # VL[3] / VH[3] of drive_b
    motor_a_overshoot: tuple[int, int]  # LL[3] / HL[3] of drive_a
    motor_b_overshoot: tuple[int, int]  # LL[3] / HL[3] of drive_b
    motor_speed_limit: int | None  # |VL[2]| = VH[2] of both motors
    motor_speed_trip: int | None  # |LL[2]| = HL[2] of both motors
    motor_accel: int | None
    motor_decel: int | None
    rule: str  # the rule, with this pair's numbers filled in
    notes: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {
            "pair": self.pair, "drive_a": self.drive_a, "drive_b": self.drive_b,
            "sigma": self.sigma, "delta": self.delta,
            "sigma_full": list(self.sigma_full), "delta_full": list(self.delta_full),
            "sigma_overshoot": list(self.sigma_overshoot), "delta_overshoot": list(self.delta_overshoot),
            "motor_a_full": list(self.motor_a_full), "motor_b_full": list(self.motor_b_full),
            "motor_a_overshoot": list(self.motor_a_overshoot),
            "motor_b_overshoot": list(self.motor_b_overshoot),
            "motor_speed_limit": self.motor_speed_limit, "motor_speed_trip": self.motor_speed_trip,
            "motor_accel": self.motor_accel, "motor_decel": self.motor_decel,
            "rule": self.rule, "notes": list(self.notes),
        }


# --------------------------------------------------------------------------- name lookup

def _unknown(kind: str, name: str, valid: Iterable[str]) -> UsageError:
    valid = sorted(set(valid))
    close = difflib.get_close_matches(name, valid, n=3, cutoff=0.5)
    if close:
        hint = "did you mean " + ", ".join(close) + "?"
    else:
        shown = ", ".join(valid[:12]) + (", ..." if len(valid) > 12 else "")
        hint = f"valid names: {shown}" if valid else "the config defines none"
    return UsageError(f"unknown {kind} {name!r}", hint=hint)


def _pair_drives(pair: PairConfig) -> tuple[str, str]:
    return (pair.drive_a, pair.drive_b)


def _joint_drives(cfg: ArmConfig, joint: JointConfig) -> tuple[str, ...]:
    if joint.role is JointRole.PLAIN:
        return (joint.drive,) if joint.drive else ()
    pair = cfg.pairs.get(joint.pair) if joint.pair else None
    return _pair_drives(pair) if pair is not None else ()


def _check_drives(cfg: ArmConfig, drives: Sequence[str] | None) -> list[str]:
    """Configured drive names, each once; ``None`` or empty means every drive of the config."""
    if not drives:
        return list(cfg.drives)
    for d in drives:
        if d not in cfg.drives:
            raise _unknown("drive", d, cfg.drives)
    return list(dict.fromkeys(drives))


# --------------------------------------------------------------------------- helpers

def _as_int(value: object, what: str, where: Location) -> int:
    if isinstance(value, bool):
        raise ConfigError(f"{what} must be a whole number, got {value!r}", where)
    if isinstance(value, int):
        return value
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        return int(value)
    raise ConfigError(f"{what} must be a whole number, got {value!r}", where)


def _magnitude(value: object, what: str, where: Location) -> int:
    n = _as_int(value, what, where)
    if n < 0:
        raise ConfigError(f"{what} must not be negative (it is a magnitude; the sign is applied "
                          f"per side), got {n}", where)
    return n


def _current_params(cur: CurrentLimits, owner: str) -> dict[str, ParamValue]:
    peak_time = cur.peak_time
    if isinstance(peak_time, bool) or not isinstance(peak_time, (int, float)) or not math.isfinite(peak_time) \
            or float(peak_time) != int(peak_time):
        raise ConfigError(f"{owner}: peak_time must be whole seconds because PL[2] is an integer "
                          f"on the drive, got {peak_time!r}", cur.where,
                          hint="round it to whole seconds")
    return {"CL[1]": float(cur.continuous), "PL[1]": float(cur.peak), "PL[2]": int(peak_time)}


def il_roles(cfg: ArmConfig) -> dict[int, str]:
    """The config's il_codes by value -> what the tool uses such an input for (for
    ``elmo.faults.describe_il``): ``{21: "stop switch", 5: "home switch", 4: "unused input"}``."""
    codes = cfg.il_codes
    return {codes.unused: "unused input", codes.home: "home switch", codes.stop: "stop switch"}


def _switch_code(cfg: ArmConfig, sw: SwitchConfig) -> int:
    return cfg.il_codes.stop if sw.kind is SwitchKind.STOP else cfg.il_codes.home


DEFAULT_INPUTS = 6  # a Whistle's digital inputs when the config names no model (as dump-params reads)

# Drive parameters only joints with speed / acceleration limits derive; without them the drive keeps its own.
SPEED_KEYS = ("VL[2]", "VH[2]", "LL[2]", "HL[2]", "AC", "DC")


def left_as_they_are(derived: Sequence[DriveParams]) -> str | None:
    """One note naming the speed/acceleration parameters no derived set programs (e.g. a D.1 config), or None."""
    missing = [k for k in SPEED_KEYS if any(k not in d.params for d in derived)]
    if not derived or not missing:
        return None
    which = [d.drive for d in derived if any(k not in d.params for k in missing)]
    names = {"VL[2]": "VL/VH[2]", "VH[2]": "VL/VH[2]", "LL[2]": "LL/HL[2]", "HL[2]": "LL/HL[2]"}
    shown = ", ".join(dict.fromkeys(names.get(k, k) for k in missing))
    drives = "" if len(which) == len(derived) else f" of {', '.join(which)}"
    return f"no speed/acceleration limits configured: {shown}{drives} stay as the drives have them"


def _il_params(cfg: ArmConfig, drive: str, *, clear_unused: bool = True) -> dict[str, int]:
    dmodel = cfg.drives[drive].model
    inputs = cfg.catalog.drives[dmodel].inputs if dmodel is not None and dmodel in cfg.catalog.drives else None
    found: dict[int, tuple[int, SwitchConfig, str]] = {}
    for joint in cfg.joints.values():
        default = _joint_drives(cfg, joint)
        for sw in joint.switches:
            if drive not in (sw.drives or default):
                continue
            n = sw.input
            if isinstance(n, bool) or not isinstance(n, int) or n < 1 or (inputs is not None and n > inputs):
                limit = f"1..{inputs}" if inputs is not None else ">= 1"
                raise ConfigError(f"joint {joint.name}: switch input {n!r} on drive {drive} is out of "
                                  f"range ({limit})", sw.where)
            code = _switch_code(cfg, sw)
            if n in found and found[n][0] != code:
                _, other, other_joint = found[n]
                raise ConfigError(
                    f"drive {drive} input {n} is wired to a {other.kind.value} switch of joint "
                    f"{other_joint} (at {other.where}) and a {sw.kind.value} switch of joint "
                    f"{joint.name}; one input has one function (IL[{n}])", sw.where)
            found.setdefault(n, (code, sw, joint.name))
    # Every input the config does not assign gets "no function": moving a switch (Example 1's
    # wiring to Example 2's) must not leave the old stop switch on its input.
    if not clear_unused:
        return {f"IL[{n}]": found[n][0] for n in sorted(found)}
    count = max([inputs if inputs is not None else DEFAULT_INPUTS, *found])
    return {f"IL[{n}]": found[n][0] if n in found else cfg.il_codes.unused for n in range(1, count + 1)}


def _ordered(values: Mapping[str, ParamValue | None]) -> dict[str, ParamValue]:
    return {k: v for k in PARAM_ORDER if (v := values.get(k)) is not None}


def _pair_joints(cfg: ArmConfig, pair: PairConfig) -> tuple[JointConfig, JointConfig]:
    try:
        return cfg.joints[pair.sigma], cfg.joints[pair.delta]
    except KeyError as exc:
        raise ConfigError(f"pair {pair.name} names joint {exc.args[0]!r}, which is not defined",
                          pair.where) from None


def _box(pair: PairConfig, s_rng: tuple[int, int], d_rng: tuple[int, int], what: str,
         sigma: JointConfig) -> MotorBox:
    try:
        return motor_box(s_rng, d_rng)
    except UsageError as exc:
        raise ConfigError(f"pair {pair.name} {what}: {exc.message}", sigma.where) from None


def _pair_magnitude(pair: PairConfig, sigma: JointConfig, delta: JointConfig, attr: str,
                    warnings: list[str]) -> int | None:
    vs, vd = getattr(sigma, attr), getattr(delta, attr)
    if vs is None and vd is None:
        return None
    if vs is None or vd is None:
        have, miss = (sigma, delta) if vd is None else (delta, sigma)
        warnings.append(f"pair {pair.name}: {attr} is set on joint {have.name} but not on "
                        f"{miss.name}; the motor limit needs both, so it is not programmed")
        return None
    s = _magnitude(vs, f"joint {sigma.name} {attr}", sigma.where)
    d = _magnitude(vd, f"joint {delta.name} {attr}", delta.where)
    return (s + d) // 2


# --------------------------------------------------------------------------- derivation

def _plain(cfg: ArmConfig, joint: JointConfig) -> dict[str, ParamValue | None]:
    w = joint.where
    v: dict[str, ParamValue | None] = {}
    if joint.vel_trip is not None:
        t = _magnitude(joint.vel_trip, f"joint {joint.name} vel_trip", w)
        v["LL[2]"], v["HL[2]"] = -t, t
    if joint.vel_limit is not None:
        s = _magnitude(joint.vel_limit, f"joint {joint.name} vel_limit", w)
        v["VL[2]"], v["VH[2]"] = -s, s
    lo, hi = joint.overshoot_range
    v["LL[3]"], v["HL[3]"] = _as_int(lo, f"joint {joint.name} overshoot range min", w), \
        _as_int(hi, f"joint {joint.name} overshoot range max", w)
    lo, hi = joint.full_range
    v["VL[3]"], v["VH[3]"] = _as_int(lo, f"joint {joint.name} pos_min", w), \
        _as_int(hi, f"joint {joint.name} pos_max", w)
    if joint.accel is not None:
        v["AC"] = _magnitude(joint.accel, f"joint {joint.name} accel", w)
    if joint.decel is not None:
        v["DC"] = _magnitude(joint.decel, f"joint {joint.name} decel", w)
    if joint.current is not None:
        v.update(_current_params(joint.current, f"joint {joint.name}"))
    return v


def _pair(cfg: ArmConfig, pair: PairConfig, drive: str, warnings: list[str]) -> dict[str, ParamValue | None]:
    sigma, delta = _pair_joints(cfg, pair)
    full = _box(pair, sigma.full_range, delta.full_range, "full range", sigma)
    over = _box(pair, sigma.overshoot_range, delta.overshoot_range, "overshoot range", sigma)
    side_full, side_over = (full.a, over.a) if drive == pair.drive_a else (full.b, over.b)
    v: dict[str, ParamValue | None] = {}
    trip = _pair_magnitude(pair, sigma, delta, "vel_trip", warnings)
    if trip is not None:
        v["LL[2]"], v["HL[2]"] = -trip, trip
    limit = _pair_magnitude(pair, sigma, delta, "vel_limit", warnings)
    if limit is not None:
        v["VL[2]"], v["VH[2]"] = -limit, limit
    v["LL[3]"], v["HL[3]"] = side_over
    v["VL[3]"], v["VH[3]"] = side_full
    v["AC"] = _pair_magnitude(pair, sigma, delta, "accel", warnings)
    v["DC"] = _pair_magnitude(pair, sigma, delta, "decel", warnings)
    if pair.current is not None:
        v.update(_current_params(pair.current, f"pair {pair.name}"))
    return v


def _derive(cfg: ArmConfig, drive: str) -> tuple[DriveParams, list[str]]:
    if drive not in cfg.drives:
        raise _unknown("drive", drive, cfg.drives)
    dcfg = cfg.drives[drive]
    warnings: list[str] = []
    joint = cfg.joint_of_drive(drive)
    pair = cfg.pair_of_drive(drive)
    if joint is not None and pair is not None:
        raise ConfigError(f"drive {drive} moves joint {joint.name} and is also in pair {pair.name}; "
                          f"a drive belongs to one of them", dcfg.where)
    if joint is not None:
        values = _plain(cfg, joint)
    elif pair is not None:
        values = _pair(cfg, pair, drive, warnings)
    else:
        values = {}
        warnings.append(f"drive {drive} moves no joint; no limits are derived for it")
    params: dict[str, ParamValue] = _ordered(values)
    # a drive that moves no joint gets only the switches wired to it; its other inputs are left alone
    params.update(_il_params(cfg, drive, clear_unused=joint is not None or pair is not None))
    return DriveParams(drive=drive, bus=dcfg.bus, node=dcfg.node, params=params), warnings


def derive_drive_params(cfg: ArmConfig, drive: str) -> DriveParams:
    """The Appendix C parameter set for one drive (UsageError for an unknown drive name)."""
    return _derive(cfg, drive)[0]


def derive_all(cfg: ArmConfig, drives: Sequence[str] | None = None) -> list[DriveParams]:
    """Parameter sets for the named drives (None = all; names come from :mod:`sherpa_cli.bus.targets`)."""
    return [_derive(cfg, d)[0] for d in _check_drives(cfg, drives)]


def derive_checked(cfg: ArmConfig, drives: Sequence[str] | None = None) -> tuple[list[DriveParams], list[str]]:
    """:func:`derive_all` plus every check a set must pass before it may be written.

    Returns the sets and the warnings (text). The first error -- an inconsistent set
    (:func:`~sherpa_cli.joints.currents.validate_params`) or a current limit beyond the
    catalog ratings -- raises ConfigError naming where to fix it, so nothing is written
    after an error was found.
    """

    drives = _check_drives(cfg, drives)
    derived: list[DriveParams] = []
    warnings: list[str] = []
    findings = []
    for d in drives:
        dp, w = _derive(cfg, d)
        derived.append(dp)
        warnings.extend(w)
        findings.extend(validate_params(dp, where=_owner_where(cfg, d)))
    findings.extend(f for f in check_currents(cfg) if f.drive is None or f.drive in drives)
    errors = [f for f in findings if f.level == "error"]
    if errors:
        more = len(errors) - 1
        raise ConfigError(errors[0].message, errors[0].location,
                          hint=f"{more} more error(s) follow once this is fixed" if more else None)
    warnings.extend(_grouped_warnings([f.message for f in findings if f.level == "warning"]))
    return derived, warnings


def _grouped_warnings(messages: Sequence[str]) -> list[str]:
    """A rating check skipped for many drives (the shipped config names no motors) is one line
    naming them all, not one line per drive on every command."""
    groups: dict[str, list[str]] = {}
    out: list[str] = []
    for m in messages:
        who, _, what = m.partition(": ")
        if "rating check skipped" in what and who.startswith("joint ") and ", drive " in who:
            joint, _, drive = who[len("joint "):].partition(", drive ")
            if what not in groups:
                groups[what] = []
                out.append(what)  # its place among the others: where its first drive was
            groups[what].append(f"{drive} ({joint})")
        else:
            out.append(m)
    # "SUBJECT: MESSAGE", as every warning: a recipe's summary groups them by the message
    return [f"{plural(len(groups[m]), 'drive')} ({', '.join(groups[m])}): {m}" if m in groups else m for m in out]


def config_findings(cfg: ArmConfig) -> list:
    """Everything :func:`derive_checked` would refuse or warn about for the whole arm, as findings.

    ``sherpa config check`` reports these, so a config passes the check exactly when
    program-limits will not refuse it for the same reason: a set the derivation cannot build
    (a ConfigError), an inconsistent set (``validate_params``), a current beyond the ratings.
    """

    findings = list(check_currents(cfg))
    for drive in cfg.drives:
        try:
            dp, _ = _derive(cfg, drive)
        except ConfigError as exc:
            findings.append(Finding("error", f"drive {drive}: {exc.problem}", exc.location, drive))
            continue
        findings.extend(f for f in validate_params(dp, where=_owner_where(cfg, drive)) if f.level == "error")
    seen: set[str] = set()
    unique = []
    for f in findings:  # a pair's problem is found once per motor
        if f.message not in seen:
            seen.add(f.message)
            unique.append(f)
    return unique


def _owner_where(cfg: ArmConfig, drive: str) -> Location | None:
    joint = cfg.joint_of_drive(drive)
    if joint is not None:
        return joint.where
    pair = cfg.pair_of_drive(drive)
    if pair is not None:
        return pair.where
    return cfg.drives[drive].where if drive in cfg.drives else None


# --------------------------------------------------------------------------- explanation

def _find_pair(cfg: ArmConfig, pair: str | PairConfig) -> PairConfig:
    if isinstance(pair, PairConfig):
        return pair
    if pair in cfg.pairs:  # a pair's name; what other names mean is sherpa_cli.bus.targets' business
        return cfg.pairs[pair]
    raise _unknown("differential pair", pair, cfg.pairs)


def _fmt(r: tuple[int, int]) -> str:
    return f"[{r[0]}, {r[1]}]"


def explain_pair(cfg: ArmConfig, pair: str | PairConfig) -> PairExplanation:
    """Σ/Δ ranges, the motor ranges drawn from them, and the rule used (with numbers)."""
    p = _find_pair(cfg, pair)
    sigma, delta = _pair_joints(cfg, p)
    full = _box(p, sigma.full_range, delta.full_range, "full range", sigma)
    over = _box(p, sigma.overshoot_range, delta.overshoot_range, "overshoot range", sigma)
    notes: list[str] = []
    limit = _pair_magnitude(p, sigma, delta, "vel_limit", notes)
    trip = _pair_magnitude(p, sigma, delta, "vel_trip", notes)
    accel = _pair_magnitude(p, sigma, delta, "accel", notes)
    decel = _pair_magnitude(p, sigma, delta, "decel", notes)

    def box_lines(label: str, s: tuple[int, int], d: tuple[int, int], box: MotorBox, keys: str) -> list[str]:
        return [
            f"{label}: Σ {_fmt(s)}, Δ {_fmt(d)}",
            f"  m_a = (Σ+Δ)/2 in [ceil(({s[0]} + {d[0]})/2), floor(({s[1]} + {d[1]})/2)] = {_fmt(box.a)}"
            f"  -> {p.drive_a} {keys}",
            f"  m_b = (Σ-Δ)/2 in [ceil(({s[0]} - {d[1]})/2), floor(({s[1]} - {d[0]})/2)] = {_fmt(box.b)}"
            f"  -> {p.drive_b} {keys}",
        ]

    lines = [f"Σ = m_a + m_b ({sigma.name}), Δ = m_a - m_b ({delta.name}); "
             f"m_a = {p.drive_a} (lower node id), m_b = {p.drive_b}."]
    lines += box_lines("full range", sigma.full_range, delta.full_range, full, "VL[3]/VH[3]")
    lines += box_lines("overshoot range", sigma.overshoot_range, delta.overshoot_range, over, "LL[3]/HL[3]")
    for label, value, keys in (("speed limit", limit, "VL[2]/VH[2]"), ("speed trip", trip, "LL[2]/HL[2]"),
                               ("acceleration", accel, "AC"), ("deceleration", decel, "DC")):
        if value is not None:
            lines.append(f"{label}: floor((Σ value + Δ value)/2) = {value} -> {keys} of both motors")
    lines.append("The box bounds each motor separately; it is necessary, not sufficient: motor "
                 "positions inside it can still put Σ or Δ outside their ranges, so the joint "
                 "limits are also checked in joint space before any motion.")
    return PairExplanation(
        pair=p.name, drive_a=p.drive_a, drive_b=p.drive_b, sigma=sigma.name, delta=delta.name,
        sigma_full=sigma.full_range, delta_full=delta.full_range,
        sigma_overshoot=sigma.overshoot_range, delta_overshoot=delta.overshoot_range,
        motor_a_full=full.a, motor_b_full=full.b, motor_a_overshoot=over.a, motor_b_overshoot=over.b,
        motor_speed_limit=limit, motor_speed_trip=trip, motor_accel=accel, motor_decel=decel,
        rule="\n".join(lines), notes=tuple(notes))


# --------------------------------------------------------------------------- software limits

def _cal_switches(joint: JointConfig) -> tuple[SwitchConfig | None, SwitchConfig | None, SwitchConfig | None]:
    """(low stop, high stop, home) switch of a joint; a stop switch without side goes by position."""
    low = high = home = None
    mid = (joint.pos_min + joint.pos_max) / 2
    for sw in joint.switches:
        if sw.kind is SwitchKind.HOME:
            home = home or sw
            continue
        side = sw.side or ("low" if sw.position < mid else "high")
        if side == "low":
            low = low or sw
        else:
            high = high or sw
    return low, high, home


def _joint_software(joint: JointConfig, suffix: str) -> dict[str, int | str]:
    low, high, home = _cal_switches(joint)
    out: dict[str, int | str] = {}
    # The seed's joint controller has one calibration input per joint (cal_sw_L: "low end
    # switch, or single position detection switch"), so a home switch takes that slot.
    if home is not None:
        out[f"cal_sw{suffix}_L"] = home.input
    else:
        if low is not None:
            out[f"cal_sw{suffix}_L"] = low.input
        if high is not None:
            out[f"cal_sw{suffix}_H"] = high.input
    return out


def _cal_pos(joint: JointConfig) -> int | None:
    if joint.cal_pos is not None:
        return joint.cal_pos
    _, _, home = _cal_switches(joint)
    return home.position if home is not None else None


def software_limits(cfg: ArmConfig, name: str) -> dict[str, int | str]:
    """The joint controller's parameters of Tables C.1/C.2 for a joint, pair or drive.

    ``pos_margin`` is the config's ``margin`` (full range edge to normal range edge). The
    seed's Table C.2 derives pos_margin_dd from the overshoot (10 = 170 - 160); here margin
    and overshoot are separate settings, so each key has one meaning. ``cal_pos`` is the
    configured value, else the home switch position, else left out (the seed software then
    uses pos_min). A Σ/Δ joint or a pair drive gives the pair's mapping.
    """
    if name in cfg.pairs:
        return _pair_software(cfg, cfg.pairs[name])
    if name in cfg.joints:
        joint = cfg.joints[name]
        if joint.role is not JointRole.PLAIN:
            if joint.pair is None or joint.pair not in cfg.pairs:
                raise ConfigError(f"joint {joint.name} is a {joint.role.value} joint without a pair", joint.where)
            return _pair_software(cfg, cfg.pairs[joint.pair])
        return _plain_software(joint)
    if name in cfg.drives:
        plain = cfg.joint_of_drive(name)
        if plain is not None:
            return _plain_software(plain)
        pair = cfg.pair_of_drive(name)
        if pair is not None:
            return _pair_software(cfg, pair)
        raise UsageError(f"drive {name} moves no joint; it has no software limits")
    raise _unknown("joint, pair or drive", name, [*cfg.joints, *cfg.pairs, *cfg.drives])


def _plain_software(joint: JointConfig) -> dict[str, int | str]:
    out: dict[str, int | str] = {"cpr": joint.cpr, "pos_min": joint.pos_min, "pos_max": joint.pos_max,
                                 "pos_margin": joint.margin}
    if joint.cal_speed is not None:
        out["cal_speed"] = joint.cal_speed
    cal_pos = _cal_pos(joint)
    if cal_pos is not None:
        out["cal_pos"] = cal_pos
    out.update(_joint_software(joint, ""))
    if joint.abs_encoder is not None:
        out["ext_pos_input"] = joint.abs_encoder.source
    return out


def _pair_software(cfg: ArmConfig, pair: PairConfig) -> dict[str, int | str]:
    sigma, delta = _pair_joints(cfg, pair)
    out: dict[str, int | str] = {"cpr": sigma.cpr}
    if delta.cpr != sigma.cpr:
        # The seed format has one cpr per pair; keep the Δ joint's own value visible.
        out["cpr_dd"] = delta.cpr
    out.update({"pos_min": sigma.pos_min, "pos_max": sigma.pos_max, "pos_margin": sigma.margin,
                "pos_min_dd": delta.pos_min, "pos_max_dd": delta.pos_max, "pos_margin_dd": delta.margin})
    if sigma.cal_speed is not None:
        out["cal_speed"] = sigma.cal_speed
    cal_pos = _cal_pos(sigma)
    if cal_pos is not None:
        out["cal_pos"] = cal_pos
    cal_pos_dd = _cal_pos(delta)
    if cal_pos_dd is not None:
        out["cal_pos_dd"] = cal_pos_dd
    out.update(_joint_software(sigma, ""))
    out.update(_joint_software(delta, "_dd"))
    if sigma.abs_encoder is not None:
        out["ext_pos_input"] = sigma.abs_encoder.source
    return out
