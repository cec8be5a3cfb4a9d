"""`sherpa diffdrive move`: drive a differential pair as two joints, both motors starting together
(docs/diffdrive.md).

Pure parts (no bus): :func:`plan_move` (targets from Σ/Δ, refusals, equal-duration profiles),
:func:`profiles` and :func:`measure_coupling`. The running part, :func:`run_move`, works inside the
motion guard with the joint-limit watch and the calibration check of the motion core; the common
start is :func:`common_begin` (also used by `jog` of a Σ/Δ joint, ops/joint_jog.py).

Common start (``motion.pair_start``): ``group`` writes the group id ``motion.pair_group_id`` to
object 0x2040 of both drives (RAM only; the old values are put back on every exit path) and sends
one BG to that id, which both drives execute on the same frame; ``sync_rpdo`` makes RPDO2
synchronous (0x1401:2 = 1, RAM, for the begin only), sends BG to each drive and one SYNC at which
both execute it; ``sequential`` sends two BG back to back. ``--naive`` is the seed's way: two BG and unscaled profiles, kept for comparison.

Recording: both motors are recorded by `sherpa log`'s recorder (log/record.py: TPDO on SYNC at
``motion.pair_record_rate``, RAM only, put back on every exit path; :class:`RecordedTrace`), whose
newest sample also feeds the move's loop (limit watch, ``--feedback``); with ``--poll`` or when the
recorder cannot be set up, the loop polls PX through the interpreter instead (:class:`PolledTrace`).
With ``source="drive"`` (``--source drive``) both drives' own recorders (ops/drive_record.py, RAM only,
put back on every exit path) are armed to start at the move's BG and record PX at the servo rate for
the move's time bound; the loop polls PX for its own watch, and the coupling figures come from the
drives' recordings (:func:`recorder_samples`).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig, PairConfig
from sherpa_cli.elmo.protocol import UM_POSITION
from sherpa_cli.elmo.recorder import MAX_GAP, RecorderPlan, RecorderSettings, plan_recording
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.joints import diffpair, units
from sherpa_cli.motion import calibration, hold, limit_watch, recovery
from sherpa_cli.motion.axis import Axis, joints_moved_by, move_time_bound
from sherpa_cli.motion.blocked import blocked_text
from sherpa_cli.motion.pair_start import CommonStart, group_reset, pair_settings, stop_motors
from sherpa_cli.motion.plan import Profile
from sherpa_cli.motion.report import with_report

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.log.record import Recorder
    from sherpa_cli.log.recording import Recording
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.limit_watch import Breach
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.drive_record import DriveRecordings, DriveRecordResult
    from sherpa_cli.ops.step import StepTime

SETTLE_S = 0.3  # s a finished move may take for PX to reach the target (servo lag) before it is reported


# --------------------------------------------------------------------------- planning (pure)

@dataclass(frozen=True)
class PairTarget:
    """A `diffdrive move` as typed: Σ and Δ still text (their units need each joint's cpr); None = hold.

    Not the one-axis request (motion/request.MoveRequest): it sets both joints of the pair at once,
    two targets with one timing and a choice of profile (naive, feedback, the recording), which a
    request for one axis does not describe; its plan uses the same pair maths (joints/diffpair.py)
    and the one move-time bound (motion/axis.py)."""

    sigma: str | None = None
    delta: str | None = None
    relative: bool = False
    velocity: str | None = None  # the speed of the faster joint; default: the joints' limits
    naive: bool = False
    feedback: bool = False
    uncalibrated: bool = False
    poll: bool = False  # record by polling PX instead of the recorder (TPDO on SYNC)
    source: str = "can"  # can: recorded over the bus (TPDO on SYNC, or --poll); drive: by the drives' recorders
    hold: bool = False  # after the move both motors stay on, holding, until Ctrl-C or `sherpa stop`


@dataclass(frozen=True)
class MovePlan:
    pair: PairConfig
    start: tuple[int, int]  # (Σ, Δ) counts
    target: tuple[int, int]
    motors_start: Mapping[str, int]
    motor_targets: Mapping[str, int]
    profiles: Mapping[str, Profile]
    duration: float  # s, the cruise-speed estimate (ramps add to it)
    timeout: float
    naive: bool = False

    @property
    def distance(self) -> tuple[int, int]:
        return self.target[0] - self.start[0], self.target[1] - self.start[1]


def _range_text(r: tuple[int, int]) -> str:
    return f"[{r[0]}, {r[1]}]"


def profiles(distances: Mapping[str, int], speed: int, accel: int, decel: int, *,
             scaled: bool = True) -> dict[str, Profile]:
    """Equal-duration profiles: the motor with the longest distance gets ``speed``/``accel``/``decel``,
    every other motor the same scaled by its share of that distance, so all start, accelerate and
    arrive together. ``scaled=False`` (the naive way): the same values for every motor."""
    longest = max((abs(d) for d in distances.values()), default=0)
    out = {}
    for name, d in distances.items():
        share = abs(d) / longest if scaled and longest else 1.0
        out[name] = Profile(max(1, round(speed * share)), max(1, round(accel * share)), max(1, round(decel * share)))
    return out


def _value(text: str, cpr: int, what: str) -> int:
    return units.parse_position(text, cpr, what=what)


def plan_move(cfg: ArmConfig, pair: PairConfig, request: PairTarget, motors: Mapping[str, int], *,
              accel: int | None = None, decel: int | None = None) -> MovePlan:
    """Motor targets and profiles for ``request`` from the motors' present positions; refuses a
    target outside either joint's normal range or the motor box. ``accel``/``decel``: motor
    counts/s² when the joints' config has none (the drives' present AC/DC)."""
    if request.sigma is None and request.delta is None:
        raise UsageError("diffdrive move: give --sigma, --delta or both (a joint left out holds)")
    sj, dj = cfg.joints[pair.sigma], cfg.joints[pair.delta]
    a, b = pair.drive_a, pair.drive_b
    s0, d0 = diffpair.to_joints(motors[a], motors[b])
    s1, d1 = s0, d0
    if request.sigma is not None:
        v = _value(request.sigma, sj.cpr, "--sigma")
        s1 = s0 + v if request.relative else v
    if request.delta is not None:
        v = _value(request.delta, dj.cpr, "--delta")
        d1 = d0 + v if request.relative else v
    for joint, value, opt in ((sj, s1, "--sigma"), (dj, d1, "--delta")):
        lo, hi = joint.normal_range
        if not lo <= value <= hi:
            raise UsageError(f"{opt}: {joint.name} target {value} counts is outside the joint's normal range "
                             f"{_range_text(joint.normal_range)}", hint="diffdrive move stays inside the normal ranges "
                             f"(see `sherpa diffdrive limits {pair.name}`)")
    if not diffpair.is_reachable(s1, d1):
        # Σ and Δ of whole motor positions have equal parity: the held (or Δ) joint gives way one count
        moving = "sigma" if request.sigma is not None else "delta"
        held = dj.normal_range if moving == "sigma" else sj.normal_range
        s1, d1 = diffpair.hold_other(s1, d1, moving, held)
    ma, mb = diffpair.to_motors(s1, d1)
    box = diffpair.motor_box(sj.full_range, dj.full_range)
    if not box.contains(ma, mb):
        raise UsageError(f"diffdrive move: motor targets {a}={ma}, {b}={mb} are outside the motor box "
                         f"{a} {_range_text(box.a)}, {b} {_range_text(box.b)}")
    dist = {a: ma - motors[a], b: mb - motors[b]}
    ds, dd = abs(s1 - s0), abs(d1 - d0)
    if request.velocity is not None:
        cpr = sj.cpr if ds >= dd else dj.cpr
        joint_speed = abs(units.parse_velocity(request.velocity, cpr, what="--velocity"))
        if joint_speed == 0:
            raise UsageError("--velocity must not be 0")
        for joint, dist_j in ((sj, ds), (dj, dd)):
            if dist_j and joint.vel_limit is not None and joint_speed * dist_j / max(ds, dd) > joint.vel_limit:
                raise UsageError(f"--velocity: {joint.name} would run at {joint_speed * dist_j // max(ds, dd)} counts/s, "
                                 f"above its speed limit {joint.vel_limit} counts/s")
        duration = max(ds, dd) / joint_speed
    else:
        times = []
        for joint, dist_j in ((sj, ds), (dj, dd)):
            if dist_j:
                if joint.vel_limit is None:
                    raise UsageError(f"{joint.name} has no velocity.limit in the config: give --velocity")
                times.append(dist_j / joint.vel_limit)
        duration = max(times, default=0.0)
    longest = max(abs(x) for x in dist.values())
    speed = max(1, math.ceil(longest / duration)) if duration else 1
    # joint accelerations bound the motors like speeds do: a motor at AC moves Σ or Δ at up to 2 AC
    acc = [j.accel for j in (sj, dj) if j.accel]
    dec = [j.decel for j in (sj, dj) if j.decel]
    ac = max(1, min(acc) // 2) if acc else (accel or speed * 10)
    dc = max(1, min(dec) // 2) if dec else (decel or speed * 10)
    prof = profiles(dist, speed, ac, dc, scaled=not request.naive)
    if request.naive:
        prof = {n: Profile(speed, ac, dc) for n in dist}
    # the one move-time bound (motion/axis.py): the cruise at speed plus both ramps
    return MovePlan(pair, (s0, d0), (s1, d1), dict(motors), {a: ma, b: mb}, prof, duration,
                    timeout=move_time_bound(speed * duration, speed, ac, dc), naive=request.naive)


# --------------------------------------------------------------------------- coupling (pure)

@dataclass
class Coupling:
    """How far the pair left the straight Σ/Δ path during a move."""

    move: float  # length of the move in joint counts (Euclidean in Σ/Δ)
    peak_sigma: float  # counts off the straight path, Σ component (peak of |.|)
    peak_delta: float
    held: str | None  # the joint that should have held (None: both were asked to move)
    held_peak: float  # its peak excursion beyond its planned path (start to its target), counts
    sigma_cpr: int
    delta_cpr: int
    held_cpr: int = 0
    # the held joint's planned move, counts: ±1 when Σ and Δ of the target had mixed parity (plan_move:
    # whole motor positions give Σ and Δ of equal parity), a give-way the plan chose, not coupling
    held_planned: int = 0

    def fraction(self, counts: float) -> float:
        return counts / self.move if self.move else 0.0

    def as_dict(self) -> dict[str, Any]:
        def entry(counts: float, cpr: int) -> dict[str, float]:
            return {"counts": round(counts, 1), "rad": round(units.counts_to_rad(counts, cpr), 6),
                    "fraction": round(self.fraction(counts), 4)}
        out: dict[str, Any] = {"move_counts": round(self.move, 1),
                               "sigma_off_path": entry(self.peak_sigma, self.sigma_cpr),
                               "delta_off_path": entry(self.peak_delta, self.delta_cpr), "held": self.held}
        if self.held is not None:
            out["held_excursion"] = entry(self.held_peak, self.held_cpr)
            out["held_planned_counts"] = self.held_planned
        return out


def measure_coupling(samples: Sequence[tuple[float, int, int]], start: tuple[int, int], target: tuple[int, int],
                     *, sigma_name: str, delta_name: str, sigma_cpr: int, delta_cpr: int,
                     held: str | None = None) -> Coupling:
    """Peak deviation of (Σ, Δ) from the straight segment start → target over ``samples`` of
    (t, m_a, m_b); and the peak excursion of ``held``, the joint that should have held (by default the
    one whose target is its start), beyond its planned path: from its start to its target, which
    differ by the one count of a parity give-way (plan_move) or not at all."""
    s0, d0 = start
    ds, dd = target[0] - s0, target[1] - d0
    length2 = ds * ds + dd * dd
    peak_s = peak_d = 0.0
    for _, ma, mb in samples:
        s, d = ma + mb, ma - mb
        u = ((s - s0) * ds + (d - d0) * dd) / length2 if length2 else 0.0
        u = min(max(u, 0.0), 1.0)
        peak_s = max(peak_s, abs(s - (s0 + u * ds)))
        peak_d = max(peak_d, abs(d - (d0 + u * dd)))
    if held is None:
        held = delta_name if dd == 0 and ds != 0 else sigma_name if ds == 0 and dd != 0 else None
    held_peak, held_cpr, planned = 0.0, 0, 0
    if held is not None:
        sig = held == sigma_name
        held_cpr = sigma_cpr if sig else delta_cpr
        first = s0 if sig else d0
        planned = (target[0] if sig else target[1]) - first
        lo, hi = min(first, first + planned), max(first, first + planned)
        held_peak = max((max(lo - v, v - hi, 0) for v in (ma + mb if sig else ma - mb for _, ma, mb in samples)),
                        default=0.0)
    return Coupling(math.sqrt(length2), peak_s, peak_d, held, held_peak, sigma_cpr, delta_cpr, held_cpr, planned)


# --------------------------------------------------------------------------- recording

class Trace(Protocol):
    """What a move records into: :class:`PolledTrace`, :class:`RecordedTrace`, or what a test's
    ``trace_factory`` makes (``source``, when it has one, names it in the result)."""

    samples: list[tuple[float, int, int]]

    def add(self, t: float, motors: Mapping[str, int]) -> None: ...


class PolledTrace:
    """Both motors' positions during the move, sampled by the move's own loop (PX polled through
    the interpreter, one drive after the other): the fallback when the recorder is not used."""

    source = "polled PX"

    def __init__(self, drives: tuple[str, str]) -> None:
        self.drives = drives
        self.samples: list[tuple[float, int, int]] = []

    def add(self, t: float, motors: Mapping[str, int]) -> None:
        a, b = self.drives
        self.samples.append((t, int(motors[a]), int(motors[b])))


class RecordedTrace:
    """Both motors recorded by `sherpa log`'s recorder (log/record.py: PX and VX on TPDO1 at every
    SYNC, RAM only, restored on every exit path). Both drives are sampled at the same SYNC, so the
    Σ/Δ of a sample is exact (polling reads one motor a round trip after the other). The move's
    loop reads the newest sample (:meth:`latest`) instead of polling PX."""

    def __init__(self, recorder: Recorder, drives: tuple[str, str], rate: float, note: str = "") -> None:
        self.recorder, self.drives, self.rate = recorder, drives, rate
        self.source = f"TPDO on SYNC at {rate:g} Hz" + (f" ({note})" if note else "")
        self.samples: list[tuple[float, int, int]] = []
        self.t_zero: float | None = None  # the recorder's time of the move's begin

    def add(self, t: float, motors: Mapping[str, int]) -> None:  # samples come from the recorder
        pass

    def latest(self, max_age: float) -> tuple[dict[str, int], dict[str, int]] | None:
        """(PX, VX) of both drives at the newest SYNC both answered, if at most ``max_age`` s old."""
        newest = self.recorder.latest()
        if newest is None or self.recorder.now() - newest[0] > max_age:
            return None
        values = newest[1]
        return {d: values[d][0] for d in self.drives}, {d: values[d][1] for d in self.drives}

    def collect(self) -> None:
        """After the recorder closed: its samples as (t from the begin, m_a, m_b)."""
        rec = self.recorder.recording(t_zero=self.t_zero)
        a, b = (rec.columns[f"{d}.px"] for d in self.drives)
        self.samples = [(t, int(x), int(y)) for t, x, y in zip(rec.times, a, b, strict=True) if x == x and y == y]


def record_rate(cfg: ArmConfig, refs: Sequence[DriveRef]) -> tuple[float, str]:
    """``motion.pair_record_rate``, capped to what the pair's bus can carry (log/record.py's budget)."""
    from sherpa_cli.devices.encoder import recorded_encoders
    from sherpa_cli.log.record import bus_budget

    rate = float(cfg.motion.pair_record_rate)
    encoders = [t.dev for t in recorded_encoders(cfg, (r.name for r in refs))]  # recorded beside them
    budget = bus_budget(cfg, refs, rate, current=False, encoders=encoders)
    if all(b.fits for b in budget):
        return rate, ""
    cap = float(min(b.max_rate for b in budget))
    return cap, f"capped from {rate:g} Hz by the bus budget"


# --------------------------------------------------------------------------- running it

@dataclass
class MoveResult:
    pair: str
    sigma: str
    delta: str
    drives: tuple[str, str]
    mode: str  # naive | group | sequential
    feedback: bool
    start: tuple[int, int]
    target: tuple[int, int]
    end: tuple[int, int]
    sigma_cpr: int
    delta_cpr: int
    motors_start: dict[str, int] = field(default_factory=dict)
    motors_end: dict[str, int] = field(default_factory=dict)
    motor_commands: dict[str, dict[str, int]] = field(default_factory=dict)  # drive -> letters -> value
    coupling: Coupling | None = None
    samples: list[tuple[float, int, int]] = field(default_factory=list)
    trace_source: str = ""
    corrections: int = 0
    calibration: list[calibration.Calibration] = field(default_factory=list)
    breaches: list[Breach] = field(default_factory=list)
    outcome: str = "done"
    duration: float | None = None
    guard_lines: list[str] = field(default_factory=list)
    stop: dict[str, Any] = field(default_factory=dict)
    held_at: dict[str, int] | None = None  # --hold: the PA each motor held (None: not held)
    held_until: str = ""  # --hold: how the hold ended (motion/hold.py)

    @property
    def ok(self) -> bool:
        return not self.breaches

    def as_dict(self) -> dict[str, Any]:
        def joint(i: int) -> dict[str, Any]:
            cpr = self.sigma_cpr if i == 0 else self.delta_cpr
            return {"start": self.start[i], "target": self.target[i], "end": self.end[i],
                    "error": self.end[i] - self.target[i],
                    "end_rad": round(units.counts_to_rad(self.end[i], cpr), 6)}
        return {"pair": self.pair, "ok": self.ok, "outcome": self.outcome, "mode": self.mode,
                "feedback": self.feedback, "drives": list(self.drives),
                "sigma": {"joint": self.sigma, **joint(0)}, "delta": {"joint": self.delta, **joint(1)},
                "motors_start": dict(self.motors_start), "motors_end": dict(self.motors_end),
                "motor_commands": dict(self.motor_commands),
                "coupling": self.coupling.as_dict() if self.coupling else None,
                "recording": {"source": self.trace_source, "samples": len(self.samples)},
                "feedback_corrections": self.corrections, "duration_s": self.duration,
                "calibration": [c.as_dict() for c in self.calibration],
                "limit": [b.as_dict() for b in self.breaches], "stop": dict(self.stop),
                **({"hold": {"at": dict(self.held_at), "ended_by": self.held_until}} if self.held_at is not None
                   else {})}


def _refs(cfg: ArmConfig, drives: Sequence[str]) -> list[DriveRef]:
    return [DriveRef(d, cfg.drives[d].bus, cfg.drives[d].node, cfg.drives[d]) for d in drives]


def prepare(session: ArmSession, pair: PairConfig, request: PairTarget) -> tuple[MovePlan, list[calibration.Calibration]]:
    """Read positions and calibration, then plan; nothing is written but NMT start."""
    cfg = session.cfg
    refs = _refs(cfg, (pair.drive_a, pair.drive_b))
    clients = {r.name: session.client(r) for r in refs}
    for c in clients.values():
        c.nmt_start()
    motors = {d: int(c.get("PX")) for d, c in clients.items()}
    acs = [int(c.get("AC")) for c in clients.values()]
    dcs = [int(c.get("DC")) for c in clients.values()]
    p = plan_move(cfg, pair, request, motors, accel=min(acs) or None, decel=min(dcs) or None)
    cal = calibration.read_calibration(cfg, cfg.joints[pair.sigma], lambda d: clients[d], resync=True)
    if not cal.calibrated and not request.uncalibrated:
        raise SafetyError(f"{pair.name}: refusing a move: joint {cal.joint} is {cal.reason}",
                          hint="home it first, or pass --uncalibrated to move by the counter as it is "
                               "(positions are then relative to where the joints stood at power-up)")
    return p, [cal]


class Feedback:
    """--feedback: keeps both motors at the same share of their own distance (which is the straight
    Σ/Δ path). Each cycle, from the newest recorded sample:

    - e = p_a - p_b, the progress difference (p = (PX - start) / (target - start));
    - v = (r_a - r_b) / mean(r), the relative difference of the progress rates r = VX / distance
      (recorder samples only; while both motors run at least ``VELOCITY_FLOOR`` of their planned
      speed): it sees one motor running faster long before the positions drift apart;
    - c = gain·s·e + integral·∫e dt + VELOCITY_GAIN·v, bounded by ``limit``. The integral learns a
      steady mismatch (one motor faster than the other); s = min(1, CYCLE_S / time since the last
      cycle) and each cycle's dt capped at MAX_DT_S keep a stalled loop from over-correcting.

    Only the motor ahead slows: its SP/AC/DC become k = (1 - |c|) / (1 + |c|) of its planned
    profile (the ratio the two would have if one slowed by c and the other sped up by c), at least
    1 - ``limit``; the other keeps its planned profile. No motor ever runs faster or accelerates
    harder than planned, so the joints' speed and acceleration limits hold. None when one motor
    does not move (there is nothing to keep in step)."""

    VELOCITY_GAIN = 0.2
    VELOCITY_FLOOR = 0.2  # share of the planned speed both motors need before v counts
    CYCLE_S = 0.012  # the loop's expected period with the recorder; slower cycles get a weaker P term
    MAX_DT_S = 0.03  # longest time step the integral takes from one cycle

    def __init__(self, plan: MovePlan, gain: float, limit: float, integral: float | None = None) -> None:
        self.plan, self.gain, self.limit = plan, gain, limit
        self.integral = self.gain * 10 if integral is None else integral
        self._sum = 0.0
        self._t: float | None = None

    def profiles(self, t: float, motors: Mapping[str, int],
                 velocities: Mapping[str, int] | None = None) -> dict[str, Profile] | None:
        p = self.plan
        a, b = p.pair.drive_a, p.pair.drive_b
        prog, rate, floor = {}, {}, {}
        for d in (a, b):
            dist = p.motor_targets[d] - p.motors_start[d]
            if dist == 0:
                return None
            prog[d] = (motors[d] - p.motors_start[d]) / dist
            floor[d] = self.VELOCITY_FLOOR * p.profiles[d].sp / abs(dist)
            if velocities is not None:
                rate[d] = velocities[d] / dist
        err = prog[a] - prog[b]
        scale = 1.0
        if self._t is not None:
            dt = t - self._t
            self._sum += err * min(dt, self.MAX_DT_S)
            if dt > self.CYCLE_S:
                scale = self.CYCLE_S / dt
        self._t = t
        # anti-windup: the integral alone never asks for more than the bound
        bound = self.limit / self.integral if self.integral else 0.0
        self._sum = max(-bound, min(bound, self._sum))
        vterm = 0.0
        if rate and all(rate[d] >= floor[d] for d in (a, b)):
            vterm = self.VELOCITY_GAIN * (rate[a] - rate[b]) / ((rate[a] + rate[b]) / 2)
        corr = max(-self.limit, min(self.limit, scale * self.gain * err + self.integral * self._sum + vterm))
        k = max(1 - self.limit, (1 - abs(corr)) / (1 + abs(corr)))

        def scaled(pr: Profile, f: float) -> Profile:
            return Profile(max(1, round(pr.sp * f)), max(1, round(pr.ac * f)), max(1, round(pr.dc * f)))
        return {a: scaled(p.profiles[a], k if corr > 0 else 1.0), b: scaled(p.profiles[b], k if corr < 0 else 1.0)}


DRIVE_SIGNALS = ("pos",)  # --source drive records PX only: the whole buffer for the finest gap


def check_source(request: PairTarget) -> None:
    """--source can|drive, and --poll only with can (it says how the bus records)."""
    if request.source not in ("can", "drive"):
        raise UsageError(f"--source {request.source}: expected can or drive")
    if request.source == "drive" and request.poll:
        raise UsageError("--source drive records in the drives, not over the bus: --poll does not apply")


def drive_record_length(plan: MovePlan) -> float:
    """s the drives record from the move's BG: its time bound and the settle window after it."""
    return plan.timeout + SETTLE_S


