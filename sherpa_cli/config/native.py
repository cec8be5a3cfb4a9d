"""The native sherpa-cli config schema (docs/config.md) -> ArmConfig.

This module checks shape and types (unknown/missing keys, wrong types); the value and
cross-reference rules (ranges, node ids, buses, switch inputs...) live in validate.py so
the rosparam loader gets exactly the same checks.
"""

from __future__ import annotations

import dataclasses
from pathlib import PurePath
from typing import Any

from sherpa_cli.config.catalog import builtin_catalog
from sherpa_cli.config.model import (
    DEVICE_TYPES,
    FT_SENSOR,
    AbsEncoderConfig,
    ArmConfig,
    BusConfig,
    Catalog,
    CurrentLimits,
    DeviceConfig,
    DriveConfig,
    DriveModel,
    FtSensorConfig,
    HomingConfig,
    ILCodes,
    JointConfig,
    JointRole,
    JoystickConfig,
    JoystickMap,
    MotionConfig,
    MotorModel,
    PairConfig,
    Pose,
    PoseValue,
    ProtocolConfig,
    SimDriveConfig,
    SimExtraNode,
    SimWiring,
    SwitchConfig,
    SwitchKind,
)
from sherpa_cli.config.simbus import parse_sim_buses
from sherpa_cli.config.simft import parse_sim_ft
from sherpa_cli.config.yamlnodes import (
    Locs,
    Section,
    YNode,
    as_int,
    as_map,
    as_name,
    as_num,
    as_seq,
    as_str,
    describe,
    named_items,
    plain,
    suggest,
)
from sherpa_cli.errors import ConfigError

TOP_KEYS = ["name", "il_codes", "protocol", "motion", "homing", "joystick", "sim", "buses", "drives", "devices", "joints",
            "pairs", "catalog", "tuning", "poses"]
TUNING_KEYS = [f"{g}[{n}]" for g in ("KP", "KI", "FF") for n in (1, 2, 3)]  # `tuning:` (docs/tune.md)
IL_KEYS = ["stop", "home", "unused"]
BUS_KEYS = ["interface", "channel", "bitrate", "send_interval_us", "poll_interval_ms", "options"]
DRIVE_KEYS = ["type", "bus", "node", "model", "motor"]
DEVICE_KEYS = ["type", "bus", "node", "position_from", "tpdo_trigger", "cyclic_ms", "base_id", "counts_per_force",
               "counts_per_torque", "frame", "force_limit", "torque_limit", "reply_ms"]
FT_KEYS = ("base_id", "counts_per_force", "counts_per_torque", "frame", "force_limit", "torque_limit", "reply_ms")
JOINT_BODY_KEYS = ["cpr", "range", "velocity", "acceleration", "switches", "calibration", "abs_encoder", "gravity"]
JOINT_KEYS = ["drive", *JOINT_BODY_KEYS, "current"]
PAIR_JOINT_KEYS = ["name", *JOINT_BODY_KEYS]
PAIR_KEYS = ["drives", "current", "sigma", "delta"]
RANGE_KEYS = ["min", "max", "margin", "overshoot"]
RANGE_ALIASES = {"pos_min": "min", "pos_max": "max", "pos_margin": "margin", "minimum": "min", "maximum": "max"}
VELOCITY_KEYS = ["limit", "trip"]
ACCEL_KEYS = ["accel", "decel"]
CURRENT_KEYS = ["continuous", "peak", "peak_time"]
SWITCH_KEYS = ["input", "kind", "side", "position", "drives"]
CALIBRATION_KEYS = ["speed", "position"]
ABS_KEYS = ["source", "offset"]
CATALOG_KEYS = ["drives", "motors", "peak_fraction"]
DRIVE_MODEL_KEYS = ["nominal_voltage", "max_voltage", "current_cont", "current_peak", "inputs"]
MOTOR_MODEL_KEYS = ["voltage", "current_cont", "power", "current_peak", "peak_power"]

SIDES = ("low", "high")


def catalog_key(name: str) -> str:
    """Catalog names are compared lower-case with blanks as '-', so 'Whistle 10/60' finds 'whistle-10/60'."""
    return "-".join(name.lower().split())


def default_name(filename: str) -> str:
    return PurePath(filename).stem or "arm"


