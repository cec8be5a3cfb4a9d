"""Typed, frozen model of an arm configuration.

Units: positions in feedback counts of the drive's controlling sensor, velocities in
counts/s, accelerations in counts/s^2, currents in A, times in s. ``cpr`` converts a
joint's counts to radians (``rad = counts * 2*pi / cpr``), gearing included.

Ranges of one joint (docs/config.md, "Ranges"):

    overshoot range  [pos_min - overshoot, pos_max + overshoot]   -> LL[3] / HL[3] (trip)
    full range       [pos_min, pos_max]                           -> VL[3] / VH[3] (clip)
    normal range     [pos_min + margin, pos_max - margin]         where the tool moves a joint

Every object keeps ``where`` (file, line, key path) so later checks, like the current
check against the catalog, can still point at the line a technician must edit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from sherpa_cli.config.simbus import SimBusConfig
from sherpa_cli.errors import Location


class SwitchKind(str, Enum):  # noqa: UP042  StrEnum would change str()/format() of a member ('stop', not 'SwitchKind.STOP')
    STOP = "stop"  # end-detection switch: the drive stops motion toward it (IL = il_codes.stop)
    HOME = "home"  # position-detection switch used by homing (IL = il_codes.home)


class JointRole(str, Enum):  # noqa: UP042  StrEnum would change str()/format() of a member ('plain', not 'JointRole.PLAIN')
    PLAIN = "plain"  # one drive, one joint
    SIGMA = "sigma"  # Σ joint of a differential pair (sum of motor positions)
    DELTA = "delta"  # Δ joint of a differential pair (difference of motor positions)


@dataclass(frozen=True)
class BusConfig:
    name: str
    interface: str | None = None  # python-can interface; None = python-can's own config decides
    channel: str | None = None
    bitrate: int | None = None
    send_interval_us: int = 1000  # minimum gap between frames this tool sends on the bus
    poll_interval_ms: int = 10  # how often drives are polled while watching motion
    options: Mapping[str, Any] = field(default_factory=dict)  # extra keyword args for can.Bus
    where: Location = field(default_factory=Location, compare=False)


@dataclass(frozen=True)
class DriveModel:
    """A servo drive type from the catalog (seed Table 3.2)."""

    name: str
    nominal_voltage: float
    max_voltage: float
    current_cont: float  # A
    current_peak: float  # A
    inputs: int = 6  # digital inputs IL[1..inputs]


@dataclass(frozen=True)
class MotorModel:
    """A motor type from the catalog (seed Table 3.1)."""

    name: str
    voltage: float
    current_cont: float  # A
    power: float  # W
    current_peak: float  # A
    peak_power: float  # W


@dataclass(frozen=True)
class Catalog:
    drives: Mapping[str, DriveModel]
    motors: Mapping[str, MotorModel]
    peak_fraction: float = 0.75  # seed 3.4: use at most 75 % of the motor's peak current


@dataclass(frozen=True)
class DriveConfig:
    name: str
    bus: str
    node: int  # CAN node id 1..127
    model: str | None = None  # key into catalog.drives; None = unknown model (no rating checks)
    motor: str | None = None  # key into catalog.motors
    where: Location = field(default_factory=Location, compare=False)
    type: str = "elmo"  # the drive's protocol: one of DRIVE_TYPES (docs/config.md)


# What a `drives:` entry speaks: Elmo's binary interpreter (elmo/) or the CiA 402 profile over SDO (cia402/).
DRIVE_TYPES = ("elmo", "cia402")

# The seed's dev_type selected device-specific code; here a device type names a class in the
# registry of sherpa_cli/devices (the way python-can maps interface names to bus classes).
# "elmo" is every entry of `drives:`; `devices:` holds the other types.
DEVICE_TYPES = ("elmo", "canopen-encoder", "ft_sensor")
FT_SENSOR = "ft_sensor"  # an ATI Net F/T on CAN: no CANopen node, a base id of its own (devices/ft_sensor.py)
ENCODER_POSITION_FROM = ("tpdo", "sdo")
ENCODER_TPDO_TRIGGERS = ("cyclic", "sync")


@dataclass(frozen=True)
class FtSensorConfig:
    """An ATI Net F/T force/torque sensor's CAN settings (docs/devices.md).

    The counts per unit are the calibration sheet's; over CAN the sensor cannot be asked for them,
    so they are required here (None = missing, which `config check` refuses). A limit of None is no
    limit of that kind; the force watch checks the ones given.
    """

    base_id: int  # the DIP-switch base address: requests go here, replies come on base+5 and base+6
    counts_per_force: float | None = None  # counts per N
    counts_per_torque: float | None = None  # counts per N·m
    frame: str = "ft_sensor"  # the sensor frame's name (recordings' frame_id)
    force_limit: float | None = None  # N: |F| beyond this stops a guarded move
    torque_limit: float | None = None  # N·m: |T| beyond this stops a guarded move
    reply_ms: float = 20.0  # how long to wait for both reply frames after a request


@dataclass(frozen=True)
class DeviceConfig:
    """A CAN device that is not a drive (`devices:`), e.g. a CANopen absolute encoder (CiA 406)."""

    name: str
    type: str  # a key of DEVICE_TYPES other than "elmo"
    bus: str
    node: int  # the CANopen node id; 0 for a device that is no CANopen node (ft_sensor)
    # canopen-encoder (docs/home.md): read 0x6004 from the encoder's TPDO1 ("tpdo"; SDO is the fallback)
    # or by SDO only ("sdo"). CiA 406 hard-wires TPDO1's event timer to the cyclic timer 0x6200 ("cyclic");
    # that a given encoder's TPDO1 also takes transmission type 1 (on SYNC, "sync") is UNCONFIRMED.
    position_from: str = "tpdo"
    tpdo_trigger: str = "cyclic"
    cyclic_ms: int = 10  # 0x6200 (ms) written to RAM while reading, when the encoder's own is 0
    ft: FtSensorConfig | None = None  # the ft_sensor settings (type ft_sensor only)
    where: Location = field(default_factory=Location, compare=False)

    @property
    def address(self) -> str:
        if self.ft is not None:
            return f"{self.bus}:0x{self.ft.base_id:03X}"
        return f"{self.bus}:{self.node}"

    @property
    def canopen(self) -> bool:
        """A CANopen node (NMT, SDO, identity): every type but the F/T sensor."""
        return self.type != FT_SENSOR


@dataclass(frozen=True)
class CurrentLimits:
    continuous: float  # A -> CL[1]
    peak: float  # A -> PL[1]
    peak_time: float  # s -> PL[2]
    where: Location = field(default_factory=Location, compare=False)


@dataclass(frozen=True)
class SwitchConfig:
    input: int  # digital input number on the drive(s), 1-based
    kind: SwitchKind
    position: int  # joint position (counts) where the switch trips
    side: str | None = None  # "low" / "high" for stop switches at the ends of the range
    drives: tuple[str, ...] = ()  # drives it is wired to; empty = the joint's drive(s)
    where: Location = field(default_factory=Location, compare=False)


@dataclass(frozen=True)
class AbsEncoderConfig:
    """An absolute encoder that gives the joint position without homing."""

    source: str  # e.g. "drive:PY" (aux position of the drive) or a topic/name
    offset: int = 0  # counts added to the encoder reading to get the joint position
    where: Location = field(default_factory=Location, compare=False)


@dataclass(frozen=True)
class JointConfig:
    name: str
    role: JointRole
    drive: str | None  # the drive of a plain joint; None for Σ/Δ joints
    pair: str | None  # the differential pair of a Σ/Δ joint
    cpr: int  # counts per joint revolution
    pos_min: int
    pos_max: int
    margin: int = 0  # full range edge -> normal range edge (inward)
    overshoot: int = 0  # full range edge -> overshoot range edge (outward)
    # None = not configured: the derivation then leaves that drive parameter alone
    # (the seed's rosparam format has no velocity, acceleration or current keys).
    vel_limit: int | None = None  # counts/s -> VL[2]/VH[2]
    vel_trip: int | None = None  # counts/s -> LL[2]/HL[2]
    accel: int | None = None  # counts/s^2 -> AC
    decel: int | None = None  # counts/s^2 -> DC
    current: CurrentLimits | None = None  # plain joints; pairs carry theirs on the pair
    switches: tuple[SwitchConfig, ...] = ()
    cal_speed: int | None = None  # counts/s toward the calibration switch
    cal_pos: int | None = None  # joint position set when the calibration switch is reached
    abs_encoder: AbsEncoderConfig | None = None
    # a joint that falls when its motor is switched off (a pitch joint without a brake): every command
    # that ends with MO=0 says so first, and `jog --hold` keeps it held (docs/motion.md)
    gravity: bool = False
    where: Location = field(default_factory=Location, compare=False)

    @property
    def full_range(self) -> tuple[int, int]:
        return (self.pos_min, self.pos_max)

    @property
    def normal_range(self) -> tuple[int, int]:
        return (self.pos_min + self.margin, self.pos_max - self.margin)

    @property
    def overshoot_range(self) -> tuple[int, int]:
        return (self.pos_min - self.overshoot, self.pos_max + self.overshoot)


@dataclass(frozen=True)
class PairConfig:
    """Two drives that together move a Σ joint (m_a + m_b) and a Δ joint (m_a - m_b).

    ``drive_a`` is the drive with the lower node id (seed D.1.3); the loader sorts them.
    """

    name: str
    drive_a: str
    drive_b: str
    sigma: str  # joint name
    delta: str  # joint name
    current: CurrentLimits | None = None  # applied to both motors
    where: Location = field(default_factory=Location, compare=False)


@dataclass(frozen=True)
class ILCodes:
    """Input-logic values written to IL[n]; public tables disagree across firmware, so they are settings."""

    stop: int = 21
    home: int = 5
    # an input no switch of the config uses: "ignore (no drive function)", active low -- the MBARI
    # table's 4, which [ELMOCAN] writes to switch limit inputs off (elmo-protocol.md, IL[N])
    unused: int = 4


@dataclass(frozen=True)
class ProtocolConfig:
    """Protocol behaviour no public source confirms (elmo-protocol.md marks it UNCONFIRMED).

    Each is a setting with the seed's or the safest value as default, so a real arm is
    matched by configuration; the simulator plays either way.
    """

    set_echo: bool = True  # the drive echoes a set on TPDO2 (False: confirm by reading back)
    query_long: bool = False  # 8-byte queries with the query bit instead of 4-byte ones
    reply_timeout: float = 0.1  # s to wait for one interpreter reply
    retries: int = 1  # resends after a timeout (never for SV)
    mo_settle: float = 0.5  # s the drive ignores the interpreter after MO=0/1 (seed: up to 500 ms)
    mo_confirm_timeout: float = 3.0  # s to wait for MO to read back after MO=0/1
    sv_blackout: float = 0.5  # s the drive's CAN is deaf after SV ("a few hundred ms")
    sdo_timeout: float = 0.3  # s to wait for one SDO answer (canopen's default); also scan's listening time
    boot_timeout: float = 2.0  # s to wait for a drive's boot-up after NMT reset node (Elmo gives no boot time)
    # what each bus's send_interval_us is kept between (the Whistle's limit is UNCONFIRMED,
    # elmo-protocol.md §4.2 puts it in each drive's receive buffer): "per-drive" = frames to the same
    # drive, skipped once that drive has answered the previous frame; "per-bus" = any two frames on the
    # bus (the tool's earlier behaviour)
    pacing: str = "per-drive"
    # per-drive pacing: µs kept between any two frames on a bus (about one worst-case 8-byte frame,
    # 138 bits, at 1 Mbit/s); 0 = none
    pacing_floor_us: int = 140
    # a caller waiting for a reply reads the bus itself (bus/reader.py); False =
    # python-can's Notifier thread reads every frame and hands replies over (one more thread switch).
    # Off by default: a SIGTERM raised inside a caller's read could leave the reader's bookkeeping
    # stale, and the stop's SDO writes then waited for frames nobody read (tests/test_signals_moving.py)
    caller_reads: bool = False
    # UI[n] that `home` sets to 1 once a joint is homed; RAM only, so a reset clears it (docs/motion.md)
    calibration_flag: int = 3


@dataclass(frozen=True)
class HomingConfig:
    """`sherpa home` (docs/home.md): the drive's HM[] codes and the search shape.

    The HM[3] event codes and the HM[4]/HM[5] values differ between public sources
    (motion-and-recording.md §2, UNCONFIRMED), so each is a named setting with the notes' value
    as default; the simulator plays whatever the config says.
    """

    event_immediate: int = 0  # HM[3]: home event at once ([KX2])
    event_input_base: int = 8  # HM[3] = base + n: event on digital input n ([COB]: 9 = input 1)
    after_stop: int = 0  # HM[4]: stop the motion at the event ([MBARI])
    after_nothing: int = 2  # HM[4]: let the motion go on
    px_absolute: int = 0  # HM[5]: PX = HM[2] at the event
    px_none: int = 2  # HM[5]: PX is left alone (the pair's Δ search only stops at its edge)
    slow_divisor: int = 4  # the re-approach runs at cal_speed / this
    backoff: int = 0  # counts to back off the switch before the re-approach; 0 = the joint's margin (at least 10)
    search_margin: int = 0  # the bounded search goes the full range plus this; 0 = the joint's margin
    # a pair search: once one drive's home event fired, the other's must fire within this many ms,
    # else both motors are stopped and `home` reports a wiring fault
    pair_edge_window_ms: int = 100


STOP_METHODS = ("auto", "st", "jv0")
PAIR_START_METHODS = ("group", "sync_rpdo", "sequential")  # motion.pair_start (docs/diffdrive.md)
BUS_ERROR_PASSIVE_ACTIONS = ("stop", "warn")  # motion.bus_error_passive (docs/bus.md)


@dataclass(frozen=True)
class MotionConfig:
    """The motion guard's settings (docs/motion.md): dead-man heartbeat, stop, standstill.

    The host's heartbeat id must be a node id no drive uses; 127 is avoided because it is the
    node id of an unconfigured Elmo drive in the guide's defaults (RPDO2 0x37F).
    """

    host_node_id: int = 126  # the tool's heartbeat COB-ID is 0x700 + this
    # more host ids for commands running at the same time: each motion command takes a free id
    # (host_node_id first) under a lock per bus, so its drives watch its own heartbeat alone
    host_id_pool: tuple[int, ...] = (124, 123, 122, 121)
    consumer_time_ms: int = 500  # 0x1016:1 time: the drive stops this long after the last host heartbeat
    heartbeat_period_ms: int = 0  # host heartbeat period; 0 = a quarter of consumer_time_ms
    # how long a command listens to the pool's ids before it takes one: longer than any drive armed on
    # an id waits for its heartbeat (0 = consumer_time_ms plus one heartbeat period)
    host_id_listen_ms: int = 0
    loss_action: int = 2  # 0x6007 on heartbeat loss (MF bit 11 names 2; 3 quick stop is UNCONFIRMED)
    comm_error_behaviour: int = 2  # 0x1029:1 (0 pre-operational, 1 no change, 2 stopped) [COB]
    stop_method: str = "auto"  # auto: ST, JV=0 + BG where ST is refused; st; jv0
    standstill_timeout: float = 2.0  # s to wait for VX = 0 after a stop
    standstill_velocity: int = 2  # counts/s: |VX| at most this is standstill (encoder noise of a held motor)
    liveness_timeout: float = 1.0  # s the command may go without a sign of life before the heartbeat stops
    velocity_unit_mode: int = 5  # velocity jogs: 5 (JV + BG in position mode) or 2 (speed mode)
    # the move back after a limit breach, in every command: this share of the slowest moved joint's
    # velocity.limit, or recovery_fallback_speed counts/s where no joint has a limit
    recovery_speed: float = 0.5
    # a commanded move with no progress for this long ends as blocked, naming an active end switch (0: off)
    stall_time: float = 1.0
    # counts a joint may lag or lead a played trajectory (move --trajectory) before every joint stops
    tracking_bound: int = 100
    recovery_fallback_speed: int = 100
    # differential pairs (docs/diffdrive.md): how both motors start together. "group": one BG to the
    # group id pair_group_id written to 0x2040 of both drives (RAM, restored afterwards; made effective
    # by a reset communication, pair_group_reset_comm); "sync_rpdo": BG to each drive's RPDO2 made
    # synchronous (0x1401:2 = 1, RAM, for the begin only), executed at one SYNC the tool sends
    # (UNCONFIRMED on the Whistle); "sequential": two BG back to back (no common start)
    pair_start: str = "group"
    pair_group_id: int = 125  # a 7-bit id no device on the pair's bus uses (126 is the host heartbeat)
    # "group": the group id takes effect after an NMT reset communication of both drives, as Elmo's
    # guide (13-10) says; the tool sends it (motors off) and arms the dead-man again, read back.
    # false: a drive on which 0x2040 acts at once
    pair_group_reset_comm: bool = True
    # the host heartbeat's thread asks for real-time priority (SCHED_FIFO) where the OS permits, so a
    # loaded computer keeps its period (docs/motion.md "A busy computer"); false: a normal thread
    heartbeat_realtime: bool = True
    feedback_gain: float = 16.0  # --feedback: SP correction per unit of progress difference between the motors
    feedback_limit: float = 0.5  # --feedback: the correction never changes a motor's SP by more than this share
    # diffdrive move records both motors by TPDO on SYNC (log/record.py) at this rate (Hz, capped to
    # what the bus budget allows); --poll or a recorder that cannot be set up: PX polled instead
    pair_record_rate: float = 500.0
    # the guard's watch of its drives (docs/motion.md): EMCY codes that are warnings (counted, the
    # motion goes on); any other EMCY from a drive whose motor is on stops the command
    emcy_warning_codes: tuple[int, ...] = (0x6300, 0x8110, 0x8140, 0x8200, 0x8210)
    # s between two reads of a moving drive's dead-man entry 0x1016:1 (another node may disarm it)
    deadman_check_interval: float = 0.5
    # the guard's watch of its buses (docs/bus.md): a bus it moves on that goes BUS-OFF (or down, stopped)
    # always stops the command; ERROR-PASSIVE stops it too ("stop") or only warns ("warn")
    bus_error_passive: str = "stop"
    bus_check_interval: float = 0.1  # s between two reads of those buses' controller state (netlink)
    # s: the longest --for of a torque jog or torque step (no drive limit acts in torque mode; the
    # time is the last guard, so a typo like --for 1e9 must not be a run until Ctrl-C)
    max_torque_for: float = 10.0

    @property
    def heartbeat_period_s(self) -> float:
        return (self.heartbeat_period_ms or self.consumer_time_ms / 4) / 1000

    @property
    def host_id_listen_s(self) -> float:
        return (self.host_id_listen_ms or self.consumer_time_ms + self.heartbeat_period_s * 1000) / 1000

    @property
    def host_ids(self) -> tuple[int, ...]:
        """Every id a sherpa command may send its heartbeat as, in the order they are taken."""
        return (self.host_node_id, *(i for i in self.host_id_pool if i != self.host_node_id))


JOYSTICK_MODES = ("velocity", "torque")
JOYSTICK_MIXES = ("xy", "sigma_delta")


@dataclass(frozen=True)
class JoystickMap:
    """One joystick mapping (docs/config.md `joystick:`): an axis to a joint, or two axes to a pair.

    A joint: full deflection of ``axis`` = ``sensitivity`` x the joint's velocity limit (velocity)
    or continuous current (torque). A pair: ``mix: xy`` drives motor a with X+Y and motor b with
    X-Y (the seed's XY+/XY-; each motor's full scale is the smaller joint speed limit), ``mix:
    sigma_delta`` drives the Σ joint with X and the Δ joint with Y.
    """

    joint: str | None = None
    axis: str | None = None  # evdev code name, e.g. ABS_Z
    pair: str | None = None
    x: str | None = None
    y: str | None = None
    mix: str = "xy"
    mode: str = "velocity"
    sensitivity: float = 0.5
    invert: bool = False


@dataclass(frozen=True)
class JoystickConfig:
    """`sherpa jog --joystick` (docs/jog.md): device, send rate, deadzone, the dead-man button, the maps."""

    device: str | None = None  # /dev/input/eventN; None: the first joystick found
    rate_hz: float = 25.0  # commands per second while the dead-man is held (20..50)
    deadzone: float = 0.1  # fraction of full deflection around the centre read as 0
    deadman: str = "BTN_TRIGGER"  # the button that must be held; release stops at once
    axes: tuple[JoystickMap, ...] = ()


@dataclass(frozen=True)
class SimDriveConfig:
    """How one simulated drive differs from a healthy one (faults and mismatch); only the simulator reads it."""

    reply_latency: float = 0.0  # s added to every interpreter reply
    sdo_latency: float = 0.0  # s added to every SDO answer
    # s the drive's one receive buffer holds a frame unless answered: one more frame to it
    # meanwhile is lost (an overrun), so a tool that paces too fast is caught; 0 = off
    rx_buffer: float = 0.0
    drop_probability: float = 0.0  # chance that a frame to or from the drive is lost
    die_at: float | None = None  # s after start: the drive goes silent for good
    die_moving_after: float | None = None  # s after its first BG: the drive goes silent for good (mid-move)
    reboot_at: float | None = None  # s after start: the drive reboots once
    speed_gain: float = 1.0  # runs its profiles this much faster (seed Fig. 9.10/9.11 mismatch)
    heartbeat_ms: int = 0  # 0x1017 producer heartbeat at power-up
    seed: int = 0  # random seed of drop_probability, so a failing run replays
    limit_trip_at: float | None = None  # s after start: trips as if past LL[3]/HL[3] (MF, EMCY 0x8680)
    # servo-loop motor model (sim/servo.py, docs/log.md); servo_bandwidth 0 = the kinematic model
    servo_bandwidth: float = 0.0  # Hz, natural frequency of the position loop
    servo_damping: float = 0.5
    servo_current_limit: float | None = None  # A; None: the drive model's peak current
    supply_current_limit: float | None = None  # A the supply can give (the seed's 1 A supply)
    st_refused_in_speed_mode: bool = False  # ST answers EC 60 in UM=2, as [BLISS] says some firmware does
    start_skew: float = 0.0  # s a separately received BG starts late (a group BG does not; seed Fig. 9.10)
    lag: float = 0.0  # s time constant of the servo loop (bandwidth mismatch of a pair); 0 = perfect
    user_program: int = -1  # what PS answers: -1 idle, -2 no program, 1 a user program runs (SV refused, EC 82)
    firmware: str | None = None  # 0x100A software version instead of the simulator's (a replaced drive)
    # NMT reset communication (0x82) as a full reboot (RAM from flash), not as CiA 301 has it (only
    # 0x1000-0x1FFF from their saved values, the application's RAM kept); Elmo's own is UNCONFIRMED
    reset_comm_reboots: bool = False
    boot_ms: float = 0.0  # from an NMT reset to the boot-up frame, deaf meanwhile; Elmo's is UNCONFIRMED
    # a group id written to 0x2040 takes effect only after NMT reset communication, as Elmo's guide
    # (13-10) says (True); False: at once
    group_id_needs_reset_comm: bool = True
    # the load (sim/load.py), joint side, SI; None: the simulator's default (a shoulder-like joint)
    inertia: float | None = None  # kg m^2
    torque_constant: float | None = None  # N m/A
    viscous: float | None = None  # N m s/rad
    coulomb: float | None = None  # N m
    gravity: float | None = None  # N m at horizontal (position 0): a pitch joint's gravity torque
    back_emf: float | None = None  # V s/rad
    resistance: float | None = None  # ohm
    supply_voltage: float | None = None  # V
    # the real arm's imperfections (docs/simulator.md "Imperfections"); 0 = off, the default
    bus_capacitance: float = 0.0  # F between supply and drive: the supply's voltage sags under a fast move
    supply_resistance: float = 0.0  # ohm, the supply's source resistance (with bus_capacitance)
    velocity_window: float = 0.0  # s: VX from the encoder's whole counts over this window (a ripple)
    cogging_torque: float = 0.0  # N m amplitude of the cogging and friction ripple
    cogging_cycles: int = 0  # its periods per joint turn
    # a fault: counts the drive adds to every PA it stores (echoed as sent): it ends off its target
    target_skew: int = 0


@dataclass(frozen=True)
class SimWiring:
    """`sim: wiring:` a drive's input wiring faults, for `home --check-wiring` (only the simulator reads it)."""

    swap: tuple[tuple[int, int], ...] = ()  # pairs of inputs whose wires are swapped
    invert: tuple[int, ...] = ()  # inputs whose switch is wired inverted (active while released)


