"""`sherpa move POSE`: several joints to a named pose of the config, all together (ops/move.py does
the work through `Arm.move_pose`; docs/move.md)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import ApplyMotion, name_list
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.motion.plan import JointMove, MotionPlan
    from sherpa_cli.motion.run import JointOutcome, MotionOutcome
    from sherpa_cli.ops.move import PreparedMove
    from sherpa_cli.ops.play import PlayResult, PreparedPlay


def move(
    ctx: typer.Context,
    pose: str | None = typer.Argument(None, metavar="POSE", help="A pose of the config's `poses:` section."),
    trajectory: Path | None = typer.Option(None, "--trajectory", metavar="FILE",
                                           help="Play a time-stamped path instead: a `log record` CSV or MCAP, "
                                                "or a planner's CSV (t,<joint>,... in s and rad)."),
    joints: list[str] | None = typer.Option(None, "--joints", metavar="JOINT",
                                            help="Move only these joints of the pose (comma-separated or repeated)."),
    speed_scale: float = typer.Option(1.0, "--speed-scale", metavar="F",
                                      help="A fraction (0 < F <= 1) of the joints' speed limits."),
    uncalibrated: bool = typer.Option(False, "--uncalibrated", help="Allow joints that have no absolute encoder "
                                      "and were not homed since power-up."),
    force_limit: float | None = typer.Option(None, "--force-limit", metavar="N",
                                             help="Stop the motion when the F/T sensor reads a force above N "
                                                  "newtons (tightens the sensor's configured force_limit)."),
    hold: bool = typer.Option(False, "--hold", help="After the move keep every motor on, holding where it ended, "
                              "until Ctrl-C or `sherpa stop`."),
    apply: ApplyMotion = False,
) -> None:
    """Move every joint a pose names to it: all start together and arrive together.

    The joint that needs the most time at its configured speed (times --speed-scale) runs at that
    speed and sets the time; the others go slower. A Σ/Δ pair moves with both motors in one
    profile. Without --apply the plan is shown (each joint from -> to, speed, the time) and
    nothing moves; the positions are read for it.

    The move runs inside the motion guard, with the dead-man armed on every bus and the limit
    watch on every joint. A joint that leaves its full range stops every joint and is brought
    back (exit 1); a fault, a lost drive, Ctrl-C or a signal stops every joint from standstill.

    \b
    With --trajectory FILE the path is played instead (docs/trajectory.md): checked against every
    joint's range, speed and acceleration, resampled to the stream's period, and it must start where
    the arm stands. With --apply it is streamed to the drives (Elmo PVT), every joint watched: one
    outside its range or farther than motion.tracking_bound from the path, a starved stream or a
    fault stops every joint.

    \b
    Examples:
      sherpa move transport
      sherpa move transport --apply
      sherpa move transport --joints elbow_pitch --joints wrist_1 --speed-scale 0.5 --apply
      sherpa move --trajectory path.csv --apply
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.motion.plan import check_speed_scale, drives_of
    from sherpa_cli.ops.move import pose_targets

    st = state(ctx)
    st.use_force_limit(force_limit)
    if (pose is None) == (trajectory is None):
        raise UsageError("name a POSE or give --trajectory FILE (one of them)",
                         hint="`sherpa pose list` shows the config's poses")
    if trajectory is not None:
        if joints or speed_scale != 1.0 or hold:
            raise UsageError("--joints, --speed-scale and --hold move to a pose; a trajectory is played as it is")
        _play(st, trajectory, uncalibrated=uncalibrated, apply=apply)
        return
    assert pose is not None
    cfg = st.load_config()
    check_speed_scale(speed_scale)
    joints = name_list(joints)
    targets = pose_targets(cfg, pose, joints)  # an unknown pose or joint: one line, before the bus
    buses = sorted({cfg.drives[d].bus for d in drives_of(cfg, list(targets))}, key=list(cfg.buses).index)
    with st.session(buses=buses) as session:
        arm = Arm(session)
        prepared = arm.plan_pose(pose, joints=joints, speed_scale=speed_scale, uncalibrated=uncalibrated)
        if not apply:
            _dry_run(st, prepared)
            return
        from sherpa_cli.motion.gravity import gravity_notice

        notice = gravity_notice(cfg, list(targets), holds=hold)
        if notice is not None:
            st.out.warn(notice)

        def progress(joints_now: object) -> None:
            if isinstance(joints_now, dict):
                st.out.progress("  ".join(f"{j}: {p}" for j, p in joints_now.items()))

        try:
            result = arm.run_pose(prepared, hold=hold, on_progress=progress)
        except BaseException as exc:
            from sherpa_cli.cli.jog_cmd import show_stop_report

            st.out.progress(None)
            show_stop_report(st, exc)
            raise
    st.out.progress(None)
    _render(st, prepared, result)
    if not result.ok:
        raise typer.Exit(1)