def register(locs: Locs, prefix: tuple[str, ...], sec: Section) -> None:
    """Remember where the section and each of its keys are, for the checks in validate.py."""
    locs.put(prefix, sec.node.loc)
    for key, child in sec.node.value.items():
        locs.put((*prefix, key), child.loc)


def parse_ft_sensor(sec: Section, name: str, dtype: str) -> FtSensorConfig | None:
    """An ft_sensor's settings; its base id replaces the node id. Other types may not use these keys."""
    if dtype not in DEVICE_TYPES or dtype == "elmo":
        others = [t for t in DEVICE_TYPES if t != "elmo"]
        raise ConfigError(f"device {name}: unknown type '{dtype}'; known: {', '.join(others)} (Elmo drives go "
                          "under drives:)", sec.loc("type"))
    if dtype != FT_SENSOR:
        extra = next((k for k in FT_KEYS if sec.get(k) is not None), None)
        if extra is not None:
            raise ConfigError(f"'{extra}' is a key of ft_sensor devices, not of type '{dtype}'", sec.loc(extra))
        return None
    if sec.get("node") is not None:
        raise ConfigError("an ft_sensor is no CANopen node: give its base_id (the DIP-switch base address), "
                          "not a node", sec.loc("node"))
    d = FtSensorConfig(0)
    return FtSensorConfig(base_id=sec.int("base_id", required=True),
                          counts_per_force=sec.num("counts_per_force"), counts_per_torque=sec.num("counts_per_torque"),
                          frame=sec.str("frame", d.frame), force_limit=sec.num("force_limit"),
                          torque_limit=sec.num("torque_limit"), reply_ms=sec.num("reply_ms", d.reply_ms))


PROTOCOL_KEYS = [f.name for f in dataclasses.fields(ProtocolConfig)]


def parse_protocol(top: Section, locs: Locs) -> ProtocolConfig:
    sec = top.section("protocol", PROTOCOL_KEYS, what="a mapping of protocol settings")
    if sec is None:
        return ProtocolConfig()
    register(locs, ("protocol",), sec)
    d = ProtocolConfig()
    return ProtocolConfig(
        set_echo=sec.bool("set_echo", d.set_echo),
        query_long=sec.bool("query_long", d.query_long),
        reply_timeout=sec.num("reply_timeout", d.reply_timeout),
        retries=sec.int("retries", d.retries),
        mo_settle=sec.num("mo_settle", d.mo_settle),
        mo_confirm_timeout=sec.num("mo_confirm_timeout", d.mo_confirm_timeout),
        sv_blackout=sec.num("sv_blackout", d.sv_blackout),
        sdo_timeout=sec.num("sdo_timeout", d.sdo_timeout),
        boot_timeout=sec.num("boot_timeout", d.boot_timeout),
        pacing=sec.str("pacing", d.pacing),
        pacing_floor_us=sec.int("pacing_floor_us", d.pacing_floor_us),
        caller_reads=sec.bool("caller_reads", d.caller_reads),
        calibration_flag=sec.int("calibration_flag", d.calibration_flag),
    )


def parse_tuning(top: Section, locs: Locs) -> dict[str, tuple[float, float]]:
    """``tuning:`` gain key -> [low, high]: the bounds `tune set` accepts (docs/tune.md)."""
    sec = top.section("tuning", TUNING_KEYS, what="a mapping of gain bounds, e.g. KP[2]: [0, 5]")
    if sec is None:
        return {}
    register(locs, ("tuning",), sec)
    out: dict[str, tuple[float, float]] = {}
    for key in TUNING_KEYS:
        node = sec.get(key)
        if node is None:
            continue
        items = as_seq(node, "a list [low, high]")
        if len(items) != 2:
            raise node.error(f"tuning.{key}: expected [low, high], got {len(items)} value(s)")
        low, high = as_num(items[0]), as_num(items[1])
        if not low <= high:
            raise node.error(f"tuning.{key}: low {low:g} is above high {high:g}")
        out[key] = (float(low), float(high))
    return out


