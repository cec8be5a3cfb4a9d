"""A time-stamped multi-joint path, its checks, its resampling to the stream period, and the
per-motor points a streamer sends (docs/trajectory.md). Pure: no bus, no streaming.

Positions are joint counts (floats: a path is not quantised until it becomes motor points).

Resampling is a shape-preserving piecewise cubic Hermite (Fritsch-Carlson "PCHIP", the tangents
SciPy's ``PchipInterpolator`` uses inside the path, the first and last secant at its ends). It was
chosen over a natural or Catmull-Rom spline because it never overshoots: where the samples rise
(or fall) between two of them the path does too, so a path that stays inside a joint's range
between its samples stays inside it between the stream's points, and a joint that stands still
between two samples stands still in the stream. Positions and velocities are continuous; a
straight line is reproduced exactly, velocity included; at every sample the velocity lies between
the speeds of the two segments beside it. Between samples a cubic can go faster than either
segment's average speed (at most 1.5 times the larger of them where the path turns hard), which is
why :func:`check_trajectory` with ``period`` checks the stream's velocities too.

A Σ/Δ pair becomes motor points as motion/plan.py turns pair targets into motor targets: each
joint rounded to whole counts (half away from zero), and where Σ and Δ then differ in parity
(m_a = (Σ+Δ)/2 has no whole count) Δ gives way by one count (joints/diffpair.py ``hold_other``);
velocities ``v_a = (vΣ+vΔ)/2``, ``v_b = (vΣ-vΔ)/2`` rounded half away from zero.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass

from sherpa_cli.config.model import ArmConfig, JointConfig, JointRole
from sherpa_cli.config.yamlnodes import suggest
from sherpa_cli.errors import UsageError
from sherpa_cli.joints import diffpair
from sherpa_cli.units import counts_per_s_to_rad_per_s, counts_to_rad, round_half_away

# float arithmetic on a path that sits exactly on a limit must not refuse it: a relative slack this
# small is far below a count (limits are whole counts, counts/s)
_SLACK = 1e-9
# a duration within this fraction of a period of a whole number of periods is that number
_GRID_SNAP = 1e-9


@dataclass(frozen=True)
class Trajectory:
    """Joint positions (counts, float) at increasing times (s, the first 0).

    ``positions[j][i]`` is joint ``joints[j]`` at ``times[i]``. ``rows`` is, when the path came
    from a text file, the file's line of each sample, for messages; else empty."""

    joints: tuple[str, ...]
    times: tuple[float, ...]
    positions: tuple[tuple[float, ...], ...]
    rows: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if len(self.positions) != len(self.joints):
            raise ValueError(f"{len(self.joints)} joints but {len(self.positions)} position series")
        for name, series in zip(self.joints, self.positions, strict=True):
            if len(series) != len(self.times):
                raise ValueError(f"{name}: {len(series)} positions for {len(self.times)} times")
        if self.rows and len(self.rows) != len(self.times):
            raise ValueError(f"{len(self.rows)} rows for {len(self.times)} samples")

    @property
    def samples(self) -> int:
        return len(self.times)

    @property
    def duration(self) -> float:
        """s from the first sample to the last (0 without samples)."""
        return self.times[-1] - self.times[0] if self.times else 0.0

    def position(self, joint: str) -> tuple[float, ...]:
        """One joint's positions (counts), a value per sample."""
        return self.positions[self.joints.index(joint)]

    def where(self, source: str, i: int) -> str:
        """Where sample ``i`` is, for a message: ``run.csv:14 (t=0.130 s)`` or ``run.mcap: t=0.130 s``."""
        t = self.times[i]
        when = f"t={t:.3f} s" if math.isfinite(t) else f"t={t}"
        return f"{source}:{self.rows[i]} ({when})" if self.rows else f"{source}: {when}"


@dataclass(frozen=True)
class Resampled:
    """A path at the stream's period: positions (counts) and velocities (counts/s) per joint.

    ``times`` are 0, period, 2·period, ... and the last is exactly the path's end, so the last
    interval is shorter than the period when the duration is not a whole number of periods."""

    period: float
    joints: tuple[str, ...]
    times: tuple[float, ...]
    positions: tuple[tuple[float, ...], ...]
    velocities: tuple[tuple[float, ...], ...]

    def position(self, joint: str) -> tuple[float, ...]:
        return self.positions[self.joints.index(joint)]

    def velocity(self, joint: str) -> tuple[float, ...]:
        return self.velocities[self.joints.index(joint)]


