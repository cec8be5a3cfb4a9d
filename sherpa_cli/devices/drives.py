"""The drive types behind the seam (sherpa_cli/drive.py): from a configured drive to its :class:`Drive`.

The config names each drive's type (``drives: NAME: type:``, "elmo" when absent); :data:`DRIVES`
maps the type to the function that builds the drive's :class:`~sherpa_cli.drive.Drive` on the
session's clients: the Elmo interpreter client, or the SDO client for a CiA 402 drive.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from sherpa_cli.cia402.drive import Cia402Drive
from sherpa_cli.config.model import DRIVE_TYPES
from sherpa_cli.elmo.drive import ElmoDrive
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.drive import Drive

ELMO = "elmo"


def _elmo(session: ArmSession, ref: DriveRef) -> Drive:
    return ElmoDrive(session.client(ref))


def _cia402(session: ArmSession, ref: DriveRef) -> Drive:
    # its confirmations wait on the session's clock, as the drive clients do (a stepped simulated
    # arm moves only while the tool waits: on the wall clock a drive's acknowledge would never come)
    overrides = getattr(session, "client_overrides", {})
    clock, sleep = overrides.get("clock"), overrides.get("sleep")
    if clock is not None and sleep is not None:
        return Cia402Drive(session.sdo(ref), f"{ref.name} ({ref.bus} node {ref.node})", clock=clock, sleep=sleep)
    return Cia402Drive(session.sdo(ref), f"{ref.name} ({ref.bus} node {ref.node})")


DRIVES: dict[str, Callable[[ArmSession, DriveRef], Drive]] = {ELMO: _elmo, "cia402": _cia402}
assert tuple(DRIVES) == DRIVE_TYPES, "config.model.DRIVE_TYPES and the drive registry must list the same types"


def drive_type(session: ArmSession, ref: DriveRef) -> str:
    """The configured type of the drive ``ref`` names ("elmo" for a BUS:NODE the config does not list)."""
    cfg = session.cfg.drives.get(ref.name)
    return ELMO if cfg is None else cfg.type


def open_drive(session: ArmSession, ref: DriveRef) -> Drive:
    kind = drive_type(session, ref)
    try:
        return DRIVES[kind](session, ref)
    except KeyError:
        raise UsageError(f"{ref.name}: unknown drive type '{kind}'; known: {', '.join(DRIVES)}") from None


def is_elmo(session: ArmSession, ref: DriveRef) -> bool:
    return drive_type(session, ref) == ELMO
