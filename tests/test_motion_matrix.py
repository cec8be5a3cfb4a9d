"""The safety-invariant matrix: every moving command x every axis kind it accepts x every way
out, on the in-process simulated arm running on stepped time (sim/stepped.py: the simulated drives
move only while the command waits, so how far a motor got when a way out is injected does not
depend on the host's load).

Each combination asserts the four safety invariants of docs/motion.md:

- every motor the tool switched off was at standstill when its MO=0 arrived (the sim drive's motor
  velocity at that instant; a CiA 402 drive: its controlword taking it out of Operation enabled), and
  no drive had to stop itself on a lost heartbeat;
- no motor went on without an armed dead-man (a consumer watching the command's heartbeat);
- every motor is off at the end, unless held (``--hold``: on while held, off once the hold ends);
- RAM is put back: the drive's CANopen objects (PDO mapping, heartbeat consumer 0x1016, group id
  0x2040, ...), its TPDO table and its profile/unit mode (UM, SP, AC, DC; a CiA 402 drive's profile
  0x6081/0x6083/0x6084) equal what they were before;
- the stop report is complete: it names every drive the command switched on.

Ways out are injected at a fixed simulated time after the first motor went on (``INJECT_AFTER``),
from the command's own waits (the stepped clock's ``sleep``): an exception (an error), Ctrl-C
(KeyboardInterrupt), SIGTERM (``motion.guard.MotionStopped``, what the guard's handler raises for it), a
drive fault (the sim drive trips: MO=0, MF, EMCY), a bus error (the host's controller bus-off for a
moment), a limit breach (the joint pushed past its range), an end switch pressed, a stall (the motors
jammed). Combinations that do not apply (a homing search has no limit watch to breach; an absolute
encoder's home does not move; a joint without end switches has none to press) are not generated.

The CiA 402 drive (``cia402``: a plain joint on a drive of that type) has the rows its drive type
moves: the position jog and the pose move. Velocity, torque and ``--hold`` are refused for it by name
before anything is sent (tests/test_cia402_motion.py), so they have no rows here.

The only lines that name ops' request and axis types are the adapters just below (the types are
being unified into motion/axis.py and motion/request.py; re-point them there).
"""

from __future__ import annotations

import dataclasses
import math
import threading
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_ref
from sherpa_cli.config import load_config
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import CommunicationError
from sherpa_cli.motion.guard import MotionStopped
from sherpa_cli.motion.settings import MotionSettings
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.drive import UNGUARDED_MO
from sherpa_cli.sim.stepped import SteppedTime

ARM = Path(__file__).resolve().parent / "data" / "matrix-arm.yaml"

# ================================================================================================
# Adapters: how each command is started: through the Python API (`sherpa_cli.api.Arm`, what the
# commands call too), with the stepped clock. Each takes the session, the name of the thing moved, and
# the stepped time; returns what the command returned.


def _rad(counts: float, cpr: int) -> float:
    return counts * 2 * math.pi / cpr


def _uncalibrated(cfg: ArmConfig, name: str) -> bool:
    """A joint on a drive whose homing sherpa does not keep (CiA 402) moves by its counter as it is."""
    joint = cfg.joints.get(name)
    return joint is not None and joint.drive is not None and cfg.drives[joint.drive].type != "elmo"


SPEED = 400  # counts/s of every motion of the matrix (towards the low side)
DISTANCE = 200  # counts of every position move
RUN_FOR = 0.4  # s of every velocity / torque motion
AMPS = 1.0
LIVE_FOR = 0.8  # s the live jog and the joystick command: longer than a stall takes to show (stall_time 0.3 s)


def jog(mode: str, hold: bool = False) -> Callable[..., Any]:
    """`jog` of any axis kind, through the Python API (`Arm.move`): what the command ends in too."""
    def run(s: ArmSession, name: str, st: SteppedTime) -> Any:
        from sherpa_cli.api import Arm
        from sherpa_cli.motion.axis import resolve_axis
        from sherpa_cli.motion.request import parse_request

        axis = resolve_axis(s.cfg, name)
        pair = axis.pair is not None  # a plain position move runs at the joint's speed limit, a pair's at SPEED
        values: dict[str, Any] = {
            "position": {"by": f"{-DISTANCE}counts", **({"velocity": f"{SPEED}counts/s"} if pair else {})},
            "velocity": {"velocity": f"{-SPEED}counts/s", "duration": RUN_FOR},
            "torque": {"torque": f"{-AMPS}A", "duration": RUN_FOR}}[mode]
        req = parse_request(axis, mode, hold=hold, uncalibrated=_uncalibrated(s.cfg, name), **values)
        return Arm(s).move(axis, req, settings=None if pair else MotionSettings.from_config(s.cfg),
                           clock=st.now, sleep=st.sleep)
    return run


