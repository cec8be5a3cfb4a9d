"""`sherpa params diff A [B]`: two parameter sets side by side, per drive and parameter.

A side is a dump file, ``live`` (read from the drives now) or ``config`` (what Appendix C
derives, as ``sherpa limits show`` prints it). The config side covers only the parameters
it derives: UM and CA[18] are outside it and never count as missing; IL[1..n] are all in it
(an input without a switch should hold il_codes.unused). Floats compare within float32 precision, because CL/PL come back from the drive
as float32 (2.3 reads back as 2.2999999523...). docs/params.md has the rules.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import ConfigError, Location, UsageError
from sherpa_cli.ops.params_file import ParamDump, param_sort_key, read_dump

LIVE = "live"
CONFIG = "config"
# float32 keeps 24 bits (~7.2 decimal digits); a value that went through float32 is within
# 2**-24 relative of the original, so 1e-6 accepts the round trip and nothing coarser.
REL_TOL = 1e-6
ABS_TOL = 1e-9


class DiffStatus(StrEnum):
    """How one parameter compares (a str: JSON shows the words)."""

    SAME = "same"
    DIFFERS = "differs"
    ONLY_A = "only in A"
    ONLY_B = "only in B"


SAME, DIFFERS, ONLY_A, ONLY_B = DiffStatus.SAME, DiffStatus.DIFFERS, DiffStatus.ONLY_A, DiffStatus.ONLY_B


@dataclass(frozen=True)
class SideDrive:
    bus: str
    node: int
    params: dict[str, int | float]
    unreadable: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Side:
    """One side of a diff. ``partial``: only the keys it holds are compared (the config side)."""

    label: str
    kind: str  # "file" | "live" | "config"
    drives: dict[str, SideDrive]
    partial: bool = False


@dataclass(frozen=True)
class ParamRow:
    key: str
    a: int | float | None
    b: int | float | None
    status: DiffStatus
    a_note: str | None = None  # why a is missing: "unreadable: error 21 ..."
    b_note: str | None = None

    def as_json(self) -> dict[str, Any]:
        return {"param": self.key, "a": self.a, "b": self.b, "status": self.status,
                "a_unreadable": self.a_note, "b_unreadable": self.b_note}


@dataclass(frozen=True)
class DriveDiff:
    drive: str
    bus: str
    node: int
    rows: tuple[ParamRow, ...]
    only_in: str | None = None  # "A" / "B": the drive is on one side only

    @property
    def differences(self) -> int:
        if self.only_in:
            return 1
        return sum(1 for r in self.rows if r.status != SAME)

    def as_json(self) -> dict[str, Any]:
        return {"drive": self.drive, "bus": self.bus, "node": self.node, "only_in": self.only_in,
                "differences": self.differences, "params": [r.as_json() for r in self.rows]}


@dataclass(frozen=True)
class DiffReport:
    a: Side
    b: Side
    drives: tuple[DriveDiff, ...]
    warnings: tuple[str, ...] = ()

    @property
    def differences(self) -> int:
        return sum(d.differences for d in self.drives)

    @property
    def drives_differing(self) -> int:
        return sum(1 for d in self.drives if d.differences)

    def as_json(self) -> dict[str, Any]:
        return {"a": {"label": self.a.label, "kind": self.a.kind},
                "b": {"label": self.b.label, "kind": self.b.kind},
                "differences": self.differences, "drives_differing": self.drives_differing,
                "drives": [d.as_json() for d in self.drives], "warnings": list(self.warnings)}


def same_value(a: int | float, b: int | float) -> bool:
    if isinstance(a, int) and isinstance(b, int):
        return a == b
    return math.isclose(float(a), float(b), rel_tol=REL_TOL, abs_tol=ABS_TOL)


# --------------------------------------------------------------------------- sides

def side_kind(spec: str) -> str:
    return spec if spec in (LIVE, CONFIG) else "file"


def check_pair(a: str, b: str) -> None:
    if a == b and a in (LIVE, CONFIG):
        raise UsageError(f"both sides are '{a}': nothing to compare",
                         hint="compare a dump file with live or config, e.g. `sherpa params diff config live`")


def config_side(cfg: ArmConfig, drives: Sequence[str]) -> tuple[Side, list[str]]:
    """What ``limits show`` derives, checked like ``program-limits`` would before writing."""
    from sherpa_cli.joints.limits import derive_checked

    derived, warnings = derive_checked(cfg, list(drives))
    side = {d.drive: SideDrive(d.bus, d.node, dict(d.params)) for d in derived}
    return Side(CONFIG, "config", side, partial=True), warnings


def dump_side(label: str, dump: ParamDump, kind: str = "file") -> Side:
    return Side(label, kind, {name: SideDrive(d.bus, d.node, dict(d.params), dict(d.unreadable))
                              for name, d in dump.drives.items()})


def file_side(path: Path, cfg: ArmConfig) -> tuple[Side, list[str]]:
    """A dump file whose drives must all be drives of the config (else ConfigError, exit 2)."""
    dump = read_dump(path)
    warnings = []
    for name, d in dump.drives.items():
        if name not in cfg.drives:
            raise ConfigError(f"drive '{name}' is not in the config ({cfg.source or 'the config'})",
                              Location(str(path), _drive_line(path, name), f"drives.{name}"),
                              hint="compare with the config of the arm the dump was taken from (--config)")
        c = cfg.drives[name]
        if (c.bus, c.node) != (d.bus, d.node):
            warnings.append(f"{path}: drive {name} was dumped at {d.bus}:{d.node}; the config has it at "
                            f"{c.bus}:{c.node}")
    return dump_side(str(path), dump), warnings


def _drive_line(path: Path, name: str) -> int | None:
    from sherpa_cli.config.yamlnodes import parse_yaml, read_input

    root = parse_yaml(read_input(path), str(path))
    node = root.value.get("drives")
    child = node.value.get(name) if node is not None and node.kind == "map" else None
    return child.key_line if child is not None else None


def drives_of(sides: Sequence[Side], cfg: ArmConfig) -> list[str]:
    """The drives a diff covers when no target is given: every drive the sides name, in config order."""
    named = {name for s in sides for name in s.drives}
    return [d for d in cfg.drives if d in named]


# --------------------------------------------------------------------------- comparing

def _present(side: Side, drive: str, key: str) -> tuple[bool, int | float | None, str | None]:
    d = side.drives[drive]
    if key in d.params:
        return True, d.params[key], None
    if key in d.unreadable:
        return True, None, f"unreadable: {d.unreadable[key]}"
    return False, None, None


def _row(a: Side, b: Side, drive: str, key: str) -> ParamRow | None:
    has_a, va, na = _present(a, drive, key)
    has_b, vb, nb = _present(b, drive, key)
    # A partial side says nothing about keys it does not derive: no row, no difference.
    if (not has_a and a.partial) or (not has_b and b.partial):
        return None
    if has_a and has_b:
        if va is not None and vb is not None:
            status = SAME if same_value(va, vb) else DIFFERS
        else:
            status = SAME if va is None and vb is None else DIFFERS
    else:
        status = ONLY_A if has_a else ONLY_B
    return ParamRow(key, va, vb, status, na, nb)


def diff_sides(a: Side, b: Side, drives: Sequence[str], warnings: Sequence[str] = ()) -> DiffReport:
    out = []
    for drive in drives:
        da, db = a.drives.get(drive), b.drives.get(drive)
        if da is None and db is None:
            continue
        if da is None or db is None:
            have = da or db
            assert have is not None
            out.append(DriveDiff(drive, have.bus, have.node, (), only_in="A" if da is not None else "B"))
            continue
        keys = sorted({*da.params, *da.unreadable, *db.params, *db.unreadable}, key=param_sort_key)
        rows = tuple(r for r in (_row(a, b, drive, k) for k in keys) if r is not None)
        out.append(DriveDiff(drive, da.bus, da.node, rows))
    return DiffReport(a, b, tuple(out), tuple(warnings))
