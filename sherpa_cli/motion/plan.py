"""A multi-joint move as one plan: every joint starts together and arrives together (docs/move.md).

:func:`plan_motion` is pure: from joint targets (counts) and the motors' present positions it
builds a :class:`MotionPlan` -- the joints, each motor's target and SP/AC/DC, one timing, the joints
to watch -- or refuses (UsageError) before anything is sent. motion/run.py runs a plan inside the
motion guard.

Timing: every motor follows the same profile shape in *progress* s(t) from 0 to 1, scaled by its
own distance: its SP, AC and DC are V·|d|, A·|d| and D·|d| for one common V (1/s), A and D (1/s²).
Each joint then moves along the straight line from its start to its target, and every joint
starts, accelerates and arrives together. V is the largest rate no joint's speed limit (times
``speed_scale``) forbids: the slowest joint -- the one that needs the most time at its configured
speed -- runs at that speed and sets the time; the others go slower. A and D come from the
joints' configured accelerations the same way (a joint without one: a ramp of
:data:`DEFAULT_RAMP_S` at its speed limit). A Σ/Δ pair moves with both motors in one profile, as
`diffdrive move` does; a pair joint the plan does not name holds where it stands.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from sherpa_cli import units
from sherpa_cli.bus.targets import DriveRef, drive_ref
from sherpa_cli.config.model import ArmConfig, JointRole
from sherpa_cli.config.yamlnodes import suggest
from sherpa_cli.errors import UsageError
from sherpa_cli.joints import diffpair
from sherpa_cli.motion.axis import Axis, joint_axis, joints_moved_by, move_time_bound

# s a joint without a configured acceleration takes to reach its speed limit
DEFAULT_RAMP_S = 0.1


@dataclass(frozen=True)
class Profile:
    """SP, AC, DC of one motor (counts/s, counts/s²)."""

    sp: int
    ac: int
    dc: int

    def as_dict(self) -> dict[str, int]:
        return {"SP": self.sp, "AC": self.ac, "DC": self.dc}


@dataclass(frozen=True)
class JointMove:
    """One joint of a plan, in its counts: where it starts, where it is sent, how fast it goes."""

    name: str
    cpr: int
    start: int
    target: int  # where the motors put it (a pair joint may give way by one count: parity)
    speed: float  # counts/s at cruise in this plan
    limit: int  # counts/s: the joint's configured speed limit
    asked: int | None = None  # the target asked for, when parity moved it by one count

    @property
    def distance(self) -> int:
        return self.target - self.start


@dataclass(frozen=True)
class MotorMove:
    """One motor of a plan: PA target and profile."""

    drive: str
    ref: DriveRef
    start: int
    target: int
    profile: Profile


@dataclass(frozen=True)
class MotionPlan:
    """Several joints moved as one (see the module docstring). ``duration`` is the profile's time
    (ramps included); ``timeout`` the one move-time bound (motion/axis.py) for arriving."""

    joints: tuple[JointMove, ...]
    motors: tuple[MotorMove, ...]
    watched: tuple[Axis, ...]  # every joint the motors move: the limit watch
    held: Mapping[str, int] = field(default_factory=dict)  # pair joints not named: held at these counts
    # where they stood: a held joint gives way by one count when Σ and Δ differ in parity
    held_from: Mapping[str, int] = field(default_factory=dict)
    duration: float = 0.0
    timeout: float = 0.0
    paced_by: str | None = None  # the joint that runs at its configured speed and sets the time
    speed_scale: float = 1.0

    @property
    def refs(self) -> list[DriveRef]:
        return [m.ref for m in self.motors]

    def joint(self, name: str) -> JointMove:
        return next(j for j in self.joints if j.name == name)


def check_joint_names(cfg: ArmConfig, names: Sequence[str], what: str = "joint") -> None:
    """Every name a configured joint (plain, Σ or Δ); UsageError with a suggestion otherwise."""
    for name in names:
        if name not in cfg.joints:
            close = suggest(name, list(cfg.joints))
            raise UsageError(f"{what} '{name}' is not a joint of the config"
                             + (f"; did you mean '{close}'?" if close else ""),
                             hint=f"joints: {', '.join(cfg.joints)}")


def drives_of(cfg: ArmConfig, joints: Sequence[str]) -> list[str]:
    """The motors that move ``joints`` (a Σ/Δ joint: both motors of its pair), in config order."""
    wanted: set[str] = set()
    for name in joints:
        j = cfg.joints[name]
        if j.role is JointRole.PLAIN:
            assert j.drive is not None  # a plain joint has its drive (config validation)
            wanted.add(j.drive)
        else:
            pair = cfg.pairs[j.pair]  # type: ignore[index]
            wanted.update((pair.drive_a, pair.drive_b))
    return [d for d in cfg.drives if d in wanted]


def check_speed_scale(speed_scale: float) -> None:
    if not (math.isfinite(speed_scale) and 0 < speed_scale <= 1):
        raise UsageError(f"--speed-scale {speed_scale:g}: expected a fraction of the joints' speed limits, "
                         "> 0 and <= 1")


def _trapezoid_time(v: float, a: float, d: float) -> float:
    """Time of a move of length 1 at peak rate ``v``, acceleration ``a``, deceleration ``d``."""
    if v <= 0:
        return 0.0
    if v * v / (2 * a) + v * v / (2 * d) <= 1.0:
        return 1.0 / v + v / (2 * a) + v / (2 * d)
    peak = math.sqrt(2 * a * d / (a + d))  # never reaches v: a triangle
    return peak / a + peak / d


def plan_motion(cfg: ArmConfig, targets: Mapping[str, int], motors: Mapping[str, int], *,
                speed_scale: float = 1.0) -> MotionPlan:
    """The plan that takes every joint of ``targets`` (joint name -> counts) from where ``motors``
    (drive -> PX of every drive of those joints) put it; refuses a joint not in the config, a
    target outside a joint's normal range or the pair's motor box, a joint without a speed
    limit, and a ``speed_scale`` outside (0, 1]."""
    if not targets:
        raise UsageError("nothing to move: no joint named")
    check_speed_scale(speed_scale)
    check_joint_names(cfg, list(targets))
    moves: list[JointMove] = []
    motor_targets: dict[str, int] = {}
    held: dict[str, int] = {}
    held_from: dict[str, int] = {}
    caps: dict[str, float] = {}  # drive -> the steepest ramp (counts/s²) its joints allow
    gives_way: list[JointMove] = []
    limits: dict[str, tuple[float, float, float]] = {}  # joint -> usable speed, accel, decel (counts/s, /s²)
    done_pairs: set[str] = set()
    for name in targets:
        j = cfg.joints[name]
        lo, hi = j.normal_range
        if not lo <= targets[name] <= hi:
            raise UsageError(f"{name}: target {targets[name]} counts is outside the joint's normal range "
                             f"[{lo}, {hi}]", hint="a move takes a joint only inside its normal range")
        if j.vel_limit is None:
            raise UsageError(f"{name}: no speed limit configured (joints.{name}.velocity.limit), so the move's "
                             "speed cannot be chosen", hint="give the joint `velocity: {limit: COUNTS_PER_S}`")
        if j.role is JointRole.PLAIN:
            assert j.drive is not None  # a plain joint has its drive (config validation)
            start = motors[j.drive]
            motor_targets[j.drive] = targets[name]
            caps[j.drive] = min(_ramps(j.vel_limit, j.accel, j.decel))
            # one motor: a speed rounded up to whole counts/s stays within the limit
            speed = max(1.0, j.vel_limit * speed_scale - 1)
            moves.append(JointMove(name, j.cpr, start, targets[name], 0.0, j.vel_limit))
        else:
            pair = cfg.pairs[j.pair]  # type: ignore[index]
            if pair.name in done_pairs:
                continue
            done_pairs.add(pair.name)
            a, b = pair.drive_a, pair.drive_b
            s0, d0 = diffpair.to_joints(motors[a], motors[b])
            sj, dj = cfg.joints[pair.sigma], cfg.joints[pair.delta]
            s1 = targets.get(pair.sigma, s0)
            d1 = targets.get(pair.delta, d0)
            if not diffpair.is_reachable(s1, d1):
                # Σ and Δ of whole motor positions have equal parity: the held joint (or Δ) gives way one count
                which = "delta" if pair.sigma not in targets else "sigma"
                s1, d1 = diffpair.hold_other(s1, d1, which, (dj if which == "sigma" else sj).normal_range)
            ma, mb = diffpair.to_motors(s1, d1)
            box = diffpair.motor_box(sj.full_range, dj.full_range)
            if not box.contains(ma, mb):
                raise UsageError(f"{pair.name}: motor targets {a}={ma}, {b}={mb} are outside the motor box "
                                 f"{a} [{box.a[0]}, {box.a[1]}], {b} [{box.b[0]}, {box.b[1]}]")
            motor_targets[a], motor_targets[b] = ma, mb
            # a motor at AC moves Σ or Δ at up to 2 AC (as `diffdrive move` bounds it)
            caps[a] = caps[b] = min(min(_ramps(x.vel_limit or 1, x.accel, x.decel)) for x in (sj, dj)) / 2
            for joint, start, target in ((sj, s0, s1), (dj, d0, d1)):
                if joint.name not in targets:
                    held[joint.name], held_from[joint.name] = target, start
                    if target == start:
                        continue
                if joint.vel_limit is None:
                    raise UsageError(f"{joint.name}: no speed limit configured (joints.{joint.name}.velocity.limit)",
                                     hint="give the joint `velocity: {limit: COUNTS_PER_S}`")
                asked = targets.get(joint.name)
                move = JointMove(joint.name, joint.cpr, start, target, 0.0, joint.vel_limit,
                                 asked=asked if asked is not None and asked != target else None)
                # a held joint that gives way for parity bounds the speed too, but is no joint of the move
                (moves if joint.name in targets else gives_way).append(move)
                # two motors, each rounded up: two counts/s of margin
                limits[joint.name] = (max(1.0, joint.vel_limit * speed_scale - 2), *_ramps(joint.vel_limit,
                                                                                         joint.accel, joint.decel))
            continue
        limits[name] = (speed, *_ramps(j.vel_limit, j.accel, j.decel))
    order = {n: i for i, n in enumerate(cfg.joints)}
    moves.sort(key=lambda m: order[m.name])
    moving = [m for m in (*moves, *gives_way) if m.distance]
    if not moving:
        return MotionPlan(tuple(moves), (), (), held, held_from, speed_scale=speed_scale)
    # the common progress rates: the most each joint allows, the least of them all
    v_rate = min(limits[m.name][0] / abs(m.distance) for m in moving)
    a_rate = min(limits[m.name][1] / abs(m.distance) for m in moving)
    d_rate = min(limits[m.name][2] / abs(m.distance) for m in moving)
    paced = min(moving, key=lambda m: limits[m.name][0] / abs(m.distance))
    moves = [JointMove(m.name, m.cpr, m.start, m.target, v_rate * abs(m.distance), m.limit, m.asked) for m in moves]
    drives = [d for d in cfg.drives if d in motor_targets and motor_targets[d] != motors[d]]
    # both motors of a pair move in one profile, even the one whose own distance is nought
    for pair in cfg.pairs.values():
        if pair.drive_a in drives or pair.drive_b in drives:
            drives = [d for d in cfg.drives if d in drives or d in (pair.drive_a, pair.drive_b)]
    duration = _trapezoid_time(v_rate, a_rate, d_rate)
    motor_moves = [MotorMove(d, drive_ref(cfg, d), motors[d], motor_targets[d],
                             motor_profile(abs(motor_targets[d] - motors[d]), v_rate, a_rate, d_rate, duration,
                                           caps[d]))
                   for d in drives]
    longest = max(moving, key=lambda m: abs(m.distance))
    n = abs(longest.distance)
    timeout = move_time_bound(n, v_rate * n, a_rate * n, d_rate * n)
    return MotionPlan(tuple(moves), tuple(motor_moves), tuple(joints_moved_by(cfg, drives)), held, held_from,
                      duration=duration, timeout=timeout, paced_by=paced.name, speed_scale=speed_scale)


def motor_profile(dist: int, v_rate: float, a_rate: float, d_rate: float, duration: float,
                  accel_cap: float = math.inf) -> Profile:
    """SP, AC, DC of a motor moving ``dist`` counts in the plan's common profile (progress rates
    ``v_rate``, ``a_rate``, ``d_rate``; ``duration`` s).

    SP is V·dist rounded up to whole counts/s; on a short move that is several percent fast (3.6
    counts/s becomes 4), and the motor would arrive that much early. The ramps make up for it: AC
    and DC keep the plan's ratio, scaled by the k that gives the trapezoid at the rounded SP the
    plan's duration, ``dist/SP + SP/(2·AC) + SP/(2·DC) = duration`` -- when that trapezoid exists
    (a cruise is left) and its ramps stay within ``accel_cap`` (counts/s², what the motor's joints
    allow) or the plan's own; else the plan's ramps."""
    if dist == 0:
        return Profile(1, 1, 1)
    sp = _up(v_rate * dist)
    a, d = a_rate * dist, d_rate * dist
    left = duration - dist / sp  # what the ramps must take at the rounded speed
    cap = max(a, d, accel_cap)
    if left > 0:
        k = (sp / 2) * (1 / a + 1 / d) / left
        ka, kd = k * a, k * d
        if sp * sp / (2 * ka) + sp * sp / (2 * kd) <= dist and max(ka, kd) <= cap:
            a, d = ka, kd
    best = Profile(sp, _up(a), _up(d))
    if sp < SMALL_SP:
        # a few counts/s and counts/s²: whole numbers are coarse; the whole AC and DC nearest in time
        # (never steeper than the joints allow). A move of a count or two still cannot take long: at
        # SP = AC = DC = 1 one count takes 2 s at most
        for cand in _near_profiles(dist, sp, a, d, duration, cap):
            if abs(profile_time(dist, cand) - duration) < abs(profile_time(dist, best) - duration):
                best = cand
    return best


SMALL_SP = 50  # counts/s: below this the whole-number rounding of a profile is searched


def _near_profiles(dist: int, sp: int, a: float, d: float, duration: float, cap: float) -> list[Profile]:
    """Whole AC (either side of ``a``) and, for each, the DC either side of what keeps ``duration``."""
    out = []
    for ac in {max(1, math.floor(a)), max(1, math.ceil(a))}:
        if ac > cap:
            continue
        rest = duration - dist / sp - sp / (2 * ac)
        ideal = sp / (2 * rest) if rest > 0 else d
        out += [Profile(sp, ac, dc) for dc in {max(1, math.floor(ideal)), max(1, math.ceil(ideal))} if dc <= cap]
    return out


def profile_time(dist: float, pr: Profile) -> float:
    """How long a move of ``dist`` counts takes at ``pr`` (a trapezoid, or a triangle when SP is not reached)."""
    v, a, dc = pr.sp, pr.ac, pr.dc
    if v * v / (2 * a) + v * v / (2 * dc) <= dist:
        return dist / v + v / (2 * a) + v / (2 * dc)
    peak = math.sqrt(2 * dist * a * dc / (a + dc))
    return peak / a + peak / dc


def _up(x: float) -> int:
    """Whole counts at least ``x`` (not one more for float error), at least 1."""
    return max(1, math.ceil(x - 1e-9))


def _ramps(limit: int, accel: int | None, decel: int | None) -> tuple[float, float]:
    default = limit / DEFAULT_RAMP_S
    return float(accel or default), float(decel or default)


def joint_axes(cfg: ArmConfig, names: Sequence[str]) -> list[Axis]:
    """The axes of ``names`` (configured joints), each watching every joint its motors move."""
    check_joint_names(cfg, names)
    out = []
    for name in names:
        j = cfg.joints[name]
        drives = drives_of(cfg, [name])
        out.append(joint_axis(cfg, j, watched=tuple(joints_moved_by(cfg, drives))))
    return out


def joint_targets(cfg: ArmConfig, values: Mapping[str, str | float | int]) -> dict[str, int]:
    """Joint name -> counts from numbers in the joint's units (rad) or text with a unit ("10deg",
    "1200counts"), as a pose or `jog --to` takes them."""
    check_joint_names(cfg, list(values))
    out: dict[str, int] = {}
    for name, value in values.items():
        cpr = cfg.joints[name].cpr
        if isinstance(value, str):
            out[name] = units.parse_position(value, cpr, what=name)
        elif isinstance(value, bool) or not isinstance(value, int | float):
            raise UsageError(f"{name}: expected a position (rad, or text like 10deg), got {value!r}")
        else:
            out[name] = units.rad_to_counts(float(value), cpr)
    return out
