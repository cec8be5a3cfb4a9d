"""One simulated Elmo SimplIQ Whistle at CAN-frame level: NMT, heartbeat producer and
consumer, EMCY, the binary interpreter (RPDO2/TPDO2) and a kinematic motor.

No bus and no threads: the owner feeds frames with :meth:`SimDrive.receive`, advances time
with :meth:`SimDrive.tick` and drains :meth:`SimDrive.pop_frames`. SDO is served elsewhere
over :meth:`SimDrive.od_read` / :meth:`SimDrive.od_write`.
"""

from __future__ import annotations

import functools
import heapq
import itertools
import math
import random
import struct
from collections.abc import Callable, Mapping
from typing import TypeVar

from sherpa_cli.elmo.faults import encode_error_field
from sherpa_cli.elmo.protocol import (
    HEARTBEAT_BASE,
    NMT_ID,
    NMT_OPERATIONAL,
    NMT_PRE_OP,
    NMT_PRE_OPERATIONAL,
    NMT_RESET_COMM,
    NMT_RESET_NODE,
    NMT_START,
    NMT_STOP,
    NMT_STOPPED,
    RPDO2_BASE,
    SDO_RX_BASE,
    SDO_TX_BASE,
    TPDO2_BASE,
)
from sherpa_cli.sim import interpreter
from sherpa_cli.sim.clock import Clock
from sherpa_cli.sim.inputs import Inputs
from sherpa_cli.sim.interpreter import Refused
from sherpa_cli.sim.motor import Motor, motion_status
from sherpa_cli.sim.od import (
    ABORT_NO_SUBINDEX,
    ABORT_RANGE,
    ABORT_READ_ONLY,
    COB_INVALID,
    SYNC_CAN_ID,
    ObjectDictionary,
    ODError,
    OdValue,
    build_od,
    flash_key,
)
from sherpa_cli.sim.params import Value, factory_ram, is_persistent, parse_flash, wrap_int32
from sherpa_cli.sim.pdo import COB_NO_RTR, DRIVE_MAPPABLE, TpdoTable
from sherpa_cli.sim.pvt import PvtEmcy, PvtQueue, RpdoTable
from sherpa_cli.sim.recorder import SDO_ENTRIES, SimRecorder
from sherpa_cli.sim.servo import ServoMotor
from sherpa_cli.sim.settings import SimSettings
from sherpa_cli.sim.speed_estimate import SpeedEstimate

Frame = tuple[int, bytes]
TIME_EPS = 1e-9  # s; float error of summed clock steps, far below any drive timing

NMT = NMT_ID
RPDO2_COMM, RPDO2_MAP, RPDO_SYNC_MAX = 0x1401, 0x1601, 240  # transmission types 0..240: run at the next SYNC
INTERPRETER_IN, INTERPRETER_OUT = 0x2012, 0x2013  # RPDO2 / TPDO2 mapped objects ([IG] 5-8; 64 bits each)
ABORT_UNSUPPORTED = 0x06010000
PRE_OPERATIONAL, OPERATIONAL, STOPPED = NMT_PRE_OPERATIONAL, NMT_OPERATIONAL, NMT_STOPPED  # heartbeat state bytes

MF_HEARTBEAT, MF_SPEED_LIMIT, MF_POSITION_LIMIT = 0x800, 0x20000, 0x400000
# the event a motor switched on with no dead-man watching records (tests assert it never comes)
UNGUARDED_MO = "motor on without an armed dead-man"
EMCY_HEARTBEAT, EMCY_SPEED_LIMIT, EMCY_POSITION_LIMIT = 0x8130, 0x8481, 0x8680
ERR_REG_GENERIC, ERR_REG_COMMUNICATION = 0x01, 0x11  # 0x1001 values from the 0x2F21 table
EMCY_FRAME = struct.Struct("<HBBHH")
EMCY_PVT, ERR_REG_PVT = 0xFF00, 0x81  # [IG] 13-28: the PVT/PT emergencies, the Elmo code in byte 3

SR_MO, SR_MF, SR_UM_SHIFT, SR_MS_SHIFT, SR_LIMIT_STOP = 1 << 4, 1 << 6, 7, 14, 1 << 28
SR_PROGRAM = 1 << 12  # a user program is running (elmo-protocol.md 2.5)


def _make_motor(settings: SimSettings, position: int) -> Motor:
    """The kinematic motor, or with ``servo_bandwidth_hz`` / ``lag_s`` the servo model (sim/servo.py);
    either drives the load (sim/load.py) in torque mode."""
    load, k, supply = settings.load(), settings.counts_per_rad, settings.supply()
    if settings.servo_bandwidth_hz > 0:
        return ServoMotor(counts=position, load=load, counts_per_rad=k, wn=2 * math.pi * settings.servo_bandwidth_hz,
                          zeta=settings.servo_damping, supply=supply)
    if settings.lag_s > 0:  # the same model as a first-order lag: trails by lag_s at speed
        return ServoMotor(counts=position, load=load, counts_per_rad=k, wn=2 / settings.lag_s, zeta=1.0,
                          feed_forward=0.0, integral_gain=0.0, supply=supply)
    return Motor(counts=position, load=load, counts_per_rad=k, supply=supply)


def _saved_int(saved: Mapping[str, object], key: str) -> int:
    value = saved[key]
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{key} {value!r} is not an integer")
    return value


_T = TypeVar("_T")


