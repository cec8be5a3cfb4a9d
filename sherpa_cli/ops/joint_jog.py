"""Jogging the Σ or Δ joint of a differential pair, or one motor of a pair, inside the motion guard,
with the joint-limit watch (docs/motion.md). Plain joints go through ops/jog.py, which uses the same
watch (motion/limit_watch.py), normal-range and calibration checks.

What a jog means per kind of axis (joints/diffpair.py for the transform):

- Σ joint: both motors move through the inverse transform; Δ holds (its target is its current
  value). Position: ``m_a = (Σ'+Δ)/2``, ``m_b = (Σ'-Δ)/2`` (when Σ' and Δ differ in parity, Δ gives
  way by one count); speed: both motors at vΣ/2; current: both motors at IΣ.
- Δ joint: likewise with Σ holding; speed ±vΔ/2, current ±IΔ.
- one motor of a pair (its drive name or BUS:NODE): that motor alone, in motor counts; it moves Σ and Δ
  together, so the target must keep both inside their normal ranges.

Position moves use equal-duration profiles: each motor's SP is its share of the distance, so
both motors start and arrive together and the held joint does not drift (seed Fig. 9.10/9.11).

Everything that can be refused is refused before the guard arms anything: a name that is not a
pair joint or pair motor, a position outside the joint's NORMAL range, a speed above the joint's limit, a current
above the configured continuous limit, a velocity or torque jog without a time limit, and a
position move of a joint that is not calibrated (motion/calibration.py) unless ``uncalibrated``.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.elmo.protocol import UM_POSITION, UM_TORQUE
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.motion import calibration, hold, limit_watch, recovery
from sherpa_cli.motion.axis import Axis, move_time_bound, profile_speed, speed_refusal
from sherpa_cli.motion.blocked import blocked_error
from sherpa_cli.motion.report import with_report
from sherpa_cli.motion.request import Mode, MoveRequest
from sherpa_cli.motion.settings import check_torque_for
from sherpa_cli.ops.jog_result import JogResult, letters

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

Range = tuple[int, int]


@dataclass(frozen=True)
class JogPlan:
    """Motor commands for one jog (pure result of :func:`plan`)."""

    axis: Axis
    mode: Mode
    start: int  # axis position at the start (counts)
    target: int | None = None  # position moves: where the axis ends
    speed: int | None = None  # counts/s of the axis
    current: float | None = None  # A
    duration: float | None = None
    motor_targets: Mapping[str, int] = field(default_factory=dict)
    motor_speeds: Mapping[str, int] = field(default_factory=dict)  # SP (position) or JV (velocity)
    motor_currents: Mapping[str, float] = field(default_factory=dict)
    timeout: float | None = None  # position moves: the bound on arriving


def _fmt_range(r: Range) -> str:
    return f"[{r[0]}, {r[1]}]"


def _check_speed(axis: Axis, speed: int, what: str) -> None:
    if speed == 0:
        raise UsageError(f"{what} must not be 0")
    refusal = speed_refusal(axis, speed, what)
    if refusal is not None:
        raise refusal


def plan(cfg: ArmConfig, axis: Axis, request: MoveRequest, motors: Mapping[str, int]) -> JogPlan:
    """Motor commands for ``request`` from the motors' present positions; refuses what is unsafe."""
    start = axis.position(motors)
    if request.mode == "position":
        return _plan_position(cfg, axis, request, motors, start)
    if request.duration is None:
        raise UsageError(f"a {request.mode} jog needs --for SECONDS: it must end by itself"
                         + (" (in torque mode no drive limit acts; the time limit is the last guard)"
                            if request.mode == "torque" else ""),
                         hint=f"e.g. sherpa jog {axis.name} --{request.mode} ... --for 1")
    if request.mode == "velocity":
        v = request.velocity
        _check_speed(axis, v, "--velocity")
        return JogPlan(axis, "velocity", start, speed=v, duration=request.duration,
                       motor_speeds=axis.motor_velocities(v))
    if request.duration is not None:
        check_torque_for(request.duration, cfg.motion.max_torque_for)
    amps = request.amps
    if amps == 0:
        raise UsageError("--torque must not be 0")
    currents = axis.motor_currents(amps)
    worst = max(abs(c) for c in currents.values())
    if axis.current_limit is not None and worst > axis.current_limit:
        raise UsageError(f"{axis.name}: --torque {amps:g} A puts {worst:g} A on a motor, above the configured "
                          f"continuous limit {axis.current_limit:g} A")
    return JogPlan(axis, "torque", start, current=amps, duration=request.duration, motor_currents=currents)


