"""A motion session: one motion guard armed for several moves of a few joints (`Arm.motion`, docs/api.md).

``with arm.motion(["elbow_pitch", "wrist_1"]) as m:`` checks the joints' calibration and arms one
guard (fault check, dead-man on every bus, lock) over every motor of the joints; then

- :meth:`MotionSession.move_to` moves the named joints together (motion/plan.py, motion/run.py:
  every joint starts and arrives together, the limit watch on);
- :meth:`MotionSession.velocity` runs joints at speeds for a time, then stops them from standstill;
- :meth:`MotionSession.hold` stops and holds every motor where it stands (position mode);
- :meth:`MotionSession.stop` stops every motor and waits for standstill (the motors stay on).

Leaving the block stops every motor from standstill, switches it off and puts back what was
changed, as every command does; :attr:`MotionSession.report` then says how.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Literal

from sherpa_cli.errors import UsageError
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.motion import limit_watch, recovery
from sherpa_cli.motion.axis import Axis, speed_refusal
from sherpa_cli.motion.plan import check_joint_names, drives_of, joint_axes, joint_targets, plan_motion
from sherpa_cli.motion.report import GuardReport
from sherpa_cli.motion.run import JointOutcome, MotionOutcome, run_plan

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

Position = str | float | int  # rad, or text with a unit ("10deg", "1200counts")


class MotionSession:
    """See the module docstring. Build it with ``Arm.motion``; use it as a context manager."""

    def __init__(self, session: ArmSession, joints: Sequence[str], *, uncalibrated: bool = False,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 on_event: Callable[[str], None] | None = None) -> None:
        from sherpa_cli.bus.targets import drive_ref
        from sherpa_cli.motion.settings import MotionSettings

        cfg = session.cfg
        if isinstance(joints, str):
            joints = [joints]
        if not joints:
            raise UsageError("a motion session needs at least one joint")
        check_joint_names(cfg, joints)
        self.joints: tuple[str, ...] = tuple(dict.fromkeys(joints))
        self._session, self._uncalibrated = session, uncalibrated
        self._clock, self._sleep, self._on_event = clock, sleep, on_event
        self._axes: dict[str, Axis] = {a.name: a for a in joint_axes(cfg, self.joints)}
        self._refs: list[DriveRef] = [drive_ref(cfg, d) for d in drives_of(cfg, self.joints)]
        self.settings: MotionSettings = MotionSettings.from_config(cfg, {r.bus for r in self._refs})
        self._guard: MotionGuard | None = None
        self.report = GuardReport()

    # -- the block --------------------------------------------------------------------------------

    def __enter__(self) -> MotionSession:
        from sherpa_cli.motion.guard import MotionGuard
        from sherpa_cli.ops.move import check_calibrated, read_motors

        read_motors(self._session, [r.name for r in self._refs])  # NMT start: the drives answer the checks
        check_calibrated(self._session, self.joints, uncalibrated=self._uncalibrated)
        guard = MotionGuard(self._session, self._refs, settings=self.settings, clock=self._clock, sleep=self._sleep,
                            on_event=self._on_event)
        guard.__enter__()
        self._guard = guard
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        guard, self._guard = self._require(), None
        try:
            guard.__exit__(exc_type, exc, tb)
        finally:
            self.report = guard.report
        if exc is not None:
            from sherpa_cli.motion.report import with_report

            carried = with_report(exc, guard.report)
            if carried is not exc:
                raise carried from exc
        return False

    def _require(self) -> MotionGuard:
        if self._guard is None:
            raise UsageError("the motion session is not open: use it as `with arm.motion([...]) as m:`")
        return self._guard

    # -- moves ------------------------------------------------------------------------------------

    def _named(self, values: Mapping[str, Position] | Position, what: str) -> Mapping[str, Position]:
        if isinstance(values, Mapping):
            stray = [j for j in values if j not in self._axes]
            if stray:
                raise UsageError(f"{what}: {', '.join(stray)} {'is' if len(stray) == 1 else 'are'} not a joint of "
                                 f"this motion session ({', '.join(self.joints)})")
            return values
        if len(self.joints) != 1:
            raise UsageError(f"{what}: this session moves {len(self.joints)} joints: give a mapping joint -> value",
                             hint=f"e.g. {{{', '.join(repr(j) + ': 0.0' for j in self.joints)}}}")
        return {self.joints[0]: values}

    def _motors(self) -> dict[str, int]:
        guard = self._require()
        return {r.name: int(guard.query(r, "PX")) for r in self._refs}

    def move_to(self, targets: Mapping[str, Position] | Position, *, speed_scale: float = 1.0,
                on_progress: Callable[[Mapping[str, int]], None] | None = None) -> MotionOutcome:
        """Move the named joints (a session of one joint: a value alone) to their targets, all starting
        and arriving together. A breach is a result (``ok`` False, the joint brought back)."""
        guard = self._require()
        counts = joint_targets(self._session.cfg, self._named(targets, "move_to"))
        plan = plan_motion(self._session.cfg, counts, self._motors(), speed_scale=speed_scale)
        result = run_plan(guard, plan, settings=self.settings, clock=self._clock, sleep=self._sleep,
                          on_progress=on_progress)
        result.stop = guard.report
        return result

    def velocity(self, speeds: Mapping[str, Position] | Position, *, for_: float,
                 on_progress: Callable[[Mapping[str, int]], None] | None = None) -> MotionOutcome:
        """Run the named joints at ``speeds`` (rad/s, or text: "5deg/s", "300counts/s") for ``for_``
        seconds, the limit watch on, then stop them from standstill (the motors stay on)."""
        from sherpa_cli.joints.diffpair import motor_velocities
        from sherpa_cli.joints.units import parse_velocity, rad_per_s_to_counts_per_s

        guard = self._require()
        if not (math.isfinite(for_) and for_ > 0):
            raise UsageError(f"velocity: for_={for_!r}: expected a time > 0 s")
        cfg = self._session.cfg
        named = self._named(speeds, "velocity")
        rates: dict[str, int] = {}
        for name, value in named.items():
            axis = self._axes[name]
            v = parse_velocity(value, axis.joint_cpr, what=name) if isinstance(value, str) else \
                rad_per_s_to_counts_per_s(float(value), axis.joint_cpr)
            refusal = speed_refusal(axis, v, "the velocity")
            if refusal is not None:
                raise refusal
            rates[name] = v
        # motor speeds: a plain joint's is its own; a pair's from its Σ and Δ rates together
        jv: dict[str, int] = {}
        for name, v in rates.items():
            axis = self._axes[name]
            if axis.drive_b is None:
                jv[axis.drive_a] = v
        for pair in cfg.pairs.values():
            s, d = rates.get(pair.sigma, 0), rates.get(pair.delta, 0)
            if s or d:
                jv[pair.drive_a], jv[pair.drive_b] = motor_velocities(s, d)
        refs = [r for r in self._refs if r.name in jv]
        clients = {r.name: guard.client(r) for r in refs}
        by_name = {r.name: r for r in refs}
        watched = tuple(a for axis in self._axes.values() for a in axis.watched)
        watched = tuple({a.name: a for a in watched}.values())
        before = self._motors()
        for r in refs:
            guard.enable(r, self.settings.velocity_unit_mode)
        with guard.motor_off_explains_failure(refs, "the velocity move"):
            for r in refs:
                clients[r.name].set("JV", 0, jv[r.name])
        for r in refs:
            clients[r.name].execute("BG")
        t0 = self._clock()

        def sample() -> dict[str, int]:
            motors = self._motors()
            if on_progress is not None:
                on_progress({a.name: a.position(motors) for a in watched})
            return motors

        result = MotionOutcome()
        w = limit_watch.watch(watched, sample, clock=self._clock, sleep=self._sleep,
                              interval=self.settings.poll_interval, duration=for_,
                              check_drives=lambda: guard.check_motors_on(refs, "the velocity move"),
                              stall=self.settings.stall_watch(max(map(abs, jv.values()), default=0)))
        result.duration = self._clock() - t0
        if w.outcome == "breach":
            result.breaches = list(w.breaches)
            recovery.recover(guard, by_name, clients, watched, w.breaches, sample, settings=self.settings,
                             clock=self._clock, sleep=self._sleep,
                             speed=recovery.recovery_speed(self.settings, watched))
        else:
            recovery.stop_now(clients, "velocity", self.settings.stop_method)
            recovery.wait_standstill(clients, self.settings, self._clock, self._sleep, guard.check,
                                     before="the end of the velocity move")
            if w.outcome == "stalled":
                from sherpa_cli.motion.blocked import blocked_error

                raise blocked_error(cfg, clients, list(clients), self.settings.stall_time, who="velocity")
        after = self._motors()
        for name in named:
            axis = self._axes[name]
            result.joints[name] = JointOutcome(name, axis.joint_cpr, axis.position(before), None, axis.position(after))
        result.stop = guard.report
        return result

    def hold(self) -> dict[str, float]:
        """Stop every motor, wait for standstill, then hold each where it stands (position mode, PA =
        PX). Returns each joint's held position in rad."""
        from sherpa_cli.motion.hold import hold_in_place

        guard = self._require()
        motors = hold_in_place(guard, self._refs, settings=self.settings, clock=self._clock, sleep=self._sleep)
        return {name: counts_to_rad(axis.position(motors), axis.joint_cpr) for name, axis in self._axes.items()}

    def stop(self) -> None:
        """Stop every motor now and wait for standstill; the motors stay on (switched off when the block ends)."""
        guard = self._require()
        clients = {r.name: guard.client(r) for r in self._refs}
        recovery.stop_now(clients, "position", self.settings.stop_method)
        recovery.wait_standstill(clients, self.settings, self._clock, self._sleep, guard.check, before="the next move")

    def positions(self) -> dict[str, float]:
        """Where the session's joints stand now, in rad."""
        motors = self._motors()
        return {name: counts_to_rad(axis.position(motors), axis.joint_cpr) for name, axis in self._axes.items()}
