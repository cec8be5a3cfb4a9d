"""A live jog session: the ops layer under `sherpa jog --interactive` and `sherpa jog --joystick`
(docs/jog.md). One motion guard (motion/guard.py) around every motor of the chosen joints, the same
joint limits, limit watch and recovery as `sherpa jog` (motion/limit_watch.py, motion/recovery.py), and small
commands a user interface calls as keys are pressed or a joystick moves:

- :meth:`LiveJog.step` moves a joint by N counts (position mode, only to a target inside the
  joint's normal range, only when the joint is calibrated unless ``allow_uncalibrated``);
- :meth:`LiveJog.set_velocity` / :meth:`LiveJog.set_torque` run a joint at a speed or current
  (in joint space; a Σ/Δ joint through the pair's inverse transform) **until** ``keepalive`` s
  without a new command: no terminal sees a key release, and a joystick reader that hangs must
  not leave a motor running, so every velocity and torque command expires by itself;
- :meth:`LiveJog.set_motor_velocities` / :meth:`LiveJog.set_motor_currents` drive the motors of a
  pair directly (a joystick's XY+ / XY- mapping);
- :meth:`LiveJog.stop` / :meth:`LiveJog.stop_all` stop now;
- :meth:`LiveJog.tick` must be called often (every 0.1 s or faster): it is the guard's sign of
  life, samples every position, stops expired commands, holds a joint at the edge of its normal
  range (a command driving it further out is not sent), runs the full-range watch (a breach
  stops everything and brings the joint back to its normal edge, like `jog`) and the stall watch
  (motion/blocked.py, as every mover: a velocity or torque command that makes no progress for
  ``motion.stall_time`` -- an end switch pressed, a jam -- is stopped and called "blocked", naming the
  active switch; the same command is not sent again until the keys or the stick let go of it).

Leaving the ``with`` block (``q``, Ctrl-C, an error) leaves the guard: every motor stopped,
switched off, what was changed put back.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING

from sherpa_cli.bus import targets
from sherpa_cli.config.model import ArmConfig, JointConfig, JointRole
from sherpa_cli.elmo.faults import decode_sr, describe_mf, describe_sr, sr_problems
from sherpa_cli.elmo.protocol import UM_POSITION, UM_TORQUE
from sherpa_cli.errors import ExitCode, SafetyError, SherpaError, UsageError
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.motion import calibration, limit_watch, recovery
from sherpa_cli.motion.axis import Axis, joint_axis, joints_moved_by, profile_speed, speed_refusal
from sherpa_cli.motion.blocked import StallWatch, blocked_text
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.report import GuardReport
from sherpa_cli.motion.settings import MotionSettings

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.ops.home import HomePlan, HomeReport

MODES = ("position", "velocity", "torque")


class HomingAborted(SherpaError):
    """The calibrate key's homing was aborted (Space, q, Ctrl-C in the view); its guard stopped it."""

    exit_code = ExitCode.INTERRUPTED

KEEPALIVE_S = 0.5  # a velocity/torque command stops this long after the last key press


def resolve_axes(cfg: ArmConfig, names: Sequence[str] | None) -> list[Axis]:
    """The joints named (a pair means both its joints), or every joint of the config."""
    chosen: list[JointConfig] = []
    if not names:
        chosen = list(cfg.joints.values())
    for text in names or ():
        t = targets.resolve_one(cfg, text)
        joints = [j for j in t.joints if j.role is not JointRole.PLAIN or j.drive is not None]
        if t.pair is not None and t.kind is not targets.TargetKind.JOINT:
            joints = [cfg.joints[t.pair.sigma], cfg.joints[t.pair.delta]]
        if not joints:
            raise UsageError(f"'{text}' moves no configured joint", hint="name a joint, a pair or a drive of the config")
        chosen += [j for j in joints if j not in chosen]
    return [joint_axis(cfg, j) for j in chosen]