def _plan_position(cfg: ArmConfig, axis: Axis, request: MoveRequest, motors: Mapping[str, int],
                   start: int) -> JogPlan:
    target = request.goal(start)
    if axis.normal is not None and not axis.normal[0] <= target <= axis.normal[1]:
        raise UsageError(f"{axis.name}: target {target} counts is outside the joint's normal range "
                          f"{_fmt_range(axis.normal)}", hint="jog moves a joint only inside its normal range")
    targets = _motor_targets(axis, target, motors)
    if axis.kind == "motor":
        after = {**motors, **targets}
        for j in axis.watched:
            p = j.position(after)
            if j.normal is not None and not j.inside_normal(p):
                raise UsageError(f"{axis.name}: moving this motor to {target} puts joint {j.name} at {p} counts, "
                                  f"outside its normal range {_fmt_range(j.normal)}")
    if request.speed is not None:
        speed = request.speed
        _check_speed(axis, speed, "--velocity")
    elif axis.vel_limit is not None:
        speed = axis.vel_limit
    else:
        raise UsageError(f"{axis.name} has no velocity.limit in the config: give --velocity for the move")
    distance = abs(target - start)
    duration = distance / speed if distance else 0.0
    sp = {d: (max(1, math.ceil(abs(t - motors[d]) / duration)) if duration else speed)
          for d, t in targets.items()}
    timeout = move_time_bound(distance, speed)  # the one bound (motion/axis.py)
    return JogPlan(axis, "position", start, target=target, speed=speed, motor_targets=targets, motor_speeds=sp,
                   timeout=timeout)


def _motor_targets(axis: Axis, target: int, motors: Mapping[str, int]) -> dict[str, int]:
    held = next((j for j in axis.watched if j.name != axis.name and j.drive_b is not None), None)
    return axis.motor_targets(target, motors, held.normal if held is not None else None)


def check_offline(cfg: ArmConfig, axis: Axis, request: MoveRequest) -> JogPlan | None:
    """Every refusal that needs no bus (a dry run's checks): the whole plan for velocity and torque
    jogs (they do not depend on where the motors stand), the values and the --to range for a move."""
    zero = {d: 0 for d in axis.sensed}
    if request.mode != "position":
        return plan(cfg, axis, request, zero)
    if not request.relative:
        return plan(cfg, axis, request, zero) if axis.kind != "motor" else None
    if request.speed is not None:
        _check_speed(axis, request.speed, "--velocity")
    return None


# --------------------------------------------------------------------------- running it

def _refs(cfg: ArmConfig, drives: tuple[str, ...]) -> list[DriveRef]:
    return [DriveRef(d, cfg.drives[d].bus, cfg.drives[d].node, cfg.drives[d]) for d in drives]


def prepare(session: ArmSession, axis: Axis, request: MoveRequest
            ) -> tuple[JogPlan, dict[str, int], list[calibration.Calibration]]:
    """Read positions (and calibration), then plan; nothing is written to a drive here but NMT start."""
    cfg = session.cfg
    refs = _refs(cfg, axis.sensed)
    clients = {r.name: session.client(r) for r in refs}
    for c in clients.values():
        c.nmt_start()
    motors = {d: int(c.get("PX")) for d, c in clients.items()}
    p = plan(cfg, axis, request, motors)
    cals: list[calibration.Calibration] = []
    if request.mode == "position":
        seen: set[tuple[str, ...]] = set()
        for joint in axis.joints:
            key = calibration.joint_drives(cfg, joint)
            if key in seen:
                continue
            seen.add(key)
            cals.append(calibration.read_calibration(cfg, joint, lambda d: clients[d], resync=True))
        missing = [c for c in cals if not c.calibrated]
        if missing and not request.uncalibrated:
            first = missing[0]
            raise SafetyError(f"{axis.name}: refusing a position move: joint {first.joint} is {first.reason}",
                              hint="home it first, or pass --uncalibrated to move by the counter as it is "
                                   "(positions are then relative to where the joint stood at power-up)")
    return p, motors, cals


