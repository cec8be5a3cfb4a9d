"""`sherpa jog`: move one plain joint (or the drive of one) inside the motion guard (docs/motion.md).

- position: UM=5, PA=target, BG, wait for MS=0 (``--to`` absolute, ``--by`` relative to PX now)
- velocity: JV=v, BG in UM=5 (a jog) or UM=2 (``motion.velocity_unit_mode``), for T s or until Ctrl-C
- torque: UM=1, TC=A for T s (T required); no position or speed limit of the drive acts in torque
  mode (seed C.1.1/C.1.2), so the current must sit within the joint's configured limits

Only what the motion needs is written (UM only if it differs, then PA/JV/TC and BG), all in RAM.
The guard stops the motor on every way out; its report says how. Values come in joint units (rad,
rad/s, A) and are converted with the joint's cpr.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from sherpa_cli.devices.drives import is_elmo
from sherpa_cli.elmo.faults import StatusRegister, decode_sr, describe_mf
from sherpa_cli.elmo.protocol import UM_POSITION, UM_TORQUE
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.motion import hold
from sherpa_cli.motion.axis import Axis, profile_speed, speed_refusal
from sherpa_cli.motion.blocked import StallWatch, blocked_error
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.report import GuardReport, MotionInterrupted, with_report
from sherpa_cli.motion.request import MoveRequest
from sherpa_cli.motion.settings import MotionSettings, check_torque_for
from sherpa_cli.ops.jog_result import JogProgress, JogResult
from sherpa_cli.ops.seam_jog import check_seam_jog, run_seam_jog, runs_as_a_plan

__all__ = ["MODES", "JogProgress", "check_request", "precheck", "run_jog"]

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.motion.calibration import Calibration
    from sherpa_cli.motion.limit_watch import Breach

MODES = ("position", "velocity", "torque")


def check_request(target: Axis, req: MoveRequest, *, max_torque_for: float | None = None) -> None:
    """Refuse what must not reach a drive, before the bus is even opened (the request's own values
    were checked when it was parsed: motion/request.py). ``max_torque_for``: ``motion.max_torque_for``
    (default: the setting's default)."""
    if target.pair is not None:  # a Σ/Δ joint or a pair motor: ops/joint_jog.py moves those
        raise UsageError(f"'{target.name}' moves the differential pair '{target.pair.name}': jogging Σ/Δ joints is "
                         "not supported here", hint="jog a plain joint or its drive")
    if target.cpr is None and req.mode != "torque":
        raise UsageError(f"{target.name}: no plain joint of the config is driven by {target.ref.name}, so there is "
                         "no cpr to convert rad into counts", hint="name the joint, or a drive that moves a plain joint")
    joint = target.joint
    if req.mode == "position":
        if not req.relative and joint is not None:  # --by is checked once PX is known (precheck)
            goal, (lo, hi) = req.counts, joint.normal_range
            if not lo <= goal <= hi:
                raise UsageError(f"{joint.name}: target {goal} counts is outside the joint's normal range "
                                  f"[{lo}, {hi}]", hint="jog moves a joint only inside its normal range")
        if req.speed is not None:
            _check_speed(target, req.speed, "--velocity")
    elif req.mode == "velocity":
        _check_speed(target, req.velocity, "--velocity")
    elif req.mode == "torque":
        if req.duration is None:
            raise UsageError("a torque jog needs --for SECONDS: no position or speed limit of the drive acts in "
                             "torque mode, so it must end by itself")
        check_torque_for(req.duration, max_torque_for)
        current = joint.current if joint is not None else None
        if current is None:
            raise UsageError(f"{target.name}: no current limits configured for it, so no torque can be checked",
                             hint="give the joint `current: {continuous: A, peak: A, peak_time: s}`")
        assert joint is not None  # current came from the joint
        if abs(req.amps) > current.continuous:
            raise UsageError(f"--torque {req.amps} A is beyond {joint.name}'s continuous current limit "
                             f"{current.continuous} A (config current.continuous)")


def _check_speed(target: Axis, counts: int, option: str) -> None:
    refusal = speed_refusal(target, counts, option)
    if refusal is not None:
        raise refusal


def run_jog(session: ArmSession, target: Axis, req: MoveRequest, *, settings: MotionSettings,
            clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
            on_progress: Callable[[JogProgress], None] | None = None,
            on_event: Callable[[str], None] | None = None, keep: bool = False) -> JogResult:
    """Move as asked inside a MotionGuard and return where it ended; every exit path stops the motor."""
    if not is_elmo(session, target.ref):
        check_seam_jog(session, target, req)
    check_request(target, req, max_torque_for=session.cfg.motion.max_torque_for)
    if runs_as_a_plan(session, target, req) and not keep:
        # a joint's position jog, any drive type: the one pipeline (ops/seam_jog.py)
        cal = precheck(session, target, req) if is_elmo(session, target.ref) else None
        return run_seam_jog(session, target, req, settings=settings, clock=clock, sleep=sleep, on_event=on_event,
                            on_progress=on_progress, cal=cal)
    ref = target.ref
    cal = precheck(session, target, req)
    guard = MotionGuard(session, [ref], settings=settings, clock=clock, sleep=sleep, keep=keep, on_event=on_event)
    state: dict[str, Any] = {"start": None, "t0": None, "t_end": None, "target": None, "command": "",
                             "ended_by": ""}
    interrupted = False
    try:
        with guard:
            try:
                _move(guard, target, req, settings, state, clock, sleep, on_progress)
            finally:
                state["t_end"] = clock()  # the motion's time, without the guard's stop and switch-off
    except KeyboardInterrupt as exc:
        held = req.hold and state.get("holding")
        if not held and not (req.mode == "velocity" and req.duration is None and state["t0"] is not None):
            raise MotionInterrupted(guard.report) from exc  # the CLI shows how it stopped
        interrupted = True  # Ctrl-C is how an open-ended velocity jog or a hold is meant to end
        hold.ctrl_c_ends_hold(guard.report, exc)
    except BaseException as exc:
        carried = with_report(exc, guard.report)  # the CLI shows how the guard stopped the motors
        if carried is exc:
            raise
        raise carried from exc
    (stopped,) = guard.report.drives
    return _result(target, req, state, stopped.position, guard.report, cal, interrupted)


def _result(target: Axis, req: MoveRequest, state: dict[str, Any], end: int | None, report: GuardReport,
            cal: Calibration | None, interrupted: bool) -> JogResult:
    """The one jog result from what the move kept in ``state``; the joint, if any, is the only one moved."""
    ref, start = target.ref, state["start"]
    breach: Breach | None = state.get("breach")
    joint = target.joint.name if target.joint is not None else None
    held_until: str = state.get("held_until", "")
    if interrupted:  # Ctrl-C is how a hold or an open-ended velocity jog ends
        held_until = hold.HELD_UNTIL_CTRL_C if state.get("holding") else ""
    sent: dict[str, int | float] | None = state.get("motor_commands")
    return JogResult(
        axis=target.name, kind=target.kind, mode=req.mode, drives=(ref.name,), addresses=(ref.address,),
        cpr=target.cpr, start_counts=start, end_counts=end, target_counts=state["target"],
        speed=state.get("speed"), current=req.amps if req.mode == "torque" else None, for_s=req.duration,
        command=state["command"], ended_by=(held_until or "Ctrl-C") if interrupted else state["ended_by"],
        duration=state["t_end"] - state["t0"] if state["t0"] is not None else 0.0,
        breaches=[breach] if breach is not None else [],
        recovered_to={breach.joint: state["recovered_to"]} if breach is not None else {},
        calibrations=[cal] if cal is not None else [], stop=report,
        joints_start={joint: start} if joint is not None else {},
        joints_end={joint: end} if joint is not None and end is not None else {},
        joint_cpr={joint: target.cpr} if joint is not None and target.cpr is not None else {},
        motors_start={ref.name: start}, motors_end={ref.name: end} if end is not None else {},
        motor_commands={ref.name: sent} if sent is not None else {},
        held_at=state.get("held_at"), held_until=held_until)


def precheck(session: ArmSession, target: Axis, req: MoveRequest) -> Calibration | None:
    """Before anything is armed (wave/jog, docs/motion.md): a position move must stay inside the
    joint's NORMAL range and needs a calibrated joint (or ``uncalibrated``). Reads PX and the
    calibration flag; writes nothing but PX of an absolute-encoder joint whose counter restarted
    (re-synced from the encoder with the motor off, first: the goal is computed from it).
    Returns the calibration found (None for other modes)."""
    joint = target.joint
    if joint is None:
        return None
    from sherpa_cli.bus.health import check_buses
    from sherpa_cli.motion import calibration

    # the guard's bus preflight, first: a request on a BUS-OFF or missing bus is a bus problem, named
    # as one, not a drive that does not answer (the guard checks again on entry)
    check_buses(session, {target.ref.bus})

    if req.mode != "position":
        if calibration.absolute(session.cfg, joint):
            # the watch's limits read PX in every mode: a counter that restarted is re-synced first
            c = session.client(target.ref)
            c.nmt_start()
            synced = calibration.read_calibration(session.cfg, joint, lambda name: c, resync=True)
            if not synced.calibrated:
                raise SafetyError(f"{joint.name}: refusing to move: joint {joint.name} is {synced.reason}",
                                  hint="its limits are watched on the counter, which must mean the encoder")
        return None
    c = session.client(target.ref)
    c.nmt_start()
    cal = calibration.read_calibration(session.cfg, joint, lambda name: c, resync=True)
    start = int(c.get("PX"))
    goal = req.goal(start)
    lo, hi = joint.normal_range
    if not lo <= goal <= hi:
        raise UsageError(f"{joint.name}: target {goal} counts is outside the joint's normal range [{lo}, {hi}]",
                          hint="jog moves a joint only inside its normal range")
    if not cal.calibrated and not req.uncalibrated:
        raise SafetyError(f"{joint.name}: refusing a position move: joint {joint.name} is {cal.reason}",
                          hint="home it first, or pass --uncalibrated to move by the counter as it is "
                               "(positions are then relative to where the joint stood at power-up)")
    return cal


def _move(guard: MotionGuard, target: Axis, req: MoveRequest, settings: MotionSettings, state: dict[str, Any],
          clock: Callable[[], float], sleep: Callable[[float], None],
          on_progress: Callable[[JogProgress], None] | None) -> None:
    ref = target.ref
    c = guard.client(ref)
    start = int(c.get("PX"))
    state["start"] = start

    def watch(done: Callable[[StatusRegister], bool] | None, limit: float | None,
              stall: StallWatch | None = None) -> None:
        _watch(guard, c, target, clock, sleep, settings, state, on_progress, done=done, limit=limit, stall=stall)

    if req.mode == "position":
        goal = req.goal(start)
        if target.joint is not None:  # again with this PX: the joint may have moved since precheck
            lo, hi = target.joint.normal_range
            if not lo <= goal <= hi:
                raise UsageError(f"{target.joint.name}: target {goal} counts is outside the joint's normal range "
                                 f"[{lo}, {hi}]", hint="jog moves a joint only inside its normal range")
        state["target"] = goal
        guard.enable(ref, UM_POSITION)
        # the speed comes from the config, never from whatever SP the drive holds (an unprogrammed
        # drive: 1800 counts/s); the guard puts SP back on the way out
        speed = profile_speed(target, settings.recovery_fallback_speed, req.speed)
        with guard.motor_off_explains_failure([ref], "the jog"):
            c.set("SP", 0, speed)
            bound = _move_bound(c, target, abs(goal - start), speed)
            c.set("PA", 0, goal)
        state["command"] = f"PA={goal}"
        state["speed"], state["motor_commands"] = speed, {"PA": goal, "SP": speed}
        state["t0"] = clock()
        c.execute("BG")
        watch(lambda sr: sr.motion_status == 0, bound, settings.stall_watch(speed))
        state["ended_by"] = state["ended_by"] or "target reached"
    elif req.mode == "velocity":
        v = req.velocity
        guard.enable(ref, settings.velocity_unit_mode)
        with guard.motor_off_explains_failure([ref], "the jog"):
            c.set("JV", 0, v)
        state["command"] = f"JV={v}"
        state["speed"], state["motor_commands"] = v, {"JV": v}
        state["t0"] = clock()
        c.execute("BG")
        watch(None, req.duration, settings.stall_watch(abs(v)))
        state["ended_by"] = state["ended_by"] or "time up"
    elif req.mode == "torque":
        guard.enable(ref, UM_TORQUE)  # TC=0 before MO=1: no old torque command is applied
        c.set("TC", 0, req.amps)
        state["command"] = f"TC={req.amps:g}"
        state["motor_commands"] = {"TC": req.amps}
        state["t0"] = clock()
        watch(None, req.duration, settings.torque_stall_watch())
        state["ended_by"] = state["ended_by"] or "time up"
    if req.hold and not state.get("breach"):
        _hold(guard, c, target, req, settings, state, clock, sleep, on_progress)


def _hold(guard: MotionGuard, c: DriveClient, target: Axis, req: MoveRequest, settings: MotionSettings,
          state: dict[str, Any], clock: Callable[[], float], sleep: Callable[[float], None],
          on_progress: Callable[[JogProgress], None] | None) -> None:
    """--hold: stop a velocity or torque motion from standstill, then keep the motor on in position
    mode holding where it stands (the dead-man still armed, the limit watch still on) until Ctrl-C
    ends it (a normal end) or the motor is switched off (`sherpa stop`: also a normal end)."""
    ref = target.ref
    if req.mode != "position":
        here = hold.hold_in_place(guard, [ref], settings=settings, clock=clock, sleep=sleep)[ref.name]
        state["command"] += f", then held at PA={here}"
        state["held_at"] = {ref.name: here}
    else:  # a move holds where it was sent, in the mode it moved in
        state["held_at"] = {ref.name: state["target"]}
    state["holding"] = True

    def watch() -> bool:
        px = int(guard.query(ref, "PX"))
        if on_progress is not None:
            on_progress(JogProgress(clock() - state["t0"], px, counts_to_rad(px, target.cpr) if target.cpr else None))
        return target.joint is not None and limit_breach(guard, c, target, px, settings, clock, sleep, state)

    ended = hold.hold_until_released(guard, [ref], settings=settings, sleep=sleep, watch=watch)
    if ended is not None:
        state["ended_by"] = state["held_until"] = ended


def _move_bound(c: DriveClient, target: Axis, distance: int, speed: int) -> float:
    """The one move-time bound (motion/axis.py) at the speed set, with the ramps the drive will use."""
    return target.move_time_bound(distance, speed, accel=abs(int(c.get("AC"))) or None,
                                  decel=abs(int(c.get("DC"))) or None)


def _watch(guard: MotionGuard, c: DriveClient, target: Axis, clock: Callable[[], float], sleep: Callable[[float], None],
           settings: MotionSettings, state: dict[str, Any], on_progress: Callable[[JogProgress], None] | None,
           *, done: Callable[[StatusRegister], bool] | None, limit: float | None,
           stall: StallWatch | None = None) -> None:
    """Poll PX and SR until ``done(sr)`` or ``limit`` s (a time-up for velocity/torque, a failure for a
    move); ``stall``: no progress for the stall time ends it as blocked, naming an active end switch."""
    t0 = state["t0"]
    while True:
        guard.check()
        px = int(guard.query(target.ref, "PX"))
        sr = decode_sr(int(guard.query(target.ref, "SR")))
        elapsed = clock() - t0
        if on_progress is not None:
            on_progress(JogProgress(elapsed, px, counts_to_rad(px, target.cpr) if target.cpr else None))
        if target.joint is not None and limit_breach(guard, c, target, px, settings, clock, sleep, state):
            return
        if not sr.motor_on:
            mf = int(guard.query(target.ref, "MF"))
            why = "; ".join(describe_mf(mf)) if mf else "MO=0 from elsewhere (sherpa stop, another tool)"
            raise SafetyError(f"{c.label}: the motor was switched off during the jog: {why}")
        if done is not None and done(sr):
            return
        if stall is not None and stall.feed({target.ref.name: px}, clock()):
            if done is not None:  # a move: stopped from elsewhere is not blocked
                guard.explain_stall([target.ref], "the jog")
            raise blocked_error(guard.session.cfg, {target.ref.name: c}, [target.ref.name], settings.stall_time,
                                who=c.label, at=f"at {px} counts")
        if limit is not None and elapsed >= limit:
            if done is not None:
                raise SafetyError(f"{c.label}: the move did not reach its target within {limit:.1f} s "
                                  f"(at {px} counts)", hint="check SP/AC/DC and what blocks the joint (SR, IP)")
            return
        sleep(settings.poll_interval if limit is None else min(settings.poll_interval, max(limit - elapsed, 0.0)))


def limit_breach(guard: MotionGuard, c: DriveClient, target: Axis, px: int, settings: MotionSettings,
                  clock: Callable[[], float], sleep: Callable[[float], None], state: dict[str, Any]) -> bool:
    """The joint-limit watch (seed 6.1, motion/limit_watch.py): past the full range, the one recovery
    (motion/recovery.py): stop at once, nothing more of the jog, standstill, then back (position
    mode) to the nearest normal edge at motion.recovery_speed."""
    from sherpa_cli.motion import limit_watch, recovery

    breaches = limit_watch.check(target.watched, {target.ref.name: px})
    if not breaches:
        return False
    ref = target.ref
    recovery.recover(guard, {ref.name: ref}, {ref.name: c}, target.watched, breaches,
                     lambda: {ref.name: int(c.get("PX"))}, settings=settings, clock=clock, sleep=sleep,
                     torque=guard.unit_mode(ref) == UM_TORQUE, speed=recovery.recovery_speed(settings, [target]))
    state["breach"] = breaches[0]
    state["recovered_to"] = int(c.get("PX"))
    state["ended_by"] = f"left its full range, brought back to {breaches[0].back_to} counts"
    return True
