"""`sherpa diffdrive match PAIR`: make both speed loops of a differential pair equally fast (docs/tune.md).

The seed's first cure for its coupled pair ("one of the drives is moving a bit faster than the other
one"): gains that make both drives equally fast. Three parts:

- :func:`measure`: a small Σ velocity step of both motors together (one common BG, the pair's start
  method), inside the motion guard, recorded by both drives' own recorders armed for that BG (RAM only,
  put back on every exit path: ops/drive_record.py); the motors stop before the upload and go back to
  where they stood.
- :func:`identify`: each motor's loop from its recorded speed and speed command. The number that
  matters for the pair is the loop's *delay* tau = integral(v_cmd - v) dt / v: at any steady speed
  a motor trails its command by v tau, so a Σ move drags Δ by v (tau_a - tau_b). The overshoot gives
  a damping and, with tau = 2 zeta / wn, a second-order model (bandwidth, damping) to show.
- :func:`propose`: the faster motor's KP[2] and KP[3] scaled by s = tau_fast / tau_slow and its KI[2]
  by s^2 -- for a cascade of a P position loop into a PI speed loop on an inertia this scales the
  loop's bandwidth by s at the same damping, so its delay becomes tau_slow. The faster motor is the
  one slowed: lowering gains stays inside every bound and never asks a loop to be stiffer than it
  was. A pair whose delays agree within ``tolerance`` gets no change.

Writing the proposal goes through `tune set`'s path (plan, dry run, --apply with read-back, --save
guarded); nothing here writes a gain.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig, PairConfig
from sherpa_cli.elmo.protocol import UM_POSITION
from sherpa_cli.errors import ProtocolError, SafetyError, UsageError
from sherpa_cli.joints import diffpair
from sherpa_cli.motion import calibration
from sherpa_cli.motion.pair_start import CommonStart, group_reset, pair_settings, stop_motors

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.elmo.recorder import RecorderSettings
    from sherpa_cli.log.recording import Recording
    from sherpa_cli.motion.guard import MotionGuard

MATCHED_KEYS = ("KP[2]", "KI[2]", "KP[3]")
STEP_SHARE = 0.25  # default step: this share of the Σ joint's speed limit
STEP_S = 0.3  # s recorded from the BG on
TOLERANCE = 0.05  # delays within 5 % of each other: matched, no change
RETURN_TIMEOUT_S = 10.0
SIGNALS = ("pos", "vel", "vel_cmd")


@dataclass(frozen=True)
class LoopModel:
    """One motor's speed loop from a step: delay (s), 10-90 % rise (s), overshoot (share), and the
    second-order model they give (damping from the overshoot, wn = 2 zeta / delay)."""

    delay_s: float
    rise_s: float
    overshoot: float
    zeta: float
    speed: float  # counts/s the step settled at (the command)
    sample_s: float = 0.0  # the recording's sample period (0: not known)

    @property
    def resolved(self) -> bool:
        """Whether the delay is long enough to give a bandwidth: a delay shorter than one sample (an
        ideal simulated loop: 0) is below what the recording resolves, and 2 zeta / delay would be
        infinite or noise."""
        return self.delay_s > 0 and self.delay_s >= self.sample_s

    @property
    def bandwidth_hz(self) -> float | None:
        """wn in Hz; None when not :attr:`resolved` (:attr:`bandwidth_above_hz` bounds it then)."""
        return 2 * self.zeta / self.delay_s / (2 * math.pi) if self.resolved else None

    @property
    def bandwidth_above_hz(self) -> float | None:
        """The bandwidth an unresolved loop exceeds: the model's at a delay of one sample."""
        if self.resolved or self.sample_s <= 0:
            return None
        return 2 * self.zeta / self.sample_s / (2 * math.pi)

    @property
    def bandwidth_note(self) -> str | None:
        if self.resolved:
            return None
        if self.sample_s <= 0:
            return "no delay measured: the bandwidth is beyond what the step resolves"
        return (f"the delay is shorter than one sample ({self.sample_s * 1e3:.2f} ms): the bandwidth is above "
                f"{self.bandwidth_above_hz:.0f} Hz, more than the recording resolves")

    def bandwidth_text(self) -> str:
        """The bandwidth as a table shows it: "12.5", "> 418" (unresolved, :attr:`bandwidth_note`) or "-"."""
        if self.bandwidth_hz is not None:
            return f"{self.bandwidth_hz:.1f}"
        above = self.bandwidth_above_hz
        return "-" if above is None else f"> {above:.0f}"

    def as_dict(self) -> dict[str, float | str | None]:
        bandwidth, above = self.bandwidth_hz, self.bandwidth_above_hz
        return {"delay_ms": round(self.delay_s * 1e3, 3), "rise_ms": round(self.rise_s * 1e3, 3),
                "overshoot": round(self.overshoot, 4), "damping": round(self.zeta, 3),
                "bandwidth_hz": None if bandwidth is None else round(bandwidth, 2),
                "bandwidth_above_hz": None if above is None else round(above, 2),
                "bandwidth_note": self.bandwidth_note, "speed": round(self.speed, 1)}


