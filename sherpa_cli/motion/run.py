"""Running a :class:`~sherpa_cli.motion.plan.MotionPlan` inside an armed motion guard (docs/move.md).

:func:`run_plan` is the one sequence for a multi-joint move: position mode on every motor, the
profiles set, the start, the watch of every joint, the stop. The guard is the caller's and is
already entered (a command arms it for one move, a motion session for several):

1. every motor switched on in position mode (the guard's :meth:`~MotionGuard.enable`), its SP/AC/DC
   kept to be put back, then the plan's profile and PA;
2. the start, per bus as ``motion.pair_start`` says (motion/pair_start.py's CommonStart over every
   motor of the move on that bus: one group BG, or BGs executed at one SYNC, or BG after BG); the
   buses one after the other, each start's time taken, so the skew across buses (and between the
   drives of a sequential start) is measured and reported -- no start frame is shared by two buses;
3. the watch (motion/limit_watch.py) of every joint the motors move, the drives' state (a fault or a
   motor switched off from elsewhere ends the move), the stall watch and the move-time bound;
4. on a breach every motor of the move is stopped at once, waits for standstill, and the breached
   joint is brought back (motion/recovery.py); any other way out is an exception, on which the
   start's exit and then the guard's stop every motor from standstill.

Every joint's arrival time is when the profiles of its motors ended (MS=0, the watch's poll), else
the first sample at most :data:`ARRIVAL_COUNTS` from its target.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.devices.drives import ELMO
from sherpa_cli.drive import Drive, Mode, Ramp
from sherpa_cli.errors import SafetyError
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.motion import limit_watch, pair_start, recovery
from sherpa_cli.motion.blocked import blocked_error
from sherpa_cli.motion.limit_watch import Breach, BreachOutcome
from sherpa_cli.motion.report import GuardReport

if TYPE_CHECKING:
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.plan import MotionPlan
    from sherpa_cli.motion.settings import MotionSettings

ARRIVAL_COUNTS = 1  # counts from its target at which a joint has arrived (a pair joint may give way by one)
SETTLE_S = 0.3  # s a finished profile may take for PX to reach the target (servo lag)


@dataclass(frozen=True)
class JointOutcome:
    """One joint of a move: in its counts, with rad beside them."""

    joint: str
    cpr: int
    start_counts: int
    target_counts: int | None  # None: a velocity move
    end_counts: int
    time_s: float | None = None  # from the start until its motors' profiles ended (None: they did not)

    @property
    def error_counts(self) -> int | None:
        return None if self.target_counts is None else self.end_counts - self.target_counts

    @property
    def reached(self) -> bool:
        err = self.error_counts
        return err is not None and abs(err) <= ARRIVAL_COUNTS

    def rad(self, counts: int | None) -> float | None:
        return None if counts is None else counts_to_rad(counts, self.cpr)

    @property
    def start_rad(self) -> float:
        return counts_to_rad(self.start_counts, self.cpr)

    @property
    def end_rad(self) -> float:
        return counts_to_rad(self.end_counts, self.cpr)

    @property
    def target_rad(self) -> float | None:
        return self.rad(self.target_counts)

    @property
    def error_rad(self) -> float | None:
        return self.rad(self.error_counts)

    def as_json(self) -> dict[str, Any]:
        def pos(counts: int | None) -> dict[str, Any] | None:
            return None if counts is None else {"counts": counts, "rad": round(counts_to_rad(counts, self.cpr), 6)}
        return {"joint": self.joint, "from": pos(self.start_counts), "to": pos(self.target_counts),
                "end": pos(self.end_counts), "error": pos(self.error_counts), "reached": self.reached,
                "time_s": None if self.time_s is None else round(self.time_s, 3)}


@dataclass(frozen=True)
class StartReport:
    """How the motors were started: per bus the method, and the measured skew."""

    methods: Mapping[str, str]  # bus -> group | sync_rpdo | sequential
    skew_s: float  # from the first start frame's send to the last one's, across every bus and drive
    times: Mapping[str, float] = field(default_factory=dict)  # bus (or drive, sequential) -> s after the first

    def line(self) -> str:
        how = ", ".join(f"{bus} {m}" for bus, m in self.methods.items())
        return f"start: {how}; skew {self.skew_s * 1000:.1f} ms (buses started one after the other)"


@dataclass
class MotionOutcome(BreachOutcome):
    """What a move did: per joint start, target, end, arrival; how it ended; how the guard stopped
    the motors (``stop``, filled once the guard has exited -- a session's moves share one guard)."""

    joints: dict[str, JointOutcome] = field(default_factory=dict)
    breaches: list[Breach] = field(default_factory=list)
    recovered_to: dict[str, int] = field(default_factory=dict)
    duration: float = 0.0  # s from the start until every motor finished (or the move ended)
    start: StartReport | None = None
    motor_commands: dict[str, dict[str, int]] = field(default_factory=dict)
    stop: GuardReport = field(default_factory=GuardReport)
    held_at: dict[str, int] | None = None  # --hold: the PA each motor held
    held_until: str = ""

    @property
    def arrival_spread_s(self) -> float | None:
        """Latest minus earliest arrival of the joints that moved and arrived (None: fewer than two)."""
        return self.arrival_spread()

    def arrival_spread(self, min_counts: int = 1) -> float | None:
        """:attr:`arrival_spread_s` of the joints that moved at least ``min_counts``."""
        times = [j.time_s for j in self.joints.values() if j.time_s is not None and j.target_counts is not None
                 and abs(j.target_counts - j.start_counts) >= min_counts]
        return max(times) - min(times) if len(times) > 1 else None

    def as_json(self) -> dict[str, Any]:
        return {"ok": self.ok, "outcome": self.outcome, "joints": [j.as_json() for j in self.joints.values()],
                "duration_s": round(self.duration, 3),
                "start": None if self.start is None else {"methods": dict(self.start.methods),
                                                          "skew_s": round(self.start.skew_s, 4)},
                "motor_commands": dict(self.motor_commands),
                "limit": [b.as_dict() for b in self.breaches], "recovered_to": dict(self.recovered_to),
                "stop": self.stop.as_json(),
                **({"hold": {"at": dict(self.held_at), "ended_by": self.held_until}} if self.held_at is not None
                   else {})}


def standing(plan: MotionPlan) -> MotionOutcome:
    """The outcome of a plan whose joints all stand at their targets: nothing is switched on."""
    result = MotionOutcome()
    for j in plan.joints:
        result.joints[j.name] = JointOutcome(j.name, j.cpr, j.start, j.target, j.start, 0.0)
    return result


def run_plan(guard: MotionGuard, plan: MotionPlan, *, settings: MotionSettings, clock: Callable[[], float],
             sleep: Callable[[float], None],
             on_progress: Callable[[Mapping[str, int]], None] | None = None) -> MotionOutcome:
    """Run ``plan`` inside ``guard`` (entered by the caller; see the module docstring). A breach is a
    result (``ok`` False, the joint brought back); a fault, a lost drive, a stall, the time bound,
    a signal raise, every motor then stopped by the start's exit and the guard's. The motors stay
    on (stopped) afterwards: the guard's exit switches them off."""
    if not plan.motors:  # every joint stands at its target already
        return standing(plan)
    result = MotionOutcome()
    session, cfg = guard.session, guard.session.cfg
    refs = {m.drive: m.ref for m in plan.motors}
    drives: dict[str, Drive] = {d: guard.drive(r) for d, r in refs.items()}
    # Elmo drives start together per bus (pair_start) and keep SP/AC/DC journaled; any other drive
    # type through the seam alone, started one after the other (the guard puts its profile back)
    clients = {d: guard.client(r) for d, r in refs.items() if drives[d].kind == ELMO}
    movers: dict[str, recovery.Motor] = {d: clients.get(d, drives[d]) for d in refs}
    targets = {m.drive: m.target for m in plan.motors}
    method, group_id = pair_start.pair_settings(cfg)
    buses: dict[str, list[DriveRef]] = {}
    others: list[DriveRef] = []
    for r in refs.values():
        if r.name in clients:
            buses.setdefault(r.bus, []).append(r)
        else:
            others.append(r)
    axes = {a.name: a for a in plan.watched}
    arrived: dict[str, float] = {}
    t0 = 0.0
    began: float | None = None

    def sample() -> dict[str, int]:
        motors = {d: guard.position(r) for d, r in refs.items()}
        if began is not None:
            for j in plan.joints:
                if j.name not in arrived and j.name in axes and \
                        abs(axes[j.name].position(motors) - j.target) <= ARRIVAL_COUNTS:
                    arrived[j.name] = clock() - t0
        if on_progress is not None:
            on_progress({a.name: a.position(motors) for a in plan.watched})
        return motors

    profile_done: dict[str, float] = {}  # drive -> s after the start its profile ended (MS=0)

    def finished(_motors: Mapping[str, int]) -> bool:
        # every drive asked every time: a drive that reads 0 before its profile began (its BG still
        # on the way) or in between is not counted until it reads 0 for good
        for d, drive in drives.items():
            if drive.profile_done():
                profile_done.setdefault(d, clock() - t0)
            else:
                profile_done.pop(d, None)
        return len(profile_done) == len(drives)

    try:
        with contextlib.ExitStack() as stack:
            starts: dict[str, pair_start.CommonStart] = {}
            for bus, bus_refs in buses.items():
                how = method if len(bus_refs) > 1 else "sequential"
                if how == "group" and cfg.motion.pair_group_reset_comm and any(guard.motor_on(r) for r in bus_refs):
                    # the group id takes effect only through a reset communication, which no motor
                    # that is on may see (it puts the dead-man back): a session's later move, its
                    # motors still on, starts them one BG after another (the skew is measured)
                    how = "sequential"
                starts[bus] = stack.enter_context(pair_start.CommonStart(
                    session, bus_refs, {r.name: clients[r.name] for r in bus_refs}, how, group_id,
                    stop=pair_start.stop_motors(guard, bus_refs, settings), reset_comm=pair_start.group_reset(guard, cfg)))
            for r in refs.values():
                guard.enable(r, Mode.POSITION)
            with guard.motor_off_explains_failure(refs.values(), "the move"):
                for m in plan.motors:
                    if m.drive in clients:
                        starts[m.ref.bus].keep_profile(m.drive)  # SP/AC/DC put back on every way out
                    drives[m.drive].set_ramp(Ramp(m.profile.sp, m.profile.ac, m.profile.dc))
                    drives[m.drive].move_to(m.target)
            result.motor_commands = {m.drive: {"PA": m.target, **m.profile.as_dict()} for m in plan.motors}
            result.start = _start(starts, {r.name: drives[r.name] for r in others}, clock)
            t0 = began = clock()
            watched = limit_watch.watch(
                plan.watched, sample, clock=clock, sleep=sleep, interval=settings.poll_interval,
                finished=finished, duration=plan.timeout,
                check_drives=lambda: guard.check_motors_on(refs.values(), "the move"),
                stall=settings.stall_watch(max(m.profile.sp for m in plan.motors)))
            result.duration = clock() - began
            if watched.outcome == "breach":
                result.breaches = list(watched.breaches)
                recovery.recover(guard, refs, movers, plan.watched, watched.breaches, sample, settings=settings,
                                 clock=clock, sleep=sleep, hold=plan.held,
                                 speed=recovery.recovery_speed(settings, plan.watched))
                back = sample()
                result.recovered_to = {a.name: a.position(back) for a in plan.watched}
            elif watched.outcome == "stalled":
                guard.explain_stall(refs.values(), "the move")
                raise blocked_error(cfg, clients, list(clients), settings.stall_time, who="move",
                                    at=_where(plan, watched.motors))
            elif watched.outcome == "elapsed":
                raise SafetyError(f"move: not every joint arrived within {plan.timeout:g} s ({_where(plan, watched.motors)})",
                                  hint="check the drives with `sherpa monitor --once`")
            final = sample()
            if watched.outcome == "finished":
                settle_end = clock() + SETTLE_S
                while final != targets and clock() < settle_end:
                    guard.check()
                    sleep(settings.poll_interval)
                    final = sample()
    finally:
        if began is not None and not result.duration:
            result.duration = clock() - began
    for j in plan.joints:
        end = axes[j.name].position(final) if j.name in axes else j.start  # a joint not moved was not read
        result.joints[j.name] = JointOutcome(j.name, j.cpr, j.start, j.target, end,
                                             _arrival(j.name, axes, profile_done, arrived) if j.distance else 0.0)
    return result


def _arrival(joint: str, axes: Mapping[str, Axis], profile_done: Mapping[str, float],
             arrived: Mapping[str, float]) -> float | None:
    """When a joint arrived: its motors' profiles ended (MS=0, the last of them), else the first
    sample that found it at its target; None if neither happened."""
    axis = axes.get(joint)
    if axis is not None and all(d in profile_done for d in axis.drives):
        return max(profile_done[d] for d in axis.drives)
    return arrived.get(joint)


def _where(plan: MotionPlan, motors: Mapping[str, int]) -> str:
    return "stopped at " + ", ".join(f"{a.name} {a.position(motors)}" for a in plan.watched
                                     if a.name in {j.name for j in plan.joints}) + " counts"


def _start(starts: Mapping[str, pair_start.CommonStart], others: Mapping[str, Drive],
           clock: Callable[[], float]) -> StartReport:
    """Every bus's start, one after the other, each timed; a sequential start with several drives
    is timed drive by drive, as is each drive of another type (its own begin)."""
    times: dict[str, float] = {}
    methods = {bus: s.method for bus, s in starts.items()}
    first: float | None = None
    for name, drive in others.items():
        now = clock()
        first = now if first is None else first
        times[name] = now - first
        drive.begin()
        methods.setdefault(name, "own")
    for bus, start in starts.items():
        if start.method == "sequential" and len(start.refs) > 1:
            for r in start.refs:
                now = clock()
                first = now if first is None else first
                times[r.name] = now - first
                start.begin([r.name])
        else:
            now = clock()
            first = now if first is None else first
            times[bus] = now - first
            start.begin()
    return StartReport(methods, max(times.values(), default=0.0), times)


def watch_hold(guard: MotionGuard, plan: MotionPlan, result: MotionOutcome, *, settings: MotionSettings,
               clock: Callable[[], float], sleep: Callable[[float], None],
               on_progress: Callable[[Mapping[str, int]], None] | None = None) -> dict[str, int]:
    """--hold after a move: every motor of the plan holds where it stands (motion/hold.py), the limit
    watch on, until Ctrl-C (raised) or `sherpa stop`. Returns the motors' positions at its end."""
    from sherpa_cli.motion import hold

    refs = plan.refs
    by_name = {r.name: r for r in refs}
    clients = {r.name: guard.client(r) for r in refs}
    result.held_at = hold.hold_in_place(guard, refs, settings=settings, clock=clock, sleep=sleep, stop=False)

    def sample() -> dict[str, int]:
        motors = {r.name: int(guard.query(r, "PX")) for r in refs}
        if on_progress is not None:
            on_progress({a.name: a.position(motors) for a in plan.watched})
        return motors

    def watch() -> bool:
        breaches = limit_watch.check(plan.watched, sample())
        if not breaches:
            return False
        result.breaches = list(breaches)
        recovery.recover(guard, by_name, clients, plan.watched, breaches, sample, settings=settings, clock=clock,
                         sleep=sleep, hold=plan.held, speed=recovery.recovery_speed(settings, plan.watched))
        return True

    result.held_until = hold.hold_until_released(guard, refs, settings=settings, sleep=sleep, watch=watch) or ""
    return sample()