def run(session: ArmSession, axis: Axis, request: MoveRequest, *,
        guard_factory: Callable[..., MotionGuard] | None = None,
        clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
        on_event: Callable[[str], None] | None = None,
        on_progress: Callable[[Mapping[str, int]], None] | None = None) -> JogResult:
    """Plan, then run the jog inside the motion guard with the limit watch; the guard stops every
    motor on the way out. A breach stops the jog at once and brings the joint back (position mode)
    to the nearest edge of its normal range; the result says so (``ok`` False). ``on_progress``
    gets the watched joints' positions (counts) at every sample. ``request.hold``: after the move
    every motor holds where it stands (motion/hold.py) until Ctrl-C or `sherpa stop`, both normal ends."""
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

    cfg = session.cfg
    p, motors, cals = prepare(session, axis, request)
    refs = _refs(cfg, axis.drives)
    by_name = {r.name: r for r in refs}
    settings = MotionSettings.from_config(cfg, {r.bus for r in refs})
    factory = guard_factory or MotionGuard
    joints_start = {j.name: j.position(motors) for j in axis.watched}
    result = JogResult(axis=axis.name, kind=axis.kind, mode=p.mode, drives=axis.drives,
                       addresses=tuple(by_name[d].address for d in axis.drives), cpr=axis.joint_cpr,
                       start_counts=p.start, end_counts=p.start, target_counts=p.target, speed=p.speed,
                       current=p.current, for_s=p.duration, joints_start=joints_start, motors_start=dict(motors),
                       calibrations=cals, joint_cpr={j.name: cfg.joints[j.name].cpr for j in axis.watched})
    guard = factory(session, refs, settings=settings, clock=clock, sleep=sleep, on_event=on_event)
    try:
        final = _run_guarded(guard, session, cfg, axis, p, by_name, settings, joints_start, result, clock, sleep,
                             on_progress, request.hold)
    except BaseException as exc:
        carried = with_report(exc, guard.report)  # the CLI shows how the guard stopped the motors
        if carried is exc:
            raise
        raise carried from exc
    # the guard stopped every motor (ST, MO=0) and put back what it changed
    result.motors_end = final
    result.joints_end = {j.name: j.position(final) for j in axis.watched}
    result.end_counts = axis.position(final)
    result.stop = guard.report
    result.command = letters(result.motor_commands)
    result.ended_by = _ended_by(result)
    return result


def _ended_by(result: JogResult) -> str:
    """How the jog ended, in the words of a plain joint's jog."""
    if result.breaches:
        return f"left its full range, brought back to {result.breaches[0].back_to} counts"
    if result.held_until:
        return result.held_until
    return "target reached" if result.mode == "position" else "time up"


def _run_guarded(guard: MotionGuard, session: ArmSession, cfg: ArmConfig, axis: Axis, p: JogPlan,
                 by_name: Mapping[str, DriveRef], settings: MotionSettings, joints_start: Mapping[str, int], result: JogResult,
                 clock: Callable[[], float], sleep: Callable[[float], None],
                 on_progress: Callable[[Mapping[str, int]], None] | None = None,
                 hold_after: bool = False) -> dict[str, int]:
    """The jog inside the guard, then (``hold_after``, no breach) the hold; a Ctrl-C that ends the
    hold is a normal end, the positions then read from the guard's stop report."""
    try:
        with guard:
            final = _move_guarded(guard, session, cfg, axis, p, by_name, settings, joints_start, result, clock,
                                  sleep, on_progress, hold_after)
    except KeyboardInterrupt as exc:
        stopped = hold.ended_hold(result, guard.report, exc)
        final = {d: _px_after(session, cfg, d, stopped.get(d)) for d in axis.sensed}
    return final


def _px_after(session: ArmSession, cfg: ArmConfig, drive: str, known: int | None) -> int:
    """Where a motor stands after the guard's exit: its stop report's PX, else read again."""
    if known is not None:
        return known
    (ref,) = _refs(cfg, (drive,))
    return int(session.client(ref).get("PX"))


