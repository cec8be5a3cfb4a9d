"""The simulated arm on CAN: one SimDrive per configured drive, the arm's mechanics, one pump per bus.

Each bus gets one thread that receives frames, hands them to the addressed drives (SDO to
the drive's SdoServer), advances every drive of the bus to the present and sends what they
produced. One thread per bus fixes the order of events on that bus, like the bus itself.

Mechanics: a plain joint's position is its motor's physical position; a differential
pair's Σ = m_a + m_b and Δ = m_a - m_b. Switches sit at their configured joint positions
and drive the configured inputs of the drives they are wired to; a stop switch tells the
drive which motor direction leads into it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import math
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, TextIO

import filelock

from sherpa_cli.config.model import ArmConfig, JointConfig, PairConfig, SimFtConfig, SwitchConfig, SwitchKind
from sherpa_cli.config.simbus import SimBusConfig
from sherpa_cli.elmo.protocol import NMT_ID, SDO_RX_BASE, SYNC_ID
from sherpa_cli.errors import SherpaError
from sherpa_cli.sim import state as sim_state
from sherpa_cli.sim.buscontroller import BusController, SimNetlink
from sherpa_cli.sim.cia402 import SimCia402Drive
from sherpa_cli.sim.clock import Clock, FrameClock, RealClock, StallMeter
from sherpa_cli.sim.drive import SimDrive
from sherpa_cli.sim.encoder import SimEncoder
from sherpa_cli.sim.ft_sensor import SimFtSensor
from sherpa_cli.sim.settings import SimSettings

if TYPE_CHECKING:
    import can  # imported where a bus is opened: the simulator's modules load without python-can

    from sherpa_cli.sim.sdo import SdoServer

log = logging.getLogger(__name__)

SDO_RX = SDO_RX_BASE
# counts either side of a home switch's position where it reads pressed; a joint that crosses the
# position within one model step also presses it for that step (a fast pass is never missed), so the
# switch's edge -- where homing sets PX -- is at its configured position to within a count
HOME_SWITCH_HALF_WIDTH = 0
ENCODER_VENDOR = 0x0000_0145  # made up: a CiA 406 encoder maker (the sim's, not a real vendor id)
ENCODER_DEVICE_TYPE = 0x0001_0196  # 0x1000: CiA 406 (0x196), single-turn absolute rotary encoder
CIA402_VENDOR = 0x0000_0402  # made up: the simulated CiA 402 drive's maker (not a real vendor id)
CIA402_PRODUCT = 0x0000_0001
LOOPBACK_ROUNDS = 4  # frames drives send because of other drives' frames, per pump cycle
# A frame that waited longer than this for its bus's pump (a starved simulator process: a loaded
# machine, the 15-20x slower vcan guest) reaches the drives at the time it arrived, not when the pump
# got to it: a real drive hears a frame when it is on the bus. Otherwise a host heartbeat queued
# behind a backlog looked lost to the consumer, and the drives stopped a command that sent every beat.
LATE_FRAME_S = 0.05
LATE_FRAME_MAX_S = 10.0  # older than this: a timestamp from another clock (or none), not a late frame
SIM_SV_SHARE = 0.6  # the simulated drive is deaf for this share of protocol.sv_blackout (the tool's bound)


def settings_for(cfg: ArmConfig, drive: str, **overrides: object) -> SimSettings:
    """Simulator behaviour from the config: the drive plays the protocol the config describes;
    ``overrides``: SimSettings fields that win over the config (SimSettings checks them)."""
    d = cfg.drives[drive]
    model = cfg.catalog.drives.get(d.model) if d.model else None
    p = cfg.protocol
    base: dict[str, Any] = dict(  # SimSettings' fields, checked when it is made
        echo_sets=p.set_echo,
        mo_settle_s=p.mo_settle,
        sv_blackout_s=round(p.sv_blackout * SIM_SV_SHARE, 6),
        inputs=model.inputs if model else 6,
        max_current=model.current_peak if model else 20.0,
        stop_code=cfg.il_codes.stop,
        device_name=_device_name(d.model),
        hm_event_immediate=cfg.homing.event_immediate, hm_event_input_base=cfg.homing.event_input_base,
        hm_after_stop=cfg.homing.after_stop, hm_px_absolute=cfg.homing.px_absolute,
    )
    cpr = _drive_cpr(cfg, drive)
    if cpr:
        base["counts_per_rad"] = cpr / (2 * math.pi)
    joint = cfg.joint_of_drive(drive)
    if joint is not None and joint.abs_encoder is not None and joint.abs_encoder.source.upper() == "DRIVE:PY":
        base["py_offset"] = -joint.abs_encoder.offset  # encoder + offset = joint position
    faults = cfg.sim.get(drive)
    if faults is not None:
        base.update(reply_latency_s=faults.reply_latency, sdo_latency_s=faults.sdo_latency,
                    rx_buffer_s=faults.rx_buffer,
                    drop_probability=faults.drop_probability,
                    die_at=faults.die_at, die_moving_after=faults.die_moving_after, reboot_at=faults.reboot_at, heartbeat_ms=faults.heartbeat_ms,
                    seed=faults.seed, limit_trip_at=faults.limit_trip_at,
                    st_refused_in_speed_mode=faults.st_refused_in_speed_mode,
                    start_skew_s=faults.start_skew, lag_s=faults.lag,
                    servo_bandwidth_hz=faults.servo_bandwidth, servo_damping=faults.servo_damping,
                    servo_current_limit=faults.servo_current_limit,
                    supply_current_limit=faults.supply_current_limit, user_program=faults.user_program,
                    reset_comm_reboots=faults.reset_comm_reboots, boot_s=faults.boot_ms / 1000,
                    group_id_needs_reset_comm=faults.group_id_needs_reset_comm,
                    bus_capacitance=faults.bus_capacitance, supply_resistance=faults.supply_resistance,
                    velocity_window_s=faults.velocity_window, cogging_torque=faults.cogging_torque,
                    cogging_cycles=faults.cogging_cycles,
                    store_skew=(("PA", faults.target_skew),) if faults.target_skew else ())
        if faults.firmware is not None:
            base["sw_version"] = faults.firmware
        base.update({key: getattr(faults, key) for key in LOAD_KEYS if getattr(faults, key) is not None})
    base.update(overrides)
    return SimSettings(**base)


LOAD_KEYS = ("inertia", "torque_constant", "viscous", "coulomb", "gravity", "back_emf", "resistance", "supply_voltage")


def _drive_cpr(cfg: ArmConfig, drive: str) -> int | None:
    """Counts per joint turn of what ``drive`` moves: its plain joint, or its pair's Σ joint."""
    joint = cfg.joint_of_drive(drive)
    if joint is not None:
        return joint.cpr
    for pair in cfg.pairs.values():
        if drive in (pair.drive_a, pair.drive_b):
            return cfg.joints[pair.sigma].cpr
    return None


