"""The position jog of one joint, for every drive type: a one-joint plan run by motion/run.py.

A jog ``--to``/``--by`` of a joint is the pose pipeline with one joint -- the same guard, dead-man,
limit watch, stall watch, move-time bound, recovery and stop -- so an Elmo drive and any other type
behind the drive seam (sherpa_cli/drive.py) move the same way, and ``--hold`` holds through the
pipeline's own hold. What the seam does not carry yet is refused by name for a drive that is not an
Elmo drive, before anything is sent: velocity and torque jogs, ``--hold``, a bare drive without a
joint. Velocity and torque jogs of an Elmo drive, and a bare drive's position jog, are ops/jog.py's.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from sherpa_cli.devices.drives import drive_type, is_elmo, open_drive
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.motion import calibration
from sherpa_cli.motion.plan import plan_motion
from sherpa_cli.ops.jog_result import JogProgress, JogResult

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.calibration import Calibration
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.plan import MotionPlan
    from sherpa_cli.motion.request import MoveRequest
    from sherpa_cli.motion.run import MotionOutcome
    from sherpa_cli.motion.settings import MotionSettings

HINT = "docs/cia402.md says what a drive of this type supports"


def check_seam_jog(session: ArmSession, target: Axis, req: MoveRequest) -> None:
    """What only an Elmo drive's jog does, refused before the bus is asked anything."""
    kind = drive_type(session, target.ref)
    if target.joint is None:
        raise UsageError(f"{target.name} is a {kind} drive: jog it by its joint", hint=HINT)
    if req.mode != "position":
        raise UsageError(f"{target.name}: a {req.mode} jog needs an Elmo drive; this joint's drive is a {kind} "
                         "drive, moved by --to or --by", hint=HINT)
    if req.hold:
        raise UsageError(f"{target.name}: --hold needs an Elmo drive; this joint's drive is a {kind} drive",
                         hint=HINT)


def runs_as_a_plan(session: ArmSession, target: Axis, req: MoveRequest) -> bool:
    """Whether this jog is the one-joint plan: a position jog of a joint with a speed limit (a joint
    without one, and a bare drive, move at ops/jog.py's fallback speed), or any jog of a drive that is
    not an Elmo drive (which :func:`check_seam_jog` refuses where the plan cannot carry it)."""
    if not is_elmo(session, target.ref):
        return True
    return req.mode == "position" and target.joint is not None and bool(target.vel_limit)


def in_range(target: Axis, goal: int) -> None:
    """A position jog moves a joint only inside its normal range."""
    assert target.joint is not None
    lo, hi = target.joint.normal_range
    if not lo <= goal <= hi:
        raise UsageError(f"{target.joint.name}: target {goal} counts is outside the joint's normal range "
                         f"[{lo}, {hi}]", hint="jog moves a joint only inside its normal range")


def _precheck(session: ArmSession, target: Axis, req: MoveRequest) -> Calibration:
    """A drive of another type: the goal inside the normal range, a calibrated joint (or
    ``uncalibrated``); reads only (an Elmo drive's is ops/jog.py's precheck, which re-syncs an
    absolute encoder's counter first)."""
    from sherpa_cli.bus.health import check_buses

    joint, ref = target.joint, target.ref
    assert joint is not None  # check_seam_jog
    check_buses(session, {ref.bus})
    session.client(ref).nmt_start()
    in_range(target, req.goal(open_drive(session, ref).position()))
    cal = calibration.read_calibration(session.cfg, joint, lambda _name: session.client(ref))
    if not cal.calibrated and not req.uncalibrated:
        raise SafetyError(f"{joint.name}: refusing a position move: joint {joint.name} is {cal.reason}",
                          hint="pass --uncalibrated to move by the counter as it is")
    return cal


