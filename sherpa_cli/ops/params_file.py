"""The parameter dump file (``sherpa dump-params``): model, YAML text, reading and atomic writing.

Pure: no bus I/O. The file is meant to live in git, so its text is a function of the
values alone: a ``meta`` header block first (the only part that changes between two
dumps of the same unchanged drives: date, tool version, config hash), then ``drives:``
with one block per drive keyed by its config name, in config order, and inside a block
fixed keys and parameters in :func:`param_sort_key` order. docs/params.md describes it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from sherpa_cli.config.yamlnodes import NAME_RE, Section, YNode, as_int, as_map, describe, parse_yaml, read_input
from sherpa_cli.errors import CodecError, ConfigError, Location

ParamValue = int | float

META_KEYS = ("tool", "tool_version", "config", "config_sha256", "date")
IDENTITY_KEYS = ("device_type", "vendor_id", "product_code", "revision", "serial",
                 "device_name", "hardware_version", "software_version")
_IDENTITY_STR = frozenset({"device_name", "hardware_version", "software_version"})
_DRIVE_KEYS = ("bus", "node", "identity", "params", "unreadable")

HEADER_COMMENT = ("# sherpa-cli parameter dump (sherpa dump-params). Only the meta block differs between\n"
                  "# two dumps of the same unchanged drives; see docs/params.md.\n")


@dataclass(frozen=True)
class DriveDump:
    """What one drive held when it was read."""

    name: str
    bus: str
    node: int
    identity: dict[str, Any]  # IDENTITY_KEYS -> int / str, None if unreadable
    params: dict[str, ParamValue]  # commands.param_key form: "UM", "LL[3]", "IL[1]", "CA[18]"
    unreadable: dict[str, str]  # param key -> why it could not be read


@dataclass(frozen=True)
class ParamDump:
    meta: dict[str, Any]  # META_KEYS
    drives: dict[str, DriveDump]  # keyed by config name, config order


def param_sort_key(key: str) -> tuple[str, int]:
    """Letters, then numeric index, so IL[10] follows IL[9]; the order of every params block."""
    from sherpa_cli.elmo.commands import parse_param_key
    try:
        return parse_param_key(key)
    except CodecError:
        return (key, -1)


def sorted_params(params: dict[str, Any]) -> dict[str, Any]:
    return {k: params[k] for k in sorted(params, key=param_sort_key)}


# --------------------------------------------------------------------------- writing

def drive_block(d: DriveDump) -> dict[str, Any]:
    """One drive as the dump file and ``dump-params --json`` write it."""
    return {
        "bus": d.bus,
        "node": d.node,
        "identity": {k: d.identity.get(k) for k in IDENTITY_KEYS},
        "params": sorted_params(d.params),
        "unreadable": sorted_params(d.unreadable),
    }


def _yaml(data: object) -> str:
    # width: never fold a long device name over lines, a fold would show up as a diff.
    # ASCII only: PyYAML writes some Unicode line breaks (U+0085) raw and reads them back as spaces.
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False, allow_unicode=False, width=10_000)


def dump_to_text(dump: ParamDump) -> str:
    meta = {k: dump.meta.get(k) for k in META_KEYS}
    meta.update({k: v for k, v in dump.meta.items() if k not in meta})
    parts = [HEADER_COMMENT, _yaml({"meta": meta}), "\ndrives:\n" if dump.drives else "\ndrives: {}\n"]
    blocks = []
    for name, d in dump.drives.items():
        text = _yaml({name: drive_block(d)})
        blocks.append("".join("  " + line if line.strip() else line for line in text.splitlines(True)))
    parts.append("\n".join(blocks))
    return "".join(parts)


def write_dump(path: Path, dump: ParamDump, option: str = "--output") -> None:
    """By the output-file rules (sherpa_cli/output_files.py): ``-`` is stdout, a regular file is replaced
    atomically (a crash leaves the old file or none, never half a file), a symlink's target is
    written, a FIFO or device in place; a directory is refused (UsageError naming ``option``)."""
    from sherpa_cli.output_files import write_output

    write_output(path, dump_to_text(dump), option, what="the dump")


# --------------------------------------------------------------------------- reading

def read_dump(path: Path) -> ParamDump:
    """Read a dump file; anything wrong is a ConfigError naming file, line and key path."""
    path = Path(path)
    try:
        text = read_input(path)
    except FileNotFoundError:
        raise ConfigError("dump file not found", Location(str(path))) from None
    except IsADirectoryError:
        raise ConfigError("is a directory, expected a dump file", Location(str(path))) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read dump file: {exc}", Location(str(path))) from None
    return dump_from_text(text, str(path))


def dump_from_text(text: str, filename: str) -> ParamDump:
    root = parse_yaml(text, filename)
    top = Section(root, ("meta", "drives"), what="a parameter dump (meta: and drives:)")
    meta_node = top.req("meta")
    meta = {k: _meta_value(v) for k, v in as_map(meta_node, "a mapping (the meta block)").items()}
    drives: dict[str, DriveDump] = {}
    drives_node = top.node.value.get("drives")
    if drives_node is None:
        raise ConfigError("missing required key 'drives' in the top level", root.child_loc("drives"))
    for name, node in as_map(drives_node, "a mapping of drive names", null_ok=True).items():
        if not NAME_RE.match(name):
            raise ConfigError(f"invalid drive name {name!r}", node.loc)
        drives[name] = _read_drive(name, node)
    return ParamDump(meta=meta, drives=drives)


def _meta_value(node: YNode) -> str | int | float | bool | None:
    if node.kind != "scalar":
        raise node.error(f"expected a plain value, got {describe(node)}")
    v = node.value
    # An unquoted date written by hand is a YAML timestamp; the dump keeps it as text.
    return v if v is None or isinstance(v, (str, int, float, bool)) else str(v)


def _read_drive(name: str, node: YNode) -> DriveDump:
    sec = Section(node, _DRIVE_KEYS, what=f"a drive block for {name!r}")
    bus = sec.str("bus", required=True)
    node_id = as_int(sec.req("node"))
    if not 1 <= node_id <= 127:
        raise sec.req("node").error(f"node id must be 1..127, got {node_id}")
    identity: dict[str, Any] = {k: None for k in IDENTITY_KEYS}
    id_node = sec.get("identity")
    if id_node is not None:
        Section(id_node, IDENTITY_KEYS, what="a mapping of identity fields")
        for key, child in id_node.value.items():
            identity[key] = _identity_value(key, child)
    params: dict[str, ParamValue] = {}
    p_node = sec.get("params")
    if p_node is not None:
        for key, child in as_map(p_node, "a mapping of parameter: value").items():
            params[_key(key, child)] = _number(child)
    unreadable: dict[str, str] = {}
    u_node = sec.get("unreadable")
    if u_node is not None:
        for key, child in as_map(u_node, "a mapping of parameter: reason").items():
            if child.kind != "scalar" or not isinstance(child.value, str):
                raise child.error(f"expected the reason as text, got {describe(child)}")
            unreadable[_key(key, child)] = child.value
    both = sorted(set(params) & set(unreadable), key=param_sort_key)
    if both:
        raise ConfigError(f"{both[0]} is both in params and in unreadable", u_node.loc if u_node else node.loc)
    return DriveDump(name=name, bus=bus, node=node_id, identity=identity, params=params, unreadable=unreadable)


def _identity_value(key: str, node: YNode) -> str | int | None:
    if node.is_null:
        return None
    v = node.value
    if key in _IDENTITY_STR:
        if node.kind != "scalar" or isinstance(v, bool) or not isinstance(v, (str, int, float)):
            raise node.error(f"expected text, got {describe(node)}")
        return str(v)
    if node.kind != "scalar" or isinstance(v, bool) or not isinstance(v, int):
        raise node.error(f"expected an integer, got {describe(node)}")
    return v


def _key(key: str, node: YNode) -> str:
    from sherpa_cli.elmo.commands import param_key, parse_param_key
    try:
        return param_key(*parse_param_key(key))
    except CodecError as exc:
        raise ConfigError(f"bad parameter key: {exc.message}", node.loc, hint=exc.hint) from None


def _number(node: YNode) -> ParamValue:
    v = node.value
    if node.kind != "scalar" or isinstance(v, bool) or not isinstance(v, (int, float)):
        raise node.error(f"expected a number, got {describe(node)}")
    if isinstance(v, float) and not math.isfinite(v):
        raise node.error(f"expected a finite number, got {v!r}")
    return v