# how far from its calibration switch a joint without absolute feedback powers up by default: this
# share of the way from the switch to the edge of the normal range the homing search comes from
POWER_UP_SHARE = 0.25


def calibration_switch(joint: JointConfig) -> SwitchConfig | None:
    """The switch ``sherpa home`` calibrates ``joint`` on (ops/home.py picks the same one): a plain
    joint's home switch, else its stop switch on the side ``calibration.speed`` points to; a Σ/Δ
    joint's stop switch on that side, else its home switch. None: nothing to home on."""
    if not joint.cal_speed:
        return None
    side = "low" if joint.cal_speed < 0 else "high"
    home = [sw for sw in joint.switches if sw.kind is SwitchKind.HOME]
    stop = [sw for sw in joint.switches if sw.kind is SwitchKind.STOP
            and (sw.side == side or (sw.side is None and (sw.position > 0) == (joint.cal_speed > 0)))]
    order = (home + stop) if joint.drive is not None else (stop + home)
    return order[0] if order else None


def default_power_up(joint: JointConfig) -> int:
    """Where a joint stands at power-up when `sim: power_up:` does not say (PX reads 0 there all the
    same). A joint with absolute feedback (abs_encoder) or nothing to home on: 0, PX = real position.
    Else a quarter of the way from its calibration switch toward the edge of the normal range the
    search comes from (the search runs toward the switch), kept inside the normal range: homing has
    something to find, and a home that just zeroes PX is told apart from a correct one."""
    sw = calibration_switch(joint)
    if joint.abs_encoder is not None or sw is None:
        return 0
    lo, hi = joint.normal_range
    edge = lo if (joint.cal_speed or 0) > 0 else hi  # the search moves toward the switch from here
    return min(max(int(sw.position + (edge - sw.position) * POWER_UP_SHARE), lo), hi)


def power_up_positions(cfg: ArmConfig) -> dict[str, int]:
    """Each drive's real motor position at power-up (counts): `sim: power_up:` (joint -> position),
    else :func:`default_power_up`; PX reads 0 there all the same. A pair's motors follow from its Σ
    and Δ: a = (Σ+Δ)//2, b = Σ - a (an odd Σ+Δ puts Δ one count low)."""
    def at(joint: JointConfig) -> int:
        given = cfg.sim_power_up.get(joint.name)
        return int(given) if given is not None else default_power_up(joint)

    out: dict[str, int] = {}
    for joint in cfg.joints.values():
        if joint.drive is not None:
            out[joint.drive] = at(joint)
    for pair in cfg.pairs.values():
        s, d = at(cfg.joints[pair.sigma]), at(cfg.joints[pair.delta])
        out[pair.drive_a], out[pair.drive_b] = (s + d) // 2, s - (s + d) // 2
    return out


def _pair_of(cfg: ArmConfig, joint: JointConfig) -> PairConfig:
    """The differential pair of a Σ/Δ joint (the loader gives every joint either a drive or a pair)."""
    assert joint.pair is not None, f"joint {joint.name} has neither a drive nor a pair"
    return cfg.pairs[joint.pair]


def _device_name(model: str | None) -> str:
    if not model:
        return "Whistle"
    kind, _, rating = model.partition("-")
    return f"{kind.capitalize()} {rating}".strip()