@dataclass(frozen=True)
class MotorTrack:
    """One motor's points: whole counts and counts/s, one per time of the stream."""

    drive: str
    positions: tuple[int, ...]
    velocities: tuple[int, ...]


@dataclass(frozen=True)
class MotorStream:
    """What a streamer sends: per drive (config order) a position and velocity per point."""

    period: float
    times: tuple[float, ...]
    motors: tuple[MotorTrack, ...]

    @property
    def drives(self) -> tuple[str, ...]:
        return tuple(m.drive for m in self.motors)

    def motor(self, drive: str) -> MotorTrack:
        for m in self.motors:
            if m.drive == drive:
                return m
        raise KeyError(drive)


# --------------------------------------------------------------------------- checks

def check_joints(cfg: ArmConfig, joints: Sequence[str], *, source: str) -> None:
    """The joints a path names: at least one, each a joint of the config (with a suggestion
    otherwise), none twice, and both joints of a Σ/Δ pair when it names one of them."""
    if not joints:
        raise UsageError(f"{source}: names no joint", hint=f"joints: {', '.join(cfg.joints)}")
    seen: set[str] = set()
    for name in joints:
        if name in seen:
            raise UsageError(f"{source}: joint '{name}' is named twice")
        seen.add(name)
        if name not in cfg.joints:
            close = suggest(name, list(cfg.joints))
            raise UsageError(f"{source}: joint '{name}' is not a joint of the config"
                             + (f"; did you mean '{close}'?" if close else ""),
                             hint=f"joints: {', '.join(cfg.joints)}")
    for name in joints:
        j = cfg.joints[name]
        if j.role is JointRole.PLAIN:
            continue
        pair = cfg.pairs[j.pair]  # type: ignore[index]
        partner = pair.delta if name == pair.sigma else pair.sigma
        if partner not in seen:
            # both motors of a pair move both joints: a path of one of them says nothing of where
            # the other must be at each point, and the path's start need not be where it stands now
            raise UsageError(f"{source}: {name} is a joint of the Σ/Δ pair {pair.name}; the trajectory must "
                             f"give {partner} too", hint=f"add a {partner} column (a constant holds it)")


def check_trajectory(cfg: ArmConfig, traj: Trajectory, *, source: str, period: float | None = None) -> None:
    """Refuse (one UsageError naming ``source`` and the row or time) a path the arm must not play:
    fewer than two samples, an unknown joint, half a Σ/Δ pair, a joint without a speed limit,
    NaN/inf, a time that does not increase or a first time other than 0, a position outside a
    joint's normal range, a speed above its limit or an acceleration above its configured
    acceleration (finite differences of the samples), a pair's motors outside their box.

    With ``period``, the velocities of the path resampled to it (what a streamer sends) are
    checked against the speed limits too."""
    if traj.samples == 0:
        raise UsageError(f"{source}: the trajectory is empty: no samples")
    if traj.samples == 1:
        raise UsageError(f"{source}: the trajectory has one sample; it needs two or more (a start and an end)")
    check_joints(cfg, traj.joints, source=source)
    for name in traj.joints:
        if cfg.joints[name].vel_limit is None:
            raise UsageError(f"{source}: {name} has no speed limit configured (joints.{name}.velocity.limit), "
                             "so the path's speed cannot be checked",
                             hint="give the joint `velocity: {limit: COUNTS_PER_S}`")
    _check_finite(traj, source)
    _check_times(traj, source)
    _check_ranges(cfg, traj, source)
    _check_speeds(cfg, traj, source)
    _check_accelerations(cfg, traj, source)
    _check_motor_box(cfg, traj, source)
    if period is not None:
        _check_resampled(cfg, resample(traj, period), source)


def _check_finite(traj: Trajectory, source: str) -> None:
    for i, t in enumerate(traj.times):
        if not math.isfinite(t):
            raise UsageError(f"{traj.where(source, i)}: the time is not a finite number")
    for name, series in zip(traj.joints, traj.positions, strict=True):
        for i, x in enumerate(series):
            if not math.isfinite(x):
                raise UsageError(f"{traj.where(source, i)}: {name} is not a finite number ({x})")


def _check_times(traj: Trajectory, source: str) -> None:
    if traj.times[0] != 0:
        raise UsageError(f"{traj.where(source, 0)}: the first sample is at {traj.times[0]:g} s; a trajectory "
                         "starts at 0")
    for i in range(1, traj.samples):
        if traj.times[i] <= traj.times[i - 1]:
            what = "repeats" if traj.times[i] == traj.times[i - 1] else "goes back from"
            raise UsageError(f"{traj.where(source, i)}: the time {what} the previous sample's "
                             f"{traj.times[i - 1]:.6g} s; times must increase")


