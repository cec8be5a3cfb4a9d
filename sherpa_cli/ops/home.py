"""`sherpa home`: calibrate joints (seed Table 4.2, Appendix C/D; docs/home.md).

Four kinds, chosen from the config:

- ``home_switch``: a position switch inside the range (Example 2). A bounded search (PR of the full
  range plus a margin, never an open-ended JV) at ``cal_speed`` with the drive's homing armed
  (HM[3] = the switch's input, HM[4] = stop, HM[5] = absolute, HM[2] = ``cal_pos``); back off;
  a slow re-approach with the homing armed again (HM[4] = nothing, so the move runs its full PR)
  gives the repeat difference: how far the first pass's counter was off at the second edge.
- ``end_switches``: the stop switch on the side ``cal_speed`` points to (Example 1); PX = ``cal_pos``
  (else that end of the range) at its edge; back into the normal range. ``measure_range`` also
  drives to the other end switch and reports the measured travel.
- ``pair``: a differential pair (Example 3), both motors together through the pair transform. Σ:
  fast search, back off, slow re-approach with both PX := 0 at its edge (the Σ reference); back off;
  Δ (Σ held): fast search, back off, slow re-approach that only stops at the edge; then both
  counters are set by an immediate home event so that (PX_a + PX_b, PX_a - PX_b) = (Σ, Δ).
- ``abs_encoder``: no motion: read the encoder, set PX from it by an immediate home event.

After success each drive gets the calibration mark (motion/calibration.mark_calibrated). Every motion
runs inside the motion guard (fault check, dead-man, stop on every exit path).

``plan_home`` needs only the config; ``run_home`` takes an open session and returns a
:class:`HomeReport`. Both are what the interactive view's "calibrate" key calls.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, Literal

from sherpa_cli.bus import journal
from sherpa_cli.bus.targets import DriveRef, drive_ref
from sherpa_cli.config.model import ArmConfig, JointConfig, JointRole, SwitchConfig, SwitchKind
from sherpa_cli.elmo.faults import describe_mf, fault_reason
from sherpa_cli.elmo.protocol import UM_POSITION
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.motion import calibration
from sherpa_cli.motion.axis import move_time_bound
from sherpa_cli.motion.blocked import blocked_text
from sherpa_cli.motion.guard import MotionGuard
from sherpa_cli.motion.report import GuardReport
from sherpa_cli.motion.settings import MotionSettings

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient

KINDS = ("home_switch", "end_switches", "pair", "abs_encoder")

log = logging.getLogger(__name__)


# -- the plan ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class HomeMove:
    """One bounded motion of the plan, in joint counts."""

    joint: str
    what: str  # "search", "back off", "slow re-approach", "measure", "return"
    direction: int  # +1 / -1
    speed: int  # joint counts/s
    max_distance: int  # joint counts

    def as_dict(self) -> dict[str, Any]:
        return {"joint": self.joint, "what": self.what, "direction": self.direction, "speed": self.speed,
                "max_distance": self.max_distance}


@dataclass(frozen=True)
class HomeUnit:
    """What is homed as one: a plain joint or a pair (its Σ and Δ joints)."""

    name: str
    kind: str
    joints: tuple[str, ...]
    drives: tuple[str, ...]
    moves: tuple[HomeMove, ...]
    switches: tuple[str, ...]  # "input 1 (home at 0)" per switch used, for the plan
    devices: tuple[str, ...] = ()  # other devices it reads (a CANopen encoder of `devices:`)

    def as_dict(self) -> dict[str, Any]:
        out = {"name": self.name, "kind": self.kind, "joints": list(self.joints), "drives": list(self.drives),
               "switches": list(self.switches), "moves": [m.as_dict() for m in self.moves]}
        if self.devices:
            out["devices"] = list(self.devices)
        return out


@dataclass(frozen=True)
class HomePlan:
    units: tuple[HomeUnit, ...]
    skipped: tuple[tuple[str, str], ...] = ()  # (joint, why) of joints nothing can home
    measure_range: bool = False

    @property
    def moves(self) -> bool:
        return any(u.moves for u in self.units)

    def as_dict(self) -> dict[str, Any]:
        return {"units": [u.as_dict() for u in self.units],
                "skipped": [{"joint": j, "why": w} for j, w in self.skipped], "measure_range": self.measure_range}


def _sign(x: int) -> int:
    return 1 if x > 0 else -1


def _backoff(cfg: ArmConfig, joint: JointConfig) -> int:
    return cfg.homing.backoff or max(10, joint.margin)


def _search_distance(cfg: ArmConfig, joint: JointConfig) -> int:
    lo, hi = joint.full_range
    return hi - lo + (cfg.homing.search_margin or max(10, joint.margin))


def _slow(cfg: ArmConfig, speed: int) -> int:
    return max(1, abs(speed) // max(1, cfg.homing.slow_divisor))


def cal_position(joint: JointConfig, side: int) -> int:
    if joint.cal_pos is not None:
        return joint.cal_pos
    return joint.pos_min if side < 0 else joint.pos_max


def _stop_switch(joint: JointConfig, side: int) -> SwitchConfig | None:
    want = "low" if side < 0 else "high"
    for sw in joint.switches:
        if sw.kind is SwitchKind.STOP and (sw.side == want or (sw.side is None and _sign(sw.position) == side)):
            return sw
    return None


def _home_switch(joint: JointConfig) -> SwitchConfig | None:
    return next((sw for sw in joint.switches if sw.kind is SwitchKind.HOME), None)


def _plain_unit(cfg: ArmConfig, joint: JointConfig, measure_range: bool) -> HomeUnit | str:
    assert joint.drive is not None
    drive = cfg.drives.get(joint.drive)
    kind = "elmo" if drive is None else drive.type
    if kind != "elmo":  # the homing switches, HM and the calibration flag are Elmo's
        return f"its drive {joint.drive} is a {kind} drive: sherpa homes joints on Elmo drives (docs/drives.md)"
    if joint.abs_encoder is not None:
        enc = joint.abs_encoder
        if enc.source.upper() == "DRIVE:PY":
            return HomeUnit(joint.name, "abs_encoder", (joint.name,), (joint.drive,), (),
                            (f"encoder {enc.source} (offset {enc.offset})",))
        dev = cfg.device_by_source(enc.source)
        if dev is None:
            return f"abs_encoder source '{enc.source}' is neither drive:PY nor a configured device"
        return HomeUnit(joint.name, "abs_encoder", (joint.name,), (joint.drive,), (),
                        (f"encoder {dev.name} ({dev.type} {dev.address}, 0x6004 "
                         f"{'by SDO' if dev.position_from == 'sdo' else 'from TPDO1, SDO as fallback'}, "
                         f"offset {enc.offset})",),
                        (dev.name,))
    if not joint.cal_speed:
        return "no calibration speed (calibration: {speed: ...})"
    d = _sign(joint.cal_speed)
    speed = abs(joint.cal_speed)
    home = _home_switch(joint)
    if home is not None:
        pos = joint.cal_pos if joint.cal_pos is not None else home.position
        b = _backoff(cfg, joint)
        steps = (HomeMove(joint.name, "search", d, speed, _search_distance(cfg, joint)),
                 HomeMove(joint.name, "back off", -d, speed, b),
                 HomeMove(joint.name, "slow re-approach", d, _slow(cfg, speed), 2 * b),
                 HomeMove(joint.name, "return", -d, speed, b))
        return HomeUnit(joint.name, "home_switch", (joint.name,), (joint.drive,), steps,
                        (f"input {home.input}: home switch, PX = {pos} at its edge",))
    sw = _stop_switch(joint, d)
    if sw is None:
        return f"no home switch and no {'low' if d < 0 else 'high'} end switch (the side calibration.speed points to)"
    pos = cal_position(joint, d)
    moves: list[HomeMove] = [HomeMove(joint.name, "search", d, speed, _search_distance(cfg, joint))]
    used = [f"input {sw.input}: {'low' if d < 0 else 'high'} end switch, PX = {pos} at its edge"]
    if measure_range:
        other = _stop_switch(joint, -d)
        if other is None:
            return f"--measure-range needs the {'high' if d < 0 else 'low'} end switch too"
        moves.append(HomeMove(joint.name, "measure", -d, speed, _search_distance(cfg, joint)))
        used.append(f"input {other.input}: {'high' if d < 0 else 'low'} end switch (measured)")
    moves.append(HomeMove(joint.name, "return", -d if not measure_range else d, speed, _search_distance(cfg, joint)))
    return HomeUnit(joint.name, "end_switches", (joint.name,), (joint.drive,), tuple(moves), tuple(used))


def _pair_unit(cfg: ArmConfig, pair_name: str) -> HomeUnit | str:
    pair = cfg.pairs[pair_name]
    s, dl = cfg.joints[pair.sigma], cfg.joints[pair.delta]
    drives = (pair.drive_a, pair.drive_b)
    if s.abs_encoder is not None and dl.abs_encoder is not None:
        return HomeUnit(pair.name, "abs_encoder", (s.name, dl.name), drives, (),
                        (f"encoders {s.abs_encoder.source}, {dl.abs_encoder.source}",))
    moves, used = [], []
    for joint in (s, dl):
        if not joint.cal_speed:
            return f"{joint.name} has no calibration speed (calibration: {{speed: ...}})"
        d = _sign(joint.cal_speed)
        sw = _stop_switch(joint, d) or _home_switch(joint)
        if sw is None:
            return f"{joint.name} has no switch on the side its calibration.speed points to"
        if sw.drives and set(sw.drives) != set(drives):
            return f"{joint.name}'s switch (input {sw.input}) must be wired to both drives of the pair"
        pos = cal_position(joint, d) if sw.kind is SwitchKind.STOP else (
            joint.cal_pos if joint.cal_pos is not None else sw.position)
        speed, back = abs(joint.cal_speed), _backoff(cfg, joint)
        moves.append(HomeMove(joint.name, "search", d, speed, _search_distance(cfg, joint)))
        moves.append(HomeMove(joint.name, "back off", -d, speed, back))
        moves.append(HomeMove(joint.name, "slow re-approach", d, _slow(cfg, speed), 2 * back + 2))
        if joint is s:
            moves.append(HomeMove(joint.name, "back off", -d, speed, back))
        used.append(f"input {sw.input}: {joint.name} switch, {joint.name} = {pos} at its edge")
    for joint in (s, dl):
        moves.append(HomeMove(joint.name, "return", -_sign(joint.cal_speed or 1), abs(joint.cal_speed or 1),
                              _backoff(cfg, joint) + joint.margin))
    return HomeUnit(pair.name, "pair", (s.name, dl.name), drives, tuple(moves), tuple(used))


def plan_home(cfg: ArmConfig, names: Sequence[str] | None = None, *, measure_range: bool = False) -> HomePlan:
    """What `home` would do. ``names``: joints, pairs, Σ/Δ joints or drives; default every joint
    that can be homed (pairs as one unit). A named joint that cannot be homed is a UsageError."""
    from sherpa_cli.bus import targets

    wanted: list[tuple[str, str]] = []  # ("joint"|"pair", name) in order
    if names:
        for text in names:
            t = targets.resolve_one(cfg, text)
            if t.pair is not None:
                wanted.append(("pair", t.pair.name))
            elif t.joints:
                wanted.extend(("joint", j.name) for j in t.joints)
            else:
                raise UsageError(f"{text}: no joint to home (a drive that moves no configured joint)")
    else:
        for j in cfg.joints.values():
            wanted.append(("pair", j.pair) if j.role is not JointRole.PLAIN else ("joint", j.name))  # type: ignore[arg-type]
    units: list[HomeUnit] = []
    skipped: list[tuple[str, str]] = []
    seen: set[tuple[str, str]] = set()
    for kind, name in wanted:
        if (kind, name) in seen:
            continue
        seen.add((kind, name))
        unit = _pair_unit(cfg, name) if kind == "pair" else _plain_unit(cfg, cfg.joints[name], measure_range)
        if isinstance(unit, str):
            if names:
                raise UsageError(f"{name}: cannot be homed: {unit}",
                                 hint="docs/home.md lists what each kind of joint needs in the config")
            skipped.append((name, unit))
        else:
            units.append(unit)
    return HomePlan(tuple(units), tuple(skipped), measure_range)


# -- the report -------------------------------------------------------------------------------------

@dataclass
class UnitResult:
    name: str
    kind: str
    drives: tuple[str, ...]
    positions: dict[str, int] = field(default_factory=dict)  # joint -> counts where it ended
    set_to: dict[str, int] = field(default_factory=dict)  # joint -> the calibration position set
    repeat_difference: int | None = None  # home_switch: counts the first pass was off at the second edge
    encoder: dict[str, int] = field(default_factory=dict)  # abs_encoder: drive -> raw encoder reading
    encoder_via: dict[str, str] = field(default_factory=dict)  # CANopen encoder -> "TPDO1" or "SDO (why)"
    measured_travel: int | None = None  # end_switches --measure-range: counts between the switch edges
    configured_travel: int | None = None
    motion_lines: list[str] = field(default_factory=list)  # the guard's stop lines
    motion_stop: dict[str, Any] = field(default_factory=dict)  # the guard's report (GuardReport.as_json)

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "kind": self.kind, "drives": list(self.drives),
                               "set_to": self.set_to, "positions": self.positions, "calibrated": True}
        if self.repeat_difference is not None:
            out["repeat_difference"] = self.repeat_difference
        if self.encoder:
            out["encoder"] = self.encoder
        if self.encoder_via:
            out["encoder_via"] = self.encoder_via
        if self.measured_travel is not None:
            out["measured_travel"] = self.measured_travel
            out["configured_travel"] = self.configured_travel
        return out


@dataclass
class HomeReport:
    units: list[UnitResult] = field(default_factory=list)
    # an interrupted or failed unit: its name, the joints it leaves un-homed (its old mark was cleared
    # before the search) and how its motion guard stopped the drives
    interrupted: str | None = None
    not_homed: list[str] = field(default_factory=list)
    stop: GuardReport | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"ok": True, "units": [u.as_dict() for u in self.units]}


# -- running ----------------------------------------------------------------------------------------

class _Disarm:
    """HM[1] = 0 on every drive whose homing a unit armed, on every exit path (end, error, Ctrl-C).
    Entered before the unit's motion guard in the same ``with``, it exits after it: the motors are
    stopped first, then the homing is put back (a restore, allowed after an error)."""

    def __init__(self, runner: _Runner) -> None:
        self.runner = runner
        self.armed: dict[str, DriveClient] = {}

    def __enter__(self) -> _Disarm:
        self.runner._armed = self.armed
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        self.runner._armed = None
        failed = []
        for label, c in self.armed.items():
            try:
                c.set("HM", 1, 0)
                journal.forget(drive_ref(self.runner.cfg, c.name), "home")
            except Exception as e:  # noqa: BLE001 - collected: every drive gets its try; raised or logged below
                failed.append(f"{label}: {e}")
        if failed and exc_type is None:
            raise SafetyError("the drive's homing could not be disarmed (HM[1]=0): " + "; ".join(failed),
                              hint="disarm it by hand (`sherpa cmd DRIVE HM[1]=0 --apply`) before jogging")
        if failed:
            log.warning("homing not disarmed (HM[1]=0): %s", "; ".join(failed))
        return False


class _Runner:
    def __init__(self, session: ArmSession, cfg: ArmConfig, settings: MotionSettings, clock: Callable[[], float],
                 sleep: Callable[[float], None]) -> None:
        self.session, self.cfg, self.settings, self.clock, self.sleep = session, cfg, settings, clock, sleep
        self.h = cfg.homing
        self._armed: dict[str, DriveClient] | None = None  # inside a unit's _Disarm: the drives whose HM[] it armed
        self.guard: MotionGuard | None = None  # the current unit's motion guard (its report after an error)
        self.on_step: Callable[[str], None] | None = None  # the step running now, with its elapsed time
        self.t_start = clock()

    # HM[] -------------------------------------------------------------------------------------
    def arm_homing(self, c: DriveClient, *, event: int, value: int, after: int, update: int | None = None) -> None:
        if self._armed is not None:
            self._armed[c.label] = c  # before the first write: a half-done arming is disarmed too
        c.set("HM", 1, 0)
        c.set("HM", 3, event)
        c.set("HM", 4, after)
        c.set("HM", 5, self.h.px_absolute if update is None else update)
        c.set("HM", 2, value)
        journal.note(drive_ref(self.cfg, c.name), journal.interp("home", "HM", 1, 0))  # before the arming
        c.set("HM", 1, 1, reads_back=lambda armed: armed in (0, 1))  # 0: its event came at once

    def input_event(self, sw: SwitchConfig) -> int:
        return self.h.event_input_base + sw.input

    # motion -----------------------------------------------------------------------------------
    def start_pr(self, guard: MotionGuard, refs: dict[str, DriveRef], distances: dict[str, int], speeds: dict[str, int]) -> None:
        for name, dist in distances.items():
            guard.enable(refs[name], UM_POSITION)
            c = guard.client(refs[name])
            c.set("SP", 0, max(1, speeds[name]))
            c.set("PR", 0, dist)
        for name in distances:
            guard.client(refs[name]).execute("BG")

    def wait(self, guard: MotionGuard, refs: dict[str, DriveRef], *, distance: int, speed: int, homing: bool,
             what: str, one_edge: Callable[[list[str], list[str]], SafetyError] | None = None) -> bool:
        """Poll until the motion ends (MS != 2 on every drive) or, with ``homing``, the home event fired
        on every drive (HM[1] reads 0). True if the event fired. A bound in time, else an error.
        ``one_edge`` (a pair's search): once some drive's event fired, the others' must fire within
        ``homing.pair_edge_window_ms``, else it raises ``one_edge(fired, not_fired)`` (the guard then
        stops every motor)."""
        bound = move_time_bound(distance, speed)  # the one move-time bound (motion/axis.py)
        t0 = self.clock()
        first_edge: float | None = None
        # a search pushing against an end stop (an interrupted search left the joint past its switch)
        # ends within motion.stall_time instead of at its time bound
        stall = self.settings.stall_watch(speed)
        while True:
            guard.check()
            if self.on_step is not None:
                self.on_step(f"{what}: {self.clock() - t0:.1f} s (homing {self.clock() - self.t_start:.1f} s)")
            on = {n: int(guard.query(r, "HM", 1)) == 0 for n, r in refs.items()} if homing else {}
            fired = homing and all(on.values())
            ms = [int(guard.query(r, "MS")) for r in refs.values()]
            self._raise_if_switched_off(guard, refs, what)
            # MS: 0 at the target, 1 stationary elsewhere (stopped by the home event or a switch), 2 moving
            if fired and all(m != 2 for m in ms):
                return True
            if all(m != 2 for m in ms):
                if homing and all(int(guard.query(r, "HM", 1)) == 0 for r in refs.values()):
                    return True
                # a drive standing short of its target whose event did not fire: stopped by another node
                if homing and any(m == 1 and not on.get(n) for n, m in zip(refs, ms, strict=True)):
                    self._stopped_short(guard, refs, what)
                return False
            if one_edge is not None and any(on.values()) and not fired:
                if first_edge is None:
                    first_edge = self.clock()
                elif self.clock() - first_edge > self.h.pair_edge_window_ms / 1000:
                    raise one_edge([n for n, v in on.items() if v], [n for n, v in on.items() if not v])
            if self.clock() - t0 > bound:
                raise SafetyError(f"{what} did not end within {bound:.1f} s",
                                  hint="check the joint; `sherpa stop` stops every drive")
            if any(m == 2 for m in ms) and stall.feed({n: int(guard.query(r, "PX")) for n, r in refs.items()},
                                                     self.clock()):
                clients = {n: guard.client(r) for n, r in refs.items()}
                raise SafetyError(f"{what}: {blocked_text(self.cfg, clients, list(refs), self.settings.stall_time)}",
                                  hint="move the joint off the stop toward its switch (`sherpa jog`), then home again")
            self.sleep(self.settings.poll_interval)

    @staticmethod
    def _raise_if_switched_off(guard: MotionGuard, refs: dict[str, DriveRef], what: str) -> None:
        for r in refs.values():
            if not int(guard.query(r, "MO")):
                mf = int(guard.query(r, "MF"))
                why = (f"MF=0x{mf:X}: " + "; ".join(describe_mf(mf)) if mf
                       else "MO=0 from elsewhere (sherpa stop, another tool)")
                raise SafetyError(f"{r.name}: the motor was switched off during {what}: {why}")

    def _stopped_short(self, guard: MotionGuard, refs: dict[str, DriveRef], what: str) -> None:
        """A search that stands short of its bound without its home event (MS 1) was stopped by
        something else: `sherpa stop` from elsewhere sends ST, waits for standstill, then MO=0, so
        its MO=0 may come a moment after the motion ended. Wait for it (standstill_timeout) and
        say so; never report the bound."""
        deadline = self.clock() + self.settings.standstill_timeout
        while True:
            guard.check()
            self._raise_if_switched_off(guard, refs, what)
            if self.clock() >= deadline:
                raise SafetyError(f"{what}: stopped short of its bound without the home event (ST from another "
                                  "node, or an end switch)",
                                  hint="check what stopped the joint (`sherpa monitor --once`), then home again")
            self.sleep(self.settings.poll_interval)

    def move_to(self, guard: MotionGuard, refs: dict[str, DriveRef], targets: dict[str, int], speed: int, what: str) -> None:
        from sherpa_cli.motion import recovery

        clients = {n: guard.client(r) for n, r in refs.items() if n in targets}
        recovery.move_to(guard, refs, clients, targets, max(1, speed), self.settings, self.clock, self.sleep, what)

    # kinds ------------------------------------------------------------------------------------
    def check_fault(self, c: DriveClient) -> None:
        c.nmt_start()
        why = fault_reason(int(c.get("MF")), int(c.get("SR")))
        if why is not None:
            raise SafetyError(f"{c.label}: refusing to home: the drive is in fault: {why}",
                              hint="clear the fault first (`sherpa cmd DRIVE MO=1 MO=0 --apply` once its cause is fixed)")

    def abs_encoder(self, unit: HomeUnit) -> UnitResult:
        res = UnitResult(unit.name, unit.kind, unit.drives)
        if len(unit.joints) != 1:
            raise UsageError(f"{unit.name}: homing a pair from absolute encoders on Σ and Δ is not supported yet")
        for jname, dname in zip(unit.joints, unit.drives, strict=True):
            joint = self.cfg.joints[jname]
            assert joint.abs_encoder is not None
            src = joint.abs_encoder.source
            c = self.session.client(drive_ref(self.cfg, dname))
            self.check_fault(c)
            if src.upper() == "DRIVE:PY":
                raw = int(c.get("PY"))
                read_from = dname
            else:
                from sherpa_cli.devices import encoder

                dev = self.cfg.device_by_source(src)
                if dev is None:
                    raise UsageError(f"{jname}: abs_encoder source '{src}' names no configured device")
                reading = encoder.read_position(self.session, dev, clock=self.clock, sleep=self.sleep)
                raw, read_from, res.encoder_via[dev.name] = reading.position, dev.name, reading.via
            value = raw + joint.abs_encoder.offset
            # the immediate event disarms itself; _Disarm still puts HM[1]=0 back and drops the journal
            # entry, or a finished home would leave an entry that refuses every later move of the joint
            with _Disarm(self):
                self.arm_homing(c, event=self.h.event_immediate, value=value, after=self.h.after_nothing)
                px = int(c.get("PX"))
                if px != value or int(c.get("HM", 1)) != 0:
                    raise SafetyError(f"{c.label}: the immediate home event did not set PX (PX={px}, wanted {value})")
            calibration.mark_calibrated(self.cfg, c)
            res.encoder[read_from], res.set_to[jname], res.positions[jname] = raw, value, px
        return res

    def plain(self, unit: HomeUnit, measure_range: bool) -> UnitResult:
        joint = self.cfg.joints[unit.joints[0]]
        name = unit.drives[0]
        ref = drive_ref(self.cfg, name)
        refs = {name: ref}
        res = UnitResult(unit.name, unit.kind, unit.drives)
        d, speed = _sign(joint.cal_speed or 1), abs(joint.cal_speed or 1)
        search = _search_distance(self.cfg, joint)
        with _Disarm(self), MotionGuard(self.session, [ref], settings=self.settings, clock=self.clock,
                                        sleep=self.sleep) as guard:
            self.guard = guard
            c = guard.client(ref)
            # an unfinished home that met its switch left PX counting from the switch: it says on which
            # side of a home switch the joint stands (read before the mark is cleared)
            seen_px = int(c.get("PX")) if calibration.switch_seen(self.cfg, c) else None
            calibration.clear_calibrated(self.cfg, c)  # a re-home that fails must not leave the old mark
            if unit.kind == "home_switch":
                sw = _home_switch(joint)
                assert sw is not None
                pos = joint.cal_pos if joint.cal_pos is not None else sw.position
                b = _backoff(self.cfg, joint)
                if seen_px is not None and (seen_px - pos) * d > b:
                    # past the switch in the search's direction: a search from here runs into the
                    # hard stop. Back to the approach side first, a known distance in the switch's
                    # counts, with the stall watch of a homing move
                    self.move_to(guard, refs, {name: pos - d * b}, speed,
                                 f"{joint.name}: back before the switch (an unfinished home left it past)")
            else:
                sw = _stop_switch(joint, d)
                assert sw is not None
                pos = cal_position(joint, d)
            res.set_to[joint.name] = pos
            if _pins(c).get(sw.input):
                # standing on the switch (a re-home ends there), or past an end switch (a search
                # interrupted at its edge): a search from here sees no edge, and toward an end switch
                # it pushes into the end stop. Off it first, away from the stop.
                off = 2 * _backoff(self.cfg, joint)
                self.start_pr(guard, refs, {name: -d * off}, {name: speed})
                self.wait(guard, refs, distance=off, speed=speed, homing=False, what=f"{joint.name}: off the switch")
                if _pins(c).get(sw.input):
                    raise SafetyError(f"{joint.name}: the switch on input {sw.input} still reads pressed after "
                                      f"moving {off} counts off it",
                                      hint=f"check the switch and its wiring (`sherpa home --check-wiring {joint.name}`)")
            self.arm_homing(c, event=self.input_event(sw), value=pos, after=self.h.after_stop)
            self.start_pr(guard, refs, {name: d * search}, {name: speed})
            if not self.wait(guard, refs, distance=search, speed=speed, homing=True, what=f"{joint.name}: the search"):
                c.set("HM", 1, 0)
                went, return_way = ("up", "down") if d > 0 else ("down", "up")
                raise SafetyError(f"{joint.name}: the switch on input {sw.input} never triggered: stopped at the "
                                  f"search bound ({search} counts {went} at {speed} counts/s)",
                                  hint="check the switch and its wiring (`sherpa home --check-wiring "
                                       f"{joint.name}`) and where the joint stands: the search goes {went} only, so "
                                       f"a joint already {'above' if d > 0 else 'below'} its switch (a home cut short "
                                       f"past it) never meets it; jog it {return_way} past the switch first (`sherpa jog "
                                       f"{joint.name} --by {-d * search}counts --uncalibrated --apply`, watching it)")
            calibration.mark_switch_seen(self.cfg, c)  # PX counts from the switch now; not homed yet
            if unit.kind == "home_switch":
                self.move_to(guard, refs, {name: pos - d * b}, speed, f"{joint.name}: the back-off")
                px0 = int(c.get("PX"))
                slow = _slow(self.cfg, speed)
                self.arm_homing(c, event=self.input_event(sw), value=pos, after=self.h.after_nothing)
                self.start_pr(guard, refs, {name: d * 2 * b}, {name: slow})
                if not self.wait(guard, refs, distance=2 * b, speed=slow, homing=True,
                                 what=f"{joint.name}: the slow re-approach"):
                    c.set("HM", 1, 0)
                    raise SafetyError(f"{joint.name}: the switch on input {sw.input} did not trigger again on the "
                                      f"slow re-approach ({2 * b} counts)",
                                      hint="a switch that triggers once and not again: check it and its mounting")
                res.repeat_difference = px0 + d * 2 * b - int(c.get("PX"))
                lo, hi = joint.normal_range
                self.move_to(guard, refs, {name: min(max(pos, lo), hi)}, speed, f"{joint.name}: the return")
            else:
                lo, hi = joint.normal_range
                if measure_range:
                    far = search
                    other = _stop_switch(joint, -d)
                    assert other is not None
                    # the far switch's edge stops the move (HM[4] = stop); PX stays as homed (HM[5] = none)
                    self.arm_homing(c, event=self.input_event(other), value=0, after=self.h.after_stop,
                                    update=self.h.px_none)
                    self.start_pr(guard, refs, {name: -d * far}, {name: speed})
                    if not self.wait(guard, refs, distance=far, speed=speed, homing=True,
                                     what=f"{joint.name}: the measure"):
                        c.set("HM", 1, 0)
                        raise SafetyError(f"{joint.name}: the {'high' if d < 0 else 'low'} end switch (input "
                                          f"{other.input}) never triggered: stopped at the bound ({far} counts)")
                    res.measured_travel = abs(int(c.get("PX")) - pos)
                    res.configured_travel = joint.pos_max - joint.pos_min
                    back = hi if d < 0 else lo
                else:
                    back = lo if d < 0 else hi
                self.move_to(guard, refs, {name: back}, speed, f"{joint.name}: the return into the normal range")
            res.positions[joint.name] = int(c.get("PX"))
            calibration.mark_calibrated(self.cfg, c)
        res.motion_lines = guard.report.lines()
        res.motion_stop = guard.report.as_json()
        return res

    def pair(self, unit: HomeUnit) -> UnitResult:
        cfg = self.cfg
        pair = cfg.pairs[unit.name]
        s, dl = cfg.joints[pair.sigma], cfg.joints[pair.delta]
        a, b = pair.drive_a, pair.drive_b
        refs = {a: drive_ref(cfg, a), b: drive_ref(cfg, b)}
        res = UnitResult(unit.name, unit.kind, unit.drives)
        ds, dd = _sign(s.cal_speed or 1), _sign(dl.cal_speed or 1)
        sw_s = _stop_switch(s, ds) or _home_switch(s)
        sw_d = _stop_switch(dl, dd) or _home_switch(dl)
        assert sw_s is not None and sw_d is not None
        cal_s = cal_position(s, ds) if sw_s.kind is SwitchKind.STOP else (
            s.cal_pos if s.cal_pos is not None else sw_s.position)
        cal_d = cal_position(dl, dd) if sw_d.kind is SwitchKind.STOP else (
            dl.cal_pos if dl.cal_pos is not None else sw_d.position)
        with _Disarm(self), MotionGuard(self.session, list(refs.values()), settings=self.settings, clock=self.clock,
                                        sleep=self.sleep) as guard:
            self.guard = guard
            ca, cb = guard.client(refs[a]), guard.client(refs[b])
            for c in (ca, cb):
                calibration.clear_calibrated(cfg, c)  # a re-home that fails must not leave the old mark
            # motor a / b move along a joint: Σ = a + b (both the same way), Δ = a - b (opposite ways)
            signs = {s.name: (1, 1), dl.name: (1, -1)}

            def search(joint: JointConfig, sw: SwitchConfig, update: int, d: int, speed: int, dist: int,
                       what: str) -> None:
                """Both motors along ``joint`` until its switch's edge stops them (HM[4] = stop on each)."""
                for c in (ca, cb):
                    self.arm_homing(c, event=self.input_event(sw), value=0, after=self.h.after_stop, update=update)
                half, motor_speed = (dist + 1) // 2, max(1, speed // 2)
                sa, sb = signs[joint.name]

                def one_edge(saw: list[str], missed: list[str]) -> SafetyError:
                    return SafetyError(
                        f"{joint.name}: {', '.join(saw)} saw the switch on input {sw.input} during {what} but "
                        f"{', '.join(missed)} did not within {self.h.pair_edge_window_ms} ms (homing.pair_edge_window_ms): "
                        f"a wiring fault (a broken or swapped wire to {', '.join(missed)}); both motors stopped",
                        hint=f"check the switch's wiring to both drives (`sherpa home --check-wiring {joint.name}`)")

                self.start_pr(guard, refs, {a: sa * d * half, b: sb * d * half}, {a: motor_speed, b: motor_speed})
                if not self.wait(guard, refs, distance=half, speed=motor_speed, homing=True,
                                 what=f"{joint.name}: {what}", one_edge=one_edge):
                    for c in (ca, cb):
                        c.set("HM", 1, 0)
                    raise SafetyError(f"{joint.name}: the switch on input {sw.input} never triggered on both drives "
                                      f"during {what}: stopped at the bound ({dist} counts at {speed} counts/s)",
                                      hint=f"check the switch and its wiring (`sherpa home --check-wiring {joint.name}`)")

            def back_off(joint: JointConfig, d: int) -> None:
                """Move ``joint`` away from its switch by the backoff (the other joint holds)."""
                step = -d * _backoff(cfg, joint)
                pa, pb = int(ca.get("PX")), int(cb.get("PX"))
                sa, sb = signs[joint.name]
                half = step // 2 if step > 0 else -((-step) // 2)
                self.move_to(guard, refs, {a: pa + sa * half, b: pb + sb * half},
                             max(1, abs(joint.cal_speed or 1) // 2), f"{joint.name}: the back-off")

            def find(joint: JointConfig, sw: SwitchConfig, d: int, final_update: int) -> None:
                """Fast search, back off, slow re-approach: the slow edge is the one that counts (both
                drives see it within a fraction of a count)."""
                speed = abs(joint.cal_speed or 1)
                search(joint, sw, self.h.px_none, d, speed, _search_distance(cfg, joint), "the search")
                back_off(joint, d)
                b2 = 2 * _backoff(cfg, joint)
                search(joint, sw, final_update, d, _slow(cfg, speed), b2 + 2, "the slow re-approach")

            # 1. Σ: at its slow edge both counters := 0, so Σ = PX_a + PX_b + cal_s from now on
            find(s, sw_s, ds, self.h.px_absolute)
            back_off(s, ds)  # so the Σ switch no longer blocks the Δ search
            # 2. Δ (Σ nominally held): its edge only stops both; the counters stay in the Σ reference,
            #    so Σ stays exact whatever the start skew of the two motors let it drift
            find(dl, sw_d, dd, self.h.px_none)
            # 3. both counters from (Σ, Δ) through the pair transform, by an immediate home event each
            sigma_now = int(ca.get("PX")) + int(cb.get("PX")) + cal_s
            xa = (sigma_now + cal_d) // 2
            for c, v in ((ca, xa), (cb, sigma_now - xa)):
                self.arm_homing(c, event=self.h.event_immediate, value=v, after=self.h.after_nothing)
                if int(c.get("PX")) != v:
                    raise SafetyError(f"{c.label}: the immediate home event did not set PX (wanted {v})")
            res.set_to = {s.name: cal_s, dl.name: cal_d}
            # 4. back into both normal ranges
            pa, pb = int(ca.get("PX")), int(cb.get("PX"))
            slo, shi = s.normal_range
            dlo, dhi = dl.normal_range
            sig2, dlt2 = min(max(pa + pb, slo), shi), min(max(pa - pb, dlo), dhi)
            if (sig2 + dlt2) % 2:
                dlt2 += 1 if dlt2 < dhi else -1
            speed = min(abs(s.cal_speed or 1), abs(dl.cal_speed or 1))
            self.move_to(guard, refs, {a: (sig2 + dlt2) // 2, b: (sig2 - dlt2) // 2}, max(1, speed // 2),
                         f"{unit.name}: the return into the normal ranges")
            pa, pb = int(ca.get("PX")), int(cb.get("PX"))
            res.positions = {s.name: pa + pb, dl.name: pa - pb}
            for c in (ca, cb):
                calibration.mark_calibrated(cfg, c)
        res.motion_lines = guard.report.lines()
        res.motion_stop = guard.report.as_json()
        return res


def run_home(session: ArmSession, plan: HomePlan, *, settings: MotionSettings | None = None,
             clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
             on_unit: Callable[[UnitResult], None] | None = None, on_step: Callable[[str], None] | None = None,
             report: HomeReport | None = None) -> HomeReport:
    """Home every unit of ``plan`` in order; stops at the first failure (an exception; what was
    homed before it keeps its mark). ``on_unit`` sees each unit's result as it is done, ``on_step``
    the running step and its elapsed time at every poll. On an exception ``report`` (pass one to
    read it) names the unit that did not finish, its joints left un-homed and its stop report."""
    cfg = session.cfg
    runner = _Runner(session, cfg, settings or MotionSettings.from_config(cfg), clock, sleep)
    runner.on_step = on_step
    report = report if report is not None else HomeReport()
    for unit in plan.units:
        runner.guard = None
        try:
            if unit.kind == "abs_encoder":
                result = runner.abs_encoder(unit)
            elif unit.kind == "pair":
                result = runner.pair(unit)
            else:
                result = runner.plain(unit, plan.measure_range)
        except BaseException:
            # Ctrl-C, SIGTERM or an error: say which joints are left un-homed and how they stopped
            report.interrupted = unit.name
            report.not_homed = list(unit.joints)
            report.stop = runner.guard.report if runner.guard is not None else None
            raise
        report.units.append(result)
        if on_unit is not None:
            on_unit(result)
    return report


# -- the wiring check (`home --check-wiring`) ----------------------------------------------------------

IP_PIN_SHIFT = 16
PINS = 10  # IP bits 16..25: the raw input pins


@dataclass(frozen=True)
class WiringPrompt:
    """What the technician is asked to do: ``action`` is "press" or "release"."""

    action: str
    joint: str
    switch: str  # "input 3 (low end switch)"
    input: int
    drives: tuple[str, ...]


@dataclass
class WiringFinding:
    joint: str
    switch: str
    drive: str
    input: int
    verdict: str  # "ok", "no change", "already active", "wrong input", "inverted", "wrong input, inverted"
    seen_input: int | None = None

    @property
    def ok(self) -> bool:
        return self.verdict == "ok"

    def line(self) -> str:
        where = f"{self.joint} {self.switch} on {self.drive}"
        if self.verdict == "ok":
            return f"ok: {where}: input {self.input} goes active when pressed"
        if self.verdict == "no change":
            return f"FAULT: {where}: no input changed when it was pressed (broken wire, switch or supply)"
        if self.verdict == "already active":
            return (f"NOT CHECKED: {where}: input {self.input} was active before the press and stayed so "
                    "(the joint stands on its switch, as after `home`?): jog it off the switch and check again")
        if self.verdict == "inverted":
            return (f"FAULT: {where}: input {self.input} is active while released and goes inactive when "
                    "pressed (inverted: normally-closed contact or polarity)")
        pol = ", and inverted" if "inverted" in self.verdict else ""
        return f"FAULT: {where}: pressing it changes input {self.seen_input}, not input {self.input} (wrong input{pol})"

    def as_dict(self) -> dict[str, Any]:
        return {"joint": self.joint, "switch": self.switch, "drive": self.drive, "input": self.input,
                "verdict": self.verdict, "seen_input": self.seen_input}


@dataclass
class WiringReport:
    joint: str
    live: dict[str, dict[int, bool]] = field(default_factory=dict)  # drive -> configured input -> active
    findings: list[WiringFinding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(f.ok for f in self.findings)

    def as_dict(self) -> dict[str, Any]:
        return {"joint": self.joint, "ok": self.ok,
                "live": {d: {str(n): v for n, v in pins.items()} for d, pins in self.live.items()},
                "findings": [f.as_dict() for f in self.findings]}


def _switch_label(sw: SwitchConfig) -> str:
    what = "home switch" if sw.kind is SwitchKind.HOME else f"{sw.side or ''} end switch".strip()
    return f"input {sw.input} ({what})"


def wiring_joints(cfg: ArmConfig, name: str) -> list[str]:
    """The joints the wiring check of ``name`` (a joint, a pair, a drive of a joint) covers."""
    from sherpa_cli.bus import targets

    return [j.name for j in targets.resolve_one(cfg, name).joints]


def wiring_plan(cfg: ArmConfig, name: str) -> list[tuple[JointConfig, SwitchConfig, tuple[str, ...]]]:
    """Each switch of the joint (or of both joints of a pair) and the drives it is wired to."""
    from sherpa_cli.bus import targets

    t = targets.resolve_one(cfg, name)
    if not t.joints:
        raise UsageError(f"{name}: no joint (the wiring check takes a joint, a pair or the drive of a joint)")
    out = []
    for joint in t.joints:
        drives = calibration.joint_drives(cfg, joint)
        for sw in joint.switches:
            out.append((joint, sw, tuple(sw.drives) or drives))
    if not out and all(j.abs_encoder is not None for j in t.joints):
        return []  # an absolute encoder says where the joint is: no switch to check (the CLI says so)
    if not out:
        raise UsageError(f"{name}: no switches configured, nothing to check",
                         hint="switches: [{input: N, kind: home|stop, ...}] in the joint's config")
    return out


def _pins(c: DriveClient) -> dict[int, bool]:
    ip = int(c.get("IP"))
    return {n: bool(ip >> (IP_PIN_SHIFT + n - 1) & 1) for n in range(1, PINS + 1)}


def check_wiring(session: ArmSession, name: str, ask: Callable[[WiringPrompt], None],
                 on_live: Callable[[dict[str, dict[int, bool]]], None] | None = None) -> WiringReport:
    """Before any motion: the live state of the configured inputs, then for each switch ask the
    technician to press it (``ask`` returns once it is held) and to let go, reading IP each time.
    Writes nothing to the drives."""
    cfg = session.cfg
    plan = wiring_plan(cfg, name)
    report = WiringReport(name)
    clients: dict[str, DriveClient] = {}
    for _, _, drives in plan:
        for d in drives:
            if d not in clients:
                clients[d] = session.client(drive_ref(cfg, d))
                clients[d].nmt_start()
    for d, c in clients.items():
        pins = _pins(c)
        report.live[d] = {sw.input: pins[sw.input] for _, sw, drives in plan if d in drives}
    if on_live is not None:
        on_live(report.live)
    for joint, sw, drives in plan:
        label = _switch_label(sw)
        before = {d: _pins(clients[d]) for d in drives}
        ask(WiringPrompt("press", joint.name, label, sw.input, drives))
        held = {d: _pins(clients[d]) for d in drives}
        ask(WiringPrompt("release", joint.name, label, sw.input, drives))
        for d in drives:
            changed = [n for n in range(1, PINS + 1) if held[d][n] != before[d][n]]
            if sw.input in changed:
                verdict = "inverted" if before[d][sw.input] else "ok"
                seen = sw.input
            elif changed:
                seen = changed[0]
                verdict = "wrong input, inverted" if before[d][seen] else "wrong input"
            elif before[d][sw.input]:
                # held active the whole time: a switch the joint stands on (or one stuck closed), which
                # a press cannot show -- not a broken wire
                verdict, seen = "already active", None
            else:
                verdict, seen = "no change", None
            report.findings.append(WiringFinding(joint.name, label, d, sw.input, verdict, seen))
    return report