class _Mechanics:
    """Moves switches with the joints; called by a drive after each of its model steps."""

    def __init__(self, cfg: ArmConfig, drives: Mapping[str, SimDrive]) -> None:
        self.cfg = cfg
        self.drives = drives
        # per drive: (switch, joint position function, +1/-1 = the switch is at the joint's high/low
        # side (0 for home switches), motor direction that leads into it)
        self.wiring: dict[str, list[tuple[SwitchConfig, Callable[[], float], int, int]]] = {n: [] for n in drives}
        self._last: dict[tuple[str, int], float] = {}  # home switches: the joint position at the last update
        for joint in cfg.joints.values():
            self._wire(joint)
        # the hard stops at each joint's overshoot range, per drive that can run into them
        self.hard_stops: dict[str, list[Callable[[], None]]] = {n: [] for n in drives}
        for joint in cfg.joints.values():
            if joint.drive is not None:
                self.hard_stops[joint.drive].append(
                    functools.partial(_clamp_plain, drives[joint.drive], joint.overshoot_range))
        for pair in cfg.pairs.values():
            a, b = drives[pair.drive_a], drives[pair.drive_b]
            check = functools.partial(_clamp_pair, a, b, cfg.joints[pair.sigma].overshoot_range,
                                      cfg.joints[pair.delta].overshoot_range)
            self.hard_stops[pair.drive_a].append(check)
            self.hard_stops[pair.drive_b].append(check)

    def _wire(self, joint: JointConfig) -> None:
        position: Callable[[], float]
        if joint.drive is not None:
            position = functools.partial(_plain_position, self.drives[joint.drive])
            signs = {joint.drive: 1}
        else:
            pair = _pair_of(self.cfg, joint)
            a, b = self.drives[pair.drive_a], self.drives[pair.drive_b]
            if joint.name == pair.sigma:
                position = functools.partial(_sigma_position, a, b)
                signs = {pair.drive_a: 1, pair.drive_b: 1}
            else:
                position = functools.partial(_delta_position, a, b)
                signs = {pair.drive_a: 1, pair.drive_b: -1}
        for sw in joint.switches:
            wired = sw.drives or tuple(signs)
            toward = 0
            if sw.kind is SwitchKind.STOP:
                toward = 1 if (sw.side == "high" or (sw.side is None and sw.position > 0)) else -1
            for name in wired:
                self.wiring[name].append((sw, position, toward, toward * signs.get(name, 1)))

    def update(self, drive_name: str) -> None:
        drive = self.drives[drive_name]
        for check in self.hard_stops[drive_name]:
            check()
        for i, (sw, position, side, direction) in enumerate(self.wiring[drive_name]):
            pos = position()
            if side == 0:
                key = (drive_name, i)
                before = self._last.get(key, pos)
                self._last[key] = pos
                active = abs(pos - sw.position) <= HOME_SWITCH_HALF_WIDTH or (before - sw.position) * (pos - sw.position) < 0
            elif side > 0:
                active = pos >= sw.position
            else:
                active = pos <= sw.position
            drive.set_input(sw.input, active, direction)


def _plain_position(drive: SimDrive) -> float:
    return drive.position


def _sigma_position(a: SimDrive, b: SimDrive) -> float:
    return a.position + b.position


def _delta_position(a: SimDrive, b: SimDrive) -> float:
    return a.position - b.position


def _pair_angle(a: SimDrive, b: SimDrive, sign: int, counts_per_rad: float) -> float:
    """A pair's Σ (sign +1) or Δ (sign -1) angle in rad: what gravity acts on for both its motors."""
    return (a.position + sign * b.position) / counts_per_rad


def _plain_reading(drive: SimDrive, offset: int) -> int:
    """An absolute encoder on a plain joint: the motor's real position minus the encoder's offset."""
    return round(drive.position) - offset


def _pair_reading(a: SimDrive, b: SimDrive, sign: int, offset: int) -> int:
    """An absolute encoder on a Σ (sign +1) or Δ (sign -1) joint, minus its offset."""
    return round(a.position + sign * b.position) - offset


def _answer_ft(sensor: SimFtSensor, can_id: int, data: bytes, out: list[tuple[int, bytes]]) -> None:
    """An F/T sensor hears a frame; what it answers goes to ``out`` (sent by the pump)."""
    out.extend(sensor.receive(can_id, data))


def _send_after_sdo_latency(drive: SimDrive, can_id: int, data: bytes) -> None:
    """An SDO answer through the drive's reply queue, so a late answer leaves on a later tick."""
    drive.send_later(can_id, data, drive.settings.sdo_latency_s)


def _pin(drive: SimDrive, position: float) -> None:
    """The motor stands at ``position``, pressed against a hard stop (no bounce, no coasting)."""
    motor = drive.motor
    whole = math.floor(position)
    motor.counts, motor.frac, motor.v = whole, position - whole, 0.0


def _clamp_plain(drive: SimDrive, bounds: tuple[int, int]) -> None:
    lo, hi = bounds
    if not lo <= drive.position <= hi:
        _pin(drive, min(max(drive.position, lo), hi))


def _clamp_pair(a: SimDrive, b: SimDrive, sigma: tuple[int, int], delta: tuple[int, int]) -> None:
    s, d = a.position + b.position, a.position - b.position
    s2, d2 = min(max(s, sigma[0]), sigma[1]), min(max(d, delta[0]), delta[1])
    if (s2, d2) != (s, d):
        _pin(a, (s2 + d2) / 2)
        _pin(b, (s2 - d2) / 2)