def _check_ranges(cfg: ArmConfig, traj: Trajectory, source: str) -> None:
    for name, series in zip(traj.joints, traj.positions, strict=True):
        j = cfg.joints[name]
        lo, hi = j.normal_range
        for i, x in enumerate(series):
            if not lo <= x <= hi:
                raise UsageError(f"{traj.where(source, i)}: {name} at {x:.1f} counts "
                                 f"({counts_to_rad(x, j.cpr):+.4f} rad) is outside its normal range "
                                 f"[{lo}, {hi}] counts",
                                 hint="a trajectory takes a joint only inside its normal range (range less margin)")


def _secants(times: Sequence[float], series: Sequence[float]) -> list[float]:
    return [(series[i + 1] - series[i]) / (times[i + 1] - times[i]) for i in range(len(times) - 1)]


def _check_speeds(cfg: ArmConfig, traj: Trajectory, source: str) -> None:
    for name, series in zip(traj.joints, traj.positions, strict=True):
        j = cfg.joints[name]
        limit = j.vel_limit
        assert limit is not None  # checked before
        for i, v in enumerate(_secants(traj.times, series)):
            if abs(v) > limit * (1 + _SLACK):
                raise UsageError(f"{traj.where(source, i + 1)}: {name} moves at {abs(v):.0f} counts/s "
                                 f"({counts_per_s_to_rad_per_s(abs(v), j.cpr):.4f} rad/s) from the previous "
                                 f"sample, above its speed limit {limit} counts/s",
                                 hint="slow the trajectory down (stretch its times)")


def _check_accelerations(cfg: ArmConfig, traj: Trajectory, source: str) -> None:
    for name, series in zip(traj.joints, traj.positions, strict=True):
        j = cfg.joints[name]
        if j.accel is None and j.decel is None:
            continue
        v = _secants(traj.times, series)
        for i in range(1, len(v)):
            # the speed change around sample i over the time between the segments' midpoints
            a = (v[i] - v[i - 1]) / ((traj.times[i + 1] - traj.times[i - 1]) / 2)
            speeding_up = abs(v[i]) >= abs(v[i - 1]) and v[i] * v[i - 1] >= 0
            key, limit = _accel_limit(j, speeding_up)
            if abs(a) > limit * (1 + _SLACK):
                what = "accelerates" if speeding_up else "decelerates"
                raise UsageError(f"{traj.where(source, i)}: {name} {what} at {abs(a):.0f} counts/s² "
                                 f"({abs(counts_per_s_to_rad_per_s(a, j.cpr)):.3f} rad/s²), above its "
                                 f"{key} {limit} counts/s² (joints.{name}.acceleration.{key})",
                                 hint="slow the trajectory down or smooth it")


def _accel_limit(j: JointConfig, speeding_up: bool) -> tuple[str, int]:
    """The configured limit a speed change is held to, and its key: accel when it speeds up, decel when
    it slows down; a joint with only one of them configured takes it both ways."""
    key = ("accel" if speeding_up else "decel") if j.accel is not None and j.decel is not None \
        else ("accel" if j.accel is not None else "decel")
    limit = j.accel if key == "accel" else j.decel
    assert limit is not None  # the callers check a joint with at least one of them
    return key, limit


def _check_motor_box(cfg: ArmConfig, traj: Trajectory, source: str) -> None:
    for pair in cfg.pairs.values():
        if pair.sigma not in traj.joints:
            continue
        sj, dj = cfg.joints[pair.sigma], cfg.joints[pair.delta]
        box = diffpair.motor_box(sj.full_range, dj.full_range)
        sig, dlt = traj.position(pair.sigma), traj.position(pair.delta)
        for i in range(traj.samples):
            ma, mb = _pair_motors(sig[i], dlt[i], dj.normal_range)
            if not box.contains(ma, mb):
                raise UsageError(f"{traj.where(source, i)}: {pair.name}: motor positions {pair.drive_a}={ma}, "
                                 f"{pair.drive_b}={mb} are outside the motor box {pair.drive_a} "
                                 f"[{box.a[0]}, {box.a[1]}], {pair.drive_b} [{box.b[0]}, {box.b[1]}]")


