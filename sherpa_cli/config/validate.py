"""Value and cross-reference checks shared by both config formats.

Loaders check shape and types and hand over the model plus a table of locations; here we
check what the values mean. All problems are collected and the first in file order is
raised, so fixing errors top to bottom works; the hint says how many more were found.
"""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import replace

from sherpa_cli import units
from sherpa_cli.config.model import (
    ArmConfig,
    CurrentLimits,
    DeviceConfig,
    DriveModel,
    JointConfig,
    JointRole,
    Pose,
    SwitchKind,
)
from sherpa_cli.config.yamlnodes import Locs, suggest
from sherpa_cli.errors import ConfigError, Location, UsageError
from sherpa_cli.words import plural

MAX_NODE_ID = 127
# safe bounds of the dead-man: beyond them a killed or hung tool's motor runs on
MAX_CONSUMER_TIME_MS = 2000  # ms a drive keeps moving after the tool's last heartbeat
MAX_LIVENESS_TIMEOUT_S = 10.0  # s a hung command keeps its heartbeat going
MAX_TORQUE_FOR_LIMIT_S = 60.0  # s: the highest motion.max_torque_for
DEFAULT_INPUTS: int = DriveModel.__dataclass_fields__["inputs"].default  # type: ignore[assignment]


def _line(loc: Location) -> str:
    return f"line {loc.line}" if loc.line is not None else "unknown line"


def _did_you_mean(word: str, choices: list[str]) -> str:
    close = suggest(word, choices)
    if close:
        return f"; did you mean '{close}'?"
    return f"; expected one of: {', '.join(sorted(choices))}" if choices else ""


class _Report:
    def __init__(self, source: str | None) -> None:
        self.source = source
        self.errors: list[ConfigError] = []
        self.warnings: list[str] = []
        self.warn_no_model = True

    def error(self, loc: Location, message: str, hint: str | None = None) -> None:
        self.errors.append(ConfigError(message, loc, hint=hint))

    def warn(self, loc: Location, message: str) -> None:
        self.warnings.append(f"{loc}: {message}")

    def raise_first(self) -> None:
        if not self.errors:
            return
        # one problem per place: the bounds checks run last and add nothing where a check already spoke
        unique: dict[Location, ConfigError] = {}
        for e in self.errors:
            unique.setdefault(e.location, e)
        ordered = sorted(unique.values(), key=lambda e: (e.location.line is None, e.location.line or 0))
        first = ordered[0]
        if len(ordered) > 1:
            more = f"{plural(len(ordered) - 1, 'more problem')} found in this file after this one"
            first.hint = f"{first.hint}; {more}" if first.hint else more
        raise first


def validate(cfg: ArmConfig, locs: Locs, warnings: list[str] | None = None, *,
             warn_no_model: bool = True) -> ArmConfig:
    """Raise ConfigError for the first problem in file order; return cfg with its warnings.

    ``warn_no_model=False`` is for formats that cannot name a model at all (rosparam); their
    loader says so once instead of once per drive.
    """
    r = _Report(cfg.source)
    r.warn_no_model = warn_no_model
    r.warnings.extend(warnings or [])
    _check_il_codes(cfg, locs, r)
    _check_protocol(cfg, locs, r)
    _check_motion(cfg, locs, r)
    _check_homing(cfg, locs, r)
    _check_sim(cfg, locs, r)
    _check_catalog(cfg, locs, r)
    _check_buses(cfg, locs, r)
    _check_drives(cfg, locs, r)
    _check_devices(cfg, locs, r)
    _check_sim_ft(cfg, locs, r)
    _check_names(cfg, locs, r)
    _check_usage(cfg, locs, r)
    for joint in cfg.joints.values():
        _check_joint(cfg, joint, locs, r)
    _check_switch_inputs(cfg, locs, r)
    _check_joystick(cfg, locs, r)
    poses = _check_poses(cfg, locs, r)
    _check_bounds(cfg, locs, r)
    r.raise_first()
    return replace(cfg, warnings=tuple(r.warnings), poses=poses)


