"""`sherpa log step`: the seed's Section 9 experiment in one call (docs/log.md).

Start recording (log/record.py), command the step at t = 0 through the motion guard
(motion/guard.py), record until the response has settled (or the time is up), stop, and compute
the step metrics (log/step_metrics.py). t = 0 is the moment the command was asked for: when
the drive first has to change its unit mode or switch its motor on (MO/UM switch, seed
Fig. 9.1), that time is in the dead time and reported on its own as ``switch_s``.

- position: a step of X rad from where the joint stands (UM=5, PA, BG; the drive's own profile)
- velocity: JV = V rad/s, BG (UM=5 jog or UM=2, ``motion.velocity_unit_mode``)
- torque: TC = A in UM=1 (the joint's continuous current limit applies, as in `jog`)

The checks are `jog`'s (ops/jog.py): a position goal outside the joint's normal range is refused,
and so is a position step of a joint that is not calibrated unless ``uncalibrated``; while it waits
for the response, the joint-limit watch (motion/limit_watch.py) stops the step and brings the joint
back into its normal range when it leaves its full range -- in torque mode too, where no drive
limit acts. The motor is stopped before the recording is torn down, so the drive
never keeps its JV/TC while the recorder drains and restores its PDOs.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.elmo.protocol import UM_POSITION, UM_SPEED, UM_TORQUE
from sherpa_cli.errors import UsageError
from sherpa_cli.joints.units import counts_per_s_to_rad_per_s, counts_to_rad, rad_per_s_to_counts_per_s, rad_to_counts
from sherpa_cli.log.record import Recorder, bus_budget
from sherpa_cli.log.recording import Recording
from sherpa_cli.log.settle import HOLD_S, judged, settled_at_end
from sherpa_cli.log.step_metrics import StepMetrics, step_metrics
from sherpa_cli.motion.axis import Axis, resolve_axis
from sherpa_cli.motion.blocked import StallWatch, blocked_error
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.report import GuardReport, with_report
from sherpa_cli.motion.request import MoveRequest, parse_request
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.motion.stopping import stop_drive
from sherpa_cli.ops.drive_step import PRE_S  # s recorded before the command
from sherpa_cli.ops.jog import check_request, limit_breach, precheck

if TYPE_CHECKING:
    import can

    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.motion.limit_watch import Breach
    from sherpa_cli.ops.drive_step import DriveTrace

SIGNAL = {"position": "pos", "velocity": "vel", "torque": "cur"}
SETTLE_HOLD_S = HOLD_S  # s the response must stay within 2 % of the step to count as settled (log/settle.py)
UM_OF = {"position": UM_POSITION, "torque": UM_TORQUE}  # velocity: motion.velocity_unit_mode
CHECK_EVERY_S = 0.05


@dataclass
class StepResult:
    joint: str
    drive: str
    mode: str
    value: float  # rad, rad/s or A as asked
    target: float  # in the signal's unit (position: start + step)
    command: str
    switch_s: float  # s from t = 0 until the step itself was sent (MO/UM switch)
    ended_by: str  # "settled" | "time up" | "left its full range, brought back to N counts"
    metrics: StepMetrics
    recording: Recording
    samples: int
    expected: int
    stop: GuardReport = field(default_factory=GuardReport)
    breach: Breach | None = None  # when the joint left its full range (the step then failed)
    recovered_to: int | None = None  # counts, where the limit recovery brought the joint
    settled: bool = False  # the signal stayed within 2 % of the target at the end (log/settle.py)
    within: float = 0.0  # s after the step was sent that the record was allowed (--for)
    switch_steps: tuple[str, ...] = ()  # what the MO/UM switch sent: ("MO=0", "UM=5", "MO=1"), () for none
    mode_first: bool = False  # the drive was put in the step's mode before t = 0 (Fig. 9.2)
    from_mode: str | None = None  # the drive was held in this other mode, motor on, before t = 0 (Fig. 9.1)
    hold: float = 0.0  # s recorded after settling (a velocity step's constant speed, Figs. 9.3/9.6)

    @property
    def signal(self) -> str:
        return SIGNAL[self.mode]

    def as_json(self) -> dict[str, Any]:
        return {"joint": self.joint, "drive": self.drive, "mode": self.mode, "value": self.value,
                "signal": self.signal, "target": round(self.target, 6), "command": self.command,
                "switch_s": round(self.switch_s, 4), "switch_steps": list(self.switch_steps),
                "mode_first": self.mode_first, "from_mode": self.from_mode, "ended_by": self.ended_by,
                "settled": self.settled,
                "within_s": round(self.within, 4), "hold_s": self.hold, "samples": self.samples,
                "expected": self.expected, "metrics": self.metrics.as_json(), "ok": self.breach is None,
                "limit": None if self.breach is None else {**self.breach.as_dict(), "recovered_to": self.recovered_to}}


def resolve_step_target(cfg: ArmConfig, text: str) -> Axis:
    """The joint to step: a plain joint or its drive. A differential pair (its Σ/Δ joints or its
    motors) is refused: a Σ or Δ step moves both motors at once, which is `diffdrive move`'s."""
    from sherpa_cli.bus.targets import resolve_one

    t = resolve_one(cfg, text)
    if t.pair is not None:
        p = t.pair
        what = "is the differential pair" if text == p.name else f"belongs to the differential pair '{p.name}'"
        raise UsageError(f"{text}: log step moves the one motor of a plain joint; '{text}' {what}, whose Σ/Δ "
                         f"steps move both motors ({p.drive_a}, {p.drive_b})",
                         hint=f"record the pair (sherpa log record {p.sigma} {p.delta} --for S -o pair.csv) while "
                         "`sherpa diffdrive move` moves it")
    axis = resolve_axis(cfg, text)
    if axis.ref.config is not None and axis.ref.config.type != "elmo":
        raise UsageError(f"{text}: its drive {axis.ref.name} is a {axis.ref.config.type} drive: `sherpa log step` "
                         "records with Elmo's interpreter and recorder", hint="docs/drives.md says what each drive type does")
    return axis