@dataclass
class PairStep:
    """The recorded Σ step of both motors: time (s from the BG) and per drive pos/vel/vel_cmd."""

    times: list[float]
    data: dict[str, dict[str, list[float]]]
    speed: int  # counts/s per motor
    period_s: float

    def delta_excursion(self, drives: tuple[str, str]) -> float:
        """Largest |Δ - Δ0| (motor counts, Δ = m_a - m_b) during the step: the coupling of this Σ move."""
        a, b = self.data[drives[0]]["pos"], self.data[drives[1]]["pos"]
        d0 = a[0] - b[0]
        return max((abs(x - y - d0) for x, y in zip(a, b, strict=False)), default=0.0)


@dataclass
class Proposal:
    drives: tuple[str, str]
    models: dict[str, LoopModel]
    gains: dict[str, dict[str, float]]  # what each drive holds now
    changes: dict[str, dict[str, float]]  # drive -> key -> new value; empty: no change
    scale: float  # s applied to the changed drive (1: none)
    mismatch: float  # (tau_slow - tau_fast) / tau_slow
    tolerance: float
    speed: float  # counts/s per motor the predictions are for
    note: str = ""

    @property
    def changed(self) -> str | None:
        return next(iter(self.changes), None)

    def predicted_delay(self, drive: str) -> float:
        d = self.models[drive].delay_s
        return d / self.scale if drive == self.changed else d

    def predicted_excursion(self, after: bool) -> float:
        """v x |tau_a - tau_b| (motor counts) at :attr:`speed`, now or with the proposal."""
        a, b = self.drives
        if after:
            return self.speed * abs(self.predicted_delay(a) - self.predicted_delay(b))
        return self.speed * abs(self.models[a].delay_s - self.models[b].delay_s)

    def as_dict(self) -> dict[str, Any]:
        return {"drives": list(self.drives), "models": {d: m.as_dict() for d, m in self.models.items()},
                "gains": self.gains, "changes": self.changes, "scale": round(self.scale, 6),
                "mismatch": round(self.mismatch, 4), "tolerance": self.tolerance,
                "predicted_delta_excursion": {"speed": round(self.speed, 1),
                                              "before": round(self.predicted_excursion(False), 2),
                                              "after": round(self.predicted_excursion(True), 2)},
                "note": self.note}


@dataclass
class MatchSettings:
    speed: int | None = None  # counts/s per motor; None: STEP_SHARE of the Σ joint's limit
    step_s: float = STEP_S
    tolerance: float = TOLERANCE
    uncalibrated: bool = False
    recorder: RecorderSettings | None = None
    extra: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- pure parts

