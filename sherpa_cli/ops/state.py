"""Where the joints are and what their drives are doing, in joint units: the snapshot behind
``Arm.state()`` and ``Arm.joint(name)``.

It asks what `sherpa monitor` asks (ops/monitor.py: NMT start, then MO, UM, PX, SR, MF over the
binary interpreter, faults decoded the same way) plus VX and IQ, and whether each joint is
calibrated (motion/calibration.py, read only: a counter that lost its encoder is reported, never
re-synced here). A Σ/Δ joint follows from both motors of its pair with the pair math of
joints/diffpair.py. Nothing is written to a drive; nothing here prints.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.bus.targets import DriveRef, drive_ref, resolve
from sherpa_cli.config.model import ArmConfig, CurrentLimits, JointConfig
from sherpa_cli.devices.drives import is_elmo, open_drive
from sherpa_cli.elmo.drive import UNIT_MODES as UNIT_MODES_OF
from sherpa_cli.elmo.faults import UNIT_MODES
from sherpa_cli.errors import CommunicationError, SherpaError, UsageError
from sherpa_cli.joints.jointmap import joint_map
from sherpa_cli.joints.units import counts_per_s2_to_rad_per_s2, counts_per_s_to_rad_per_s, counts_to_rad
from sherpa_cli.motion.calibration import Calibration, joint_drives, read_calibration
from sherpa_cli.ops.monitor import POLLED, decoded_mf, decoded_sr, query
from sherpa_cli.ops.params_read import per_bus

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient

#: what a snapshot asks each drive: the monitor's queries, then velocity and active current
STATE_KEYS = (*POLLED, "VX", "IQ")


@dataclass(frozen=True)
class DriveState:
    """One drive as it answered: motor counts, its own units."""

    drive: str
    bus: str
    node: int
    position_counts: int  # PX
    velocity_counts: int  # VX, counts/s
    current: float  # IQ, A (active current)
    motor_on: bool  # MO = 1
    unit_mode: int  # UM
    sr: int
    mf: int
    faults: tuple[str, ...]  # MF's latched failures, then what SR says needs a look

    @property
    def address(self) -> str:
        return f"{self.bus}:{self.node}"


@dataclass(frozen=True)
class JointState:
    """One joint in joint units. A Σ/Δ joint is computed from both motors of its pair: position and
    velocity as Σ = a + b, Δ = a - b; current as (I_a ± I_b)/2, the torque both motors put on it."""

    name: str
    position: float  # rad
    velocity: float  # rad/s
    current: float  # A
    position_counts: int  # joint counts (Σ/Δ for a pair joint)
    velocity_counts: int  # joint counts/s
    calibrated: bool
    calibration: str  # why (calibrated or not): "absolute encoder", "not homed since power-up (...)"
    motor_on: bool  # any of its motors is on
    mode: int | None  # the drive's unit mode (UM); None when the two motors of a pair differ
    faults: tuple[str, ...]  # "drive: text", per drive of the joint; empty when nothing needs a look
    drives: tuple[str, ...]  # the drive, or a pair's two motors (a, b)

    @property
    def mode_text(self) -> str:
        """The unit mode in words ("single-feedback position", "speed", "torque", ...)."""
        if self.mode is None:
            return "the motors of the pair are in different unit modes"
        return UNIT_MODES.get(self.mode, f"unknown unit mode {self.mode}")

    @property
    def ok(self) -> bool:
        """No fault latched and nothing in the status register that needs a look."""
        return not self.faults


@dataclass(frozen=True)
class ArmState:
    """A snapshot: the joints asked for (config order) and the drives that were read for them."""

    joints: tuple[JointState, ...]
    drives: tuple[DriveState, ...]
    at: float  # the clock's time when the reads were done

    def __getitem__(self, joint: str) -> JointState:
        for j in self.joints:
            if j.name == joint:
                return j
        raise KeyError(joint)

    def __iter__(self) -> Iterator[JointState]:
        return iter(self.joints)

    def __len__(self) -> int:
        return len(self.joints)

    @property
    def positions(self) -> dict[str, float]:
        """Joint -> position in rad."""
        return {j.name: j.position for j in self.joints}

    @property
    def ok(self) -> bool:
        return all(j.ok for j in self.joints)


@dataclass(frozen=True)
class JointLimits:
    """A joint's configured limits in joint units (rad, rad/s, rad/s², A); None: not configured."""

    joint: str
    full: tuple[float, float]  # the mechanical range the drive's position limits are derived from
    normal: tuple[float, float]  # inside the margin: where a move may end
    overshoot: tuple[float, float]  # beyond it the drive trips
    velocity: float | None  # the speed limit
    velocity_trip: float | None  # the speed the drive trips at
    acceleration: float | None
    deceleration: float | None
    current: CurrentLimits | None  # per motor (a pair's limits apply to both its motors)


def joints_of(cfg: ArmConfig, targets: Sequence[str] | None) -> tuple[list[JointConfig], list[DriveRef]]:
    """The joints ``targets`` mean (joints, pairs, drives; none: every joint) in config order, and the
    drives to read for them."""
    resolved = resolve(cfg, targets, configured_only=True)
    named = {j.name for t in resolved for j in t.joints}
    joints = [j for j in cfg.joints.values() if j.name in named]
    if not joints:
        raise UsageError(f"no joint among {', '.join(targets or [])}: the drives named move no configured joint")
    # a pair motor named alone still needs the other motor: its joints are Σ and Δ of both
    wanted = {d for j in joints for d in joint_drives(cfg, j)}
    return joints, [drive_ref(cfg, d) for d in cfg.drives if d in wanted]