class SyncSource(Protocol):
    """A SYNC source made by :meth:`StepTime.sync_factory`: the recorder stops it when it ends."""

    def stop(self) -> None: ...


class StepTime(Protocol):
    """Where a step's time comes from when it is not wall time: the CLI injects the simulated
    arm's stepped time with --sim (sim/stepped.py), so the figures do not depend on the host."""

    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...

    def sync_factory(self, name: str, bus: can.BusABC, period: float) -> SyncSource: ...

    def follow(self, answered: Callable[[int], bool]) -> None: ...


def step_request(target: Axis, mode: str, value: float, *, duration: float,
                 uncalibrated: bool = False, max_torque_for: float | None = None) -> MoveRequest:
    """The step as a jog request, with every check that needs no bus (`jog`'s); a dry run's checks."""
    if target.joint is None:
        raise UsageError(f"{target.name}: log step needs a plain joint (its cpr converts rad to counts)")
    req = parse_request(target, mode, by=value if mode == "position" else None,
                        velocity=value if mode == "velocity" else None, torque=value if mode == "torque" else None,
                        duration=duration if mode != "position" else None, uncalibrated=uncalibrated)
    check_request(target, req, max_torque_for=max_torque_for)
    if not (math.isfinite(duration) and duration > 0):
        raise UsageError(f"--for {duration}: expected a time > 0 s")
    return req


# --from-mode: the drive's own modes, standing still with the motor on (velocity: the Elmo's speed mode)
FROM_UM = {"position": UM_POSITION, "velocity": UM_SPEED}
FROM_MODES = tuple(FROM_UM)