def _live(s: ArmSession, name: str, st: SteppedTime) -> Any:
    """`Arm.live_jog` (ops/live_jog.py LiveJog), as `jog --interactive` drives it: a velocity command
    refreshed every period, then the keys let go."""
    from sherpa_cli.api import Arm

    live = Arm(s).live_jog([name], clock=st.now, sleep=st.sleep, keepalive=0.3)
    try:
        with live:
            joint = next(iter(live.axes))
            t0 = st.now()
            while st.now() - t0 < LIVE_FOR:
                live.set_velocity(joint, -SPEED)
                live.tick()
                st.sleep(0.02)
            live.stop_all()
            live.tick()
    except BaseException as exc:
        exc.live_report = live.report  # type: ignore[attr-defined]  # as the CLI shows it on every exit
        raise
    return live


JOY_AXIS = {"stiff": ("ABS_Z", 0), "pitch": ("ABS_X", 1), "roll": ("ABS_Y", 1)}


def _joystick(s: ArmSession, name: str, st: SteppedTime) -> Any:
    from sherpa_cli.api import Arm
    from sherpa_cli.ops.joystick import ScriptedSource

    code, mapping = JOY_AXIS[name]
    arm = Arm(s)
    jcfg = dataclasses.replace(s.cfg.joystick, axes=(s.cfg.joystick.axes[mapping],))
    live = arm.live_jog(arm.joystick_joints(jcfg), clock=st.now, sleep=st.sleep, keepalive=0.3)
    try:
        with live:
            src = ScriptedSource([(0.0, "BTN_TRIGGER", 1.0), (0.0, code, -0.8), (LIVE_FOR, code, 0.0),
                                  (LIVE_FOR + 0.1, "BTN_TRIGGER", 0.0)], st.now)
            arm.joystick(live, src, mapping=jcfg, clock=st.now, sleep=st.sleep, duration=LIVE_FOR + 0.2)
    except BaseException as exc:
        exc.live_report = live.report  # type: ignore[attr-defined]  # as the CLI shows it on every exit
        raise
    return live


def _log_step(s: ArmSession, name: str, st: SteppedTime) -> Any:
    from sherpa_cli.api import Arm

    return Arm(s).log_step(name, "velocity", _rad(-SPEED, s.cfg.joints["stiff"].cpr), duration=RUN_FOR, rate=100,
                           settings=MotionSettings.from_config(s.cfg), timebase=st)


def diffdrive(hold: bool = False) -> Callable[..., Any]:
    def run(s: ArmSession, name: str, st: SteppedTime) -> Any:
        from sherpa_cli.api import Arm

        sigma, delta = (f"{-DISTANCE}counts", "0counts") if name == "pitch" else ("0counts", f"{-DISTANCE}counts")
        return Arm(s).diffdrive_move("diff", sigma=sigma, delta=delta, relative=True, velocity=f"{SPEED}counts/s",
                                     hold=hold, timebase=st)
    return run


# `move` of several joints at once: the joint of the axis kind and a plain joint beside it (another
# drive), so a way out on one joint must stop every joint of the move
MOVE_WITH = {"stiff": "yaw", "pitch": "stiff", "roll": "stiff", "wrist": "stiff"}


def _position(s: ArmSession, arm: Any, joint: str, st: SteppedTime) -> int:
    """Where a joint stands (counts): `Arm.state` (Elmo's interpreter), a CiA 402 joint's drive
    through the drive seam (`Arm.state` reads the interpreter's letters only)."""
    if _uncalibrated(s.cfg, joint):
        from sherpa_cli.devices.drives import open_drive

        drive = s.cfg.joints[joint].drive
        assert drive is not None
        return open_drive(s, drive_ref(s.cfg, drive)).position()
    return int(arm.state([joint], clock=st.now)[joint].position_counts)