def _check_resampled(cfg: ArmConfig, rs: Resampled, source: str) -> None:
    """What the drives are sent, not only the samples: the speed and the acceleration between samples
    (the cubic is only C1), a pair's motor box."""
    for name, series in zip(rs.joints, rs.velocities, strict=True):
        j = cfg.joints[name]
        limit = j.vel_limit
        assert limit is not None
        for k, v in enumerate(series):
            if abs(v) > limit * (1 + _SLACK):
                raise UsageError(f"{source}: t={rs.times[k]:.3f} s: {name} would move at {abs(v):.0f} counts/s "
                                 f"in the stream resampled to {rs.period:g} s, above its speed limit {limit} "
                                 "counts/s (the samples start or turn too sharply at that speed)",
                                 hint="slow the trajectory down (stretch its times)")
        _check_stream_accelerations(j, name, rs, series, source, from_rest=False)
    for pair in cfg.pairs.values():
        if pair.sigma not in rs.joints or pair.delta not in rs.joints:
            continue
        dj = cfg.joints[pair.delta]
        box = diffpair.motor_box(cfg.joints[pair.sigma].full_range, dj.full_range)
        for k, (s, d) in enumerate(zip(rs.position(pair.sigma), rs.position(pair.delta), strict=True)):
            ma, mb = _pair_motors(s, d, dj.normal_range)
            if not box.contains(ma, mb):
                raise UsageError(f"{source}: t={rs.times[k]:.3f} s: {pair.name}: between samples the motors would "
                                 f"reach {pair.drive_a}={ma}, {pair.drive_b}={mb}, outside the motor box "
                                 f"{pair.drive_a} [{box.a[0]}, {box.a[1]}], {pair.drive_b} [{box.b[0]}, {box.b[1]}]")


def check_played_from_rest(cfg: ArmConfig, rs: Resampled, source: str) -> None:
    """A path played on the drives starts from standstill and ends at it: the speed change from rest
    to its first point, and from its last back to rest, within each joint's configured acceleration."""
    for name, series in zip(rs.joints, rs.velocities, strict=True):
        _check_stream_accelerations(cfg.joints[name], name, rs, series, source, from_rest=True)


def _check_stream_accelerations(j: JointConfig, name: str, rs: Resampled, series: Sequence[float],
                                source: str, *, from_rest: bool) -> None:
    """The resampled speed changes (``from_rest``: only from rest before the first point and to rest
    after the last) against the joint's configured acceleration (a joint with one of accel/decel takes
    it both ways)."""
    if j.accel is None and j.decel is None:
        return
    if from_rest:
        speeds = [0.0, series[0], series[-1], 0.0]
        times = [rs.times[0] - rs.period, rs.times[0], rs.times[-1], rs.times[-1] + rs.period]
    else:
        speeds, times = list(series), list(rs.times)
    for k in range(1, len(speeds)):
        dt = times[k] - times[k - 1]
        if dt <= 0 or (from_rest and k == 2):
            continue  # from_rest: the first and last points' own speeds, not the path between them
        a = (speeds[k] - speeds[k - 1]) / dt
        speeding_up = abs(speeds[k]) >= abs(speeds[k - 1]) and speeds[k] * speeds[k - 1] >= 0
        key, limit = _accel_limit(j, speeding_up)
        if abs(a) > limit * (1 + _SLACK):
            when = min(max(times[k], rs.times[0]), rs.times[-1])
            raise UsageError(f"{source}: t={when:.3f} s: {name} would {'accelerate' if speeding_up else 'decelerate'} "
                             f"at {abs(a):.0f} counts/s² in the stream resampled to {rs.period:g} s"
                             f"{' (from rest at its start, to rest at its end)' if from_rest else ''}, above its "
                             f"{key} {limit} counts/s² "
                             f"(joints.{name}.acceleration.{key})",
                             hint="start and end the trajectory at rest, slow it down or smooth it")


# --------------------------------------------------------------------------- resampling

def _tangents(times: Sequence[float], series: Sequence[float]) -> list[float]:
    """PCHIP tangents: a weighted harmonic mean of the neighbouring secants where they agree in
    sign, 0 where the path turns or stands, the neighbouring secant at either end."""
    n = len(times)
    d = _secants(times, series)
    h = [times[i + 1] - times[i] for i in range(n - 1)]
    m = [0.0] * n
    m[0], m[-1] = d[0], d[-1]
    for i in range(1, n - 1):
        if d[i - 1] * d[i] <= 0:
            continue
        w1, w2 = 2 * h[i] + h[i - 1], h[i] + 2 * h[i - 1]
        m[i] = (w1 + w2) / (w1 / d[i - 1] + w2 / d[i])
    return m