def parse_poses(top: Section, locs: Locs) -> dict[str, Pose]:
    """``poses:`` name -> {joint: value}: shape and types only (validate.py checks the joints, reads
    the values in each joint's counts and checks them against its range)."""
    node = top.get("poses")
    if node is None:
        return {}
    out: dict[str, Pose] = {}
    for pname, pnode in named_items(node, "pose"):
        locs.put(("pose", pname), pnode.loc)
        values: dict[str, PoseValue] = {}
        items = as_map(pnode, f"pose {pname}: a mapping of joint name -> position (rad, or text like 10deg)")
        if not items:
            raise pnode.error(f"pose {pname}: names no joint", hint="give it joint: position entries")
        for jname, vnode in items.items():
            locs.put(("pose", pname, jname), vnode.loc)
            v = vnode.value
            if vnode.kind != "scalar" or isinstance(v, bool) or not isinstance(v, int | float | str):
                raise vnode.error(f"pose {pname}: {jname}: expected a position (a number in rad, or text like "
                                  f"10deg or 1200counts), got {describe(vnode)}")
            values[jname] = float(v) if isinstance(v, int | float) else v
        out[pname] = Pose(pname, values, where=pnode.loc)
    return out


MOTION_KEYS = [f.name for f in dataclasses.fields(MotionConfig)]


def parse_motion(top: Section, locs: Locs) -> MotionConfig:
    sec = top.section("motion", MOTION_KEYS, what="a mapping of motion guard settings")
    if sec is None:
        return MotionConfig()
    register(locs, ("motion",), sec)
    d = MotionConfig()
    values = {f.name: (sec.str if f.type == "str" else sec.num if f.type == "float" else
                       sec.bool if f.type == "bool" else sec.int)(
        f.name, getattr(d, f.name)) for f in dataclasses.fields(MotionConfig) if f.name not in ("host_id_pool", "emcy_warning_codes")}
    pool = sec.get("host_id_pool")
    if pool is not None:
        values["host_id_pool"] = tuple(as_int(n) for n in as_seq(pool, "a list of node ids (1..127)"))
    codes = sec.get("emcy_warning_codes")
    if codes is not None:
        values["emcy_warning_codes"] = tuple(as_int(n) for n in as_seq(codes, "a list of EMCY codes (0..0xFFFF)"))
    return MotionConfig(**values)


JOYSTICK_KEYS = ["device", "rate_hz", "deadzone", "deadman", "axes"]
JOYSTICK_MAP_KEYS = [f.name for f in dataclasses.fields(JoystickMap)]


def parse_joystick(top: Section, locs: Locs) -> JoystickConfig:
    """The ``joystick:`` section (shape and types; validate.py checks names and ranges)."""
    sec = top.section("joystick", JOYSTICK_KEYS, what="a mapping of joystick settings (rate_hz, deadman, axes...)")
    if sec is None:
        return JoystickConfig()
    register(locs, ("joystick",), sec)
    d = JoystickConfig()
    maps = []
    if sec.get("axes") is not None:
        for i, item in enumerate(as_seq(sec.req("axes"), "a list like [{axis: ABS_X, joint: elbow_pitch}]")):
            m = Section(item, JOYSTICK_MAP_KEYS, what="a map like {axis: ABS_X, joint: elbow_pitch} or "
                        "{pair: shoulder, x: ABS_X, y: ABS_Y, mix: xy}")
            register(locs, ("joystick", "axes", str(i)), m)
            locs.put(("joystick", "axes", str(i)), item.loc)
            b = JoystickMap()
            maps.append(JoystickMap(joint=m.str("joint"), axis=m.str("axis"), pair=m.str("pair"), x=m.str("x"),
                                    y=m.str("y"), mix=m.str("mix", b.mix), mode=m.str("mode", b.mode),
                                    sensitivity=m.num("sensitivity", b.sensitivity), invert=m.bool("invert", b.invert)))
    return JoystickConfig(device=sec.str("device"), rate_hz=sec.num("rate_hz", d.rate_hz),
                          deadzone=sec.num("deadzone", d.deadzone), deadman=sec.str("deadman", d.deadman),
                          axes=tuple(maps))


SIM_DRIVE_KEYS = [f.name for f in dataclasses.fields(SimDriveConfig)]
SIM_EXTRA_KEYS = [f.name for f in dataclasses.fields(SimExtraNode)]
SIM_KEYS = ["drives", "extra_nodes", "reply_timeout", "power_up", "wiring", "buses", "ft_sensors"]