def move_pose(hold: bool = False) -> Callable[..., Any]:
    """`sherpa move` through the Python API (`Arm.move_pose`): two joints to targets DISTANCE counts
    (the other half as far) below where they stand, together."""
    def run(s: ArmSession, name: str, st: SteppedTime) -> Any:
        from sherpa_cli.api import Arm

        arm = Arm(s)
        here = {j: _position(s, arm, j, st) for j in (name, MOVE_WITH[name])}
        pose = {name: f"{here[name] - DISTANCE}counts", MOVE_WITH[name]: f"{here[MOVE_WITH[name]] - DISTANCE // 2}counts"}
        return arm.move_pose(pose, hold=hold, uncalibrated=_uncalibrated(s.cfg, name), clock=st.now, sleep=st.sleep)
    return run


def _home(s: ArmSession, name: str, st: SteppedTime) -> Any:
    from sherpa_cli.api import Arm
    from sherpa_cli.ops.home import HomeReport

    report = HomeReport()
    try:
        Arm(s).home([name], settings=MotionSettings.from_config(s.cfg), clock=st.now, sleep=st.sleep, report=report)
    except BaseException as exc:
        exc.home_report = report  # type: ignore[attr-defined]  # read by reports_of
        raise
    return report


def reports_of(outcome: Any) -> list[dict[str, Any]]:
    """The guard reports (GuardReport.as_json) a command's result or exception carries."""
    found: list[Any] = []
    for attr in ("motion_report", "live_report", "stop", "report"):
        value = getattr(outcome, attr, None)
        if value is not None:
            found.append(value)
    home = getattr(outcome, "home_report", None)
    if home is not None and home.stop is not None:
        found.append(home.stop)
    for unit in getattr(outcome, "units", None) or ():  # HomeReport: one guard per unit
        found.append(unit.motion_stop)
    out = []
    for r in found:
        data = r if isinstance(r, dict) else r.as_json() if hasattr(r, "as_json") else None
        if isinstance(data, dict) and "drives" in data:
            out.append(data)
    return out

# ================================================================================================


@dataclass(frozen=True)
class AxisKind:
    name: str  # what the command is given
    drives: tuple[str, ...]  # what it moves
    breach: str  # the joint pushed out of its range for "limit_breach"
    switches: tuple[tuple[str, int], ...] = ()  # (drive, input) of the low end switch (none: no end_switch rows)


PAIR = ("pair_a", "pair_b")
AXES = {
    "plain": AxisKind("stiff", ("stiff_drive",), "stiff", (("stiff_drive", 3),)),
    "sigma": AxisKind("pitch", PAIR, "pitch", (("pair_a", 1), ("pair_b", 1))),
    "delta": AxisKind("roll", PAIR, "roll", (("pair_a", 3), ("pair_b", 3))),
    "pair_motor": AxisKind("pair_a", PAIR, "pitch", (("pair_a", 1), ("pair_b", 1))),
    "drive": AxisKind("stiff_drive", ("stiff_drive",), "stiff", (("stiff_drive", 3),)),
    "cia402": AxisKind("wrist", ("wrist_drive",), "wrist"),  # a plain joint on a CiA 402 drive
}
HOME_AXES = {
    "home_switch": AxisKind("yaw", ("yaw_drive",), "yaw"),
    "end_switches": AxisKind("stiff", ("stiff_drive",), "stiff"),
    "pair": AxisKind("diff", PAIR, "pitch"),
    "abs_encoder": AxisKind("twist", ("twist_drive",), "twist"),
}

WAYS = ("normal", "error", "ctrl_c", "sigterm", "drive_fault", "bus_error", "limit_breach", "end_switch", "stall")
MOVING = ("plain", "sigma", "delta", "pair_motor", "drive")
HOLD_WAYS = tuple(w for w in WAYS if w not in ("normal", "end_switch", "stall"))


@dataclass(frozen=True)
class Row:
    run: Callable[..., Any]
    axes: tuple[str, ...]
    ways: tuple[str, ...] = WAYS
    hold: bool = False
    home: bool = False