def _grid(duration: float, period: float) -> list[float]:
    n = math.floor(duration / period + _GRID_SNAP)
    times = [k * period for k in range(n + 1)]
    if duration - times[-1] > _GRID_SNAP * period:
        times.append(duration)
    else:
        times[-1] = duration
    return times


def check_period(period: float) -> None:
    if isinstance(period, bool) or not isinstance(period, (int, float)) or not math.isfinite(period) \
            or period <= 0:
        raise UsageError(f"stream period {period!r}: expected a positive number of seconds")


def resample(traj: Trajectory, period: float) -> Resampled:
    """``traj`` (checked: at least two samples, increasing finite times from 0) at ``period`` s
    with the module's cubic Hermite: positions and velocities at 0, period, ... and at the end."""
    check_period(period)
    if traj.samples < 2:
        raise UsageError("a trajectory needs two or more samples to be resampled")
    times = traj.times
    grid = _grid(traj.duration, period)
    positions, velocities = [], []
    for series in traj.positions:
        m = _tangents(times, series)
        xs, vs = [], []
        for t in grid:
            x, v = _hermite(times, series, m, t)
            xs.append(x)
            vs.append(v)
        positions.append(tuple(xs))
        velocities.append(tuple(vs))
    return Resampled(period, traj.joints, tuple(grid), tuple(positions), tuple(velocities))


def _hermite(times: Sequence[float], x: Sequence[float], m: Sequence[float], t: float) -> tuple[float, float]:
    i = bisect.bisect_right(times, t) - 1
    if i >= len(times) - 1:
        return x[-1], m[-1]
    i = max(i, 0)
    if t == times[i]:
        return x[i], m[i]
    h = times[i + 1] - times[i]
    s = (t - times[i]) / h
    s2, s3 = s * s, s * s * s
    pos = ((2 * s3 - 3 * s2 + 1) * x[i] + (s3 - 2 * s2 + s) * h * m[i] + (-2 * s3 + 3 * s2) * x[i + 1]
           + (s3 - s2) * h * m[i + 1])
    vel = ((6 * s2 - 6 * s) * (x[i] - x[i + 1]) / h + (3 * s2 - 4 * s + 1) * m[i] + (3 * s2 - 2 * s) * m[i + 1])
    return pos, vel


# --------------------------------------------------------------------------- motor points

def _pair_motors(sigma: float, delta: float, delta_range: tuple[int, int]) -> tuple[int, int]:
    """Σ, Δ (counts, float) -> whole motor counts as motion/plan.py does: both rounded, Δ giving
    way by one count (inside its range) when their parity differs."""
    s, d = round_half_away(sigma), round_half_away(delta)
    s, d = diffpair.hold_other(s, d, "sigma", delta_range)
    return diffpair.to_motors(s, d)


def motor_points(cfg: ArmConfig, traj: Trajectory, period: float) -> MotorStream:
    """Each drive's (position counts, velocity counts/s) at every point of ``traj`` resampled to
    ``period``: a plain joint 1:1, a Σ/Δ pair through the pair transform (module docstring).
    ``traj`` is a checked trajectory (:func:`check_trajectory`)."""
    check_joints(cfg, traj.joints, source="trajectory")
    rs = resample(traj, period)
    tracks: dict[str, MotorTrack] = {}
    for name in rs.joints:
        j = cfg.joints[name]
        if j.role is JointRole.PLAIN:
            assert j.drive is not None  # a plain joint has its drive (config validation)
            tracks[j.drive] = MotorTrack(j.drive, tuple(round_half_away(x) for x in rs.position(name)),
                                         tuple(round_half_away(v) for v in rs.velocity(name)))
            continue
        pair = cfg.pairs[j.pair]  # type: ignore[index]
        if name != pair.sigma:
            continue
        delta_range = cfg.joints[pair.delta].normal_range
        motors = [_pair_motors(s, d, delta_range) for s, d in zip(rs.position(pair.sigma), rs.position(pair.delta),
                                                                   strict=True)]
        vs, vd = rs.velocity(pair.sigma), rs.velocity(pair.delta)
        tracks[pair.drive_a] = MotorTrack(pair.drive_a, tuple(a for a, _ in motors),
                                          tuple(round_half_away((s + d) / 2) for s, d in zip(vs, vd, strict=True)))
        tracks[pair.drive_b] = MotorTrack(pair.drive_b, tuple(b for _, b in motors),
                                          tuple(round_half_away((s - d) / 2) for s, d in zip(vs, vd, strict=True)))
    return MotorStream(period, rs.times, tuple(tracks[d] for d in cfg.drives if d in tracks))