class SimArm:
    """The simulated arm on python-can buses (``virtual``, ``socketcan`` on vcan, ...)."""

    def __init__(self, cfg: ArmConfig, endpoints: Mapping[str, Mapping[str, Any]], *,
                 clock: Clock | None = None, flash: Mapping[str, sim_state.DriveFlash] | None = None,
                 settings: Mapping[str, SimSettings] | None = None, persist: bool = False,
                 tick_s: float = 0.002, bus_factory: Callable[..., can.BusABC] | None = None,
                 event_log: str | None = None, keep_ram: bool = False, link_retry_s: float = 0.5,
                 stalls: StallMeter | None = None, ram_save_s: float = 0.05) -> None:
        """``endpoints``: bus name -> keyword arguments for ``can.Bus`` (interface, channel);
        ``bus_factory`` opens them instead of ``can.Bus``; ``event_log``: a file that gets one JSON
        line per motor on/off and dead-man event (appended, flushed at once), so another process can
        tell when a motor went off; ``keep_ram``: the arm stays powered between runs (`--sim`): its RAM
        is loaded from the state directory by :meth:`start` and saved by :meth:`stop`, under a lock
        held meanwhile (sim/state.py), and while the arm runs it is written again every ``ram_save_s``
        when it changed, so a command killed with SIGKILL leaves the RAM a real arm would hold;
        ``link_retry_s``: how often a pump whose bus failed under it (a kernel interface set down) reopens
        it; ``stalls``: an in-process arm's meter of the time its process did not run, which the drives'
        heartbeat consumers leave out (sim/clock.py)."""
        self.cfg = cfg
        self.stalls = stalls
        self.endpoints = dict(endpoints)
        self.bus_factory = bus_factory
        self.clock = clock or RealClock()
        # where a late frame is placed in time (RealClock; a test's clock may do it too), else None:
        # a stepped or manual clock without it is the test's, and frames reach it when the test moves it
        self._received_at = self.clock.received_at if isinstance(self.clock, FrameClock) else None
        self.persist = persist
        self.tick_s = tick_s
        self.link_retry_s = link_retry_s
        self.link_outages: dict[str, int] = dict.fromkeys(cfg.buses, 0)  # times each bus's link failed under its pump
        self.flash = dict(flash) if flash is not None else sim_state.load(cfg) if persist else {
            name: sim_state.DriveFlash(sim_state.default_serial(cfg, name)) for name in cfg.drives}
        self.drives: dict[str, SimDrive] = {}
        start = power_up_positions(cfg)
        for name, d in cfg.drives.items():
            saved = self.flash[name]
            # config check keeps a cia402 drive to a plain joint: the mechanics below treat it as any drive
            cia402 = d.type == "cia402"
            made = (settings or {}).get(name) or settings_for(
                cfg, name, **({"vendor_id": CIA402_VENDOR, "product_code": CIA402_PRODUCT,
                               "device_name": "CiA 402 drive"} if cia402 else {}))
            self.drives[name] = (SimCia402Drive if cia402 else SimDrive)(
                d.node, clock=self.clock,
                settings=made,
                serial=saved.serial, flash=saved.flash, save_count=saved.save_count,
                speed_gain=cfg.sim[name].speed_gain if name in cfg.sim else 1.0, position=start.get(name, 0),
                on_step=functools.partial(self._drive_stepped, name),
                on_event=functools.partial(self._drive_event, name),
                stalled=None if stalls is None else stalls.read,
                stalled_at=None if stalls is None else stalls.stalled_at)
        self._mechanics = _Mechanics(cfg, self.drives)
        for pair in cfg.pairs.values():
            # a pair's motors carry its joint together: gravity (`gravity:` of each motor, N m at horizontal)
            # acts on the Σ angle, or on Δ's where only Δ is marked gravity-loaded
            a, b = self.drives[pair.drive_a], self.drives[pair.drive_b]
            sign = -1 if cfg.joints[pair.delta].gravity and not cfg.joints[pair.sigma].gravity else 1
            k = cfg.joints[pair.sigma if sign > 0 else pair.delta].cpr / (2 * math.pi)
            for motor in (a.motor, b.motor):
                motor.gravity_angle = functools.partial(_pair_angle, a, b, sign, k)
        for name, w in cfg.sim_wiring.items():
            if name in self.drives:
                self.drives[name].inputs.wiring_faults(w.swap, w.invert)
        # `sim: extra_nodes:` -- devices the config does not name (a stray node, a duplicate id):
        # on their bus like any drive, but outside the arm's mechanics and never saved.
        self.extras: dict[str, tuple[str, SimDrive]] = {
            f"extra-{e.bus}-{e.node}-{i}": (e.bus, SimDrive(
                e.node, clock=self.clock, serial=0x7E000000 + i,
                settings=SimSettings(vendor_id=e.vendor_id, device_name=e.device_name, heartbeat_ms=e.heartbeat_ms)))
            for i, e in enumerate(cfg.sim_extra_nodes)}
        # `devices:` of other types (sherpa_cli/devices): a CANopen encoder answers NMT and SDO (identity,
        # 0x1000 = CiA 406, 0x6004 = its joint's real position minus the joint's abs_encoder offset) and
        # sends 0x6004 in its TPDO1 (sim/encoder.py: cyclic by 0x6200, or on SYNC)
        for dev in cfg.devices.values():
            if dev.type == "canopen-encoder":
                reading, resolution = self._encoder_reading(dev.name)
                self.extras[dev.name] = (dev.bus, SimEncoder(
                    dev.node, position=reading, clock=self.clock, serial=0x7E100000 + dev.node, resolution=resolution,
                    settings=SimSettings(vendor_id=ENCODER_VENDOR, device_name="CANopen encoder", inputs=1),
                    od_live={(0x1000, 0): lambda: ENCODER_DEVICE_TYPE}))
        # `devices:` of type ft_sensor: no CANopen node; the pump hands it the frames on its base id and
        # sends its two reply frames (sim/ft_sensor.py: payload gravity through the wrist, a wall, noise, drift)
        self.ft_sensors: dict[str, tuple[str, SimFtSensor]] = {
            dev.name: (dev.bus, SimFtSensor(dev, cfg.sim_ft.get(dev.name, SimFtConfig()), self.clock, cfg.joints,
                                            self.joint_position))
            for dev in cfg.ft_sensors()}
        self.lock = threading.RLock()  # held by the pumps while they touch drives; tests take it too
        # the host's CAN controller on each bus (`sim: buses:`), read like netlink (bus/linkstate.py)
        self.controllers = {name: BusController(name, cfg.sim_buses.get(name, SimBusConfig()), bus.bitrate,
                                                self.clock.now()) for name, bus in cfg.buses.items()}
        self.netlink = SimNetlink(self.controllers, self.lock)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._buses: dict[str, can.BusABC] = {}
        self._sdo: dict[str, SdoServer] = {}
        self.errors: list[BaseException] = []
        self.late_frames = 0  # frames a pump got to more than LATE_FRAME_S late (heard when they arrived)
        self.event_log = event_log
        self._event_file: TextIO | None = None
        self.keep_ram = keep_ram
        self.ram_save_s = ram_save_s
        # another `--sim` command holds the arm: how long to wait (None: RAM_LOCK_TIMEOUT; 0: refused at
        # once, `sherpa stop`) and where to say so at once (the CLI's stderr)
        self.ram_wait: float | None = None
        self.on_busy: Callable[[str], None] | None = None
        self._ram_lock: filelock.BaseFileLock | None = None

    def unheard(self) -> tuple[int, float]:
        """(requests its drives did not hear in their MO settle windows, the settle time they had left):
        what a stepped clock charges the clients' waits (sim/stepped.py)."""
        return (sum(d.unheard for d in self.drives.values()), sum(d.unheard_s for d in self.drives.values()))

    def _drive_stepped(self, name: str, drive: SimDrive) -> None:
        """A drive's ``on_step``: the mechanics follow its motor."""
        self._mechanics.update(name)

    def _drive_event(self, name: str, drive: SimDrive, t: float, text: str) -> None:
        """A drive's ``on_event``: to the event log."""
        self._log_event(name, drive.node, t, text)

    @classmethod
    def in_process(cls, cfg: ArmConfig,
                   factory: Callable[[ArmConfig, Mapping[str, str]], SimArm] | None = None) -> SimArm:
        """The arm ``--sim`` hands to the session: fresh virtual channels (bus -> channel name),
        built by ``factory(cfg, channels)``, by default :meth:`for_session`."""
        token = uuid.uuid4().hex[:8]  # virtual channels are process-wide: keep sessions apart
        return (factory or cls.for_session)(cfg, {name: f"sherpa-sim-{token}-{name}" for name in cfg.buses})

    @classmethod
    def for_session(cls, cfg: ArmConfig, channels: Mapping[str, str], *, clock: Clock | None = None) -> SimArm:
        """The in-process arm of ``--sim``: virtual channels, flash kept in the state directory;
        ``clock``: its time (default wall time; `log step` gives it a stepped clock). Its drives'
        heartbeat consumers leave out the time this process did not run (sim/clock.py StallMeter)."""
        return cls(cfg, {bus: {"interface": "virtual", "channel": ch} for bus, ch in channels.items()},
                   persist=True, clock=clock, keep_ram=True, stalls=StallMeter())

    def _log_event(self, name: str, node: int, t: float, text: str) -> None:
        """One JSON line per event: ``t`` is the drive's clock (time.monotonic() for a RealClock,
        the same scale in every process of this machine), ``wall`` is time.time()."""
        if self.event_log is None:
            return
        import json
        import time

        if self._event_file is None:
            # open until stop(): one line per event, appended as it happens
            self._event_file = open(self.event_log, "a", encoding="utf-8")  # noqa: SIM115 - closed by stop()
        self._event_file.write(json.dumps({"drive": name, "node": node, "t": t, "wall": time.time(),
                                           "event": text}) + "\n")
        self._event_file.flush()

    def _encoder_reading(self, device: str) -> tuple[Callable[[], int], int]:
        """What encoder ``device`` reads: the real position of the joint whose abs_encoder names it, and
        its steps per revolution (the joint's cpr)."""
        cfg = self.cfg
        for joint in cfg.joints.values():
            enc = joint.abs_encoder
            if enc is None or cfg.device_by_source(enc.source) is not cfg.devices[device]:
                continue
            if joint.drive is not None:
                return functools.partial(_plain_reading, self.drives[joint.drive], enc.offset), joint.cpr
            pair = _pair_of(cfg, joint)
            a, b = self.drives[pair.drive_a], self.drives[pair.drive_b]
            sign = 1 if joint.name == pair.sigma else -1
            return functools.partial(_pair_reading, a, b, sign, enc.offset), joint.cpr
        return (lambda: 0), 4096  # an encoder no joint uses reads 0

    def joint_position(self, joint: str) -> float:
        """A joint's real position (counts): its motor's, or a pair's Σ (a + b) or Δ (a - b)."""
        j = self.cfg.joints[joint]
        if j.drive is not None:
            return self.drives[j.drive].position
        pair = _pair_of(self.cfg, j)
        a, b = self.drives[pair.drive_a], self.drives[pair.drive_b]
        return _sigma_position(a, b) if joint == pair.sigma else _delta_position(a, b)

    def press_switch(self, drive: str, switch_input: int, pressed: bool | None) -> None:
        """A technician holds (True), lets go of (False) or leaves (None) the switch wired to
        ``switch_input`` of ``drive``; a swapped or inverted wire (`sim: wiring:`) shows on the pin."""
        with self.lock:
            self.drives[drive].inputs.press(switch_input, pressed)

    def drive_by_node(self, bus: str, node: int) -> SimDrive | None:
        for name, d in self.cfg.drives.items():
            if d.bus == bus and d.node == node:
                return self.drives[name]
        return None

    # -- running -------------------------------------------------------------------------------

    def start(self) -> SimArm:
        import can

        from sherpa_cli.sim.sdo import SdoServer

        if self.keep_ram:
            self._power_on()
        try:
            for bus_name, kwargs in self.endpoints.items():
                self._buses[bus_name] = (self.bus_factory or can.Bus)(**kwargs)
        except BaseException:
            self._close_buses()
            self._release_ram()
            raise
        try:
            # an SDO answer leaves through its drive's one outbox, in the order the drive produced its
            # frames (a TPDO made before the request goes out before the answer), as on a real node
            for name, d in self.cfg.drives.items():
                if d.bus in self._buses:
                    drive = self.drives[name]
                    send = functools.partial(_send_after_sdo_latency, drive) if drive.settings.sdo_latency_s > 0 \
                        else drive.send_now
                    self._sdo[name] = SdoServer(d.node, drive, send)
            for name, (bus_name, drive) in self.extras.items():
                if bus_name in self._buses:
                    self._sdo[name] = SdoServer(drive.node, drive, drive.send_now)
            if self.stalls is not None:
                self._start_thread(self.stalls.keep_time, (self._stop,), "sim-stalls")
            if self.keep_ram and self._ram_lock is not None and self.ram_save_s > 0:
                self._start_thread(self._keep_ram_saved, (), "sim-ram")
            powered = {bus_name: threading.Event() for bus_name in self._buses}
            for bus_name in self._buses:
                self._start_thread(self._pump, (bus_name, powered[bus_name]), f"sim-{bus_name}")
            # The arm is powered before anyone connects: its power-up boot-ups are on the bus before
            # start() returns, so a tool opening the bus next never hears them by the luck of timing.
            for event in powered.values():
                event.wait(timeout=2.0)
        except BaseException:
            # a signal (the entry's Terminated) or an error half-way: no bus left open, no pump running
            self._abandon_start()
            raise
        return self

    def _start_thread(self, target: Callable[..., None], args: tuple[object, ...], name: str) -> None:
        t = threading.Thread(target=target, args=args, name=name, daemon=True)
        self._threads.append(t)
        t.start()

    def _abandon_start(self) -> None:
        self._stop.set()
        for t in self._threads:
            deadline = time.monotonic() + 2
            while True:
                try:
                    t.join(timeout=max(0.0, deadline - time.monotonic()))
                    break
                except RuntimeError:  # interrupted inside its start(): running, not yet marked started
                    if time.monotonic() >= deadline:
                        break
                    time.sleep(0.001)
        self._threads.clear()
        self._close_buses()
        self._release_ram()

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2)
        self._threads.clear()
        self._close_buses()
        if self._event_file is not None:
            self._event_file.close()
            self._event_file = None
        try:
            if self.persist:
                self.save_state()
        finally:
            if self.keep_ram and self._ram_lock is not None:
                try:
                    self._save_ram()
                finally:
                    self._release_ram()

    # -- RAM between runs ----------------------------------------------------------------------------
    RAM_LOCK_TIMEOUT = 30.0  # s a `--sim` command waits for another to leave the arm (then exit 5)

    def _ram_nodes(self) -> dict[str, SimDrive | SimFtSensor]:
        nodes: dict[str, SimDrive | SimFtSensor] = dict(self.drives)
        nodes.update((name, node) for name, (_, node) in self.extras.items() if isinstance(node, SimEncoder))
        nodes.update((name, sensor) for name, (_, sensor) in self.ft_sensors.items())
        return nodes

    def _power_on(self) -> None:
        """Take the arm's lock and put back what it held when the last command left it (positions only
        after `sim --power-cycle`; nothing after `--reset-state` or the first time)."""
        wait = self.RAM_LOCK_TIMEOUT if self.ram_wait is None else self.ram_wait
        self._ram_lock = sim_state.ram_lock(self.cfg, wait, self.on_busy)
        try:
            saved = sim_state.load_ram(self.cfg)
            if saved is None:
                return
            with self.lock:
                for name, node in self._ram_nodes().items():
                    item = saved["drives"].get(name)
                    if not isinstance(item, dict):
                        continue
                    try:
                        if saved.get("powered", True) and "ram" in item:
                            node.restore_ram(item)
                        elif isinstance(item.get("position"), (int, float)) and math.isfinite(item["position"]):
                            node.restore_position(float(item["position"]))
                    except (ValueError, TypeError, KeyError, LookupError) as exc:
                        raise sim_state.ram_damaged(sim_state.ram_path(self.cfg), f"{name}: {exc}") from None
        except BaseException:
            self._release_ram()
            raise

    def _save_ram(self) -> None:
        with self.lock:
            snapshot = {name: node.ram_snapshot() for name, node in self._ram_nodes().items()}
        sim_state.save_ram(self.cfg, snapshot)

    def _keep_ram_saved(self) -> None:
        """While the command runs, its RAM file follows the drives: a process killed with SIGKILL runs no
        exit path, and the next command must find what the powered arm holds (the motor on, the consumer
        watching, the temporary changes), not what it held before. Taken as each drive stands at its
        last step (the pumps run them), written without fsync (it must outlive the process, not the
        machine) and only when a drive changed; an SV's flash too. A failed write is logged once: the
        final save at stop() reports it."""
        last: dict[str, dict[str, object]] | None = None
        warned = False
        while not self._stop.wait(self.ram_save_s):
            with self.lock:
                snapshot = {name: node.ram_snapshot(advance=False) for name, node in self._ram_nodes().items()}
                saved_flash = any(d.save_count != self.flash[n].save_count for n, d in self.drives.items())
            # an F/T sensor's copy carries its age, new every time: a change of the drives decides
            drives = {name: item for name, item in snapshot.items() if name not in self.ft_sensors}
            if drives == last and not saved_flash:
                continue
            try:
                sim_state.save_ram(self.cfg, snapshot, durable=False)
                if saved_flash:
                    self.save_state()
            except (SherpaError, OSError) as exc:
                if not warned:
                    log.warning("simulated arm: cannot keep its RAM file current: %s", exc)
                warned = True
                continue
            last = drives

    def _release_ram(self) -> None:
        lock, self._ram_lock = self._ram_lock, None
        if lock is not None:
            sim_state.release_ram_lock(self.cfg, lock)

    def save_state(self) -> None:
        with self.lock:
            now = {name: dataclasses.replace(self.flash[name], flash=dict(drive.flash), save_count=drive.save_count)
                   for name, drive in self.drives.items()}
        sim_state.save_changes(self.cfg, self.flash, now)  # merged with another simulator's saves
        self.flash = now

    def __enter__(self) -> SimArm:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _close_buses(self) -> None:
        for bus in self._buses.values():
            with contextlib.suppress(Exception):  # shutting down must not hide the error that stopped the sim
                bus.shutdown()
        self._buses.clear()

    def bus_controller(self, bus: str) -> BusController:
        """The host's controller on ``bus`` (a test control: take ``self.lock`` to call it)."""
        return self.controllers[bus]

    def _pump(self, bus_name: str, powered: threading.Event | None = None) -> None:
        import can

        bus = self._buses[bus_name]
        on_bus = {n: self.drives[n] for n, d in self.cfg.drives.items() if d.bus == bus_name}
        on_bus.update((n, drive) for n, (b, drive) in self.extras.items() if b == bus_name)
        names = list(on_bus)
        sensors = [sensor for b, sensor in self.ft_sensors.values() if b == bus_name]
        by_node: dict[int, list[str]] = {}
        for n, drive in on_bus.items():
            by_node.setdefault(drive.node, []).append(n)  # two entries: a duplicate node id
        next_tick = 0.0
        last_tick = self.clock.now()
        ctrl = self.controllers.get(bus_name)
        failed: list[Exception] = []  # what the link raised in this pass (a send); the pass itself goes on
        down = False  # in an outage: logged once, not once per retry
        sent: list[bool] = []  # a frame went out in this pass: the link works

        def send_raw(can_id: int, data: bytes, is_error: bool = False) -> None:
            # a frame lost to a link that is down is lost as on the wire; the pass goes on without it
            try:
                bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False, is_error_frame=is_error))
                sent.append(True)
            except (can.CanError, OSError) as exc:
                failed.append(exc)

        def send(can_id: int, data: bytes) -> None:
            send_raw(can_id, data)

        try:
            while not self._stop.is_set():
                if failed:
                    reopened = self._relink(bus_name, bus, failed[0], logged=down)
                    failed.clear()
                    if reopened is None:
                        break
                    bus, down = reopened, True
                try:
                    msg = bus.recv(timeout=self.tick_s)
                except (can.CanError, OSError) as exc:
                    failed.append(exc)
                    continue
                sent.clear()
                with self.lock:
                    if msg is None:  # one may have come while this pump waited for the lock (held up)
                        try:
                            msg = bus.recv(timeout=0)
                        except (can.CanError, OSError) as exc:
                            failed.append(exc)
                    now = self.clock.now()
                    # a frame the pump got to late is heard when it arrived; the drives catch up to
                    # now only once the backlog is worked off (no tick to now meanwhile)
                    at = max(self._arrival(msg, now), last_tick)
                    behind = at < now
                    # running motors: every drive of the bus up to (almost) then together first
                    self._guarded(bus_name, "a drive", functools.partial(self._lockstep, on_bus, last_tick, at))
                    last_tick = at
                    # a frame advances only the drives it reached (their replies go out now);
                    # every drive advances at least once per tick_s (motion, heartbeats, latency)
                    touched: list[str] = []
                    # frames pass only while the host's controller runs (not bus-off, down or missing)
                    passing = ctrl is None or ctrl.running
                    ft_frames: list[tuple[int, bytes]] = []  # what an F/T sensor answers to this frame
                    # a remote (RTR) frame requests a frame; it is none itself (an RTR on 0x080 is no
                    # SYNC), and the drives offer no RTR-requestable PDO or node guarding
                    if msg is not None and not msg.is_error_frame and not msg.is_extended_id and \
                            not msg.is_remote_frame and passing:
                        if ctrl is not None:
                            ctrl.count(host_sent=1, sent_bytes=len(msg.data))
                        # receive() ran the drives to now: what the frame caused is in their outbox
                        touched = self._dispatch(msg.arbitration_id, bytes(msg.data), on_bus, by_node, bus_name=bus_name,
                                                 at=at if behind else None)
                        for sensor in sensors:
                            self._guarded(bus_name, sensor.name, functools.partial(
                                _answer_ft, sensor, msg.arbitration_id, bytes(msg.data), ft_frames))
                    now = self.clock.now()
                    ticking = not behind and now >= next_tick
                    if ticking:
                        touched = names
                        next_tick = now + self.tick_s
                    if ticking:
                        for name in touched:
                            self._guarded(bus_name, name, on_bus[name].tick)

                    def out(can_id: int, data: bytes, _passing: bool = passing) -> None:
                        # frames pass only while the host's controller runs (not bus-off, down or missing)
                        if _passing:
                            send(can_id, data)
                            if ctrl is not None:
                                ctrl.count(host_received=1, received_bytes=len(data))
                    for can_id, data in ft_frames:
                        out(can_id, data)
                    self._send_out(touched, on_bus, by_node, out, bus_name, at=at if behind else None)
                    if ctrl is not None:
                        ctrl.tick(now)
                        for can_id, data, is_error in ctrl.pop_frames():
                            send_raw(can_id, data, is_error)
                if down and not failed and (msg is not None or sent):
                    down = False  # frames pass again (a socket that is down only times out on receive)
                    log.info("simulated bus %s: link back, serving again", bus_name)
                if powered is not None and touched is names:
                    powered.set()
        except BaseException as exc:  # noqa: BLE001 - kept in errors: a dead pump shows in tests and `sim --serve`
            if not self._stop.is_set():
                self.errors.append(exc)

    def _relink(self, bus_name: str, bus: can.BusABC, exc: Exception, *, logged: bool) -> can.BusABC | None:
        """The bus failed under the pump (python-can's CanOperationError, OSError ENETDOWN: `ip link set
        vcanN down`): every ``link_retry_s`` close it and open it again, until that works (a link that is
        still down fails the next receive and comes back here) or the arm stops (None). One log line per
        outage, not one per retry."""
        import can

        if not logged:
            self.link_outages[bus_name] = self.link_outages.get(bus_name, 0) + 1
            log.warning("simulated bus %s: link down (%s); reopening every %g s", bus_name, exc, self.link_retry_s)
        while not self._stop.wait(self.link_retry_s):
            with contextlib.suppress(Exception):  # a bus that failed may fail to close as well
                bus.shutdown()
            try:
                bus = (self.bus_factory or can.Bus)(**self.endpoints[bus_name])
            except (can.CanError, OSError):
                continue  # the interface is gone for now (deleted, not yet back)
            self._buses[bus_name] = bus  # stop() closes what is open now
            return bus
        return None

    def _arrival(self, msg: can.Message | None, now: float) -> float:
        """When ``msg`` arrived, on the simulator's clock: ``now``, unless the pump got to it more than
        LATE_FRAME_S late by its receive timestamp (a clock that places frames: FrameClock)."""
        if msg is None or self._received_at is None:
            return now
        late = now - self._received_at(msg.timestamp)
        if LATE_FRAME_S < late < LATE_FRAME_MAX_S:
            self.late_frames += 1
            return now - late
        return now

    def _guarded(self, bus_name: str, name: str, work: Callable[[], object]) -> bool:
        """Run one drive's ``work``; a fault inside the simulator is logged at once and kept in
        :attr:`errors`, and the bus goes on (other drives, later frames). False: it failed."""
        try:
            work()
            return True
        except Exception as exc:
            log.exception("simulated %s on %s: internal fault (the bus goes on)", name, bus_name)
            self.errors.append(exc)
            return False

    def _send_out(self, touched: list[str], on_bus: Mapping[str, SimDrive], by_node: Mapping[int, list[str]],
                  send: Callable[[int, bytes], None], bus_name: str, at: float | None = None) -> None:
        """Send what the ``touched`` drives produced; every frame also reaches the other nodes of the
        bus (a CAN controller does not hear itself), as on a real bus: one drive's heartbeat feeds
        another's consumer. What that makes them send goes out too (a few rounds at most)."""
        pending = list(touched)
        for _ in range(LOOPBACK_ROUNDS):
            if not pending:
                break
            frames = [(name, can_id, data) for name in pending for can_id, data in on_bus[name].pop_frames()]
            reached: list[str] = []
            for sender, can_id, data in frames:
                send(can_id, data)
                if len(on_bus) > 1:
                    for name in self._dispatch(can_id, data, on_bus, by_node, exclude=sender, bus_name=bus_name, at=at):
                        if name not in reached:
                            reached.append(name)
            pending = reached

    @staticmethod
    def _lockstep(on_bus: Mapping[str, SimDrive], since: float, now: float) -> None:
        """While a motor runs, advance the bus's drives together, one model step at a time, so the
        mechanics (a pair's Σ/Δ switches, its joint-space hard stops) see both motors at the same
        instant even when this pump runs late; each drive's own tick() then reaches ``now``."""
        drives = list(on_bus.values())
        if not any(d.motor_on for d in drives):
            return
        step = min(d.settings.model_step_s for d in drives)
        t = since + step
        while t < now:
            for d in drives:
                d.advance_to(t)
            t += step

    def _dispatch(self, can_id: int, data: bytes, on_bus: Mapping[str, SimDrive],
                  by_node: Mapping[int, list[str]], exclude: str | None = None, bus_name: str = "",
                  at: float | None = None) -> list[str]:
        """Hand a frame to the drive(s) it concerns (not to ``exclude``, the node that sent it), at
        time ``at`` (default now: see LATE_FRAME_S); returns their names."""
        if can_id in (NMT_ID, SYNC_ID) or 0x700 <= can_id <= 0x77F or any(d.sync_id == can_id for d in on_bus.values()):
            # NMT broadcast / SYNC (0x080 or what a node's 0x1005 names) / host heartbeats: every drive
            # decides for itself
            targets = list(on_bus)
        else:
            targets = by_node.get(can_id & 0x7F, [])
            if 0x301 <= can_id <= 0x37F:  # RPDO2 of a group id (0x2040): every drive of the group
                targets = targets + [n for n, d in on_bus.items()
                                     if d.group_id == can_id - 0x300 and n not in targets]
        if exclude is not None:
            targets = [name for name in targets if name != exclude]
        sdo = SDO_RX + 1 <= can_id <= SDO_RX + 0x7F
        for name in targets:
            arrived = self._receive(bus_name, name, on_bus[name], can_id, data, at)
            if arrived is None:
                if sdo and name in self._sdo:
                    self._sdo[name].abort_request(data)  # the client hears an abort, not silence
            elif arrived and sdo:
                self._sdo[name].receive(can_id, data)
        return targets

    def _receive(self, bus_name: str, name: str, drive: SimDrive, can_id: int, data: bytes,
                 at: float | None = None) -> bool | None:
        """``drive.receive``; None: it failed inside (logged and kept, see :meth:`_guarded`)."""
        result: list[bool] = []
        ok = self._guarded(bus_name or "its bus", name, lambda: result.append(drive.receive(can_id, data, at)))
        return result[0] if ok else None
