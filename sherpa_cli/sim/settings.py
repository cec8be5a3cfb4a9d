"""Behaviour knobs of a simulated Whistle.

Every field is either a point the protocol doc (elmo-protocol.md) marks UNCONFIRMED, so that
tests can exercise both readings of the manual, or a fault to inject. Defaults are the values
the seed / public sources suggest; a bench measurement should replace them when one exists.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from sherpa_cli.sim.load import Load
from sherpa_cli.sim.supply import Supply


@dataclass(frozen=True)
class SimSettings:
    # The guide contradicts itself on whether a set is echoed (section 1.3); public code ([COB])
    # relies on the echo. False = silent on success; errors are always replied.
    echo_sets: bool = True
    # No Elmo figure exists for MO latency (section 4.1); the seed saw the interpreter stay
    # deaf for up to 500 ms after MO=1/MO=0, so requests in this window get no reply.
    mo_settle_s: float = 0.5
    # SV disables the CAN drivers for "a few hundred ms" ([CR 3-138]): frames sent to the
    # drive in this window are lost and the drive sends nothing (its heartbeat pauses too).
    sv_blackout_s: float = 0.3
    # Typical round-trip time is UNCONFIRMED (section 4.2); delay every interpreter reply.
    reply_latency_s: float = 0.0
    # The same for SDO answers (0x580+node), e.g. a drive busy in its own program; 0 = at once.
    sdo_latency_s: float = 0.0
    # The drive's one receive buffer (elmo-protocol.md 4.2): a frame to this drive (its
    # RPDO2 or SDO request) is held this long unless answered first; one more frame to the drive
    # meanwhile is an overrun, lost and counted in ``overruns``. UNCONFIRMED how long a Whistle
    # takes; 0 = off (every frame is taken at once).
    rx_buffer_s: float = 0.0
    # Chance that any one frame to or from the drive is lost on the bus; drawn from a
    # random.Random(seed) so a failing run can be replayed.
    drop_probability: float = 0.0
    seed: int = 0
    # 0x1017 producer heartbeat time in ms; the guide's default is 0 (off).
    heartbeat_ms: int = 0
    # Identity (0x1018, SN[1..4], 0x1008/9/A). 0x9A is Elmo's vendor id on EtherCAT; the
    # SimplIQ-CAN value is UNCONFIRMED. Product code and versions are made up but shaped like
    # the guide's examples (revision 0x000103E8 = 1.1000, hardware "0x1FF6B").
    vendor_id: int = 0x9A
    product_code: int = 0x00010100
    revision: int = 0x000103E8
    device_name: str = "Whistle"
    hw_version: int = 0x1FF6B  # WS[30]; 0x1009 shows it as hex text
    sw_version: str = "Whistle 1.1.10.4 SIM"
    # NMT reset communication (0x82): CiA 301 reloads only the communication objects 0x1000-0x1FFF
    # from their saved values and keeps the application's RAM (False); True plays a full reboot
    # like reset node. Elmo's own behaviour is UNCONFIRMED.
    reset_comm_reboots: bool = False
    # Time from an NMT reset (node, or communication played as a reboot) to the boot-up frame: the
    # motor goes off at once and the drive hears nothing until it has booted. Elmo gives no boot
    # time (UNCONFIRMED); 0 boots at once.
    boot_s: float = 0.0
    # Elmo's implementation guide (13-10): a group id written to 0x2040 takes effect after an NMT
    # reset communication (True); False makes it effective at once. Default as documented.
    group_id_needs_reset_comm: bool = True
    # Digital inputs IL[1..inputs]; the catalog's Whistle models have 6.
    inputs: int = 6
    # MC (A, read-only): the whistle-10/60's peak current. CL[1] may be at most MC/2 and
    # PL[1] at most MC ([MBARI]), so this bounds the out-of-range (EC 21) checks.
    max_current: float = 20.0
    # IL value whose input acts as an end (stop) switch. The seed's Whistle firmware uses 21;
    # public tables disagree across firmware (design.md), so it follows the config's il_codes.
    stop_code: int = 21
    # The kinematic model's IQ outside torque mode: its profile's acceleration / this (cnt/s^2 per A),
    # clamped to the peak current. Motion is integrated in steps of at most model_step_s so a coarse
    # tick() still brakes in time.
    torque_accel: float = 10000.0
    model_step_s: float = 0.001
    # The load (sim/load.py), joint side, SI: what torque mode (UM=1) and the servo model drive. The
    # defaults are a shoulder-like joint: 1 A settles near 0.5 rad/s (seed Fig. 9.8/9.9).
    inertia: float = 0.06  # kg m^2
    torque_constant: float = 1.0  # N m/A
    viscous: float = 1.2  # N m s/rad
    coulomb: float = 0.4  # N m
    gravity: float = 0.0  # N m at horizontal (position 0); a pitch joint's setting
    back_emf: float = 4.0  # V s/rad
    resistance: float = 1.0  # ohm
    supply_voltage: float = 25.0  # V
    counts_per_rad: float = 3600 / (2 * math.pi)  # the joint's cpr / 2 pi
    # The real arm's imperfections (docs/simulator.md "Imperfections"), all off by default: the seed's
    # bench profile turns them on. bus_capacitance F between the supply and the drive: > 0 makes the
    # supply sag (sim/supply.py) -- its supply_current_limit then limits through the bus voltage, and
    # supply_resistance ohm is its source resistance; 0 = a stiff supply (load.py's power bound).
    bus_capacitance: float = 0.0
    supply_resistance: float = 0.0
    # The speed the drive reports (VX, 0x6069/0x606C): > 0 = the encoder's whole counts over this window
    # (a speed estimated from position differences, with the quantisation's ripple); 0 = the model's speed.
    velocity_window_s: float = 0.0
    # Cogging and friction ripple: a torque of this amplitude (N m), cogging_cycles periods per joint
    # turn, its phase drawn from ``seed`` (the same run for the same seed).
    cogging_torque: float = 0.0
    cogging_cycles: int = 0
    # Fault injection: at die_at the drive goes silent for good (crashed CPU, power stage off);
    # at reboot_at it resets once as after NMT reset node (brown-out, watchdog).
    die_at: float | None = None
    # ... or die_moving_after s after its first motion started (BG): mid-move, whatever the host's start-up
    # time (a process test kills one drive of a pair in the middle of a command)
    die_moving_after: float | None = None
    reboot_at: float | None = None
    # Fault injection: (parameter key, amount) pairs; a set of that key is echoed as sent but
    # stored off by the amount, as a drive that garbles a value would. Only a read-back shows it.
    store_skew: tuple[tuple[str, float], ...] = ()
    # At limit_trip_at the drive trips as if its feedback had left LL[3]..HL[3] (a bumped joint,
    # a noisy encoder): MO=0, MF 0x400000, EMCY 0x8680 -- a fault a monitor must show decoded.
    limit_trip_at: float | None = None
    # [BLISS]: ST "cannot be executed in speed control mode" on some firmware; True: ST in UM=2
    # answers EC 12 and a tool must stop with JV=0 + BG (elmo-protocol.md 2.1, UNCONFIRMED).
    st_refused_in_speed_mode: bool = False
    # HM[] homing codes (motion-and-recording.md §2, UNCONFIRMED): the sim plays the config's homing: table
    hm_event_immediate: int = 0
    hm_event_input_base: int = 8
    hm_after_stop: int = 0
    hm_px_absolute: int = 0
    # PY (an absolute encoder on the auxiliary input) reads the motor's real position plus this
    py_offset: int = 0
    # A differential pair's start skew (seed Fig. 9.10/9.11): a BG received on the drive's own
    # RPDO2 starts its motion this many seconds late (host latency between two separately sent
    # begin commands). A BG sent to the drive's group id (0x2040) or executed at SYNC starts at
    # once on every drive of the group.
    start_skew_s: float = 0.0
    # PVT (sim/pvt.py, docs/pvt.md; all UNCONFIRMED): the rows of the PVT table ([IG] 13-28: 1..64), the
    # RPDO mapping value of the PVT record (0x2001 sub 0, 64 bits), the interpreter keys that hold the period
    # (ms) and the first row written, and what the motor stops with on an underflow ("DC" or "SD").
    pvt_rows: int = 64
    pvt_record_entry: int = 0x20010040
    pvt_period_key: str = "QT[1]"
    pvt_write_pointer_key: str = "MP[6]"
    pvt_start_key: str = "PV"
    pvt_underflow_decel: str = "DC"
    # The servo model (sim/servo.py), one model for both settings: lag_s > 0 (diffdrive) is its
    # first-order-lag form (damping 1, no velocity feed-forward, bandwidth 1 / (pi lag_s)): the motor
    # trails its profile by lag_s at speed; servo_bandwidth_hz > 0 (`log step`) its PID form with
    # velocity feed-forward (natural frequency, damping). The current goes through the load's limits:
    # servo_current_limit A (None: max_current; never above it), the supply's voltage against the
    # back-EMF, and supply_current_limit A of supply current (the seed's 1 A supply, Fig. 9.4/9.5).
    # Both 0 = the kinematic model (a perfect loop; torque mode still drives the load).
    lag_s: float = 0.0
    servo_bandwidth_hz: float = 0.0
    servo_damping: float = 0.5
    servo_current_limit: float | None = None
    supply_current_limit: float | None = None
    # User program (real-arm.md section 4, one public source: UNCONFIRMED): what PS answers at power-up
    # (-1 idle, -2 no program, 1 running; tests set SimDrive.user_program). While PS reads
    # user_program_running, SR bit 12 is set and SV answers sv_program_error (EC 82 "program is running").
    user_program: int = -1
    user_program_running: int = 1
    sv_program_error: int = 82
    # [IG] 9-2: the command letters "must be upper-case". What a SimplIQ answers a frame whose letters
    # are lower case, not letters or not ASCII (or that cannot be parsed otherwise) is UNCONFIRMED; the
    # guide's error reply (9-4) with EC 2 "bad command", its code for a command it does not know, is
    # the documented reading. Frames too short to carry letters and index (< 4 bytes) stay unanswered.
    malformed_command_error: int = 2

    def load(self) -> Load:
        """The load this drive's motor drives (sim/load.py)."""
        peak = self.max_current if self.servo_current_limit is None else min(self.servo_current_limit, self.max_current)
        phase = random.Random(f"cogging:{self.seed}").uniform(0.0, 2 * math.pi) if self.cogging_torque else 0.0
        return Load(inertia=self.inertia, torque_constant=self.torque_constant, viscous=self.viscous,
                    coulomb=self.coulomb, gravity=self.gravity, back_emf=self.back_emf, resistance=self.resistance,
                    supply_voltage=self.supply_voltage, supply_current=self.supply_current_limit, peak_current=peak,
                    cogging_torque=self.cogging_torque, cogging_cycles=self.cogging_cycles, cogging_phase=phase)

    def supply(self) -> Supply | None:
        """A supply that sags (sim/supply.py), or None: a stiff one."""
        if not self.bus_capacitance:
            return None
        return Supply(voltage=self.supply_voltage, current_limit=self.supply_current_limit,
                      capacitance=self.bus_capacitance, resistance=self.supply_resistance)
    # The drive's recorder (sim/recorder.py, real-arm.md 2): one source each, so the simulator plays
    # whatever the host's RecorderSettings (elmo/recorder.py) may assume. Sample time at RG=1 (s),
    # samples shared by the signals, 0x2030 header layout ("cob" / "aligned"), data type nibble
    # (4 long, 5 float), signal ids by name, the 0x2030 sub-index of logical signal 1, and an
    # injected upload fault ("" none, "short", "bad_type", "abort").
    recorder_sample_s: float = 360e-6
    recorder_capacity: int = 4096
    recorder_header: str = "cob"
    recorder_type: int = 4
    recorder_signals: tuple[tuple[str, int], ...] = (("pos", 2), ("vel", 1), ("cur", 10), ("pos_err", 4),
                                                     ("vel_cmd", 16))
    recorder_sub_base: int = 1
    recorder_upload_fault: str = ""

    def __post_init__(self) -> None:
        for name in ("mo_settle_s", "sv_blackout_s", "reply_latency_s", "sdo_latency_s", "start_skew_s", "lag_s",
                     "rx_buffer_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"SimSettings.{name} must be >= 0")
        if not 0.0 <= self.drop_probability <= 1.0:
            raise ValueError("SimSettings.drop_probability must be within 0..1")
        if not 0 <= self.heartbeat_ms <= 0xFFFF:
            raise ValueError("SimSettings.heartbeat_ms must fit u16 (0x1017)")
        if not 0 <= self.malformed_command_error <= 0xFF:
            raise ValueError("SimSettings.malformed_command_error must be an Elmo error code 0..255")
        if not 1 <= self.inputs <= 10:
            raise ValueError("SimSettings.inputs must be 1..10 (IL index range)")
        if self.model_step_s <= 0:
            raise ValueError("SimSettings.model_step_s must be > 0")
        if self.max_current <= 0:
            raise ValueError("SimSettings.max_current must be > 0")
        if not (math.isfinite(self.servo_bandwidth_hz) and self.servo_bandwidth_hz >= 0):
            raise ValueError("SimSettings.servo_bandwidth_hz must be a finite number >= 0")
        if not (math.isfinite(self.servo_damping) and self.servo_damping > 0):
            raise ValueError("SimSettings.servo_damping must be a finite number > 0")
        if not (math.isfinite(self.counts_per_rad) and self.counts_per_rad > 0):
            raise ValueError("SimSettings.counts_per_rad must be a finite number > 0")
        for name in ("bus_capacitance", "supply_resistance", "velocity_window_s", "cogging_torque"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"SimSettings.{name} must be a finite number >= 0")
        if self.cogging_cycles < 0:
            raise ValueError("SimSettings.cogging_cycles must be >= 0")
        self.load()  # checks the load's numbers
        if not self.recorder_sample_s > 0 or self.recorder_capacity < 1:
            raise ValueError("SimSettings.recorder_sample_s and recorder_capacity must be > 0")
        if self.recorder_header not in ("cob", "aligned") or self.recorder_type not in (4, 5) \
                or self.recorder_upload_fault not in ("", "short", "bad_type", "abort"):
            raise ValueError("SimSettings.recorder_header must be cob|aligned, recorder_type 4|5, "
                             "recorder_upload_fault ''|short|bad_type|abort")
        for name in ("servo_current_limit", "supply_current_limit"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"SimSettings.{name} must be a finite number > 0 (or None)")