@dataclass
class AxisState:
    """What the view shows of one joint."""

    name: str
    counts: int | None = None
    rad: float | None = None
    mode: str = "position"
    command: str = "-"  # what runs now: "-", "PA=...", "JV=...", "TC=..."
    calibrated: bool = False
    calibration: str = ""
    faults: list[str] = field(default_factory=list)
    note: str = ""  # the last refusal or limit message for this joint


@dataclass(frozen=True)
class DriveStatus:
    """One drive's answer to Get Status: OK or Fail with why, and the decoded SR/MF on request."""

    drive: str
    ok: bool
    sr: int
    mf: int
    problems: list[str]  # why it fails (empty: OK)
    details: list[str]  # every fact SR and MF state


@dataclass
class _Running:
    mode: str  # velocity | torque | position
    motors: dict[str, float]  # JV (counts/s) or TC (A) per drive; position: PA
    until: float | None  # clock time it expires (velocity/torque)


@dataclass
class _Blocked:
    """A velocity/torque command the stall watch stopped: the same direction is refused until
    ``until`` (pushed on by every refused repeat, so a held key or stick stays refused)."""

    direction: dict[str, int]  # sign per motor of the blocked command
    until: float
    text: str


def _direction(motors: Mapping[str, float]) -> dict[str, int]:
    return {d: (v > 0) - (v < 0) for d, v in motors.items()}