def plan_drive_recording(length: float, settings: RecorderSettings) -> RecorderPlan:
    """The drives' recording of a move that may take ``length`` s (:func:`drive_record_length`); a
    move longer than the recorder holds is refused (UsageError) before anything moves."""
    longest = MAX_GAP * (settings.capacity // len(DRIVE_SIGNALS)) * settings.sample_time_s
    if length > longest:
        raise UsageError(f"--source drive: the move may take up to {length:.1f} s (its time bound); the drive's "
                         f"recorder holds at most {longest:.1f} s of PX (RG={MAX_GAP})",
                         hint="a shorter or faster move, or --source can (recorded over the bus)")
    return plan_recording(length, settings, signals=DRIVE_SIGNALS, trigger="bg")


def recorder_samples(rec: Recording, drives: tuple[str, str], *, until: float | None = None
                     ) -> list[tuple[float, int, int]]:
    """A drive recording (ops/drive_record.py's columns ``<drive>.px``) as the trace's samples
    (t, m_a, m_b), up to ``until`` s."""
    a, b = (rec.columns[f"{d}.px"] for d in drives)
    return [(t, round(x), round(y)) for t, x, y in zip(rec.times, a, b, strict=True)
            if x == x and y == y and (until is None or t <= until)]


def _open_trace(stack: contextlib.ExitStack, session: ArmSession, refs: Sequence[DriveRef], request: PairTarget,
                drives: tuple[str, str], recorder_kw: Mapping[str, Any] | None) -> PolledTrace | RecordedTrace:
    """The move's recording: the recorder of `sherpa log` (TPDO on SYNC), or PX polled by the move's
    loop with --poll or when the recorder cannot be set up (its source says which)."""
    if request.poll:
        trace = PolledTrace(drives)
        trace.source = "polled PX (--poll)"
        return trace
    if request.source == "drive":  # the drives record; the loop polls PX for its own watch
        return PolledTrace(drives)
    from sherpa_cli.log.record import Recorder

    rate, note = record_rate(session.cfg, refs)
    try:
        rec = stack.enter_context(Recorder(session, refs, rate, enforce_budget=False, **dict(recorder_kw or {})))
    except Exception as exc:  # noqa: BLE001 - shown in the trace's source; the move records by polling
        # the recorder put back what it changed
        trace = PolledTrace(drives)
        trace.source = f"polled PX (the recorder could not be set up: {exc})"
        return trace
    return RecordedTrace(rec, drives, rate, note)


def run_move(session: ArmSession, pair: PairConfig, request: PairTarget, *,
             guard_factory: Callable[..., MotionGuard] | None = None,
             clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
             on_event: Callable[[str], None] | None = None,
             recorder_kw: Mapping[str, Any] | None = None,
             trace_factory: Callable[[tuple[str, str]], Trace] | None = None,
             drive_recorder: RecorderSettings | None = None, timebase: StepTime | None = None,
             on_progress: Callable[[Mapping[str, int]], None] | None = None) -> MoveResult:
    """Plan, then move both motors inside the motion guard with the limit watch, recording both.

    ``recorder_kw`` goes to log/record.py's Recorder (``clock``, ``sync_factory``: tests);
    ``timebase`` (ops/step.py): the move's clock, waits and SYNC source instead of wall time, ``clock``,
    ``sleep`` and ``recorder_kw`` (the simulated arm's stepped time; each SYNC's TPDOs are in before
    the clock moves on);
    ``trace_factory(drives)`` replaces the recording with anything that has ``add(t, motors)``,
    ``samples`` and ``source`` (PX is then polled, as with --poll). With ``request.source ==
    "drive"`` both drives' recorders (ops/drive_record.py, ``drive_recorder``: their settings) are
    armed for the move's BG and the move runs while they record; its coupling figures come from
    their recordings. ``request.hold``: after the move both motors hold where they ended until
    Ctrl-C or `sherpa stop` (motion/hold.py), ``on_progress`` seeing Σ and Δ (counts) meanwhile."""
    from sherpa_cli.motion.guard import MotionGuard
    from sherpa_cli.motion.settings import MotionSettings

    cfg = session.cfg
    check_source(request)
    if timebase is not None:
        clock, sleep = timebase.now, timebase.sleep
        recorder_kw = {**(recorder_kw or {}), "clock": timebase.now, "sync_factory": timebase.sync_factory}
    method, group_id = pair_settings(cfg)
    if request.naive:
        method = "sequential"
        if request.feedback:
            raise UsageError("--naive and --feedback do not go together: --naive is the seed's way, for comparison")
    p, cals = prepare(session, pair, request)
    drives = (pair.drive_a, pair.drive_b)
    refs = _refs(cfg, drives)
    by_name = {r.name: r for r in refs}
    settings = MotionSettings.from_config(cfg, {r.bus for r in refs})
    watched = tuple(joints_moved_by(cfg, drives))
    sj, dj = cfg.joints[pair.sigma], cfg.joints[pair.delta]
    result = MoveResult(pair.name, pair.sigma, pair.delta, drives, "naive" if request.naive else method,
                        request.feedback, p.start, p.target, p.start, sj.cpr, dj.cpr,
                        motors_start=dict(p.motors_start), calibration=cals)
    rec_plan: RecorderPlan | None = None
    rec_length, rec_settings = 0.0, drive_recorder or RecorderSettings()
    drive_rec: DriveRecordResult | None = None
    if request.source == "drive":  # a move longer than the drives can record is refused before anything moves
        rec_length = drive_record_length(p)
        rec_plan = plan_drive_recording(rec_length, rec_settings)
    guard = (guard_factory or MotionGuard)(session, refs, settings=settings, clock=clock, sleep=sleep,
                                           on_event=on_event)
    drive_recs: DriveRecordings | None = None
    if rec_plan is not None:
        from sherpa_cli.ops.drive_record import DriveRecordings

        # every drive armed (inside the guard) to start at the move's BG, for the move's time bound
        drive_recs = DriveRecordings(session, refs, rec_plan, rec_settings, clock=clock, sleep=sleep)
    box: dict[str, Any] = {}  # what the move leaves for the result

    def moving() -> None:
        try:
            guarded()
        except KeyboardInterrupt as exc:
            stopped = hold.ended_hold(result, guard.report, exc)
            box["final"] = {d: stopped.get(d) if stopped.get(d) is not None else box["final"][d] for d in drives}

    def guarded() -> None:
        with guard:
            clients = {d: guard.client(by_name[d]) for d in drives}
            start = CommonStart(session, refs, clients, method, group_id, stop=stop_motors(guard, refs, settings),
                                reset_comm=group_reset(guard, session.cfg))
            with contextlib.ExitStack() as stack:
                stack.callback(start.close)  # the group id put back on every way out (close runs once)
                # before the recording: a reset communication would put its PDO settings back
                start.prepare()
                trace: Trace = (trace_factory(drives) if trace_factory is not None else
                                _open_trace(stack, session, refs, request, drives, recorder_kw))
                result.trace_source = getattr(trace, "source", type(trace).__name__)
                recorded = trace if isinstance(trace, RecordedTrace) else None  # its newest SYNC feeds the loop
                if timebase is not None and recorded is not None:
                    timebase.follow(recorded.recorder.answered)
                # entered after the recorder, so it exits first: the motors stop and the RAM settings go
                # back before the recorder puts its PDO settings back
                stack.enter_context(start)
                for d in drives:
                    guard.enable(by_name[d], UM_POSITION)
                for d, c in clients.items():
                    start.keep_profile(d)  # SP/AC/DC put back on every way out, like 0x2040
                    pr = p.profiles[d]
                    c.set("SP", 0, pr.sp)
                    c.set("AC", 0, pr.ac)
                    c.set("DC", 0, pr.dc)
                    c.set("PA", 0, p.motor_targets[d])
                result.motor_commands = {d: {"PA": p.motor_targets[d], **p.profiles[d].as_dict()} for d in drives}
                last = dict(p.profiles)
                fb = Feedback(p, cfg.motion.feedback_gain, cfg.motion.feedback_limit) if request.feedback else None
                # with the recorder the loop reads the newest SYNC's PX instead of polling it, so it
                # can run at the recording's rate; the drives' status (SR, MS) is still asked at
                # most every poll interval, as before
                stale = max(10 / recorded.rate, 0.02) if recorded is not None else 0.0
                interval = (min(settings.poll_interval, 1 / recorded.rate) if recorded is not None and fb
                            else settings.poll_interval)
                state: dict[str, Any] = {"status_due": 0.0, "seen": None}

                def positions() -> dict[str, int]:
                    state["velocities"] = None
                    if recorded is not None:
                        got = recorded.latest(stale)
                        if got is not None:
                            guard.check()  # the guard's sign of life (a query gives one)
                            state["velocities"] = got[1]
                            return got[0]
                    return {d: int(guard.query(by_name[d], "PX")) for d in drives}

                def sample() -> dict[str, int]:
                    motors = positions()
                    now = clock() - t0
                    trace.add(now, motors)
                    if fb is not None and motors != state["seen"]:
                        state["seen"] = motors
                        new = fb.profiles(now, motors, state["velocities"])
                        near_end = any(abs(p.motor_targets[d] - motors[d]) <= 2 for d in drives)
                        if new is not None and not near_end and new != last:
                            for d in drives:
                                for key, v in new[d].as_dict().items():
                                    if v != last[d].as_dict()[key]:
                                        clients[d].set(key, 0, v)
                            start.begin()  # in UM=5 a BG takes the new profile on the fly
                            last.update(new)
                            result.corrections += 1
                    return motors

                def status_due() -> bool:
                    return clock() >= state["status_due"]

                def check_drives() -> None:
                    if status_due():
                        guard.check_motors_on([by_name[d] for d in clients], "the move")
                    else:
                        guard.check()

                def finished(motors: Mapping[str, int]) -> bool:
                    if not status_due():
                        return False
                    vel = state["velocities"]
                    if vel is not None and not all(motors[d] == p.motor_targets[d] and vel[d] == 0 for d in drives) \
                            and clock() < state.get("ms_due", 0.0):
                        state["status_due"] = clock() + settings.poll_interval
                        return False  # the recording says not there yet: MS is asked only now and then
                    state["ms_due"] = clock() + 5 * settings.poll_interval
                    state["status_due"] = clock() + settings.poll_interval
                    return all(int(c.get("MS")) == 0 for c in clients.values())

                if drive_recs is not None:  # inside the guard (its lock and checks first), just before the BG
                    drive_recs.arm()
                t0 = t_begin = clock()
                if recorded is not None:
                    recorded.t_zero = recorded.recorder.now()
                start.begin()
                w = limit_watch.watch(watched, sample, clock=clock, sleep=sleep, interval=interval,
                                      finished=finished, duration=p.timeout, check_drives=check_drives,
                                      stall=settings.stall_watch(max(pr.sp for pr in p.profiles.values())))
                result.duration = round(clock() - t_begin, 3)
                if w.outcome == "breach":
                    result.outcome = "limit"
                    result.breaches = list(w.breaches)
                    recovery.recover(guard, by_name, clients, watched, w.breaches,
                                     lambda: {d: int(clients[d].get("PX")) for d in drives}, settings=settings,
                                     clock=clock, sleep=sleep, hold={},
                                     speed=recovery.recovery_speed(settings, watched))
                elif w.outcome == "stalled":
                    guard.explain_stall([by_name[d] for d in drives], "the move")
                    s_now, d_now = w.joints.get(sj.name), w.joints.get(dj.name)
                    raise SafetyError(f"{pair.name}: {blocked_text(session.cfg, clients, drives, settings.stall_time)}; "
                                      f"at Σ={s_now}, Δ={d_now} on the way to Σ={p.target[0]}, Δ={p.target[1]}",
                                      hint="move the joint away from the switch or the stop (`sherpa jog`), "
                                      "then check the target against the joint's range")
                elif w.outcome == "elapsed":
                    raise SafetyError(f"{pair.name}: did not reach Σ={p.target[0]}, Δ={p.target[1]} within "
                                      f"{p.timeout:g} s", hint="check the drives with `sherpa monitor --once`")
                final = {d: int(clients[d].get("PX")) for d in drives}
                if w.outcome == "finished":
                    # the profile is done (MS=0); the motor may still be settling onto it (servo lag):
                    # wait a bounded moment for PX to reach the target, as a TR window would
                    settle_end = clock() + SETTLE_S
                    while final != dict(p.motor_targets) and clock() < settle_end:
                        guard.check()
                        sleep(settings.poll_interval)
                        final = {d: int(clients[d].get("PX")) for d in drives}
                trace.add(clock() - t0, final)
            if recorded is not None:
                recorded.collect()  # the recorder has stopped and put the PDO settings back
            box.update(final=final, trace=trace)
            if request.hold and not result.breaches:
                # after the pair start's exit (its stop frames went out, its RAM is back) and the
                # recording: the hold is no part of the move's trace
                box["final"] = _hold(guard, refs, clients, watched, settings, clock, sleep, result, on_progress)

    try:
        with contextlib.ExitStack() as recs_stack:
            if drive_recs is not None:
                recs_stack.enter_context(drive_recs)  # the recorder settings back on every way out
            moving()
            if drive_recs is not None:
                # the guard has stopped the motors (on every way out of moving()) before the uploads
                drive_rec = drive_recs.collect()
    except BaseException as exc:
        carried = with_report(exc, guard.report)  # the CLI shows how the guard stopped the motors
        if carried is exc:
            raise
        raise carried from exc
    final, trace = box["final"], box["trace"]
    result.motors_end = final
    result.end = diffpair.to_joints(final[pair.drive_a], final[pair.drive_b])
    result.samples = list(trace.samples)
    if rec_plan is not None:
        # the coupling figures from the drives' own recordings (t = 0: the move's BG), up to where the
        # move's loop read the final positions
        until = trace.samples[-1][0] if trace.samples else None
        assert drive_rec is not None  # record_drives returned
        result.samples = recorder_samples(drive_rec.recording, drives, until=until)
        result.trace_source = (f"drive recorders at {1 / drive_rec.period_s:.0f} Hz (sample time "
                               f"{rec_settings.sample_time_s * 1e6:.0f} us, RG={drive_rec.plan.gap})")
    result.coupling = measure_coupling(result.samples, p.start, p.target, sigma_name=pair.sigma,
                                       delta_name=pair.delta, sigma_cpr=sj.cpr, delta_cpr=dj.cpr,
                                       held=pair.delta if request.delta is None else
                                       pair.sigma if request.sigma is None else None)
    result.guard_lines = guard.report.lines()
    result.stop = guard.report.as_json()
    return result


def _hold(guard: MotionGuard, refs: Sequence[DriveRef], clients: Mapping[str, DriveClient], watched: Sequence[Axis],
          settings: MotionSettings, clock: Callable[[], float], sleep: Callable[[float], None],
          result: MoveResult, on_progress: Callable[[Mapping[str, int]], None] | None) -> dict[str, int]:
    """--hold: both motors hold where the move ended (motion/hold.py), the limit watch of Σ and Δ on,
    until Ctrl-C (raised) or `sherpa stop`. Returns the motors' positions at its end."""
    result.held_at = hold.hold_in_place(guard, refs, settings=settings, clock=clock, sleep=sleep, stop=False)

    def sample() -> dict[str, int]:
        motors = {r.name: int(guard.query(r, "PX")) for r in refs}
        if on_progress is not None:
            on_progress({j.name: j.position(motors) for j in watched})
        return motors

    def watch() -> bool:
        breaches = limit_watch.check(watched, sample())
        if not breaches:
            return False
        result.outcome = "limit"
        result.breaches = list(breaches)
        recovery.recover(guard, {r.name: r for r in refs}, clients, watched, breaches, sample, settings=settings,
                         clock=clock, sleep=sleep, hold={}, speed=recovery.recovery_speed(settings, watched))
        return True

    result.held_until = hold.hold_until_released(guard, refs, settings=settings, sleep=sleep, watch=watch) or ""
    return sample()


# --------------------------------------------------------------------------- plot

def plot(result: MoveResult, path: str) -> Figure:
    """Both joints over time (rad), like the seed's Figs. 9.10/9.11 (log/plot.py plot_pair: the
    held joint with a span of at least HELD_SPAN_COUNTS and its peak excursion marked)."""
    from sherpa_cli.log.plot import PairTrace, plot_pair

    c = result.coupling
    held = c.held if c is not None else None
    held_cpr = (result.sigma_cpr if held == result.sigma else result.delta_cpr) if held else result.sigma_cpr
    trace = PairTrace(
        result.pair, result.sigma, result.delta, [s[0] for s in result.samples],
        [units.counts_to_rad(s[1] + s[2], result.sigma_cpr) for s in result.samples],
        [units.counts_to_rad(s[1] - s[2], result.delta_cpr) for s in result.samples],
        units.counts_to_rad(result.target[0], result.sigma_cpr), units.counts_to_rad(result.target[1], result.delta_cpr),
        held=held, held_excursion=units.counts_to_rad(c.held_peak, held_cpr) if c is not None and held else 0.0,
        held_span=units.counts_to_rad(HELD_SPAN_COUNTS, held_cpr),
        subtitle=result.mode + (", feedback" if result.feedback else ""))
    return plot_pair(trace, path)


HELD_SPAN_COUNTS = 20  # the held joint's plot shows at least this many counts: quantisation stays small