def check_mode_first(mode: str, mode_first: bool, from_mode: str | None = None) -> None:
    """--mode-first holds the drive in the step's mode with its motor on before t = 0; in torque
    mode that is TC=0 for the settle window, with no limit watch yet: a joint under load would
    sag or fall, so it is refused (the seed's Fig. 9.2 is a position step). --from-mode holds it in
    another mode (position or velocity: standing still), so the step's switch is the seed's MO=0, UM,
    MO=1 (Fig. 9.1)."""
    if mode_first and mode == "torque":
        raise UsageError("--mode-first is for position and velocity steps: in torque mode the motor would be on "
                         "with no torque (TC=0) for the settle window before the step",
                         hint="a torque step's own switch is short: leave --mode-first out")
    if from_mode is None:
        return
    if from_mode not in FROM_MODES:
        raise UsageError(f"--from-mode {from_mode}: expected one of {', '.join(FROM_MODES)} (a mode that holds the "
                         "joint still with its motor on)")
    if mode_first:
        raise UsageError("--from-mode and --mode-first exclude each other: the drive stands before t = 0 either in "
                         "another mode (--from-mode) or in the step's own (--mode-first)")
    if from_mode == mode:
        raise UsageError(f"--from-mode {from_mode} is the step's own mode: that is --mode-first")


def check_from_mode_switches(from_mode: str | None, step_unit_mode: int) -> None:
    """--from-mode must leave the step a mode to change: a velocity step jogs in UM=5 unless
    motion.velocity_unit_mode is 2, and then `--from-mode position` is no other mode."""
    if from_mode is not None and FROM_UM[from_mode] == step_unit_mode:
        raise UsageError(f"--from-mode {from_mode}: the step runs in that unit mode too (UM={step_unit_mode}), so "
                         "there would be no switch", hint="velocity steps run in UM=motion.velocity_unit_mode "
                         "(docs/config.md); set it to 2 for the Elmo's speed mode")


# the lowest --rate of a step (at 0.5 Hz a step's loop stopped showing signs of life
# between samples and the dead-man tripped), and the longest --for (a recording's)
MIN_STEP_RATE = 10.0
MAX_STEP_S = 3600.0


def check_step_values(duration: float, rate: float, hold: float = 0.0) -> None:
    """--for, --rate and --hold of a step, for the command and the API alike."""
    if not (math.isfinite(duration) and 0 < duration <= MAX_STEP_S):
        raise UsageError(f"--for {duration}: expected seconds > 0 and <= {MAX_STEP_S:g}")
    if not (MIN_STEP_RATE <= rate <= 10000):
        raise UsageError(f"--rate {rate:g}: expected Hz >= {MIN_STEP_RATE:g} (the step's settling check and the "
                         "motion guard's watch need a sample at least every 0.1 s) and <= 10000")
    if not (math.isfinite(hold) and 0 <= hold < duration):
        raise UsageError(f"--hold {hold}: expected seconds >= 0 and less than --for {duration:g}")