def run_seam_jog(session: ArmSession, target: Axis, req: MoveRequest, *, settings: MotionSettings,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 on_event: Callable[[str], None] | None = None,
                 on_progress: Callable[[JogProgress], None] | None = None,
                 cal: Calibration | None = None) -> JogResult:
    """The position jog of ``target`` (see the module docstring), its result in the one JogResult.
    ``cal``: the calibration an Elmo drive's precheck read (ops/jog.py); None: read here, for a drive
    of another type."""
    from sherpa_cli.motion import hold as holding
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.report import with_report
    from sherpa_cli.motion.run import MotionOutcome, run_plan, watch_hold

    elmo = is_elmo(session, target.ref)
    if not elmo:
        check_seam_jog(session, target, req)
    if cal is None:
        cal = _precheck(session, target, req)
    joint, ref = target.joint, target.ref
    assert joint is not None  # check_seam_jog, runs_as_a_plan
    limit = target.vel_limit
    scale = 1.0 if req.speed is None or not limit else min(1.0, abs(req.speed) / limit)
    guard = MotionGuard(session, [ref], settings=settings, clock=clock, sleep=sleep, on_event=on_event)
    result = MotionOutcome()
    planned: list[MotionPlan] = []
    began: list[float] = []

    def progress(joints: Mapping[str, int]) -> None:
        if on_progress is not None and joint.name in joints:
            counts = joints[joint.name]
            on_progress(JogProgress(clock() - (began[0] if began else clock()), counts,
                                    counts_to_rad(counts, joint.cpr)))

    try:
        try:
            with guard:
                plan = _plan(guard, target, req, scale)
                planned.append(plan)
                began.append(clock())
                result = run_plan(guard, plan, settings=settings, clock=clock, sleep=sleep, on_progress=progress)
                if req.hold and result.ok:
                    watch_hold(guard, plan, result, settings=settings, clock=clock, sleep=sleep,
                               on_progress=progress)
        except KeyboardInterrupt as exc:
            holding.ended_hold(result, guard.report, exc)  # a hold's normal end; else raised again
    except BaseException as exc:
        carried = with_report(exc, guard.report)  # the CLI shows how the guard stopped the motor
        if carried is exc:
            raise
        raise carried from exc
    result.stop = guard.report
    return _result(session, target, req, planned[0], result, cal, elmo)


def _plan(guard: MotionGuard, target: Axis, req: MoveRequest, scale: float) -> MotionPlan:
    """The one-joint plan from the position read with the guard armed: the joint may have moved since
    the precheck, so a ``--by`` goal and the range are taken again from it."""
    assert target.joint is not None
    ref = target.ref
    start = guard.position(ref)
    goal = req.goal(start)
    in_range(target, goal)
    return plan_motion(guard.session.cfg, {target.joint.name: goal}, {ref.name: start}, speed_scale=scale)


def _result(session: ArmSession, target: Axis, req: MoveRequest, plan: MotionPlan, outcome: MotionOutcome,
            cal: Calibration, elmo: bool) -> JogResult:
    joint, ref = target.joint, target.ref
    assert joint is not None
    (move,) = plan.joints
    start, goal = move.start, move.target
    moved = outcome.joints.get(joint.name)
    end: int | None = moved.end_counts if moved is not None else start
    stopped = {d.drive: d.position for d in outcome.stop.drives}
    if ref.name in stopped:  # where the guard's stop found it (None: PX could not be read)
        end = stopped[ref.name]
    if outcome.breaches:
        b = outcome.breaches[0]
        ended_by = f"left its full range, brought back to {b.back_to} counts"
    else:
        ended_by = "target reached"
    if outcome.held_until:
        ended_by = outcome.held_until
    return JogResult(
        axis=target.name, kind=target.kind, mode="position", drives=(ref.name,), addresses=(ref.address,),
        cpr=target.cpr, start_counts=start, end_counts=end, target_counts=goal, speed=round(move.speed),
        command=f"PA={goal}" if elmo else f"target {goal} ({drive_type(session, ref)})",
        ended_by=ended_by, duration=outcome.duration, breaches=list(outcome.breaches),
        recovered_to=dict(outcome.recovered_to), calibrations=[cal], stop=outcome.stop,
        joints_start={joint.name: start}, joints_end={joint.name: end} if end is not None else {},
        joint_cpr={joint.name: joint.cpr}, motors_start={ref.name: start},
        motors_end={ref.name: end} if end is not None else {},
        motor_commands={d: dict(c) for d, c in outcome.motor_commands.items()},
        held_at=dict(outcome.held_at) if outcome.held_at is not None else None, held_until=outcome.held_until)