ROWS: dict[str, Row] = {
    "jog-position": Row(jog("position"), (*MOVING, "cia402")),
    "jog-velocity": Row(jog("velocity"), MOVING),
    "jog-torque": Row(jog("torque"), MOVING),
    # --hold: the hold ends at Ctrl-C (its normal end) or any other way out (held at standstill, a
    # pressed end switch or a jam changes nothing: no end_switch, no stall)
    "jog-velocity-hold": Row(jog("velocity", hold=True), MOVING, HOLD_WAYS, hold=True),
    "live-jog": Row(_live, ("plain", "sigma", "delta", "drive")),
    "joystick": Row(_joystick, ("plain", "sigma", "delta")),
    "log-step": Row(_log_step, ("plain", "drive")),
    "diffdrive-move": Row(diffdrive(), ("sigma", "delta")),
    "diffdrive-move-hold": Row(diffdrive(hold=True), ("sigma", "delta"), HOLD_WAYS, hold=True),
    "move-pose": Row(move_pose(), ("plain", "sigma", "delta", "cia402")),
    "move-pose-hold": Row(move_pose(hold=True), ("plain", "sigma", "delta"), HOLD_WAYS, hold=True),
    # a homing search runs into its switch (no end switch to inject) and has no limit watch to breach
    "home": Row(_home, ("home_switch", "end_switches", "pair"),
                tuple(w for w in WAYS if w not in ("limit_breach", "end_switch")), home=True),
    "home-abs": Row(_home, ("abs_encoder",), ("normal",), home=True),  # reads the encoder, does not move
}


# Known gaps, each failing today for the reason given (strict: a fix makes them pass and must remove the mark).
KNOWN_GAPS: dict[tuple[str, str], str] = {}


def _applies(spec: Row, axis: str, way: str) -> bool:
    """An end switch is pressed only on an axis that has one (the homing rows leave it out themselves)."""
    return spec.home or way != "end_switch" or bool(AXES[axis].switches)


def _cases() -> list[Any]:
    return [pytest.param(row, axis, way, id=f"{row}-{axis}-{way}",
                         marks=[pytest.mark.xfail(strict=True, reason=KNOWN_GAPS[(row, way)])]
                         if (row, way) in KNOWN_GAPS else [])
            for row, spec in ROWS.items() for axis in spec.axes for way in spec.ways if _applies(spec, axis, way)]


# ------------------------------------------------------------------------------------------------
# The stepped arm and what it records


INJECT_AFTER = 0.06  # s of simulated time after the first motor went on
# well into the hold: after a jog's RUN_FOR, the stop and a pair jog's correction of its held joint
# (about 0.9 s for Δ), and after a `diffdrive move` (about 0.6 s)
HOLD_INJECT_AFTER = RUN_FOR + 1.5
HOLD_END_AFTER = 0.3  # s after a way out the hold survived (a bus error, a switch): Ctrl-C ends it
BUS_OFF_FOR = 0.5  # s of wall time the host's controller is bus-off: longer than one request's wait, shorter
# than its attempts (sim/stepped.py: STEPPED_REPLY_S x STEPPED_RETRIES); the controller's restart is the
# host's, on wall time, and simulated time stands still meanwhile (nothing of the command sleeps)
STANDSTILL = 2.0  # counts/s: motion.standstill_velocity
# how a simulated drive records a switch-off the tool commanded: an Elmo drive's MO=0, a CiA 402
# drive's controlword taking it out of Operation enabled (sim/cia402.py: "motor off: CiA 402: <state>")
TOOL_OFF = ("motor off: MO=0", "motor off: CiA 402: ")


@dataclass
class Record:
    """What the simulated drives saw: each motor on/off with the motor's velocity at that instant."""
    events: list[tuple[str, float, str, float]] = field(default_factory=list)  # drive, t, text, velocity
    # a lost heartbeat that found the motor on (drive, t, text): the drive stopped itself. A CiA 402
    # drive records it apart from the switch-off 0x6007 then makes ("motor off: CiA 402: ...")
    own_stops: list[tuple[str, float, str]] = field(default_factory=list)

    def offs(self) -> list[tuple[str, float, str, float]]:
        return [e for e in self.events if e[2].startswith("motor off")]

    def switched_on(self) -> set[str]:
        return {e[0] for e in self.events if e[2].startswith("motor on")}


CIA402_PROFILE = ("0x6081", "0x6083", "0x6084")  # profile velocity, acceleration, deceleration