def run_step(session: ArmSession, target: Axis, mode: str, value: float, *, duration: float, rate: float,
             settings: MotionSettings, sleep: Callable[[float], None] = time.sleep,
             on_event: Callable[[str], None] | None = None, recorder_kw: dict[str, Any] | None = None,
             uncalibrated: bool = False, timebase: StepTime | None = None, mode_first: bool = False,
             hold: float = 0.0, drive_trace: DriveTrace | None = None, from_mode: str | None = None) -> StepResult:
    """``timebase``: the step's clock, waits and SYNC source (the recorder's, the motion guard's
    and the waits here); without it wall time, ``sleep`` and ``recorder_kw``. ``mode_first``: the
    drive is put in the step's unit mode with its motor on before t = 0, and the drive's settle
    window waited out, so the step itself has no MO/UM switch (seed Fig. 9.2); ``from_mode`` the same
    in another mode (standing still), so the step's switch is MO=0, UM, MO=1 (seed Fig. 9.1). ``hold``: s to go
    on recording once the step has settled (bounded by ``duration``). ``drive_trace``: the
    drive's own recorder of the same step (ops/drive_step.py, `--source drive`), armed just before
    the command and read once the guard has stopped the motor."""
    check_step_values(duration, rate, hold)
    req = step_request(target, mode, value, duration=duration, uncalibrated=uncalibrated,
                       max_torque_for=session.cfg.motion.max_torque_for)
    check_mode_first(mode, mode_first, from_mode)
    check_from_mode_switches(from_mode, UM_OF.get(mode, settings.velocity_unit_mode))
    # jog's checks before anything is armed: a position goal inside the normal range, a calibrated joint
    precheck(session, target, req)
    ref, joint = target.ref, target.joint
    assert joint is not None  # step_request refused a target without a plain joint
    current = all(b.fits for b in bus_budget(session.cfg, [ref], rate, current=True))
    signal = SIGNAL[mode]
    clock: Callable[[], float] = time.monotonic
    rec_kw = dict(recorder_kw or {})
    if timebase is not None:
        clock, sleep = timebase.now, timebase.sleep
        rec_kw.update(clock=timebase.now, sync_factory=timebase.sync_factory)
    guard = MotionGuard(session, [ref], settings=settings, clock=clock, sleep=sleep, on_event=on_event)
    state: dict[str, Any] = {}
    with _report_on_error(guard), guard:
        c = guard.client(ref)
        start_counts = int(c.get("PX"))
        with Recorder(session, [ref], rate, current=current, **rec_kw) as rec, \
                _StopFirst(guard, ref, settings, rec, state, clock, sleep):
            if timebase is not None:
                timebase.follow(rec.answered)
            um = UM_OF.get(mode, settings.velocity_unit_mode)
            if mode_first or from_mode is not None:
                # Fig. 9.2: the drive already in the step's mode, its motor on and past the settle window;
                # Fig. 9.1: in another mode (standing still: no BG), so the step must switch it first
                held_um = um if from_mode is None else FROM_UM[from_mode]
                guard.enable(ref, held_um)
                _wait(guard, clock, sleep, session.cfg.protocol.mo_settle)
            state["switch_steps"] = _switch_steps(guard, ref, um)
            if drive_trace is not None:  # armed before t = 0: its set-up is not in the step's dead time
                drive_trace.arm("now" if mode == "torque" else "bg", state["switch_steps"])
                t_armed = rec.now()
            _wait(guard, clock, sleep, PRE_S)
            t_cmd = rec.now()
            if drive_trace is not None and mode == "torque":
                drive_trace.started(t_armed - t_cmd)  # no BG: it records from its arming on
            if mode == "position":
                goal = start_counts + rad_to_counts(value, joint.cpr)
                lo, hi = joint.normal_range
                if not lo <= goal <= hi:  # again with this PX: the joint may have moved since precheck
                    raise UsageError(f"{joint.name}: target {goal} counts is outside the joint's normal range "
                                     f"[{lo}, {hi}]", hint="log step moves a joint only inside its normal range")
                guard.enable(ref, UM_POSITION)
                c.set("PA", 0, goal)
                state["switch"] = rec.now() - t_cmd
                if drive_trace is not None:
                    drive_trace.started(state["switch"])
                c.execute("BG")
                state["command"], state["target"] = f"PA={goal}", counts_to_rad(goal, joint.cpr)
            elif mode == "velocity":
                v = rad_per_s_to_counts_per_s(value, joint.cpr)
                guard.enable(ref, settings.velocity_unit_mode)
                c.set("JV", 0, v)
                state["switch"] = rec.now() - t_cmd
                if drive_trace is not None:
                    drive_trace.started(state["switch"])
                c.execute("BG")
                # the target is what was sent: JV is whole counts/s, and its rounding is no error of the drive's
                state["command"], state["target"] = f"JV={v}", counts_per_s_to_rad_per_s(v, joint.cpr)
            else:
                guard.enable(ref, UM_TORQUE)
                state["switch"] = rec.now() - t_cmd
                c.set("TC", 0, float(value))
                state["command"], state["target"] = f"TC={value:g}", value
            # --for counts from the step itself, not from the command (a switch may come first)
            # a blocked velocity or torque step ends within the stall time, naming an active end switch
            # (a position step ends at its target: no progress there is no stall; not watched here)
            stall = (settings.torque_stall_watch() if mode == "torque" else
                     settings.stall_watch(rad_per_s_to_counts_per_s(value, joint.cpr)) if mode == "velocity" else None)
            state["ended_by"] = _until_settled(guard, rec, joint.name, signal, t_cmd, state["target"],
                                               state["switch"] + duration, clock, sleep, settle=mode != "torque",
                                               jog_target=target, settings=settings, state=state, hold=hold,
                                               stall=stall)
        # the step ends where the motor was told to stop: the stop (and a limit recovery) is not the step
        # --mode-first: the switch and its settle window before t = 0 are not the step either
        until, since = state["t_stop"] - t_cmd, -PRE_S if mode_first or from_mode is not None else None
        recording = _cut(rec.recording(t_zero=t_cmd), until, since=since)
        # what the files hold: the samples of the cut recording, of the SYNCs sent within its span
        samples = len(recording.sample_rows())
        expected = len(_cut(Recording(times=rec.sync_times(t_zero=t_cmd)), until, since=since).times)
    # position: the recorded start is the reference (PX may not have been exactly 0)
    series = recording.series(joint.name, signal)
    if series is None or len(series[0]) < 2:
        raise UsageError(f"{joint.name}: no {signal} samples were recorded")
    target_value = state["target"]
    if mode == "position":
        before = [v for t, v in zip(*series, strict=True) if t < 0]
        start = before[-1] if before else series[1][0]
        target_value = start + value
    # metrics only from a settled step: position and velocity settled while recording; a torque step
    # (recorded for --for) has settled when its current ends within the band (log/settle.py)
    if mode == "torque":
        settled = state.get("breach") is None and settled_at_end(series[0], series[1], target_value)
    else:
        settled = "settled_at" in state
    metrics = judged(step_metrics(series[0], series[1], t_step=0.0, target=target_value), settled)
    if drive_trace is not None:
        before = [v for t, v in zip(*series, strict=True) if t < 0]
        drive_trace.collect(session.cfg, joint.name, signal, state["t_stop"] - t_cmd, target_value,
                            initial=before[-1] if before else None)
    return StepResult(joint=joint.name, drive=ref.name, mode=mode, value=value, target=target_value,
                      command=state["command"], switch_s=state["switch"], ended_by=state["ended_by"],
                      metrics=metrics, recording=recording, samples=samples, expected=expected, stop=guard.report,
                      breach=state.get("breach"), recovered_to=state.get("recovered_to"), settled=settled,
                      within=duration, switch_steps=tuple(state["switch_steps"]), mode_first=mode_first, hold=hold,
                      from_mode=from_mode)