def _move_guarded(guard: MotionGuard, session: ArmSession, cfg: ArmConfig, axis: Axis, p: JogPlan,
                  by_name: Mapping[str, DriveRef], settings: MotionSettings, joints_start: Mapping[str, int],
                  result: JogResult, clock: Callable[[], float], sleep: Callable[[float], None],
                  on_progress: Callable[[Mapping[str, int]], None] | None, hold_after: bool) -> dict[str, int]:
    from sherpa_cli.motion import pair_start

    began: float | None = None  # the start command: what the result's duration counts from
    try:
        with contextlib.ExitStack() as stack:
            clients = {d: guard.client(by_name[d]) for d in axis.drives}
            # a Σ/Δ joint starts both motors together, as `diffdrive move` does (motion.pair_start)
            method = pair_start.pair_settings(cfg)[0] if axis.kind in ("sigma", "delta") else "sequential"
            refs = [by_name[d] for d in axis.drives]
            start = stack.enter_context(pair_start.CommonStart(session, refs, clients, method, cfg.motion.pair_group_id,
                                                              stop=pair_start.stop_motors(guard, refs, settings),
                                                              reset_comm=pair_start.group_reset(guard, cfg)))

            def check_drives() -> None:
                """The guard's sign of life, and every moving motor still on (a trip ends the jog)."""
                guard.check_motors_on([by_name[d] for d in clients], "the jog")
            others = {r.name: session.client(r) for r in _refs(cfg, axis.sensed) if r.name not in clients}

            def sample() -> dict[str, int]:
                # guarded drives through guard.query: it waits out a drive deaf in its MO settle window
                # (`sherpa stop` from another terminal), so the jog ends with the reason, not a timeout
                motors = {d: int(guard.query(by_name[d], "PX")) for d in clients}
                motors.update((d, int(c.get("PX"))) for d, c in others.items())
                if on_progress is not None:
                    on_progress({j.name: j.position(motors) for j in axis.watched})
                return {d: motors[d] for d in axis.sensed}

            um = UM_TORQUE if p.mode == "torque" else (settings.velocity_unit_mode if p.mode == "velocity"
                                                       else UM_POSITION)
            for d in axis.drives:
                guard.enable(by_name[d], um)
            if p.mode == "position":
                with guard.motor_off_explains_failure([by_name[d] for d in clients], "the jog"):
                    for d, c in clients.items():
                        c.set("SP", 0, p.motor_speeds[d])
                        c.set("PA", 0, p.motor_targets[d])
                result.motor_commands = {d: {"PA": p.motor_targets[d], "SP": p.motor_speeds[d]} for d in axis.drives}
                start.begin()
                began = clock()
                watched = limit_watch.watch(
                    axis.watched, sample, clock=clock, sleep=sleep, interval=settings.poll_interval,
                    finished=lambda m: all(int(c.get("MS")) == 0 for c in clients.values()), duration=p.timeout,
                    check_drives=check_drives, stall=settings.stall_watch(max(p.motor_speeds.values(), default=0)))
                if watched.outcome == "elapsed":
                    raise SafetyError(f"{axis.name}: did not reach {p.target} within {p.timeout:g} s "
                                      f"(stopped at {axis.position(watched.motors)})",
                                      hint="check the drives with `sherpa monitor --once`")
            elif p.mode == "velocity":
                with guard.motor_off_explains_failure([by_name[d] for d in clients], "the jog"):
                    for d, c in clients.items():
                        c.set("JV", 0, p.motor_speeds[d])
                result.motor_commands = {d: {"JV": p.motor_speeds[d]} for d in axis.drives}
                start.begin()
                began = clock()
                watched = limit_watch.watch(axis.watched, sample, clock=clock, sleep=sleep,
                                            interval=settings.poll_interval, duration=p.duration,
                                            check_drives=check_drives,
                                            stall=settings.stall_watch(max(map(abs, p.motor_speeds.values()),
                                                                           default=0)))
            else:
                result.motor_commands = {d: {"TC": p.motor_currents[d]} for d in axis.drives}
                with guard.motor_off_explains_failure([by_name[d] for d in clients], "the jog"):
                    for d, c in clients.items():
                        c.set("TC", 0, p.motor_currents[d])
                began = clock()  # a current acts once it is set
                watched = limit_watch.watch(axis.watched, sample, clock=clock, sleep=sleep,
                                            interval=settings.poll_interval, duration=p.duration,
                                            check_drives=check_drives, stall=settings.torque_stall_watch())
            if watched.outcome == "stalled":
                raise blocked_error(session.cfg, clients, axis.drives, settings.stall_time, who=axis.name,
                                    at=f"at {axis.position(watched.motors)} counts")
            held = {j.name: joints_start[j.name] for j in axis.watched
                    if axis.kind in ("sigma", "delta") and j.name != axis.name and j.drive_b is not None}
            if watched.outcome == "breach":
                result.breaches = list(watched.breaches)
                recovery.recover(guard, by_name, clients, axis.watched, watched.breaches, sample, settings=settings,
                                 clock=clock, sleep=sleep, torque=p.mode == "torque", hold=held,
                                 speed=recovery.recovery_speed(settings, [axis, *axis.watched]))
                final = sample()
                result.recovered_to = {j.name: j.position(final) for j in axis.watched}
            else:
                if p.mode != "position":
                    recovery.stop_now(clients, p.mode, settings.stop_method)
                    recovery.wait_standstill(clients, settings, clock, sleep, guard.check,
                                             before="the correction of the held joint")
                final = sample()
                if held and p.mode != "position":
                    # start and stop skew between the two motors shifts the held joint a little (seed
                    # Fig. 9.10/9.11): put it back, keeping the moved joint where it ended
                    final = _restore_held(guard, by_name, clients, axis, final, held, settings, clock, sleep, result)
        # held after the pair start's exit: its stop frames (ST) went out and its RAM is back
        if hold_after and not result.breaches:
            final = _hold(guard, axis, by_name, clients, sample, held, settings, clock, sleep, result)
    finally:
        result.duration = clock() - began if began is not None else 0.0
    return final


