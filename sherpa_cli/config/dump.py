"""ArmConfig -> native YAML (``sherpa config convert``); ``load(dump(cfg)) == cfg``.

Every value the model holds is written, defaults included, so a converted file shows the
technician what the tool will do; only empty blocks (no velocity, no switches, ...) and the
catalog entries that equal the built-in ones are left out.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import yaml

from sherpa_cli.config.catalog import builtin_catalog
from sherpa_cli.config.model import (
    ArmConfig,
    BusConfig,
    CurrentLimits,
    DeviceConfig,
    HomingConfig,
    ILCodes,
    JointConfig,
    JointRole,
    JoystickConfig,
    JoystickMap,
    MotionConfig,
    ProtocolConfig,
    SimDriveConfig,
)
from sherpa_cli.config.simbus import dump_sim_buses
from sherpa_cli.config.simft import dump_sim_ft


def dump_native(cfg: ArmConfig) -> str:
    sections: list[dict[str, Any]] = [{"name": cfg.name}]
    if cfg.il_codes != ILCodes():
        sections.append({"il_codes": dataclasses.asdict(cfg.il_codes)})
    if cfg.protocol != ProtocolConfig():
        sections.append({"protocol": dataclasses.asdict(cfg.protocol)})
    if cfg.tuning:
        sections.append({"tuning": {key: list(bounds) for key, bounds in cfg.tuning.items()}})
    if cfg.motion != MotionConfig():
        sections.append({"motion": dataclasses.asdict(cfg.motion)})
    if cfg.homing != HomingConfig():
        sections.append({"homing": dataclasses.asdict(cfg.homing)})
    if cfg.joystick != JoystickConfig():
        joy = cfg.joystick
        base = JoystickMap()
        maps = [{k: v for k, v in dataclasses.asdict(m).items() if v is not None and (v != getattr(base, k) or
                                                                                        k in ("mode", "sensitivity"))}
                for m in joy.axes]
        sections.append({"joystick": _drop_none({"device": joy.device, "rate_hz": joy.rate_hz,
                                                 "deadzone": joy.deadzone, "deadman": joy.deadman, "axes": maps})})
    sim: dict[str, Any] = {}
    if cfg.sim:
        sim["drives"] = {name: _drop_default(dataclasses.asdict(f), SimDriveConfig()) for name, f in cfg.sim.items()}
    if cfg.sim_extra_nodes:
        sim["extra_nodes"] = [dataclasses.asdict(e) for e in cfg.sim_extra_nodes]
    if cfg.sim_reply_timeout != ArmConfig.sim_reply_timeout:
        sim["reply_timeout"] = cfg.sim_reply_timeout
    if cfg.sim_power_up:
        sim["power_up"] = dict(cfg.sim_power_up)
    if cfg.sim_wiring:
        sim["wiring"] = {name: _drop_none({"swap": [list(p) for p in w.swap] or None, "invert": list(w.invert) or None})
                         for name, w in cfg.sim_wiring.items()}
    if cfg.sim_buses:
        sim["buses"] = dump_sim_buses(cfg.sim_buses)
    if cfg.sim_ft:
        sim["ft_sensors"] = dump_sim_ft(cfg.sim_ft)
    if sim:
        sections.append({"sim": sim})
    sections.append({"buses": {b.name: _bus(b) for b in cfg.buses.values()}})
    # the default type is left out, so a config without cia402 drives dumps as it always did
    sections.append({"drives": {d.name: _drop_none({"type": None if d.type == "elmo" else d.type, "bus": d.bus,
                                                    "node": d.node, "model": d.model, "motor": d.motor})
                                for d in cfg.drives.values()}})
    if cfg.devices:
        sections.append({"devices": {d.name: _device(d) for d in cfg.devices.values()}})
    plain = {j.name: {"drive": j.drive, **_joint_body(j)} for j in cfg.joints.values() if j.role is JointRole.PLAIN}
    for name, j in ((j.name, j) for j in cfg.joints.values() if j.role is JointRole.PLAIN):
        if j.current is not None:
            plain[name]["current"] = _current(j.current)
    if plain:
        sections.append({"joints": plain})
    pairs: dict[str, Any] = {}
    for p in cfg.pairs.values():
        entry: dict[str, Any] = {"drives": [p.drive_a, p.drive_b]}
        if p.current is not None:
            entry["current"] = _current(p.current)
        for key, jname in (("sigma", p.sigma), ("delta", p.delta)):
            entry[key] = {"name": jname, **_joint_body(cfg.joints[jname])}
        pairs[p.name] = entry
    if pairs:
        sections.append({"pairs": pairs})
    if cfg.poses:  # after the joints they name
        sections.append({"poses": {p.name: dict(p.values) for p in cfg.poses.values()}})
    catalog = _catalog_diff(cfg)
    if catalog:
        sections.append({"catalog": catalog})
    header = f"# sherpa-cli native config, written from {cfg.source}\n" if cfg.source else ""
    # Flow style for leaf blocks keeps one joint readable at a glance: range: {min: .., max: ..}.
    return header + "\n".join(
        yaml.safe_dump(s, sort_keys=False, default_flow_style=None if i else False, allow_unicode=True, width=120)
        for i, s in enumerate(sections))


def _drop_none(d: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in d.items() if v is not None}


def _bus(b: BusConfig) -> dict[str, Any]:
    out = _drop_none({"interface": b.interface, "channel": b.channel, "bitrate": b.bitrate})
    out["send_interval_us"] = b.send_interval_us
    out["poll_interval_ms"] = b.poll_interval_ms
    if b.options:
        out["options"] = dict(b.options)
    return out


def _current(c: CurrentLimits) -> dict[str, Any]:
    return {"continuous": c.continuous, "peak": c.peak, "peak_time": c.peak_time}


def _joint_body(j: JointConfig) -> dict[str, Any]:
    out: dict[str, Any] = {"cpr": j.cpr,
                           "range": {"min": j.pos_min, "max": j.pos_max, "margin": j.margin,
                                     "overshoot": j.overshoot}}
    vel = _drop_none({"limit": j.vel_limit, "trip": j.vel_trip})
    if vel:
        out["velocity"] = vel
    acc = _drop_none({"accel": j.accel, "decel": j.decel})
    if acc:
        out["acceleration"] = acc
    if j.switches:
        out["switches"] = []
        for s in j.switches:
            sw: dict[str, Any] = {"input": s.input, "kind": s.kind.value}
            if s.side is not None:
                sw["side"] = s.side
            sw["position"] = s.position
            if s.drives:
                sw["drives"] = list(s.drives)
            out["switches"].append(sw)
    cal = _drop_none({"speed": j.cal_speed, "position": j.cal_pos})
    if cal:
        out["calibration"] = cal
    if j.abs_encoder is not None:
        out["abs_encoder"] = {"source": j.abs_encoder.source, "offset": j.abs_encoder.offset}
    if j.gravity:
        out["gravity"] = True
    return out


def _catalog_diff(cfg: ArmConfig) -> dict[str, Any]:
    base = builtin_catalog()
    out: dict[str, Any] = {}
    drives = {k: {"nominal_voltage": m.nominal_voltage, "max_voltage": m.max_voltage,
                  "current_cont": m.current_cont, "current_peak": m.current_peak, "inputs": m.inputs}
              for k, m in cfg.catalog.drives.items() if base.drives.get(k) != m}
    motors = {k: {"voltage": m.voltage, "current_cont": m.current_cont, "power": m.power,
                  "current_peak": m.current_peak, "peak_power": m.peak_power}
              for k, m in cfg.catalog.motors.items() if base.motors.get(k) != m}
    if drives:
        out["drives"] = drives
    if motors:
        out["motors"] = motors
    if cfg.catalog.peak_fraction != base.peak_fraction:
        out["peak_fraction"] = cfg.catalog.peak_fraction
    return out


def _drop_default(values: dict[str, Any], default: object) -> dict[str, Any]:
    return {k: v for k, v in values.items() if v != getattr(default, k)}


def _device(d: DeviceConfig) -> dict[str, Any]:
    if d.ft is None:
        return {"type": d.type, "bus": d.bus, "node": d.node, **_device_options(d)}
    ft = d.ft
    return _drop_none({"type": d.type, "bus": d.bus, "base_id": ft.base_id, "counts_per_force": ft.counts_per_force,
                       "counts_per_torque": ft.counts_per_torque, "frame": ft.frame, "force_limit": ft.force_limit,
                       "torque_limit": ft.torque_limit, "reply_ms": ft.reply_ms})


def _device_options(d: DeviceConfig) -> dict[str, Any]:
    """The encoder settings that differ from their defaults (a dump stays as short as the config)."""
    base = DeviceConfig(d.name, d.type, d.bus, d.node)
    return {k: getattr(d, k) for k in ("position_from", "tpdo_trigger", "cyclic_ms") if getattr(d, k) != getattr(base, k)}