@dataclass(frozen=True)
class SimFtConfig:
    """`sim: ft_sensors:` what a simulated F/T sensor feels (sim/ft_sensor.py); only the simulator reads it.

    Gravity: a payload of ``payload_kg`` whose centre of mass sits ``payload_com`` (m, sensor frame)
    from the sensor, tilted about the sensor's x axis by the sum of the ``wrist`` joints' angles.
    Contact: past ``wall_position`` (counts of ``wall_joint``, on ``wall_side``) a spring of
    ``wall_stiffness`` N/rad pushes along ``wall_axis``. Noise is seeded; the bias drifts linearly.
    """

    payload_kg: float = 0.0
    payload_com: tuple[float, float, float] = (0.0, 0.0, 0.05)
    wrist: tuple[str, ...] = ()
    wall_joint: str | None = None
    wall_position: int = 0
    wall_side: str = "high"  # "high": contact above wall_position; "low": below it
    wall_stiffness: float = 500.0  # N per rad of the wall joint past the wall
    wall_axis: str = "Fz"
    noise_force: float = 0.02  # N, standard deviation on each force axis
    noise_torque: float = 0.002  # N·m, on each torque axis
    drift_force: float = 0.01  # N/s on each force axis
    drift_torque: float = 0.001  # N·m/s on each torque axis
    seed: int = 0
    silent_at: float | None = None  # s after start: the sensor stops answering
    status: int = 0  # the 16-bit system status word every reply carries (nonzero: the sensor reports a fault)


