"""The one axis: everything a motion command can move, with its drives, limits and maps.

An :class:`Axis` is one of

- ``plain``: a plain joint, moved by its one drive (joint counts are motor counts);
- ``sigma`` / ``delta``: the Σ or Δ joint of a differential pair (Σ = m_a + m_b, Δ = m_a - m_b;
  joints/diffpair.py holds the maths, reused here);
- ``motor``: one motor of a pair alone (it moves Σ and Δ together, in motor counts);
- ``drive``: a drive that moves no plain joint of the config (an ad-hoc BUS:NODE, a spare drive):
  no cpr, no ranges; only a torque jog with an explicit time limit is possible.

The same type is what the limit watch watches (motion/limit_watch.py): a joint as a function of
motor positions, ``m[drive_a] + sign * m[drive_b]``. :func:`resolve_axis` is the one resolver from a
name on the command line (bus/targets.py decides what the name means); :func:`joint_axis` builds
the axis of a configured joint and :func:`joints_moved_by` every joint some drives move.

:meth:`Axis.move_time_bound` is the one bound on how long a move of a given size may take, for
every mover (jog, the pair jog, the live jog, `diffdrive move`, `home`, the move back after a
limit breach).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Final, Literal

from sherpa_cli.bus import targets
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig, JointConfig, JointRole, PairConfig
from sherpa_cli.errors import UsageError
from sherpa_cli.joints import diffpair
from sherpa_cli.joints.diffpair import Range
from sherpa_cli.joints.units import counts_to_rad

Motors = Mapping[str, int]  # drive name -> motor position (counts, PX)

# a move may take twice its profile's time (distance at speed plus both ramps), plus this much for
# starting, settling in the window and the polls: arriving later means something holds the joint
MOVE_SLACK_S = 5.0


# the kinds of axis, as plain strings: results and --json show them as they are
PLAIN: Final = "plain"
SIGMA: Final = "sigma"
DELTA: Final = "delta"
MOTOR: Final = "motor"  # one motor of a pair, alone
DRIVE: Final = "drive"  # a drive that moves no plain joint of the config
AxisKind = Literal["plain", "sigma", "delta", "motor", "drive"]


def move_time_bound(distance: float, speed: float, accel: float | None = None, decel: float | None = None) -> float:
    """The one bound (s) on how long a point-to-point move of ``distance`` counts at ``speed``
    counts/s may take: twice the profile's time (the ramps at ``accel``/``decel`` counts/s² when
    known) plus :data:`MOVE_SLACK_S`. Monotonic in the distance; never below the slack."""
    v = max(abs(speed), 1.0)
    ramps = (v / abs(accel) if accel else 0.0) + (v / abs(decel) if decel else 0.0)
    return 2 * (abs(distance) / v + ramps) + MOVE_SLACK_S


def speed_refusal(axis: Axis, counts_per_s: int, what: str) -> UsageError | None:
    """The one speed check of every mover (jog, a pair's jog, the live jog): why ``counts_per_s``
    may not be sent on ``axis``, or None. A joint without a configured speed limit is refused too:
    never an unchecked speed (the seed's rosparam format has no limit)."""
    joint = axis.joint
    limit = axis.vel_limit  # a pair motor's: the slower of its pair's joints
    if limit is None:
        where = f"joints.{joint.name}.velocity.limit" if joint is not None else "velocity.limit of its joint"
        return UsageError(f"{axis.name}: no speed limit configured ({where} is missing), so {what} cannot be checked",
                          hint="give the joint `velocity: {limit: COUNTS_PER_S}` in the config")
    if abs(counts_per_s) <= limit:
        return None
    cpr = axis.cpr
    if cpr is None:
        asked, allowed = f"{abs(counts_per_s)} counts/s", f"{limit} counts/s"
    else:
        asked = f"{counts_to_rad(abs(counts_per_s), cpr):.4f} rad/s ({abs(counts_per_s)} counts/s)"
        allowed = f"{counts_to_rad(limit, cpr):.4f} rad/s ({limit} counts/s)"
    return UsageError(f"{axis.name}: {what} {asked} is above the joint's speed limit {allowed}",
                      hint="ask for less, or raise velocity.limit in the config")


@dataclass(frozen=True)
class Axis:
    """One thing a command can move (see the module docstring for the kinds)."""

    name: str  # as the user named it (a joint's name for a joint axis)
    kind: AxisKind  # plain | sigma | delta | motor | drive
    drive_a: str
    drive_b: str | None = None  # the second motor of a Σ/Δ joint
    sign: int = 1  # +1 Σ, -1 Δ: position = m_a + sign * m_b
    full: Range | None = None  # counts; None: no configured range (a motor or a bare drive)
    normal: Range | None = None
    cpr: int | None = None  # counts per joint revolution (None: a bare drive)
    vel_limit: int | None = None  # counts/s of the moved joint (a pair motor: the slower pair joint)
    current_limit: float | None = None  # A per motor (the configured continuous limit)
    accel: int | None = None  # counts/s² (config), for the move-time bound
    decel: int | None = None
    calibrated_by_config: bool = False  # an absolute encoder: no homing needed
    joint: JointConfig | None = None  # the joint moved (plain, Σ, Δ)
    pair: PairConfig | None = None
    joints: tuple[JointConfig, ...] = ()  # the joints whose calibration matters
    watched: tuple[Axis, ...] = ()  # every joint its motors move (the limit watch); empty for a watched joint
    refs: tuple[DriveRef, ...] = field(default=(), compare=False)  # the drives (config order: a, b)

    # -- drives ---------------------------------------------------------------------------------

    @property
    def drives(self) -> tuple[str, ...]:
        """The motors this axis commands (a, b for a Σ/Δ joint)."""
        return (self.drive_a,) if self.drive_b is None else (self.drive_a, self.drive_b)

    @property
    def ref(self) -> DriveRef:
        """The drive of a one-drive axis (plain, motor, drive)."""
        if len(self.refs) != 1:
            raise UsageError(f"'{self.name}' is moved by {len(self.drives)} drives ({', '.join(self.drives)}); "
                             "name one")
        return self.refs[0]

    @property
    def joint_config(self) -> JointConfig:
        """The joint this axis moves; a pair motor or a bare drive moves none (UsageError)."""
        if self.joint is None:
            raise UsageError(f"'{self.name}' moves no single joint of the config",
                             hint="name a joint, or a drive that moves a plain joint")
        return self.joint

    @property
    def joint_cpr(self) -> int:
        """Counts per revolution; a bare drive has none (UsageError: units cannot be converted)."""
        if self.cpr is None:
            raise UsageError(f"{self.name}: no joint of the config is driven by it, so there is no cpr to "
                             "convert units into counts", hint="name a joint, or a drive that moves one")
        return self.cpr

    @property
    def sensed(self) -> tuple[str, ...]:
        """Every drive whose position the watch needs (a pair motor alone: both motors of the pair)."""
        out = list(self.drives)
        for j in self.watched:
            out += [d for d in j.drives if d not in out]
        return tuple(out)

    @property
    def is_pair_joint(self) -> bool:
        return self.kind in (SIGMA, DELTA)

    # -- joint space <-> motor space ------------------------------------------------------------

    def position(self, motors: Motors) -> int:
        """Axis position (counts) from motor positions."""
        p = motors[self.drive_a]
        return p if self.drive_b is None else p + self.sign * motors[self.drive_b]

    def _split(self, value: int, other: int) -> tuple[int, int]:
        return (value, other) if self.kind == SIGMA else (other, value)

    def motor_targets(self, target: int, motors: Motors, held_range: Range | None = None) -> dict[str, int]:
        """Motor positions that put this axis at ``target`` while the other joint of a pair holds
        where ``motors`` have it (on a parity clash it gives way by one count, inside
        ``held_range`` when given: joints/diffpair.hold_other)."""
        if self.drive_b is None:
            return {self.drive_a: int(target)}
        a, b = self.drive_a, self.drive_b
        s, d = diffpair.to_joints(motors[a], motors[b])
        moving = "sigma" if self.kind == SIGMA else "delta"
        s2, d2 = diffpair.hold_other(target, d, moving, held_range) if moving == "sigma" else \
            diffpair.hold_other(s, target, moving, held_range)
        return dict(zip(self.drives, diffpair.to_motors(s2, d2), strict=True))

    def motor_velocities(self, velocity: int) -> dict[str, int]:
        """Motor speeds (counts/s) for this axis at ``velocity`` with the other pair joint at rest."""
        if self.drive_b is None:
            return {self.drive_a: int(velocity)}
        va, vb = diffpair.motor_velocities(*self._split(int(velocity), 0))
        return dict(zip(self.drives, (va, vb), strict=True))

    def motor_currents(self, amps: float) -> dict[str, float]:
        """Motor currents (A) for this axis's torque ``amps`` (the transpose of the position map)."""
        if self.drive_b is None:
            return {self.drive_a: float(amps)}
        ia, ib = diffpair.motor_currents(*self._split(amps, 0.0))  # type: ignore[arg-type]  # floats
        return dict(zip(self.drives, (ia, ib), strict=True))

    def velocity(self, motor_speeds: Motors) -> int:
        """Axis speed (counts/s) from motor speeds (the same linear map as :meth:`position`)."""
        return self.position(motor_speeds)

    def current(self, motor_currents: Mapping[str, float]) -> float:
        """Axis torque (A) from motor currents: the inverse of :meth:`motor_currents`."""
        if self.drive_b is None:
            return float(motor_currents[self.drive_a])
        return (motor_currents[self.drive_a] + self.sign * motor_currents[self.drive_b]) / 2

    # -- time -----------------------------------------------------------------------------------

    def move_time_bound(self, distance: float, speed: float | None = None, *, accel: float | None = None,
                        decel: float | None = None) -> float:
        """How long a move of ``distance`` counts of this axis may take (:func:`move_time_bound`), at
        ``speed`` (default: the axis's speed limit) and the given ramps (default: the config's)."""
        v = speed if speed is not None else (self.vel_limit or 1)
        return move_time_bound(distance, v, accel if accel is not None else self.accel,
                               decel if decel is not None else self.decel)

    # -- checks ---------------------------------------------------------------------------------

    def inside_normal(self, position: int) -> bool:
        return self.normal is None or self.normal[0] <= position <= self.normal[1]

    def inside_full(self, position: int) -> bool:
        return self.full is None or self.full[0] <= position <= self.full[1]


def profile_speed(axis: Axis, fallback: int, requested: int | None = None) -> int:
    """counts/s of a position move of ``axis``: the requested speed, else the
    joint's configured speed limit, else ``fallback`` (motion.recovery_fallback_speed) -- never the
    SP the drive happens to hold. The motion guard puts the drive's SP back afterwards."""
    if requested:
        return abs(int(requested))
    if axis.vel_limit:
        return abs(int(axis.vel_limit))
    return fallback


# --------------------------------------------------------------------------- resolving

def _current_limit(cfg: ArmConfig, joint: JointConfig) -> float | None:
    if joint.role is JointRole.PLAIN:
        return joint.current.continuous if joint.current is not None else None
    pair = cfg.pairs[joint.pair]  # type: ignore[index]
    return pair.current.continuous if pair.current is not None else None


def _absolute(cfg: ArmConfig, joint: JointConfig) -> bool:
    # as motion/calibration.absolute (kept here without the import: calibration reads drives)
    if joint.role is JointRole.PLAIN:
        return joint.abs_encoder is not None
    pair = cfg.pairs[joint.pair]  # type: ignore[index]
    return all(cfg.joints[n].abs_encoder is not None for n in (pair.sigma, pair.delta))


def _refs(cfg: ArmConfig, drives: Iterable[str]) -> tuple[DriveRef, ...]:
    return tuple(targets.drive_ref(cfg, d) for d in drives if d in cfg.drives)


def joint_axis(cfg: ArmConfig, joint: JointConfig, *, name: str | None = None,
               watched: tuple[Axis, ...] = ()) -> Axis:
    """The axis of a configured joint (plain, Σ or Δ)."""
    common = dict(full=joint.full_range, normal=joint.normal_range, cpr=joint.cpr, vel_limit=joint.vel_limit,
                  current_limit=_current_limit(cfg, joint), accel=joint.accel, decel=joint.decel,
                  calibrated_by_config=_absolute(cfg, joint), joint=joint, joints=(joint,), watched=watched)
    if joint.role is JointRole.PLAIN:
        assert joint.drive is not None  # a plain joint has its drive (config validation)
        return Axis(name or joint.name, PLAIN, joint.drive, refs=_refs(cfg, [joint.drive]),
                    **common)  # type: ignore[arg-type]
    pair = cfg.pairs[joint.pair]  # type: ignore[index]
    kind: AxisKind = "sigma" if joint.role is JointRole.SIGMA else "delta"
    return Axis(name or joint.name, kind, pair.drive_a, pair.drive_b, 1 if kind == SIGMA else -1,
                pair=pair, refs=_refs(cfg, [pair.drive_a, pair.drive_b]), **common)  # type: ignore[arg-type]


def joints_moved_by(cfg: ArmConfig, drives: Iterable[str]) -> list[Axis]:
    """Every joint the given drives move (a pair drive moves both Σ and Δ), in config order."""
    wanted = set(drives)
    out: list[Axis] = []
    for joint in cfg.joints.values():
        if joint.role is JointRole.PLAIN:
            moved = joint.drive in wanted
        else:
            pair = cfg.pairs.get(joint.pair) if joint.pair else None
            moved = pair is not None and bool(wanted & {pair.drive_a, pair.drive_b})
        if moved:
            out.append(joint_axis(cfg, joint))
    return out


def resolve_axis(cfg: ArmConfig, name: str, *, allow_pair: bool = False) -> Axis:
    """The one resolver: a plain joint, a Σ/Δ joint, one motor of a pair (its drive name or
    BUS:NODE), or a drive (of a plain joint: that joint's axis; else a bare drive). A whole pair is
    refused (name the joint to move) unless ``allow_pair`` (then its Σ axis stands for it, for the
    callers that expand a pair into its joints themselves)."""
    t = targets.resolve_one(cfg, name)
    pair = t.pair
    if pair is not None:
        if t.kind is targets.TargetKind.PAIR and not allow_pair:
            raise UsageError(f"'{name}' is a differential pair: name the joint to move ({pair.sigma} or "
                             f"{pair.delta}) or one motor ({pair.drive_a} or {pair.drive_b})")
        sigma, delta = cfg.joints[pair.sigma], cfg.joints[pair.delta]
        watched = tuple(joints_moved_by(cfg, (pair.drive_a, pair.drive_b)))
        if t.kind in (targets.TargetKind.JOINT, targets.TargetKind.PAIR):
            (joint,) = t.joints if t.kind is targets.TargetKind.JOINT else (sigma,)
            return joint_axis(cfg, joint, name=joint.name, watched=watched)
        (ref,) = t.drives  # a drive name or BUS:NODE: one motor of the pair
        # one motor at v moves Σ and Δ at v each: the slower joint limit bounds it
        limits = [v for v in (sigma.vel_limit, delta.vel_limit) if v is not None]
        ramps = [x for j in (sigma, delta) for x in (j.accel,) if x]
        decels = [x for j in (sigma, delta) for x in (j.decel,) if x]
        return Axis(ref.name, MOTOR, ref.name, cpr=sigma.cpr, vel_limit=min(limits) if limits else None,
                    current_limit=pair.current.continuous if pair.current is not None else None,
                    accel=min(ramps) if ramps else None, decel=min(decels) if decels else None,
                    calibrated_by_config=_absolute(cfg, sigma), pair=pair, joints=(sigma, delta),
                    watched=tuple(joints_moved_by(cfg, [ref.name])), refs=(ref,))
    if len(t.drives) != 1:
        raise UsageError(f"'{name}' is moved by {len(t.drives)} drives ({', '.join(t.drive_names)}); name one")
    (ref,) = t.drives
    plain = [j for j in t.joints if j.role is JointRole.PLAIN]
    if len(plain) == 1:
        joint = plain[0]
        base = joint_axis(cfg, joint, name=name)
        # the name as given (a joint or its drive), the drive as addressed (BUS:NODE keeps its ref)
        return replace(base, refs=(ref,), watched=(joint_axis(cfg, joint),))
    return Axis(name, DRIVE, ref.name, refs=(ref,))


def pair_axes(cfg: ArmConfig, pair: PairConfig) -> tuple[Axis, Axis]:
    """The Σ and Δ axes of a pair."""
    watched = tuple(joints_moved_by(cfg, (pair.drive_a, pair.drive_b)))
    return (joint_axis(cfg, cfg.joints[pair.sigma], watched=watched),
            joint_axis(cfg, cfg.joints[pair.delta], watched=watched))