def _ram(drive: Any) -> dict[str, Any]:
    """What a command may change only for a while: objects, TPDOs, the unit mode and profile (a CiA
    402 drive's profile objects)."""
    snap = drive.ram_snapshot()
    cia402 = snap.get("cia402")
    profile = {k: cia402["objects"][k] for k in CIA402_PROFILE} if isinstance(cia402, dict) else {}
    return {"od": snap["od"], "tpdo": snap["tpdo"], **{k: snap["ram"].get(k) for k in ("UM", "SP", "AC", "DC")},
            **profile}


def _prepare(s: ArmSession, cfg: ArmConfig) -> None:
    """Every drive Operational and calibrated where it stands (PX = its real position, UI[3]=1), so
    the tool's joint positions are the simulator's and the limit and switch positions agree; the end
    switches' stop function in IL[n] (what `program-limits` leaves on a commissioned arm)."""
    for name in cfg.drives:
        c = s.client(drive_ref(cfg, name))
        c.nmt_start()
        if cfg.drives[name].type != "elmo":
            continue  # no interpreter: a CiA 402 drive's joint moves by its counter (--uncalibrated)
        with s.sim.lock:
            here = s.sim.drives[name].motor.rounded
        c.set("PX", 0, here)
        c.set("UI", 3, 1)
    for joint in cfg.joints.values():
        drives = (joint.drive,) if joint.drive is not None else PAIR
        for sw in joint.switches:
            if sw.kind.value == "stop":
                for name in sw.drives or drives:
                    s.client(drive_ref(cfg, name)).set("IL", sw.input, cfg.il_codes.stop)


class Injector:
    """Wraps the stepped clock's sleep (every wait of the command goes through it): once a motor of
    the command went on, at ``after`` s of simulated time, the way out happens, once."""

    def __init__(self, st: SteppedTime, arm: SimArm, axis: AxisKind, way: str, after: float, *,
                 hold: bool = False) -> None:
        self.st, self.arm, self.axis, self.way, self.after = st, arm, axis, way, after
        self.hold = hold  # a hold outlives a way out it survives: the technician's Ctrl-C ends it after
        self.ended_hold = False
        self.t_on: float | None = None
        self.fired_at: float | None = None
        self.bus_back: threading.Timer | None = None
        self._sleep = st.sleep
        st.sleep = self.sleep  # type: ignore[method-assign]  # the clients' waits too (client_overrides)

    def sleep(self, seconds: float) -> None:
        self._sleep(seconds)
        if threading.current_thread() is not threading.main_thread():
            return
        now = self.st.now()
        if self.hold and self.fired_at is not None and not self.ended_hold and now - self.fired_at >= HOLD_END_AFTER:
            self.ended_hold = True
            raise KeyboardInterrupt
        if self.fired_at is not None or self.way == "normal":
            return
        if self.t_on is None:
            with self.arm.lock:
                if any(self.arm.drives[d].motor_on for d in self.axis.drives):
                    self.t_on = now
            return
        if now - self.t_on >= self.after:
            self.fired_at = now
            self.fire()

    def restart(self) -> None:
        with self.arm.lock:
            self.arm.bus_controller("can0").set_state("error-active")

    def fire(self) -> None:
        way, arm = self.way, self.arm
        if way == "error":
            # what ends a motion with an error: a request that fails mid-move (a bug, any other
            # exception, ends it too, but carries no report: motion/report.with_report)
            raise CommunicationError("injected error (the matrix)")
        if way == "ctrl_c":
            raise KeyboardInterrupt
        if way == "sigterm":
            # what the guard's own handler raises for SIGTERM while motors may move (motion/guard.py
            # _on_signal); the real signal is sent across processes in test_signals_crossprocess
            raise MotionStopped("SIGTERM received: motion stopped")
        with arm.lock:
            drives = [arm.drives[d] for d in self.axis.drives]
            if way == "drive_fault":
                drives[0].trip()
            elif way == "bus_error":
                arm.bus_controller("can0").set_state("bus-off")
                self.bus_back = threading.Timer(BUS_OFF_FOR, self.restart)
                self.bus_back.start()
            elif way == "end_switch":
                for d, inp in self.axis.switches:
                    arm.drives[d].inputs.press(inp, True)
            elif way == "stall":
                for d in drives:
                    _jam(d.motor)
            elif way == "limit_breach":
                _push_out(arm, self.axis.breach)