def _check_protocol(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    p = cfg.protocol
    if not p.reply_timeout > 0:
        r.error(locs.get("protocol", "reply_timeout"), f"reply_timeout {p.reply_timeout} s must be > 0")
    if not 0 < p.sdo_timeout <= 60:
        r.error(locs.get("protocol", "sdo_timeout"), f"sdo_timeout {p.sdo_timeout} s must be > 0 and <= 60")
    if not 0 < p.boot_timeout <= 60:
        r.error(locs.get("protocol", "boot_timeout"), f"boot_timeout {p.boot_timeout} s must be > 0 and <= 60")
    if p.retries < 0:
        r.error(locs.get("protocol", "retries"), f"retries {p.retries} is negative; expected 0 or more")
    if not 1 <= p.calibration_flag <= 24:
        r.error(locs.get("protocol", "calibration_flag"),
                f"calibration_flag {p.calibration_flag} must be a UI index 1..24")
    if p.pacing not in ("per-drive", "per-bus"):
        r.error(locs.get("protocol", "pacing"), f"pacing {p.pacing!r}: expected per-drive or per-bus")
    if not 0 <= p.pacing_floor_us <= 1_000_000:
        r.error(locs.get("protocol", "pacing_floor_us"),
                f"pacing_floor_us {p.pacing_floor_us} must be 0..1,000,000 µs")
    for key in ("mo_settle", "mo_confirm_timeout", "sv_blackout"):
        if getattr(p, key) < 0:
            r.error(locs.get("protocol", key), f"{key} {getattr(p, key)} s is negative; expected >= 0")


def _check_homing(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    w = cfg.homing.pair_edge_window_ms
    if not 1 <= w <= 2000:
        r.error(locs.get("homing", "pair_edge_window_ms"),
                f"pair_edge_window_ms {w} must be 1..2000 (ms a pair's second home event may lag the first)")


def _check_motion(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    m = cfg.motion
    where = lambda key: locs.get("motion", key)  # noqa: E731
    if not 1 <= m.host_node_id <= 127:
        r.error(where("host_node_id"), f"host_node_id {m.host_node_id} out of range 1..127")
    else:
        for d in cfg.drives.values():
            if d.node == m.host_node_id:
                r.error(where("host_node_id"), f"host_node_id {m.host_node_id} is the node id of drive "
                        f"'{d.name}' ({d.bus}); the tool's heartbeat needs an id no drive uses")
                break
    if len(set(m.host_id_pool)) != len(m.host_id_pool):
        r.error(where("host_id_pool"), f"host_id_pool {list(m.host_id_pool)} names an id twice")
    if len(m.host_id_pool) > 16:
        r.error(where("host_id_pool"), f"host_id_pool has {len(m.host_id_pool)} ids; at most 16")
    used = {d.node: d for d in cfg.drives.values()} | {dev.node: dev for dev in cfg.devices.values()}
    for hid in m.host_id_pool:
        if not 1 <= hid <= 127:
            r.error(where("host_id_pool"), f"host_id_pool: {hid} out of range 1..127")
        elif hid in used:
            r.error(where("host_id_pool"), f"host_id_pool: {hid} is the node id of '{used[hid].name}' "
                    f"({used[hid].bus}); a host heartbeat needs an id no device uses")
        elif hid == m.pair_group_id:
            r.error(where("host_id_pool"), f"host_id_pool: {hid} is motion.pair_group_id")
    if not 1 <= m.consumer_time_ms <= 0xFFFF:
        r.error(where("consumer_time_ms"), f"consumer_time_ms {m.consumer_time_ms} must be 1..65535 (0x1016:1 is 16 bits)")
    elif m.consumer_time_ms > MAX_CONSUMER_TIME_MS:
        r.error(where("consumer_time_ms"), f"consumer_time_ms {m.consumer_time_ms} is above the safe bound "
                f"{MAX_CONSUMER_TIME_MS} ms: a killed tool's motor would run that long before its drive stops it")
    elif not 0 <= m.heartbeat_period_ms <= m.consumer_time_ms / 2:
        r.error(where("heartbeat_period_ms"), f"heartbeat_period_ms {m.heartbeat_period_ms} must be 0 (a quarter "
                f"of consumer_time_ms) or at most half of consumer_time_ms ({m.consumer_time_ms})")
    if m.host_id_listen_ms and not m.consumer_time_ms <= m.host_id_listen_ms <= 10_000:
        r.error(where("host_id_listen_ms"), f"host_id_listen_ms {m.host_id_listen_ms} must be 0 (consumer_time_ms plus "
                f"one heartbeat period) or {m.consumer_time_ms} (consumer_time_ms) .. 10000: a shorter listen could take "
                "the id of a command killed a moment ago while its drives still watch it")
    if not 0 <= m.stall_time <= 30:
        r.error(where("stall_time"), f"stall_time {m.stall_time} must be 0 (off) .. 30 s")
    if not 1 <= m.tracking_bound <= 1_000_000:
        r.error(where("tracking_bound"), f"tracking_bound {m.tracking_bound} counts must be 1..1000000")
    if not 0 < m.recovery_speed <= 1:
        r.error(where("recovery_speed"), f"recovery_speed {m.recovery_speed} must be > 0 and at most 1 "
                "(a share of the joint's velocity.limit)")
    if not 1 <= m.recovery_fallback_speed <= 100_000:
        r.error(where("recovery_fallback_speed"), f"recovery_fallback_speed {m.recovery_fallback_speed} must be "
                "1..100000 counts/s")
    if not 0 <= m.loss_action <= 3:
        r.error(where("loss_action"), f"loss_action {m.loss_action} must be 0..3 (0x6007)")
    elif m.loss_action == 0:
        r.error(where("loss_action"), "loss_action 0 is refused (the safe bound is 1..3): a drive would keep "
                "moving when the tool's heartbeat stops (a killed tool, a pulled cable)")
    if not 0 <= m.comm_error_behaviour <= 2:
        r.error(where("comm_error_behaviour"), f"comm_error_behaviour {m.comm_error_behaviour} must be 0..2 (0x1029:1)")
    from sherpa_cli.config.model import STOP_METHODS

    if m.stop_method not in STOP_METHODS:
        r.error(where("stop_method"), f"stop_method '{m.stop_method}': expected one of {', '.join(STOP_METHODS)}")
    for key in ("standstill_timeout", "liveness_timeout"):
        if not getattr(m, key) > 0:
            r.error(where(key), f"{key} {getattr(m, key)} s must be > 0")
    if m.liveness_timeout > MAX_LIVENESS_TIMEOUT_S or not math.isfinite(m.liveness_timeout):
        r.error(where("liveness_timeout"), f"liveness_timeout {m.liveness_timeout} s is above the safe bound "
                f"{MAX_LIVENESS_TIMEOUT_S:g} s: a hung tool would keep its motors going that long")
    if not (math.isfinite(m.max_torque_for) and 0 < m.max_torque_for <= MAX_TORQUE_FOR_LIMIT_S):
        r.error(where("max_torque_for"), f"max_torque_for {m.max_torque_for} s must be > 0 and at most "
                f"{MAX_TORQUE_FOR_LIMIT_S:g} s (no drive limit acts in torque mode: the time is the last guard)")
    for code in m.emcy_warning_codes:
        if not 0 <= code <= 0xFFFF:
            r.error(where("emcy_warning_codes"), f"emcy_warning_codes: {code} out of range 0..0xFFFF (an EMCY code)")
    if not (math.isfinite(m.deadman_check_interval) and 0.05 <= m.deadman_check_interval <= 10):
        r.error(where("deadman_check_interval"), f"deadman_check_interval {m.deadman_check_interval} s must be "
                "0.05..10")
    from sherpa_cli.config.model import BUS_ERROR_PASSIVE_ACTIONS

    if m.bus_error_passive not in BUS_ERROR_PASSIVE_ACTIONS:
        r.error(where("bus_error_passive"), f"bus_error_passive '{m.bus_error_passive}': expected one of "
                f"{', '.join(BUS_ERROR_PASSIVE_ACTIONS)}")
    if not (math.isfinite(m.bus_check_interval) and 0.01 <= m.bus_check_interval <= 5):
        r.error(where("bus_check_interval"), f"bus_check_interval {m.bus_check_interval} s must be 0.01..5")
    if not 0 <= m.standstill_velocity <= 1000:
        r.error(where("standstill_velocity"), f"standstill_velocity {m.standstill_velocity} counts/s must be 0..1000")
    from sherpa_cli.config.model import PAIR_START_METHODS

    if m.pair_start not in PAIR_START_METHODS:
        r.error(where("pair_start"), f"pair_start '{m.pair_start}': expected one of {', '.join(PAIR_START_METHODS)}")
    if not (math.isfinite(m.pair_record_rate) and m.pair_record_rate > 0):
        r.error(where("pair_record_rate"), f"pair_record_rate {m.pair_record_rate} Hz must be > 0")
    if m.velocity_unit_mode not in (2, 5):
        r.error(where("velocity_unit_mode"), f"velocity_unit_mode {m.velocity_unit_mode}: expected 5 (jog in "
                "position mode) or 2 (speed mode)")


def _check_sim(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    t = cfg.sim_reply_timeout
    if not (isinstance(t, (int, float)) and 0 < t <= 60):
        r.error(locs.get("sim", "reply_timeout"), f"sim reply_timeout {t} s must be > 0 and at most 60")
    for name, faults in cfg.sim.items():
        if name not in cfg.drives:
            close = difflib.get_close_matches(name, list(cfg.drives), n=1)
            r.error(locs.get("sim", "drives", name), f"sim fault for unknown drive '{name}'"
                    + (f"; did you mean '{close[0]}'?" if close else ""))
            continue
        if not 0.0 <= faults.drop_probability <= 1.0:
            r.error(locs.get("sim", "drives", name, "drop_probability"),
                    f"drop_probability {faults.drop_probability} must be within 0..1")
        if faults.reply_latency < 0:
            r.error(locs.get("sim", "drives", name, "reply_latency"), "reply_latency must be >= 0")
        if faults.sdo_latency < 0:
            r.error(locs.get("sim", "drives", name, "sdo_latency"), "sdo_latency must be >= 0")
        if faults.rx_buffer < 0:
            r.error(locs.get("sim", "drives", name, "rx_buffer"), "rx_buffer must be >= 0")
        if not faults.speed_gain > 0:
            r.error(locs.get("sim", "drives", name, "speed_gain"), "speed_gain must be > 0")
        if faults.limit_trip_at is not None and faults.limit_trip_at < 0:
            r.error(locs.get("sim", "drives", name, "limit_trip_at"), "limit_trip_at must be >= 0")
    for i, extra in enumerate(cfg.sim_extra_nodes):
        where = ("sim", "extra_nodes", str(i))
        if extra.bus not in cfg.buses:
            r.error(locs.get(*where, "bus"), f"extra node on unknown bus '{extra.bus}'; "
                    f"configured buses: {', '.join(cfg.buses)}")
        if not 1 <= extra.node <= 127:
            r.error(locs.get(*where, "node"), f"node id {extra.node} out of range 1..127")
        if not 0 <= extra.vendor_id <= 0xFFFFFFFF:
            r.error(locs.get(*where, "vendor_id"), f"vendor_id {extra.vendor_id} does not fit 32 bits")


def _check_devices(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    from sherpa_cli.config.model import DEVICE_TYPES, ENCODER_POSITION_FROM, ENCODER_TPDO_TRIGGERS

    taken = {(d.bus, d.node): f"drive {d.name}" for d in cfg.drives.values()}
    for dev in cfg.devices.values():
        where = ("device", dev.name)
        if dev.type not in DEVICE_TYPES or dev.type == "elmo":
            others = [t for t in DEVICE_TYPES if t != "elmo"]
            r.error(locs.get(*where, "type"), f"device {dev.name}: unknown type '{dev.type}'; known: "
                    f"{', '.join(others)} (Elmo drives go under drives:)")
        if dev.bus not in cfg.buses:
            r.error(locs.get(*where, "bus"), f"device {dev.name} on unknown bus '{dev.bus}'; "
                    f"configured buses: {', '.join(cfg.buses)}")
        if dev.ft is not None:
            _check_ft_sensor(cfg, dev, locs, r)
            continue
        if not 1 <= dev.node <= 127:
            r.error(locs.get(*where, "node"), f"device {dev.name}: node id {dev.node} out of range 1..127")
        other = taken.get((dev.bus, dev.node))
        if other is not None:
            r.error(locs.get(*where, "node"), f"device {dev.name}: node {dev.bus}:{dev.node} is already {other}")
        if dev.position_from not in ENCODER_POSITION_FROM:
            r.error(locs.get(*where, "position_from"), f"device {dev.name}: position_from '{dev.position_from}'; "
                    f"expected one of: {', '.join(ENCODER_POSITION_FROM)}")
        if dev.tpdo_trigger not in ENCODER_TPDO_TRIGGERS:
            r.error(locs.get(*where, "tpdo_trigger"), f"device {dev.name}: tpdo_trigger '{dev.tpdo_trigger}'; "
                    f"expected one of: {', '.join(ENCODER_TPDO_TRIGGERS)}")
        if not 1 <= dev.cyclic_ms <= 0xFFFF:
            r.error(locs.get(*where, "cyclic_ms"), f"device {dev.name}: cyclic_ms {dev.cyclic_ms} out of range "
                    "1..65535 (0x6200 is 16 bits, in ms)")
        taken[(dev.bus, dev.node)] = f"device {dev.name}"
    for joint in cfg.joints.values():
        enc = joint.abs_encoder
        if enc is None or enc.source.lower().startswith("drive:"):
            continue
        import re

        if cfg.device_by_source(enc.source) is None and re.fullmatch(r"[\w-]+:\d+", enc.source):
            r.error(locs.get("joint", joint.name, "abs_encoder", "source"),
                    f"{joint.name}: abs_encoder source '{enc.source}' names no configured device "
                    f"(devices: {', '.join(cfg.devices) or 'none'})")


# CiA 301's predefined connection set: the ids a CANopen node with id n uses (the F/T sensor's base id
# and its replies must stay clear of them on its bus). Written here again: config sits below elmo.
_FIXED_IDS = {0x000: "NMT", 0x080: "SYNC", 0x100: "TIME", 0x7E4: "LSS", 0x7E5: "LSS"}
_NODE_ID_BASES = ((0x080, "EMCY"), (0x180, "TPDO1"), (0x200, "RPDO1"), (0x280, "TPDO2"), (0x300, "RPDO2"),
                  (0x380, "TPDO3"), (0x400, "RPDO3"), (0x480, "TPDO4"), (0x500, "RPDO4"), (0x580, "SDO tx"),
                  (0x600, "SDO rx"), (0x700, "heartbeat"))
MAX_FT_BASE_ID = 0x7FF - 6
FT_COUNT_MAX = 0x7FFF  # the F/T short format's INT16: an axis reads no more than this


def _ids_in_use(cfg: ArmConfig, bus: str, skip: str) -> dict[int, str]:
    """Every 11-bit id another configured node on ``bus`` uses, and whose it is."""
    used = dict(_FIXED_IDS)
    nodes = [(f"drive {d.name}", d.node) for d in cfg.drives.values() if d.bus == bus]
    nodes += [(f"device {d.name}", d.node) for d in cfg.devices.values() if d.bus == bus and d.canopen]
    nodes += [("the tool's heartbeat", h) for h in cfg.motion.host_ids]
    if any(d.bus == bus for p in cfg.pairs.values() for d in (cfg.drives.get(p.drive_a), cfg.drives.get(p.drive_b))
           if d is not None):
        nodes.append(("the pairs' group id", cfg.motion.pair_group_id))  # a pair's BG goes to its RPDO2
    only = {"the tool's heartbeat": "heartbeat", "the pairs' group id": "RPDO2"}
    for who, node in nodes:
        for base, what in _NODE_ID_BASES:
            if who in only and what != only[who]:
                continue
            used.setdefault(base + node, f"{what} 0x{base + node:03X} of {who} (node {node})")
    for d in cfg.devices.values():
        if d.ft is not None and d.bus == bus and d.name != skip:
            for i, cob in enumerate((d.ft.base_id, d.ft.base_id + 5, d.ft.base_id + 6)):
                used.setdefault(cob, f"0x{cob:03X} of F/T sensor {d.name} ({('base', 'base+5', 'base+6')[i]})")
    return used


def _check_ft_sensor(cfg: ArmConfig, dev: DeviceConfig, locs: Locs, r: _Report) -> None:
    """An ft_sensor: base id and its reply ids free on its bus, calibration given, limits > 0."""
    ft = dev.ft
    assert ft is not None
    where = ("device", dev.name)
    if not 0 < ft.base_id <= MAX_FT_BASE_ID:
        r.error(locs.get(*where, "base_id"), f"device {dev.name}: base_id 0x{ft.base_id:X} out of range "
                f"0x001..0x{MAX_FT_BASE_ID:03X} (the replies come on base+5 and base+6, 11-bit ids)")
    elif dev.bus in cfg.buses:
        used = _ids_in_use(cfg, dev.bus, dev.name)
        for offset, label in ((0, "base"), (5, "base+5"), (6, "base+6")):
            other = used.get(ft.base_id + offset)
            if other is not None:
                r.error(locs.get(*where, "base_id"), f"device {dev.name}: base_id 0x{ft.base_id:03X}: its {label} "
                        f"id 0x{ft.base_id + offset:03X} is {other} on {dev.bus}",
                        hint="set the sensor's base address switches to ids no node on the bus uses")
                break
    for key in ("counts_per_force", "counts_per_torque"):
        value = getattr(ft, key)
        if value is None:
            r.error(locs.get(*where), f"device {dev.name}: {key} missing; take it from the sensor's calibration "
                    "sheet (counts per N / per N·m)")
        elif not value > 0:
            r.error(locs.get(*where, key), f"device {dev.name}: {key} {value:g} must be > 0")
    for key, unit, per_key in (("force_limit", "N", "counts_per_force"), ("torque_limit", "N·m", "counts_per_torque")):
        per = getattr(ft, per_key)
        value = getattr(ft, key)
        if value is not None and not value > 0:
            r.error(locs.get(*where, key), f"device {dev.name}: {key} {value:g} {unit} must be > 0")
        elif value is not None and per is not None and per > 0 and value * per >= FT_COUNT_MAX:
            # one axis saturates below the limit: a push along it could never be seen to cross it
            r.error(locs.get(*where, key), f"device {dev.name}: {key} {value:g} {unit} is beyond what the sensor "
                    f"reports on one axis ({FT_COUNT_MAX} counts / {per_key} {per:g} = {FT_COUNT_MAX / per:.4g} {unit})",
                    hint="set a lower limit, or the sensor's calibration for a larger range")
    if not 1 <= ft.reply_ms <= 1000:
        r.error(locs.get(*where, "reply_ms"), f"device {dev.name}: reply_ms {ft.reply_ms} must be 1..1000")
    if not ft.frame.strip():
        r.error(locs.get(*where, "frame"), f"device {dev.name}: frame must name the sensor frame")


def _check_sim_ft(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    from sherpa_cli.config.model import SIM_FT_WALL_SIDES

    axes = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
    for name, sim in cfg.sim_ft.items():
        where = ("sim", "ft_sensors", name)
        dev = cfg.devices.get(name)
        if dev is None or dev.ft is None:
            r.error(locs.get(*where), f"sim ft_sensors: '{name}' is no ft_sensor device "
                    f"(ft_sensors: {', '.join(d.name for d in cfg.ft_sensors()) or 'none'})")
        for joint in (*sim.wrist, *((sim.wall_joint,) if sim.wall_joint else ())):
            if joint not in cfg.joints:
                r.error(locs.get(*where), f"sim ft_sensors: {name}: unknown joint '{joint}'{_did_you_mean(joint, list(cfg.joints))}")
        if sim.wall_side not in SIM_FT_WALL_SIDES:
            r.error(locs.get(*where, "wall_side"), f"sim ft_sensors: {name}: wall_side '{sim.wall_side}'; expected "
                    "high or low")
        if sim.wall_axis not in axes:
            r.error(locs.get(*where, "wall_axis"), f"sim ft_sensors: {name}: wall_axis '{sim.wall_axis}'; expected "
                    f"one of {', '.join(axes)}")
        for key in ("payload_kg", "wall_stiffness", "noise_force", "noise_torque"):
            if getattr(sim, key) < 0:
                r.error(locs.get(*where, key), f"sim ft_sensors: {name}: {key} {getattr(sim, key)} is negative")


def _check_il_codes(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    for key in ("stop", "home", "unused"):
        value = getattr(cfg.il_codes, key)
        if value < 0:
            r.error(locs.get("il_codes", key), f"IL code {value} is negative; expected a value >= 0")
    if cfg.il_codes.stop == cfg.il_codes.home:
        r.error(locs.get("il_codes", "home"),
                f"il_codes.stop and il_codes.home are both {cfg.il_codes.stop}; a stop switch and a home switch "
                "need different input logic")
    for key in ("stop", "home"):
        if cfg.il_codes.unused == getattr(cfg.il_codes, key):
            r.error(locs.get("il_codes", "unused"),
                    f"il_codes.unused and il_codes.{key} are both {cfg.il_codes.unused}; an input without a switch "
                    f"must not get a switch's input logic")


def _check_catalog(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    cat = cfg.catalog
    if not 0 < cat.peak_fraction <= 1:
        r.error(locs.get("catalog", "peak_fraction"),
                f"peak_fraction {cat.peak_fraction} must be above 0 and at most 1")
    for key, dm in cat.drives.items():
        if ("catalog", "drives", key) not in locs.table:
            continue
        at = lambda f: locs.get("catalog", "drives", key, f)  # noqa: E731, B023  used in this iteration only
        for f in ("nominal_voltage", "max_voltage", "current_cont", "current_peak"):
            if getattr(dm, f) <= 0:
                r.error(at(f), f"{f} of drive model '{key}' must be positive, got {getattr(dm, f)}")
        if dm.max_voltage < dm.nominal_voltage:
            r.error(at("max_voltage"), f"max_voltage {dm.max_voltage} of '{key}' is below its nominal_voltage "
                                       f"{dm.nominal_voltage}")
        if dm.current_peak < dm.current_cont:
            r.error(at("current_peak"), f"current_peak {dm.current_peak} of '{key}' is below its current_cont "
                                        f"{dm.current_cont}")
        if not 1 <= dm.inputs <= 32:
            r.error(at("inputs"), f"inputs {dm.inputs} of '{key}' must be 1..32")
    for key, mm in cat.motors.items():
        if ("catalog", "motors", key) not in locs.table:
            continue
        for f in ("voltage", "current_cont", "power", "current_peak", "peak_power"):
            if getattr(mm, f) <= 0:
                r.error(locs.get("catalog", "motors", key, f),
                        f"{f} of motor '{key}' must be positive, got {getattr(mm, f)}")
        if mm.current_peak < mm.current_cont:
            r.error(locs.get("catalog", "motors", key, "current_peak"),
                    f"current_peak {mm.current_peak} of motor '{key}' is below its current_cont {mm.current_cont}")


def _check_buses(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    if not cfg.buses:
        r.error(locs.get("buses"), "no buses defined; expected at least one, like can0: {interface: socketcan, "
                                   "channel: can0}")
    for b in cfg.buses.values():
        if b.bitrate is not None and b.bitrate <= 0:
            r.error(locs.get("bus", b.name, "bitrate"), f"bitrate {b.bitrate} must be positive (bit/s, e.g. 1000000)")
        if b.send_interval_us < 0:
            r.error(locs.get("bus", b.name, "send_interval_us"),
                    f"send_interval_us {b.send_interval_us} is negative; expected >= 0 µs")
        if b.poll_interval_ms <= 0:
            r.error(locs.get("bus", b.name, "poll_interval_ms"),
                    f"poll_interval_ms {b.poll_interval_ms} must be at least 1 ms")
        if not any(d.bus == b.name for d in cfg.drives.values()):
            r.warn(locs.get("bus", b.name), f"bus '{b.name}' has no drives")


def _check_drives(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    from sherpa_cli.config.model import DRIVE_TYPES

    seen: dict[tuple[str, int], str] = {}
    for d in cfg.drives.values():
        if d.type not in DRIVE_TYPES:
            r.error(locs.get("drive", d.name, "type"),
                    f"drive '{d.name}': unknown type '{d.type}'; valid: {', '.join(DRIVE_TYPES)}")
        if not 1 <= d.node <= MAX_NODE_ID:
            r.error(locs.get("drive", d.name, "node"),
                    f"node id {d.node} of drive '{d.name}' is not a valid CAN node id; expected 1..{MAX_NODE_ID}")
        if d.bus not in cfg.buses:
            r.error(locs.get("drive", d.name, "bus"),
                    f"drive '{d.name}' is on bus '{d.bus}', which is not defined" + _did_you_mean(d.bus, list(cfg.buses)))
        if d.model is not None and d.model not in cfg.catalog.drives:
            r.error(locs.get("drive", d.name, "model"),
                    f"unknown drive model '{d.model}'" + _did_you_mean(d.model, list(cfg.catalog.drives)),
                    hint="add it under catalog.drives if it is a model the built-in catalog lacks")
        if d.motor is not None and d.motor not in cfg.catalog.motors:
            r.error(locs.get("drive", d.name, "motor"),
                    f"unknown motor '{d.motor}'" + _did_you_mean(d.motor, list(cfg.catalog.motors)),
                    hint="add it under catalog.motors if it is a motor the built-in catalog lacks")
        if d.model is None and r.warn_no_model:
            r.warn(locs.get("drive", d.name), f"drive '{d.name}' has no model; rating and input checks use "
                                              f"defaults ({DEFAULT_INPUTS} inputs)")
        key = (d.bus, d.node)
        if key in seen:
            other = seen[key]
            r.error(locs.get("drive", d.name, "node"),
                    f"drives '{other}' ({_line(locs.get('drive', other, 'node'))}) and '{d.name}' "
                    f"({_line(locs.get('drive', d.name, 'node'))}) both use node id {d.node} on bus '{d.bus}'; "
                    "node ids must be unique per bus")
        else:
            seen[key] = d.name
    for pair in cfg.pairs.values():
        for name in (pair.drive_a, pair.drive_b):
            if name in cfg.drives and cfg.drives[name].type == "cia402":
                # the pair's synchronized start (one SYNC for both BGs) is Elmo's binary interpreter
                r.error(locs.get("drive", name, "type"),
                        f"drive '{name}' of differential pair '{pair.name}' is a cia402 drive; a pair's "
                        "synchronized start needs elmo drives")


def _check_names(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    # Drives, joints and pairs are all CLI targets, so one name must mean one thing.
    for j in cfg.joints.values():
        if j.name in cfg.drives and not (j.role is JointRole.PLAIN and j.drive == j.name):
            r.error(locs.get("joint", j.name),
                    f"joint '{j.name}' has the same name as drive '{j.name}' "
                    f"({_line(locs.get('drive', j.name))}) but is not moved by it; names are shared by drives and "
                    "joints on the command line")
    for p in cfg.pairs.values():
        for kind, table in (("drive", cfg.drives), ("joint", cfg.joints)):
            if p.name in table:
                r.error(locs.get("pair", p.name),
                        f"pair '{p.name}' has the same name as {kind} '{p.name}' ({_line(locs.get(kind, p.name))}); "
                        "names are shared by drives, joints and pairs on the command line")


def _check_usage(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    user: dict[str, tuple[str, Location]] = {}

    def use(drive: str, who: str, loc: Location) -> None:
        if drive in user:
            prev, ploc = user[drive]
            r.error(loc, f"drive '{drive}' is used by both {prev} ({_line(ploc)}) and {who}; a drive moves one "
                         "joint or one pair")
        else:
            user[drive] = (who, loc)

    for j in cfg.joints.values():
        if j.role is not JointRole.PLAIN or j.drive is None:
            continue
        dloc = locs.get("joint", j.name, "drive")
        if j.drive not in cfg.drives:
            r.error(dloc, f"joint '{j.name}' uses drive '{j.drive}', which is not defined"
                    + _did_you_mean(j.drive, list(cfg.drives)))
            continue
        use(j.drive, f"joint '{j.name}'", dloc)
        if j.current is None:
            r.warn(locs.get("joint", j.name), f"joint '{j.name}' has no current limits; CL/PL stay as on the drive")
    for p in cfg.pairs.values():
        if p.drive_a == p.drive_b:
            r.error(locs.get("pair", p.name, "drives"), f"pair '{p.name}' names drive '{p.drive_a}' twice; "
                                                        "expected two different drives")
            continue
        known = True
        for d in (p.drive_a, p.drive_b):
            dloc = locs.get("pair", p.name, "drive", d)
            if d not in cfg.drives:
                r.error(dloc, f"pair '{p.name}' uses drive '{d}', which is not defined"
                        + _did_you_mean(d, list(cfg.drives)))
                known = False
            else:
                use(d, f"pair '{p.name}'", dloc)
        if known:
            a, b = cfg.drives[p.drive_a], cfg.drives[p.drive_b]
            if a.bus != b.bus:
                r.error(locs.get("pair", p.name, "drives"),
                        f"pair '{p.name}' drives '{a.name}' (bus {a.bus}) and '{b.name}' (bus {b.bus}) are on "
                        "different buses; both motors of a differential pair must be on one bus")
        if p.current is None:
            r.warn(locs.get("pair", p.name), f"pair '{p.name}' has no current limits; CL/PL stay as on the drives")
        else:
            _check_current(p.current, ("pair", p.name), locs, r)
    for drive in cfg.drives.values():
        if drive.name not in user:
            r.warn(locs.get("drive", drive.name), f"drive '{drive.name}' moves no joint or pair")


def _check_current(cur: CurrentLimits, prefix: tuple[str, ...], locs: Locs, r: _Report) -> None:
    at = lambda f: locs.get(*prefix, "current", f)  # noqa: E731
    for f in ("continuous", "peak", "peak_time"):
        if getattr(cur, f) <= 0:
            r.error(at(f), f"current {f} must be positive, got {getattr(cur, f)}")
    if cur.peak < cur.continuous:
        r.error(at("peak"), f"peak current {cur.peak} A is below the continuous current {cur.continuous} A")


def _check_joint(cfg: ArmConfig, j: JointConfig, locs: Locs, r: _Report) -> None:
    at = lambda *k: locs.get("joint", j.name, *k)  # noqa: E731
    if j.cpr <= 0:
        r.error(at("cpr"), f"cpr {j.cpr} must be positive (counts per joint revolution)")
    range_ok = True
    if j.pos_min >= j.pos_max:
        r.error(at("range", "max"), f"range max {j.pos_max} must be above range min {j.pos_min}")
        range_ok = False
    if j.margin < 0:
        r.error(at("range", "margin"), f"margin {j.margin} is negative; expected >= 0 counts (inward from the "
                                       "full range)")
        range_ok = False
    if j.overshoot < 0:
        r.error(at("range", "overshoot"), f"overshoot {j.overshoot} is negative; expected >= 0 counts (outward "
                                          "from the full range)")
        range_ok = False
    if range_ok and 2 * j.margin >= j.pos_max - j.pos_min:
        r.error(at("range", "margin"),
                f"margin {j.margin} leaves no normal range: 2*margin must be less than max-min = "
                f"{j.pos_max - j.pos_min}")
    for key, sub, value in (("velocity", "limit", j.vel_limit), ("velocity", "trip", j.vel_trip),
                            ("acceleration", "accel", j.accel), ("acceleration", "decel", j.decel)):
        if value is not None and value <= 0:
            r.error(at(key, sub), f"{key} {sub} {value} must be positive")
    if j.vel_limit is not None and j.vel_trip is not None and 0 < j.vel_trip <= j.vel_limit:
        r.error(at("velocity", "trip"),
                f"velocity trip {j.vel_trip} must be above the velocity limit {j.vel_limit} (it is the safeguard "
                "that stops the drive, LL/HL[2])")
    if j.current is not None:
        _check_current(j.current, ("joint", j.name), locs, r)
    if j.cal_speed is not None and j.cal_speed == 0:
        r.error(at("calibration", "speed"), "calibration speed 0 would never reach the switch; expected a "
                                            "non-zero counts/s")
    lo, hi = j.overshoot_range
    if range_ok and j.cal_pos is not None and not lo <= j.cal_pos <= hi:
        r.error(at("calibration", "position"),
                f"calibration position {j.cal_pos} is outside the overshoot range {lo}..{hi}")
    if range_ok:
        for i, s in enumerate(j.switches):
            sloc = locs.get("joint", j.name, "switches", str(i), "position")
            if s.kind is SwitchKind.STOP and not lo <= s.position <= hi:
                r.error(sloc, f"stop switch at {s.position} is outside the overshoot range {lo}..{hi} of joint "
                              f"'{j.name}'; the drive could never reach it")
            if s.kind is SwitchKind.HOME and not j.pos_min <= s.position <= j.pos_max:
                r.error(sloc, f"home switch at {s.position} is outside the full range {j.pos_min}..{j.pos_max} "
                              f"of joint '{j.name}'")
    if not j.switches and j.abs_encoder is None:
        r.warn(locs.get("joint", j.name), f"joint '{j.name}' has no home or stop switch and no absolute encoder; "
                                          "it cannot be calibrated")


def _joint_drives(cfg: ArmConfig, j: JointConfig) -> tuple[str, ...]:
    if j.role is JointRole.PLAIN:
        return (j.drive,) if j.drive else ()
    pair = cfg.pairs.get(j.pair or "")
    return (pair.drive_a, pair.drive_b) if pair else ()


def _check_switch_inputs(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    taken: dict[tuple[str, int], tuple[str, Location]] = {}
    for j in cfg.joints.values():
        own = _joint_drives(cfg, j)
        for i, s in enumerate(j.switches):
            base = ("joint", j.name, "switches", str(i))
            if s.drives:
                for d in s.drives:
                    if d not in own:
                        r.error(locs.get(*base, "drives"),
                                f"switch is wired to drive '{d}', which does not move joint '{j.name}'; expected "
                                f"one of: {', '.join(own) or '(none)'}")
            wired = [d for d in (s.drives or own) if d in cfg.drives]
            iloc = locs.get(*base, "input")
            if s.input < 1:
                r.error(iloc, f"switch input {s.input} is not a digital input number; inputs count from 1")
                continue
            for d in wired:
                drive = cfg.drives[d]
                dm = cfg.catalog.drives.get(drive.model) if drive.model else None
                n = dm.inputs if dm else DEFAULT_INPUTS
                if s.input > n:
                    model = f"model {drive.model}" if dm else "an unknown model (assumed)"
                    r.error(iloc, f"switch input {s.input} is outside the inputs of drive '{d}' ({model} has "
                                  f"inputs 1..{n})")
                    continue
                key = (d, s.input)
                if key in taken:
                    who, ploc = taken[key]
                    r.error(iloc, f"input {s.input} of drive '{d}' is already used by {who} ({_line(ploc)}); "
                                  "one input can carry one switch")
                else:
                    taken[key] = (f"a switch of joint '{j.name}'", iloc)


_ABS_CODE = re.compile(r"^ABS_[A-Z0-9_]+$")
_BUTTON_CODE = re.compile(r"^(BTN|KEY)_[A-Z0-9_]+$")


def _check_joystick(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    """`joystick:` (docs/config.md): evdev code names, rates, the joints and pairs the axes drive."""
    from sherpa_cli.config.model import JOYSTICK_MIXES, JOYSTICK_MODES, JointRole

    j = cfg.joystick
    where = lambda *key: locs.get("joystick", *key)  # noqa: E731
    if not 20 <= j.rate_hz <= 50:
        r.error(where("rate_hz"), f"rate_hz {j.rate_hz:g} must be 20..50 (commands per second while the dead-man "
                "is held)")
    if not 0 <= j.deadzone < 1:
        r.error(where("deadzone"), f"deadzone {j.deadzone:g} must be >= 0 and < 1 (a fraction of full deflection)")
    if not _BUTTON_CODE.match(j.deadman):
        r.error(where("deadman"), f"deadman '{j.deadman}': expected an evdev button name like BTN_TRIGGER or "
                "BTN_TL (`sherpa jog --list-joysticks` shows them)")
    used: dict[str, int] = {}
    for i, m in enumerate(j.axes):
        at = lambda key, i=i: locs.get("joystick", "axes", str(i), key)  # noqa: E731
        item = locs.get("joystick", "axes", str(i))
        if (m.joint is None) == (m.pair is None):
            r.error(item, "a joystick map names exactly one of 'joint' (with 'axis') or 'pair' (with 'x' and 'y')")
            continue
        if m.mode not in JOYSTICK_MODES:
            r.error(at("mode"), f"mode '{m.mode}': expected one of {', '.join(JOYSTICK_MODES)}")
        if not 0 < m.sensitivity <= 1:
            r.error(at("sensitivity"), f"sensitivity {m.sensitivity:g} must be > 0 and <= 1 (full deflection = "
                    "this fraction of the joint's speed limit or continuous current)")
        if m.joint is not None:
            if m.axis is None or m.x is not None or m.y is not None:
                r.error(item, f"joystick map of joint '{m.joint}': give 'axis' (not x/y)")
                continue
            joint = cfg.joints.get(m.joint)
            if joint is None:
                hint = suggest(m.joint, cfg.joints)
                r.error(at("joint"), f"joint '{m.joint}' is not in the config" + (f"; did you mean '{hint}'?" if hint
                                                                                   else ""))
                continue
            codes = [("axis", m.axis)]
            if m.mode == "torque":
                cur = joint.current if joint.role is JointRole.PLAIN else cfg.pairs[joint.pair].current  # type: ignore[index]
                if cur is None:
                    r.error(at("mode"), f"torque for joint '{m.joint}' needs its current limits (current.continuous)")
            elif joint.vel_limit is None:
                r.error(at("joint"), f"joint '{m.joint}' has no velocity.limit: the joystick's full scale is a "
                        "fraction of it")
        else:
            if m.x is None or m.y is None or m.axis is not None:
                r.error(item, f"joystick map of pair '{m.pair}': give 'x' and 'y' (not axis)")
                continue
            pair = cfg.pairs.get(m.pair)  # type: ignore[arg-type]
            if pair is None:
                r.error(at("pair"), f"pair '{m.pair}' is not in the config ({', '.join(cfg.pairs) or 'none'})")
                continue
            if m.mix not in JOYSTICK_MIXES:
                r.error(at("mix"), f"mix '{m.mix}': expected xy (X+Y -> {pair.drive_a}, X-Y -> {pair.drive_b}) or "
                        "sigma_delta (X -> Σ, Y -> Δ)")
            if m.mode == "torque" and pair.current is None:
                r.error(at("mode"), f"torque for pair '{m.pair}' needs its current limits (current.continuous)")
            codes = [("x", m.x), ("y", m.y)]
        for key, code in codes:
            if not _ABS_CODE.match(code or ""):
                r.error(at(key), f"{key} '{code}': expected an evdev axis name like ABS_X, ABS_RZ")
            elif code in used:
                r.error(at(key), f"{key} '{code}' is already used by joystick map {used[code] + 1}")
            else:
                used[code] = i


def _check_poses(cfg: ArmConfig, locs: Locs, r: _Report) -> dict[str, Pose]:
    """`poses:` (docs/move.md): every joint named exists, every value reads as a position in that
    joint's units and lies inside its normal range (where the tool moves a joint). Returns the poses
    with their values in counts."""
    out: dict[str, Pose] = {}
    for pose in cfg.poses.values():
        counts: dict[str, int] = {}
        for jname, value in pose.values.items():
            at = locs.get("pose", pose.name, jname)
            joint = cfg.joints.get(jname)
            if joint is None:
                r.error(at, f"joint '{jname}' is not in the config" + _did_you_mean(jname, list(cfg.joints)))
                continue
            try:
                n = (units.parse_position(value, joint.cpr, what=jname) if isinstance(value, str)
                     else units.rad_to_counts(value, joint.cpr))
            except UsageError as exc:
                r.error(at, exc.message)
                continue
            lo, hi = joint.normal_range
            if not lo <= n <= hi:
                r.error(at, f"{jname} {value!r} is {n} counts, outside the joint's normal range "
                        f"[{lo}, {hi}] counts ({units.counts_to_rad(lo, joint.cpr):.4f} .. "
                        f"{units.counts_to_rad(hi, joint.cpr):.4f} rad)",
                        hint="a pose lies where the tool moves a joint: inside its range less the margin")
                continue
            counts[jname] = n
        out[pose.name] = replace(pose, counts=counts)
    return out


# --- number bounds ---------------------------------------------------------------------------
# Every number the config takes is bounded here, so `config check` passes exactly when no later
# step refuses a value for its size: the codec (int32 / float32), the drive's ranges as the
# simulator models them (IL 0..23, PL[2] 0..60 s), the OD (0x1017 u16), and waits that must end.

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
IL_CODE_MAX = 23  # the IL function table (elmo-protocol.md 2.4) ends at 22/23 (abort)
PEAK_TIME_MAX = 60  # s; PL[2] range of the simulated drive (the Whistle's own maximum is UNCONFIRMED)
WAIT_MAX = 60.0  # s; a protocol wait or simulated latency beyond a minute is a typo, not a bus
MO_CONFIRM_MAX = 600.0  # s
RETRIES_MAX = 100
BITRATE_MAX = 1_000_000  # bit/s: classical CAN (the Whistle's CAN port)
SEND_INTERVAL_MAX = 1_000_000  # µs
POLL_INTERVAL_MAX = 60_000  # ms
SIM_TIME_MAX = 1e6  # s after start for simulated faults
SPEED_GAIN_MAX = 1000.0
# servo-loop motor model (sim/servo.py): its 1 ms model step integrates a loop of up to ~100 Hz
# stably (wn * dt = 0.63); damping beyond 10 is a loop that barely moves; currents in A
SERVO_BANDWIDTH_MAX = 100.0  # Hz
SERVO_DAMPING_MAX = 10.0
SIM_CURRENT_MAX = 1000.0  # A
SIM_LOAD_MAX = 1e6  # the load's numbers (inertia, friction, gravity, EMF, ohm, V): finite and below this
SIM_CAPACITANCE_MAX = 10.0  # F of a drive's bus: a bench supply's and a drive's capacitors are mF
SIM_COGGING_CYCLES_MAX = 100_000  # ripple periods per joint turn (motor poles x gear ratio)
SIM_TARGET_SKEW_MAX = 1_000_000  # counts a faulty simulated drive adds to PA


def _bad_number(value: object) -> str | None:
    """Why a number is unusable anywhere (NaN, infinite), else None."""
    if isinstance(value, float) and not math.isfinite(value):
        return "is not a finite number"
    return None


def _check_bounds(cfg: ArmConfig, locs: Locs, r: _Report) -> None:
    def within(value: object, lo: float, hi: float, loc: Location, what: str, unit: str = "") -> None:
        if value is None or isinstance(value, bool):
            return
        bad = _bad_number(value)
        if bad is None and lo <= value <= hi:  # type: ignore[operator]
            return
        shown = f"{lo:g}..{hi:g}" if isinstance(lo, float) or isinstance(hi, float) else f"{lo}..{hi}"
        r.error(loc, f"{what} {value} {bad or 'is out of range'}; expected {shown}{unit}")

    def positive(value: object, hi: float, loc: Location, what: str, unit: str = "") -> None:
        """None (not given) or a finite number > 0 and <= hi."""
        if value is None or isinstance(value, bool):
            return
        bad = _bad_number(value)
        if bad is None and 0 < value <= hi:  # type: ignore[operator]
            return
        r.error(loc, f"{what} {value} {bad or 'is out of range'}; expected > 0 and <= {hi:g}{unit}")

    p = cfg.protocol
    for key in ("reply_timeout", "mo_settle", "sv_blackout"):
        within(getattr(p, key), 0.0, WAIT_MAX, locs.get("protocol", key), key, " s")
    within(p.mo_confirm_timeout, 0.0, MO_CONFIRM_MAX, locs.get("protocol", "mo_confirm_timeout"),
           "mo_confirm_timeout", " s")
    within(p.retries, 0, RETRIES_MAX, locs.get("protocol", "retries"), "retries")
    if _bad_number(p.sdo_timeout):
        r.error(locs.get("protocol", "sdo_timeout"), f"sdo_timeout {p.sdo_timeout} is not a finite number")

    for key in ("stop", "home"):
        within(getattr(cfg.il_codes, key), 0, IL_CODE_MAX, locs.get("il_codes", key), f"IL code {key}",
               " (the drive's input logic table)")

    for name, sim_drive in cfg.sim.items():
        at_sim = lambda k: locs.get("sim", "drives", name, k)  # noqa: E731, B023  used in this iteration only
        within(sim_drive.reply_latency, 0.0, WAIT_MAX, at_sim("reply_latency"), "reply_latency", " s")
        within(sim_drive.sdo_latency, 0.0, WAIT_MAX, at_sim("sdo_latency"), "sdo_latency", " s")
        within(sim_drive.rx_buffer, 0.0, WAIT_MAX, at_sim("rx_buffer"), "rx_buffer", " s")
        for key in ("die_at", "die_moving_after", "reboot_at", "limit_trip_at"):
            within(getattr(sim_drive, key), 0.0, SIM_TIME_MAX, at_sim(key), key, " s")
        within(sim_drive.speed_gain, 0.0, SPEED_GAIN_MAX, at_sim("speed_gain"), "speed_gain")
        within(sim_drive.boot_ms, 0.0, 1000 * WAIT_MAX, at_sim("boot_ms"), "boot_ms", " ms")
        within(sim_drive.heartbeat_ms, 0, 0xFFFF, at_sim("heartbeat_ms"), "heartbeat_ms", " ms (0x1017 is u16)")
        within(sim_drive.seed, 0, 2**32 - 1, at_sim("seed"), "seed")
        within(sim_drive.servo_bandwidth, 0.0, SERVO_BANDWIDTH_MAX, at_sim("servo_bandwidth"), "servo_bandwidth",
               " Hz (0 = the kinematic motor model)")
        positive(sim_drive.servo_damping, SERVO_DAMPING_MAX, at_sim("servo_damping"), "servo_damping")
        for key in ("servo_current_limit", "supply_current_limit"):
            positive(getattr(sim_drive, key), SIM_CURRENT_MAX, at_sim(key), key, " A")
        for key in ("inertia", "torque_constant", "resistance", "supply_voltage"):  # the load (sim/load.py)
            positive(getattr(sim_drive, key), SIM_LOAD_MAX, at_sim(key), key)
        for key in ("viscous", "coulomb", "back_emf", "gravity"):
            lo = -SIM_LOAD_MAX if key == "gravity" else 0.0
            if getattr(sim_drive, key) is not None:
                within(getattr(sim_drive, key), lo, SIM_LOAD_MAX, at_sim(key), key)
        for key, hi, unit in (("bus_capacitance", SIM_CAPACITANCE_MAX, " F"), ("supply_resistance", SIM_LOAD_MAX, " ohm"),
                              ("velocity_window", WAIT_MAX, " s"), ("cogging_torque", SIM_LOAD_MAX, " N m"),
                              ("cogging_cycles", SIM_COGGING_CYCLES_MAX, " per turn")):
            within(getattr(sim_drive, key), 0, hi, at_sim(key), key, unit)  # imperfections: 0 = off
        within(sim_drive.target_skew, -SIM_TARGET_SKEW_MAX, SIM_TARGET_SKEW_MAX, at_sim("target_skew"), "target_skew",
               " counts")
        for key in ("start_skew", "lag"):  # the simulator refuses a negative time (SimSettings)
            within(getattr(sim_drive, key), 0.0, WAIT_MAX, at_sim(key), key, " s")
        if _bad_number(sim_drive.drop_probability):
            r.error(at_sim("drop_probability"), f"drop_probability {sim_drive.drop_probability} is not a finite number")

    for b in cfg.buses.values():
        within(b.bitrate, 1, BITRATE_MAX, locs.get("bus", b.name, "bitrate"), "bitrate", " bit/s")
        within(b.send_interval_us, 0, SEND_INTERVAL_MAX, locs.get("bus", b.name, "send_interval_us"),
               "send_interval_us", " µs")
        within(b.poll_interval_ms, 1, POLL_INTERVAL_MAX, locs.get("bus", b.name, "poll_interval_ms"),
               "poll_interval_ms", " ms")

    cat = cfg.catalog
    if _bad_number(cat.peak_fraction):
        r.error(locs.get("catalog", "peak_fraction"), f"peak_fraction {cat.peak_fraction} is not a finite number")
    for kind, table, fields in (("drives", cat.drives, ("nominal_voltage", "max_voltage", "current_cont",
                                                          "current_peak")),
                                ("motors", cat.motors, ("voltage", "current_cont", "power", "current_peak",
                                                        "peak_power"))):
        for key, entry in table.items():
            if ("catalog", kind, key) not in locs.table:
                continue
            for field_name in fields:
                bad = _bad_number(getattr(entry, field_name))
                if bad:
                    r.error(locs.get("catalog", kind, key, field_name), f"{field_name} of '{key}' {bad}")

    for owner, cur in [(("joint", j.name), j.current) for j in cfg.joints.values()] + \
            [(("pair", p.name), p.current) for p in cfg.pairs.values()]:
        if cur is None:
            continue
        for field_name in ("continuous", "peak"):
            bad = _bad_number(getattr(cur, field_name))
            if bad:
                r.error(locs.get(*owner, "current", field_name),
                        f"current {field_name} {getattr(cur, field_name)} {bad}")
        within(cur.peak_time, 0.0, PEAK_TIME_MAX, locs.get(*owner, "current", "peak_time"), "current peak_time",
               " s (PL[2])")

    for j in cfg.joints.values():
        at = lambda *k: locs.get("joint", j.name, *k)  # noqa: E731, B023  used in this iteration only
        drive_value = lambda v, loc, what: within(v, INT32_MIN, INT32_MAX, loc, what,  # noqa: E731
                                                  " (a drive value is a 32-bit integer)")
        within(j.cpr, 1, INT32_MAX, at("cpr"), "cpr")
        drive_value(j.pos_min, at("range", "min"), "range min")
        drive_value(j.pos_max, at("range", "max"), "range max")
        within(j.margin, 0, INT32_MAX, at("range", "margin"), "margin")
        within(j.overshoot, 0, INT32_MAX, at("range", "overshoot"), "overshoot")
        lo, hi = j.overshoot_range
        if lo < INT32_MIN or hi > INT32_MAX:
            r.error(at("range", "overshoot"), f"overshoot range {lo}..{hi} does not fit the drive's 32-bit "
                                              f"LL[3]/HL[3] ({INT32_MIN}..{INT32_MAX})")
        for key, sub, value in (("velocity", "limit", j.vel_limit), ("velocity", "trip", j.vel_trip),
                                ("acceleration", "accel", j.accel), ("acceleration", "decel", j.decel)):
            within(value, 1, INT32_MAX, at(key, sub), f"{key} {sub}")
        if j.cal_speed is not None:
            within(j.cal_speed, -INT32_MAX, INT32_MAX, at("calibration", "speed"), "calibration speed")
        drive_value(j.cal_pos, at("calibration", "position"), "calibration position")
        if j.abs_encoder is not None:
            drive_value(j.abs_encoder.offset, at("abs_encoder", "offset"), "abs_encoder offset")
        for i, sw in enumerate(j.switches):
            drive_value(sw.position, locs.get("joint", j.name, "switches", str(i), "position"), "switch position")
