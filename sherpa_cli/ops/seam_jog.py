"""A jog of a joint whose drive is not an Elmo drive: a one-joint plan run by motion/run.py.

The Elmo jog (ops/jog.py) speaks the interpreter; any other drive type moves through the drive
seam (sherpa_cli/drive.py) alone, and the one pipeline already does that for a pose: the jog is
that pipeline with one joint -- the same guard, dead-man, limit watch, recovery and stop. What the
seam does not carry yet is refused by name before anything is sent: velocity and torque jogs,
``--hold``, a bare drive without a joint.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from sherpa_cli.devices.drives import drive_type, open_drive
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.motion import calibration
from sherpa_cli.motion.plan import plan_motion
from sherpa_cli.ops.jog_result import JogResult

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.request import MoveRequest
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


def run_seam_jog(session: ArmSession, target: Axis, req: MoveRequest, *, settings: MotionSettings,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 on_event: Callable[[str], None] | None = None) -> JogResult:
    """The position jog of ``target`` (see the module docstring), its result in the one JogResult."""
    from sherpa_cli.bus.health import check_buses
    from sherpa_cli.ops.move import PreparedMove, run_move

    check_seam_jog(session, target, req)
    joint, ref, cfg = target.joint, target.ref, session.cfg
    assert joint is not None  # check_seam_jog
    check_buses(session, {ref.bus})
    session.client(ref).nmt_start()
    start = open_drive(session, ref).position()
    goal = req.goal(start)
    lo, hi = joint.normal_range
    if not lo <= goal <= hi:
        raise UsageError(f"{joint.name}: target {goal} counts is outside the joint's normal range [{lo}, {hi}]",
                         hint="jog moves a joint only inside its normal range")
    cal = calibration.read_calibration(cfg, joint, lambda _name: session.client(ref))
    if not cal.calibrated and not req.uncalibrated:
        raise SafetyError(f"{joint.name}: refusing a position move: joint {joint.name} is {cal.reason}",
                          hint="pass --uncalibrated to move by the counter as it is")
    limit = target.vel_limit
    scale = 1.0 if req.speed is None or not limit else min(1.0, abs(req.speed) / limit)
    plan = plan_motion(cfg, {joint.name: goal}, {ref.name: start}, speed_scale=scale)
    outcome = run_move(session, PreparedMove(None, plan, [cal]), clock=clock, sleep=sleep, on_event=on_event)
    moved = outcome.joints.get(joint.name)
    end = moved.end_counts if moved is not None else start
    stopped = {d.drive: d.position for d in outcome.stop.drives if d.position is not None}
    end = stopped.get(ref.name, end)
    speed = round(plan.joints[0].speed) if plan.joints else None
    return JogResult(
        axis=target.name, kind=target.kind, mode="position", drives=(ref.name,), addresses=(ref.address,),
        cpr=target.cpr, start_counts=start, end_counts=end, target_counts=goal, speed=speed,
        command=f"target {goal} ({drive_type(session, ref)})",
        ended_by="target reached" if outcome.ok else "left its full range",
        duration=outcome.duration, breaches=list(outcome.breaches), recovered_to=dict(outcome.recovered_to),
        calibrations=[cal], stop=outcome.stop, joints_start={joint.name: start}, joints_end={joint.name: end},
        joint_cpr={joint.name: joint.cpr}, motors_start={ref.name: start}, motors_end={ref.name: end},
        motor_commands={d: dict(c) for d, c in outcome.motor_commands.items()})