def _other_state(session: ArmSession, ref: DriveRef) -> DriveState:
    """A drive of another type through the seam: no current (NaN: not read), SR and MF 0, the unit
    mode its mode's Elmo equivalent (the words say the same), a reported fault as its one fault."""
    drive = open_drive(session, ref)
    try:
        st = drive.status()
        position, velocity = drive.position(), drive.velocity()
    except SherpaError as exc:
        raise CommunicationError(f"{ref.name} ({ref.address}): {exc}") from exc
    return DriveState(ref.name, ref.bus, ref.node, position, velocity, math.nan, st.enabled,
                      UNIT_MODES_OF.get(st.mode, 0), 0, 0, (st.fault,) if st.fault else ())


def read_state(session: ArmSession, targets: Sequence[str] | None = None, *,
               clock: Callable[[], float] = time.monotonic) -> ArmState:
    """Read the drives of ``targets`` (buses at the same time) and compute their joints.

    Each drive is NMT-started first, as `sherpa monitor` and `sherpa cmd` do: the binary interpreter
    answers only when Operational. A drive that does not answer (or refuses a query) raises a
    CommunicationError naming every such drive: a snapshot never holds old or made-up values.
    """
    cfg = session.cfg
    joints, refs = joints_of(cfg, targets)
    ref_of = {r.name: r for r in refs}

    def read(drive: str) -> DriveState:
        ref = ref_of[drive]
        client = session.client(ref)
        client.nmt_start()
        if not is_elmo(session, ref):
            return _other_state(session, ref)
        values, problem = query(client, STATE_KEYS)
        if problem is not None:
            raise CommunicationError(f"{drive} ({ref.address}): {problem}")
        sr, mf = int(values["SR"]), int(values["MF"])
        faults = tuple(f.line() for f in (*decoded_mf(mf), *decoded_sr(sr)))
        return DriveState(drive, ref.bus, ref.node, int(values["PX"]), int(values["VX"]), float(values["IQ"]),
                          int(values["MO"]) == 1, int(values["UM"]), sr, mf, faults)

    outcomes = per_bus(session, [r.name for r in refs], read)
    errors = [o.error for o in outcomes.values() if o.error is not None]
    if errors:
        unexpected = [e for e in errors if not isinstance(e, CommunicationError)]
        if len(errors) == 1 or unexpected:
            raise (unexpected or errors)[0]
        raise CommunicationError("; ".join(map(str, errors)))  # every silent drive named at once
    drives: dict[str, DriveState] = {name: o.value for name, o in outcomes.items()}
    at = clock()

    def client_of(drive: str) -> DriveClient:
        return session.client(ref_of[drive])

    states = tuple(joint_state(cfg, j, drives, read_calibration(cfg, j, client_of)) for j in joints)
    return ArmState(states, tuple(drives[r.name] for r in refs), at)


def joint_state(cfg: ArmConfig, joint: JointConfig, drives: Mapping[str, DriveState],
                 calibration: Calibration) -> JointState:
    """One joint from its drives' states (read already) and its calibration: pure."""
    jm = joint_map(cfg, joint)
    if jm is None:
        raise UsageError(f"{joint.name}: no drive and no pair: nothing to read")
    names = jm.drives
    mine = [drives[d] for d in names]
    b = mine[1] if len(mine) > 1 else None
    px = int(jm.value(mine[0].position_counts, None if b is None else b.position_counts))
    vx = int(jm.value(mine[0].velocity_counts, None if b is None else b.velocity_counts))
    amps = jm.current(mine[0].current, None if b is None else b.current)
    modes = {d.unit_mode for d in mine}
    return JointState(
        name=joint.name, position=counts_to_rad(px, joint.cpr), velocity=counts_per_s_to_rad_per_s(vx, joint.cpr),
        current=amps, position_counts=px, velocity_counts=vx, calibrated=calibration.calibrated,
        calibration=calibration.reason, motor_on=any(d.motor_on for d in mine),
        mode=modes.pop() if len(modes) == 1 else None,
        faults=tuple(f"{d.drive}: {text}" for d in mine for text in d.faults), drives=names)


def joint_limits(cfg: ArmConfig, name: str) -> JointLimits:
    """The configured limits of joint ``name`` in joint units."""
    if name not in cfg.joints:
        from sherpa_cli.bus.targets import unknown_target

        raise unknown_target(cfg, name)
    j = cfg.joints[name]

    def rad(r: tuple[int, int]) -> tuple[float, float]:
        return counts_to_rad(r[0], j.cpr), counts_to_rad(r[1], j.cpr)

    def speed(v: int | None) -> float | None:
        return None if v is None else counts_per_s_to_rad_per_s(v, j.cpr)

    def accel(v: int | None) -> float | None:
        return None if v is None else counts_per_s2_to_rad_per_s2(v, j.cpr)

    current = j.current if j.pair is None else cfg.pairs[j.pair].current
    return JointLimits(j.name, rad(j.full_range), rad(j.normal_range), rad(j.overshoot_range), speed(j.vel_limit),
                       speed(j.vel_trip), accel(j.accel), accel(j.decel), current)