def parse_sim(top: Section, locs: Locs) -> tuple[dict[str, SimDriveConfig], tuple[SimExtraNode, ...]]:
    """The ``sim:`` section: per-drive faults and extra nodes on the buses."""
    sec = top.section("sim", SIM_KEYS,
                      what="a mapping with 'drives', 'extra_nodes' and/or 'reply_timeout'")
    if sec is None:
        return {}, ()
    register(locs, ("sim",), sec)
    drives: dict[str, SimDriveConfig] = {}
    if sec.get("drives") is not None:
        for dname, dnode in named_items(sec.req("drives"), "drive"):
            d = Section(dnode, SIM_DRIVE_KEYS, what="a mapping of simulated faults")
            register(locs, ("sim", "drives", dname), d)
            locs.put(("sim", "drives", dname), dnode.loc)
            # every field is a number (the int ones, heartbeat_ms and seed, whole), a bool or a string
            faults: dict[str, Any] = {
                f.name: (d.int if f.type == "int" else d.bool if f.type == "bool" else
                         d.str if str(f.type).startswith("str") else d.num)(f.name, f.default)
                for f in dataclasses.fields(SimDriveConfig)}
            drives[dname] = SimDriveConfig(**faults)
    extras = []
    if sec.get("extra_nodes") is not None:
        for i, item in enumerate(as_seq(sec.req("extra_nodes"), "a list like [{bus: can1, node: 99}]")):
            e = Section(item, SIM_EXTRA_KEYS, what="an extra node like {bus: can1, node: 99}")
            register(locs, ("sim", "extra_nodes", str(i)), e)
            base = SimExtraNode("", 0)
            extras.append(SimExtraNode(bus=e.str("bus", required=True), node=e.int("node", required=True),
                                       vendor_id=e.int("vendor_id", base.vendor_id),
                                       device_name=e.str("device_name", base.device_name),
                                       heartbeat_ms=e.int("heartbeat_ms", base.heartbeat_ms)))
    return drives, tuple(extras)


HOMING_KEYS = [f.name for f in dataclasses.fields(HomingConfig)]


def parse_homing(top: Section, locs: Locs) -> HomingConfig:
    sec = top.section("homing", HOMING_KEYS, what="a mapping of homing settings (HM[] codes, backoff, ...)")
    if sec is None:
        return HomingConfig()
    register(locs, ("homing",), sec)
    d = HomingConfig()
    return HomingConfig(**{f.name: sec.int(f.name, getattr(d, f.name)) for f in dataclasses.fields(HomingConfig)})


def parse_sim_homing(top: Section) -> tuple[dict[str, int], dict[str, SimWiring]]:
    """``sim: power_up:`` {joint: counts} and ``sim: wiring:`` {drive: {swap: [[3, 4]], invert: [3]}}."""
    sec = top.section("sim", SIM_KEYS)
    if sec is None:
        return {}, {}
    power_up: dict[str, int] = {}
    if sec.get("power_up") is not None:
        for jname, jnode in named_items(sec.req("power_up"), "joint"):
            power_up[jname] = as_int(jnode)
    wiring: dict[str, SimWiring] = {}
    if sec.get("wiring") is not None:
        for dname, dnode in named_items(sec.req("wiring"), "drive"):
            w = Section(dnode, ["swap", "invert"], what="a mapping {swap: [[3, 4]], invert: [3]}")
            swap_node = w.get("swap")
            swap = tuple(tuple(as_int(x) for x in as_seq(p, "a pair of inputs like [3, 4]"))
                         for p in as_seq(swap_node, "a list of input pairs")) if swap_node is not None else ()
            for p in swap:
                if len(p) != 2:
                    raise w.req("swap").error("each swap entry is two input numbers, like [3, 4]")
            invert = tuple(as_int(x) for x in as_seq(w.req("invert"), "a list of inputs")) \
                if w.get("invert") is not None else ()
            wiring[dname] = SimWiring(swap=swap, invert=invert)  # type: ignore[arg-type]
    return power_up, wiring


def parse_sim_reply_timeout(top: Section) -> float:
    """``sim: reply_timeout:`` (the interpreter reply timeout with --sim); parse_sim checked the section."""
    sec = top.section("sim", SIM_KEYS)
    return ArmConfig.sim_reply_timeout if sec is None else sec.num("reply_timeout", ArmConfig.sim_reply_timeout)