SIM_FT_WALL_SIDES = ("high", "low")


@dataclass(frozen=True)
class SimExtraNode:
    """A node the simulator puts on a bus although the config names no drive there (a stray device)."""

    bus: str
    node: int
    vendor_id: int = 0x9A
    device_name: str = "Whistle"
    heartbeat_ms: int = 0  # 0x1017 producer heartbeat at power-up


PoseValue = float | str  # a number in the joint's unit (rad), or text with a unit as `jog --to` takes it


@dataclass(frozen=True)
class Pose:
    """A named pose (`poses:`): joint name -> target. ``values`` are as written (rad, or text such as
    "10deg", "1200counts"); ``counts`` the same in each joint's counts, filled in by validation
    (config/validate.py), which refuses an unknown joint, a bad value and one outside the joint's
    normal range."""

    name: str
    values: Mapping[str, PoseValue]
    counts: Mapping[str, int] = field(default_factory=dict)
    where: Location = field(default_factory=Location, compare=False)


@dataclass(frozen=True)
class ArmConfig:
    name: str
    buses: Mapping[str, BusConfig]
    drives: Mapping[str, DriveConfig]
    joints: Mapping[str, JointConfig]
    pairs: Mapping[str, PairConfig]
    catalog: Catalog
    devices: Mapping[str, DeviceConfig] = field(default_factory=dict)  # `devices:` (not drives)
    il_codes: ILCodes = field(default_factory=ILCodes)
    protocol: ProtocolConfig = field(default_factory=ProtocolConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    joystick: JoystickConfig = field(default_factory=JoystickConfig)
    homing: HomingConfig = field(default_factory=HomingConfig)
    sim: Mapping[str, SimDriveConfig] = field(default_factory=dict)  # drive name -> simulated faults
    sim_extra_nodes: tuple[SimExtraNode, ...] = ()  # `sim: extra_nodes:`, only the simulator reads it
    # `sim: power_up:` joint name -> the joint's real position (counts) at power-up, while PX reads 0
    sim_power_up: Mapping[str, int] = field(default_factory=dict)
    sim_wiring: Mapping[str, SimWiring] = field(default_factory=dict)  # `sim: wiring:` drive name -> faults
    # `sim: reply_timeout:` s to wait for one interpreter reply with --sim (instead of protocol.reply_timeout):
    # the in-process simulator shares a possibly loaded machine, so it is given patient timeouts
    sim_reply_timeout: float = 1.0
    sim_buses: Mapping[str, SimBusConfig] = field(default_factory=dict)  # `sim: buses:` controller faults
    sim_ft: Mapping[str, SimFtConfig] = field(default_factory=dict)  # `sim: ft_sensors:` device name -> what it feels
    # `tuning:` gain key ("KP[2]") -> (low, high) that `tune set` accepts; ops/tune.py has the defaults
    tuning: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    poses: Mapping[str, Pose] = field(default_factory=dict)  # `poses:` name -> pose (docs/move.md)
    source: str | None = None  # file the config came from
    warnings: tuple[str, ...] = ()  # non-fatal findings of validation, shown by `config check`

    def joint_of_drive(self, drive: str) -> JointConfig | None:
        """The plain joint a drive moves, if any."""
        for joint in self.joints.values():
            if joint.drive == drive:
                return joint
        return None

    def device_by_source(self, source: str) -> DeviceConfig | None:
        """The device an ``abs_encoder.source`` names: its name or BUS:NODE."""
        if source in self.devices:
            return self.devices[source]
        return next((d for d in self.devices.values() if d.address == source), None)

    def ft_sensors(self) -> list[DeviceConfig]:
        """The configured F/T sensors, in config order."""
        return [d for d in self.devices.values() if d.ft is not None]

    def pair_of_drive(self, drive: str) -> PairConfig | None:
        for pair in self.pairs.values():
            if drive in (pair.drive_a, pair.drive_b):
                return pair
        return None