def _pos(counts: int, cpr: int) -> str:
    from sherpa_cli.joints.units import counts_to_rad

    return f"{counts_to_rad(counts, cpr):+.4f} rad ({counts} counts)"


def _joint_plan(j: JointMove, plan: MotionPlan) -> str:
    from sherpa_cli.joints.units import counts_per_s_to_rad_per_s

    if not j.distance:
        return f"  {j.name}: stays at {_pos(j.start, j.cpr)}"
    speed = f"{counts_per_s_to_rad_per_s(j.speed, j.cpr):.4f} rad/s ({j.speed:.0f} counts/s"
    speed += f" of {j.limit}" + (", sets the time)" if j.name == plan.paced_by else ")")
    gave = f" (asked {j.asked}: Σ and Δ share parity)" if j.asked is not None else ""
    return f"  {j.name}: {_pos(j.start, j.cpr)} -> {_pos(j.target, j.cpr)}{gave}, {speed}"


def _cpr(prepared: PreparedMove, joint: str) -> int:
    return next(a.joint_cpr for a in prepared.plan.watched if a.name == joint)


def _dry_run(st: AppState, prepared: PreparedMove) -> None:
    plan = prepared.plan
    what = f"pose {prepared.pose}" if prepared.pose else "the pose"
    if st.json_mode:
        st.out.json({"pose": prepared.pose, "applied": False, "duration_s": round(plan.duration, 3),
                     "paced_by": plan.paced_by, "speed_scale": plan.speed_scale,
                     "joints": [{"joint": j.name, "from": j.start, "to": j.target, "speed": round(j.speed, 1),
                                 "limit": j.limit} for j in plan.joints],
                     "held": {n: {"from": plan.held_from.get(n, c), "to": c} for n, c in plan.held.items()},
                     "motors": {m.drive: {"PA": m.target, **m.profile.as_dict()} for m in plan.motors}})
        return
    if not plan.motors:
        st.out.line(f"dry run: {what}: every joint stands at its target already; nothing to move")
        return
    buses = sorted({m.ref.bus for m in plan.motors})
    st.out.line(f"dry run: would move {len([j for j in plan.joints if j.distance])} joint(s) to {what} on "
                f"{', '.join(buses)}, all starting and arriving together in {plan.duration:.2f} s"
                + (f" (speed scale {plan.speed_scale:g})" if plan.speed_scale != 1 else ""))
    for j in plan.joints:
        st.out.line(_joint_plan(j, plan))
    for name, counts in plan.held.items():
        before = plan.held_from.get(name, counts)
        st.out.line(f"  {name}: holds at {_pos(before, _cpr(prepared, name))}" +
                    (" (its pair moves)" if before == counts else
                     f", giving way to {counts} counts: Σ and Δ share parity"))
    st.out.line("  would send: " + "; ".join(f"{m.drive} SP={m.profile.sp} AC={m.profile.ac} DC={m.profile.dc} "
                                       f"PA={m.target}" for m in plan.motors))
    st.out.line("nothing sent; add --apply to move")


def _joint_end(j: JointOutcome) -> str:
    text = f"  {j.joint}: at {_pos(j.end_counts, j.cpr)}"
    err = j.error_counts
    if err is not None:
        text += ", target reached" if j.reached else ", did not reach its target"
        text += f"; error {err:+d} counts ({j.error_rad or 0.0:+.4f} rad)"
    return text


def _render(st: AppState, prepared: PreparedMove, r: MotionOutcome) -> None:
    from sherpa_cli.cli.jog_cmd import hold_line

    if st.json_mode:
        st.out.json({"pose": prepared.pose, "applied": True, **r.as_json()})
        return
    for line in r.stop.lines(st.verbose):
        st.out.line(f"stop: {line}")
    if r.start is not None:
        st.out.line(r.start.line())
    for b in r.breaches:
        st.out.line(f"limit: {b.joint} left its full range [{b.full[0]}, {b.full[1]}] on the {b.side} side: "
                    f"every joint stopped, nothing more sent, brought back to {r.recovered_to.get(b.joint)} counts "
                    f"(normal range edge {b.back_to})")
    if r.held_at is not None:
        st.out.line(hold_line(r.held_at, r.held_until))
    what = f"pose {prepared.pose}" if prepared.pose else "the pose"
    st.out.line(f"{what}: " + ("every joint arrived" if r.ok and all(j.reached for j in r.joints.values())
                               else "stopped by the joint-limit watch" if not r.ok else "not every joint arrived"))
    for j in r.joints.values():
        st.out.line(_joint_end(j))