def _jam(motor: Any) -> None:
    """The joint is blocked: commanded motion makes no progress (a collision, a jammed gear)."""
    step = motor.step

    def jammed(dt: float) -> None:
        counts, frac = motor.counts, motor.frac
        step(dt)
        motor.counts, motor.frac, motor.v = counts, frac, 0.0
        if motor.mode == "stop":
            motor.mode = "idle"
    motor.step = jammed


def _push_out(arm: SimArm, joint: str) -> None:
    """Push ``joint`` 10 counts past the low end of its range (inside its overshoot: no hard stop)."""
    j = arm.cfg.joints[joint]
    low = j.pos_min - 10
    if joint == "wrist":  # its counter reads 0 where it powered up (no PX to set on a CiA 402 drive)
        d = arm.drives[j.drive]
        d.motor.counts += low - d.px
        return
    if joint in ("stiff", "yaw", "twist"):
        m = arm.drives[j.drive].motor
        m.counts += low - m.counts
        return
    a, b = arm.drives["pair_a"].motor, arm.drives["pair_b"].motor
    if joint == "pitch":  # Σ = a + b: move both
        d = (low - (a.counts + b.counts)) // 2
        a.counts += d
        b.counts += d
    else:  # Δ = a - b
        d = (low - (a.counts - b.counts)) // 2
        a.counts += d
        b.counts -= d


# ------------------------------------------------------------------------------------------------


@dataclass
class Outcome:
    value: Any = None
    error: BaseException | None = None
    record: Record = field(default_factory=Record)
    held: bool | None = None  # --hold: every motor stayed on from the end of the move to the way out
    before: dict[str, Any] = field(default_factory=dict)
    after: dict[str, Any] = field(default_factory=dict)
    motors_on: set[str] = field(default_factory=set)
    moving: dict[str, float] = field(default_factory=dict)
    injected: float | None = None


def run_case(row: Row, axis: AxisKind, way: str) -> Outcome:
    cfg = load_config(ARM)
    st = SteppedTime()
    tag = uuid.uuid4().hex[:8]
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": f"matrix-{tag}"}}, clock=st.clock)
    out = Outcome()
    with ArmSession.open(cfg, sim=arm) as s:
        unheard = lambda: (sum(d.unheard for d in arm.drives.values()),  # noqa: E731
                           sum(d.unheard_s for d in arm.drives.values()))
        s.client_overrides.update(st.client_overrides(cfg.protocol.reply_timeout, cfg.protocol.retries, unheard))
        _prepare(s, cfg)
        with arm.lock:
            out.before = {n: _ram(d) for n, d in arm.drives.items()}
            for name, d in arm.drives.items():
                def seen(drive: Any, t: float, text: str, _name: str = name, _next: Any = d.on_event) -> None:
                    out.record.events.append((_name, t, text, drive.motor.v))
                    if text.startswith("heartbeat lost") and drive.motor_on:
                        out.record.own_stops.append((_name, t, text))
                    if _next is not None:
                        _next(drive, t, text)
                d.on_event = seen
        inj = Injector(st, arm, axis, way, HOLD_INJECT_AFTER if row.hold else INJECT_AFTER, hold=row.hold)
        try:
            out.value = row.run(s, axis.name, st)
        except BaseException as exc:  # noqa: BLE001 - every way out is looked at below
            out.error = exc
        out.injected = inj.fired_at
        if inj.bus_back is not None:
            inj.bus_back.join()
        with arm.lock:
            arm_now = st.clock.now()
            for d in arm.drives.values():
                d.advance_to(arm_now)
            out.after = {n: _ram(d) for n, d in arm.drives.items()}
            out.motors_on = {n for n, d in arm.drives.items() if d.motor_on}
            out.moving = {n: d.motor.v for n, d in arm.drives.items() if d.motor.v}
        if row.hold and inj.fired_at is not None:
            offs_before = [e for e in out.record.offs() if e[1] < inj.fired_at]
            out.held = not offs_before
    return out