def _switch_steps(guard: MotionGuard, ref: DriveRef, unit_mode: int) -> list[str]:
    """What :meth:`MotionGuard.enable` will send before the step: a UM change needs the motor off
    first, so a drive whose motor is on in another mode pays the drive's MO settle window twice
    (MO=0 and MO=1: 1026 ms were seen on a 500 ms window), a drive whose motor is off once."""
    steps = []
    if guard.unit_mode(ref) != unit_mode:
        if guard.motor_on(ref):
            steps.append("MO=0")
        steps.append(f"UM={unit_mode}")
    if not guard.motor_on(ref) or steps:
        steps.append("MO=1")
    return steps


@contextlib.contextmanager
def _report_on_error(guard: MotionGuard) -> Iterator[None]:
    """An exception that leaves the guard (Ctrl-C, SIGTERM, an error) carries the guard's stop report,
    as jog's do: the CLI shows how the motor was stopped."""
    try:
        yield
    except BaseException as exc:
        carried = with_report(exc, guard.report)  # typed: a SherpaError's field, Ctrl-C as MotionInterrupted
        if carried is exc:
            raise
        raise carried from exc


def _wait(guard: MotionGuard, clock: Callable[[], float], sleep: Callable[[float], None], seconds: float) -> None:
    end = clock() + seconds
    while True:
        guard.check()
        rest = end - clock()
        if rest <= 1e-9:  # a stepped clock lands on sums of periods: float dust is no time left
            return
        sleep(min(rest, CHECK_EVERY_S))


