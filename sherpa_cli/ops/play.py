"""`sherpa move --trajectory FILE` and `Arm.play`: a time-stamped multi-joint path played on the arm
(docs/trajectory.md, docs/pvt.md).

:func:`prepare_play` reads and checks the path (joints/trajectory.py: ranges, speeds, accelerations,
the pairs' motor box), resamples it to the stream's period, reads where every joint stands and
refuses a path that does not start there -- nothing is sent but NMT start. :func:`run_play` streams
it inside one motion guard (motion/pvt_stream.py: Elmo PVT), watching every joint on the command's
thread, one joint per period in turn: a joint outside its full range, or farther than
``motion.tracking_bound`` counts from where the path puts it at that moment, stops every joint at
once, from standstill on the guard's exit. A
starved stream, an underflow, a fault, Ctrl-C or a signal stop every joint the same way.
"""

from __future__ import annotations

import bisect
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.joints.trajectory import (
    Resampled,
    Trajectory,
    check_played_from_rest,
    check_trajectory,
    motor_points,
    resample,
)
from sherpa_cli.motion import calibration, limit_watch
from sherpa_cli.motion.axis import Axis, joint_axis
from sherpa_cli.motion.plan import drives_of
from sherpa_cli.motion.pvt_stream import StreamSettings
from sherpa_cli.motion.report import GuardReport, with_report

# a path ends at rest: the speed its resampled end may still have (numerical tangents of a recording
# or a planner's last samples), as a share of the joint's speed limit; the last row then stops there
END_AT_REST = 0.05
# s between two looks of the watch, each at one joint in turn (its drives' positions read from the
# stream's own thread, between two periods' sends): every joint is looked at every WATCH_S x joints
WATCH_S = 0.01

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.joints.trajectory import MotorStream
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.pvt_stream import StreamReport


@dataclass(frozen=True)
class PreparedPlay:
    """A checked path, at the stream's period, with where the arm stands."""

    source: str
    trajectory: Trajectory
    resampled: Resampled
    stream: MotorStream
    motors: Mapping[str, int]  # drive -> PX read for the start check
    start_off: Mapping[str, int]  # joint -> counts from where it stands to the path's first point
    calibrations: list[calibration.Calibration] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return self.trajectory.duration


@dataclass
class PlayResult(limit_watch.BreachOutcome):
    """What the play did: the stream's report (periods on time, lateness, skew), per joint the largest
    tracking error the watch saw and where it ended against the path's end, and how the guard stopped."""

    source: str
    stream: StreamReport | None = None
    tracking: dict[str, int] = field(default_factory=dict)  # joint -> max |measured - path| counts
    end: dict[str, int] = field(default_factory=dict)  # joint -> counts after the stop
    target: dict[str, int] = field(default_factory=dict)  # joint -> the path's last point
    breaches: list[limit_watch.Breach] = field(default_factory=list)
    stop: GuardReport = field(default_factory=GuardReport)

    def as_json(self) -> dict[str, Any]:
        s = self.stream
        return {"source": self.source, "ok": self.ok,
                "stream": None if s is None else {"periods": s.periods, "on_time_pct": round(s.on_time_pct, 2),
                                                  "late": s.late, "max_lateness_s": round(s.max_lateness_s, 4),
                                                  "skew_s": round(s.skew_s, 4)},
                "joints": [{"joint": j, "end": self.end.get(j), "target": self.target.get(j),
                            "max_tracking_error": self.tracking.get(j)} for j in self.target],
                "stop": self.stop.as_json()}


def prepare_play(session: ArmSession, path: Path | Trajectory, *, uncalibrated: bool = False,
                 settings: StreamSettings | None = None) -> PreparedPlay:
    """Read (a path: ``log/trajectory_file``) and check the trajectory, resample it to the stream's
    period and check that it starts where the arm stands; UsageError / SafetyError before anything moves."""
    from sherpa_cli.log.trajectory_file import load_trajectory
    from sherpa_cli.ops.move import check_calibrated, read_motors

    cfg = session.cfg
    s = settings or StreamSettings()
    period = s.pvt.period_s
    if isinstance(path, Trajectory):
        traj, source = path, "the trajectory"
        check_trajectory(cfg, traj, source=source, period=period)
    else:
        traj, source = load_trajectory(Path(path), cfg, period=period), str(path)
    drives = drives_of(cfg, list(traj.joints))
    others = [d for d in drives if cfg.drives[d].type != "elmo"]
    if others:
        raise UsageError(f"{source}: {', '.join(others)}: a {cfg.drives[others[0]].type} drive; a trajectory is "
                         "streamed as Elmo PVT, and CiA 402 interpolated position is not built yet",
                         hint="docs/drives.md says what each drive type does")
    rs = resample(traj, period)
    check_played_from_rest(cfg, rs, source)
    for name in traj.joints:
        end_v, limit = rs.velocity(name)[-1], cfg.joints[name].vel_limit or 0
        if abs(end_v) > END_AT_REST * limit:
            raise UsageError(f"{source}: {name} still moves at its end ({end_v:+.0f} counts/s); a path must end "
                             f"at rest (at most {END_AT_REST:.0%} of the joint's speed limit)",
                             hint="end the path with the joints standing still")
    stream = motor_points(cfg, traj, period)
    motors = read_motors(session, drives)
    cals = check_calibrated(session, list(traj.joints), uncalibrated=uncalibrated)
    off = {}
    for name in traj.joints:
        axis = _axis(cfg, name)
        off[name] = round(rs.position(name)[0]) - axis.position(motors)
    far = {j: o for j, o in off.items() if abs(o) > s.start_tolerance}
    if far:
        j, o = next(iter(far.items()))
        raise UsageError(f"{source}: starts {o:+d} counts from where {j} stands"
                         + (f" (and {len(far) - 1} more joint(s))" if len(far) > 1 else "")
                         + f"; a path is played from where it begins (within {s.start_tolerance} counts)",
                         hint="bring the joints to its first point first (`sherpa move` with a pose there)")
    return PreparedPlay(source, traj, rs, stream, motors, off, cals)