class LiveJog:
    """``with LiveJog(session, axes) as live:`` -- see the module docstring."""

    def __init__(self, session: ArmSession, axes: Sequence[Axis], *, settings: MotionSettings | None = None,
                 keepalive: float = KEEPALIVE_S, allow_uncalibrated: bool = False, tick_period: float = 0.1,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 on_event: Callable[[str], None] | None = None) -> None:
        if not axes:
            raise UsageError("nothing to jog: the config has no joints")
        self.session = session
        self.cfg: ArmConfig = session.cfg
        self.axes = {a.name: a for a in axes}
        drives: list[str] = []
        for a in axes:
            drives += [d for d in a.drives if d not in drives]
        self.drives = tuple(drives)
        self.refs = {d: targets.drive_ref(self.cfg, d) for d in drives}
        # every joint these motors move (a Σ joint alone still moves Δ): the watch covers them all
        self.watched = joints_moved_by(self.cfg, drives)
        self.settings = settings or MotionSettings.from_config(self.cfg, {r.bus for r in self.refs.values()})
        self.keepalive = keepalive
        self.tick_period = tick_period  # how often the caller ticks (the edge hold looks this far ahead)
        self.allow_uncalibrated = allow_uncalibrated
        self.clock, self.sleep = clock, sleep
        self.guard = MotionGuard(session, list(self.refs.values()), settings=self.settings, clock=clock,
                                 sleep=sleep, on_event=on_event)
        self.state = {a.name: AxisState(a.name) for a in axes}
        self.motors: dict[str, int] = {}
        self.running: dict[str, _Running] = {}  # per axis
        self.stalls: dict[str, tuple[dict[str, int], StallWatch]] = {}  # per running velocity/torque axis
        self.blocked: dict[str, _Blocked] = {}  # per axis: a command the stall watch stopped
        self.messages: list[str] = []  # limit breaches and recoveries, oldest first
        self.dead: dict[str, str] = {}  # drive -> why it must not be commanded again in this session
        self.moved: set[str] = set()  # drives this session sent a motion command to
        self.outside: set[str] = set()  # joints found outside their full range, not by this session's motion
        self.unguarded: set[str] = set()  # drives the guard could not take back after homing (read raw)

    # -- context ---------------------------------------------------------------------------------

    def __enter__(self) -> LiveJog:
        self._read_calibration(list(self.axes.values()))  # first: nothing is armed if it cannot be read
        self.guard.__enter__()
        try:
            self.tick()
        except BaseException as exc:
            self.guard.__exit__(type(exc), exc, exc.__traceback__)  # the stop says why (error, Ctrl-C)
            raise
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> bool:
        self.running.clear()
        return self.guard.__exit__(exc_type, exc, tb)

    @property
    def report(self) -> GuardReport:
        return self.guard.report

    def _raw(self, drive: str) -> DriveClient:
        c = self.session.client(self.refs[drive])
        c.nmt_start()
        return c

    def _client(self, drive: str) -> DriveClient:
        return self.guard.client(self.refs[drive])

    # -- commands ----------------------------------------------------------------------------------

    def set_mode(self, name: str, mode: str) -> None:
        """The mode the next command of this joint uses; what runs is stopped first."""
        if mode not in MODES:
            raise UsageError(f"mode '{mode}': expected one of {', '.join(MODES)}")
        self.stop(name)
        self.state[name].mode = mode

    def step(self, name: str, counts: int, *, to: int | None = None) -> str:
        """Position mode: move the joint by ``counts`` (the other joint of a pair holds); ``to``: to
        that position instead (counts, absolute: a typed set point)."""
        a = self._axis(name)
        st = self.state[name]
        if not (st.calibrated or self.allow_uncalibrated):
            return self._refuse(name, f"{name} is {st.calibration}: position steps need a calibrated joint "
                                      "(home it, or start with --uncalibrated)")
        self.guard.check()
        now = self._sample(a.drives)
        start = a.position(now)
        base = self.running[name].motors.get("target", start) if name in self.running and \
            self.running[name].mode == "position" else start
        goal = int(to) if to is not None else int(base) + int(counts)
        assert a.normal is not None  # a joint's axis (resolve_axes) has its ranges
        lo, hi = a.normal
        if not lo <= goal <= hi:
            return self._refuse(name, f"{name}: target {goal} counts is outside the normal range [{lo}, {hi}]: "
                                      "not sent")
        # the other joint of a pair holds; on a parity clash it gives way by one count inside its
        # normal range (Axis.motor_targets, the same map as `jog`)
        other = next((j for j in joints_moved_by(self.cfg, a.drives) if j.name != a.name), None)
        motor_targets = a.motor_targets(goal, now, other.normal if other is not None and a.is_pair_joint else None)
        # half the joint's speed (motion/axis.profile_speed), never the SP the drive holds
        speed = max(1, profile_speed(a, self.settings.recovery_fallback_speed) // 2)
        distance = max(abs(t - now[d]) for d, t in motor_targets.items())
        duration = distance / speed if distance else 0.0
        self._stop_others_on(a.drives, name)
        self.stalls.pop(name, None)  # a position step ends at its target: no progress there is no stall
        # on record before the first write: a command that fails half-way is still stopped
        self.running[name] = _Running("position", {"target": goal, **motor_targets}, None)
        self.moved.update(motor_targets)
        for d, t in motor_targets.items():
            self._enable(d, UM_POSITION)
            c = self._client(d)
            c.set("SP", 0, max(1, math.ceil(abs(t - now[d]) / duration)) if duration else speed)
            c.set("PA", 0, t)
        for d in motor_targets:
            self._client(d).execute("BG")
        st.command = f"PA -> {goal}"
        st.note = ""
        return f"{name}: to {goal} counts"

    def set_velocity(self, name: str, counts_per_s: int) -> str:
        """Run the joint at ``counts_per_s`` until ``keepalive`` s without a new command (0 stops)."""
        a = self._axis(name)
        v = int(counts_per_s)
        refusal = speed_refusal(a, v, "the set point")  # as on the command line (jog --velocity)
        if refusal is not None:
            return self._refuse(name, f"{refusal.message}: not sent")
        return self._run(name, "velocity", a.motor_velocities(v))

    def set_torque(self, name: str, amps: float) -> str:
        """Apply ``amps`` (per joint; a Σ/Δ joint through the pair's transpose) until ``keepalive`` s pass."""
        a = self._axis(name)
        motors = a.motor_currents(amps)
        if a.current_limit is None:
            return self._refuse(name, f"{name}: no current limits configured: torque not sent")
        if max(abs(x) for x in motors.values()) > a.current_limit:
            return self._refuse(name, f"{name}: {amps:g} A is above the continuous limit {a.current_limit:g} A: "
                                      "not sent")
        return self._run(name, "torque", motors)

    def set_motor_velocities(self, pair_axis: str, motors: Mapping[str, int]) -> str:
        """Both motors of a pair at the given speeds (counts/s), e.g. X+Y and X-Y of a joystick.
        Scaled down together when a joint of the pair would exceed its speed limit."""
        a = self._axis(pair_axis)
        va, vb = (int(motors[d]) for d in a.drives)
        scale = 1.0
        for j in self._pair_axes(a):
            jv = va + vb if j.kind == "sigma" else va - vb
            if j.vel_limit and abs(jv) > j.vel_limit:
                scale = min(scale, j.vel_limit / abs(jv))
        if scale < 1.0:
            va, vb = int(va * scale), int(vb * scale)
        return self._run(pair_axis, "velocity", dict(zip(a.drives, (va, vb), strict=True)))

    def set_motor_currents(self, pair_axis: str, motors: Mapping[str, float]) -> str:
        """Both motors of a pair at the given currents (A), each clamped to the continuous limit."""
        a = self._axis(pair_axis)
        lim = a.current_limit
        if lim is None:
            return self._refuse(pair_axis, f"{pair_axis}: no current limits configured: torque not sent")
        out = {d: max(-lim, min(lim, float(motors[d]))) for d in a.drives}
        return self._run(pair_axis, "torque", out)

    def stop(self, name: str) -> None:
        a = self._axis(name)
        run = self.running.pop(name, None)
        self.stalls.pop(name, None)
        drives = [d for d in a.drives if d not in self.dead]
        if run is not None and drives:
            self.guard.check()
            recovery.stop_now({d: self._client(d) for d in drives}, run.mode, self.settings.stop_method)
        self.state[name].command = "-"

    def stop_all(self) -> None:
        """Stop every live drive this session has commanded, not only the commands on record: a motor
        started by a command that failed half-way is stopped too. A drive never commanded
        gets nothing (whether a drive takes ST with its motor off is not confirmed)."""
        self.running.clear()
        self.stalls.clear()
        for name in self.state:
            self.state[name].command = "-"
        live = [d for d in self.drives if d not in self.dead and d in self.moved]
        if live:
            self.guard.check()
        for d in live:
            recovery.stop_now({d: self._client(d)},
                               "torque" if self.guard.unit_mode(self.refs[d]) == UM_TORQUE else "position",
                               self.settings.stop_method)

    def status(self, name: str) -> list[DriveStatus]:
        """Get Status (the seed GUI's button): SR and MF of the joint's drives, read now. OK when no SR
        problem, no motor failure and the drive is still commanded in this session."""
        out = []
        for d in self._axis(name).drives:
            q = (lambda key, d=d: self._raw(d).get(key)) if d in self.unguarded else \
                (lambda key, d=d: self.guard.query(self.refs[d], key))
            sr, mf = int(q("SR")), int(q("MF"))
            problems = [f.line() for f in sr_problems(sr) if f.code != 1 << 28]
            fails = problems + describe_mf(mf) + ([f"not commanded again: {self.dead[d]}"] if d in self.dead else [])
            out.append(DriveStatus(d, not fails, sr, mf, fails, describe_sr(sr) + (describe_mf(mf) or ["MF: none"])))
        return out

    # -- calibrate (home) ----------------------------------------------------------------------------

    def home_plan(self, name: str) -> HomePlan:
        """What the calibrate key would do for this joint: ops/home.plan_home of it (a Σ or Δ joint
        homes its pair as one unit). A joint that cannot be homed is a UsageError saying why."""
        from sherpa_cli.ops import home

        self._axis(name)
        plan = home.plan_home(self.cfg, [name])
        missing = sorted({d for u in plan.units for d in u.drives} - set(self.drives))
        if missing:
            raise UsageError(f"{name}: homing it moves {', '.join(missing)}, not part of this session",
                             hint="start the view with every joint of the pair")
        return plan

    def calibrate(self, name: str, *, abort: Callable[[], bool] = lambda: False,
                  on_event: Callable[[str], None] | None = None) -> HomeReport:
        """Home the joint (its pair as one unit) with ops/home.run_home and take it back.

        Every running command stops first (nothing ticks while homing runs). The unit's drives leave
        this session's motion guard (stopped, motor off if it switched it on, dead-man put back):
        `home` guards them itself, and two guards on one drive would fight over the dead-man. The
        other drives stay guarded; homing's waits are their sign of life. ``abort()`` true ends the
        homing at its next wait (its own guard stops the motors). Afterwards the drives are guarded
        again (a drive in fault is refused and not commanded again) and the calibration re-read.
        Returns the HomeReport; raises what homing raised."""
        from sherpa_cli.ops import home

        plan = self.home_plan(name)
        drives = [d for d in self.drives if any(d in u.drives for u in plan.units)]
        refs = [self.refs[d] for d in drives]
        self.stop_all()
        released = self.guard.release(refs)
        self.moved -= set(drives)  # stopped and off now: STOP ALL has nothing to send them until commanded
        if on_event is not None:
            for r in released:
                on_event(f"stop: {r.line()}")

        # the other drives' dead-man goes on while homing runs: each of home's waits is a sign of life
        # lasting one of its guard's longest steps without a wait (its entry, a motor-on confirmation)
        s = self.settings
        mo_confirm = max(self.session.client(r).settings.mo_confirm_timeout for r in refs)
        allowance = 12 * s.request_bound * len(refs) + 3.0 + mo_confirm + 2 * s.request_bound

        def sleep(seconds: float) -> None:
            self.guard.keep_alive(allowance)
            if abort():
                raise HomingAborted(f"{name}: homing aborted: every motor of it stopped")
            self.sleep(seconds)

        try:
            self.guard.keep_alive(allowance)
            report = home.run_home(self.session, plan, settings=self.settings, clock=self.clock, sleep=sleep)
        except BaseException as exc:
            # where homing left the joint its counter means nothing (a search stopped at its bound reads
            # outside the range): the limit watch must not "bring it back", nothing may command it
            why = "homing aborted" if isinstance(exc, HomingAborted) else f"homing failed: {exc}"
            for d in drives:
                self.dead.setdefault(d, why)
            self.messages.append(f"{', '.join(drives)}: {why}; not commanded again in this session "
                                 "(leave with q, find the cause, home again)")
            raise
        finally:
            try:
                self.guard.adopt(refs)
            except Exception as exc:  # noqa: BLE001 - recorded: its drives are not commanded again in this session
                for d in drives:
                    self.unguarded.add(d)
                    if d not in self.dead:
                        self.dead[d] = f"not guarded again after homing: {exc}"
                self.messages.append(f"{', '.join(drives)}: not guarded again after homing ({exc}); "
                                     "not commanded again in this session")
            finally:
                self._read_calibration([a for a in self.axes.values() if set(a.drives) & set(drives)])
        return report

    def _read_calibration(self, axes: Sequence[Axis]) -> None:
        for a in axes:
            c = calibration.read_calibration(self.cfg, self._joint(a), lambda d: self._raw(d), resync=True)
            self.state[a.name].calibrated = c.calibrated
            self.state[a.name].calibration = c.reason

    # -- the periodic part ---------------------------------------------------------------------------

    def tick(self) -> dict[str, AxisState]:
        """Sign of life, positions, expiry, edge hold and the full-range watch; returns the joints' state."""
        self.guard.check()
        now = self.clock()
        for name, run in list(self.running.items()):
            if run.until is not None and now >= run.until:
                self.stop(name)
        self.blocked = {n: b for n, b in self.blocked.items() if now < b.until}  # the keys let go of it
        motors = self._sample(self.drives)
        for d in self.drives:
            if d in self.dead:
                continue
            sr = int(self.guard.query(self.refs[d], "SR"))
            s = decode_sr(sr)
            faults = [f.line() for f in sr_problems(sr) if f.code != 1 << 28]
            if not s.motor_on and self._commanded(d):
                mf = int(self.guard.query(self.refs[d], "MF"))
                why = "; ".join(describe_mf(mf)) if mf else "MO=0 from elsewhere (sherpa stop, another tool)"
                self.dead[d] = why
                for name in [n for n, a in self.axes.items() if d in a.drives]:
                    self.running.pop(name, None)
                    self.state[name].command = "-"
                self.messages.append(f"{d}: the motor was switched off: {why}; it is not commanded again "
                                     "in this session")
            for name, a in self.axes.items():
                if d in a.drives:
                    st = self.state[name]
                    st.faults = [x for x in st.faults if not x.startswith(d + ":")] + [f"{d}: {f}" for f in faults]
                    if d in self.dead:
                        st.faults.append(f"{d}: {self.dead[d]}")
        self._edge_hold(motors)
        self._stall_watch(motors)
        # a joint of a drive not commanded again (tripped, homing failed) cannot be brought back:
        # watching it would stop everything on every tick
        breaches = self._own_breaches(
            limit_watch.check([w for w in self.watched if not set(w.drives) & set(self.dead)], motors))
        if breaches:
            self._recover(motors, breaches)
            motors = self._sample(self.drives)
        for name, a in self.axes.items():
            st = self.state[name]
            st.counts = a.position(motors)
            st.rad = counts_to_rad(st.counts, self._joint(a).cpr)
            now_running = self.running.get(name)
            if now_running is not None and now_running.mode == "position" and all(
                    int(self._client(d).get("MS")) == 0 for d in a.drives if d not in self.dead):
                self.running.pop(name, None)
                st.command = "-"
        return self.state

    @property
    def deadman(self) -> str:
        s = self.settings
        return (f"dead-man: heartbeat {s.heartbeat_period * 1000:.0f} ms to every drive "
                f"(consumer {s.consumer_time_ms} ms); keys step once per press, velocity/torque stop "
                f"{self.keepalive:g} s after the last press")

    # -- internals ---------------------------------------------------------------------------------

    def _axis(self, name: str) -> Axis:
        try:
            return self.axes[name]
        except KeyError:
            raise UsageError(f"'{name}' is not a joint of this session ({', '.join(self.axes)})") from None

    @staticmethod
    def _joint(a: Axis) -> JointConfig:
        assert a.joint is not None  # the session's axes are joints (resolve_axes)
        return a.joint

    def _pair_axes(self, a: Axis) -> list[Axis]:
        out = [b for b in self.axes.values() if b.drives == a.drives]
        if a.kind == "plain":
            return [a]
        if len(out) < 2:  # the other joint of the pair is not in the session: still limit it
            for j in (self.cfg.joints[n] for n in self.cfg.joints):
                if j.pair == self._joint(a).pair and j.name != a.name:
                    out += resolve_axes(self.cfg, [j.name])
        return out

    def _refuse(self, name: str, text: str) -> str:
        self.state[name].note = text
        return text

    def _commanded(self, drive: str) -> bool:
        return any(drive in self.axes[n].drives for n in self.running)

    def _enable(self, drive: str, um: int) -> None:
        if drive in self.dead:
            raise SafetyError(f"{drive}: not commanded again in this session: {self.dead[drive]}",
                              hint="leave the view (q) and find the cause; `sherpa monitor --once`")
        self.guard.enable(self.refs[drive], um)

    def _stop_others_on(self, drives: Sequence[str], keep: str) -> None:
        """Another joint of the same motors (Σ and Δ of one pair) stops before this one is commanded."""
        for name, a in self.axes.items():
            if name != keep and name in self.running and set(a.drives) & set(drives):
                self.stop(name)

    def _run(self, name: str, mode: str, motors: Mapping[str, float]) -> str:
        a = self._axis(name)
        st = self.state[name]
        if all(v == 0 for v in motors.values()):
            self.stop(name)
            return f"{name}: stopped"
        self.guard.check()
        blocked = self._outward(motors, mode=mode)
        if blocked:
            self.stop(name)
            return self._refuse(name, blocked)
        direction = _direction(motors)
        stalled = self.blocked.get(name)
        if stalled is not None and stalled.direction == direction:
            stalled.until = self.clock() + self.keepalive
            return self._refuse(name, stalled.text)
        self.blocked.pop(name, None)
        prev = self.running.get(name)
        if prev is not None and prev.mode != mode:
            self.stop(name)
        self._stop_others_on(a.drives, name)
        um = UM_TORQUE if mode == "torque" else self.settings.velocity_unit_mode
        # on record before the first write: a command that fails half-way still expires and is
        # stopped by stop / stop_all
        self.running[name] = _Running(mode, dict(motors), self.clock() + self.keepalive)
        watching = self.stalls.get(name)
        s = self.settings
        fresh = s.torque_stall_watch() if mode == "torque" else s.stall_watch(max(abs(v) for v in motors.values()))
        if watching is None or watching[0] != direction:
            # a new direction starts a new watch; a refresh of the same command keeps it running
            self.stalls[name] = (direction, fresh)
        else:
            # ...but asks no more progress than the slowest speed since then makes (a stick eased
            # back is not a jam); a faster command does not raise it (stick jitter would reset it)
            watching[1].min_progress = min(watching[1].min_progress, fresh.min_progress)
        self.moved.update(motors)
        for d in motors:
            self._enable(d, um)
        for d, v in motors.items():
            c = self._client(d)
            if mode == "torque":
                c.set("TC", 0, float(v))
            else:
                c.set("JV", 0, int(v))
        if mode == "velocity":
            for d in motors:
                self._client(d).execute("BG")
        self.running[name].until = self.clock() + self.keepalive  # from the command, not from MO=1
        letters = "TC" if mode == "torque" else "JV"
        parts = [f"{letters}={v:g}" if isinstance(v, float) else f"{letters}={v}" for v in motors.values()]
        st.command = parts[0] if len(parts) == 1 else ", ".join(f"{d} {p}" for d, p in zip(motors, parts, strict=True))
        st.note = ""
        return f"{name}: {st.command}"

    def _outward(self, motors: Mapping[str, float], positions: Mapping[str, int] | None = None,
                 mode: str = "velocity") -> str | None:
        """A command that drives a joint at (or past) the edge of its normal range further out. In
        velocity mode the edge is met early by the distance the joint needs to stop (its configured
        decel) plus one tick of travel, so the stop lands inside the normal range."""
        pos = positions if positions is not None else self.motors
        for j in joints_moved_by(self.cfg, motors):
            if any(d not in pos for d in j.drives) or j.normal is None:
                continue
            rate = float(motors.get(j.drive_a, 0)) + (j.sign * float(motors.get(j.drive_b, 0))
                                                       if j.drive_b is not None else 0.0)
            p = float(j.position(pos))
            if mode == "velocity":
                decel = self.cfg.joints[j.name].decel
                p += rate * self.tick_period + (rate * abs(rate) / (2 * decel) if decel else 0.0)
            if (rate > 0 and p >= j.normal[1]) or (rate < 0 and p <= j.normal[0]):
                side = "high" if rate > 0 else "low"
                return (f"{j.name} is at the {side} edge of its normal range [{j.normal[0]}, {j.normal[1]}]: "
                        "a command further out is not sent")
        return None

    def _edge_hold(self, motors: Mapping[str, int]) -> None:
        for name, run in list(self.running.items()):
            if run.mode == "position":
                continue
            blocked = self._outward(run.motors, motors, run.mode)
            if blocked:
                self.stop(name)
                self._refuse(name, blocked)
                self.messages.append(blocked)

    def _stall_watch(self, motors: Mapping[str, int]) -> None:
        """A running velocity/torque command whose motors made no progress for the stall time (an end
        switch the drive stopped it at, a jam) is stopped and called blocked, naming an active switch."""
        now = self.clock()
        for name, (direction, watch) in list(self.stalls.items()):
            a = self.axes[name]
            if name not in self.running or self.running[name].mode == "position":  # ended or replaced
                del self.stalls[name]
                continue
            if not watch.feed({d: motors[d] for d in a.drives if d in motors}, now):
                continue
            self.stop(name)
            clients = {d: self._client(d) for d in a.drives if d not in self.dead}
            text = (f"{name}: {blocked_text(self.cfg, clients, clients, self.settings.stall_time)}; stopped; "
                    "not sent again until the key or the stick is let go")
            self.blocked[name] = _Blocked(direction, now + self.keepalive, text)
            self._refuse(name, text)
            self.messages.append(text)

    def _sample(self, drives: Sequence[str]) -> dict[str, int]:
        for d in drives:
            if d in self.refs and d not in self.unguarded:
                self.motors[d] = int(self.guard.query(self.refs[d], "PX"))
            else:
                self.motors[d] = int(self._raw(d).get("PX"))
        return dict(self.motors)

    def _own_breaches(self, breaches: Sequence[limit_watch.Breach]) -> list[limit_watch.Breach]:
        """The breaches this session's motion made: only those are brought back. A joint
        found outside its full range with no command of this session on its motors (uncalibrated at
        power-up, pushed by hand) is reported once and left where it is; commands further out are
        not sent (the edge hold), commands back inward are, and once inside it is watched as usual."""
        self.outside &= {b.joint for b in breaches}
        own = []
        for b in breaches:
            drives = next(j.drives for j in self.watched if j.name == b.joint)
            if b.joint not in self.outside and self.moved & set(drives):
                own.append(b)
            elif b.joint not in self.outside:
                self.outside.add(b.joint)
                text = (f"limit: {b.joint} is outside its full range [{b.full[0]}, {b.full[1]}] at {b.position} "
                        "counts, not moved there by this session: not brought back; a command further out is "
                        "not sent")
                self.messages.append(text)
                if b.joint in self.state:
                    self.state[b.joint].note = text
        return own

    def _recover(self, motors: Mapping[str, int], breaches: Sequence[limit_watch.Breach]) -> None:
        """Like `jog`: stop every motor at once, then bring the breached joints back to their normal edge."""
        modes = {run.mode for run in self.running.values()}
        self.running.clear()
        self.stalls.clear()
        live = {d: self._client(d) for d in self.drives if d not in self.dead}
        recovery.recover(self.guard, self.refs, live, self.watched, breaches, lambda: self._sample(self.drives),
                         settings=self.settings, clock=self.clock, sleep=self.sleep, torque="torque" in modes,
                         speed=recovery.recovery_speed(self.settings, self.axes.values()))
        for b in breaches:
            text = (f"limit: {b.joint} left its full range [{b.full[0]}, {b.full[1]}] on the {b.side} side: "
                    f"stopped everything, brought back to {b.back_to} counts")
            self.messages.append(text)
            if b.joint in self.state:
                self.state[b.joint].note = text
        for st in self.state.values():
            st.command = "-"
