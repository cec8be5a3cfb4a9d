"""What a simulated drive keeps across power cycles: its flash (what SV saved) and its save count.

``--sim`` behaves like a real arm that is power-cycled between commands: RAM is new each
run, flash persists in one JSON file per arm under the user's state directory. Two simulators
of the same arm (two commands at once) merge their saves under a file lock: neither loses the
other's SV.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.paths import file_lock, read_json, state_dir, write_atomic

FORMAT = 1


@dataclass
class DriveFlash:
    serial: int
    flash: dict[str, int | float] = field(default_factory=dict)  # parameter key -> saved value
    save_count: int = 0


def arm_key(cfg: ArmConfig) -> str:
    """One state file per arm: its name plus the drives' addresses (a re-wired arm starts fresh)."""
    layout = sorted((d.name, d.bus, d.node) for d in cfg.drives.values())
    digest = hashlib.sha256(json.dumps(layout).encode()).hexdigest()[:10]
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in cfg.name)
    return f"{safe}-{digest}"


def state_path(cfg: ArmConfig) -> Path:
    return state_dir() / "sim" / f"{arm_key(cfg)}.json"


def default_serial(cfg: ArmConfig, drive: str) -> int:
    """A stable serial number per drive (unique within the arm), as 0x1018 sub 4 reports it."""
    names = sorted(cfg.drives)
    return 0x5A000000 + 0x100 * (names.index(drive) + 1) + cfg.drives[drive].node


def load(cfg: ArmConfig, path: Path | None = None) -> dict[str, DriveFlash]:
    """Flash per drive; drives not in the file start at factory state."""
    data: dict[str, Any] = read_json(path or state_path(cfg), {})
    drives = data.get("drives", {}) if data.get("format") == FORMAT else {}
    result = {}
    for name in cfg.drives:
        saved = drives.get(name, {})
        result[name] = DriveFlash(serial=int(saved.get("serial", default_serial(cfg, name))),
                                  flash=dict(saved.get("flash", {})),
                                  save_count=int(saved.get("save_count", 0)))
    return result


def save(cfg: ArmConfig, drives: dict[str, DriveFlash], path: Path | None = None) -> Path:
    target = path or state_path(cfg)
    body = {"format": FORMAT, "arm": cfg.name,
            "drives": {name: {"serial": d.serial, "save_count": d.save_count, "flash": d.flash}
                       for name, d in sorted(drives.items())}}
    write_atomic(target, json.dumps(body, indent=1, sort_keys=True) + "\n")
    return target


def save_changes(cfg: ArmConfig, before: dict[str, DriveFlash], after: dict[str, DriveFlash],
                 path: Path | None = None) -> Path:
    """Store what changed between ``before`` (as loaded) and ``after``, merged with the file as it
    is now: another simulator of this arm may have saved meanwhile. A drive this one saved gets
    its flash and the other's saves added to its count; the others keep what the file holds."""
    target = path or state_path(cfg)
    with file_lock(target):
        current = load(cfg, target)
        for name, now in after.items():
            then = before.get(name)
            if then is not None and now.flash == then.flash and now.save_count == then.save_count:
                continue
            added = now.save_count - (then.save_count if then is not None else 0)
            base = current.get(name)
            count = (base.save_count if base is not None else 0) + max(added, 0)
            current[name] = DriveFlash(serial=now.serial, flash=dict(now.flash), save_count=count)
        return save(cfg, current, target)


def reset(cfg: ArmConfig, path: Path | None = None) -> bool:
    """Factory state for the arm: removes its state file; True if there was one."""
    target = path or state_path(cfg)
    with file_lock(target):
        try:
            target.unlink()
            return True
        except FileNotFoundError:
            return False