class FrameRecord(list[_T]):
    """A list that keeps only the newest ``limit`` entries, so a long-running served sim stays bounded."""

    limit = 100_000

    def append(self, item: _T) -> None:
        super().append(item)
        if len(self) > self.limit:
            del self[: len(self) - self.limit // 2]  # trim in chunks: amortised O(1) per append


class SimDrive:
    """A simulated Whistle on node ``node``.

    ``flash`` is the saved parameter image (keys like ``"LL[3]"`` and ``"0x1017:0"``); it is
    copied, and :attr:`flash` holds the drive's own copy for the caller to persist.
    ``speed_gain`` makes the drive run its profiles that much faster than commanded (a
    mismatched motor of a pair). ``position`` is the motor's physical position in counts at
    power-up (PX always starts at 0, as with an incremental encoder). ``on_step(drive)`` is
    called after every model step, so arm mechanics can move switches with the motor.
    """

    def __init__(self, node: int, *, clock: Clock, settings: SimSettings | None = None, serial: int = 1,
                 flash: Mapping[str, Value] | None = None, save_count: int = 0, speed_gain: float = 1.0,
                 position: int = 0, on_step: Callable[[SimDrive], None] | None = None,
                 on_event: Callable[[SimDrive, float, str], None] | None = None,
                 od_live: Mapping[tuple[int, int], Callable[[], OdValue]] | None = None,
                 stalled: Callable[[], float] | None = None,
                 stalled_at: Callable[[float], float] | None = None) -> None:
        if isinstance(node, bool) or not isinstance(node, int) or not 1 <= node <= 127:
            raise ValueError(f"node id must be 1..127, got {node!r}")
        if not speed_gain > 0:
            raise ValueError(f"speed_gain must be > 0, got {speed_gain!r}")
        self.node = node
        self.clock = clock
        self.settings = settings or SimSettings()
        self.serial = serial
        self.speed_gain = float(speed_gain)
        self.on_step = on_step
        # motor on/off and dead-man events with the drive's time: (t, text); also handed to on_event
        self.on_event = on_event
        self.events: list[tuple[float, str]] = FrameRecord()
        self.flash: dict[str, Value] = parse_flash(flash)
        self.save_count = save_count  # restored by the caller along with flash
        self.unguarded_motor_on = 0  # MO=1 accepted while no dead-man watched (deadman_watching)
        self.received: list[tuple[float, int, bytes]] = FrameRecord()  # every frame addressed to this drive
        self.lost: list[tuple[float, int, bytes]] = FrameRecord()  # the subset that never reached its software
        self.od_writes: list[tuple[float, int, int, int]] = []  # SDO writes, for "dry run wrote nothing"
        self.boots = 0
        self.motor = _make_motor(self.settings, int(position))
        # VX from the encoder's counts (settings.velocity_window_s), or None: the model's own speed
        self._speed = SpeedEstimate(self.settings.velocity_window_s) if self.settings.velocity_window_s else None
        self._outbox: list[Frame] = []
        self._replies: list[tuple[float, int, Frame]] = []  # heap: (release time, seq, frame)
        self._seq = itertools.count()
        self._rng = random.Random(self.settings.seed)
        self._t = clock.now()
        self._dead = False
        self._moved = False  # a BG since power-up (die_moving_after)
        # Fault times are seconds after this drive was made (power-up), whatever the clock's origin:
        # a RealClock reads time.monotonic(), which starts long before the simulator does.
        self._die_due = self._after_start(self.settings.die_at)
        self._reboot_due = self._after_start(self.settings.reboot_at)
        self._trip_due = self._after_start(self.settings.limit_trip_at)
        self.inputs = Inputs(self.settings.inputs)
        self._od_live = dict(od_live or {})  # extra live objects: another device type's profile (sim/arm.py)
        self.tpdo = self._make_tpdo_table(node)
        self.rpdos = RpdoTable(node, self.settings.pvt_record_entry)  # RPDO1/3/4: PVT records (sim/pvt.py)
        self.pvt = PvtQueue(self.settings.pvt_rows)
        self.pvt_records = 0  # PVT records taken into the queue
        self.last_request = b""  # the last binary interpreter request (0x2012) and reply (0x2013)
        self.last_reply = b""
        self.syncs = 0  # SYNC frames this drive answered (Operational)
        # (SYNC number, the frame): each buffered synchronous RPDO2 and the SYNC it ran at, so a test
        # sees whether two drives started at one SYNC (pair_start: sync_rpdo)
        self.sync_runs: list[tuple[int, bytes]] = FrameRecord()
        # interpreter requests lost to the MO settle window, and the settle time each had left: what a
        # host waited for them (sim/stepped.py charges it on its clock)
        self.unheard = 0
        self.unheard_s = 0.0
        self._live: dict[str, Callable[[], Value]] | None = None  # status values by key, built on first use
        self._pdo_sources: dict[int, Callable[[], int]] | None = None  # mappable TPDO objects, the same
        # The state below is what every boot (power-up, NMT reset, reboot_at) sets afresh: _boot() does.
        self.last_error = 0  # EC
        self.ram: dict[str, Value] = {}
        self._od: ObjectDictionary  # the object dictionary: flash's writable entries, built by _boot()
        self._error_field = 0  # 0x1003:1, the one stored error of a SimplIQ; a boot clears it
        self._error_register = 0  # 0x1001
        self._motor_on = False
        self._px_offset = 0  # PX = motor counts + this
        self._mf = 0
        self._limit_stop = False  # SR bit 28: a motion stopped at VL[3]/VH[3] or a stop switch
        self._quick_stop = False  # heartbeat lost with 0x6007=3: motor off once the stop is done
        self._hm_pin: bool | None = None  # armed homing on an input: the pin's level when last seen
        self._target_kind = "PA"  # what the next BG starts in UM=5: PA / PR (a move) or JV (a jog)
        self._begin_due: float | None = None  # a BG's start delayed by settings.start_skew_s
        self._via_group = False  # the frame being handled reached the drive on its group id or at SYNC
        self._nmt_state = PRE_OPERATIONAL
        self._hb_last: float | None = None  # the consumed heartbeat's last arrival; None: not armed
        # seconds the simulator's own process did not run (sim/clock.py StallMeter), and their count
        # at the last heartbeat: the consumer leaves them out, they were no silence of the host
        self._stalled = stalled or (lambda: 0.0)
        # the same meter as of an earlier instant (StallMeter.stalled_at): a heartbeat handled late is
        # charged only what the process did not run after it arrived
        self._stalled_at = stalled_at or (lambda _when: self._stalled())
        self._hb_stalled = 0.0
        self._settle_until = -math.inf  # the interpreter is deaf until then (MO settle window)
        self._blackout_until = -math.inf  # SV blackout: nothing in or out until then
        # the receive buffer (settings.rx_buffer_s): holds the last frame to this drive until then
        self._rx_busy_until = -math.inf
        self.overruns: list[tuple[float, int, bytes]] = []  # frames that found the buffer still full
        self._next_heartbeat = math.inf
        self._rpdo2_type = 255  # 0x1401:2
        self._rpdo2_buffer: bytes | None = None  # a synchronous RPDO2 waiting for SYNC
        self.user_program = self.settings.user_program  # PS; a test control (a program started or stopped)
        self.recorder = SimRecorder(self.settings, ram=lambda: self.ram, now=lambda: self._t,
                                    sources=self._recorder_sources())  # sim/recorder.py
        self._boot()

    def _make_tpdo_table(self, node: int) -> TpdoTable:
        """TPDO1/3/4 free to map, TPDO2 the interpreter's reply channel (sim/pdo.py)."""
        return TpdoTable(node, mappable={**DRIVE_MAPPABLE, (0x1002, 0): 32})  # 0x1002 is mappable ([IG] 12-3)

    def _after_start(self, seconds: float | None) -> float | None:
        return None if seconds is None else self._t + seconds

    # -- public API --------------------------------------------------------------------------

    @property
    def outbox(self) -> list[Frame]:
        """Frames waiting to go on the bus, oldest first (drained by :meth:`pop_frames`)."""
        return self._outbox

    def pop_frames(self) -> list[Frame]:
        frames, self._outbox = self._outbox, []
        return frames

    def tick(self) -> None:
        self.advance_to(self.clock.now())

    def advance_to(self, t: float) -> None:
        """Run the drive up to time ``t``; several drives can be stepped in lockstep with it."""
        self._fire_events()
        while self._t < t:
            # A motor that is off cannot move, so one step reaches the next event: the same end
            # state as many small ones, without a thousand idle steps per drive per second.
            step = self.settings.model_step_s if self._motor_on else math.inf
            nxt = min(t, self._t + step, self._next_event())
            if nxt <= self._t:
                break  # unreachable unless an event failed to reschedule; never spin
            if not self._dead:
                self._model_step(nxt - self._t)
            self._t = nxt
            self._fire_events()

    def receive(self, can_id: int, data: bytes, at: float | None = None) -> bool:
        """A frame from the bus; frames for other nodes are ignored and not recorded. ``at``: when it
        arrived, if earlier than now (a bus pump that runs late, sim/arm.py LATE_FRAME_S).

        Returns True if the frame reached the drive's software (False: not addressed to it,
        lost to SV blackout, bus drop or a dead drive, or an SDO request to a node in NMT
        Stopped), so a bus loop hands an SDO request (0x600+node, recorded here but not served)
        to the SDO server only when this is True.
        """
        data = bytes(data)
        self.advance_to(self.clock.now() if at is None else at)
        if not self._addressed(can_id, data):
            return False
        t = self._t
        self.received.append((t, can_id, data))
        if self._dead or t + TIME_EPS < self._blackout_until or self._dropped():
            self.lost.append((t, can_id, data))
            return False
        if self.settings.rx_buffer_s and can_id in (RPDO2_BASE + self.node, SDO_RX_BASE + self.node):
            if t + TIME_EPS < self._rx_busy_until:
                # a frame before the drive took the last one: a tool that paces too fast
                self.overruns.append((t, can_id, data))
                self.lost.append((t, can_id, data))
                return False
            self._rx_busy_until = t + self.settings.rx_buffer_s
        if can_id == NMT:
            self._nmt(data[0])
        elif can_id == self.sync_id:
            self._sync()
        elif can_id == SDO_RX_BASE + self.node:
            # CiA 301: a Stopped node serves only NMT and error control (its heartbeat goes on)
            return self._nmt_state != STOPPED
        elif self._rpdo2_type <= RPDO_SYNC_MAX and can_id in (RPDO2_BASE + self.node, RPDO2_BASE + self.group_id):
            # a synchronous RPDO2 (0x1401:2 = 0..240) is kept until the next SYNC; a later frame
            # overwrites it ([IG] 5-4: one buffered frame)
            if self._nmt_state == OPERATIONAL:
                self._rpdo2_buffer = data
        elif can_id == RPDO2_BASE + self.node:
            self._interpreter_frame(data)
        elif can_id == RPDO2_BASE + self.group_id:
            self._via_group = True  # one frame reaches every drive of the group at once: no start skew
            try:
                self._interpreter_frame(data)
            finally:
                self._via_group = False
        elif can_id == HEARTBEAT_BASE + self._consumer()[0]:
            self._hb_last, self._hb_stalled = t, self._stalled_at(t)
        elif self.rpdos.record_cob(can_id) and self._nmt_state == OPERATIONAL:  # PDOs live in Operational only
            self.pvt_records += 1
            self._pvt_emcy(self.pvt.push(data))
        return True

    def send_now(self, can_id: int, data: bytes) -> None:
        """A frame made outside the drive (an SDO answer) leaving now, through the one outbox: after
        every frame the drive produced before it (a TPDO of the event timer), never before."""
        if can_id == SDO_TX_BASE + self.node:
            self._rx_busy_until = min(self._rx_busy_until, self._t)  # answered: the buffer is free
        if not self._dead:
            self._outbox.append((can_id, bytes(data)))

    def send_later(self, can_id: int, data: bytes, delay: float) -> None:
        """Queue a frame made outside the drive (an SDO answer) to leave ``delay`` s from now, in
        order with the interpreter's replies; lost like them if the drive dies or reboots first."""
        if can_id == SDO_TX_BASE + self.node:
            self._rx_busy_until = min(self._rx_busy_until, self._t + delay)  # answered: buffer free
        heapq.heappush(self._replies, (self._t + delay, next(self._seq), (can_id, bytes(data))))

    def set_input(self, n: int, active: bool, direction: int = 0) -> None:
        """Set digital input ``n`` (1-based) for the arm mechanics. ``active`` means the input's
        function is active (IL polarity is not modelled). ``direction`` says where a stop switch
        lies: +1 positive side, -1 negative, 0 both (a hard stop freezes motion either way)."""
        self.inputs.set(n, active, direction)

    # RPDO1/3/4 (0x1400/0x1600 + n), served from :attr:`rpdos` (sim/pvt.py)
    sdo_rpdos: tuple[int, ...] = (0, 2, 3)
    # 0x2030, the recorder's upload: added to the Whistle's objects by sim/sdo.py
    sdo_more: tuple[tuple[int, int | None, str, int, str], ...] = SDO_ENTRIES

    def od_read(self, index: int, sub: int) -> OdValue | bytes:
        """Read an object; raises od.ODError. A dead drive still answers here: an SDO server
        must check :attr:`dead` and stay silent, as the interpreter does."""
        if index == SDO_ENTRIES[0][0]:
            return self.recorder.upload(sub)
        if self.tpdo.serves(index):
            return self.tpdo.read(index, sub)
        if index in (RPDO2_COMM, RPDO2_MAP):
            return self._rpdo2_read(index, sub)
        if self.rpdos.serves(index):
            return self.rpdos.read(index, sub)
        if sub == 0 and index in self._pdo_values():
            return self._pdo_values()[index]()
        if (index, sub) in ((INTERPRETER_IN, 0), (INTERPRETER_OUT, 0)):
            frame = self.last_request if index == INTERPRETER_IN else self.last_reply
            return int.from_bytes(frame[:8].ljust(8, b"\0"), "little")
        return self._od.read(index, sub)

    def od_write(self, index: int, sub: int, value: int) -> None:
        """Write an object; raises od.ODError carrying the SDO abort code on refusal."""
        self.advance_to(self.clock.now())
        if self.tpdo.serves(index):
            self.tpdo.write(index, sub, value, now=self._t)
            self.od_writes.append((self._t, index, sub, value))
            return
        if index in (INTERPRETER_IN, INTERPRETER_OUT):
            raise ODError(f"0x{index:04X}: the binary interpreter is reached by RPDO2 only", ABORT_UNSUPPORTED)
        if (index, sub) == (0x1003, 0):
            if value != 0:
                raise ODError("0x1003:0: only 0 may be written (it clears the error history)", ABORT_RANGE)
            self._error_field = 0  # CiA 301: writing 0 deletes the stored errors
            self.od_writes.append((self._t, index, sub, value))
            return
        if index in (RPDO2_COMM, RPDO2_MAP):
            self._rpdo2_write(index, sub, value)
            self.od_writes.append((self._t, index, sub, value))
            return
        if self.rpdos.serves(index):
            self.rpdos.write(index, sub, value)
            self.od_writes.append((self._t, index, sub, value))
            return
        value = self._od.check_write(index, sub, value)
        self._od.check_change(index, sub, value)
        self.od_writes.append((self._t, index, sub, value))
        self._od.values[(index, sub)] = value
        if (index, sub) == (0x1016, 1):
            self._hb_last = None  # a new consumer entry waits for that host's first heartbeat
        elif (index, sub) == (0x1017, 0):
            self._next_heartbeat = self._t + value / 1000 if value else math.inf

    @property
    def nmt_state(self) -> int:
        return self._nmt_state

    @property
    def sync_id(self) -> int:
        """The CAN-ID this node takes as SYNC: 0x1005's bits 0..10 (CiA 301; 0x080 by default)."""
        return self._od.values[(0x1005, 0)] & SYNC_CAN_ID

    @property
    def group_id(self) -> int:
        """The group id in effect ([IG] 13-10): 0 = no group; binary interpreter frames to 0x300 + id reach
        this drive. What is written to 0x2040 takes effect at the next reset communication (or boot),
        or at once with ``group_id_needs_reset_comm`` off."""
        if self.settings.group_id_needs_reset_comm:
            return self._group_active
        return self._od.values[(0x2040, 0)]

    @property
    def group_id_written(self) -> int:
        """What 0x2040 holds (RAM), whether or not it has taken effect yet (:attr:`group_id`)."""
        return self._od.values[(0x2040, 0)]

    @property
    def dead(self) -> bool:
        return self._dead

    def die(self) -> None:
        """Die now, as ``die_at`` would: silent from the next step on (tests that kill a drive at a
        chosen point of a command)."""
        self._die_due = self._t

    def trip(self) -> None:
        """Trip now, as ``limit_trip_at`` would: a drive fault (MO=0, MF, EMCY) at the next step
        (tests that fault a drive at a chosen point of a command)."""
        self._trip_due = self._t

    @property
    def motor_on(self) -> bool:
        return self._motor_on

    @property
    def position(self) -> float:
        """Physical motor position in counts (not PX), for arm mechanics."""
        return self.motor.position

    @property
    def px(self) -> int:
        return wrap_int32(self.motor.rounded + self._px_offset)

    @property
    def mf(self) -> int:
        return self._mf

    # -- RAM between `--sim` commands (sim/state.py) ----------------------------------------------

    def ram_snapshot(self, advance: bool = True) -> dict[str, object]:
        """What a powered drive keeps: the joint's position, RAM, objects, faults, NMT state and whether
        its heartbeat consumer was watching (the host that armed it has gone when this is restored).
        ``advance`` False: as the drive stands at its last step, for a copy taken while a bus pump runs
        it (running it to now there could pass a host heartbeat still queued for the pump)."""
        if advance:
            self.advance_to(self.clock.now())
        return {"position": self.motor.position, "px_offset": self._px_offset, "motor_on": self._motor_on,
                "ram": dict(self.ram), "od": {flash_key(*key): value for key, value in self._od.values.items()},
                "mf": self._mf, "last_error": self.last_error, "error_field": self._error_field,
                "error_register": self._error_register, "limit_stop": self._limit_stop, "nmt": self._nmt_state,
                "tpdo": self.tpdo.snapshot(), "rpdo2_type": self._rpdo2_type, "rpdos": self.rpdos.snapshot(),
                "consumer_watching": self._hb_last is not None and self._consumer()[1] > 0}

    def restore_position(self, position: float) -> None:
        """The joint stands at ``position`` (counts) at this power-up; PX reads 0 there."""
        whole = math.floor(position)
        self.motor.off()
        self.motor.counts, self.motor.frac = whole, position - whole
        self._px_offset = -self.motor.rounded

    def restore_ram(self, saved: Mapping[str, object]) -> None:
        """Power this drive back to what :meth:`ram_snapshot` gave, without a boot. A motion does not
        carry over (a motor left on holds its position); a consumer that was watching has lost its host's
        heartbeat and acts on it now. ValueError / TypeError / KeyError: the snapshot is damaged."""
        position = saved["position"]
        if not isinstance(position, (int, float)) or not math.isfinite(position):
            raise ValueError(f"position {position!r}")
        ram, od_values, tpdo = saved["ram"], saved["od"], saved["tpdo"]
        if not isinstance(ram, dict) or not isinstance(od_values, dict) or not isinstance(tpdo, dict):
            raise TypeError("ram, od and tpdo must be mappings")
        ints = {key: _saved_int(saved, key) for key in ("px_offset", "mf", "last_error", "error_field",
                                                         "error_register", "nmt", "rpdo2_type")}
        if ints["nmt"] not in (PRE_OPERATIONAL, OPERATIONAL, STOPPED):
            raise ValueError(f"NMT state {ints['nmt']}")
        values = {}
        for key, value in od_values.items():
            index, sub = (int(part, 16) if i == 0 else int(part) for i, part in enumerate(str(key).split(":")))
            values[(index, sub)] = self._od.check_write(index, sub, value)
        self.tpdo.restore(tpdo)
        rpdos = saved.get("rpdos", {})
        if not isinstance(rpdos, dict):
            raise TypeError("rpdos must be a mapping")
        self.rpdos.restore(rpdos)
        self.ram = {str(k): v for k, v in ram.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
        self._od.values.update(values)
        self.restore_position(float(position))
        self._px_offset = ints["px_offset"]
        self._mf, self.last_error = ints["mf"], ints["last_error"]
        self._error_field, self._error_register = ints["error_field"], ints["error_register"]
        self._nmt_state, self._rpdo2_type = ints["nmt"], ints["rpdo2_type"]
        self._limit_stop = bool(saved.get("limit_stop", False))
        self._motor_on = bool(saved["motor_on"])
        if self._motor_on and self.ram.get("UM") == 1:
            self._apply_torque()
        period = self._od.values[(0x1017, 0)]
        self._next_heartbeat = self._t + period / 1000 if period else math.inf
        if self._nmt_state == OPERATIONAL:
            self.tpdo.start_timers(self._t)
        self._outbox.clear()  # a powered drive did not boot: no boot-up frame
        if saved.get("consumer_watching"):
            self._heartbeat_lost()  # the command that armed it has ended without disarming it

    # -- interpreter state, used by sim.interpreter -------------------------------------------

    def read_param(self, key: str) -> Value:
        live = self._live_values()
        if key in live:
            return live[key]()
        if key[:2] in ("SN", "WS"):
            return self._identity_word(key)
        return self.ram.get(key, 0)  # never-written entries (ET[n], HM[n], CA[n]) read 0

    def write_param(self, key: str, value: Value) -> None:
        if key == "MO":
            self._set_motor(bool(value))
        elif key == "PX":
            self._px_offset = int(value) - self.motor.rounded
        elif key == "HM[1]":
            self.ram[key] = int(value)
            self._arm_homing(bool(value))
        else:
            for skewed, amount in self.settings.store_skew:
                if skewed == key:
                    value = type(value)(value + amount)
            if key[:2] in ("RC", "RG", "RL", "RR"):
                self.recorder.check(key, value)  # refuses like the drive (EC 21)
                if key == "RR":
                    self.recorder.write_rr(int(value))
            self.ram[key] = value
            if key[:3] == "MP[" or key == self.settings.pvt_write_pointer_key:
                self._pvt_configure()  # a new PVT table: the rows sent before are gone
            if key in ("PA", "PR", "JV") or key == self.settings.pvt_start_key:
                self._target_kind = key  # what the next BG starts in UM=5: a move or a jog
            elif key == "TC" and self._motor_on and self.ram["UM"] == 1:
                self._apply_torque()

    def execute(self, letters: str) -> None:
        """BG / ST / SV / LD / HP; raises interpreter.Refused with the Elmo error code."""
        if letters == "BG":
            if not self._motor_on:
                raise Refused(interpreter.EC_MOTOR_MUST_BE_ON)
            skew = self.settings.start_skew_s
            if skew > 0 and not self._via_group:
                self._begin_due = self._t + skew  # a separately received BG starts late (seed Fig. 9.10)
            else:
                self._begin()
            self.recorder.on_bg()  # the recorder's BG trigger (RR=1, RP[3]=1)
        elif letters == "ST":
            if self.settings.st_refused_in_speed_mode and self.ram["UM"] == 2:
                raise Refused(interpreter.EC_NOT_IN_THIS_UM)  # [BLISS]: "cannot be executed in speed mode"
            self._begin_due = None
            self.pvt.stop()
            if self._motor_on:
                self.motor.stop(self.ram["SD"] * self.speed_gain)
        elif letters in ("SV", "LD"):
            if self._motor_on:
                raise Refused(interpreter.EC_MOTOR_MUST_BE_OFF)
            if letters == "SV" and self.program_running:
                raise Refused(self.settings.sv_program_error)
            self._save() if letters == "SV" else self._load_ram()
        # HP: meaning UNCONFIRMED; accepted and ignored so [ELMOCAN]'s HP+SV sequence works.

    # -- boot, NMT, heartbeat ------------------------------------------------------------------

    def _boot(self) -> None:
        """Power-up and NMT reset: RAM from flash, motor off, Pre-operational, boot-up frame."""
        self.boots += 1
        if self._motor_on:
            self._record("motor off: reset")
        self.last_error = 0
        self._load_ram()
        self._error_field = 0
        self._od = build_od(self.settings, self.serial, self.flash, self._od_live_all(), self.node)
        self._group_active = self._od.values[(0x2040, 0)]
        self._motor_on = False
        self.motor.off()
        self._px_offset = -self.motor.rounded
        self._mf = 0
        self._error_register = 0
        self._limit_stop = False
        self._quick_stop = False
        self._hm_pin = None
        self._target_kind = "PA"
        self._begin_due = None
        self._via_group = False
        self._nmt_state = PRE_OPERATIONAL
        self._hb_last = None
        self._settle_until = self._blackout_until = -math.inf
        period = self._od.values[(0x1017, 0)]
        self._next_heartbeat = self._t + period / 1000 if period else math.inf
        self._replies.clear()
        self.tpdo.reset()  # PDO settings are RAM only here
        self.rpdos.reset()
        self.pvt.stop()
        self._rpdo2_type = 255  # 0x1401:2, RAM only: asynchronous, every frame runs when it arrives
        self._rpdo2_buffer = None
        self.recorder.reset()  # the recorder is RAM
        self._send(HEARTBEAT_BASE + self.node, b"\x00")

    def _od_live_all(self) -> dict[tuple[int, int], Callable[[], OdValue]]:
        return {(0x1001, 0): lambda: self._error_register, (0x1002, 0): lambda: self._sr() & 0xFFFFFFFF,
                (0x1003, 0): lambda: int(self._error_field != 0), (0x1003, 1): lambda: self._error_field,
                **self._od_live}

    def _nmt(self, cs: int) -> None:
        before = self._nmt_state
        self._nmt_command(cs)
        if self._nmt_state == OPERATIONAL and before != OPERATIONAL:
            self.tpdo.start_timers(self._t)  # event-driven TPDOs live in Operational only
        elif self._nmt_state != OPERATIONAL:
            self.tpdo.stop_timers()

    def _nmt_command(self, cs: int) -> None:
        # Unknown command specifiers are ignored (the real drive may raise EMCY 0x8200).
        if cs == NMT_START:
            self._nmt_state = OPERATIONAL
        elif cs == NMT_STOP:
            self._nmt_state = STOPPED
        elif cs == NMT_PRE_OP:
            self._nmt_state = PRE_OPERATIONAL
        elif cs == NMT_RESET_NODE or (cs == NMT_RESET_COMM and self.settings.reset_comm_reboots):
            if self.settings.boot_s > 0:
                self._start_booting()
            else:
                self._boot()
        elif cs == NMT_RESET_COMM:
            self._reset_communication()

    def _start_booting(self) -> None:
        """A reset that takes ``boot_s``: the motor off now, nothing heard or sent until :meth:`_boot`."""
        if self._motor_on:
            self._record("motor off: reset")
        self._motor_on = False
        self.motor.off()
        self._nmt_state = PRE_OPERATIONAL
        self._hb_last = None
        self._next_heartbeat = math.inf
        self._begin_due = None
        self._replies.clear()
        self._blackout_until = self._t + self.settings.boot_s
        self._reboot_due = self._t + self.settings.boot_s

    def _reset_communication(self) -> None:
        """CiA 301 reset communication: the communication objects 0x1000-0x1FFF back to their saved
        values (the heartbeat consumer and producer, 0x1029, the PDOs), Pre-operational, a boot-up
        frame; the application keeps its RAM (interpreter values, 0x2000+, the motor, PX)."""
        kept = {key: value for key, value in self._od.values.items() if not 0x1000 <= key[0] <= 0x1FFF}
        self._od = build_od(self.settings, self.serial, self.flash, self._od_live_all(), self.node)
        self._od.values.update(kept)
        self._group_active = self._od.values[(0x2040, 0)]  # a group id written since takes effect now
        self._record(f"NMT reset communication: group id {self._group_active}")
        self._nmt_state = PRE_OPERATIONAL
        self._hb_last = None
        period = self._od.values[(0x1017, 0)]
        self._next_heartbeat = self._t + period / 1000 if period else math.inf
        self.tpdo.reset()
        self.rpdos.reset()
        self.pvt.stop()
        self._rpdo2_type = 255
        self._rpdo2_buffer = None
        self._send(HEARTBEAT_BASE + self.node, b"\x00")

    def _sync(self) -> None:
        """SYNC: a buffered synchronous RPDO2 runs now (every drive that has one, on the same frame:
        no start skew), then synchronous TPDOs sample the drive (PDOs only live in Operational)."""
        if self._nmt_state != OPERATIONAL:
            return
        self.syncs += 1
        frame, self._rpdo2_buffer = self._rpdo2_buffer, None
        if frame is not None:
            self.sync_runs.append((self.syncs, frame))
            self._via_group = True
            try:
                self._interpreter_frame(frame)
            finally:
                self._via_group = False
        for can_id, data in self.tpdo.on_sync(self._pdo_values()):
            self._send_pdo(can_id, data)

    def _pdo_values(self) -> dict[int, Callable[[], int]]:
        values = self._pdo_sources
        if values is None:
            values = self._pdo_sources = {0x1002: lambda: self._sr() & 0xFFFFFFFF, 0x6064: lambda: self.px, 0x6069: self._vx, 0x606C: self._vx,
                                          0x6078: lambda: max(-32768, min(32767, round(self._iq() * 1000)))}
        return values

    def _rpdo2_read(self, index: int, sub: int) -> int:
        """RPDO2, the binary interpreter's: 0x1401 communication parameter (COB-ID, transmission type)
        and 0x1601 its fixed mapping (0x2012, 64 bits)."""
        # bit 30 set as the guide prints it (0x4000037F for node 127)
        values = {0: 2, 1: COB_NO_RTR | RPDO2_BASE + self.node, 2: self._rpdo2_type} if index == RPDO2_COMM else \
            {0: 1, 1: INTERPRETER_IN << 16 | 64}
        if sub in values:
            return values[sub]
        raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)

    def _rpdo2_write(self, index: int, sub: int, value: int) -> None:
        if index == RPDO2_MAP or sub != 2:
            if (index == RPDO2_COMM and sub > 2) or (index == RPDO2_MAP and sub > 1):
                raise ODError(f"object 0x{index:04X} has no sub-index {sub}", ABORT_NO_SUBINDEX)
            raise ODError(f"0x{index:04X}:{sub} is read-only (the binary interpreter's RPDO2)", ABORT_READ_ONLY)
        if not 0 <= value <= 255 or RPDO_SYNC_MAX < value < 254:
            raise ODError(f"0x{RPDO2_COMM:04X}:2: {value} is no transmission type (0..240, 254, 255)", ABORT_RANGE)
        self._rpdo2_type = value
        if value > RPDO_SYNC_MAX:
            self._rpdo2_buffer = None

    def deadman_watching(self) -> bool:
        """Whether a lost host heartbeat would switch the motor off now: a consumer entry with a time,
        that host heard since the entry was written, and a loss action that acts (1, 2, 3)."""
        return (self._consumer()[1] > 0 and self._hb_last is not None
                and self._od.values[(0x6007, 0)] in (1, 2, 3))

    def _consumer_due(self) -> float | None:
        """When the consumer acts if no heartbeat comes: the last one plus its time, plus what the
        simulator's process did not run since (None: not watching)."""
        timeout = self._consumer()[1]
        if self._hb_last is None or not timeout:
            return None
        return self._hb_last + timeout + (self._stalled() - self._hb_stalled)

    def _consumer(self) -> tuple[int, float]:
        """(host node, timeout s) of the 0x1016 sub1 entry; timeout 0 = not monitoring."""
        entry = self._od.values[(0x1016, 1)]
        return entry >> 16 & 0x7F, (entry & 0xFFFF) / 1000

    def _heartbeat_lost(self) -> None:
        self._hb_last = None  # re-armed by the host's next heartbeat
        self._emcy(EMCY_HEARTBEAT, ERR_REG_COMMUNICATION)
        action = self._od.values[(0x6007, 0)]
        self._record(f"heartbeat lost (0x6007={action})")
        if self._motor_on:
            # 0x6007 ([IG] 3.5; DS402 meanings, Elmo's own UNCONFIRMED): 0 nothing, 1 fault and
            # 2 disable voltage -> motor off at once (MF bit 11), 3 quick stop -> decelerate with SD,
            # then motor off (MF bit 11)
            if action in (1, 2):
                self._shut_down(MF_HEARTBEAT, f"heartbeat lost, 0x6007={action}")
            elif action == 3:
                self.motor.stop(self.ram["SD"] * self.speed_gain)
                self._quick_stop = True
        action = self._od.values[(0x1029, 1)]
        if action == 0 and self._nmt_state == OPERATIONAL:
            self._nmt_state = PRE_OPERATIONAL
        elif action == 2:
            self._nmt_state = STOPPED

    # -- time ----------------------------------------------------------------------------------

    def _next_event(self) -> float:
        times = [self._next_heartbeat]
        if not self._dead and self._die_due is not None:
            times.append(self._die_due)
        if self._reboot_due is not None:
            times.append(self._reboot_due)
        if self._trip_due is not None:
            times.append(self._trip_due)
        if self._begin_due is not None:
            times.append(self._begin_due)
        if self.pvt.active:
            times.append(self.pvt.next_due())
        if self._hb_last is not None:  # checked first: _consumer() is a lookup on every step
            due = self._consumer_due()
            if due is not None:
                times.append(due)
        if self._replies:
            times.append(self._replies[0][0])
        if self._nmt_state == OPERATIONAL:
            times.append(self.tpdo.next_due())
        times.append(self.recorder.next_due)
        return min(times)

    def _fire_events(self) -> None:
        # Events due within TIME_EPS count as due: a test clock advanced 10 x 0.01 s sits at
        # 0.09999999999999999 and must still see the 100 ms heartbeat.
        t = self._t + TIME_EPS
        if self._dead:
            return
        if self._die_due is not None and t >= self._die_due:
            if self._motor_on:
                self._record("motor off: the drive died")
            self._dead = True
            self._motor_on = False
            self.motor.off()
            self._next_heartbeat = math.inf
            self._replies.clear()
            self._outbox.clear()  # not on the bus yet: a dead drive sends nothing more, its boot-up included
            return
        self.recorder.fire(t - TIME_EPS)  # servo-rate samples due by now
        if self._reboot_due is not None and t >= self._reboot_due:
            self._reboot_due = None
            self._boot()
        if self._begin_due is not None and t >= self._begin_due:
            self._begin_due = None
            if self._motor_on:
                self._begin()
        if self.pvt.active and t >= self.pvt.next_due():
            self._pvt_boundary()
        if self._trip_due is not None and t >= self._trip_due:
            self._trip_due = None
            self._shut_down(MF_POSITION_LIMIT, "position limit (injected trip)")
            self._emcy(EMCY_POSITION_LIMIT, ERR_REG_GENERIC)
        if self._hb_last is not None:
            due = self._consumer_due()
            if due is not None and t >= due:
                self._heartbeat_lost()
        while self._replies and self._replies[0][0] <= t:
            _, _, (can_id, data) = heapq.heappop(self._replies)
            self._send(can_id, data, blackout_applies=False)
        if self._nmt_state == OPERATIONAL:
            for can_id, data in self.tpdo.on_timers(self._t, self._pdo_values(), TIME_EPS):
                self._send_pdo(can_id, data)
        if t >= self._next_heartbeat:
            self._send(HEARTBEAT_BASE + self.node, bytes([self._nmt_state]))
            period = self._od.values[(0x1017, 0)] / 1000
            while self._next_heartbeat <= t:  # skip beats a coarse tick jumped over
                self._next_heartbeat += period

    # -- frames ---------------------------------------------------------------------------------

    def _addressed(self, can_id: int, data: bytes) -> bool:
        if can_id == NMT:
            return len(data) == 2 and data[1] in (0, self.node)
        if can_id == self.sync_id:
            return True
        if can_id in (RPDO2_BASE + self.node, SDO_RX_BASE + self.node):
            return True
        if self.group_id and can_id == RPDO2_BASE + self.group_id:
            return True
        host, timeout = self._consumer()
        if timeout and can_id == HEARTBEAT_BASE + host:
            return True
        return self.rpdos.record_cob(can_id)

    def _dropped(self) -> bool:
        p = self.settings.drop_probability
        return p > 0 and self._rng.random() < p

    def _send(self, can_id: int, data: bytes, *, blackout_applies: bool = True) -> None:
        if self._dead or (blackout_applies and self._t + TIME_EPS < self._blackout_until) or self._dropped():
            return
        self._outbox.append((can_id, data))

    def _send_pdo(self, can_id: int, data: bytes) -> None:
        """A TPDO the table made (on SYNC or its event timer)."""
        self._send(can_id, data)

    def _emcy(self, code: int, register: int, elmo_code: int = 0, field1: int = 0, field2: int = 0) -> None:
        self._error_register = register
        if code:
            self._error_field = encode_error_field(code, register, elmo_code)
        cob = self._od.values[(0x1014, 0)]
        # CiA 301: a Stopped node sends no EMCY, nor one whose COB-ID is not valid (the error is still stored)
        if self._nmt_state != STOPPED and not cob & COB_INVALID:
            self._send(cob & 0x7FF, EMCY_FRAME.pack(code, register, elmo_code, field1 & 0xFFFF, field2 & 0xFFFF))

    def _interpreter_frame(self, data: bytes) -> None:
        # PDOs only live in Operational; during the MO settle window the interpreter is deaf.
        if self._nmt_state != OPERATIONAL:
            return
        if self._t + TIME_EPS < self._settle_until:
            self.unheard += 1
            self.unheard_s += self._settle_until - self._t
            return
        self.last_request = data
        reply = interpreter.handle(self, data)
        if reply is None:
            return
        self.last_reply = reply
        release = self._t + self.settings.reply_latency_s
        self._rx_busy_until = min(self._rx_busy_until, release)  # answered: the buffer is free again
        heapq.heappush(self._replies, (release, next(self._seq), (TPDO2_BASE + self.node, reply)))
        self._fire_events()

    # -- parameters -----------------------------------------------------------------------------

    def _load_ram(self) -> None:
        self.ram = factory_ram(self.settings.inputs)
        self.ram.update({k: v for k, v in self.flash.items() if not k.startswith("0x")})

    def _save(self) -> None:
        self.flash = {k: v for k, v in self.ram.items() if is_persistent(k)}
        self.flash.update({flash_key(*key): value for key, value in self._od.values.items()})
        self.save_count += 1
        # The reply goes out first (it is queued before this window starts to count for sends).
        self._blackout_until = self._t + self.settings.sv_blackout_s

    def _identity_word(self, key: str) -> int:
        s = self.settings
        words = {"SN[1]": s.vendor_id, "SN[2]": s.product_code, "SN[3]": s.revision, "SN[4]": self.serial,
                 "WS[30]": s.hw_version}
        return wrap_int32(words.get(key, 0))

    def _live_values(self) -> dict[str, Callable[[], Value]]:
        # built once: every status query reads through it
        live = self._live
        if live is None:
            live = self._live = self._build_live_values()
        return live

    def _build_live_values(self) -> dict[str, Callable[[], Value]]:
        return {
            "MO": lambda: int(self._motor_on), "PX": lambda: self.px,
            "VX": self._vx,
            "VY": lambda: 0, "PE": lambda: 0, "VE": lambda: 0, "DV[1]": lambda: 0,
            "DV[2]": self._vx, "DV[3]": lambda: self.px, "MS": self._ms,
            # the auxiliary (absolute) encoder: the motor's real position plus its mounting offset
            "PY": lambda: wrap_int32(round(self.motor.position) + self.settings.py_offset),
            "IQ": self._iq, "ID": lambda: 0.0, "MC": lambda: self.settings.max_current, "LC": lambda: 0,
            "IP": self._ip, "SR": self._sr, "MF": lambda: self._mf, "EC": lambda: self.last_error,
            "PS": lambda: self.user_program,
            "RR": lambda: self.recorder.rr,
            **{f"IB[{n}]": functools.partial(self._ib, n) for n in range(32)},
        }

    # -- motion ---------------------------------------------------------------------------------

    def _set_motor(self, on: bool) -> None:
        self._settle_until = self._t + self.settings.mo_settle_s
        if on == self._motor_on:
            return  # [MBARI] re-sends MO=1 while polling: a repeat must not disturb a motion
        self._limit_stop = False
        self._quick_stop = False
        self._record("motor on: MO=1" if on else "motor off: MO=0")
        if self._speed is not None:
            self._speed.reset(self._t, self.motor.rounded)
        if on and not self.deadman_watching():
            # the tool's invariant (docs/motion.md "The dead-man"), checked by the tests over every MO=1
            self.unguarded_motor_on += 1
            host, timeout = self._consumer()
            self._record(f"{UNGUARDED_MO}: 0x1016:1 host {host} {timeout * 1000:.0f} ms, "
                         f"{'watching' if self._hb_last is not None else 'no heartbeat heard since armed'}, "
                         f"0x6007={self._od.values[(0x6007, 0)]}")
        if not on:
            self._motor_on = False
            self._begin_due = None
            self.pvt.stop()
            self.motor.off()
            return
        self._motor_on = True
        self._mf = 0  # MF is latched until the next MO=1 ([CR MF])
        if self._error_register:
            self._emcy(0x0000, 0)  # CiA 301: the error is gone -- EMCY "error reset / no error"
        self._error_register = 0
        self.motor.off()  # hold the current position until BG
        if self.ram["UM"] == 1:
            self._apply_torque()

    def _apply_torque(self) -> None:
        self.motor.torque(self.ram["TC"] * self.speed_gain)

    def _begin(self) -> None:
        um, r, g = self.ram["UM"], self.ram, self.speed_gain
        self._limit_stop = False
        kind = "JV" if um == 2 else self._target_kind if um == 5 else None
        self._record(f"BG: UM={um}" + (f", {kind}={r[kind]}" if kind else ""))
        if self.settings.die_moving_after is not None and not self._moved:
            self._moved = True  # the first motion since power-up arms die_moving_after
            due = self._t + self.settings.die_moving_after
            self._die_due = due if self._die_due is None else min(self._die_due, due)
        if um == 2:
            jv = min(max(r["JV"], r["VL[2]"]), r["VH[2]"])
            self.motor.jog(jv * g, r["AC"] * g, r["DC"] * g)
        elif um == 5 and self._target_kind == self.settings.pvt_start_key:
            self._pvt_start()
        elif um == 5 and self._target_kind == "JV":
            # a jog in position mode: the speed command is clipped like UM=2's; VL[3]/VH[3] still
            # hold the position reference, so the jog stops at them (SR bit 28)
            jv = min(max(r["JV"], r["VL[2]"]), r["VH[2]"]) if r["VL[2]"] < 0 < r["VH[2]"] else r["JV"]
            self.motor.jog(jv * g, r["AC"] * g, r["DC"] * g)
        elif um == 5:
            if self._target_kind == "PR":
                start = self.motor.x_target if self.motor.mode == "position" else self.motor.counts
                target = start + self._px_offset + self._int_param("PR")
            else:
                target = self._int_param("PA")
            clipped = min(max(target, self._int_param("VL[3]")), self._int_param("VH[3]"))
            self._limit_stop = clipped != target
            if self._target_kind == "PR":
                r["PA"], self._target_kind = target, "PA"  # a second BG must not add PR again
            speed = min(r["SP"], r["VH[2]"], -r["VL[2]"]) if r["VL[2]"] < 0 < r["VH[2]"] else r["SP"]
            self.motor.move_to(clipped - self._px_offset, speed * g, r["AC"] * g, r["DC"] * g)

    def _model_step(self, dt: float) -> None:
        m = self.motor
        if self._motor_on:
            if isinstance(m, ServoMotor):
                m.set_gains(self.ram)  # the loop runs on the gains the drive holds now (tune set, RAM)
            heading = m.intended_direction()
            moving = heading and m.mode in ("velocity", "position", "torque")
            if moving and heading in self.inputs.blocked(self._il, self.settings.stop_code):
                # stop switches act in every mode, torque included (seed C.1.1)
                self.pvt.stop()
                m.stop(self.ram["SD"] * self.speed_gain)
                self._limit_stop = True
            if self.pvt.active:
                self._pvt_step(dt)
            else:
                m.step(dt)
            if self._speed is not None:
                self._speed.sample(self._t + dt, m.rounded)
            if self._quick_stop and m.v == 0 and m.mode in ("idle", "stop"):
                self._shut_down(MF_HEARTBEAT, "heartbeat lost, 0x6007=3 (quick stop done)")
                return
            self._check_limits()
        if self.on_step is not None:
            self.on_step(self)
        self._check_homing()

    # -- homing (HM[], motion-and-recording.md §2; codes from the config's homing: table) ----------

    def _arm_homing(self, on: bool) -> None:
        self._hm_pin = None
        if not on:
            return
        s, event = self.settings, int(self.ram.get("HM[3]", 0))
        if event == s.hm_event_immediate:
            self._home_event()
            return
        n = event - s.hm_event_input_base
        if 1 <= n <= s.inputs:
            self._hm_pin = self.inputs.pin(n)  # the event is the next inactive -> active edge
        # other events (index pulse, ...) are not modelled: the homing stays armed and never fires

    def _check_homing(self) -> None:
        if self._hm_pin is None:
            return
        level = self.inputs.pin(int(self.ram.get("HM[3]", 0)) - self.settings.hm_event_input_base)
        if level and not self._hm_pin:
            self._hm_pin = None
            self._home_event(edge=True)
        else:
            self._hm_pin = level

    def _home_event(self, edge: bool = False) -> None:
        s, r = self.settings, self.ram
        update, value = int(r.get("HM[5]", 0)), int(r.get("HM[2]", 0))
        if update == s.hm_px_absolute:
            # an input edge (the motor moving) is taken at the nearest count of the motor's position,
            # not its floor; an immediate event sets PX itself to the value (it reads back as written)
            self._px_offset = value - (round(self.motor.position) if edge else self.motor.rounded)
        elif update == s.hm_px_absolute + 1:  # relative: the event's position moves by HM[2]
            self._px_offset += value
        if int(r.get("HM[4]", 0)) == s.hm_after_stop and self._motor_on:
            self.motor.stop(r["SD"] * self.speed_gain)
        r["HM[1]"] = 0
        self._record(f"home event: PX={self.px}")

    # -- PVT (sim/pvt.py) --------------------------------------------------------------------------

    def _pvt_period(self) -> float:
        return float(self.ram.get(self.settings.pvt_period_key, 0)) / 1000

    def _pvt_configure(self) -> None:
        r, s = self.ram, self.settings
        if self.pvt.active and self._motor_on:
            self.motor.stop(self.ram["DC"] * self.speed_gain)  # a new table ends the motion: never coast on
        self.pvt.configure(int(r.get("MP[1]", 0)), int(r.get("MP[2]", 0)), int(r.get("MP[3]", 0)),
                           int(r.get("MP[4]", 0)), int(r.get(s.pvt_write_pointer_key, 0)))

    def _pvt_start(self) -> None:
        self._pvt_emcy(self.pvt.start(self._t, self.motor.position + self._px_offset, self._pvt_period()))
        if self.pvt.active:
            self.motor.jog(self.motor.v, 0.0, 0.0)  # MS 2, a heading for the stop switches; _pvt_step moves it

    def _pvt_step(self, dt: float) -> None:
        seg, m = self.pvt.segment, self.motor
        assert seg is not None
        x, v = seg.at(self._t + dt)
        v0 = m.v
        whole = math.floor(x - self._px_offset)
        m.counts, m.frac = whole, x - self._px_offset - whole
        m.v, m.a, m.v_target = v, (v - v0) / dt, v
        if isinstance(m, ServoMotor):
            m.ref.counts, m.ref.frac, m.ref.v = m.counts, m.frac, v

    def _pvt_boundary(self) -> None:
        emcy = self.pvt.boundary(self._t, self._pvt_period())
        if not self.pvt.active:  # the queue ran empty while moving: the drive stops the motor itself
            key = "SD" if self.settings.pvt_underflow_decel == "SD" else "DC"
            self.motor.stop(self.ram[key] * self.speed_gain)
            self._record(f"PVT underflow after {self.pvt.played} rows: stopping with {key}")
        self._pvt_emcy(emcy)

    def _pvt_emcy(self, emcy: PvtEmcy | None) -> None:
        if emcy is not None:
            self._emcy(EMCY_PVT, ERR_REG_PVT, emcy.code, emcy.field1, emcy.field2)

    def _check_limits(self) -> None:
        r = self.ram
        if r["UM"] == 1:
            return  # seed C.1.1/C.1.2: neither position nor velocity limits act in torque mode
        lo, hi = r["LL[3]"], r["HL[3]"]
        if (lo or hi) and not lo <= self.px <= hi:  # LL=HL=0 switches the check off
            self._shut_down(MF_POSITION_LIMIT, "position limit (LL[3]/HL[3])")
            self._emcy(EMCY_POSITION_LIMIT, ERR_REG_GENERIC)
            return
        lo, hi = r["LL[2]"], r["HL[2]"]
        if (lo or hi) and not lo <= self.motor.v <= hi:
            self._shut_down(MF_SPEED_LIMIT, "speed limit (LL[2]/HL[2])")
            self._emcy(EMCY_SPEED_LIMIT, ERR_REG_GENERIC)

    def _shut_down(self, mf_bit: int, why: str) -> None:
        if self._motor_on:
            self._record(f"motor off: {why}")
        self._motor_on = False
        self._quick_stop = False
        self._begin_due = None
        self.pvt.stop()
        self.motor.off()
        self._mf |= mf_bit

    def _record(self, text: str) -> None:
        self.events.append((self._t, text))
        if self.on_event is not None:
            self.on_event(self, self._t, text)

    # -- status registers -----------------------------------------------------------------------

    def _int_param(self, key: str) -> int:
        """An integer parameter's RAM value: coerce() stores every one as an int, this narrows the type."""
        value = self.ram[key]
        if not isinstance(value, int):
            raise TypeError(f"RAM {key} holds {value!r}, not an integer")
        return value

    def _vx(self) -> int:
        if self._speed is not None:
            return wrap_int32(round(self._speed.value(self._t, self.motor.rounded))) if self._motor_on else 0
        return wrap_int32(round(self.motor.v))

    def _ms(self) -> int:
        return motion_status(self.motor, self._int_param("UM"), self._motor_on)

    def _iq(self) -> float:
        if not self._motor_on:
            return 0.0
        if isinstance(self.motor, ServoMotor) or self.ram["UM"] == 1:
            return self.motor.current  # what the drive really puts through: clamped, as on the drive
        peak = self.settings.max_current
        return max(-peak, min(peak, self.motor.a / self.settings.torque_accel))

    def _il(self, n: int) -> int:
        return self._int_param(f"IL[{n}]")

    def _ip(self) -> int:
        return self.inputs.ip(self._il)

    def _ib(self, n: int) -> int:
        return self._ip() >> n & 1

    def _sr(self) -> int:
        sr = (self._int_param("UM") & 7) << SR_UM_SHIFT | self._ms() << SR_MS_SHIFT
        if self._motor_on:
            sr |= SR_MO
        if self._mf:
            sr |= SR_MF
        if self._limit_stop:
            sr |= SR_LIMIT_STOP
        if self.program_running:
            sr |= SR_PROGRAM
        sr |= self.recorder.state << 16  # recorder state, SR bits 16-17
        return wrap_int32(sr)

    @property
    def program_running(self) -> bool:
        return self.user_program == self.settings.user_program_running

    def _recorder_sources(self) -> dict[str, Callable[[], float]]:
        """What the recorder samples (sim/recorder.py): the servo model's command and error where it has one."""
        def ref() -> Motor:
            return self.motor.ref if isinstance(self.motor, ServoMotor) else self.motor

        return {"pos": lambda: self.px, "vel": lambda: self.motor.v, "cur": self._iq,
                "pos_err": lambda: ref().position - self.motor.position if self._motor_on else 0.0,
                "vel_cmd": lambda: ref().v if self._motor_on else 0.0}
