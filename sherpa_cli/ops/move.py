"""`sherpa move POSE`: several joints to a named pose, all starting and arriving together (docs/move.md).

:func:`pose_targets` turns a pose of the config (or a mapping a script gives) into joint targets in
counts; :func:`prepare` reads where the motors stand and whether the joints are calibrated, and plans
(motion/plan.py); :func:`run_move` runs the plan in one motion guard over every motor of the move
(motion/run.py), then holds (``hold``) until Ctrl-C or `sherpa stop`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.motion import calibration
from sherpa_cli.motion.plan import (
    MotionPlan,
    check_joint_names,
    check_speed_scale,
    drives_of,
    joint_targets,
    plan_motion,
)
from sherpa_cli.motion.report import with_report
from sherpa_cli.ops.poses import pose_named

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.run import MotionOutcome

PoseTargets = Mapping[str, str | float | int]  # joint -> rad, or text with a unit ("10deg")


@dataclass(frozen=True)
class PreparedMove:
    """A planned move with what was read for it: the calibration of every joint it moves."""

    pose: str | None  # the pose's name (None: targets a script gave)
    plan: MotionPlan
    calibrations: list[calibration.Calibration] = field(default_factory=list)


def pose_targets(cfg: ArmConfig, pose: str | PoseTargets, joints: Sequence[str] | None = None) -> dict[str, int]:
    """Joint -> counts of ``pose`` (a pose of the config by name, or joint -> value), limited to
    ``joints`` when given (each must be in the pose)."""
    targets = dict(pose_named(cfg, pose).counts) if isinstance(pose, str) else joint_targets(cfg, pose)
    if joints:
        check_joint_names(cfg, joints, "--joints")
        missing = [j for j in joints if j not in targets]
        if missing:
            raise UsageError(f"--joints: {', '.join(missing)} {'is' if len(missing) == 1 else 'are'} not in the pose",
                             hint=f"the pose names {', '.join(targets)}")
        targets = {j: targets[j] for j in targets if j in joints}
    return targets


def read_motors(session: ArmSession, drives: Sequence[str]) -> dict[str, int]:
    """PX of each drive (NMT start first, as every command does); nothing else is written."""
    from sherpa_cli.bus.targets import drive_ref
    from sherpa_cli.devices.drives import open_drive

    out = {}
    for d in drives:
        ref = drive_ref(session.cfg, d)
        session.client(ref).nmt_start()
        out[d] = open_drive(session, ref).position()
    return out


def check_calibrated(session: ArmSession, joints: Sequence[str], *, uncalibrated: bool) -> list[calibration.Calibration]:
    """The calibration of every joint (a pair once); refuses one not calibrated unless ``uncalibrated``."""
    from sherpa_cli.bus.targets import drive_ref

    cfg = session.cfg
    cals: list[calibration.Calibration] = []
    seen: set[tuple[str, ...]] = set()
    for name in joints:
        joint = cfg.joints[name]
        key = calibration.joint_drives(cfg, joint)
        if key in seen:
            continue
        seen.add(key)
        cals.append(calibration.read_calibration(cfg, joint, lambda d: session.client(drive_ref(cfg, d)), resync=True))
    missing = [c for c in cals if not c.calibrated]
    if missing and not uncalibrated:
        first = missing[0]
        raise SafetyError(f"refusing the move: joint {first.joint} is {first.reason}",
                          hint="home it first, or pass --uncalibrated to move by the counter as it is "
                               "(positions are then relative to where the joint stood at power-up)")
    return cals


def prepare(session: ArmSession, pose: str | PoseTargets, *, joints: Sequence[str] | None = None,
            speed_scale: float = 1.0, uncalibrated: bool = False) -> PreparedMove:
    """Read positions and calibration, then plan; nothing is written to a drive but NMT start."""
    cfg = session.cfg
    targets = pose_targets(cfg, pose, joints)
    if not targets:
        raise UsageError("the pose names no joint")
    check_speed_scale(speed_scale)  # before the bus
    motors = read_motors(session, drives_of(cfg, list(targets)))
    cals = check_calibrated(session, list(targets), uncalibrated=uncalibrated)
    plan = plan_motion(cfg, targets, motors, speed_scale=speed_scale)
    return PreparedMove(pose if isinstance(pose, str) else None, plan, cals)


def run_move(session: ArmSession, prepared: PreparedMove, *, hold: bool = False,
             guard_factory: Callable[..., MotionGuard] | None = None,
             clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
             on_event: Callable[[str], None] | None = None,
             on_progress: Callable[[Mapping[str, int]], None] | None = None) -> MotionOutcome:
    """Run a prepared move in one motion guard over every motor it moves; ``hold``: afterwards every
    motor holds where it ended until Ctrl-C (a normal end) or `sherpa stop`. A breach is a result
    (``ok`` False); a refusal or failure raises with the guard's report attached."""
    from sherpa_cli.motion import hold as holding
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.run import MotionOutcome, run_plan, standing, watch_hold
    from sherpa_cli.motion.settings import MotionSettings

    plan = prepared.plan
    if not plan.motors:  # every joint stands at its target: no guard, nothing switched on
        return standing(plan)
    settings = MotionSettings.from_config(session.cfg, {r.bus for r in plan.refs})
    guard = (guard_factory or MotionGuard)(session, plan.refs, settings=settings, clock=clock, sleep=sleep,
                                           on_event=on_event)
    result = MotionOutcome()
    try:
        try:
            with guard:
                result = run_plan(guard, plan, settings=settings, clock=clock, sleep=sleep, on_progress=on_progress)
                if hold and result.ok:
                    watch_hold(guard, plan, result, settings=settings, clock=clock, sleep=sleep,
                               on_progress=on_progress)
        except KeyboardInterrupt as exc:
            holding.ended_hold(result, guard.report, exc)
    except BaseException as exc:
        carried = with_report(exc, guard.report)  # the CLI shows how the guard stopped the motors
        if carried is exc:
            raise
        raise carried from exc
    result.stop = guard.report
    if result.held_until:
        # the hold ended: where the guard's stop found each joint
        stopped = {d.drive: d.position for d in guard.report.drives if d.position is not None}
        _ends_from(result, plan, stopped)
    return result


def _ends_from(result: MotionOutcome, plan: MotionPlan, motors: Mapping[str, int]) -> None:
    from dataclasses import replace

    for a in plan.watched:
        if a.name in result.joints and all(d in motors for d in a.drives):
            result.joints[a.name] = replace(result.joints[a.name], end_counts=a.position(motors))
