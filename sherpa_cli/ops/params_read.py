"""Reading drives now: identity over SDO, parameters over the binary interpreter, buses at once.

Drives of one bus are read one after the other (one bus carries one conversation at a time
well); the buses run concurrently. A drive that stops answering ends that drive's reading
with a CommunicationError naming it; a parameter the drive refuses (an Elmo error reply) is
recorded as unreadable, since firmware differs in what it exposes (CA[18]).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.parallel import Outcome, run_concurrently
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import DriveRefusedError, SherpaError
from sherpa_cli.joints.params import PARAM_ORDER
from sherpa_cli.ops.params_file import DriveDump, ParamDump
from sherpa_cli.ops.tune import GAINS
from sherpa_cli.version import __version__

if TYPE_CHECKING:
    from sherpa_cli.bus.sdo import DriveSdo
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.elmo.client import DriveClient

# 0x1018 sub 1-4 and the strings of 0x1008/9/A (CiA 301), in IDENTITY_KEYS order.
IDENTITY_OBJECTS: tuple[tuple[str, int, int, str], ...] = (
    ("device_type", 0x1000, 0, "u32"),
    ("vendor_id", 0x1018, 1, "u32"),
    ("product_code", 0x1018, 2, "u32"),
    ("revision", 0x1018, 3, "u32"),
    ("serial", 0x1018, 4, "u32"),
    ("device_name", 0x1008, 0, "str"),
    ("hardware_version", 0x1009, 0, "str"),
    ("software_version", 0x100A, 0, "str"),
)
DEFAULT_INPUTS = 6  # a Whistle's digital inputs when the config names no model
DUMP_DATE_ENV = "SHERPA_DUMP_DATE"  # fixed date for the dump header (golden tests, reproducible dumps)

Progress = Callable[[str, str], None]  # (drive, what is being read)


def params_to_read(cfg: ArmConfig, drive: str) -> list[str]:
    """What commissioning touches: UM, every Appendix C parameter, IL[1..inputs], CA[18], and the
    loop gains `tune show` reads (ops/tune.py GAINS: `tune set` and `diffdrive match` change them)."""
    model = cfg.drives[drive].model
    inputs = cfg.catalog.drives[model].inputs if model is not None and model in cfg.catalog.drives else DEFAULT_INPUTS
    return ["UM", *PARAM_ORDER, *(f"IL[{n}]" for n in range(1, inputs + 1)), "CA[18]", *GAINS]


def read_identity(sdo: DriveSdo) -> tuple[dict[str, Any], dict[str, str]]:
    """Identity objects over the drive's SDO client: (values, why a field is None).

    An abort leaves that field None with the reason; any other failure (no answer, a
    malformed answer) raises the SdoError.
    """
    from sherpa_cli.bus.canopen_names import decode_text
    from sherpa_cli.errors import SdoError

    values: dict[str, Any] = {}
    notes: dict[str, str] = {}
    for key, index, sub, kind in IDENTITY_OBJECTS:
        try:
            data = sdo.upload(index, sub)
        except SdoError as exc:
            if exc.reason != "abort":
                raise
            values[key] = None
            notes[key] = exc.detail
            continue
        values[key] = decode_text(data) if kind == "str" else int.from_bytes(data[:4], "little")
    return values, notes


def read_params(client: DriveClient, keys: Iterable[str], progress: Progress | None = None,
                drive: str = "") -> tuple[dict[str, int | float], dict[str, str]]:
    """(values, unreadable): a refused parameter is unreadable, a silent drive raises."""
    from sherpa_cli.elmo.commands import parse_param_key
    from sherpa_cli.elmo.faults import ec_text

    values: dict[str, int | float] = {}
    unreadable: dict[str, str] = {}
    for key in keys:
        if progress:
            progress(drive, key)
        letters, index = parse_param_key(key)
        try:
            values[key] = client.get(letters, index)
        except DriveRefusedError as exc:
            unreadable[key] = f"error {exc.code}: {ec_text(exc.code)}" if exc.code is not None else exc.message
    return values, unreadable


def per_bus(session: ArmSession, drives: Sequence[str], work: Callable[[str], Any]) -> dict[str, Outcome[str]]:
    """``work(drive)`` for every drive: buses concurrently, drives of a bus in config order.

    Outcomes come back in the order of ``drives`` whatever finished first.
    """
    cfg: ArmConfig = session.cfg
    by_bus: dict[str, list[str]] = {}
    for d in drives:
        by_bus.setdefault(cfg.drives[d].bus, []).append(d)

    def bus_job(names: list[str]) -> Callable[[], dict[str, Outcome[str]]]:
        def run() -> dict[str, Outcome[str]]:
            done: dict[str, Outcome[str]] = {}
            for name in names:
                try:
                    done[name] = Outcome(name, value=work(name))
                except Exception as exc:  # noqa: BLE001 - one drive's failure is reported for that drive
                    done[name] = Outcome(name, error=exc)
            return done
        return run

    results: dict[str, Outcome[str]] = {}
    for outcome in run_concurrently({bus: bus_job(names) for bus, names in by_bus.items()}).values():
        if outcome.error is not None:
            raise outcome.error  # only KeyboardInterrupt and the like escape bus_job
        results.update(outcome.value)
    return {d: results[d] for d in drives}


def ref_of(cfg: ArmConfig, drive: str) -> DriveRef:
    from sherpa_cli.bus.targets import drive_ref

    return drive_ref(cfg, drive)


def open_drive(session: ArmSession, drive: str, progress: Progress | None = None) -> tuple[DriveClient, dict[str, Any], dict[str, str]]:
    """NMT-start a configured drive and read its identity: (client, identity, notes)."""
    cfg: ArmConfig = session.cfg
    client = session.client(ref_of(cfg, drive))
    client.nmt_start()  # the binary interpreter answers only in Operational
    if progress:
        progress(drive, "identity")
    identity, notes = read_identity(session.sdo(ref_of(cfg, drive)))
    return client, identity, notes


def read_drive_dump(session: ArmSession, drive: str, progress: Progress | None = None) -> DriveDump:
    cfg: ArmConfig = session.cfg
    d = cfg.drives[drive]
    client, identity, _ = open_drive(session, drive, progress)
    params, unreadable = read_params(client, params_to_read(cfg, drive), progress, drive)
    return DriveDump(name=drive, bus=d.bus, node=d.node, identity=identity, params=params, unreadable=unreadable)


def read_live(session: ArmSession, drives: Sequence[str], progress: Progress | None = None) -> dict[str, DriveDump]:
    """Every drive's dump; the first failed drive (in config order) raises, naming itself."""
    outcomes = per_bus(session, drives, lambda name: read_drive_dump(session, name, progress))
    failed = [o for o in outcomes.values() if not o.ok]
    if failed:
        first = failed[0].error
        assert first is not None
        if len(failed) > 1 and isinstance(first, SherpaError):
            others = ", ".join(o.key for o in failed[1:])
            first.hint = (first.hint + "; " if first.hint else "") + f"also failed: {others}"
        raise first
    return {name: o.value for name, o in outcomes.items()}


def dump_meta(cfg: ArmConfig, now: Callable[[], datetime] | None = None,
              environ: Mapping[str, str] = os.environ) -> dict[str, Any]:
    """The header block: tool, version, config file and its SHA-256, date (UTC).

    The date is ``$SHERPA_DUMP_DATE`` when set, so a dump can be reproduced byte for byte.
    """
    config_hash = None
    if cfg.source:
        try:
            config_hash = hashlib.sha256(Path(cfg.source).read_bytes()).hexdigest()
        except OSError:
            config_hash = None
    date = environ.get(DUMP_DATE_ENV)
    if not date:
        moment = now() if now is not None else datetime.now(UTC)
        date = moment.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    return {"tool": "sherpa-cli", "tool_version": __version__, "config": cfg.source,
            "config_sha256": config_hash, "date": date}


def dump_params(session: ArmSession, drives: Sequence[str], progress: Progress | None = None,
                now: Callable[[], datetime] | None = None) -> ParamDump:
    return ParamDump(meta=dump_meta(session.cfg, now), drives=read_live(session, drives, progress))