def _play(st: AppState, path: Path, *, uncalibrated: bool, apply: bool) -> None:
    """`move --trajectory FILE`: the checks and the dry run, or the play (ops/play.py via `Arm.play`)."""
    from sherpa_cli.api import Arm
    from sherpa_cli.log.trajectory_file import load_trajectory
    from sherpa_cli.motion.plan import drives_of

    cfg = st.load_config()
    joints = load_trajectory(path, cfg, check=False).joints  # the buses to open; checked in plan_play
    buses = sorted({cfg.drives[d].bus for d in drives_of(cfg, [j for j in joints if j in cfg.joints])},
                   key=list(cfg.buses).index)
    with st.session(buses=buses) as session:
        arm = Arm(session)
        prepared = arm.plan_play(path, uncalibrated=uncalibrated)
        if not apply:
            _play_dry_run(st, prepared)
            return
        try:
            result = arm.play(prepared)
        except BaseException as exc:
            from sherpa_cli.cli.jog_cmd import show_stop_report

            show_stop_report(st, exc)
            raise
    _render_play(st, result, prepared)
    if not result.ok:
        raise typer.Exit(1)


def _play_dry_run(st: AppState, prepared: PreparedPlay) -> None:
    from sherpa_cli.joints.units import counts_per_s_to_rad_per_s

    traj, rs, cfg = prepared.trajectory, prepared.resampled, st.load_config()
    if st.json_mode:
        st.out.json({"trajectory": prepared.source, "applied": False, "duration_s": round(traj.duration, 3),
                     "samples": traj.samples, "period_s": rs.period, "points": len(rs.times),
                     "joints": [{"joint": j, "from": round(rs.position(j)[0]), "to": round(rs.position(j)[-1]),
                                 "peak_speed": round(max(abs(v) for v in rs.velocity(j))),
                                 "limit": cfg.joints[j].vel_limit, "start_off": prepared.start_off[j]}
                                for j in traj.joints]})
        return
    st.out.line(f"dry run: would play {prepared.source}: {len(traj.joints)} joint(s), {traj.duration:.2f} s, "
                f"{traj.samples} samples -> {len(rs.times)} points every {rs.period * 1000:g} ms (Elmo PVT)")
    for j in traj.joints:
        joint = cfg.joints[j]
        peak = max(abs(v) for v in rs.velocity(j))
        limit = f" (limit {counts_per_s_to_rad_per_s(joint.vel_limit, joint.cpr):.4f})" if joint.vel_limit else ""
        st.out.line(f"  {j}: {_pos(round(rs.position(j)[0]), joint.cpr)} -> {_pos(round(rs.position(j)[-1]), joint.cpr)}, "
                    f"peak {counts_per_s_to_rad_per_s(peak, joint.cpr):.4f} rad/s{limit}; "
                    f"starts {prepared.start_off[j]:+d} counts from where it stands")
    st.out.line("nothing sent; add --apply to play")


def _render_play(st: AppState, result: PlayResult, prepared: PreparedPlay) -> None:
    if st.json_mode:
        st.out.json({"applied": True, **result.as_json()})
        return
    for line in result.stop.lines(st.verbose):
        st.out.line(f"stop: {line}")
    s = result.stream
    if s is not None:
        st.out.line(f"played {prepared.source}: {s.periods} periods, {s.on_time_pct:.2f} % on time "
                    f"(max {s.max_lateness_s * 1000:.1f} ms late), start skew {s.skew_s * 1000:.1f} ms")
    cfg = st.load_config()
    for j, target in result.target.items():
        end = result.end.get(j)
        where = "?" if end is None else _pos(end, cfg.joints[j].cpr)
        err = "" if end is None else f"; error {end - target:+d} counts"
        st.out.line(f"  {j}: at {where}, the path's end {target} counts{err}; "
                    f"largest tracking error {result.tracking.get(j, 0)} counts")