@pytest.mark.parametrize("row_name,axis_kind,way", _cases())
def test_every_way_out_stops_from_standstill_switches_off_puts_ram_back_and_reports(row_name, axis_kind, way):
    row = ROWS[row_name]
    axis = (HOME_AXES if row.home else AXES)[axis_kind]
    out = run_case(row, axis, way)
    told = f"raised {out.error!r}" if out.error is not None else f"returned {out.value!r}"  # what the command said
    told += "".join(f"; {m}" for m in getattr(out.value, "messages", None) or ())  # LiveJog's notes
    what = f"{row_name} {axis.name} ({way}): {told[:400]}"

    # the way out happened while the command was moving (else the combination tests nothing)
    switched_on = out.record.switched_on()
    if row_name != "home-abs":
        assert switched_on, f"{what}: no motor went on"
    if way != "normal":
        assert out.injected is not None, f"{what}: the command ended before the way out was injected"
    # the exception a way out raises is never swallowed (Ctrl-C may end an open-ended motion normally)
    if way == "error":
        assert isinstance(out.error, CommunicationError), what
    if way == "sigterm":
        assert isinstance(out.error, MotionStopped), what
    if way == "normal":
        assert out.error is None, what
    # Ctrl-C is how a hold is meant to end: a normal end that says so (and the way out found it holding)
    if row.hold and way == "ctrl_c":
        assert out.error is None and "held until Ctrl-C" in told, f"{what}: Ctrl-C did not end the hold normally"
    # clear endings: what ended the command is named
    if way == "end_switch":
        assert "end switch" in told, f"{what}: the end switch is not named"
    if way == "stall":
        assert "blocked" in told, f"{what}: the stall is not called blocked"
    if way == "drive_fault":
        assert out.error is not None and axis.drives[0] in str(out.error), f"{what}: the faulted drive is not named"

    # 1. stopped from standstill: every switch-off the tool sent (MO=0, a CiA 402 controlword) found
    # its motor still; no drive stopped itself
    own = [(drive, round(t, 3), text) for drive, t, text in out.record.own_stops]
    assert not own, f"{what}: stopped by its own heartbeat consumer: {own}"
    for drive, t, text, v in out.record.offs():
        assert "heartbeat lost" not in text, f"{what}: {drive} stopped by its own heartbeat consumer at {t:.3f}"
        if text.startswith(TOOL_OFF):
            assert abs(v) <= STANDSTILL, f"{what}: {drive} switched off while moving at {v:.0f} counts/s"
    # the move back after a limit breach starts only from standstill: every position
    # move begun after the breach (the recovery: BG with PA/PR, a CiA 402 drive's new set-point; a
    # velocity refresh is not one) found its motor still
    if way == "limit_breach" and out.injected is not None:
        for drive, t, text, v in out.record.events:
            started = (text.startswith("BG") and ("PA=" in text or "PR=" in text)) or text.startswith("PP: target")
            if started and t >= out.injected:
                assert abs(v) <= STANDSTILL, f"{what}: {drive} {text} at {t:.3f} while moving at {v:.0f} counts/s"
    # 1b. no motor went on without an armed dead-man (the sim drive records every MO=1
    # that found no consumer watching, sim/drive.py UNGUARDED_MO)
    unguarded = [(d, round(t, 3), text) for d, t, text, _ in out.record.events if text.startswith(UNGUARDED_MO)]
    assert not unguarded, f"{what}: {unguarded}"
    # 2. off unless held
    assert not out.motors_on, f"{what}: motor still on: {sorted(out.motors_on)}"
    assert not out.moving, f"{what}: still moving: {out.moving}"
    if row.hold and way in ("ctrl_c", "error", "sigterm", "bus_error"):
        assert out.held, f"{what}: the held motor went off before the way out"
    # 3. RAM put back
    for drive in sorted(out.before):
        before, after = out.before[drive], out.after[drive]
        changed = {k: (before[k], after[k]) for k in before if before[k] != after[k]}
        if "od" in changed:
            b, a = changed.pop("od")
            changed.update({f"od {k}": (b.get(k), a.get(k)) for k in set(b) | set(a) if b.get(k) != a.get(k)})
        assert not changed, f"{what}: {drive} RAM not put back: {changed}"
    # 4. the report is complete: it names every drive the command switched on
    reports = reports_of(out.error if out.error is not None else out.value)
    assert reports or not switched_on, f"{what}: no stop report"
    named = {d["drive"] for r in reports for d in r["drives"]}
    assert switched_on <= named, f"{what}: report names {sorted(named)}, switched on {sorted(switched_on)}"
