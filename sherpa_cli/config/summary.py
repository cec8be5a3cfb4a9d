"""A plain-data summary of a loaded config (what `config check` shows and prints as JSON)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from sherpa_cli.config.model import ArmConfig, JointConfig


def _joint_drives(cfg: ArmConfig, joint: JointConfig) -> tuple[str, ...]:
    if joint.drive:
        return (joint.drive,)
    assert joint.pair is not None  # a joint has a drive or a pair (config/validate.py)
    pair = cfg.pairs[joint.pair]
    return (pair.drive_a, pair.drive_b)


def summarize(cfg: ArmConfig, findings: Iterable[Any] = ()) -> dict[str, Any]:
    moves: dict[str, str] = {}
    for joint in cfg.joints.values():
        if joint.drive:
            moves[joint.drive] = joint.name
    for pair in cfg.pairs.values():
        moves[pair.drive_a] = f"pair {pair.name}, motor a"
        moves[pair.drive_b] = f"pair {pair.name}, motor b"
    out = {
        "name": cfg.name,
        "source": cfg.source,
        "buses": [
            {"name": b.name, "interface": b.interface, "channel": b.channel, "bitrate": b.bitrate,
             "send_interval_us": b.send_interval_us, "poll_interval_ms": b.poll_interval_ms,
             "drives": sum(1 for d in cfg.drives.values() if d.bus == b.name)}
            for b in cfg.buses.values()
        ],
        "drives": [
            {"name": d.name, "bus": d.bus, "node": d.node, "model": d.model, "motor": d.motor,
             "moves": moves.get(d.name)}
            for d in cfg.drives.values()
        ],
        "joints": [
            {"name": j.name, "role": j.role.value, "drive": j.drive, "pair": j.pair, "cpr": j.cpr,
             "full_range": list(j.full_range), "normal_range": list(j.normal_range),
             "overshoot_range": list(j.overshoot_range),
             "switches": [{"input": s.input, "kind": s.kind.value, "side": s.side, "position": s.position,
                           "drives": list(s.drives or _joint_drives(cfg, j))} for s in j.switches]}
            for j in cfg.joints.values()
        ],
        "pairs": [
            {"name": p.name, "drive_a": p.drive_a, "drive_b": p.drive_b, "sigma": p.sigma, "delta": p.delta}
            for p in cfg.pairs.values()
        ],
        "warnings": list(cfg.warnings),
        "findings": [{"level": f.level, "message": f.message} for f in findings],
    }
    sensors = cfg.ft_sensors()
    if sensors:  # only then: a config without one summarizes as before
        out["ft_sensors"] = [
            {"name": d.name, "bus": d.bus, "base_id": d.ft.base_id, "frame": d.ft.frame,
             "counts_per_force": d.ft.counts_per_force, "counts_per_torque": d.ft.counts_per_torque,
             "force_limit": d.ft.force_limit, "torque_limit": d.ft.torque_limit}
            for d in sensors if d.ft is not None]
    return out