def step_speed(cfg: ArmConfig, pair: PairConfig, speed: int | None) -> int:
    """counts/s per motor of the Σ step: ``speed`` or STEP_SHARE of the Σ joint's limit, never above it."""
    sj = cfg.joints[pair.sigma]
    motor_limit = abs(diffpair.motor_velocities(sj.vel_limit, 0)[0]) if sj.vel_limit else None
    if speed is None:
        if motor_limit is None:
            raise UsageError(f"{pair.name}: the Σ joint {sj.name} has no velocity limit: give --speed",
                             hint="a step needs a speed inside the joint's limits")
        return max(1, round(STEP_SHARE * motor_limit))
    if speed <= 0:
        raise UsageError(f"--speed {speed}: expected counts/s > 0")
    if motor_limit is not None and speed > motor_limit:
        raise UsageError(f"--speed {speed}: above the motors' share of {sj.name}'s speed limit ({motor_limit} counts/s)")
    return speed


def identify(times: Sequence[float], vel: Sequence[float], vel_cmd: Sequence[float]) -> LoopModel:
    """The loop of one motor from a velocity step (times from the BG)."""
    n = len(times)
    if n < 8 or len(vel) != n or len(vel_cmd) != n:
        raise ProtocolError(f"a step of {n} samples is too short to identify a loop")
    tail = max(1, n // 5)
    target = sum(vel_cmd[-tail:]) / tail
    if abs(target) < 1e-9:
        raise ProtocolError("the recorded speed command stays at 0: the step did not start",
                            hint="check the recorder's signal ids (RecorderSettings.signal_ids)")
    sign = 1.0 if target > 0 else -1.0
    v = [x * sign for x in vel]
    cmd = [x * sign for x in vel_cmd]
    speed = abs(target)
    area = sum((cmd[k] - v[k] + cmd[k + 1] - v[k + 1]) / 2 * (times[k + 1] - times[k]) for k in range(n - 1))
    delay = max(0.0, area / speed)
    peak = max(v)
    overshoot = max(0.0, (peak - speed) / speed)

    def crossing(share: float) -> float:
        for k in range(n):
            if v[k] >= share * speed:
                if k == 0:
                    return times[0]
                f = (share * speed - v[k - 1]) / (v[k] - v[k - 1])
                return times[k - 1] + f * (times[k] - times[k - 1])
        return times[-1]

    rise = crossing(0.9) - crossing(0.1)
    if overshoot > 0.005:
        ln = math.log(overshoot)
        zeta = -ln / math.sqrt(math.pi ** 2 + ln * ln)
    else:
        zeta = 1.0
    return LoopModel(delay, rise, overshoot, zeta, speed, (times[-1] - times[0]) / (n - 1))


def propose(drives: tuple[str, str], models: Mapping[str, LoopModel], gains: Mapping[str, Mapping[str, float]],
            bounds: Mapping[str, tuple[float, float]], *, tolerance: float = TOLERANCE,
            speed: float | None = None) -> Proposal:
    """Slow the faster motor to the slower one's delay (module docstring); no change within ``tolerance``."""
    a, b = drives
    ta, tb = models[a].delay_s, models[b].delay_s
    fast, slow = (a, b) if ta < tb else (b, a)
    t_fast, t_slow = models[fast].delay_s, models[slow].delay_s
    mismatch = (t_slow - t_fast) / t_slow if t_slow > 0 else 0.0
    v = speed if speed is not None else models[a].speed
    held = {d: {k: float(gains[d][k]) for k in MATCHED_KEYS} for d in drives}
    if mismatch <= tolerance:
        return Proposal(drives, dict(models), held, {}, 1.0, mismatch, tolerance, v,
                        note=f"delays agree within {tolerance:.0%}: no change")
    if t_fast <= 0:
        raise ProtocolError(f"{fast}: no measurable delay (its speed matched its command at once)",
                            hint="a longer or faster step (--speed) shows the loop better")
    s = t_fast / t_slow
    new = scaled_gains(held[fast], s)
    _check_bounds(fast, new, bounds)
    changes = {fast: {k: x for k, x in new.items() if x != held[fast][k]}}
    return Proposal(drives, dict(models), held, changes, s, mismatch, tolerance, v,
                    note=f"{fast} is faster: its KP[2], KP[3] x {s:.4f}, KI[2] x {s * s:.4f}")


# --------------------------------------------------------------------------- on the bus

def _refs(cfg: ArmConfig, pair: PairConfig) -> list[DriveRef]:
    out = []
    for name in (pair.drive_a, pair.drive_b):
        d = cfg.drives[name]
        out.append(DriveRef(name, d.bus, d.node))
    return out


def read_matched_gains(session: ArmSession, refs: Sequence[DriveRef]) -> dict[str, dict[str, float]]:
    from sherpa_cli.elmo.commands import parse_param_key

    out: dict[str, dict[str, float]] = {}
    for ref in refs:
        c = session.client(ref)
        c.nmt_start()
        out[ref.name] = {k: float(c.get(*parse_param_key(k))) for k in MATCHED_KEYS}
    return out


def check_travel(cfg: ArmConfig, pair: PairConfig, motors: Mapping[str, int], speed: int, step_s: float) -> None:
    """Refuse a step that could leave the Σ joint's normal range: it travels at most
    speed x (step + 1 s) per motor (the step, the wait for the data, the stop), then comes back."""
    sj = cfg.joints[pair.sigma]
    travel = 2 * speed * (step_s + 1.0)
    sigma = motors[pair.drive_a] + motors[pair.drive_b]
    lo, hi = sj.normal_range
    if not lo <= sigma + travel <= hi:
        raise SafetyError(f"{pair.name}: a Σ step of up to {travel:.0f} counts from Σ={sigma} leaves "
                          f"{sj.name}'s normal range [{lo}, {hi}]",
                          hint="move the pair towards the middle of its range first, or a smaller --speed")


def measure(session: ArmSession, pair: PairConfig, settings: MatchSettings, *,
            guard_factory: Callable[..., MotionGuard] | None = None,
            clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
            on_event: Callable[[str], None] | None = None) -> PairStep:
    """One Σ velocity step of both motors, recorded by their drives; both come back to where they stood."""
    from sherpa_cli.elmo.recorder import RecorderSettings
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.motion.stopping import wait_all_standstill
    from sherpa_cli.ops.drive_record import record_drives

    cfg = session.cfg
    refs = _refs(cfg, pair)
    speed = step_speed(cfg, pair, settings.speed)
    clients = {r.name: session.client(r) for r in refs}
    for c in clients.values():
        c.nmt_start()
    cal = calibration.read_calibration(cfg, cfg.joints[pair.sigma], lambda d: clients[d])
    if not cal.calibrated and not settings.uncalibrated:
        raise SafetyError(f"{pair.name}: refusing to step: joint {cal.joint} is {cal.reason}",
                          hint="home it first, or pass --uncalibrated")
    start = {r.name: int(clients[r.name].get("PX")) for r in refs}
    check_travel(cfg, pair, start, speed, settings.step_s)
    motion = MotionSettings.from_config(cfg, {r.bus for r in refs})
    method, group_id = pair_settings(cfg)
    rec_settings = settings.recorder or RecorderSettings()
    guard = (guard_factory or MotionGuard)(session, refs, settings=motion, clock=clock, sleep=sleep, on_event=on_event)

    def alive_sleep(seconds: float) -> None:
        guard.check()  # the guard's sign of life while the recorders are polled
        sleep(seconds)

    with guard:
        stop = stop_motors(guard, refs, motion)

        def stop_before_upload() -> None:
            stop()  # a drive that does not answer: the guard's exit stops it and reports

        with CommonStart(session, refs, {r.name: guard.client(r) for r in refs}, method, group_id, stop=stop,
                         reset_comm=group_reset(guard, session.cfg)) as begin:
            for r in refs:
                guard.enable(r, motion.velocity_unit_mode)
                guard.client(r).set("JV", 0, speed)
            result = record_drives(session, refs, settings.step_s, trigger="bg", settings=rec_settings,
                                   signals=SIGNALS, clock=clock, sleep=alive_sleep, on_armed=begin.begin,
                                   on_ready=stop_before_upload)
            moving = wait_all_standstill({r.name: guard.client(r) for r in refs},
                                         standstill_timeout=motion.standstill_timeout,
                                         poll_interval=motion.poll_interval,
                                         standstill_velocity=motion.standstill_velocity, clock=clock, sleep=sleep,
                                         pulse=guard.check)
            if moving:
                raise SafetyError(f"{', '.join(moving)}: not at standstill after the step's stop",
                                  hint="the guard stops and switches off both motors; check the pair")
            # back to where both stood: one position move each, started together
            for r in refs:
                guard.enable(r, UM_POSITION)
                c = guard.client(r)
                c.set("SP", 0, speed)
                c.set("PA", 0, start[r.name])
            begin.begin()
            deadline = clock() + RETURN_TIMEOUT_S
            while any(int(guard.query(r, "MS")) == 2 for r in refs):
                if clock() > deadline:
                    raise SafetyError(f"{pair.name}: the motors did not get back to where they stood within "
                                      f"{RETURN_TIMEOUT_S:g} s", hint="they were stopped; check the pair")
                alive_sleep(motion.poll_interval)
    data = {name: dict(d) for name, d in _columns(result.recording, refs).items()}
    return PairStep(list(result.recording.times), data, speed, result.period_s)


def _columns(recording: Recording, refs: Sequence[DriveRef]) -> dict[str, dict[str, list[float]]]:
    from sherpa_cli.ops.drive_record import COLUMNS

    out: dict[str, dict[str, list[float]]] = {}
    for r in refs:
        out[r.name] = {sig: list(recording.columns[f"{r.name}.{COLUMNS[sig]}"]) for sig in SIGNALS}
    return out


def models_of(step: PairStep) -> dict[str, LoopModel]:
    return {name: identify(step.times, d["vel"], d["vel_cmd"]) for name, d in step.data.items()}


# --------------------------------------------------------------------------- the match: trial rounds

JOURNAL_OWNER = "diffdrive match"
ROUNDS = 5
MIN_EXPONENT, MAX_EXPONENT = 0.5, 3.0  # how strongly a delay may follow the gain scale (tau ~ S^-p)


@dataclass
class MatchRound:
    scale: float  # S: the changed drive's KP[2], KP[3] x S, KI[2] x S^2 of what it held
    models: dict[str, LoopModel]
    excursion: float  # measured Δ excursion of the Σ step (motor counts)

    def error(self, fast: str, slow: str) -> float:
        return abs(self.models[fast].delay_s - self.models[slow].delay_s) / self.models[slow].delay_s

    def as_dict(self) -> dict[str, Any]:
        return {"scale": round(self.scale, 6), "models": {d: m.as_dict() for d, m in self.models.items()},
                "delta_excursion": round(self.excursion, 2)}


@dataclass
class MatchResult:
    pair: str
    proposal: Proposal  # the gains to write (empty changes: none)
    rounds: list[MatchRound]  # round 0: the gains the drives hold; then the trials
    chosen: int  # the round whose gains are proposed
    steps: list[PairStep]
    reached: bool  # the chosen round's delays agree within the tolerance

    def as_dict(self) -> dict[str, Any]:
        before, after = self.rounds[0], self.rounds[self.chosen]
        return {"pair": self.pair, "proposal": self.proposal.as_dict(),
                "rounds": [r.as_dict() for r in self.rounds], "chosen_round": self.chosen, "reached": self.reached,
                "measured_delta_excursion": {"speed": self.proposal.speed, "before": round(before.excursion, 2),
                                             "after": round(after.excursion, 2)}}


def scaled_gains(held: Mapping[str, float], s: float) -> dict[str, float]:
    return {"KP[2]": float(f"{held['KP[2]'] * s:.6g}"), "KP[3]": float(f"{held['KP[3]'] * s:.6g}"),
            "KI[2]": float(f"{held['KI[2]'] * s * s:.6g}")}


def run_match(session: ArmSession, pair: PairConfig, settings: MatchSettings, *, rounds: int = ROUNDS,
              bounds: Mapping[str, tuple[float, float]], **measure_kw: Any) -> MatchResult:
    """Step, identify, propose; while the delays disagree, try the proposal on the faster drive (its
    gains in RAM, journaled and put back on every exit path) and step again, refining the scale from
    what each trial measured (a secant in log space: a real loop's delay need not follow 1/S). The
    gains the drives held are back when this returns; the caller writes the proposal, if any."""
    from sherpa_cli.bus import journal
    from sherpa_cli.elmo.commands import parse_param_key

    if rounds < 1:
        raise UsageError(f"--rounds {rounds}: expected 1 or more")
    cfg = session.cfg
    refs = _refs(cfg, pair)
    drives = (pair.drive_a, pair.drive_b)
    held = read_matched_gains(session, refs)
    step = measure(session, pair, settings, **measure_kw)
    steps = [step]
    first = models_of(step)
    proposal = propose(drives, first, held, bounds, tolerance=settings.tolerance, speed=step.speed)
    history = [MatchRound(1.0, first, step.delta_excursion(drives))]
    fast = proposal.changed
    if fast is None:
        return MatchResult(pair.name, proposal, history, 0, steps, True)
    slow = drives[1] if fast == drives[0] else drives[0]
    ref = next(r for r in refs if r.name == fast)
    client = session.client(ref)
    journal.note(ref, *(journal.interp(JOURNAL_OWNER, *parse_param_key(k), held[fast][k]) for k in MATCHED_KEYS))
    s_prev, tau_prev, p, s = 1.0, first[fast].delay_s, 1.0, proposal.scale
    try:
        for _ in range(rounds):
            trial = scaled_gains(held[fast], s)
            _check_bounds(fast, trial, bounds)
            for key, value in trial.items():
                client.set(*parse_param_key(key), value)
            step = measure(session, pair, settings, **measure_kw)
            steps.append(step)
            models = models_of(step)
            history.append(MatchRound(s, models, step.delta_excursion(drives)))
            if history[-1].error(fast, slow) <= settings.tolerance:
                break
            tau, target = models[fast].delay_s, models[slow].delay_s
            if tau <= 0 or target <= 0:
                break
            if abs(math.log(s / s_prev)) > 1e-9 and tau != tau_prev:
                p = min(MAX_EXPONENT, max(MIN_EXPONENT, -math.log(tau / tau_prev) / math.log(s / s_prev)))
            s_prev, tau_prev = s, tau
            s = s * (tau / target) ** (1 / p)
    finally:
        failed = _put_back(held[fast], client)
        if not failed:
            journal.forget(ref, JOURNAL_OWNER)  # else the journal keeps them for `sherpa recover`
    if failed:
        raise ProtocolError(f"{ref.name}: the trial gains {', '.join(failed)} were not put back",
                            hint="`sherpa recover --apply` puts them back from the journal")
    chosen = min(range(1, len(history)), key=lambda k: history[k].error(fast, slow))
    best = history[chosen]
    final = scaled_gains(held[fast], best.scale)
    proposal.changes = {fast: {k: v for k, v in final.items() if v != held[fast][k]}}
    proposal.scale = best.scale
    proposal.note = (f"{fast} is faster: its KP[2], KP[3] x {best.scale:.4f}, KI[2] x {best.scale ** 2:.4f} "
                     f"(round {chosen} of {len(history) - 1} trials)")
    return MatchResult(pair.name, proposal, history, chosen, steps, best.error(fast, slow) <= settings.tolerance)


def _check_bounds(drive: str, gains: Mapping[str, float], bounds: Mapping[str, tuple[float, float]]) -> None:
    for key, value in gains.items():
        low, high = bounds[key]
        if not low <= value <= high:
            raise SafetyError(f"{drive}: the matching {key}={value:g} is outside its bounds {low:g}..{high:g}",
                              hint="the bounds are the config's `tuning:` section (docs/tune.md)")


def _put_back(held: Mapping[str, float], client: DriveClient) -> list[str]:
    """The trial's gains back to what the drive held; every key is tried. Returns those that failed
    (never raises: on the way out of an error, that error is the one reported)."""
    from sherpa_cli.elmo.commands import parse_param_key

    failed: list[str] = []
    for key, value in held.items():
        try:
            client.set(*parse_param_key(key), value)
        except Exception:  # noqa: BLE001 - every key is tried; the journal keeps what failed for `sherpa recover`
            failed.append(key)
    return failed


@dataclass(frozen=True)
class MatchPanel:
    """One round's column of the match plot: its words and what it draws, from one set of values."""

    round: int
    label: str  # "before (own gains)" | "after (round N)"
    times_ms: list[float]
    speeds: dict[str, list[float]]  # drive -> counts/s
    command: list[float]
    drag: list[float]  # Δ - Δ0, counts
    legends: dict[str, str]  # drive -> its legend entry
    speed_title: str
    drag_title: str


def delta_drag(step: PairStep, drives: tuple[str, str]) -> list[float]:
    """Δ - Δ0 (motor counts, Δ = m_a - m_b) over the step: what :meth:`PairStep.delta_excursion` peaks."""
    a, b = step.data[drives[0]]["pos"], step.data[drives[1]]["pos"]
    d0 = a[0] - b[0]
    return [x - y - d0 for x, y in zip(a, b, strict=False)]


def match_panels(result: MatchResult) -> list[MatchPanel]:
    """Before (the drives' own gains) and after (the round whose gains are proposed); a pair that
    needed no trial has the one round. Each drive's delay is written once, for its legend entry;
    the drag title's peak is the plotted trace's."""
    drives = result.proposal.drives
    panels = []
    rounds = [(0, "before (own gains)"), (result.chosen, f"after (trial {result.chosen})")] if result.chosen else \
        [(0, "own gains (no change proposed)")]
    for k, label in rounds:
        step, rnd = result.steps[k], result.rounds[k]
        drag = delta_drag(step, drives)
        peak = max((abs(v) for v in drag), default=0.0)
        legends = {d: f"{d}, delay {rnd.models[d].delay_s * 1e3:.1f} ms" for d in drives}
        panels.append(MatchPanel(k, label, [x * 1e3 for x in step.times],
                                 {d: list(step.data[d]["vel"]) for d in drives}, list(step.data[drives[0]]["vel_cmd"]),
                                 drag, legends, f"{label}: both motors' speed",
                                 f"{label}: Δ drag, peak {peak:.0f} counts"))
    return panels


def plot(result: MatchResult, path: str) -> Figure:
    """Before / after: both motors' recorded speed and Δ (m_a - m_b, counts) of the Σ step (the round
    with the drives' own gains and the round whose gains are proposed), each row on one y scale so
    the columns compare at a glance. PNG, matplotlib (log/plot.py)."""
    from sherpa_cli.log.plot import figure, legend_outside, save_png

    fig = figure()
    panels = match_panels(result)
    axes = fig.subplots(2, len(panels), sharex=True, sharey="row", squeeze=False)
    for col, panel in enumerate(panels):
        ax = axes[0][col]
        for drive, speed in panel.speeds.items():
            ax.plot(panel.times_ms, speed, label=panel.legends[drive])
        ax.plot(panel.times_ms, panel.command, "k:", linewidth=0.8, label="speed command")
        ax.set_title(panel.speed_title, fontsize="medium")
        ax.set_ylabel("speed [counts/s]")
        ax.grid(True, alpha=0.3)
        legend_outside(ax)
        drag = axes[1][col]
        drag.plot(panel.times_ms, panel.drag, label="Δ - Δ at BG")
        drag.set_title(panel.drag_title, fontsize="medium")
        drag.set_ylabel("Δ drag [counts]")
        drag.set_xlabel("time since BG [ms]")
        drag.grid(True, alpha=0.3)
    fig.suptitle(f"diffdrive match {result.pair}: Σ step, each motor {result.steps[0].speed} counts/s")
    save_png(fig, path)
    return fig