def load_native(root: YNode, filename: str) -> tuple[ArmConfig, Locs, list[str]]:
    """Shape and types only; the caller runs validate() on the result."""
    locs = Locs(filename)
    top = Section(root, TOP_KEYS, what="a mapping of configuration keys (name, buses, drives, joints, pairs)")
    name = as_name(top.req("name"), "arm") if "name" in top else default_name(filename)

    il = ILCodes()
    il_sec = top.section("il_codes", IL_KEYS)
    if il_sec is not None:
        register(locs, ("il_codes",), il_sec)
        il = ILCodes(stop=il_sec.int("stop", il.stop), home=il_sec.int("home", il.home),
                     unused=il_sec.int("unused", il.unused))

    protocol = parse_protocol(top, locs)
    motion = parse_motion(top, locs)
    joystick = parse_joystick(top, locs)
    homing = parse_homing(top, locs)
    tuning = parse_tuning(top, locs)
    poses = parse_poses(top, locs)
    sim, sim_extra_nodes = parse_sim(top, locs)
    sim_power_up, sim_wiring = parse_sim_homing(top)
    sim_reply_timeout = parse_sim_reply_timeout(top)
    catalog = parse_catalog(top.get("catalog"), locs)

    buses: dict[str, BusConfig] = {}
    for bname, bnode in named_items(top.req("buses"), "bus"):
        sec = Section(bnode, BUS_KEYS, what="a bus mapping like {interface: socketcan, channel: can0}",
                      null_ok=True)
        register(locs, ("bus", bname), sec)
        opts = sec.get("options")
        if opts is not None:
            as_map(opts, "a mapping of keyword arguments for can.Bus")
        options = plain(opts) if opts is not None else {}
        buses[bname] = BusConfig(
            name=bname, interface=sec.str("interface"), channel=sec.str("channel"), bitrate=sec.int("bitrate"),
            send_interval_us=sec.int("send_interval_us", 1000), poll_interval_ms=sec.int("poll_interval_ms", 10),
            options=options, where=sec.node.loc)

    drives: dict[str, DriveConfig] = {}
    for dname, dnode in named_items(top.req("drives"), "drive"):
        sec = Section(dnode, DRIVE_KEYS, what="a drive mapping like {bus: can0, node: 10, model: whistle-10/60}")
        register(locs, ("drive", dname), sec)
        model, motor = sec.str("model"), sec.str("motor")
        drives[dname] = DriveConfig(
            name=dname, bus=as_str(sec.req("bus")), node=as_int(sec.req("node")),
            model=catalog_key(model) if model is not None else None,
            motor=catalog_key(motor) if motor is not None else None, where=sec.node.loc,
            type=sec.str("type", "elmo"))

    devices: dict[str, DeviceConfig] = {}
    if top.get("devices") is not None:
        for dname, dnode in named_items(top.req("devices"), "device"):
            sec = Section(dnode, DEVICE_KEYS, what="a device mapping like {type: canopen-encoder, bus: can1, node: 45}")
            register(locs, ("device", dname), sec)
            dtype = as_str(sec.req("type"))
            ft = parse_ft_sensor(sec, dname, dtype)
            devices[dname] = DeviceConfig(name=dname, type=dtype, bus=as_str(sec.req("bus")),
                                          node=0 if ft is not None else as_int(sec.req("node")),
                                          position_from=sec.str("position_from", "tpdo"),
                                          tpdo_trigger=sec.str("tpdo_trigger", "cyclic"),
                                          cyclic_ms=sec.int("cyclic_ms", 10), ft=ft, where=sec.node.loc)

    joints: dict[str, JointConfig] = {}
    joints_node = top.get("joints")
    if joints_node is not None:
        for jname, jnode in named_items(joints_node, "joint"):
            sec = Section(jnode, JOINT_KEYS, what="a joint mapping (drive, cpr, range, ...)")
            register(locs, ("joint", jname), sec)
            drive = as_str(sec.req("drive"))
            current = parse_current(sec, ("joint", jname), locs)
            joints[jname] = parse_joint_body(sec, jname, JointRole.PLAIN, drive, None, current, locs)

    pairs: dict[str, PairConfig] = {}
    pairs_node = top.get("pairs")
    if pairs_node is not None:
        for pname, pnode in named_items(pairs_node, "pair"):
            sec = Section(pnode, PAIR_KEYS, what="a differential pair mapping (drives, sigma, delta, current)")
            register(locs, ("pair", pname), sec)
            dnode = sec.req("drives")
            items = as_seq(dnode, "a list of the pair's two drives, like [shoulder_2a, shoulder_2b]")
            if len(items) != 2:
                raise dnode.error(f"a differential pair needs exactly 2 drives, got {len(items)}")
            pair_drives = [as_str(i) for i in items]
            for i, dn in zip(items, pair_drives, strict=True):
                locs.put(("pair", pname, "drive", dn), i.loc)
            # Σ = a + b, Δ = a - b with a = the lower node id (seed D.1.3); the sign of Δ depends on it.
            if all(d in drives for d in pair_drives):
                pair_drives.sort(key=lambda d: drives[d].node)
            current = parse_current(sec, ("pair", pname), locs)
            names = []
            for role, key in ((JointRole.SIGMA, "sigma"), (JointRole.DELTA, "delta")):
                jsec = Section(sec.req(key), PAIR_JOINT_KEYS, what=f"the {key} joint's mapping (name, cpr, range, ...)")
                jname = as_name(jsec.req("name"), "joint")
                if jname in joints:
                    first = locs.get("joint", jname)
                    raise ConfigError(f"joint name '{jname}' is already used (line {first.line})", jsec.loc("name"))
                register(locs, ("joint", jname), jsec)
                joints[jname] = parse_joint_body(jsec, jname, role, None, pname, None, locs)
                names.append(jname)
            pairs[pname] = PairConfig(name=pname, drive_a=pair_drives[0], drive_b=pair_drives[1], sigma=names[0],
                                      delta=names[1], current=current, where=sec.node.loc)

    sim_buses = parse_sim_buses(top, locs, buses, SIM_KEYS)
    sim_ft = parse_sim_ft(top, locs, SIM_KEYS)
    cfg = ArmConfig(name=name, buses=buses, drives=drives, joints=joints, pairs=pairs, catalog=catalog, devices=devices,
                    il_codes=il, protocol=protocol, motion=motion, joystick=joystick, sim=sim,
                    sim_extra_nodes=sim_extra_nodes, sim_reply_timeout=sim_reply_timeout, homing=homing,
                    sim_power_up=sim_power_up, sim_wiring=sim_wiring, sim_buses=sim_buses, sim_ft=sim_ft, tuning=tuning,
                    poses=poses, source=filename)
    return cfg, locs, []