def _hold(guard: MotionGuard, axis: Axis, by_name: Mapping[str, DriveRef], clients: Mapping[str, DriveClient],
          sample: Callable[[], dict[str, int]], held: Mapping[str, int], settings: MotionSettings,
          clock: Callable[[], float], sleep: Callable[[float], None], result: JogResult) -> dict[str, int]:
    """--hold: every motor of the jog holds where it stands (motion/hold.py), the limit watch of the
    Σ/Δ joints on, until Ctrl-C (raised) or `sherpa stop`."""
    refs = [by_name[d] for d in axis.drives]
    result.held_at = hold.hold_in_place(guard, refs, settings=settings, clock=clock, sleep=sleep, stop=False)

    def watch() -> bool:
        motors = sample()  # shows the joints (on_progress)
        breaches = limit_watch.check(axis.watched, motors)
        if not breaches:
            return False
        result.breaches = list(breaches)
        recovery.recover(guard, by_name, clients, axis.watched, breaches, sample, settings=settings, clock=clock,
                         sleep=sleep, hold=held, speed=recovery.recovery_speed(settings, [axis, *axis.watched]))
        result.recovered_to = {j.name: j.position(sample()) for j in axis.watched}
        return True

    result.held_until = hold.hold_until_released(guard, refs, settings=settings, sleep=sleep, watch=watch) or ""
    return sample()


def _slow(axis: Axis, settings: MotionSettings) -> int:
    """The held joint's correction: half the speed of a move (motion/axis.profile_speed)."""
    return max(1, profile_speed(axis, settings.recovery_fallback_speed) // 2)


def _restore_held(guard: MotionGuard, by_name: Mapping[str, DriveRef], clients: Mapping[str, DriveClient],
                  axis: Axis, now: dict[str, int], held: Mapping[str, int], settings: MotionSettings, clock: Callable[[], float],
                  sleep: Callable[[float], None], result: JogResult) -> dict[str, int]:
    (name, value), = held.items()
    a, b = axis.drives
    s, d = now[a] + now[b], now[a] - now[b]
    if (d if axis.kind == "sigma" else s) == value:
        return now
    # the held joint's own axis to its value, the moved joint giving way by a count on a parity clash
    (other,) = [j for j in axis.watched if j.name == name]
    targets = other.motor_targets(value, now)
    result.held_correction = {name: {"from": (d if axis.kind == "sigma" else s), "to": value}}
    recovery.move_to(guard, by_name, clients, targets, _slow(axis, settings), settings, clock, sleep,
                     f"the correction of the held joint {name}")
    return {**now, **{dr: int(c.get("PX")) for dr, c in clients.items()}}
