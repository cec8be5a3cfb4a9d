"""`sim: ft_sensors:` what a simulated ATI F/T sensor feels (sim/ft_sensor.py)::

    sim:
      ft_sensors:
        wrist_ft: {payload_kg: 1.2, wrist: [wrist_pitch], wall_joint: wrist_pitch, wall_position: 3000}

Only the simulator reads it; the names must be ft_sensor devices (config/validate.py).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping

from sherpa_cli.config.model import SimFtConfig
from sherpa_cli.config.yamlnodes import Locs, Section, as_num, as_seq, as_str, named_items
from sherpa_cli.errors import ConfigError

SIM_FT_KEYS = tuple(f.name for f in dataclasses.fields(SimFtConfig))


def parse_sim_ft(top: Section, locs: Locs, sim_keys: Iterable[str]) -> dict[str, SimFtConfig]:
    sim = top.section("sim", list(sim_keys))
    if sim is None or sim.get("ft_sensors") is None:
        return {}
    out: dict[str, SimFtConfig] = {}
    d = SimFtConfig()
    for name, node in named_items(sim.req("ft_sensors"), "ft_sensor"):
        sec = Section(node, list(SIM_FT_KEYS), what="a mapping like {payload_kg: 1.0, wrist: [wrist_pitch]}")
        locs.put(("sim", "ft_sensors", name), node.loc)
        for key, child in sec.node.value.items():
            locs.put(("sim", "ft_sensors", name, key), child.loc)
        com = d.payload_com
        if sec.get("payload_com") is not None:
            items = as_seq(sec.req("payload_com"), "a list [x, y, z] in m")
            if len(items) != 3:
                raise ConfigError(f"payload_com: expected [x, y, z], got {len(items)} value(s)", sec.loc("payload_com"))
            com = (as_num(items[0]), as_num(items[1]), as_num(items[2]))
        wrist: tuple[str, ...] = ()
        if sec.get("wrist") is not None:
            wrist = tuple(as_str(i) for i in as_seq(sec.req("wrist"), "a list of joint names"))
        out[name] = SimFtConfig(
            payload_kg=sec.num("payload_kg", d.payload_kg), payload_com=com, wrist=wrist,
            wall_joint=sec.str("wall_joint"), wall_position=sec.int("wall_position", d.wall_position),
            wall_side=sec.str("wall_side", d.wall_side), wall_stiffness=sec.num("wall_stiffness", d.wall_stiffness),
            wall_axis=sec.str("wall_axis", d.wall_axis), noise_force=sec.num("noise_force", d.noise_force),
            noise_torque=sec.num("noise_torque", d.noise_torque), drift_force=sec.num("drift_force", d.drift_force),
            drift_torque=sec.num("drift_torque", d.drift_torque), seed=sec.int("seed", d.seed),
            silent_at=sec.num("silent_at"), status=_status(sec))
    return out


def _status(sec: Section) -> int:
    value = sec.int("status", 0)
    if not 0 <= value <= 0xFFFF:
        raise ConfigError(f"status: {value} is not a 16-bit status word (0..0xFFFF)", sec.loc("status"))
    return value


def dump_sim_ft(sensors: Mapping[str, SimFtConfig]) -> dict[str, dict[str, object]]:
    """The section back as plain data (only what differs from the defaults)."""
    base = SimFtConfig()
    out: dict[str, dict[str, object]] = {}
    for name, s in sensors.items():
        values = {f.name: getattr(s, f.name) for f in dataclasses.fields(s) if getattr(s, f.name) != getattr(base, f.name)}
        out[name] = {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
    return out