def parse_current(sec: Section, prefix: tuple[str, ...], locs: Locs) -> CurrentLimits | None:
    csec = sec.section("current", CURRENT_KEYS, what="a mapping {continuous: A, peak: A, peak_time: s}")
    if csec is None:
        return None
    register(locs, (*prefix, "current"), csec)
    return CurrentLimits(continuous=csec.num("continuous", required=True), peak=csec.num("peak", required=True),
                         peak_time=csec.num("peak_time", required=True), where=csec.node.loc)


def parse_joint_body(sec: Section, name: str, role: JointRole, drive: str | None, pair: str | None,
                     current: CurrentLimits | None, locs: Locs) -> JointConfig:
    prefix = ("joint", name)
    cpr = sec.int("cpr", required=True)
    rng = sec.section("range", RANGE_KEYS, required=True, what="a mapping {min, max, margin, overshoot}",
                      aliases=RANGE_ALIASES)
    assert rng is not None
    register(locs, (*prefix, "range"), rng)
    pos_min, pos_max = rng.int("min", required=True), rng.int("max", required=True)

    vel = sec.section("velocity", VELOCITY_KEYS, what="a mapping {limit: counts/s, trip: counts/s}")
    acc = sec.section("acceleration", ACCEL_KEYS, what="a mapping {accel: counts/s², decel: counts/s²}")
    cal = sec.section("calibration", CALIBRATION_KEYS, what="a mapping {speed: counts/s, position: counts}")
    for key, sub in (("velocity", vel), ("acceleration", acc), ("calibration", cal)):
        if sub is not None:
            register(locs, (*prefix, key), sub)

    abs_enc = None
    asec = sec.section("abs_encoder", ABS_KEYS, what='a mapping {source: "drive:PY", offset: counts}')
    if asec is not None:
        register(locs, (*prefix, "abs_encoder"), asec)
        abs_enc = AbsEncoderConfig(source=asec.str("source", required=True), offset=asec.int("offset", 0),
                                   where=asec.node.loc)

    switches: list[SwitchConfig] = []
    snode = sec.get("switches")
    if snode is not None:
        items = as_seq(snode, "a list of switches like [{input: 3, kind: stop, side: low}]")
        locs.put((*prefix, "switches"), snode.loc)
        for i, item in enumerate(items):
            switches.append(parse_switch(item, (*prefix, "switches", str(i)), pos_min, pos_max, locs))

    return JointConfig(
        name=name, role=role, drive=drive, pair=pair, cpr=cpr, pos_min=pos_min, pos_max=pos_max,
        margin=rng.int("margin", 0), overshoot=rng.int("overshoot", 0),
        vel_limit=vel.int("limit") if vel else None, vel_trip=vel.int("trip") if vel else None,
        accel=acc.int("accel") if acc else None, decel=acc.int("decel") if acc else None,
        current=current, switches=tuple(switches),
        cal_speed=cal.int("speed") if cal else None, cal_pos=cal.int("position") if cal else None,
        abs_encoder=abs_enc, gravity=bool(sec.bool("gravity", False)), where=sec.node.loc)


