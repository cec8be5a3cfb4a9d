"""Appendix C's software side: the ROS parameters (Tables C.1/C.2) of each joint, and a config
written back in the seed's rosparam format (Appendix D.1).

Pure functions over an ArmConfig. The mapping is the inverse of rosparam.py's (docs/config.md):
a plain joint is one node; a differential pair is two nodes that both carry the Σ joint's
values and the Δ joint's as ``*_dd``, each naming the other in ``diffdrive``. What the format
cannot say (overshoot, velocity, acceleration, currents, models, switches other than the
seed's end/home switches) is reported as a warning, never silently dropped.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from sherpa_cli.config.model import ArmConfig, JointConfig, SwitchKind

# Table C.1 / C.2 wording of each parameter (Table D.4 for the rest), in the seed's key order.
DESCRIPTIONS = {
    "cpr": "counts per round",
    "pos_min": "minimum position (of full operating range)",
    "pos_max": "maximum position (of full operating range)",
    "pos_margin": "difference between normal and full operating range",
    "diffdrive": "node of the other motor of the differential pair",
    "pos_min_dd": "minimum position of the Δ-joint",
    "pos_max_dd": "maximum position of the Δ-joint",
    "pos_margin_dd": "difference between normal and full operating range of the Δ-joint",
    "cal_speed": "speed towards the calibration switch",
    "cal_pos": "position to be set after reaching calibration switch",
    "ext_pos_input": "topic of an absolute position sensor",
    "cal_sw_L": "input number of the low position end switch (or the position switch)",
    "cal_sw_H": "input number of the high position end switch",
    "cal_sw_dd_L": "input number of the low position end switch of the Δ-joint",
    "cal_sw_dd_H": "input number of the high position end switch of the Δ-joint",
}
NODE_ORDER = ["topics", "dev_bus", "dev_id", "dev_type", *DESCRIPTIONS]
ELMO_SIMPLIQ = 1
QUEUE_SIZE = 100  # the seed's value; the format's queue_size has no counterpart in the native config


@dataclass
class SoftwareEntry:
    """The ROS parameters of one plain joint or one differential pair (both motors carry them)."""

    title: str  # "joint joint1" / "pair pair1 (Σ joint_sigma, Δ joint_delta)"
    joints: tuple[str, ...]
    drives: tuple[str, ...]
    params: dict[str, Any]
    warnings: list[str] = field(default_factory=list)


def software_params(cfg: ArmConfig) -> list[SoftwareEntry]:
    """Per plain joint and per pair, in config order: Table C.1/C.2's parameters."""
    entries: list[SoftwareEntry] = []
    for joint in cfg.joints.values():
        if joint.drive is not None:
            warnings: list[str] = []
            params = _joint_params(joint, "", warnings)
            entries.append(SoftwareEntry(f"joint {joint.name}", (joint.name,), (joint.drive,),
                                         {k: v for k, v in params.items() if v is not None}, warnings))
    for pair in cfg.pairs.values():
        sigma, delta = cfg.joints[pair.sigma], cfg.joints[pair.delta]
        warnings = []
        params = _joint_params(sigma, "", warnings)
        dd = _joint_params(delta, "_dd", warnings)
        for key in ("cpr", "cal_speed"):
            if dd.get(key) != params.get(key):
                warnings.append(f"pair {pair.name}: the Δ joint's {key} ({dd.get(key)}) differs from the Σ joint's "
                                f"({params.get(key)}); the format has one {key} per node (the Σ joint's is written)")
        if delta.cal_pos is not None and delta.cal_pos != delta.pos_min and delta.abs_encoder is None:
            warnings.append(f"joint {delta.name}: the format has no Δ calibration position; "
                            f"{delta.cal_pos} becomes pos_min_dd ({delta.pos_min})")
        for key in ("pos_min", "pos_max", "pos_margin", "cal_sw_L", "cal_sw_H"):
            if dd.get(key) is not None:
                params[key + "_dd" if not key.startswith("cal_sw") else key.replace("cal_sw", "cal_sw_dd")] = dd[key]
        params["ext_pos_input_dd"] = dd.get("ext_pos_input")  # the other node's ext_pos_input (rosparam.py)
        entries.append(SoftwareEntry(f"pair {pair.name} (Σ {sigma.name}, Δ {delta.name})", (sigma.name, delta.name),
                                     (pair.drive_a, pair.drive_b), {k: v for k, v in params.items() if v is not None},
                                     warnings))
    return entries


def _joint_params(j: JointConfig, sfx: str, warnings: list[str]) -> dict[str, Any]:
    p: dict[str, Any] = {"cpr": j.cpr, "pos_min": j.pos_min, "pos_max": j.pos_max, "pos_margin": j.margin,
                         "cal_speed": j.cal_speed, "cal_pos": j.cal_pos,
                         "ext_pos_input": j.abs_encoder.source if j.abs_encoder is not None else None}
    stops = {s.side: s for s in j.switches if s.kind is SwitchKind.STOP}
    homes = [s for s in j.switches if s.kind is SwitchKind.HOME]
    kinds = sorted((s.kind.value, s.side or "") for s in j.switches)
    if kinds == [("stop", "high"), ("stop", "low")]:
        p["cal_sw_L"], p["cal_sw_H"] = stops["low"].input, stops["high"].input
        _at(j, stops["low"].position, j.pos_min, "low stop switch", warnings)
        _at(j, stops["high"].position, j.pos_max, "high stop switch", warnings)
    elif len(homes) == 1 and len(j.switches) == 1:
        p["cal_sw_L"] = homes[0].input
        _at(j, homes[0].position, j.cal_pos if j.cal_pos is not None else j.pos_min, "home switch", warnings)
    elif kinds == [("stop", "high")]:
        p["cal_sw_H"] = stops["high"].input
        _at(j, stops["high"].position, j.pos_max, "high stop switch", warnings)
    elif j.switches:
        warnings.append(f"joint {j.name}: its switches ({', '.join(f'{s.kind.value} on input {s.input}' for s in j.switches)}) "
                        "are not one of the seed's layouts (two end switches, one home switch, one high end "
                        "switch); cal_sw_* left out")
    return p