def _axis(cfg: ArmConfig, joint: str) -> Axis:
    return joint_axis(cfg, cfg.joints[joint])


def run_play(session: ArmSession, prepared: PreparedPlay, *, settings: StreamSettings | None = None,
             guard_factory: Callable[..., MotionGuard] | None = None,
             clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
             on_event: Callable[[str], None] | None = None) -> PlayResult:
    """Play ``prepared`` in one motion guard over every motor it moves (module docstring). A watch
    breach or tracking error raises with every joint stopped; the result says how it went."""
    from sherpa_cli.bus.targets import drive_ref
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.pvt_stream import stream_motion_settings, stream_pvt
    from sherpa_cli.motion.settings import MotionSettings

    cfg = session.cfg
    s = settings or StreamSettings()
    drives = prepared.stream.drives
    refs = [drive_ref(cfg, d) for d in drives]
    motion = stream_motion_settings(MotionSettings.from_config(cfg, {r.bus for r in refs}))
    guard = (guard_factory or MotionGuard)(session, refs, settings=motion, clock=clock, sleep=sleep,
                                           on_event=on_event)
    axes = [_axis(cfg, j) for j in prepared.trajectory.joints]
    rs = prepared.resampled
    result = PlayResult(prepared.source,
                        target={a.name: round(rs.position(a.name)[-1]) for a in axes})
    bound = cfg.motion.tracking_bound
    by_name = {r.name: r for r in refs}
    # the stream's rows are the path's points after its first: the drive reaches row k at (k + 1) T;
    # the last row stands still (prepare_play let only a crawl at the end through)
    tracks = {d: [*zip(prepared.stream.motor(d).positions[1:-1], prepared.stream.motor(d).velocities[1:-1],
                       strict=True), (prepared.stream.motor(d).positions[-1], 0)] for d in drives}

    turn = [0]

    def watch(elapsed: float) -> None:
        # one joint per look, in turn: the sender's period must not wait for every drive's answer
        a = axes[turn[0] % len(axes)]
        turn[0] += 1
        motors = {d: guard.position(by_name[d]) for d in a.drives}
        breaches = limit_watch.check([a], motors)
        if breaches:
            result.breaches = list(breaches)
            raise SafetyError("trajectory: " + "; ".join(b.describe() for b in breaches) + "; every joint stopped",
                              hint="check the joint; the path was checked against the normal ranges")
        err = a.position(motors) - round(_at(rs, a.name, elapsed))
        result.tracking[a.name] = max(result.tracking.get(a.name, 0), abs(err))
        if abs(err) > bound:
            raise SafetyError(f"trajectory: {a.name} is {err:+d} counts from the path at t={elapsed:.2f} s "
                              f"(motion.tracking_bound {bound}); every joint stopped",
                              hint="a joint that cannot follow: lower the path's speed, or check the joint")

    try:
        with guard:
            result.stream = stream_pvt(guard, tracks, settings=s, clock=clock, sleep=sleep, watch=watch,
                                       watch_interval=WATCH_S)
    except BaseException as exc:
        carried = with_report(exc, guard.report)  # the CLI shows how the guard stopped the motors
        if carried is exc:
            raise
        raise carried from exc
    result.stop = guard.report
    stopped = {d.drive: d.position for d in guard.report.drives if d.position is not None}
    for a in axes:
        if all(d in stopped for d in a.drives):
            result.end[a.name] = a.position({d: p for d, p in stopped.items() if p is not None})
    return result


def _at(rs: Resampled, joint: str, t: float) -> float:
    """The resampled path's position at ``t`` s (linear between its points; held at its ends)."""
    times, xs = rs.times, rs.position(joint)
    if t <= times[0]:
        return xs[0]
    if t >= times[-1]:
        return xs[-1]
    i = bisect.bisect_right(times, t) - 1
    span = times[i + 1] - times[i]
    return xs[i] + (xs[i + 1] - xs[i]) * (t - times[i]) / span