def parse_switch(item: YNode, prefix: tuple[str, ...], pos_min: int, pos_max: int, locs: Locs) -> SwitchConfig:
    s = Section(item, SWITCH_KEYS, what="a switch mapping like {input: 3, kind: stop, side: low}")
    register(locs, prefix, s)
    inp = s.int("input", required=True)
    knode = s.req("kind")
    kind_text = as_str(knode)
    try:
        kind = SwitchKind(kind_text)
    except ValueError:
        close = suggest(kind_text, [k.value for k in SwitchKind])
        more = f"; did you mean '{close}'?" if close else ""
        raise knode.error(f"unknown switch kind {kind_text!r}; expected 'stop' or 'home'{more}") from None
    side = None
    snode = s.get("side")
    if snode is not None:
        side = as_str(snode)
        if side not in SIDES:
            raise snode.error(f"unknown switch side {side!r}; expected 'low' or 'high'")
        if kind is SwitchKind.HOME:
            raise snode.error("'side' is only for stop switches; a home switch has just a position")
    if kind is SwitchKind.STOP and side is None:
        raise ConfigError("a stop switch needs 'side: low' or 'side: high' (the end of the range it guards)",
                          s.loc("side"))
    position = s.int("position")
    if position is None:
        if kind is SwitchKind.HOME:
            raise ConfigError("missing required key 'position' of a home switch (the joint position where it trips)",
                              s.loc("position"))
        position = pos_min if side == "low" else pos_max
    wired: tuple[str, ...] = ()
    wnode = s.get("drives")
    if wnode is not None:
        wired = tuple(as_str(w) for w in as_seq(wnode, "a list of drive names"))
    return SwitchConfig(input=inp, kind=kind, position=position, side=side, drives=wired, where=s.node.loc)


def parse_catalog(node: YNode | None, locs: Locs) -> Catalog:
    base = builtin_catalog()
    if node is None:
        return base
    sec = Section(node, CATALOG_KEYS, what="a mapping {drives: ..., motors: ..., peak_fraction: ...}")
    register(locs, ("catalog",), sec)
    drives = dict(base.drives)
    dnode = sec.get("drives")
    if dnode is not None:
        for raw, child in as_map(dnode, "a mapping of drive model names").items():
            key = catalog_key(raw)
            esec = Section(child, DRIVE_MODEL_KEYS, what="a drive model mapping (nominal_voltage, max_voltage, ...)")
            register(locs, ("catalog", "drives", key), esec)
            old = drives.get(key)
            vals = {k: _entry_num(esec, k, old) for k in DRIVE_MODEL_KEYS[:4]}
            inputs = esec.int("inputs", old.inputs if old else 6)
            drives[key] = DriveModel(key, inputs=inputs, **vals)
    motors = dict(base.motors)
    mnode = sec.get("motors")
    if mnode is not None:
        for raw, child in as_map(mnode, "a mapping of motor names").items():
            key = catalog_key(raw)
            esec = Section(child, MOTOR_MODEL_KEYS, what="a motor mapping (voltage, current_cont, ...)")
            register(locs, ("catalog", "motors", key), esec)
            old_motor = motors.get(key)
            motors[key] = MotorModel(key, **{k: _entry_num(esec, k, old_motor) for k in MOTOR_MODEL_KEYS})
    fraction = sec.num("peak_fraction", base.peak_fraction)
    return Catalog(drives=drives, motors=motors, peak_fraction=fraction)


def _entry_num(sec: Section, key: str, old: object | None) -> float:
    # Overriding a built-in entry may name only the keys that change; a new entry needs all of them.
    if old is not None and key not in sec:
        return float(getattr(old, key))
    return sec.num(key, required=True)