def _at(j: JointConfig, position: int, expected: int, what: str, warnings: list[str]) -> None:
    if position != expected:
        warnings.append(f"joint {j.name}: its {what} is at {position}; the format puts it at {expected}")


def _node_keys(cfg: ArmConfig) -> dict[str, str]:
    """Drive -> node key: ``node<k>`` names keep their k (a config read from D.1), else config order."""
    keys: dict[str, str] = {}
    if all(re.fullmatch(r"node\d+", d) for d in cfg.drives):
        return {d: str(int(d[4:])) for d in cfg.drives}
    for i, d in enumerate(cfg.drives):
        keys[d] = str(i)
    return keys


def dump_rosparam(cfg: ArmConfig) -> tuple[str, list[str]]:
    """The config as the seed's D.1 file (``ros_can_interface:``), and what the format cannot hold."""
    keys = _node_keys(cfg)
    warnings: list[str] = []
    lost: dict[str, list[str]] = {}  # what the format has no key for -> the joints/drives/buses that had it
    nodes: dict[str, dict[str, Any]] = {}
    for entry in software_params(cfg):
        warnings.extend(entry.warnings)
        own = {k: v for k, v in entry.params.items() if k != "ext_pos_input_dd"}
        if len(entry.drives) == 1:
            nodes[entry.drives[0]] = own
            continue
        a, b = entry.drives
        lo, hi = sorted((a, b), key=lambda d: int(keys[d]))
        # each node names its partner; the lower key's ext_pos_input is the Σ joint's, the other's the Δ's
        nodes[lo] = {**own, "diffdrive": int(keys[hi])}
        hi_params = {**own, "diffdrive": int(keys[lo])}
        hi_params.pop("ext_pos_input", None)
        if entry.params.get("ext_pos_input_dd") is not None:
            hi_params["ext_pos_input"] = entry.params["ext_pos_input_dd"]
        nodes[hi] = hi_params
    lines = [f"# {cfg.name}: written by `sherpa config convert --to rosparam` (seed Appendix D.1 format)",
             "ros_can_interface:",
             " topics: [/joint]",
             f" interfaces: [{', '.join(cfg.buses)}]",
             f" queue_size: [{', '.join(str(QUEUE_SIZE) for _ in cfg.buses)}]",
             f" send_interval: [{', '.join(str(b.send_interval_us) for b in cfg.buses.values())}]",
             f" scheduler_interval: [{', '.join(str(b.poll_interval_ms) for b in cfg.buses.values())}]",
             " nodes:"]
    for bus in cfg.buses.values():
        if bus.channel not in (None, bus.name) or bus.interface not in (None, "socketcan"):
            warnings.append(f"bus {bus.name}: interface {bus.interface} channel {bus.channel} is not written; the "
                            f"format always means socketcan channel {bus.name}")
        if bus.bitrate:
            lost.setdefault("bitrate (set with ip link)", []).append(bus.name)
    for drive, d in sorted(cfg.drives.items(), key=lambda x: int(keys[x[0]])):
        k = keys[drive]
        values = {"topics": f"joint/{_moves(cfg, drive)}/joint_mc/{k}", "dev_bus": d.bus, "dev_id": d.node,
                  "dev_type": ELMO_SIMPLIQ, **nodes.get(drive, {})}
        if drive not in nodes:
            warnings.append(f"drive {drive}: moves no joint; written without joint keys (the format needs cpr, "
                            "pos_min, pos_max, pos_margin: fill them in)")
        if d.model or d.motor:
            lost.setdefault("drive model and motor", []).append(drive)
        body = ", ".join(f"{key}: {_scalar(values[key])}" for key in NODE_ORDER if values.get(key) is not None)
        lines.append(f"    '{k}': {{{body}}}")
    for j in cfg.joints.values():
        if j.overshoot:
            lost.setdefault("overshoot (LL/HL[3] then equal the full range)", []).append(j.name)
        if any(v is not None for v in (j.vel_limit, j.vel_trip, j.accel, j.decel)):
            lost.setdefault("velocity and acceleration limits", []).append(j.name)
        if j.current is not None:
            lost.setdefault("current limits", []).append(j.name)
    for p in cfg.pairs.values():
        if p.current is not None:
            lost.setdefault("current limits", []).append(p.name)
    for what, names in lost.items():
        warnings.append(f"the rosparam format has no {what}: not written for {', '.join(names)}")
    return "\n".join(lines) + "\n", warnings


def _moves(cfg: ArmConfig, drive: str) -> str:
    joint = cfg.joint_of_drive(drive)
    if joint is not None:
        return joint.name
    pair = cfg.pair_of_drive(drive)
    return pair.name if pair is not None else drive


def _scalar(value: object) -> str:
    if isinstance(value, str):
        import yaml

        return yaml.safe_dump(value, default_style=None, width=1 << 20).strip().removesuffix("\n...").strip()
    return str(value)