def _until_settled(guard: MotionGuard, rec: Recorder, joint: str, signal: str, t_cmd: float, target: float,
                   duration: float, clock: Callable[[], float], sleep: Callable[[float], None], *, settle: bool,
                   jog_target: Axis,
                   settings: MotionSettings, state: dict[str, Any], hold: float = 0.0,
                   stall: StallWatch | None = None) -> str:
    """Record until the signal has stayed within 2 % of the step around the target for
    SETTLE_HOLD_S (position and velocity steps) and then ``hold`` s more, or until ``duration`` s
    after the command (whichever comes first; a step cut off by ``duration`` is "not settled").
    Meanwhile the joint-limit watch (jog's, every ``settings.poll_interval``): past the full range
    the motor is stopped at once and the joint brought back to the nearest edge of its normal range;
    ``stall``: no progress for the stall time ends the step as blocked (motion/blocked.py)."""
    next_settle = 0.0
    while True:
        guard.check()
        rec.check()  # another SYNC producer on the bus: the samples no longer fit the time grid
        now = rec.now()
        px = int(guard.query(jog_target.ref, "PX"))
        if limit_breach(guard, guard.client(jog_target.ref), jog_target, px, settings, clock, sleep, state):
            state["t_stop"] = now  # the watch stopped the motor here; the way back is not the step
            return state["ended_by"]
        if stall is not None and stall.feed({jog_target.ref.name: px}, clock()):
            c = guard.client(jog_target.ref)
            raise blocked_error(guard.session.cfg, {jog_target.ref.name: c}, [jog_target.ref.name],
                                settings.stall_time, who=c.label, at=f"at {px} counts; the step was not recorded")
        elapsed = now - t_cmd
        settled_at = state.get("settled_at")
        if settled_at is not None and elapsed >= settled_at + hold:
            return "settled"
        if elapsed >= duration:
            return "settled" if settled_at is not None else "time up"
        if settle and settled_at is None and elapsed > SETTLE_HOLD_S and elapsed >= next_settle:
            next_settle = elapsed + CHECK_EVERY_S
            series = rec.recording(t_zero=t_cmd).series(joint, signal)
            if series is not None and settled_at_end(*series, target):
                state["settled_at"] = elapsed
                if hold <= 0:
                    return "settled"
                continue
        sleep(settings.poll_interval)


class _StopFirst:
    """Entered just inside the Recorder, so it exits first: on every way out (the end, an error,
    Ctrl-C) the motor is stopped -- the guard's stop (TC=0 in torque mode, ST or JV=0 + BG as
    motion.stop_method says, then standstill) -- before the Recorder drains and restores its PDOs
   . The guard's own stop and switch-off follow as before."""

    def __init__(self, guard: MotionGuard, ref: DriveRef, settings: MotionSettings, rec: Recorder,
                 state: dict[str, Any], clock: Callable[[], float], sleep: Callable[[float], None]) -> None:
        self.guard, self.ref, self.settings, self.rec, self.state = guard, ref, settings, rec, state
        self.clock, self.sleep = clock, sleep

    def __enter__(self) -> _StopFirst:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.state.setdefault("t_stop", self.rec.now())
        s = self.settings
        try:
            stop_drive(self.guard.client(self.ref), unit_mode=self.guard.unit_mode(self.ref), method=s.stop_method,
                       standstill_timeout=s.standstill_timeout, poll_interval=s.poll_interval, clock=self.clock,
                       sleep=self.sleep,
                       pulse=self.guard.check if exc_type is None else None,
                       standstill_velocity=s.standstill_velocity)
        except Exception:
            if exc_type is None:
                raise
            # on the way out of an error: never hide it; the guard's stop follows and reports


def _cut(recording: Recording, until: float, since: float | None = None) -> Recording:
    """The samples taken before ``until`` (and from ``since`` on, when given; s, the recording's time).
    A SYNC at the very instant of the stop (stepped time stops on SYNC instants) is not the step's:
    the current it reports on every 2nd SYNC may be after the stop; float dust decides nothing."""
    keep = [i for i, t in enumerate(recording.times)
            if t < until - 1e-9 and (since is None or t >= since - 1e-9)]
    return Recording(times=[recording.times[i] for i in keep],
                     columns={name: [values[i] for i in keep] for name, values in recording.columns.items()})
